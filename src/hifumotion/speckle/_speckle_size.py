"""The speckle's size in an image: the width of its autocorrelation peak (Wagner et al. 1983).

The speckle cell of a fully developed speckle pattern is the imaging system's
resolution cell, so its size, measured from the image, sets every length the tracker
needs (the smoothing scale, how far a bright solid's blur reaches) without a
parameter per device.
"""

from __future__ import annotations

import numpy as np


def speckle_fwhm_px(image: np.ndarray, region: np.ndarray | None = None, window_px: int = 64) -> tuple[float, float]:
    """Full width at half maximum ``(rows, cols)`` (px) of the autocorrelation peak of ``image``
    in the best-textured ``window_px`` square (inside ``region`` where given).

    The autocovariance of the mean-removed window (FFT, zero-padded) is read along each
    axis from the peak to where it falls below half, linearly interpolated; at least
    1 px each.
    """
    img = np.asarray(image, np.float64)
    h, w = img.shape
    n = int(min(window_px, h, w))
    if region is None:
        region = np.ones((h, w), bool)
    # the window whose centre is deepest inside the region
    from scipy import ndimage

    depth = ndimage.distance_transform_edt(np.asarray(region, bool))
    r, c = np.unravel_index(int(np.argmax(depth)), depth.shape)
    r0 = int(np.clip(r - n // 2, 0, h - n))
    c0 = int(np.clip(c - n // 2, 0, w - n))
    patch = img[r0:r0 + n, c0:c0 + n]
    valid = np.asarray(region, bool)[r0:r0 + n, c0:c0 + n]
    patch = np.where(valid, patch - patch[valid].mean() if valid.any() else 0.0, 0.0)
    spec = np.fft.rfft2(patch, s=(2 * n, 2 * n))
    ac = np.fft.irfft2(np.abs(spec) ** 2, s=(2 * n, 2 * n))
    if ac[0, 0] <= 0:
        return (1.0, 1.0)
    ac = np.fft.fftshift(ac / ac[0, 0])
    centre = n

    def width(profile: np.ndarray) -> float:
        below = np.flatnonzero(profile[centre:] < 0.5)
        if below.size == 0:
            return float(n)
        k = int(below[0])
        a, b = profile[centre + k - 1], profile[centre + k]
        half = (k - 1) + (a - 0.5) / max(a - b, 1e-12)
        return max(2.0 * half, 1.0)

    return (width(ac[:, centre]), width(ac[centre, :]))
