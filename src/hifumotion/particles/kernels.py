"""SPH smoothing kernels (SI units: lengths in m, kernels in 1/m³).

The paper interpolates with "the cubic spline" (Eq. 9–11, 14, 16, 18) over the
particles "within distance h", so ``h`` here is the kernel's *support radius*:
W(r, h) = 0 for r ≥ h. In that convention (Müller et al. 2003; SPlisHSPlasH)
the 3D cubic spline is, with q = r / h and σ = 8 / (π h³),

    W = σ (6q³ − 6q² + 1)      for 0 ≤ q ≤ ½
    W = σ 2 (1 − q)³           for ½ < q ≤ 1,

normalised so that ∫W dV = 1. The viscosity force of Eq. 12 uses the Laplacian
of Müller's viscosity kernel, ∇²W_visc = 45 / (π h⁶) (h − r), which stays
positive so the viscous force only ever damps relative motion.

Each kernel has a scalar Numba version (for use inside other kernels) and a
vectorised NumPy wrapper for tests and set-up code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def cubic_w(r: float, h: float) -> float:
    """Cubic spline W(r, h) (1/m³); ``h`` is the support radius (Eq. 9)."""
    q = r / h
    if q >= 1.0:
        return 0.0
    sigma = 8.0 / (math.pi * h * h * h)
    if q <= 0.5:
        return sigma * (6.0 * q * q * q - 6.0 * q * q + 1.0)
    t = 1.0 - q
    return sigma * 2.0 * t * t * t


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def cubic_dw(r: float, h: float) -> float:
    """dW/dr of the cubic spline (1/m⁴); ∇W(r_ij) = dW/dr · r_ij / |r_ij|."""
    q = r / h
    if q >= 1.0:
        return 0.0
    sigma = 8.0 / (math.pi * h * h * h)
    if q <= 0.5:
        return sigma * (18.0 * q * q - 12.0 * q) / h
    t = 1.0 - q
    return -sigma * 6.0 * t * t / h


@njit(cache=True, inline="always", fastmath=True, error_model="numpy")
def viscosity_laplacian(r: float, h: float) -> float:
    """∇²W_visc(r, h) = 45 / (π h⁶) (h − r) (1/m⁵), Müller et al. 2003 (Eq. 12)."""
    if r >= h:
        return 0.0
    return 45.0 / (math.pi * h ** 6) * (h - r)


@njit(cache=True)
def _map(func_id: int, r: np.ndarray, h: float) -> np.ndarray:
    out = np.empty_like(r)
    for i in range(r.size):
        if func_id == 0:
            out[i] = cubic_w(r[i], h)
        elif func_id == 1:
            out[i] = cubic_dw(r[i], h)
        else:
            out[i] = viscosity_laplacian(r[i], h)
    return out


def kernel(r_m, h_m: float) -> np.ndarray:
    """Cubic spline W at distances ``r_m`` (m) for support radius ``h_m`` (m); 1/m³."""
    r = np.ascontiguousarray(r_m, dtype=np.float64)
    return _map(0, r.ravel(), float(h_m)).reshape(r.shape)


def kernel_derivative(r_m, h_m: float) -> np.ndarray:
    """dW/dr of the cubic spline (1/m⁴)."""
    r = np.ascontiguousarray(r_m, dtype=np.float64)
    return _map(1, r.ravel(), float(h_m)).reshape(r.shape)


def kernel_gradient(rij_m, h_m: float) -> np.ndarray:
    """∇W(r_ij) for displacement vectors ``rij_m`` (…, 3) in m (1/m⁴)."""
    rij = np.asarray(rij_m, dtype=np.float64)
    r = np.linalg.norm(rij, axis=-1)
    dw = kernel_derivative(r, h_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(r[..., None] > 0, rij / r[..., None], 0.0)
    return dw[..., None] * unit


def viscosity_kernel_laplacian(r_m, h_m: float) -> np.ndarray:
    """∇²W_visc (1/m⁵) of Müller's viscosity kernel (Eq. 12)."""
    r = np.ascontiguousarray(r_m, dtype=np.float64)
    return _map(2, r.ravel(), float(h_m)).reshape(r.shape)
