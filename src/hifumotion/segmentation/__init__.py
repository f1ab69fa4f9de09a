"""Level-set segmentation of the target in B-mode images: the paper's GLCV and the five it is compared with.

One function per model, sharing one level-set core (:mod:`.levelset`):

=========  =====================================================  =================
method     model                                                  reference
=========  =====================================================  =================
``gac``    geodesic active contour                                Caselles 1997
``cv``     Chan-Vese, global region means                         Chan & Vese 2001
``lcv``    localized Chan-Vese (Eq. 1–5)                          Lankton 2008
``rsf``    region-scalable fitting                                Li et al. 2008
``mslcv``  multi-scale, shape-constrained LCV                     Liao et al. 2014
``glcv``   geodesic localized Chan-Vese (Eq. 6–7), the paper's    Liao et al.
=========  =====================================================  =================

:func:`segment` runs any of them from any kind of initial contour;
:func:`track` follows a target through a cine loop, each frame starting from
the previous frame's contour. φ is positive inside the contour.

Scale-dependent parameters (local radius, σ, iteration caps) are derived from
the initial contour's size, so one default parameter set serves every image.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from hifumotion.contour import Contour, parse_init_entry
from hifumotion.errors import InputError
from hifumotion.segmentation._common import SegmentationResult
from hifumotion.segmentation.cv import cv
from hifumotion.segmentation.gac import gac
from hifumotion.segmentation.glcv import glcv
from hifumotion.segmentation.lcv import lcv
from hifumotion.segmentation.mslcv import mslcv
from hifumotion.segmentation.rsf import rsf

#: The models by name, in the order of the paper's Table 2.
METHODS: dict[str, Callable[..., SegmentationResult]] = {
    "gac": gac,
    "cv": cv,
    "lcv": lcv,
    "rsf": rsf,
    "mslcv": mslcv,
    "glcv": glcv,
}


#: What makes a model that solves around its start refine a contour instead: a frame's or a
#: plane's start is the previous contour, which lies on the boundary, not inside the target.
_LOCAL = {"gac": {"solver": "descent"}, "glcv": {"carry": "balloon"}}


def local_params(method: str) -> dict[str, Any]:
    """The parameters with which ``method`` refines a start lying on the boundary (tracking,
    the next sweep plane, a carried contour) instead of carrying a start from inside."""
    return dict(_LOCAL.get(method.lower(), {}))


def _resolve_init(init: Any, init_kind: str | None) -> Any:
    if isinstance(init, SegmentationResult):
        return init.mask
    if isinstance(init, Mapping):
        return parse_init_entry(init, init_kind)
    return init


def segment(image: Any, init: Any, method: str = "glcv", spacing=None, *, init_kind: str | None = None,
            **params: Any) -> SegmentationResult:
    """Segment the target in one image.

    Parameters
    ----------
    image
        2D array of any dtype (scaled to [0, 1] internally), or an
        :class:`~hifumotion.sequence.ImageSequence` of one frame.
    init
        The initial contour: an :class:`~hifumotion.contour.Ellipse`,
        :class:`~hifumotion.contour.ClickedPoints` or an ``(N, 2)`` array of
        clicked ``(x, y)`` points (a closed smooth curve through them), a
        :class:`~hifumotion.contour.Contour`, a mask, a previous
        :class:`SegmentationResult`, or an ``init.json`` entry as is (a dict
        with ``"ellipse"`` and/or ``"points"``).
    method
        One of :data:`METHODS`: ``gac``, ``cv``, ``lcv``, ``rsf``, ``mslcv``, ``glcv``.
    spacing
        Pixel size in mm (scalar or ``(row, col)``) for the contour in mm; an
        ImageSequence's own spacing is used when not given.
    init_kind
        With a dict holding both, ``"ellipse"`` (default) or ``"points"``.
    **params
        The model's own parameters (see each model's function).

    Returns
    -------
    SegmentationResult
        ``mask``, ``contour`` (px and mm), ``iterations``, ``converged``, ``seconds``, ``params``.
    """
    from hifumotion.sequence import ImageSequence

    if isinstance(image, ImageSequence):
        if image.n_frames != 1:
            raise InputError(f"segment takes one image; this sequence has {image.n_frames} frames (use track)", "image")
        spacing = spacing if spacing is not None else image.spacing_mm
        image = image.frames[0]
    name = method.lower()
    if name not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}", "method")
    return METHODS[name](image, _resolve_init(init, init_kind), spacing=spacing, **params)


@dataclass
class TrackResult:
    """Segmentations of every frame of a sequence, in order."""

    results: list[SegmentationResult]

    @property
    def masks(self) -> np.ndarray:
        """Boolean ``(T, H, W)``."""
        return np.stack([r.mask for r in self.results])

    @property
    def contours(self) -> list[Contour | None]:
        return [r.contour for r in self.results]

    @property
    def seconds(self) -> float:
        return float(sum(r.seconds for r in self.results))


#: Iteration cap of every frame after the first: the start is already moved by the target's
#: translation (``predict_motion``), and 10 iterations follow about 2.5 px of deformation a frame
#: (0.25 px per iteration at μ = 1). On the tracking benchmark's cines 10 iterations come within
#: 0.001 DSC of 20 (``docs/decisions.md``).
TRACK_ITERATIONS = 10


def estimate_shift(previous: np.ndarray, current: np.ndarray, mask: np.ndarray, margin: int = 16) -> np.ndarray:
    """The target's translation ``(drow, dcol)`` in px from ``previous`` to ``current``.

    The peak of the cross-correlation (whole pixels: the level set refines the
    rest) of a window around the target's mask grown by ``margin`` px,
    Hann-tapered, so the target's own speckle, not the background's, sets the shift.
    Computed with real FFTs: the same peak as scikit-image's
    ``phase_cross_correlation(..., normalization=None)`` at half its cost.
    """
    from scipy import fft

    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return np.zeros(2)
    h, w = mask.shape
    r0, r1 = max(rows[0] - margin, 0), min(rows[-1] + 1 + margin, h)
    c0, c1 = max(cols[0] - margin, 0), min(cols[-1] + 1 + margin, w)
    taper = np.outer(np.hanning(r1 - r0), np.hanning(c1 - c0))
    a = previous[r0:r1, c0:c1]
    b = current[r0:r1, c0:c1]
    a = (a - a.mean()) * taper
    b = (b - b.mean()) * taper
    # zero-padded to a size the FFT does fast: the taper already takes both windows to zero at
    # their edges, so the padding adds no edge of its own
    size = tuple(fft.next_fast_len(n, real=True) for n in a.shape)
    product = fft.rfft2(b, s=size) * np.conj(fft.rfft2(a, s=size))
    peak = np.unravel_index(int(np.argmax(fft.irfft2(product, s=size))), size)
    shift = np.array([p - n if p > n // 2 else p for p, n in zip(peak, size)], float)
    limit = 0.25 * min(r1 - r0, c1 - c0)  # beyond this the correlation peak is not the target
    return np.asarray(shift, float) if np.all(np.abs(shift) <= limit) else np.zeros(2)


def _shift_mask(mask: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``mask`` translated by a whole-pixel ``(drow, dcol)``; what leaves the image is lost."""
    dr, dc = (int(round(v)) for v in shift)
    if dr == 0 and dc == 0:
        return mask
    h, w = mask.shape
    moved = np.zeros_like(mask)
    moved[max(dr, 0) : h + min(dr, 0), max(dc, 0) : w + min(dc, 0)] = mask[max(-dr, 0) : h + min(-dr, 0),
                                                                            max(-dc, 0) : w + min(-dc, 0)]
    return moved if moved.any() else mask


def _segment_window(image: np.ndarray, start: np.ndarray, method: str, spacing, margin: int,
                    params: dict) -> SegmentationResult:
    """Segment only the window around ``start`` (grown by ``margin`` px) and place the result
    back on the full grid: a frame of a cine loop costs what its target's neighbourhood costs."""
    from dataclasses import replace

    from hifumotion.segmentation.levelset import BAND

    rows, cols = np.nonzero(start)
    h, w = start.shape
    r0, r1 = max(int(rows.min()) - margin, 0), min(int(rows.max()) + 1 + margin, h)
    c0, c1 = max(int(cols.min()) - margin, 0), min(int(cols.max()) + 1 + margin, w)
    part = segment(image[r0:r1, c0:c1], start[r0:r1, c0:c1], method, spacing, **params)
    mask = np.zeros((h, w), bool)
    mask[r0:r1, c0:c1] = part.mask
    phi = np.full((h, w), -(BAND + 1.0), np.float32)
    phi[r0:r1, c0:c1] = part.phi
    contour = part.contour
    if contour is not None:
        contour = Contour(contour.points_px + np.array([c0, r0]), contour.spacing_mm)
    return replace(part, mask=mask, phi=phi, contour=contour)


def track(sequence: Any, init: Any, method: str = "glcv", *, init_kind: str | None = None, spacing=None,
          predict_motion: bool = True, progress: bool = False, exclude: np.ndarray | None = None,
          **params: Any) -> TrackResult:
    """Segment every frame of a cine loop, each starting from the previous frame's contour.

    The first frame starts from ``init``. Later frames start from the previous
    mask, at full resolution (the contour is already close), keep the first
    frame's scale parameters, and run at most :data:`TRACK_ITERATIONS`
    iterations on a window around the target, so tracking costs a few
    milliseconds per frame. With
    ``predict_motion`` each frame starts from the previous mask moved by the
    target's translation between the frames (:func:`estimate_shift`), so the
    level set only has to follow the deformation.

    Parameters
    ----------
    sequence
        An :class:`~hifumotion.sequence.ImageSequence` or a ``(T, H, W)`` array.
    init, method, init_kind, params
        As :func:`segment`.
    predict_motion
        Move the previous contour by the phase-correlation shift before refining it.
    progress
        Show a progress bar.
    exclude
        Pixels known not to be the target, ``(H, W)`` for every frame or ``(T, H, W)``
        (a pool's floor, where an instrument is): removed from each frame's result
        before the next frame starts from it.
    """
    from hifumotion.console import track as progress_bar
    from hifumotion.sequence import ImageSequence

    if isinstance(sequence, ImageSequence):
        frames = sequence.frames
        spacing = spacing if spacing is not None else sequence.spacing_mm
    else:
        frames = np.asarray(sequence)
        if frames.ndim == 2:
            frames = frames[None]
        if frames.ndim != 3:
            raise InputError(f"expected frames (T, H, W), got shape {frames.shape}", "sequence")
    results: list[SegmentationResult] = []
    start = _resolve_init(init, init_kind)
    indices = range(frames.shape[0])
    carried: dict[str, Any] = {}
    for t in (progress_bar(indices, f"tracking ({method})", total=len(indices)) if progress else indices):
        extra = dict(params)
        if t > 0 and method.lower() in ("gac", "cv", "lcv", "glcv"):
            for key, value in local_params(method).items():
                extra.setdefault(key, value)
            extra.setdefault("multiscale", False)
            extra.setdefault("max_iterations", TRACK_ITERATIONS)
            extra.update({k: v for k, v in carried.items() if k not in params})
        if t > 0 and predict_motion:
            start = _shift_mask(start, estimate_shift(frames[t - 1], frames[t], start))
        if t > 0 and "radius" in carried:
            result = _segment_window(frames[t], start, method, spacing, int(carried["radius"]) + 12, extra)
        else:
            result = segment(frames[t], start, method, spacing, **extra)
        if exclude is not None:
            from dataclasses import replace

            ex = exclude[t] if exclude.ndim == 3 else exclude
            kept = result.mask & ~ex
            if kept.any() and not np.array_equal(kept, result.mask):
                result = replace(result, mask=kept, contour=Contour.from_mask(kept, result.contour.spacing_mm
                                                                            if result.contour is not None else None))
        results.append(result)
        if t == 0:
            # keep the scale of the first frame: a previous contour is no rough inside start
            names = {"radius_px": "radius", "sigma_px": "sigma", "kappa1": "kappa1", "force_scale": "force_unit"}
            carried = {arg: result.params[key] for key, arg in names.items() if key in result.params}
        if not result.mask.any():
            raise InputError(f"the contour vanished at frame {t}; check the initial contour or the method", "track")
        start = result.mask
    return TrackResult(results)


__all__ = ["METHODS", "SegmentationResult", "TrackResult", "segment", "track", "local_params", "gac", "cv", "lcv", "rsf", "mslcv", "glcv"]
