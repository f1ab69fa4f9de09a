"""A segmentation's boundary moved by the imaging system's measured offset."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def shift_boundary(mask: np.ndarray, offset_mm: float, pixel_mm: float) -> np.ndarray:
    """The mask with its boundary moved inwards by ``offset_mm`` (outwards when negative).

    Exact Euclidean distances (pixel centres): a pixel stays inside when it is more than
    ``offset_mm`` from the outside; a negative offset adds the pixels within ``-offset_mm``."""
    m = np.asarray(mask, bool)
    if offset_mm == 0 or not m.any():
        return m.copy()
    if offset_mm > 0:
        inside = ndimage.distance_transform_edt(m) * pixel_mm
        out = inside > offset_mm + 0.5 * pixel_mm
        return out if out.any() else m.copy()
    outside = ndimage.distance_transform_edt(~m) * pixel_mm
    return outside <= -offset_mm + 0.5 * pixel_mm


__all__ = ["shift_boundary"]
