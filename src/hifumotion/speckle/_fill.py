"""Normalised convolution: smooth a field by its per-pixel weights and fill where it has none.

Knutsson H, Westin C-F. Normalized and differential convolution. CVPR 1993.
"""

from __future__ import annotations

import numpy as np

#: A pixel takes the finest scale whose blurred weight reaches this (1 = full weight all round).
ENOUGH_WEIGHT = 0.25


def _blur(x: np.ndarray, sigma_px: tuple[float, float]) -> np.ndarray:
    import cv2

    sr, sc = sigma_px
    return cv2.GaussianBlur(x, (0, 0), sigmaX=float(sc), sigmaY=float(sr), borderType=cv2.BORDER_REFLECT)


def normalized_convolution(field: np.ndarray, weight: np.ndarray, sigma_px: tuple[float, float],
                           levels: int = 6) -> np.ndarray:
    """``field`` (H, W, C) smoothed with a Gaussian of ``sigma_px`` (row, col) weighted by ``weight``
    (H, W) ≥ 0; where the weight around a pixel is too thin (< :data:`ENOUGH_WEIGHT`), coarser
    scales fill it (a Gaussian pyramid of the weighted field and of the weight, each level
    twice as wide, up to ``levels``), so occluded or textureless pixels take the weighted
    mean of their well-measured neighbours.

    A zero-order fill: inside a gap the field is the neighbours' mean, not their trend. A
    first-order one (a local plane) was tried for the tissue under the bar and made the
    twins' tracking worse: the planes, extrapolated into the water around the tissue,
    start the next frame's flow far from the answer (docs/decisions.md).
    """
    import cv2

    f = np.ascontiguousarray(np.nan_to_num(field, nan=0.0), np.float32)
    w = np.ascontiguousarray(np.clip(weight, 0.0, None), np.float32)
    h, wd = w.shape
    den = _blur(w, sigma_px)
    num = _blur(f * w[..., None], sigma_px)
    if num.ndim == 2:
        num = num[..., None]
    ok = den >= ENOUGH_WEIGHT
    out = np.where(ok[..., None], num / np.maximum(den, 1e-12)[..., None], f)
    todo = ~ok
    pw, pwf = den, num
    for _ in range(levels):
        if not todo.any() or min(pw.shape[:2]) < 4:
            break
        pw, pwf = cv2.pyrDown(pw), cv2.pyrDown(pwf)
        if pwf.ndim == 2:
            pwf = pwf[..., None]
        up_w = cv2.resize(pw, (wd, h), interpolation=cv2.INTER_LINEAR)
        up_f = cv2.resize(pwf, (wd, h), interpolation=cv2.INTER_LINEAR)
        if up_f.ndim == 2:
            up_f = up_f[..., None]
        fill = todo & (up_w >= ENOUGH_WEIGHT * 0.5)
        out[fill] = up_f[fill] / up_w[fill][:, None]
        todo &= ~fill
    return out
