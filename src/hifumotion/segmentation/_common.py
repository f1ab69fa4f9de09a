"""What every model shares: the image as float64 in [0, 1], scale-derived defaults, the result."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from hifumotion.contour import Contour
from hifumotion.errors import InputError
from hifumotion.sequence import as_spacing_mm, scale_intensities
from hifumotion.segmentation import _kernels as K
from hifumotion.segmentation.levelset import CFL, Evolution, downsample, evolve, initial_phi, pyramid_factors, resample_phi


def prepare_image(image: Any) -> np.ndarray:
    """A 2D image of any dtype as float64 in [0, 1] (uint8 by 0–255, others by min–max).

    Raises :class:`InputError` for a non-2D array or NaN/inf values.
    """
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 2:
        raise InputError(f"expected a 2D image, got an array of shape {arr.shape}", "image")
    if min(arr.shape) < 8:
        raise InputError(f"image of shape {arr.shape} is too small to segment (at least 8 × 8 px)", "image")
    if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
        raise InputError("image contains NaN or infinite values; fill or mask them first", "image")
    if np.issubdtype(arr.dtype, np.floating) and arr.min() >= 0.0 and arr.max() <= 1.0:
        return arr.astype(np.float64)
    return scale_intensities(arr).astype(np.float64)


def equivalent_radius_px(phi: np.ndarray) -> float:
    """Radius of the disc with the area of ``φ > 0`` (px): the scale of the initial contour."""
    return float(np.sqrt(max(np.count_nonzero(phi > 0), 1) / np.pi))


def default_iterations(radius_px: float) -> int:
    """Iteration cap: enough for the contour to travel 1.5 initial radii at 0.06 px per
    iteration (a balloon of 0.5 at half weight with the curvature-limited step of 0.25)."""
    return int(min(max(200, np.ceil(1.5 * radius_px / 0.06)), 3000))


_BORDERS = {"nearest": 1, "constant": 0}  # cv2.BORDER_REPLICATE, cv2.BORDER_CONSTANT


def gaussian(image: np.ndarray, sigma_px: float, mode: str = "nearest", truncate: float = 4.0,
             precise: bool = False) -> np.ndarray:
    """``G_σ * I`` (float64), as ``scipy.ndimage.gaussian_filter(image, σ, mode=mode, truncate=truncate)``.

    Computed by OpenCV's separable filter, in float32 by default: the same kernel (within
    1e-6 of SciPy's result on [0, 1] images), three to four times faster at the σ of
    5–30 px the models use on whole images every pyramid level (``docs/decisions.md``).
    ``precise`` filters in float64 (twice as fast as SciPy), for sums that later cancel (RSF's
    energies on a 0–255 scale)."""
    import cv2

    radius = int(truncate * float(sigma_px) + 0.5)
    size = 2 * radius + 1
    dtype = np.float64 if precise else np.float32
    out = cv2.GaussianBlur(np.ascontiguousarray(image, dtype=dtype), (size, size), float(sigma_px),
                           sigmaY=float(sigma_px), borderType=_BORDERS[mode])
    return out.astype(np.float64)


def edge_indicator(image: np.ndarray, sigma_px: float, smoothed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``g = 1 / (1 + |∇(G_σ * I)|² / λ²)`` and its gradient ``(g, ∂g/∂x, ∂g/∂y)``.

    The papers write ``g = 1/(1 + |∇G_σ * I|²)``, whose value depends on the
    intensity scale. We divide the gradient by λ, the 90th percentile of
    ``|∇(G_σ * I)|`` over the image, so that g is the same for any brightness
    scale and image: g ≈ 0.5 on the image's strongest 10 % of edges.
    ``smoothed`` passes ``G_σ * I`` when the caller already has it.
    """
    smooth = smoothed if smoothed is not None else gaussian(image, sigma_px)
    mag2 = K.gradient_magnitude2(np.ascontiguousarray(smooth, dtype=np.float64))
    lam2 = percentile(mag2, 90.0) or 1e-12
    return K.edge_function(mag2, lam2)


def percentile(a: np.ndarray, q: float) -> float:
    """``np.percentile(a, q)`` (linear interpolation) from one partial sort, without its overhead."""
    flat = np.ravel(a)
    k = q / 100.0 * (flat.size - 1)
    lo = int(k)
    hi = min(lo + 1, flat.size - 1)
    part = np.partition(flat, [lo, hi])
    return float(part[lo] + (k - lo) * (part[hi] - part[lo]))


@dataclass
class LocalStatistics:
    """Disk sums of the image that do not change during an evolution.

    The pixel count and the intensity sum over the ball ``B(x, r)`` (Eq. 1) of a
    pixel are computed the first time a band point needs them and cached, so
    the cost follows the area the contour sweeps, not the image.
    """

    image: np.ndarray
    radius_px: float
    half_widths: np.ndarray
    prefix: np.ndarray  # (H, W+1, 2): row prefix sums of 1 and I
    count: np.ndarray  # (H, W): cached pixel count of each ball, NaN where not computed yet
    total: np.ndarray  # (H, W): cached intensity sum of each ball, NaN where not computed yet

    @classmethod
    def of(cls, image: np.ndarray, radius_px: float) -> "LocalStatistics":
        h, w = image.shape
        prefix = np.concatenate([K.row_prefix(np.ones_like(image), 0, h, 0, w), K.row_prefix(image, 0, h, 0, w)], axis=2)
        return cls(image, radius_px, K.disk_half_widths(radius_px), prefix,
                   np.full((h, w), np.nan), np.full((h, w), np.nan))

    def static_sums(self, band: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel count and intensity sum over the ball of each band point."""
        rows, cols = band[:, 0], band[:, 1]
        count = self.count[rows, cols]
        missing = np.isnan(count)
        if missing.any():
            h, w = self.image.shape
            new = band[missing]
            sums = K.disk_sums(self.prefix, new, self.half_widths, 0, 0, h, w)
            self.count[new[:, 0], new[:, 1]] = sums[:, 0]
            self.total[new[:, 0], new[:, 1]] = sums[:, 1]
            count = self.count[rows, cols]
        return count, self.total[rows, cols]

    def region_force(self, phi: np.ndarray, band: np.ndarray, box, point_image: np.ndarray | None,
                     scale: float, integral: bool, eps: float):
        """LCV's region force at the band points (see :func:`_kernels.local_region_force`)."""
        h, w = phi.shape
        r = int(np.ceil(self.radius_px))
        r0, r1 = max(box[0] - r, 0), min(box[1] + r, h)
        c0, c1 = max(box[2] - r, 0), min(box[3] + r, w)
        pim = self.image if point_image is None else point_image
        return K.local_region_force(phi, self.image, pim, band, self.half_widths, r0, r1, c0, c1, self.prefix,
                                    self.count, self.total, float(scale), float(eps), bool(integral))

    def local_means(self, phi: np.ndarray, image: np.ndarray, band: np.ndarray, box, eps: float,
                    with_delta: bool = True):
        """At each band point x: inside and outside means ``c_x1, c_x2`` over the disk B(x, r)
        (Eq. 2–3, sharp Heaviside) and the disk sums of ``δ(φ)`` and ``δ(φ)·I`` (for Eq. 5).

        Returns ``(c1, c2, s_delta, s_delta_i, n_inside, n_outside)``; without
        ``with_delta`` the two δ sums are not computed (None).
        """
        h, w = phi.shape
        r = int(np.ceil(self.radius_px))
        r0, r1 = max(box[0] - r, 0), min(box[1] + r, h)
        c0, c1_ = max(box[2] - r, 0), min(box[3] + r, w)
        dyn = K.stack_local_fields(phi, image, eps, r0, r1, c0, c1_, with_delta)
        sums_dyn = K.disk_sums(dyn, band, self.half_widths, r0, c0, h, w)
        n_all, s_all = self.static_sums(band)
        n_in, s_in = sums_dyn[:, 0], sums_dyn[:, 1]
        n_out = n_all - n_in
        with np.errstate(invalid="ignore", divide="ignore"):
            c_in = np.where(n_in > 0, s_in / np.maximum(n_in, 1e-12), np.nan)
            c_out = np.where(n_out > 0, (s_all - s_in) / np.maximum(n_out, 1e-12), np.nan)
        if not with_delta:
            return c_in, c_out, None, None, n_in, n_out
        return c_in, c_out, sums_dyn[:, 2], sums_dyn[:, 3], n_in, n_out


def normalise(force: np.ndarray, scale: float) -> np.ndarray:
    """``F / scale`` clipped to [-1, 1], NaN (no pixel on one side) as 0.

    Lankton & Tannenbaum divide the region force by its maximum at every
    iteration; that rescales noise to full speed once the contour sits in a
    flat region, and the contour frays. A scale fixed from the image (the
    square of an intensity spread) keeps flat regions slow and edges fast.
    """
    f = np.nan_to_num(force, nan=0.0) / scale
    return np.clip(f, -1.0, 1.0)


def intensity_scale(image: np.ndarray, inside: np.ndarray) -> float:
    """A robust intensity spread of the image (its standard deviation), at least 1e-3."""
    return max(float(np.std(image)), 1e-3)


@dataclass
class SegmentationResult:
    """The outcome of one segmentation.

    Attributes
    ----------
    mask
        Boolean ``(H, W)``, True inside the target.
    contour
        The boundary of the largest region, px and mm (:class:`~hifumotion.contour.Contour`);
        None when the mask is empty.
    phi
        The final level-set function (positive inside, signed distance near the contour, px).
    method
        Name of the model.
    iterations
        Iterations run (summed over scales for multi-scale models).
    converged
        Whether the convergence test stopped the run before the cap.
    seconds
        Wall time of the segmentation.
    params
        The parameters used, with the scale-derived ones resolved.
    """

    mask: np.ndarray
    contour: Contour | None
    phi: np.ndarray
    method: str
    iterations: int
    converged: bool
    seconds: float
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def spacing_mm(self) -> tuple[float, float]:
        return self.contour.spacing_mm if self.contour is not None else (1.0, 1.0)


def make_result(phi: np.ndarray, evo: Evolution | None, method: str, t0: float, spacing, params: dict,
                iterations: int | None = None, converged: bool | None = None) -> SegmentationResult:
    mask = phi > 0
    contour = Contour.from_mask(mask, as_spacing_mm(spacing)) if mask.any() else None
    return SegmentationResult(
        mask=mask,
        contour=contour,
        phi=phi,
        method=method,
        iterations=int(iterations if iterations is not None else (evo.iterations if evo else 0)),
        converged=bool(converged if converged is not None else (evo.converged if evo else False)),
        seconds=time.perf_counter() - t0,
        params=params,
    )


#: Run models that offer it (LCV, GLCV) in one compiled loop instead of a Python loop calling
#: the speed each iteration; the same arithmetic, without the per-iteration call overhead.
COMPILED_LOOP = True

SpeedBuilder = Callable[[np.ndarray, np.ndarray, int], tuple[Callable, float]]


def refine_iterations(ratio: float) -> int:
    """Iteration cap of a finer level: the coarse contour is within about one coarse pixel."""
    return int(np.ceil(3.0 * ratio / CFL)) + 20


def run_narrow_band(image: Any, init: Any, method: str, build: SpeedBuilder, params: dict, *,
                    spacing=None, multiscale: bool = True, max_iterations: int | None = None) -> SegmentationResult:
    """Run a narrow-band model coarse to fine and package the result.

    ``build(image_level, phi_level, factor)`` returns ``(speed, curvature_weight)``
    for one pyramid level (optionally a third element: a compiled
    ``run(phi, max_iterations) -> Evolution`` doing the same evolution), where ``factor`` is the level's pixel size in
    original pixels (scale-dependent parameters are divided by it). The
    coarsest level runs from the initial contour to convergence; each finer
    level refines the previous result with a short run. With
    ``multiscale=False`` the model runs at full resolution only.
    """
    t0 = time.perf_counter()
    img = prepare_image(image)
    phi0 = initial_phi(init, img.shape)
    r0 = equivalent_radius_px(phi0)
    factors = pyramid_factors(r0, img.shape, multiscale)
    phi, previous, total, evo = None, None, 0, None
    for f in factors:
        level_image = downsample(img, f)
        if phi is None:
            level_phi = resample_phi(phi0, 1.0 / f, level_image.shape) if f > 1 else phi0
            cap = max_iterations or default_iterations(r0 / f)
        else:
            level_phi = resample_phi(phi, previous / f, level_image.shape)
            cap = refine_iterations(previous / f)
        built = build(level_image, level_phi, f)
        speed, mu = built[0], built[1]
        fast = built[2] if len(built) > 2 and COMPILED_LOOP else None
        evo = fast(level_phi, cap) if fast is not None else evolve(level_phi, speed, cap, curvature_weight=mu)
        phi, previous, total = evo.phi, f, total + evo.iterations
    params = dict(params, pyramid_factors=factors)
    return make_result(phi, evo, method, t0, spacing, params, iterations=total)
