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
    scales fill it: a pull–push pyramid (the weighted field and the weight halved in size
    ``levels`` times, then each level blended into the next finer one where that one's
    weight is thin), so occluded or textureless pixels take the weighted mean of their
    well-measured neighbours, at the cost of about one extra level's work.

    A zero-order fill: inside a gap the field is the neighbours' mean, not their trend. A
    first-order one (a local plane) was tried for the tissue under the bar and made the
    twins' tracking worse: the planes, extrapolated into the water around the tissue,
    start the next frame's flow far from the answer (docs/decisions.md).
    """
    import cv2

    f = np.ascontiguousarray(field, np.float32)
    if not np.isfinite(f).all():
        f = np.nan_to_num(f, nan=0.0)
    w = np.ascontiguousarray(weight, np.float32)
    if w.min() < 0:
        w = np.clip(w, 0.0, None)
    den = _blur(w, sigma_px)
    num = _blur(f * w[..., None], sigma_px)
    if num.ndim == 2:
        num = num[..., None]
    if den.min() >= ENOUGH_WEIGHT:
        return num / den[..., None]
    # pull: the weight and the weighted field, halved in size level by level
    dens, nums = [den], [num]
    for _ in range(levels):
        if min(dens[-1].shape) < 4:
            break
        nxt = cv2.pyrDown(nums[-1])
        nums.append(nxt[..., None] if nxt.ndim == 2 else nxt)
        dens.append(cv2.pyrDown(dens[-1]))
    # push: from the coarsest level down, thin weight takes the coarser level's estimate
    estimate = nums[-1] / np.maximum(dens[-1], 1e-12)[..., None]
    for d, n in zip(dens[-2::-1], nums[-2::-1]):
        up = cv2.resize(estimate, (d.shape[1], d.shape[0]), interpolation=cv2.INTER_LINEAR)
        if up.ndim == 2:
            up = up[..., None]
        # estimate = α n/d + (1 − α) up with α = min(d / ENOUGH, 1), written so that where α = 1
        # (most pixels) it costs one division
        alpha = np.minimum(d * np.float32(1.0 / ENOUGH_WEIGHT), np.float32(1.0))[..., None]
        own = n / np.maximum(d, np.float32(1e-12))[..., None]
        estimate = up + alpha * (own - up)
    return estimate.astype(np.float32, copy=False)


def linear_fill(field: np.ndarray, weight: np.ndarray, where: np.ndarray, sigma_px: float) -> np.ndarray:
    """``field`` (H, W, C) with the pixels ``where`` replaced by a local weighted plane
    ``a + b x + c y`` fitted to the pixels around them (Gaussian window ``sigma_px`` × ``weight``):
    first-order normalised convolution, so a gap takes its rim's value *and gradient*. Fitted on
    a grid coarsened by 2; pixels whose window holds too little weight keep their value."""
    import cv2

    out = np.array(field, np.float32, copy=True)
    if not where.any():
        return out
    h, w = weight.shape
    size = (max(w // 2, 1), max(h // 2, 1))
    # float32 moments: coordinates are centred on the (small) box, so x² stays in the hundreds
    sw = cv2.resize(np.ascontiguousarray(weight, np.float32), size, interpolation=cv2.INTER_AREA)
    sf = cv2.resize(np.ascontiguousarray(field * weight[..., None], np.float32), size, interpolation=cv2.INTER_AREA)
    sf = sf.reshape(size[1], size[0], -1) / np.maximum(sw, 1e-9)[..., None]
    ys, xs = np.mgrid[0:size[1], 0:size[0]].astype(np.float32)
    xs -= size[0] / 2.0
    ys -= size[1] / 2.0
    s = max(float(sigma_px) / 2.0, 1.0)

    def g(x):
        return cv2.GaussianBlur(x, (0, 0), sigmaX=s, sigmaY=s, borderType=cv2.BORDER_CONSTANT)

    m = [g(sw), g(sw * xs), g(sw * ys), g(sw * xs * xs), g(sw * xs * ys), g(sw * ys * ys)]
    mat = np.stack([np.stack([m[0], m[1], m[2]], -1), np.stack([m[1], m[3], m[4]], -1),
                    np.stack([m[2], m[4], m[5]], -1)], -2).astype(np.float64) + np.eye(3) * 1e-12
    # only where the gap is (on the coarse grid, grown by a pixel for the interpolation back)
    need = cv2.dilate(cv2.resize(where.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST),
                      np.ones((3, 3), np.uint8)).astype(bool)
    ok = need & (m[0] > 0.05)
    fit = np.full(sf.shape, np.nan, np.float32)
    if ok.any():
        sub = mat[ok]
        # enough weight spread in both directions (a plane needs more than a line of points)
        good = np.linalg.det(sub) > 1e-6 * m[0][ok] ** 3
        ok[ok] = good
        sub = sub[good]
    if ok.any():
        inv = np.linalg.inv(sub)
        for c in range(sf.shape[-1]):
            f = sf[..., c] * sw
            rhs = np.stack([g(f), g(f * xs), g(f * ys)], -1)[ok].astype(np.float64)
            coef = np.einsum("nij,nj->ni", inv, rhs)
            fit[..., c][ok] = coef[:, 0] + coef[:, 1] * xs[ok] + coef[:, 2] * ys[ok]
    up = cv2.resize(fit, (w, h), interpolation=cv2.INTER_LINEAR).reshape(h, w, -1)
    take = where & np.isfinite(up).all(-1)
    out[take] = up[take]
    return out
