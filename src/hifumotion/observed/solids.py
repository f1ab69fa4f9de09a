"""What in an image cannot be the tissue: the pool's floor and the bar, and how far their echoes blur.

The setup (``setup.json``) says where the floor and the resting bar are; the image says
how far a solid's bright echo spreads beyond its surface (its *bloom*: the
point-spread function's tails, shown by the log compression). A segmentation or a
speckle tracker that reads the bloom as tissue puts the target's boundary on the bar,
so the bloom is measured on the image (:func:`measure_bloom_px`) rather than assumed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.observed.setup import Setup
from hifumotion.scene import Plane


@dataclass(frozen=True)
class Solids:
    """Frame-0 pixels of the known solids, bool ``(H, W)`` each.

    ``floor``: below the pool's floor (static); ``bar``: inside the resting bar (moves
    rigidly with the push). ``floor_distance_px``/``bar_distance_px``: where the geometry is
    known (:func:`known_solids`), each solid's signed distance at the pixel centres (px,
    negative inside; without a margin, ``mask == (distance <= 0)``): its surface to a fraction
    of a pixel, where a mask knows it to half a pixel — a tilted face's mask is a staircase.
    """

    floor: np.ndarray
    bar: np.ndarray
    floor_distance_px: np.ndarray | None = None
    bar_distance_px: np.ndarray | None = None

    @property
    def any(self) -> np.ndarray:
        return self.floor | self.bar


def imaging_plane(setup: Setup, z_mm: float | None = None) -> Plane:
    """The image plane at ``z_mm`` (default: the time series'), in the pool frame, from the setup."""
    im = setup.imaging
    x0, y0 = im.row0_col0_mm
    z = im.frames_plane_z_mm if z_mm is None else z_mm
    return Plane((float(x0), float(y0), float(z)), im.column_axis, im.row_axis, tuple(im.image_shape), im.pixel_mm)


def known_solids(plane: Plane, setup: Setup, bar_margin_mm: float = 0.0) -> Solids:
    """The pixels of ``plane`` below the pool's floor (y < 0) and inside the resting bar, grown
    by ``bar_margin_mm``, with their signed distances (px).

    The bar is taken with a sharp rim (``edge_radius_mm`` is the model's): rounding its mask by
    the edge radius moved 7 pixels of ``slide_stop_s48``'s bar and its carried contour's
    centroid by 0.06 mm through frame 0's bloom measure (docs/decisions.md, "Tissue cannot
    enter the bar"), so the masks stay what they were."""
    pts = plane.points_mm()
    px = float(plane.pixel_mm)
    floor_mm = pts[..., 1]
    floor = floor_mm < 0.0
    bar = np.zeros(floor.shape, bool)
    bar_mm = None
    b = setup.bar
    if b.enabled:
        along, radial = _bar_coordinates(pts, b)
        m = float(bar_margin_mm)
        bar = (along <= m) & (along >= -b.length_mm - m) & (radial <= b.radius_mm + m)
        bar_mm = _rounded_rectangle_mm(along, radial, b, 0.0) - m
    return Solids(floor, bar & ~floor, (floor_mm / px).astype(np.float32),
                  None if bar_mm is None else (bar_mm / px).astype(np.float32))


def bar_distance_mm(points_mm: np.ndarray, bar, edge_radius_mm: float | None = None) -> np.ndarray:
    """Signed distance (mm, negative inside) of ``points_mm`` ``(..., 3)`` to the resting bar
    (:class:`~hifumotion.observed.setup.BarSetup`): a cylinder of ``radius_mm`` and
    ``length_mm`` back from its tip along ``direction``, both ends' rims rounded by
    ``edge_radius_mm`` (default the bar's own; 0 for sharp) — a rounded rectangle in (along the
    axis, from the axis), exactly."""
    along, radial = _bar_coordinates(points_mm, bar)
    return _rounded_rectangle_mm(along, radial, bar, bar.edge_radius_mm if edge_radius_mm is None else edge_radius_mm)


def _bar_coordinates(points_mm: np.ndarray, bar) -> tuple[np.ndarray, np.ndarray]:
    """``(along, radial)`` (mm) of points from the resting bar's tip: along its axis (into the
    tissue), and from the axis."""
    axis = np.asarray(bar.direction, float)
    axis = axis / np.linalg.norm(axis)
    d = np.asarray(points_mm, float) - np.asarray(bar.tip_at_rest_mm, float)
    along = d @ axis
    return along, np.linalg.norm(d - along[..., None] * axis, axis=-1)


def _rounded_rectangle_mm(along: np.ndarray, radial: np.ndarray, bar, edge_radius_mm: float) -> np.ndarray:
    """The bar's signed distance (mm) in its (along, radial) coordinates, rims rounded by ``edge_radius_mm``."""
    e = float(edge_radius_mm)
    half = 0.5 * float(bar.length_mm)
    # the rounded rectangle's SDF: centred on the axis half a length back from the tip
    qa = np.abs(along + half) - (half - e)
    qr = radial - (float(bar.radius_mm) - e)
    return np.hypot(np.maximum(qa, 0.0), np.maximum(qr, 0.0)) + np.minimum(np.maximum(qa, qr), 0.0) - e


def check_bar_in_image(frame: np.ndarray, solids: Solids, where) -> None:
    """Raise :class:`~hifumotion.errors.InputError` naming ``where`` when the resting bar the
    setup places in the image lies mostly on dark pixels of ``frame`` (a metal bar echoes
    brightly): the setup is not this cine's, or its geometry is off."""
    from hifumotion.errors import InputError

    if not solids.bar.any():
        return
    img = np.asarray(frame, np.float32)
    bright = float((img[solids.bar] > np.median(img)).mean())
    if bright < 0.5:
        raise InputError(f"places the resting bar where frame 0 is dark ({100 * bright:.0f} % of its pixels "
                         "brighter than the image's median; a bar echoes brightly): is this the setup of this "
                         "cine, with the right image origin and bar tip?", where)


def measure_bloom_px(image: np.ndarray, solid: np.ndarray, level: float, speckle_fwhm_px: tuple[float, float],
                     limit_px: int = 40) -> tuple[int, int]:
    """How far (px, ``(rows, cols)``) a solid's echo stays brighter than ``level`` beyond its surface.

    Read on the image beside the solid, along the columns: for every distance ``d`` the
    mean grey level of the pixels ``d`` columns outside the solid's left and right edges
    (rows the solid occupies, pixels not in the solid); the bloom ends at the first ``d``
    where that mean is at or below ``level`` (where a segmentation would call it
    background). Beside a bar in water nothing but the bloom is bright, whereas its
    pushing face may touch the tissue; the depth-wise bloom is the lateral one scaled by
    the point-spread function's aspect, the speckle's FWHM ``(rows, cols)``
    (:func:`hifumotion.speckle.speckle_fwhm_px`). ``(0, 0)`` for an empty solid.
    """
    img = np.asarray(image, np.float32)
    solid = np.asarray(solid, bool)
    rows = np.flatnonzero(solid.any(1))
    if rows.size == 0:
        return (0, 0)
    s = solid[rows]
    a = img[rows]
    n = s.shape[1]
    first = s.argmax(1)
    last = n - 1 - s[:, ::-1].argmax(1)
    lateral = limit_px
    for d in range(1, limit_px + 1):
        vals = []
        for edge in (first - d, last + d):
            ok = (edge >= 0) & (edge < n)
            ok[ok] &= ~s[np.flatnonzero(ok), edge[ok]]
            if ok.any():
                vals.append(a[np.flatnonzero(ok), edge[ok]])
        if not vals:
            lateral = d - 1
            break
        if float(np.concatenate(vals).mean()) <= level:
            lateral = d - 1
            break
    fr, fc = speckle_fwhm_px
    axial = int(np.ceil(lateral * fr / max(fc, 1e-6))) if lateral else 0
    return (axial, int(lateral))


def bloom_mask(solid: np.ndarray, bloom_px: tuple[int, int]) -> np.ndarray:
    """``solid`` grown by its bloom: an ellipse of semi-axes ``bloom_px`` (rows, cols)."""
    import cv2

    ry, rx = (max(int(v), 0) for v in bloom_px)
    if ry == 0 and rx == 0:
        return np.asarray(solid, bool)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * rx + 1, 2 * ry + 1))
    return cv2.dilate(np.asarray(solid, np.uint8), kernel).astype(bool)


def continue_into_bloom(mask: np.ndarray, solid: np.ndarray, bloom_px: tuple[int, int]) -> np.ndarray:
    """``mask`` continued through a solid's bloom along the lines that leave the solid's surface.

    A segmentation that cannot see inside the bloom (:func:`bloom_mask`, set to the water's
    level before it ran) stops at the bloom's edge, whereas tissue pressed by the bar reaches
    the bar: the strip the bloom hides is left out of the target and, carried through a cine,
    biases every frame's section towards the side away from the bar. Each hidden pixel is
    taken as target when the first pixel beyond the bloom on the line from its nearest solid
    pixel through it is target: what the bloom hides between the solid and tissue seen at its
    edge is that tissue; where the bloom's edge shows water, the strip stays water. Distances
    are measured in units of the bloom's own semi-axes (rows, cols), so "beyond the bloom"
    means the same on its short and long sides.

    Returns a new mask; ``mask`` is not changed. A solid that is empty, or a zero bloom, leaves
    ``mask`` as it is.
    """
    from scipy import ndimage

    mask = np.asarray(mask, bool)
    solid = np.asarray(solid, bool)
    if not solid.any() or max(bloom_px) <= 0:
        return mask.copy()
    ry, rx = (max(int(v), 1) for v in bloom_px)
    # distance from the solid in bloom units (the bloom is where it is <= 1), and the nearest solid pixel
    dist, (near_r, near_c) = ndimage.distance_transform_edt(~solid, sampling=(1.0 / ry, 1.0 / rx),
                                                            return_indices=True)
    band = bloom_mask(solid, bloom_px)
    hidden = band & ~solid & ~mask
    r, c = np.nonzero(hidden)
    if r.size == 0:
        return mask.copy()
    sr, sc = near_r[r, c], near_c[r, c]
    length_px = np.hypot(r - sr, c - sc)
    # along the line from (sr, sc) through (r, c) the bloom's edge lies at 1 / dist of the way
    # out; the first pixel beyond it is the first one there or further that the band does not hold
    # (the band is the solid dilated by a pixel ellipse, which the distance's level 1 follows to
    # within a pixel)
    edge = 1.0 / dist[r, c]
    seen = np.zeros(r.size, bool)
    pending = np.ones(r.size, bool)
    for step_px in range(1, max(ry, rx) + 2):
        scale = edge + step_px / length_px
        qr = np.rint(sr + (r - sr) * scale).astype(int)
        qc = np.rint(sc + (c - sc) * scale).astype(int)
        inside = (qr >= 0) & (qr < mask.shape[0]) & (qc >= 0) & (qc < mask.shape[1])
        pending &= inside
        beyond = pending.copy()
        beyond[pending] = ~band[qr[pending], qc[pending]]
        seen[beyond] = mask[qr[beyond], qc[beyond]]
        pending &= ~beyond
        if not pending.any():
            break
    out = mask.copy()
    out[r[seen], c[seen]] = True
    return out


__all__ = ["Solids", "check_bar_in_image", "imaging_plane", "known_solids", "measure_bloom_px", "bloom_mask",
           "continue_into_bloom"]
