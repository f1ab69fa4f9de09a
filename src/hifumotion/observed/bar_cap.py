"""The tissue under the resting bar that the sweep's segmentation was not allowed to see.

The sweep is segmented with the resting bar, grown by a margin, excluded
(:func:`~hifumotion.estimation.prepare.known_solid_mask`): the bar's echo blooms, and a
segmentation that read the bloom as tissue would put the target's top on the bar. The price is
that the tissue the bar rests on loses its top, cut flat at the margin. A model reconstructed
from those masks has a flat top a margin below the face where the real one is convex and
touches it, so its contact with the bar is wrong from the first step (measured on the
``paper_s41`` twin: the model's bar travelled 35 % less than the truth's at the true
parameters, and the fit made the tissue softer to make up; ``docs/decisions.md``).

:func:`fill_under_bar` continues the visible top into the excluded band: the surface seen
from the bar's face (the first tissue along the bar's axis) is fitted by a quadratic in the
face's coordinates on the samples the exclusion did not cut, within 1.5 radii of the axis, and
the cut columns are filled from the band's bottom up to that surface, clipped at the face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: How far around the axis (in bar radii, margin included) the visible top is fitted.
FIT_REACH = 1.5


@dataclass(frozen=True)
class BarCap:
    """What :func:`fill_under_bar` did.

    ``filled_voxels``: mask samples set; ``fitted_columns`` / ``cut_columns``: how many of the
    columns along the bar's axis the fit used and how many the exclusion had cut;
    ``apex_depth_mm``: the fitted surface's least depth below the face within the face's
    radius (mm; 0 = touching, negative = the fit would enter the bar, clipped);
    ``skipped``: why nothing was filled, or ``""``.
    """

    filled_voxels: int
    fitted_columns: int
    cut_columns: int
    apex_depth_mm: float
    skipped: str = ""


def _face_frame(axis: np.ndarray, plane_normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the bar's face: ``e2`` across the sweep's planes where it can be
    (so that one column of the face's grid is one plane), ``e1`` completing the frame."""
    e2 = plane_normal - (plane_normal @ axis) * axis
    if np.linalg.norm(e2) < 1e-6:                    # the bar along the sweep: any frame of the face
        e2 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e2 = e2 / np.linalg.norm(e2)
    return np.cross(e2, axis), e2


def _quadratic_terms(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)


def fill_under_bar(masks: np.ndarray, points_mm: np.ndarray, tip_mm, direction, radius_mm: float,
                   margin_mm: float, column_mm: tuple[float, float], surface_offset_mm: float = 0.0
                   ) -> tuple[np.ndarray, BarCap]:
    """Fill the tissue a bar's exclusion cut from a stack of masks (module docstring).

    Parameters
    ----------
    masks
        ``(N, H, W)`` bool masks of the sweep, segmented with the bar grown by ``margin_mm``
        excluded.
    points_mm
        ``(N, H, W, 3)`` positions (mm) of the masks' pixel centres.
    tip_mm, direction
        The resting bar's tip (mm) and its axis (pointing into the tissue).
    radius_mm, margin_mm
        The bar's radius and the margin of the exclusion (mm).
    column_mm
        ``(across the planes' rows and columns, across the planes)``: the sizes (mm) of the face's
        grid cells, one pixel and one plane gap.
    surface_offset_mm
        How far outside the true boundary the masks lie (the imaging system's offset): the
        filled surface may reach that far past the face, so that the boundary, once moved in by
        the offset, touches it.

    Returns
    -------
    masks, cap
        A filled copy of the masks and a :class:`BarCap` saying what was done.
    """
    masks = np.asarray(masks, bool)
    pts = np.asarray(points_mm, float)
    axis = np.asarray(direction, float)
    axis = axis / np.linalg.norm(axis)
    rel = pts - np.asarray(tip_mm, float)
    normal = np.cross(pts[0, 0, 1] - pts[0, 0, 0], pts[0, 1, 0] - pts[0, 0, 0]) if masks.shape[1:] > (1, 1) \
        else np.array([0.0, 0.0, 1.0])
    e1, e2 = _face_frame(axis, normal / np.linalg.norm(normal))
    depth = rel @ axis                               # mm below the face along the axis
    u, v = rel @ e1, rel @ e2
    reach = radius_mm + margin_mm
    cell_u, cell_v = float(column_mm[0]), max(float(column_mm[1]), float(column_mm[0]))
    iu = np.floor(u / cell_u + 0.5).astype(np.int64)
    iv = np.floor(v / cell_v + 0.5).astype(np.int64)
    n_u = int(np.ceil(FIT_REACH * reach / cell_u)) + 1
    n_v = int(np.ceil(FIT_REACH * reach / cell_v)) + 1
    near = (np.abs(iu) <= n_u) & (np.abs(iv) <= n_v) & (depth > -margin_mm)
    # the first tissue along the axis in each column of the face's grid
    top = np.full((2 * n_u + 1, 2 * n_v + 1), np.inf)
    tissue = masks & near
    np.minimum.at(top, (iu[tissue] + n_u, iv[tissue] + n_v), depth[tissue])
    gu, gv = np.meshgrid((np.arange(2 * n_u + 1) - n_u) * cell_u, (np.arange(2 * n_v + 1) - n_v) * cell_v,
                         indexing="ij")
    rho = np.hypot(gu, gv)
    band_bottom = margin_mm + cell_u
    seen = np.isfinite(top)
    cut = seen & (top <= band_bottom + 0.5 * cell_u) & (rho <= reach)
    fit = seen & ~cut & (rho <= FIT_REACH * reach)
    if not cut.any():
        return masks.copy(), BarCap(0, int(fit.sum()), 0, float("nan"), "the exclusion cut no tissue")
    quadrants = {(int(a), int(b)) for a, b in zip(np.sign(gu[fit]) >= 0, np.sign(gv[fit]) >= 0)}
    if fit.sum() < 12 or len(quadrants) < 3:
        return masks.copy(), BarCap(0, int(fit.sum()), int(cut.sum()), float("nan"),
                                    "too little of the top is seen around the bar to continue it")
    from scipy.optimize import least_squares

    design = _quadratic_terms(gu[fit], gv[fit])
    # a mask's boundary lies between its last outside and its first inside pixel: half a pixel
    # above the first inside centre
    seen_depth = top[fit] - 0.5 * cell_u
    start = np.linalg.lstsq(design, seen_depth, rcond=None)[0]
    # robust: the sides of the target, where the surface turns down, are not its top
    coef = least_squares(lambda c: design @ c - seen_depth, start, loss="soft_l1", f_scale=cell_u).x
    inside = rho <= radius_mm
    apex = float((_quadratic_terms(gu[inside], gv[inside]) @ coef).min()) if inside.any() else float("nan")
    # fill: the cut columns, from the fitted surface (clipped at the face) down to the band's bottom
    fitted = _quadratic_terms(u, v) @ coef
    surface = np.maximum(fitted, -surface_offset_mm)
    in_cut = np.zeros(masks.shape, bool)
    in_cut[near] = cut[iu[near] + n_u, iv[near] + n_v]
    radial = np.hypot(u, v)
    add = in_cut & (radial <= reach) & (depth >= surface) & (depth <= band_bottom) & ~masks
    out = masks | add
    return out, BarCap(int(add.sum()), int(fit.sum()), int(cut.sum()), apex)


def fill_section_under_bar(mask: np.ndarray, points_mm: np.ndarray, inside_mm: np.ndarray, tip_mm, direction,
                           radius_mm: float, margin_mm: float, surface_offset_mm: float = 0.0) -> np.ndarray:
    """One plane's mask with its top under the bar continued up to a 3D shape's (``inside_mm``).

    The time series' frame-0 contour is cut under the bar as the sweep's planes were (by the
    bar's measured bloom); the reconstruction, its top continued by :func:`fill_under_bar`,
    knows what lies there. In each line along the bar's axis within ``radius_mm +
    margin_mm`` of it, the pixels between the face (less ``surface_offset_mm``) and the mask's
    first pixel are added where ``inside_mm`` (the shape's signed distance at the pixels, mm,
    positive inside) says tissue. ``points_mm``: ``(H, W, 3)`` pixel centres.
    """
    mask = np.asarray(mask, bool)
    pts = np.asarray(points_mm, float)
    axis = np.asarray(direction, float)
    axis = axis / np.linalg.norm(axis)
    rel = pts - np.asarray(tip_mm, float)
    depth = rel @ axis
    across = rel - depth[..., None] * axis
    radial = np.linalg.norm(across, axis=-1)
    # the lines along the axis: the in-plane coordinate across it, binned at the pixel
    column = pts[0, 1] - pts[0, 0] if pts.shape[1] > 1 else np.array([1.0, 0.0, 0.0])
    pixel = float(np.linalg.norm(column))
    side = column - (column @ axis) * axis
    if np.linalg.norm(side) < 1e-9 * max(pixel, 1.0):
        side = (pts[1, 0] - pts[0, 0]) if pts.shape[0] > 1 else np.array([0.0, 1.0, 0.0])
        side = side - (side @ axis) * axis
    side = side / np.linalg.norm(side)
    bins = np.floor((across @ side) / pixel + 0.5).astype(np.int64)
    reach = radius_mm + margin_mm
    near = radial <= reach
    if not (mask & near).any():
        return mask.copy()
    lo = int(bins[near].min())
    top = np.full(int(bins[near].max()) - lo + 1, np.inf)
    np.minimum.at(top, bins[mask & near] - lo, depth[mask & near])
    first = np.full(mask.shape, -np.inf)
    first[near] = top[bins[near] - lo]
    add = near & (depth < first) & (depth >= -surface_offset_mm) & (np.asarray(inside_mm) > 0) & ~mask
    return mask | add


__all__ = ["BarCap", "fill_under_bar", "fill_section_under_bar", "FIT_REACH"]
