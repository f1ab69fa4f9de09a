"""A tracking's files: what ``hifumotion track`` writes, and the calibration keeps of it.

Layout (lengths in mm, times in s)::

    masks/frame_NNNN.png        the target in every frame (0/255)
    masks.nii.gz                the same as 2D+t label map (3D Slicer)
    contours.csv                every frame's contour (point i is the same material point), at
                                most 256 points a frame
    material_points.npz         the material points' trajectories: rest_mm, kind (contour/interior),
                                displacement_mm (T, N, 2), quality (T, N); a grid of at most 2,000 inside
    material_points.csv         one row a point: x0_mm, y0_mm, last and largest displacement, mean quality
    tracking.json               speckle size, bar bloom, the bar's tracked push, timings
    motion.png                  frame 0 and the last frame with the contours; displacement quiver; strain

With ``fields`` (``track --fields``), the dense Lagrangian field around the target (frame 0's
target grown by :data:`FIELD_MARGIN_MM`, cut to its box and placed there)::

    displacement_x_mm.nii.gz    displacement of frame 0's pixels, x (column) component
    displacement_y_mm.nii.gz    … y (row) component
    quality.nii.gz              its per-pixel quality (local NCC with frame 0; 0 = filled)

NIfTI as ITK writes it keeps no NaN: pixels without an estimate (the known solids, and the box's
pixels beyond the margin) hold displacement 0 and quality 0 — read the quality to tell them.

Given points (``track --points``)::

    points.csv                  frame, time_s, point, name, x_px, y_px, x_mm, y_mm, disagreement_px
    points.png                  frame 0 and the last frame with every point's trajectory
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from hifumotion.speckle.displacement import DisplacementSeries
from hifumotion.speckle.follow import FollowResult
from hifumotion.speckle.points import PointTrack


def interior_points_px(mask: np.ndarray, step_px: float) -> np.ndarray:
    """Points ``(N, 2)`` (x, y px) on a grid of ``step_px`` inside ``mask`` eroded by one step."""
    from scipy import ndimage

    step = max(int(round(step_px)), 1)
    inner = ndimage.binary_erosion(mask, iterations=step)
    rows, cols = np.nonzero(inner)
    keep = (rows % step == 0) & (cols % step == 0)
    return np.column_stack([cols[keep], rows[keep]]).astype(float)


#: Most contour points written a frame (every k-th of the carried ones, so point i stays one
#: material point): a target's outline needs no more, and 500 frames of 1-px steps made 36 MB.
MAX_CONTOUR_POINTS_WRITTEN = 256
#: How far around frame 0's target the dense field is written (mm; at least 3 px).
FIELD_MARGIN_MM = 2.0

#: Most interior material points written: the grid's step grows until the target holds no more
#: (a 1 mm grid over a large region in coarse pixels made 7,500 points × 500 frames).
MAX_INTERIOR_POINTS = 2000


def material_points(result: FollowResult, interior_step_mm: float = 1.0,
                    max_interior: int = MAX_INTERIOR_POINTS) -> dict[str, np.ndarray]:
    """The material points of the fit: the contour's and a grid inside frame 0's section.

    The grid's step is ``interior_step_mm``, grown (by whole pixels) until at most
    ``max_interior`` points fall inside. Returns ``kind`` (N,), ``rest_px`` (N, 2),
    ``displacement_mm`` (T, N, 2), ``quality`` (T, N) and ``interior_step_mm``.
    """
    series = result.displacement
    spacing = series.spacing_mm
    contour0 = result.contours[0].points_px
    pixel = float(np.mean(spacing))
    step_px = max(int(round(interior_step_mm / pixel)), 1)
    area_px = int(result.masks[0].sum())
    if area_px > max_interior * step_px ** 2:
        step_px = int(np.ceil(np.sqrt(area_px / max_interior)))
    inner = interior_points_px(result.masks[0], step_px)
    while len(inner) > max_interior:   # the erosion's rounding: one more pixel of step
        step_px += 1
        inner = interior_points_px(result.masks[0], step_px)
    rest = np.vstack([contour0, inner])
    kind = np.array(["contour"] * len(contour0) + ["interior"] * len(inner))
    disp, qual = [], []
    for t in range(series.n_frames):
        d, q = series.at(rest, t)
        disp.append(d)
        qual.append(q)
    return {"kind": kind, "rest_px": rest, "displacement_mm": np.stack(disp), "quality": np.stack(qual),
            "interior_step_mm": step_px * pixel}


def material_points_csv(points: dict[str, np.ndarray], spacing_mm) -> str:
    """One row a material point: where it was on frame 0 (mm), its displacement on the last
    frame and the largest over the frames (mm), its mean quality. The trajectories themselves
    are in ``material_points.npz`` (:func:`write_material_points`)."""
    row, col = spacing_mm
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["point", "kind", "x0_mm", "y0_mm", "last_dx_mm", "last_dy_mm", "largest_displacement_mm",
                "mean_quality"])
    rest_mm = points["rest_px"] * np.array([col, row])
    d = points["displacement_mm"]
    last = d[-1]
    norms = np.linalg.norm(d, axis=2)
    seen = np.isfinite(norms).any(axis=0)          # a point on a solid has no displacement at all
    largest = np.full(len(rest_mm), np.nan)
    largest[seen] = np.nanmax(norms[:, seen], axis=0)
    quality = points["quality"].mean(axis=0)

    def num(v, digits):
        return "" if not np.isfinite(v) else f"{v:.{digits}f}"

    for i in range(len(rest_mm)):
        w.writerow([i, points["kind"][i], f"{rest_mm[i, 0]:.4f}", f"{rest_mm[i, 1]:.4f}", num(last[i, 0], 5),
                    num(last[i, 1], 5), num(largest[i], 5), f"{quality[i]:.4f}"])
    return buf.getvalue()


def write_material_points(folder: str | Path, points: dict[str, np.ndarray], spacing_mm) -> None:
    """``material_points.npz`` (every frame: ``rest_mm`` (N, 2), ``kind`` (N,),
    ``displacement_mm`` (T, N, 2) float32, ``quality`` (T, N) float16) and the one-row-a-point
    summary ``material_points.csv`` into ``folder``."""
    from hifumotion.io.files import atomic_path, write_text

    folder = Path(folder)
    row, col = spacing_mm
    with atomic_path(folder / "material_points.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, rest_mm=(points["rest_px"] * np.array([col, row])).astype(np.float32),
                                kind=points["kind"].astype("U8"),
                                displacement_mm=points["displacement_mm"].astype(np.float32),
                                quality=points["quality"].astype(np.float16),
                                spacing_mm=np.asarray(spacing_mm, float))
    write_text(folder / "material_points.csv", material_points_csv(points, spacing_mm))


def _pyplot():
    """matplotlib's pyplot on the file-only backend (no display is needed or opened)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_png(fig, path: str | Path) -> Path:
    """``fig`` laid out and written atomically to ``path`` as PNG, then closed."""
    import matplotlib.pyplot as plt

    from hifumotion.io.files import atomic_path

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return Path(path)


def motion_figure(frames: np.ndarray, result: FollowResult, path: str | Path) -> Path:
    """Frame 0 with the last frame's displacement of its tissue (arrows, true length, from
    where the material was) and both contours; the last frame with its contour; the last
    frame's axial strain ε_yy on frame 0's grid. Drawn as the frames are stored and shown by any
    image viewer: row 0 at the top."""
    plt = _pyplot()
    series = result.displacement
    last = series.n_frames - 1
    row, col = series.spacing_mm
    h, w = frames.shape[1:]
    # row 0 at the top, as the frames' own files show it (y, the row direction, points down)
    extent = (-0.5 * col, (w - 0.5) * col, (h - 0.5) * row, -0.5 * row)
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.8))
    for a, t, title in ((ax[0], 0, f"frame 0, displacement to frame {last}"), (ax[1], last, f"frame {last}")):
        a.imshow(frames[t], cmap="gray", vmin=0, vmax=1, origin="upper", extent=extent)
        for k, colour in ((0, "yellow"), (last, "orange")):
            if k == t or t == 0:
                p = result.contours[k].points_mm
                a.plot(np.r_[p[:, 0], p[:1, 0]], np.r_[p[:, 1], p[:1, 1]], color=colour, lw=1.2)
        a.set_title(title)
    u = series.displacement_mm[last]
    step = max(1, int(round(2.0 / col)))
    ys, xs = np.mgrid[0:h:step, 0:w:step]
    inside = result.masks[0][ys, xs] & np.isfinite(u[ys, xs, 0])
    ax[0].quiver(xs[inside] * col, ys[inside] * row, u[ys, xs, 0][inside], u[ys, xs, 1][inside],
                 color="cyan", angles="xy", scale_units="xy", scale=1.0, width=0.004)
    strain = np.where(result.masks[0], series.strain(last)[..., 1], np.nan)
    lim = np.nanpercentile(np.abs(strain), 98) if np.isfinite(strain).any() else 1.0
    im = ax[2].imshow(strain, cmap="RdBu_r", vmin=-lim, vmax=lim, origin="upper", extent=extent)
    ax[2].set_title(f"axial strain ε_yy, frame {last}")
    fig.colorbar(im, ax=ax[2], fraction=0.046)
    for a in ax:
        a.set_aspect("equal")
    return _save_png(fig, path)


def points_figure(frames: np.ndarray, track: PointTrack, path: str | Path) -> Path:
    """Frame 0 and the last frame, each point's trajectory drawn over both (px, row 0 at the top)."""
    plt = _pyplot()
    last = track.n_frames - 1
    pos = track.positions_px
    fig, ax = plt.subplots(1, 2, figsize=(12, 5))
    for a, t in ((ax[0], 0), (ax[1], last)):
        a.imshow(frames[t], cmap="gray", origin="upper")
        for i in range(pos.shape[1]):
            a.plot(pos[:, i, 0], pos[:, i, 1], lw=0.8, color="cyan")
        a.scatter(pos[t, :, 0], pos[t, :, 1], s=12, color="yellow" if t == 0 else "orange", zorder=3)
        a.set_title(f"frame {t}" + (", where the points start" if t == 0 else ", where they are"))
        a.set_xlabel("x (px)")
        a.set_ylabel("y (px)")
    return _save_png(fig, path)


def write_point_track(folder: str | Path, frames: np.ndarray, track: PointTrack, spacing_mm=None,
                      frame_interval_s: float | None = None) -> dict:
    """``points.csv`` and ``points.png`` into ``folder`` (module docstring); returns their summary
    (for ``tracking.json``): the points, the largest shift of any from frame 0 (px, and mm with a
    pixel size), the estimators' largest disagreement and the time a frame took."""
    from hifumotion.io.files import write_text
    from hifumotion.io.points import point_track_csv

    folder = Path(folder)
    write_text(folder / "points.csv", point_track_csv(track.positions_px, track.names, track.disagreement_px,
                                                      spacing_mm, frame_interval_s))
    points_figure(frames, track, folder / "points.png")
    shift_px = np.linalg.norm(track.positions_px - track.positions_px[:1], axis=2)
    summary = {"names": list(track.names), "largest_shift_px": round(float(shift_px.max()), 3),
               "largest_disagreement_px": round(float(track.disagreement_px.max()), 3),
               "ms_per_frame_mean": round(1000 * float(np.mean(track.seconds_per_frame[1:])), 3)
               if track.n_frames > 1 else None}
    if spacing_mm is not None:
        summary["largest_shift_mm"] = round(float(np.linalg.norm(track.positions_mm(spacing_mm)
                                                                 - track.positions_mm(spacing_mm)[:1], axis=2).max()), 4)
    return summary


def write_fields(folder: str | Path, series: DisplacementSeries, target: np.ndarray,
                 frame_interval_s: float | None) -> dict:
    """The dense displacement and quality around frame 0's ``target`` (module docstring); returns
    the box written, ``{"origin_px": [x, y], "shape_px": [h, w]}``."""
    from scipy import ndimage

    from hifumotion.io.writers import write_nifti

    spacing = series.spacing_mm
    grow = max(int(np.ceil(FIELD_MARGIN_MM / min(spacing))), 3)
    near = ndimage.binary_dilation(target, iterations=grow) if target.any() else np.ones_like(target)
    rows, cols = np.nonzero(near)
    box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    keep = near[box][None]
    origin = (int(cols.min()), int(rows.min()))
    for name, data in (("displacement_x_mm", series.displacement_mm[..., 0]),
                       ("displacement_y_mm", series.displacement_mm[..., 1]), ("quality", series.quality)):
        cut = np.where(keep, np.nan_to_num(data[:, box[0], box[1]], nan=0.0), np.float32(0.0)).astype(np.float32)
        write_nifti(Path(folder) / f"{name}.nii.gz", cut, spacing, frame_interval_s, origin_px=origin)
    return {"origin_px": list(origin), "shape_px": [int(box[0].stop - box[0].start), int(box[1].stop - box[1].start)]}


def write_tracking(folder: str | Path, frames: np.ndarray, result: FollowResult, frame_interval_s: float | None,
                   extra: dict | None = None, fields: bool = False) -> dict:
    """Write the layout of the module docstring into ``folder``; returns ``tracking.json``'s content."""
    from hifumotion.contour import Contour
    from hifumotion.io import write_contours_csv, write_json, write_masks_nifti, write_png_stack

    folder = Path(folder)
    series: DisplacementSeries = result.displacement
    spacing = series.spacing_mm
    write_png_stack(folder / "masks", result.masks)
    write_masks_nifti(folder / "masks.nii.gz", result.masks, spacing, frame_interval_s)
    every = int(np.ceil(len(result.contours[0].points_px) / MAX_CONTOUR_POINTS_WRITTEN))
    write_contours_csv(folder / "contours.csv",
                       {t: Contour(c.points_px[::every], c.spacing_mm) for t, c in enumerate(result.contours)})
    field_box = write_fields(folder, series, result.masks[0], frame_interval_s) if fields else None
    points = material_points(result)
    write_material_points(folder, points, spacing)
    motion_figure(frames, result, folder / "motion.png")
    first = result.first
    centroid = np.array([c.centroid_mm for c in result.contours])
    summary = {
        "frames": int(series.n_frames), "spacing_mm": list(spacing), "frame_interval_s": frame_interval_s,
        "estimator": series.estimator,
        "speckle_fwhm_px": None if first is None else [round(float(v), 3) for v in first.speckle_fwhm_px],
        "bar_bloom_px": None if first is None else list(first.bloom_px),
        "frame0_segmentation": None if first is None else {
            "outside_given_region_fraction": round(float(first.outside_fraction), 4),
            "given_region_kept": bool(first.given_region_kept),
            "bar_bloom_continued_px": int(first.bloom_continued_px)},
        "ms_per_frame_mean": round(1000 * float(np.mean(result.seconds_per_frame[1:])), 3)
        if series.n_frames > 1 else None,
        "centroid_shift_mm": np.round(np.linalg.norm(centroid - centroid[0], axis=1), 4).tolist(),
        "bar_shift_mm": None if series.rigid_shift_mm is None else np.round(series.rigid_shift_mm, 4).tolist(),
        "contour_points_written": int(len(result.contours[0].points_px[::every])),
        "material_points": {"contour": int((points["kind"] == "contour").sum()),
                            "interior": int((points["kind"] == "interior").sum()),
                            "interior_step_mm": round(float(points["interior_step_mm"]), 4)},
        "fields": field_box,
        **(extra or {}),
    }
    write_json(folder / "tracking.json", summary)
    return summary


__all__ = ["FIELD_MARGIN_MM", "MAX_CONTOUR_POINTS_WRITTEN", "MAX_INTERIOR_POINTS", "points_figure", "write_fields", "write_material_points", "write_point_track", "write_tracking",
           "material_points", "material_points_csv", "interior_points_px", "motion_figure"]
