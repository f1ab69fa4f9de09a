"""Closed contours and the two kinds of initial contour (ellipse, clicked points).

Conventions, shared with ``../shared/data/README.md``:

* pixel coordinates are ``(x, y)`` with ``x`` = column and ``y`` = row, origin
  at the centre of the top-left pixel;
* millimetre coordinates are ``(x_mm, y_mm) = (x * col_spacing, y * row_spacing)``,
  so the same origin, scaled;
* a contour is closed implicitly: its last point is *not* a copy of the first.

A mask is a 2D boolean array, ``True`` (or non-zero) inside the target.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy.interpolate import CubicSpline

from hifumotion._polygon import boundary_curves
from hifumotion.errors import InputError
from hifumotion.sequence import as_spacing_mm


def as_mask(mask: Any, what: str = "mask", require_foreground: bool = True) -> np.ndarray:
    """Return ``mask`` as a 2D boolean array; raise :class:`InputError` if it is not one.

    Non-zero pixels are foreground. With ``require_foreground`` an all-background
    mask is an error, since no contour or distance can be defined for it.
    """
    arr = np.asarray(mask)
    if arr.ndim == 3 and arr.shape[-1] in (3, 4):  # an RGB(A) mask image: any channel counts
        arr = arr[..., :3].max(axis=-1)
    if arr.ndim != 2:
        raise InputError(f"expected a 2D mask, got an array of shape {arr.shape}", what)
    out = arr != 0 if arr.dtype != np.bool_ else arr
    if require_foreground and not out.any():
        raise InputError("mask has no foreground (every pixel is 0)", what)
    return out


def _drop_closing_point(points: np.ndarray) -> np.ndarray:
    # np.allclose's test (atol 1e-8, rtol 1e-5) on two points, without its per-call cost
    if len(points) > 1 and all(abs(a - b) <= 1e-8 + 1e-5 * abs(b) for a, b in zip(points[0].tolist(), points[-1].tolist())):
        return points[:-1]
    return points


def _polygon_area(points: np.ndarray) -> float:
    """Signed shoelace area of a closed polygon (same units squared as ``points``)."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def resample_closed(points: np.ndarray, count: int | None = None, step: float | None = None,
                    start: float = 0.0) -> np.ndarray:
    """Points evenly spaced in arc length along the closed polyline ``points`` ``(N, 2)``.

    Give ``count`` (that many points) or ``step`` (one every ``step`` units of arc length,
    at least 3); ``start`` is the arc length of the first point (wrapped around)."""
    closed = np.vstack([points, points[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    if count is None:
        if step is None:
            raise ValueError("give count or step")
        count = max(int(np.ceil(arc[-1] / step)), 3)
    at = (start + np.arange(count) * arc[-1] / count) % arc[-1]
    return np.column_stack([np.interp(at, arc, closed[:, 0]), np.interp(at, arc, closed[:, 1])])


def mask_boundaries_px(mask: np.ndarray) -> list[np.ndarray]:
    """All boundary curves of a mask, sub-pixel, as ``(N, 2)`` arrays of ``(x, y)`` pixels.

    The curves are the 0.5 iso-lines of the mask (marching squares), so they
    pass half-way between foreground and background pixel centres; the mask is
    padded first, so a region touching the image border still gets a closed curve.
    Holes give curves of their own. The same curves, in the same orientation, as
    scikit-image's ``find_contours(mask, 0.5)`` (tested), compiled
    (:func:`hifumotion._polygon.boundary_curves`): it assembled its curves in Python.
    """
    m = np.asarray(mask, dtype=bool)
    rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    if rows.size == 0:
        return []
    # only the mask's bounding box holds curves: marching squares costs what that box costs
    padded = np.pad(m[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1].astype(np.uint8), 1)
    points, starts = boundary_curves(padded)
    points += np.array([cols[0] - 1.0, rows[0] - 1.0])
    return [points[a:b] for a, b in zip(starts[:-1].tolist(), starts[1:].tolist()) if b - a >= 3]


def polygon_centroid(points: np.ndarray) -> np.ndarray:
    """Area centroid ``(2,)`` of the closed polygon ``points`` ``(M, 2)`` (its vertices' mean if it has no area)."""
    p = np.asarray(points, float)
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    a = cross.sum() / 2.0
    if abs(a) < 1e-12:
        return p.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * a)


@dataclass
class Contour:
    """A closed contour in one image plane.

    Attributes
    ----------
    points_px
        ``(N, 2)`` float array of ``(x, y)`` = (column, row) pixel coordinates,
        in boundary order, not closed by a repeated point.
    spacing_mm
        Pixel size ``(row, col)`` in mm, used for every mm quantity.
    """

    points_px: np.ndarray
    spacing_mm: tuple[float, float] = (1.0, 1.0)

    def __post_init__(self) -> None:
        pts = np.asarray(self.points_px, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
            raise InputError(f"a contour needs at least 3 points as an (N, 2) array, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise InputError("contour points must be finite")
        self.points_px = _drop_closing_point(pts)
        self.spacing_mm = as_spacing_mm(self.spacing_mm)

    # --- construction -------------------------------------------------------------------
    @classmethod
    def from_mm(cls, points_mm: np.ndarray, spacing_mm: float | tuple[float, float]) -> "Contour":
        """A contour from ``(x_mm, y_mm)`` points."""
        sp = as_spacing_mm(spacing_mm)
        pts = np.asarray(points_mm, dtype=float)
        return cls(pts / np.array([sp[1], sp[0]]), sp)

    @classmethod
    def from_mask(cls, mask: np.ndarray, spacing_mm: float | tuple[float, float] | None = None) -> "Contour":
        """The outer boundary of the mask's largest region (sub-pixel, see :func:`mask_boundaries_px`)."""
        m = as_mask(mask)
        curves = mask_boundaries_px(m)
        if not curves:
            raise InputError("mask has no closed boundary")
        best = max(curves, key=lambda c: abs(_polygon_area(c)))
        return cls(best, as_spacing_mm(spacing_mm))

    # --- geometry -------------------------------------------------------------------------
    @property
    def points_mm(self) -> np.ndarray:
        """``(N, 2)`` points in mm, ``(x_mm, y_mm)``."""
        return self.points_px * np.array([self.spacing_mm[1], self.spacing_mm[0]])

    @property
    def area_mm2(self) -> float:
        """Enclosed area in mm² (shoelace formula on the polygon)."""
        return abs(_polygon_area(self.points_mm))

    @property
    def length_mm(self) -> float:
        """Perimeter in mm."""
        p = self.points_mm
        return float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum())

    @property
    def centroid_mm(self) -> np.ndarray:
        """Area centroid ``(x_mm, y_mm)`` of the enclosed polygon."""
        return polygon_centroid(self.points_mm)

    def to_mask(self, shape: tuple[int, int]) -> np.ndarray:
        """Rasterise: ``True`` for every pixel whose centre lies inside the polygon (even-odd rule)."""
        from hifumotion._polygon import fill_polygon

        pts = self.points_px
        return fill_polygon(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), int(shape[0]), int(shape[1]))

    def resampled(self, step_px: float = 1.0) -> "Contour":
        """The same closed curve with points every ``step_px`` pixels of arc length (linear)."""
        return Contour(resample_closed(self.points_px, step=step_px), self.spacing_mm)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: points in px and mm, spacing, area and centroid."""
        return {
            "spacing_mm": list(self.spacing_mm),
            "points_px": np.round(self.points_px, 4).tolist(),
            "points_mm": np.round(self.points_mm, 5).tolist(),
            "area_mm2": self.area_mm2,
            "centroid_mm": self.centroid_mm.tolist(),
        }


@dataclass(frozen=True)
class Ellipse:
    """An initial ellipse in pixels (see ``../shared/data/README.md``).

    Boundary: ``x = cx + a cos t cos A − b sin t sin A``,
    ``y = cy + a cos t sin A + b sin t cos A`` with ``A = radians(angle_deg)``.

    Attributes
    ----------
    cx, cy
        Centre: column and row, px.
    a, b
        Semi-axes, px (``a`` along the direction ``angle_deg``).
    angle_deg
        Rotation of the ``a`` axis from the +x (column) axis towards +y (down), degrees.
    """

    cx: float
    cy: float
    a: float
    b: float
    angle_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("cx", "cy", "a", "b", "angle_deg"):
            v = getattr(self, name)
            if not np.isfinite(v):
                raise InputError(f"ellipse {name} must be finite, got {v!r}")
        if self.a <= 0 or self.b <= 0:
            raise InputError(f"ellipse semi-axes must be positive, got a={self.a}, b={self.b}")

    def points(self, n: int = 256) -> np.ndarray:
        """``n`` boundary points ``(x, y)`` in px."""
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        A = np.deg2rad(self.angle_deg)
        x = self.cx + self.a * np.cos(t) * np.cos(A) - self.b * np.sin(t) * np.sin(A)
        y = self.cy + self.a * np.cos(t) * np.sin(A) + self.b * np.sin(t) * np.cos(A)
        return np.column_stack([x, y])

    def to_contour(self, spacing_mm: float | tuple[float, float] | None = None, n: int = 256) -> Contour:
        """The boundary as a :class:`Contour`."""
        return Contour(self.points(n), as_spacing_mm(spacing_mm))

    def to_mask(self, shape: tuple[int, int]) -> np.ndarray:
        """Pixels whose centre lies inside the ellipse (exact test, no polygon)."""
        rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
        A = np.deg2rad(self.angle_deg)
        dx, dy = cols - self.cx, rows - self.cy
        u = dx * np.cos(A) + dy * np.sin(A)
        v = -dx * np.sin(A) + dy * np.cos(A)
        return (u / self.a) ** 2 + (v / self.b) ** 2 <= 1.0

    def to_dict(self) -> dict[str, float]:
        return {"cx": self.cx, "cy": self.cy, "a": self.a, "b": self.b, "angle_deg": self.angle_deg}


@dataclass(frozen=True)
class ClickedPoints:
    """An initial contour given as 5–7 (or more) points clicked along the boundary, in order.

    Attributes
    ----------
    points_px
        ``(N, 2)`` tuple-of-tuples of ``(x, y)`` px, N ≥ 3, in boundary order.
    """

    points_px: tuple[tuple[float, float], ...]

    def __init__(self, points_px: Any):
        pts = np.asarray(points_px, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
            raise InputError(f"clicked points need at least 3 (x, y) pairs, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise InputError("clicked points must be finite")
        object.__setattr__(self, "points_px", tuple(map(tuple, _drop_closing_point(pts).tolist())))

    @property
    def array(self) -> np.ndarray:
        return np.asarray(self.points_px, dtype=float)

    def polygon(self, spacing_mm: float | tuple[float, float] | None = None) -> Contour:
        """The closed polygon through the points (straight segments)."""
        return Contour(self.array, as_spacing_mm(spacing_mm))

    def smooth(self, spacing_mm: float | tuple[float, float] | None = None, n: int = 256) -> Contour:
        """A closed smooth curve through every point: periodic cubic spline in chord length.

        This is how a clinician's few clicks become a contour: the curve passes
        through each click and bends smoothly between them.
        """
        pts = self.array
        closed = np.vstack([pts, pts[:1]])
        chord = np.linalg.norm(np.diff(closed, axis=0), axis=1)
        if np.any(chord <= 0):
            raise InputError("clicked points contain two equal consecutive points")
        s = np.concatenate([[0.0], np.cumsum(chord)])
        spline = CubicSpline(s, closed, bc_type="periodic", axis=0)
        t = np.linspace(0.0, s[-1], n, endpoint=False)
        return Contour(spline(t), as_spacing_mm(spacing_mm))

    def to_mask(self, shape: tuple[int, int], smooth: bool = True) -> np.ndarray:
        """The region inside the smooth curve (or the polygon with ``smooth=False``)."""
        return (self.smooth() if smooth else self.polygon()).to_mask(shape)

    def to_dict(self) -> dict[str, Any]:
        return {"points": [list(p) for p in self.points_px]}


InitialContour = Ellipse | ClickedPoints


def parse_init_entry(entry: Mapping[str, Any], kind: str | None = None, where: str = "init") -> InitialContour:
    """One entry of an ``init.json`` (``{"ellipse": {...}}`` and/or ``{"points": [...]}``) as an object.

    ``kind`` picks ``"ellipse"`` or ``"points"``; ``None`` takes the ellipse when
    both are present (the paper's default start).
    """
    if not isinstance(entry, Mapping):
        raise InputError("expected an object with an 'ellipse' or a 'points' key", where)
    if kind not in (None, "ellipse", "points"):
        raise InputError(f"init kind must be 'ellipse' or 'points', got {kind!r}", where)
    if kind is None:
        kind = "ellipse" if "ellipse" in entry else "points"
    if kind not in entry:
        raise InputError(f"has no '{kind}' initial contour (keys: {sorted(entry)})", where)
    try:
        if kind == "ellipse":
            e = entry["ellipse"]
            return Ellipse(float(e["cx"]), float(e["cy"]), float(e["a"]), float(e["b"]), float(e.get("angle_deg", 0.0)))
        return ClickedPoints(entry["points"])
    except InputError as exc:
        raise InputError(exc.reason, f"{where}.{kind}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed '{kind}' entry ({exc})", where) from None
