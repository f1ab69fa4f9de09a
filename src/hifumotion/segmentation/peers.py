"""Peer implementations measured beside ours: scikit-image and SimpleITK level sets.

Each runs from the same initial mask as our models and returns a boolean mask.
They are benchmarks' yardsticks, not part of the pipeline. Sign conventions
are handled here: SimpleITK's Chan-Vese wants φ positive inside and an image
on a 0–255 scale; its geodesic active contour evolves a level set that is
negative inside and grows against positive propagation scaling.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from hifumotion.segmentation.levelset import initial_phi


def _iterations(mask: np.ndarray) -> int:
    radius = np.sqrt(max(mask.sum(), 1) / np.pi)
    return int(max(100, 3 * radius))


def skimage_morph_gac(image: np.ndarray, init_mask: np.ndarray) -> np.ndarray:
    """scikit-image ``morphological_geodesic_active_contour`` on the inverse Gaussian gradient, balloon +1."""
    from skimage.segmentation import inverse_gaussian_gradient, morphological_geodesic_active_contour

    gimage = inverse_gaussian_gradient(image)
    out = morphological_geodesic_active_contour(gimage, _iterations(init_mask), init_level_set=init_mask,
                                                smoothing=1, threshold="auto", balloon=1)
    return out.astype(bool)


def skimage_morph_cv(image: np.ndarray, init_mask: np.ndarray) -> np.ndarray:
    """scikit-image ``morphological_chan_vese`` (smoothing 1, λ1 = λ2 = 1)."""
    from skimage.segmentation import morphological_chan_vese

    return morphological_chan_vese(image, _iterations(init_mask), init_level_set=init_mask, smoothing=1).astype(bool)


def skimage_chan_vese(image: np.ndarray, init_mask: np.ndarray) -> np.ndarray:
    """scikit-image ``chan_vese`` (the dense, global model), started from the initial contour's signed distance."""
    from skimage.segmentation import chan_vese

    phi0 = initial_phi(init_mask, image.shape).astype(float)
    out = chan_vese(image, mu=0.25, lambda1=1, lambda2=1, tol=1e-3, max_num_iter=200, dt=0.5,
                    init_level_set=phi0)
    # chan_vese labels the region of its own φ > 0 as True; with our φ (positive inside) that is the inside
    return np.asarray(out, bool)


def _sitk():
    """SimpleITK on one thread: a peer is timed on one core, and ITK's thread pool spins without
    end in a process forked from one that already used it (the benchmark's worker pool hung)."""
    import SimpleITK as sitk

    sitk.ProcessObject.SetGlobalDefaultNumberOfThreads(1)
    return sitk


def sitk_geodesic_active_contour(image: np.ndarray, init_mask: np.ndarray) -> np.ndarray:
    """SimpleITK ``GeodesicActiveContourLevelSetImageFilter`` on a sigmoid of the gradient magnitude.

    It does not converge on speckle: its result is where the iteration cap (3 × the start's
    radius) stops it (``docs/decisions.md``)."""
    sitk = _sitk()

    img = sitk.GetImageFromArray(image.astype(np.float32))
    grad = sitk.GradientMagnitudeRecursiveGaussian(img, sigma=max(1.0, np.sqrt(init_mask.sum() / np.pi) / 25))
    g_arr = sitk.GetArrayFromImage(grad)
    k = float(np.percentile(g_arr, 90)) or 1.0
    speed = sitk.Sigmoid(grad, alpha=-k / 4, beta=k / 2, outputMaximum=1.0, outputMinimum=0.0)
    phi0 = -initial_phi(init_mask, image.shape)  # ITK: negative inside
    f = sitk.GeodesicActiveContourLevelSetImageFilter()
    f.SetPropagationScaling(1.0)
    f.SetCurvatureScaling(1.0)
    f.SetAdvectionScaling(1.0)
    f.SetMaximumRMSError(0.005)
    f.SetNumberOfIterations(_iterations(init_mask))
    out = f.Execute(sitk.GetImageFromArray(phi0.astype(np.float32)), sitk.Cast(speed, sitk.sitkFloat32))
    return sitk.GetArrayFromImage(out) < 0


def sitk_chan_vese(image: np.ndarray, init_mask: np.ndarray) -> np.ndarray:
    """SimpleITK ``ScalarChanAndVeseDenseLevelSetImageFilter`` (φ positive inside, image on 0–255)."""
    sitk = _sitk()

    phi0 = initial_phi(init_mask, image.shape)  # positive inside, as this filter wants
    f = sitk.ScalarChanAndVeseDenseLevelSetImageFilter()
    f.SetMaximumRMSError(0.0)
    f.SetNumberOfIterations(min(_iterations(init_mask), 200))
    f.SetLambda1(1.0)
    f.SetLambda2(1.0)
    f.SetCurvatureWeight(1.0)
    f.SetAreaWeight(0.0)
    f.SetReinitializationSmoothingWeight(0.0)
    f.SetUseImageSpacing(False)
    out = f.Execute(sitk.GetImageFromArray(phi0.astype(np.float32)),
                    sitk.GetImageFromArray((image * 255.0).astype(np.float32)))
    return sitk.GetArrayFromImage(out) > 0


#: Peers by name.
PEERS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "skimage_chan_vese": skimage_chan_vese,
    "skimage_morph_cv": skimage_morph_cv,
    "skimage_morph_gac": skimage_morph_gac,
    "sitk_gac": sitk_geodesic_active_contour,
    "sitk_chan_vese": sitk_chan_vese,
}
