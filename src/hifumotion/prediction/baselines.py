"""Baselines any motion predictor must beat: no motion, a Kalman filter, an NCC template tracker.

* :func:`hold_last` — the last observed contour held (what a clinician does who
  stops re-aiming).
* :func:`kalman_predict` — the paper's discussion names Kalman filtering as the
  alternative (ref. 38): a constant-velocity Kalman filter (``filterpy``) on the
  contour's centroid and its shape, the radii from the centroid at evenly
  spaced angles (a star-shaped description), run over the observed frames and
  extrapolated to the frames asked for.
* :func:`ncc_track` — for the online mode: the image patch around the target in
  the last frame located in the next by normalised cross-correlation
  (``skimage.feature.match_template``); the contour moves by that shift.

Masks are boolean arrays on one image grid; times are frame numbers with a
frame interval in s; lengths in mm unless a name says px.
"""

from __future__ import annotations

import numpy as np
from skimage import draw

from hifumotion.errors import InputError


def hold_last(observed: dict[int, np.ndarray], frames) -> dict[int, np.ndarray]:
    """Every frame asked for gets the last observed mask (the no-motion baseline)."""
    if not observed:
        raise InputError("no observed frame to hold")
    last = observed[max(observed)]
    return {int(f): last.copy() for f in frames}


def star_descriptor(mask: np.ndarray, angles: int, pixel_mm: float) -> np.ndarray:
    """``[cx, cy, r_0 … r_{angles-1}]`` in mm: the centroid and the farthest boundary radius
    along each of ``angles`` evenly spaced directions (columns = x, rows = y)."""
    m = np.asarray(mask, bool)
    if not m.any():
        raise InputError("an empty mask has no shape to describe")
    rows, cols = np.nonzero(m)
    cx, cy = cols.mean(), rows.mean()
    theta = 2 * np.pi * np.arange(angles) / angles
    step = 0.25
    reach = np.arange(0.0, np.hypot(*m.shape), step)
    xs = cx + np.cos(theta)[:, None] * reach[None, :]
    ys = cy + np.sin(theta)[:, None] * reach[None, :]
    xi = np.clip(np.rint(xs).astype(int), 0, m.shape[1] - 1)
    yi = np.clip(np.rint(ys).astype(int), 0, m.shape[0] - 1)
    inside = m[yi, xi] & (xs >= 0) & (xs < m.shape[1]) & (ys >= 0) & (ys < m.shape[0])
    last = np.where(inside.any(1), inside.shape[1] - 1 - np.argmax(inside[:, ::-1], axis=1), 0)
    radii = reach[last] + 0.5
    return np.concatenate([[cx, cy], radii]) * pixel_mm


def star_mask(descriptor_mm: np.ndarray, shape: tuple[int, int], pixel_mm: float) -> np.ndarray:
    """The mask of a star descriptor (inverse of :func:`star_descriptor`)."""
    d = np.asarray(descriptor_mm, float) / pixel_mm
    cx, cy, radii = d[0], d[1], np.maximum(d[2:], 0.0)
    theta = 2 * np.pi * np.arange(len(radii)) / len(radii)
    rr, cc = draw.polygon(cy + radii * np.sin(theta), cx + radii * np.cos(theta), shape)
    out = np.zeros(shape, bool)
    out[rr, cc] = True
    return out


def kalman_predict(observed: dict[int, np.ndarray], frames, frame_interval_s: float, pixel_mm: float,
                   angles: int = 64, acceleration_mm_s2: float = 0.2, measurement_mm: float = 0.2
                   ) -> dict[int, np.ndarray]:
    """Constant-velocity Kalman filter on the star descriptor, extrapolated to ``frames``.

    ``acceleration_mm_s2`` is the white-noise acceleration of every descriptor entry
    (the process noise) and ``measurement_mm`` the standard deviation of a measured
    contour; the filter runs over the observed frames in order, then predicts ahead.
    """
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    if not observed:
        raise InputError("the Kalman filter needs at least one observed frame")
    times = sorted(observed)
    shape = observed[times[0]].shape
    z = np.stack([star_descriptor(observed[t], angles, pixel_mm) for t in times])
    m = z.shape[1]
    kf = KalmanFilter(dim_x=2 * m, dim_z=m)
    kf.H = np.kron(np.eye(m), np.array([[1.0, 0.0]]))
    kf.R = np.eye(m) * measurement_mm ** 2
    kf.x = np.kron(z[0], np.array([1.0, 0.0]))
    kf.P = np.kron(np.eye(m), np.diag([measurement_mm ** 2, 10.0 ** 2]))

    def set_dt(dt: float) -> None:
        kf.F = np.kron(np.eye(m), np.array([[1.0, dt], [0.0, 1.0]]))
        kf.Q = np.kron(np.eye(m), Q_discrete_white_noise(2, dt=dt, var=acceleration_mm_s2 ** 2))

    for prev, t, zt in zip(times[:-1], times[1:], z[1:]):
        set_dt((t - prev) * frame_interval_s)
        kf.predict()
        kf.update(zt)
    out = {}
    for f in sorted(int(f) for f in frames):
        dt = (f - times[-1]) * frame_interval_s
        x = np.kron(np.eye(m), np.array([[1.0, dt], [0.0, 1.0]])) @ kf.x if dt > 0 else kf.x
        out[f] = star_mask(kf.H @ x, shape, pixel_mm)
    return out


def ncc_shift(previous: np.ndarray, current: np.ndarray, mask: np.ndarray, margin_px: int = 10,
              search_px: int = 15) -> tuple[int, int]:
    """Integer shift ``(dx, dy)`` px of the target from ``previous`` to ``current``: the patch
    around ``mask`` (its bounding box + ``margin_px``) found by NCC within ``search_px``."""
    from skimage.feature import match_template

    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return 0, 0
    h, w = previous.shape
    r0, r1 = max(rows.min() - margin_px, 0), min(rows.max() + margin_px + 1, h)
    c0, c1 = max(cols.min() - margin_px, 0), min(cols.max() + margin_px + 1, w)
    patch = previous[r0:r1, c0:c1].astype(float)
    s0, s1 = max(r0 - search_px, 0), min(r1 + search_px, h)
    t0, t1 = max(c0 - search_px, 0), min(c1 + search_px, w)
    window = current[s0:s1, t0:t1].astype(float)
    score = match_template(window, patch)
    i, j = np.unravel_index(int(np.argmax(score)), score.shape)
    return int(t0 + j - c0), int(s0 + i - r0)


def ncc_track(images: np.ndarray, first_mask: np.ndarray, start: int = 0, **kwargs) -> dict[int, np.ndarray]:
    """Track ``first_mask`` (on frame ``start``) through ``images[start:]`` by NCC shifts."""
    from scipy import ndimage

    mask = np.asarray(first_mask, bool)
    out = {start: mask.copy()}
    total = np.zeros(2)
    for k in range(start + 1, len(images)):
        dx, dy = ncc_shift(images[k - 1], images[k], out[k - 1], **kwargs)
        total += (dx, dy)
        out[k] = ndimage.shift(mask.astype(float), (total[1], total[0]), order=0) > 0.5
    return out
