"""LCV: the localized Chan-Vese model (Lankton & Tannenbaum 2008), the paper's Eq. 1–5.

References
----------
.. [1] Lankton S, Tannenbaum A. Localizing region-based active contours.
   IEEE Trans. Image Process. 2008; 17(11): 2029-2039.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hifumotion.errors import InputError

from hifumotion.segmentation._common import (
    LocalStatistics,
    SegmentationResult,
    equivalent_radius_px,
    gaussian,
    intensity_scale,
    run_narrow_band,
)
from hifumotion.segmentation import _kernels as K
from hifumotion.segmentation.levelset import EPSILON, Evolution, band_box

#: Local radius r as a fraction of the initial contour's equivalent radius (Eq. 1).
RADIUS_FRACTION = 0.3
#: Bounds (px) of the local radius.
RADIUS_MIN_PX, RADIUS_MAX_PX = 6.0, 40.0
#: Curvature weight μ of Eq. 4–5, relative to the normalised region force.
MU = 1.0
#: The local contrast that counts as an edge, in units of the median contrast along the initial
#: contour (which is what speckle alone produces). It is GLCV's κ1 (Eq. 6) and LCV's force unit.
CONTRAST_FACTOR = 4.0


def checked_force_unit(force_unit: float | None) -> float | None:
    """``force_unit`` as a float, or :class:`InputError` unless it is a positive finite number."""
    if force_unit is None:
        return None
    try:
        value = float(force_unit)
    except (TypeError, ValueError):
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"force_unit must be a positive number (squared intensity), got {force_unit!r}", "force_unit")
    return value


def local_radius(radius_px: float) -> float:
    """Default r of Eq. 1: 0.3 × the initial contour's equivalent radius, within [6, 40] px."""
    return float(np.clip(RADIUS_FRACTION * radius_px, RADIUS_MIN_PX, RADIUS_MAX_PX))


def initial_contrast(stats: LocalStatistics, phi: np.ndarray, image: np.ndarray) -> float:
    """The median local contrast ``|c_x1 − c_x2|`` along the zero level of ``phi``.

    Along the initial contour, drawn inside the target (the clinician's rough
    ellipse or clicks), both halves of each ball hold the same tissue: the
    contrast measured there is what speckle alone produces at this scale.
    """
    box = band_box(phi, 2)
    band = K.band_points(phi, 0.75, *box)
    c_in, c_out, *_ = stats.local_means(phi, image, band, box, EPSILON, with_delta=False)
    contrast = np.abs(c_in - c_out)
    contrast = contrast[np.isfinite(contrast)]
    return float(np.median(contrast)) if contrast.size else 0.0


def force_scale(stats: LocalStatistics, phi: np.ndarray, image: np.ndarray) -> tuple[float, float]:
    """``(edge_contrast, scale)``: the contrast that counts as an edge (``CONTRAST_FACTOR`` ×
    :func:`initial_contrast`, floored at 1 % of the intensity spread) and the force unit
    ``edge_contrast × intensity spread`` (see :func:`lcv_force`)."""
    spread = intensity_scale(image, phi > 0)
    edge = max(CONTRAST_FACTOR * initial_contrast(stats, phi, image), 0.01 * spread)
    return edge, edge * spread


def lcv_force(stats: LocalStatistics, phi: np.ndarray, image: np.ndarray, band: np.ndarray, box,
              scale: float, integral: bool = False,
              point_image: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The region term of Eq. 5 at the band points, for φ positive inside.

    Eq. 5 integrates ``δ(φ(y)) [(I(y) − c_x1)² − (I(y) − c_x2)²]`` over the ball
    B(x, r). With ``integral=False`` the integrand is taken at ``y = x``,
    ``(I(x) − c_x1)² − (I(x) − c_x2)²``, as in Lankton & Tannenbaum's own
    implementation; it pins the contour pixel by pixel but follows speckle. The
    full integral only constrains the contour's *average* position within each
    ball, so wiggles shorter than r are left to the curvature term (see
    ``docs/decisions.md``). With ``integral=True`` the integral is computed
    exactly, ``(c_x1 − c_x2) [(c_x1 + c_x2) Σδ − 2 Σδ·I]`` from two more disk
    sums, and divided by ``Σδ``. ``point_image`` replaces the image in the
    pointwise form: the models pass the image smoothed over a small Gaussian,
    i.e. the integrand averaged over the immediate neighbourhood of x, which
    pins the contour like the pointwise form without following single grains.

    The paper (after Lankton) writes the flow for φ negative inside; with φ
    positive inside the term changes sign. The force is divided by ``scale``
    (:func:`force_scale`: the edge contrast times the image's intensity spread,
    so a point on an edge of that contrast whose intensity is one spread from
    the local mid-level moves at full speed) and clipped to [-1, 1]. Returns
    that force and the local means ``(c_x1, c_x2)``.
    """
    return stats.region_force(phi, band, box, point_image, scale, integral, EPSILON)


#: How Eq. 5's integral is evaluated (see :func:`lcv_force`).
FORMS = ("smoothed", "integral", "point")
#: Width of the neighbourhood of the ``smoothed`` form, as a fraction of the local radius r.
SMOOTHING_FRACTION = 0.25


class RegionForce:
    """LCV's region force on one pyramid level: ``force(phi, band, box) -> (F, c_x1, c_x2)``,
    and :meth:`evolve`, the whole evolution of LCV or GLCV in one compiled loop."""

    def __init__(self, stats: LocalStatistics, scale: float, integral: bool, point_image: np.ndarray | None):
        self.stats, self.scale, self.integral, self.point_image = stats, scale, integral, point_image

    def __call__(self, phi, band, box):
        return lcv_force(self.stats, phi, self.stats.image, band, box, self.scale, self.integral, self.point_image)

    def evolve(self, phi: np.ndarray, max_iterations: int, mu: float, geodesic: tuple | None = None) -> Evolution:
        """Evolve ``phi`` in place (see :func:`_kernels.evolve_region`); ``geodesic`` is
        ``(kappa1, g, gx, gy, weight)`` for GLCV, None for LCV."""
        from hifumotion.segmentation import levelset as L

        st = self.stats
        pim = st.image if self.point_image is None else self.point_image
        if geodesic is None:
            dummy = np.zeros((1, 1))
            geo = (0.0, dummy, dummy, dummy, dummy)
        else:
            geo = geodesic
        it, converged = K.evolve_region(phi, st.image, pim, st.half_widths, float(st.radius_px), st.prefix, st.count,
                                        st.total, float(self.scale), float(EPSILON), bool(self.integral),
                                        geodesic is not None, float(geo[0]), geo[1], geo[2], geo[3], geo[4],
                                        float(mu), int(max_iterations), float(L.CFL), float(L.BAND),
                                        float(L.UPDATE_BAND), int(L.CONVERGENCE_WINDOW), float(L.CONVERGENCE_FRACTION))
        return Evolution(phi, int(it), bool(converged))


def region_force(img: np.ndarray, phi: np.ndarray, factor: int, params: dict, radius: float | None, form: str) -> RegionForce:
    """Set up LCV's region force on one pyramid level (a :class:`RegionForce`).

    Resolves and records in ``params`` the scale-derived values on the first
    (coarsest) level: the local radius r, the edge contrast and the force unit.
    ``form`` is ``"smoothed"`` (default of the models: the integrand of Eq. 5 at
    x, on the image smoothed over a Gaussian of ``r/4``), ``"integral"`` (Eq. 5
    exactly) or ``"point"`` (the integrand at x on the raw image, as Lankton's code).
    """
    if form not in FORMS:
        raise InputError(f"form must be one of {FORMS}, got {form!r}", "form")
    r = params.setdefault("radius_px", radius or local_radius(equivalent_radius_px(phi) * factor))
    stats = LocalStatistics.of(img, r / factor)
    if "force_scale" not in params:
        params["edge_contrast"], params["force_scale"] = force_scale(stats, phi, img)
    point_image = None
    if form == "smoothed":
        point_image = gaussian(img, max(SMOOTHING_FRACTION * r / factor, 0.5))
    return RegionForce(stats, params["force_scale"], form == "integral", point_image)


def lcv(image: Any, init: Any, *, radius: float | None = None, mu: float = MU, form: str = "smoothed",
        force_unit: float | None = None, multiscale: bool = True, max_iterations: int | None = None,
        spacing=None) -> SegmentationResult:
    """Segment with the localized Chan-Vese model (Eq. 1–5).

    Parameters
    ----------
    image
        2D image, any dtype.
    init
        Initial contour: :class:`~hifumotion.contour.Ellipse`, clicked points, contour or mask.
    radius
        Radius r (px) of the local ball B of Eq. 1; default from the initial contour's size.
    mu
        Weight μ of the curvature (length) term, relative to the normalised region force.
    form
        How Eq. 5's integral is evaluated: ``"smoothed"``, ``"integral"`` or ``"point"``
        (see :func:`region_force`).
    force_unit
        The region force's unit (squared intensity); default from the initial contour
        (:func:`force_scale`). Tracking passes the first frame's: a previous frame's
        boundary is no inside start, and the contrast measured along it is the edge's.
    multiscale
        Run coarse to fine (a numerical acceleration; see ``docs/decisions.md``).
    max_iterations
        Iteration cap of the coarsest level; default from the initial contour's size.
    spacing
        Pixel size in mm (row, col), for the contour in mm.
    """
    params: dict[str, Any] = {"mu": mu, "form": form}
    if force_unit is not None:
        params["force_scale"] = checked_force_unit(force_unit)

    def build(img, phi, factor):
        force = region_force(img, phi, factor, params, radius, form)

        def speed(p, band, box):
            return force(p, band, box)[0]

        return speed, mu, lambda p, cap: force.evolve(p, cap, mu)

    return run_narrow_band(image, init, "lcv", build, params, spacing=spacing, multiscale=multiscale,
                           max_iterations=max_iterations)
