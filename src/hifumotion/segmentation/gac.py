"""GAC: the geodesic active contour (Caselles, Kimmel & Sapiro 1997).

``φ_t = g |∇φ| (div(∇φ/|∇φ|) + α) + ∇g·∇φ`` with the edge function
``g = 1 / (1 + |∇(G_σ * I)|²)`` (the spec's form; the gradient is measured in
units of the image's 90th-percentile gradient, see
:func:`hifumotion.segmentation._common.edge_indicator`).

References
----------
.. [1] Caselles V, Kimmel R, Sapiro G. Geodesic active contours. IJCV 1997; 22(1): 61-79.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hifumotion.segmentation import _kernels as K
from hifumotion.segmentation._common import SegmentationResult, edge_indicator, equivalent_radius_px, run_narrow_band

#: σ of the edge function's Gaussian as a fraction of the initial equivalent radius.
SIGMA_FRACTION = 1.0 / 25.0
#: Balloon constant α (> 0 grows the contour).
ALPHA = 1.0


def gac_sigma(radius_px: float) -> float:
    """Default σ (px): the initial equivalent radius / 25, at least 1 px."""
    return float(max(1.0, SIGMA_FRACTION * radius_px))


def gac(image: Any, init: Any, *, alpha: float = ALPHA, sigma: float | None = None, multiscale: bool = True,
        max_iterations: int | None = None, spacing=None) -> SegmentationResult:
    """Segment with the geodesic active contour.

    Parameters
    ----------
    alpha
        Balloon constant α; positive grows the contour (the initial contour is inside the target).
    sigma
        σ (px) of the Gaussian smoothing in g; default the initial equivalent radius / 25.
    multiscale, max_iterations, spacing
        As :func:`hifumotion.segmentation.lcv.lcv`.
    """
    params: dict[str, Any] = {"alpha": alpha}

    def build(img, phi, factor):
        s = params.setdefault("sigma_px", sigma or gac_sigma(equivalent_radius_px(phi) * factor))
        g, gx, gy = edge_indicator(img, max(s / factor, 0.5))

        def speed(p, band, box):
            return K.geodesic_terms(p, band, g, gx, gy, np.full(band.shape[0], alpha))

        return speed, 0.0

    return run_narrow_band(image, init, "gac", build, params, spacing=spacing, multiscale=multiscale,
                           max_iterations=max_iterations)
