"""The level-set core shared by every model.

Representation
--------------
``φ`` (``phi``) is a float32 image, **positive inside** the contour, equal to the
signed distance in pixels to the zero level within a narrow band of half-width
:data:`BAND` and clamped to ``±(BAND + 1)`` beyond. The zero level is the
contour; ``φ > 0`` is the mask.

Evolution
---------
Each iteration a model returns a speed ``F`` on the band points (``|φ| ≤``
:data:`UPDATE_BAND`); the core applies ``φ ← φ + Δt F`` with ``Δt`` from a CFL
condition (the zero level moves at most :data:`CFL` px per iteration), then
re-initialises ``φ`` to a signed distance. Re-initialisation is exact and
sub-pixel: the zero level is extracted by marching squares and every band
pixel gets its distance to those segments (this keeps the zero level in place
to second order, unlike PDE re-initialisation, which drifts). Only a bounding
box around the contour is touched, so the cost follows the contour's length,
not the image's size.

The models' factor ``δ_ε(φ(x))`` in front of their flows only scales the speed
of the band around the zero level; we take it as 1 on the update band, so the
zero level moves with the speed ``F`` itself and one CFL number serves every
model. Inside integrals (LCV's Eq. 5) the regularised Dirac is the compactly
supported ``δ_ε(φ) = (1 + cos(πφ/ε)) / (2ε)`` for ``|φ| < ε``: the Lorentzian
``ε/(π(ε² + φ²))`` has a tail that, summed over a ball, would weigh pixels far
from the contour.

Convergence: the run stops when, over the last :data:`CONVERGENCE_WINDOW`
iterations, the mask changed by fewer pixels than
:data:`CONVERGENCE_FRACTION` × the contour length in pixels (the contour moved
less than that fraction of a pixel on average), or at the iteration cap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from hifumotion.contour import ClickedPoints, Contour, Ellipse, as_mask
from hifumotion.errors import InputError
from hifumotion.segmentation import _kernels as K

#: Half-width (px) of the band where φ is a true signed distance.
BAND = 3.0
#: Half-width (px) of the band where the speed is evaluated and φ updated.
UPDATE_BAND = 1.5
#: Largest motion of the zero level in one iteration (px).
CFL = 0.45
#: Width ε (px) of the regularised Heaviside and Dirac functions.
EPSILON = 1.5
CONVERGENCE_WINDOW = 10
CONVERGENCE_FRACTION = 0.005


def _segments_of_polygon(points: np.ndarray) -> np.ndarray:
    closed = np.vstack([points, points[:1]])
    return np.column_stack([closed[:-1, 0], closed[:-1, 1], closed[1:, 0], closed[1:, 1]]).astype(np.float64)


def phi_from_mask(mask: np.ndarray, width: float = BAND) -> np.ndarray:
    """Signed distance to the 0.5 iso-line of a binary mask (positive inside), clamped to ±(width+1)."""
    m = as_mask(mask, "initial mask")
    far = width + 1.0
    # ±far crosses zero half-way between pixels, as ±0.5 does: the same segments, and the
    # pixels beyond the mask's box need no pass (they are farther than the band)
    phi = np.where(m, far, -far).astype(np.float32)
    rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    if rows.size == 0:
        return phi
    grow = int(np.ceil(far)) + 1
    h, w = m.shape
    segments = K.interface_segments(phi, rows[0] - 1, rows[-1] + 2, cols[0] - 1, cols[-1] + 2)
    K.redistance_box(phi, segments, float(width), max(rows[0] - grow, 0), min(rows[-1] + grow + 1, h),
                     max(cols[0] - grow, 0), min(cols[-1] + grow + 1, w))
    return phi


def phi_from_contour(points_px: np.ndarray, shape: tuple[int, int], width: float = BAND) -> np.ndarray:
    """Signed distance to a closed polygon of ``(x, y)`` points, exact within the band."""
    contour = Contour(points_px)
    inside = contour.to_mask(shape)
    if not inside.any():
        raise InputError("the initial contour encloses no pixel of the image", "init")
    phi = np.where(inside, width + 1.0, -(width + 1.0)).astype(np.float32)
    K.redistance_box(phi, _segments_of_polygon(contour.points_px), float(width), 0, shape[0], 0, shape[1])
    return phi


def redistance(phi: np.ndarray, width: float = BAND, box: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Re-initialise ``phi`` in place to a signed distance to its own zero level (within ``box``)."""
    h, w = phi.shape
    r0, r1, c0, c1 = box if box is not None else (0, h, 0, w)
    segments = K.interface_segments(phi, r0, r1, c0, c1)
    K.redistance_box(phi, segments, float(width), r0, r1, c0, c1)
    return phi


def check_init(init: Any, shape: tuple[int, int], where: str = "init") -> None:
    """Raise :class:`InputError` (naming ``where``) unless the initial contour can start a level
    set on an image of ``shape``: finite, not absurdly larger than the image, overlapping it.

    Checked before φ is built: an ellipse of a 10⁹ px radius would be sampled at 10¹⁰ points."""
    from hifumotion.contour import parse_init_entry

    if isinstance(init, dict):
        init = parse_init_entry(init, where=where)
    h, w = int(shape[0]), int(shape[1])
    if isinstance(init, Ellipse):
        values = np.array([init.cx, init.cy, init.a, init.b, init.angle_deg], float)
        if not np.all(np.isfinite(values)) or init.a <= 0 or init.b <= 0:
            raise InputError("the ellipse needs finite values and positive semi-axes a, b (px)", where)
        if max(init.a, init.b) > 2 * np.hypot(h, w):
            raise InputError(f"an ellipse with semi-axes {init.a:g} × {init.b:g} px on a {h} × {w} px image; "
                             "expected one inside the image", where)
        lo = np.array([init.cx, init.cy]) - max(init.a, init.b)
        hi = np.array([init.cx, init.cy]) + max(init.a, init.b)
    else:
        if isinstance(init, ClickedPoints):
            pts = init.array
        elif isinstance(init, Contour):
            pts = init.points_px
        else:
            pts = np.asarray(init)
            if pts.shape == (h, w):
                return                      # a mask of the image's size
            if pts.ndim != 2 or pts.shape[1] != 2:
                raise InputError(f"an initial mask of shape {pts.shape} for an image of shape {(h, w)}", where)
        pts = np.asarray(pts, float)
        if not np.all(np.isfinite(pts)):
            raise InputError("the initial contour's points must be finite numbers (px)", where)
        lo, hi = pts.min(0), pts.max(0)
        if np.any(hi - lo > 4 * np.hypot(h, w)):
            raise InputError(f"the initial contour spans {hi - lo} px on a {h} × {w} px image", where)
    if hi[0] < 0 or hi[1] < 0 or lo[0] > w - 1 or lo[1] > h - 1:
        raise InputError(f"the initial contour (x {lo[0]:.0f}…{hi[0]:.0f}, y {lo[1]:.0f}…{hi[1]:.0f} px) lies outside "
                         f"the {h} × {w} px image", where)


#: Largest share of the image an initial contour may enclose: it outlines a target, and a level
#: set needs the background beside it to tell the two apart.
MAX_INIT_COVERAGE = 0.9


def check_init_region(init: Any, shape: tuple[int, int], where: str = "init") -> np.ndarray:
    """The initial region (bool mask) of a checked initial contour (:func:`check_init`); raise
    :class:`InputError` (naming ``where``) when it encloses no pixel or more than
    :data:`MAX_INIT_COVERAGE` of the image. For the edges where a user's contour enters."""
    check_init(init, shape, where)
    region = initial_phi(init, shape) > 0
    share = float(region.mean())
    if not region.any():
        raise InputError("the initial contour encloses no pixel of the image", where)
    if share > MAX_INIT_COVERAGE:
        raise InputError(f"the initial contour encloses {100 * share:.0f} % of the image; expected the target's "
                         f"outline (at most {100 * MAX_INIT_COVERAGE:.0f} %)", where)
    return region


def initial_phi(init: Any, shape: tuple[int, int]) -> np.ndarray:
    """φ for any initial contour: an :class:`Ellipse`, :class:`ClickedPoints` (closed smooth
    curve through them), a :class:`Contour`, an ``(N, 2)`` point array ``(x, y)``, or a mask."""
    from hifumotion.contour import parse_init_entry

    if isinstance(init, dict):
        init = parse_init_entry(init)
    check_init(init, shape)
    if isinstance(init, Ellipse):
        return phi_from_contour(init.points(max(64, int(2 * np.pi * max(init.a, init.b)))), shape)
    if isinstance(init, ClickedPoints):
        pts = init.array
        return phi_from_contour(init.smooth(n=max(64, int(_perimeter(pts)))).points_px, shape)
    if isinstance(init, Contour):
        return phi_from_contour(init.points_px, shape)
    arr = np.asarray(init)
    if arr.ndim == 2 and arr.shape == tuple(shape):
        return phi_from_mask(arr)
    if arr.ndim == 2 and arr.shape[1] == 2 and arr.shape[0] >= 3:
        pts = ClickedPoints(arr)
        return phi_from_contour(pts.smooth(n=max(64, int(_perimeter(pts.array)))).points_px, shape)
    raise InputError(
        f"expected an ellipse, clicked points (N, 2), a contour or a mask of shape {tuple(shape)}; got an array of shape {arr.shape}",
        "init",
    )


def _perimeter(points: np.ndarray) -> float:
    closed = np.vstack([points, points[:1]])
    return float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())


def band_box(phi: np.ndarray, margin: int, within: tuple[int, int, int, int] | None = None) -> tuple[int, int, int, int]:
    """Bounding box ``(r0, r1, c0, c1)`` of the band ``|φ| ≤ BAND`` grown by ``margin`` px.

    ``within`` limits the search to a window known to hold the whole band.
    """
    h, w = phi.shape
    r0, r1, c0, c1 = within if within is not None else (0, h, 0, w)
    b = K.band_bounds(phi, BAND, r0, r1, c0, c1)
    if b[1] == 0:
        return (0, h, 0, w)
    return (max(b[0] - margin, 0), min(b[1] + margin, h), max(b[2] - margin, 0), min(b[3] + margin, w))


@dataclass
class Evolution:
    """The outcome of :func:`evolve`."""

    phi: np.ndarray
    iterations: int
    converged: bool
    history: list[int] = field(default_factory=list)  # pixels that changed side, per iteration


SpeedFunction = Callable[[np.ndarray, np.ndarray, tuple[int, int, int, int]], np.ndarray]


def evolve(
    phi: np.ndarray,
    speed: SpeedFunction,
    max_iterations: int,
    *,
    curvature_weight: float = 0.0,
    min_iterations: int = 0,
    after_step: Callable[[np.ndarray, int], None] | None = None,
) -> Evolution:
    """Run the narrow-band evolution ``φ_t = F`` until convergence or ``max_iterations``.

    ``speed(phi, band, box)`` returns the model's speed at the band points (the
    data and edge terms); ``curvature_weight`` adds ``μ κ`` with κ the mean
    curvature. Speeds are in px per unit time with 1 the fastest a model asks
    for; the step is ``Δt = CFL / max(max|F|, 1)`` and at most ``0.25 / μ`` (the
    explicit stability limit of the curvature term), so a weak force moves the
    contour slowly and the run can converge.
    """
    h, w = phi.shape
    margin = int(BAND) + 2
    box = band_box(phi, margin)
    history: list[int] = []
    converged = False
    snapshot, snapshot_box = phi > 0, box
    it = 0
    for it in range(1, max_iterations + 1):
        band = K.band_points(phi, UPDATE_BAND, *box)
        if band.shape[0] == 0:
            break  # the contour vanished
        f = speed(phi, band, box)
        if curvature_weight:
            f = f + curvature_weight * K.curvature(phi, band)
        peak, dt = K.time_step(np.ascontiguousarray(f, dtype=np.float64), CFL, float(curvature_weight))
        if peak < 1e-9:
            converged = True
            break
        flips = K.apply_update(phi, band, f, dt, BAND + 1.0)
        grown = (max(box[0] - 1, 0), min(box[1] + 1, h), max(box[2] - 1, 0), min(box[3] + 1, w))
        redistance(phi, BAND, grown)
        box = band_box(phi, margin, grown)
        history.append(int(flips))
        if after_step is not None:
            after_step(phi, it)
        # convergence: net change of the mask over the window, relative to the contour length
        if it % CONVERGENCE_WINDOW == 0:
            union = (min(box[0], snapshot_box[0]), max(box[1], snapshot_box[1]),
                     min(box[2], snapshot_box[2]), max(box[3], snapshot_box[3]))
            changed = K.count_changed(phi, snapshot, *union)
            length = max(band.shape[0] / (2 * UPDATE_BAND + 1), 1.0)
            if it >= min_iterations and changed <= CONVERGENCE_FRACTION * length * CONVERGENCE_WINDOW:
                converged = True
                break
            snapshot, snapshot_box = phi > 0, box
    return Evolution(phi, it, converged, history)


# --------------------------------------------------------------------------- coarse-to-fine


#: The coarsest level keeps the initial contour's equivalent radius at least this many pixels.
COARSE_RADIUS_PX = 24.0


def pyramid_factors(radius_px: float, shape: tuple[int, int], multiscale: bool = True) -> list[int]:
    """Downsampling factors from coarse to fine, powers of two ending at 1.

    The coarsest level keeps the initial contour at least :data:`COARSE_RADIUS_PX`
    in equivalent radius and the image at least 48 px a side.
    """
    if not multiscale:
        return [1]
    f = 1
    while radius_px / (2 * f) >= COARSE_RADIUS_PX and min(shape) / (2 * f) >= 48:
        f *= 2
    factors = []
    while f >= 1:
        factors.append(f)
        f //= 2
    return factors


def downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Block-average by an integer factor (anti-aliased; edge blocks averaged over what exists)."""
    if factor == 1:
        return image
    h, w = image.shape
    hh, ww = -(-h // factor), -(-w // factor)
    padded = np.pad(image, ((0, hh * factor - h), (0, ww * factor - w)), mode="edge")
    return padded.reshape(hh, factor, ww, factor).mean(axis=(1, 3))


def resample_phi(phi: np.ndarray, ratio: float, shape: tuple[int, int]) -> np.ndarray:
    """φ on a grid ``ratio`` times finer (``ratio > 1``) or coarser, re-initialised.

    Pixel centres map as ``x_new = (x_old + 0.5) · ratio − 0.5``; distances scale by ``ratio``.
    """
    from scipy import ndimage

    rows = (np.arange(shape[0]) + 0.5) / ratio - 0.5
    cols = (np.arange(shape[1]) + 0.5) / ratio - 0.5
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    out = ndimage.map_coordinates(phi.astype(np.float64), [rr, cc], order=1, mode="nearest") * ratio
    out = np.clip(out, -(BAND + 1.0), BAND + 1.0).astype(np.float32)
    if not np.any(out > 0):
        raise InputError("the contour vanished when changing resolution", "init")
    return redistance(out, BAND)
