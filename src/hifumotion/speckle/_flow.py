"""Dense optical flow between two B-mode frames: the estimators the tracker can use.

Every estimator answers the same question: for each pixel ``x`` of ``reference``, the
shift ``f(x)`` (px, ``(dx, dy)`` = (column, row)) with ``moving(x + f(x)) ≈ reference(x)``.
Frames are float32 in [0, 1] or uint8 (0–255).

=============  ======================================================  ===========================
name           estimator                                               library
=============  ======================================================  ===========================
``dis``        Dense Inverse Search: inverse-compositional patch       OpenCV (Kroeger et al. 2016)
               matching on a pyramid + variational refinement
``farneback``  polynomial expansion, pyramidal                         OpenCV (Farnebäck 2003)
``ilk``        iterative Lucas–Kanade, dense                           scikit-image
``tvl1``       TV-L1 variational flow                                  scikit-image (Zach et al. 2007)
=============  ======================================================  ===========================

``farneback`` is the default, chosen by measurement (``benchmarks/bench_observation.py``;
docs/decisions.md, "Seeing the motion: speckle tracking").
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from hifumotion.errors import InputError

#: ``flow(reference, moving, initial) -> (H, W, 2)``; a flow that averages over a window carries
#: its half-width as ``support_px`` (px): within it of the image's edge the window is cut short.
Flow = Callable[[np.ndarray, np.ndarray, np.ndarray | None], np.ndarray]


def _u8(image: np.ndarray) -> np.ndarray:
    """A frame in [0, 1] as uint8 (what OpenCV's flows take); a uint8 frame as it is."""
    if image.dtype == np.uint8:
        return image
    return np.clip(np.rint(np.asarray(image, np.float32) * 255.0), 0, 255).astype(np.uint8)


def _unit(image: np.ndarray) -> np.ndarray:
    """A frame as float32 in [0, 1] (uint8 frames divided by 255)."""
    return image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else np.asarray(image, np.float32)


def dis_flow(patch_px: int = 8, stride_px: int = 3) -> Flow:
    """OpenCV's DIS flow (Kroeger et al. 2016), with the given patch size and stride.

    Patch 8 px / stride 3 px is OpenCV's "medium" preset, whose patches span a few
    speckle cells at the project's pixel sizes; the variational refinement runs on the
    finest level, so the flow is dense and sub-pixel.
    """
    import cv2

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    dis.setPatchSize(int(patch_px))
    dis.setPatchStride(int(stride_px))
    dis.setUseMeanNormalization(True)   # a grey-level change between frames is not motion
    dis.setUseSpatialPropagation(True)

    def flow(reference: np.ndarray, moving: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        if initial is not None:
            return dis.calc(_u8(reference), _u8(moving), np.ascontiguousarray(initial, np.float32))
        return dis.calc(_u8(reference), _u8(moving), None)

    flow.support_px = int(patch_px)
    return flow


def farneback_flow(levels: int = 0, window_px: int = 15, iterations: int = 1) -> Flow:
    """OpenCV's Farnebäck flow (polynomial expansion; ``levels`` extra pyramid levels).

    The tracker always starts it from the previous frame's estimate, within a pixel or two
    of the answer, so by default it runs on the full-resolution images only: coarser
    levels of a speckle image are mostly noise, and starting there made the field worse
    (docs/decisions.md, "Seeing the motion: speckle tracking").
    """
    import cv2

    def flow(reference: np.ndarray, moving: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        flags = 0
        out = None
        if initial is not None:
            out = np.ascontiguousarray(initial, np.float32).copy()
            flags = cv2.OPTFLOW_USE_INITIAL_FLOW
        return cv2.calcOpticalFlowFarneback(_u8(reference), _u8(moving), out, 0.5, levels, window_px, iterations,
                                            5, 1.1, flags)

    flow.support_px = int(window_px) // 2 * 2 ** int(levels)
    return flow


def ilk_flow(radius_px: int = 7) -> Flow:
    """scikit-image's dense iterative Lucas–Kanade (``optical_flow_ilk``)."""
    from skimage.registration import optical_flow_ilk

    def flow(reference: np.ndarray, moving: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        v, u = optical_flow_ilk(_unit(reference), _unit(moving), radius=radius_px,
                                num_warp=5, prefilter=True)
        return np.dstack([u, v]).astype(np.float32)

    flow.support_px = int(radius_px)
    return flow


def tvl1_flow(attachment: float = 15.0) -> Flow:
    """scikit-image's TV-L1 flow (``optical_flow_tvl1``)."""
    from skimage.registration import optical_flow_tvl1

    def flow(reference: np.ndarray, moving: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
        v, u = optical_flow_tvl1(_unit(reference), _unit(moving),
                                 attachment=attachment, num_warp=5)
        return np.dstack([u, v]).astype(np.float32)

    return flow


#: The estimators by name.
ESTIMATORS: dict[str, Callable[[], Flow]] = {
    "dis": dis_flow,
    "farneback": farneback_flow,
    "ilk": ilk_flow,
    "tvl1": tvl1_flow,
}


def estimator(name: str) -> Flow:
    """The flow function called ``name`` (one of :data:`ESTIMATORS`)."""
    key = name.lower()
    if key not in ESTIMATORS:
        raise InputError(f"unknown displacement estimator {name!r}; expected one of {', '.join(ESTIMATORS)}",
                         "estimator")
    return ESTIMATORS[key]()
