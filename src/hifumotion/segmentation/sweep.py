"""Segment a spatial sweep: parallel planes through the resting tissue, from one contour.

The paper segments every image of its spatial sequence with GLCV before
reconstructing the tissue (Fig. 1, first step). A clinician outlines the
tissue once, in one plane; :func:`segment_sweep` segments that plane from the
outline and walks outwards plane by plane until the section stops standing out
from its surroundings — there the sweep has left the tissue.

With the models that carry a start from inside the target to its boundary
(GAC, CV, GLCV), every later plane is segmented the way the first is, from a
start inside its section, with the scales (local radius, σ, κ1) its own start
gives: the section predicted from the two planes before (:func:`inner_start`)
eroded by :data:`START_SHRINK` of its equivalent radius (GLCV's later planes are
carried by its balloon, :data:`INSIDE_PLANE_PARAMS`). Starting from the neighbour's mask
itself, as a tracked frame starts from the previous frame, puts the start on or
outside the next section's boundary wherever the sections shrink — towards the
ends of the sweep, by a whole plane's difference — and GLCV's balloon, with the
first plane's scales, over-segmented a small end section two- to six-fold
(``docs/decisions.md``). The models that only refine a boundary they start
near (LCV, RSF, MSLCV) still start from the neighbour's mask.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from hifumotion.errors import InputError

#: A plane's region must differ from the ring around it by this fraction of the first plane's contrast.
CONTRAST_FRACTION = 0.5
#: A section smaller than this fraction of the first plane's is where the tissue ends.
MIN_AREA_FRACTION = 0.02
#: A later plane starts from its neighbour's mask eroded by this fraction of the mask's equivalent radius.
START_SHRINK = 0.15
#: Iteration cap of a later plane refined from its neighbour's mask (``plane_start="neighbour"``).
PLANE_ITERATIONS = 150
#: The models that carry a start from inside the target to its boundary (a balloon, a global
#: region term or a global solve): their later planes start inside (``plane_start="inside"``).
CARRY_FROM_INSIDE = ("gac", "cv", "glcv")
PLANE_STARTS = ("inside", "neighbour")
#: How a later plane is segmented from its inside start, where that differs from the first plane:
#: GLCV's balloon, which stops where the tissue stops looking like the target, and not the global
#: geodesic, which took an outer edge on small end sections in low-contrast texture (``docs/decisions.md``).
INSIDE_PLANE_PARAMS = {"glcv": {"carry": "balloon"}}


def region_contrast(image: np.ndarray, mask: np.ndarray, ring_px: int = 8) -> float:
    """``(mean inside − mean of a ring just outside) / std of the image``: does the region stand out,
    and is it brighter (> 0) or darker (< 0) than its surroundings?"""
    img = np.asarray(image, float)
    ring = ndimage.binary_dilation(mask, iterations=ring_px) & ~mask
    if not mask.any() or not ring.any():
        return 0.0
    return float((img[mask].mean() - img[ring].mean()) / (img.std() + 1e-12))


def inner_start(mask: np.ndarray, before: np.ndarray | None = None, shrink: float | None = None) -> np.ndarray:
    """A start inside the next plane's section, from the last plane's ``mask`` (and the one
    ``before`` it, when there is one).

    The next section is predicted by extrapolating the in-plane signed distance along the
    sweep, ``2 d(mask) − d(before)`` (the shape-based interpolation of the reconstruction,
    carried one plane on), never beyond ``mask`` itself (a growing section stays as it was:
    a start must not lie outside), and eroded by ``shrink`` × the mask's equivalent radius
    (default :data:`START_SHRINK`). A prediction too small to start from falls back to
    ``mask`` eroded alone, and a mask too small to erode is returned as it is.
    """
    shrink = START_SHRINK if shrink is None else shrink
    margin = shrink * np.sqrt(mask.sum() / np.pi)
    depth = _signed_distance_px(mask)
    if before is not None and before.any():
        predicted = np.minimum(2.0 * depth - _signed_distance_px(before), depth)
        inner = predicted > margin
        if inner.sum() >= 9:
            return inner
    inner = depth > margin
    return inner if inner.sum() >= 9 else mask.copy()


def _signed_distance_px(mask: np.ndarray) -> np.ndarray:
    """Distance (px) to the mask's boundary, positive inside."""
    return np.where(mask, ndimage.distance_transform_edt(mask), -ndimage.distance_transform_edt(~mask))


@dataclass
class SweepSegmentation:
    """Masks of every plane of a sweep (empty where the tissue is absent)."""

    masks: np.ndarray                 # bool (S, H, W)
    start: int                        # the plane segmented from the clinician's contour
    contrast: np.ndarray              # (S,) region contrast of each plane's result (0 when empty)
    notes: list[str] = field(default_factory=list)

    @property
    def present(self) -> np.ndarray:
        return self.masks.reshape(len(self.masks), -1).any(axis=1)


def segment_sweep(images: Any, init: Any, start: int, method: str = "glcv", spacing=None,
                  exclude: np.ndarray | None = None, plane_start: str | None = None,
                  **params: Any) -> SweepSegmentation:
    """Segment a sweep from one initial contour.

    Parameters
    ----------
    images
        ``(S, H, W)`` images of parallel planes in order of position.
    init
        The initial contour on plane ``start`` (anything :func:`~hifumotion.segmentation.segment` takes).
    start
        Index of the plane ``init`` belongs to.
    method, spacing, params
        As :func:`~hifumotion.segmentation.segment`; ``params`` apply to every plane.
    exclude
        ``(S, H, W)`` pixels known not to be the target (a pool's floor, an instrument
        where it rests): removed from each plane's result before the next plane starts from it.
    plane_start
        How a later plane starts: ``"inside"`` — segmented as the first plane is, from the
        neighbour's mask eroded (:func:`inner_start`), with its own scales (the default of
        the models that carry a start from inside to the boundary: ``gac``, ``cv``,
        ``glcv``, :data:`CARRY_FROM_INSIDE`); ``"neighbour"`` — refined from the
        neighbour's mask itself with the first plane's scales and at most
        :data:`PLANE_ITERATIONS` iterations (the default of the models that only refine a
        boundary they start near: ``lcv``, ``rsf``, ``mslcv``).

    Returns
    -------
    SweepSegmentation
        Masks; a plane whose result no longer stands out as the first plane's does
        (contrast of the same sign, at least :data:`CONTRAST_FRACTION` of it) or shrank below
        :data:`MIN_AREA_FRACTION` of it is where the tissue ends: it and the planes
        beyond are empty.
    """
    from hifumotion.segmentation import METHODS, local_params, segment

    imgs = np.asarray(images)
    if imgs.ndim != 3:
        raise InputError(f"expected sweep images (S, H, W), got shape {imgs.shape}", "images")
    if not 0 <= start < len(imgs):
        raise InputError(f"start plane {start} is outside the sweep's {len(imgs)} planes", "start")
    if exclude is not None and exclude.shape != imgs.shape:
        raise InputError(f"expected an exclusion mask of shape {imgs.shape}, got {exclude.shape}", "exclude")
    how = plane_start or ("inside" if method.lower() in CARRY_FROM_INSIDE else "neighbour")
    if how not in PLANE_STARTS:
        raise InputError(f"plane_start must be one of {PLANE_STARTS}, got {plane_start!r}", "plane_start")
    masks = np.zeros(imgs.shape, bool)
    contrast = np.zeros(len(imgs))
    keep = (lambda k, m: m & ~exclude[k]) if exclude is not None else (lambda k, m: m)
    first = segment(imgs[start], init, method, spacing, **params)
    first_mask = keep(start, first.mask)
    if not first_mask.any():
        raise InputError(f"the contour vanished on sweep plane {start}", "init")
    masks[start] = first_mask
    contrast[start] = reference = region_contrast(imgs[start], first_mask)
    if how == "inside":
        later, start_from = {**INSIDE_PLANE_PARAMS.get(method.lower(), {}), **params}, inner_start
    else:  # the neighbour's mask lies on the boundary: its scales would be the boundary's
        scale = {arg: first.params[key] for key, arg in
                 (("radius_px", "radius"), ("sigma_px", "sigma"), ("kappa1", "kappa1")) if key in first.params}
        later = {"multiscale": False, "max_iterations": PLANE_ITERATIONS, **local_params(method), **scale}
        accepted = inspect.signature(METHODS[method.lower()]).parameters
        later = {**{k: v for k, v in later.items() if k in accepted}, **params}
        start_from = lambda mask, before: mask  # noqa: E731
    min_area = MIN_AREA_FRACTION * first_mask.sum()
    notes = []
    for direction in (1, -1):
        previous, before = first_mask, None
        k = start + direction
        while 0 <= k < len(imgs):
            mask = keep(k, segment(imgs[k], start_from(previous, before), method, spacing, **later).mask)
            c = region_contrast(imgs[k], mask)
            if mask.sum() <= min_area or c * np.sign(reference) < CONTRAST_FRACTION * abs(reference):
                notes.append(f"tissue ends before plane {k} (contrast {c:.2f} vs {reference:.2f} at the start)")
                break
            masks[k], contrast[k] = mask, c
            previous, before = mask, previous
            k += direction
    return SweepSegmentation(masks, start, contrast, notes)


__all__ = ["SweepSegmentation", "segment_sweep", "region_contrast", "inner_start"]
