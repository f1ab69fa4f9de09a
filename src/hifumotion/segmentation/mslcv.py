"""MSLCV: multi-scale, shape-constrained localized Chan-Vese (Liao et al. 2014).

The spec only summarises this model ("multi-scale segmentation", a "shape
constraint" and an "adaptive localizing radius"); its reference describes it
in words. We re-derive it as:

* **multi-scale**: LCV runs on a Gaussian-free block-average pyramid, coarse
  to fine; the coarse levels decide the shape, the finer ones refine it for
  a few iterations (so, as the spec says, the result largely depends on the
  coarse scale);
* **shape constraint**: the contour is drawn towards the ellipse with the
  same second moments as the current region (uterine fibroids, like the
  reference's targets, are near-elliptical): ``ω (φ_E − φ)`` is added to the
  LCV speed, with φ_E the signed distance to that ellipse, refitted every
  :data:`REFIT_EVERY` iterations. It stops leaks through weak boundaries and
  excessive contraction, the two failures the reference names;
* **adaptive radius**: the localizing radius follows the current contour's
  size, ``r = RADIUS_FRACTION × its equivalent radius`` (updated with the fit).

See ``docs/decisions.md`` for why.

References
----------
.. [1] Liao X, Yuan Z, Zheng Q, Yin Q, Zhang D, Zhao J. Multi-scale and shape
   constrained localized region-based active contour segmentation of uterine
   fibroid ultrasound images in HIFU therapy. PLoS ONE 2014; 9(7): e103334.
.. [2] Lankton S, Tannenbaum A. Localizing region-based active contours. IEEE TIP 2008.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hifumotion.segmentation._common import (
    SegmentationResult,
    equivalent_radius_px,
    run_narrow_band,
)
from hifumotion.segmentation.lcv import MU, local_radius, region_force

#: Weight ω of the shape term (per unit time).
OMEGA = 0.1
#: Iterations between refits of the ellipse and of the adaptive radius.
REFIT_EVERY = 5


def moment_ellipse(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ellipse with the region's area centroid and second moments.

    Returns the centre ``(row, col)``, the unit axis directions (2 × 2, as
    columns, in (row, col)) and the semi-axes (px): ``2 √λ`` for each
    eigenvalue λ of the covariance, which is exact for a filled ellipse.
    """
    rows, cols = np.nonzero(mask)
    centre = np.array([rows.mean(), cols.mean()])
    cov = np.cov(np.vstack([rows - centre[0], cols - centre[1]])) if rows.size > 2 else np.eye(2)
    evals, evecs = np.linalg.eigh(cov)
    return centre, evecs, 2.0 * np.sqrt(np.maximum(evals, 0.25))


def ellipse_distance(band: np.ndarray, centre, axes, semi) -> np.ndarray:
    """Approximate signed distance (positive inside) of band points to an ellipse.

    Along the ray from the centre: ``ρ_E(θ) − |p − c|`` with ``ρ_E(θ)`` the
    ellipse's radius in the point's direction; exact on circles, and within
    a fraction of a pixel near the boundary of moderately elongated ellipses.
    """
    d = band.astype(float) - centre
    u, v = d @ axes[:, 0], d @ axes[:, 1]
    rho = np.hypot(u, v)
    with np.errstate(invalid="ignore", divide="ignore"):
        radius = 1.0 / np.sqrt((u / (rho * semi[0])) ** 2 + (v / (rho * semi[1])) ** 2)
    radius = np.where(rho > 0, radius, semi.min())
    return radius - rho


def mslcv(image: Any, init: Any, *, mu: float = MU, omega: float = OMEGA, max_iterations: int | None = None,
          spacing=None) -> SegmentationResult:
    """Segment with MSLCV: multi-scale LCV with an elliptical shape constraint and adaptive radius.

    ``omega`` weighs the shape term; ``mu`` the curvature term (as LCV).
    """
    params: dict[str, Any] = {"mu": mu, "omega": omega, "refit_every": REFIT_EVERY}

    def build(img, phi, factor):
        state: dict[str, Any] = {"calls": 0}

        def refit(p):
            r = local_radius(equivalent_radius_px(p) * factor)  # adaptive radius, original px
            if "force" not in state or abs(r - state["radius"]) > 0.1 * state["radius"]:
                level_params = dict(params, radius_px=r)
                state["force"], state["radius"] = region_force(img, p, factor, level_params, r, "smoothed"), r
                params.setdefault("edge_contrast", level_params["edge_contrast"])
                params.setdefault("force_scale", level_params["force_scale"])
            state["ellipse"] = moment_ellipse(p > 0)

        def speed(p, band, box):
            if state["calls"] % REFIT_EVERY == 0:
                refit(p)
            state["calls"] += 1
            region = state["force"](p, band, box)[0]
            shape = ellipse_distance(band, *state["ellipse"]) - p[band[:, 0], band[:, 1]]
            return region + omega * shape

        return speed, mu

    return run_narrow_band(image, init, "mslcv", build, params, spacing=spacing, multiscale=True,
                           max_iterations=max_iterations)
