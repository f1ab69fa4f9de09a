"""Colour to grey, keeping the original intensity scale."""

from __future__ import annotations

import numpy as np

# ITU-R BT.709 luma weights, as scikit-image's rgb2gray; grey RGB (R = G = B) maps to itself.
_LUMA = np.array([0.2125, 0.7154, 0.0721])


def to_grey(array: np.ndarray, channel_axis_present: bool) -> np.ndarray:
    """Drop alpha and turn RGB into luminance in the array's own scale (0–255 stays 0–255).

    ``channel_axis_present`` says whether the last axis holds colour channels
    (3 or 4 of them); otherwise the array is returned unchanged. An integer
    array stays of its dtype so that intensity scaling can use the dtype's range.
    """
    if not channel_axis_present:
        return array
    rgb = array[..., :3]
    if np.all(rgb[..., 0] == rgb[..., 1]) and np.all(rgb[..., 1] == rgb[..., 2]):
        return rgb[..., 0]
    grey = rgb.astype(np.float64) @ _LUMA
    if np.issubdtype(array.dtype, np.integer):
        return np.clip(np.rint(grey), 0, np.iinfo(array.dtype).max).astype(array.dtype)
    return grey.astype(np.float32)


def has_channels(array: np.ndarray, frame_ndim: int) -> bool:
    """True when ``array`` has one axis more than ``frame_ndim`` and it has 3 or 4 entries."""
    return array.ndim == frame_ndim + 1 and array.shape[-1] in (3, 4)
