"""GAC: the geodesic active contour (Caselles, Kimmel & Sapiro 1997).

The contour of least geodesic length ``∮ g ds`` in the metric of an edge function g.
Two solvers:

- ``solver="global"`` (default): the exact minimum over the closed curves that
  surround the start, by a shortest path in polar coordinates
  (:mod:`._minimal_path`; Appleton & Talbot 2005), with ITK's sigmoid edge function
  of the radial derivative. No balloon and no stopping rule.
- ``solver="descent"``: the level-set flow
  ``φ_t = g |∇φ| (div(∇φ/|∇φ|) + α) + ∇g·∇φ`` with ``g = 1 / (1 + |∇(G_σ * I)|²)``
  (the spec's form; the gradient in units of the image's 90th-percentile gradient, see
  :func:`hifumotion.segmentation._common.edge_indicator`), a local minimum from the start;
  tracking uses it, since a frame's start (the previous contour) need not lie inside the target.

``docs/decisions.md`` has what each scored on the shared real images.

References
----------
.. [1] Caselles V, Kimmel R, Sapiro G. Geodesic active contours. IJCV 1997; 22(1): 61-79.
.. [2] Appleton B, Talbot H. Globally optimal geodesic active contours. J Math Imaging Vis 2005; 23: 67-86.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hifumotion.contour import Contour
from hifumotion.errors import InputError
from hifumotion.segmentation import _kernels as K
from hifumotion.segmentation._common import (
    SegmentationResult,
    edge_indicator,
    equivalent_radius_px,
    make_result,
    prepare_image,
    run_narrow_band,
)
from hifumotion.segmentation._minimal_path import minimal_geodesic_contour
from hifumotion.segmentation.levelset import initial_phi, phi_from_mask

SOLVERS = ("global", "descent")

#: σ of the edge function's Gaussian as a fraction of the initial equivalent radius.
SIGMA_FRACTION = 1.0 / 25.0
#: Balloon constant α (> 0 grows the contour).
ALPHA = 1.0


def gac_sigma(radius_px: float) -> float:
    """Default σ (px): the initial equivalent radius / 25, at least 1 px."""
    return float(max(1.0, SIGMA_FRACTION * radius_px))


def gac(image: Any, init: Any, *, solver: str = "global", alpha: float = ALPHA, sigma: float | None = None,
        multiscale: bool = True, max_iterations: int | None = None, spacing=None) -> SegmentationResult:
    """Segment with the geodesic active contour.

    Parameters
    ----------
    solver
        ``"global"`` (the least-length closed curve around the start, exactly) or
        ``"descent"`` (the level-set flow from the start; see the module).
    alpha
        Balloon constant α of the descent; positive grows the contour (the initial contour
        is inside the target). The global solver has no balloon.
    sigma
        σ (px) of the Gaussian smoothing in g; default the initial equivalent radius / 25.
    multiscale, max_iterations, spacing
        As :func:`hifumotion.segmentation.lcv.lcv` (descent only).
    """
    if solver not in SOLVERS:
        raise InputError(f"solver must be one of {SOLVERS}, got {solver!r}", "solver")
    if solver == "global":
        return _global(image, init, sigma, spacing)
    params: dict[str, Any] = {"alpha": alpha, "solver": solver}

    def build(img, phi, factor):
        s = params.setdefault("sigma_px", sigma or gac_sigma(equivalent_radius_px(phi) * factor))
        g, gx, gy = edge_indicator(img, max(s / factor, 0.5))

        def speed(p, band, box):
            return K.geodesic_terms(p, band, g, gx, gy, np.full(band.shape[0], alpha))

        return speed, 0.0

    return run_narrow_band(image, init, "gac", build, params, spacing=spacing, multiscale=multiscale,
                           max_iterations=max_iterations)


def _global(image: Any, init: Any, sigma: float | None, spacing) -> SegmentationResult:
    t0 = time.perf_counter()
    img = prepare_image(image)
    start = initial_phi(init, img.shape) > 0
    s = sigma or gac_sigma(equivalent_radius_px(start.astype(np.float32)))
    points, length = minimal_geodesic_contour(img, start, s)
    mask = Contour(points).to_mask(img.shape) | start
    params = {"solver": "global", "sigma_px": s, "geodesic_length_px": length}
    return make_result(phi_from_mask(mask), None, "gac", t0, spacing, params, iterations=1, converged=True)
