"""Points to follow (a CSV a user writes) and their trajectories (the CSV ``track --points`` writes).

Input, one row a point, on frame 0::

    name,x_px,y_px            (or x_mm,y_mm with a known pixel size; name optional)
    hyoid,133.2,99.2

A contour CSV of one frame (``frame, point, x_px, y_px, …``, as ``segment`` and ``track`` write
it) is read the same way: its vertices become the points.

Output (``points.csv``), one row a point and frame; x is the column, y the row, origin at
the top-left pixel's centre as in the contour CSVs::

    frame,time_s,point,name,x_px,y_px,x_mm,y_mm,disagreement_px
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from hifumotion.errors import InputError, brief

#: Most points a file may hold: a few landmarks or a contour's vertices, not a dense grid
#: (a region is followed with ``--init``).
MAX_POINTS = 10_000

POINT_TRACK_COLUMNS = ("frame", "time_s", "point", "name", "x_px", "y_px", "x_mm", "y_mm", "disagreement_px")


def read_points_csv(path: str | Path, spacing_mm=None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Frame-0 points from a CSV with columns ``x_px, y_px`` or ``x_mm, y_mm`` (and ``name``).

    Returns ``(N, 2)`` (x, y) px and the names (``point_<i>`` where none is given). mm columns
    need ``spacing_mm`` (mm, scalar or (row, col)).
    """
    from hifumotion.io.files import require_regular_file
    from hifumotion.sequence import as_spacing_mm

    p = require_regular_file(path, "points CSV")
    try:
        with open(p, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read as a points CSV ({brief(exc)})", p) from None
    if not rows:
        raise InputError("no point rows (expected a header and one row a point)", p)
    if len(rows) > MAX_POINTS:
        raise InputError(f"holds {len(rows)} points; at most {MAX_POINTS} (follow a region with --init)", p)
    cols = {c.strip() for c in rows[0] if c is not None}
    use_px = {"x_px", "y_px"} <= cols
    if not (use_px or {"x_mm", "y_mm"} <= cols):
        raise InputError(f"expected columns 'x_px, y_px' or 'x_mm, y_mm' (and optionally 'name'), got {sorted(cols)}",
                         p)
    if not use_px and spacing_mm is None:
        raise InputError("gives points in mm but the cine carries no pixel size; give --spacing MM or x_px, y_px", p)
    row_mm, col_mm = as_spacing_mm(spacing_mm) if spacing_mm is not None else (1.0, 1.0)
    xk, yk = ("x_px", "y_px") if use_px else ("x_mm", "y_mm")
    points, names = [], []
    for line, r in enumerate(rows, start=2):           # line 1 is the header
        r = {(k or "").strip(): v for k, v in r.items()}
        if r.get(xk) is None or r.get(yk) is None:
            raise InputError(f"line {line} has fewer fields than the header (expected {xk}, {yk})", p)
        try:
            x, y = float(r[xk]), float(r[yk])
        except ValueError:
            raise InputError(f"line {line}: non-numeric coordinate ({r[xk]!r}, {r[yk]!r})", p) from None
        if not (np.isfinite(x) and np.isfinite(y)):
            raise InputError(f"line {line}: coordinates must be finite numbers, got ({x}, {y})", p)
        points.append((x, y) if use_px else (x / col_mm, y / row_mm))
        name = (r.get("name") or "").strip()
        names.append(name or f"point_{line - 2}")
    if "frame" in cols:
        # a contour CSV (frame, point, x_px, y_px, …): its vertices are points of one frame
        frames = sorted({(r.get("frame") or "").strip() for r in rows})
        if len(frames) > 1:
            raise InputError(f"holds points of frames {', '.join(frames[:4])}{' …' if len(frames) > 4 else ''}; "
                             "give those of frame 0 only", p)
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"names a point more than once: {', '.join(twice[:5])}", p)
    return np.asarray(points, float), tuple(names)


def point_track_csv(positions_px: np.ndarray, names, disagreement_px: np.ndarray, spacing_mm=None,
                    frame_interval_s: float | None = None) -> str:
    """The rows of ``points.csv`` (module docstring); mm columns empty without a pixel size,
    ``time_s`` empty without a frame interval."""
    from hifumotion.sequence import as_spacing_mm

    pos = np.asarray(positions_px, float)
    t_count, n = pos.shape[:2]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(POINT_TRACK_COLUMNS)
    scale = None
    if spacing_mm is not None:
        row, col = as_spacing_mm(spacing_mm)
        scale = np.array([col, row])
    for t in range(t_count):
        time_s = "" if frame_interval_s is None else f"{t * frame_interval_s:.6f}"
        mm = pos[t] * scale if scale is not None else None
        for i in range(n):
            w.writerow([t, time_s, i, names[i], f"{pos[t, i, 0]:.3f}", f"{pos[t, i, 1]:.3f}",
                        "" if mm is None else f"{mm[i, 0]:.4f}", "" if mm is None else f"{mm[i, 1]:.4f}",
                        f"{disagreement_px[t, i]:.3f}"])
    return buf.getvalue()


__all__ = ["MAX_POINTS", "POINT_TRACK_COLUMNS", "point_track_csv", "read_points_csv"]
