"""CV: the Chan-Vese model, active contours without edges (Chan & Vese 2001).

``φ_t = δ(φ) [μ div(∇φ/|∇φ|) − ν − λ1 (I − c1)² + λ2 (I − c2)²]`` with the
global means ``c1`` inside and ``c2`` outside (φ positive inside), evolved in a
narrow band around the contour.

References
----------
.. [1] Chan TF, Vese LA. Active contours without edges. IEEE TIP 2001; 10(2): 266-277.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hifumotion.segmentation._common import SegmentationResult, intensity_scale, normalise, run_narrow_band
from hifumotion.segmentation.lcv import MU


def cv(image: Any, init: Any, *, mu: float = MU, nu: float = 0.0, lambda1: float = 1.0, lambda2: float = 1.0,
       multiscale: bool = True, max_iterations: int | None = None, spacing=None) -> SegmentationResult:
    """Segment with the global Chan-Vese model (means over the whole inside and outside).

    ``mu`` weighs the length term (relative to the region force in units of the
    image's intensity variance), ``nu`` the area term, ``lambda1``/``lambda2`` the
    inside/outside fitting terms.
    """
    params: dict[str, Any] = {"mu": mu, "nu": nu, "lambda1": lambda1, "lambda2": lambda2}

    def build(img, phi, factor):
        total, count = float(img.sum()), img.size
        scale = params.setdefault("intensity_scale", intensity_scale(img, phi > 0))

        def speed(p, band, box):
            inside = p > 0
            n_in = int(np.count_nonzero(inside))
            s_in = float(img[inside].sum())
            c1 = s_in / max(n_in, 1)
            c2 = (total - s_in) / max(count - n_in, 1)
            v = img[band[:, 0], band[:, 1]]
            return normalise(-lambda1 * (v - c1) ** 2 + lambda2 * (v - c2) ** 2 - nu, scale * scale)

        return speed, mu

    return run_narrow_band(image, init, "cv", build, params, spacing=spacing, multiscale=multiscale,
                           max_iterations=max_iterations)
