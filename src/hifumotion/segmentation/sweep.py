"""Segment a spatial sweep: parallel planes through the resting tissue, from one contour.

The paper segments every image of its spatial sequence with GLCV before
reconstructing the tissue (Fig. 1, first step). A clinician outlines the
tissue once, in one plane; :func:`segment_sweep` segments that plane from the
outline and walks outwards plane by plane, each starting from its
neighbour's mask with the first plane's scale parameters, until the section
stops standing out from its surroundings — there the sweep has left the tissue.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage

from hifumotion.errors import InputError

#: A plane's region must differ from the ring around it by this fraction of the first plane's contrast.
CONTRAST_FRACTION = 0.5
#: A section smaller than this fraction of the first plane's is where the tissue ends.
MIN_AREA_FRACTION = 0.02
#: Iteration cap per plane after the first (its start is the neighbour's mask, already close).
PLANE_ITERATIONS = 150


def region_contrast(image: np.ndarray, mask: np.ndarray, ring_px: int = 8) -> float:
    """``|mean inside − mean of a ring just outside| / std of the image``: does the region stand out?"""
    img = np.asarray(image, float)
    ring = ndimage.binary_dilation(mask, iterations=ring_px) & ~mask
    if not mask.any() or not ring.any():
        return 0.0
    return float(abs(img[mask].mean() - img[ring].mean()) / (img.std() + 1e-12))


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
                  exclude: np.ndarray | None = None, **params: Any) -> SweepSegmentation:
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
        As :func:`~hifumotion.segmentation.segment`.
    exclude
        ``(S, H, W)`` pixels known not to be the target (a pool's floor, an instrument
        where it rests): removed from each plane's result before the next plane starts from it.

    Returns
    -------
    SweepSegmentation
        Masks; a plane whose result no longer stands out (contrast below
        :data:`CONTRAST_FRACTION` of the first plane's) or shrank below
        :data:`MIN_AREA_FRACTION` of it is where the tissue ends: it and the planes
        beyond are empty.
    """
    from hifumotion.segmentation import local_params, segment

    imgs = np.asarray(images)
    if imgs.ndim != 3:
        raise InputError(f"expected sweep images (S, H, W), got shape {imgs.shape}", "images")
    if not 0 <= start < len(imgs):
        raise InputError(f"start plane {start} is outside the sweep's {len(imgs)} planes", "start")
    masks = np.zeros(imgs.shape, bool)
    contrast = np.zeros(len(imgs))
    keep = (lambda k, m: m & ~exclude[k]) if exclude is not None else (lambda k, m: m)
    if exclude is not None and exclude.shape != imgs.shape:
        raise InputError(f"expected an exclusion mask of shape {imgs.shape}, got {exclude.shape}", "exclude")
    first = segment(imgs[start], init, method, spacing, **params)
    first_mask = keep(start, first.mask)
    if not first_mask.any():
        raise InputError(f"the contour vanished on sweep plane {start}", "init")
    masks[start] = first_mask
    contrast[start] = reference = region_contrast(imgs[start], first_mask)
    scale = {arg: first.params[key] for key, arg in
             (("radius_px", "radius"), ("sigma_px", "sigma"), ("kappa1", "kappa1")) if key in first.params}
    later = {"multiscale": False, "max_iterations": PLANE_ITERATIONS, **local_params(method), **scale, **params}
    min_area = MIN_AREA_FRACTION * first_mask.sum()
    notes = []
    for direction in (1, -1):
        previous = first_mask
        k = start + direction
        while 0 <= k < len(imgs):
            mask = keep(k, segment(imgs[k], previous, method, spacing, **later).mask)
            c = region_contrast(imgs[k], mask)
            if mask.sum() <= min_area or c < CONTRAST_FRACTION * reference:
                notes.append(f"tissue ends before plane {k} (contrast {c:.2f} vs {reference:.2f} at the start)")
                break
            masks[k], contrast[k] = mask, c
            previous = mask
            k += direction
    return SweepSegmentation(masks, start, contrast, notes)


__all__ = ["SweepSegmentation", "segment_sweep", "region_contrast"]
