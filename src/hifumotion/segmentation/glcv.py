"""GLCV: the geodesic localized Chan-Vese model, the paper's Eq. 6–7.

LCV (Eq. 5) plus, where the neighbourhood of a contour point is nearly uniform
(``t(x) = 1`` when ``|c_x1 − c_x2| < κ1``, Eq. 6), the geodesic active contour
flow ``g|∇φ| div(∇φ/|∇φ|) + ∇g·∇φ + α g|∇φ|`` that carries the contour across
flat regions; near the boundary the local contrast is high, ``t(x) = 0`` and
LCV places the contour. By default the balloon is weighted by how typical
each point's intensity is of the target (:class:`TargetModel`), which stops
the leaks of the constant balloon on weak boundaries (``balloon="constant"``
is the paper's form; ``docs/decisions.md``).

From a rough start drawn inside the target, every point of the start sees
uniform tissue (t(x) = 1 along it, by κ1's definition): the geodesic term
alone must carry the whole contour to the boundary. ``carry="global"``
(default) does it exactly, by the GAC's global solver (the closed curve of least
geodesic length around the start, :mod:`._minimal_path`), and Eq. 7 then
refines the carried contour at full resolution with κ1, r and the force unit
measured on the start. ``carry="balloon"`` is the paper's way: Eq. 7's flow from
the start, the balloon doing the carrying. On the shared real images the global
carry scores 0.02–0.06 higher in mean DSC in a quarter to half the time; on
small sections in low-contrast texture it can take an outer edge, so the
sweep's later planes and tracked frames use the balloon (their start is a
previous contour, on or near the boundary; ``docs/decisions.md``).

References
----------
.. [1] Liao X et al. Modeling and predicting tissue movement and deformation
   for HIFU therapy. PLoS ONE (the spec, Section 2.1.2).
.. [2] Lankton S, Tannenbaum A. Localizing region-based active contours. IEEE TIP 2008.
.. [3] Caselles V, Kimmel R, Sapiro G. Geodesic active contours. IJCV 1997; 22(1): 61-79.
.. [4] Appleton B, Talbot H. Globally optimal geodesic active contours. J Math Imaging Vis 2005; 23: 67-86.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hifumotion.errors import InputError
from hifumotion.segmentation import _kernels as K
from hifumotion.segmentation._common import (
    SegmentationResult,
    edge_indicator,
    equivalent_radius_px,
    gaussian,
    prepare_image,
    run_narrow_band,
)
from hifumotion.segmentation.levelset import initial_phi
from hifumotion.segmentation.lcv import MU, checked_force_unit, force_scale, region_force

#: σ of the edge function's Gaussian in the geodesic term, as a fraction of the initial
#: equivalent radius: wide enough to see through speckle grains, which GAC's own σ is not.
SIGMA_FRACTION = 0.2
#: Balloon weight α of Eq. 7 (> 0 expands: the initial contour is inside the target).
ALPHA = 0.3
#: Iterations of Eq. 7 refining the globally carried contour (at full resolution, 0.45 px each).
REFINE_ITERATIONS = 20
CARRIES = ("global", "balloon")


@dataclass(frozen=True)
class TargetModel:
    """The target's intensity distribution against the rest of the image, learned from the
    initial contour (which a clinician draws inside the target).

    ``weight(I) = p_target(I) / (p_target(I) + p_rest(I))`` in (0, 1): near 1 where a
    (smoothed) intensity is typical of the target, near 0 where it is typical of
    the rest of the image. Histograms of :data:`BINS` bins with one pseudo-count per bin.
    """

    lo: float
    step: float
    log_ratio: np.ndarray

    BINS = 32

    @classmethod
    def learn(cls, image: np.ndarray, inside: np.ndarray) -> "TargetModel":
        lo, hi = float(image.min()), float(image.max())
        model = cls(lo, (hi + 1e-9 - lo) / cls.BINS, np.zeros(cls.BINS))
        idx = model.bin_of(image)
        p_in = np.bincount(idx[inside], minlength=cls.BINS) + 1.0
        p_out = np.bincount(idx[~inside], minlength=cls.BINS) + 1.0
        return cls(lo, model.step, np.log(p_in / p_in.sum()) - np.log(p_out / p_out.sum()))

    def bin_of(self, image: np.ndarray) -> np.ndarray:
        """The histogram bin of each intensity: :data:`BINS` equal bins from the learned image's
        minimum to its maximum, values beyond them in the end bins."""
        return np.clip(((image - self.lo) / self.step).astype(np.intp), 0, self.BINS - 1)

    def weight(self, image: np.ndarray) -> np.ndarray:
        """``P(target | I)`` for equal priors, in (0, 1), at every pixel of a smoothed image."""
        return 1.0 / (1.0 + np.exp(-self.log_ratio[self.bin_of(image)]))


def glcv(image: Any, init: Any, *, radius: float | None = None, mu: float = MU, alpha: float = ALPHA,
         kappa1: float | None = None, sigma: float | None = None, balloon: str = "target", form: str = "smoothed",
         force_unit: float | None = None, carry: str = "global", multiscale: bool = True,
         max_iterations: int | None = None, spacing=None) -> SegmentationResult:
    """Segment with GLCV (Eq. 6–7).

    Parameters
    ----------
    image, init, spacing
        As :func:`hifumotion.segmentation.segment`.
    radius
        Local radius r (px) of Eq. 1; default 0.3 × the initial contour's equivalent radius.
    mu
        Curvature weight μ (Eq. 7), relative to the normalised region force.
    alpha
        Balloon constant α of the geodesic term (Eq. 7); positive grows the contour.
    kappa1
        Contrast threshold κ1 of Eq. 6 (intensity in [0, 1]); default
        :data:`~hifumotion.segmentation.lcv.CONTRAST_FACTOR` × the median local
        contrast along the initial contour, i.e. a multiple of what speckle
        alone produces (:func:`~hifumotion.segmentation.lcv.initial_contrast`).
    sigma
        σ (px) of the Gaussian in the edge function g; default from the contour's size.
    balloon
        ``"constant"``: the paper's balloon ``α g |∇φ|``. ``"target"`` (default):
        α is weighted at each point by how typical its smoothed intensity is of the
        target (:class:`TargetModel`), so the balloon that carries the contour across
        flat parts of the target fades in tissue unlike the target instead of
        pushing on until it meets an edge (see ``docs/decisions.md``).
    form
        How LCV's integral (Eq. 5) is evaluated, see :func:`~hifumotion.segmentation.lcv.region_force`.
    force_unit
        The region force's unit, as :func:`~hifumotion.segmentation.lcv.lcv`'s.
    carry
        ``"global"`` (default): the GAC's global solver carries the start to the boundary,
        then :data:`REFINE_ITERATIONS` of Eq. 7 refine it; ``"balloon"``: Eq. 7's flow from
        the start (see the module).
    multiscale
        Run coarse to fine (a numerical acceleration; see ``docs/decisions.md``); ``carry="balloon"`` only.
    max_iterations
        Iteration cap of the coarsest level; default from the initial contour's size
        (with ``carry="global"``: of the refinement, default :data:`REFINE_ITERATIONS`).
    """
    if balloon not in ("constant", "target"):
        raise InputError(f"balloon must be 'constant' or 'target', got {balloon!r}", "balloon")
    if carry not in CARRIES:
        raise InputError(f"carry must be one of {CARRIES}, got {carry!r}", "carry")
    params: dict[str, Any] = {"mu": mu, "alpha": alpha, "balloon": balloon, "form": form, "carry": carry}
    if force_unit is not None:
        params["force_scale"] = checked_force_unit(force_unit)
    t0 = time.perf_counter()
    if carry == "global":
        from hifumotion.segmentation.gac import gac

        img = prepare_image(image)
        phi0 = initial_phi(init, img.shape)
        region_force(img, phi0, 1, params, radius, form)  # r, κ1 and the force unit from the start
        carried = gac(img, phi0 > 0)
        params["geodesic_length_px"] = carried.params["geodesic_length_px"]
        image, init, multiscale = img, carried.mask, False
        max_iterations = max_iterations or REFINE_ITERATIONS
    learned: dict[str, TargetModel] = {}

    def build(img, phi, factor):
        s = params.setdefault("sigma_px", sigma or max(1.0, SIGMA_FRACTION * equivalent_radius_px(phi) * factor))
        force = region_force(img, phi, factor, params, radius, form)
        if kappa1 is None and "edge_contrast" not in params:  # a force unit was given, κ1 was not
            params["edge_contrast"] = force_scale(force.stats, phi, img)[0]
        k1 = params.setdefault("kappa1", kappa1 if kappa1 is not None else params["edge_contrast"])
        smooth = gaussian(img, max(s / factor, 0.5))
        g, gx, gy = edge_indicator(img, max(s / factor, 0.5), smooth)
        if balloon == "target":
            if "model" not in learned:  # from the initial contour, on the coarsest level
                learned["model"] = TargetModel.learn(smooth, phi > 0)
            weight = alpha * learned["model"].weight(smooth)
        else:
            weight = np.full(img.shape, float(alpha))

        def speed(p, band, box):
            region, c_in, c_out = force(p, band, box)
            return K.add_geodesic_where_flat(region, c_in, c_out, k1, p, band, g, gx, gy, weight)  # Eq. 6-7

        return speed, mu, lambda p, cap: force.evolve(p, cap, mu, (k1, g, gx, gy, weight))

    result = run_narrow_band(image, init, "glcv", build, params, spacing=spacing, multiscale=multiscale,
                             max_iterations=max_iterations)
    result.seconds = time.perf_counter() - t0
    return result
