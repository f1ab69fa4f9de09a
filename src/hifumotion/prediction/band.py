"""The aim's band: where the focus would go if the fit were one standard error off along the
direction the training frames fix least.

A push seen over a few seconds leaves some directions of the parameters nearly undetermined —
typically E against ν, and β1 against β2 (the creep's scale against its exponent), each pair
correlated beyond 0.95. A prediction from the best fit alone says nothing of them. The band is a
Laplace approximation cut to its widest direction: the calibration's covariance
(:func:`~hifumotion.estimation.fit.uncertainty`: standard errors and correlations of the
coordinates ln E, ν, ln β1, β2 [, ln μ_f]) is taken in units of each coordinate's relevance
(:data:`~hifumotion.estimation.fit.RELEVANCE`, the scale below which a coordinate counts as
determined), its leading eigenvector ``v`` with eigenvalue ``λ`` is the least determined direction,
and the model is run again at ``θ ± √λ·v`` (held inside the search bounds). Per frame the band is
the larger distance of those two aims from the fit's (mm).

A coordinate whose standard error no data bound (infinite) counts with half its search range:
the prior the bounds express. Two runs, not a sample: the band shows how far the undetermined
direction moves the aim, not a probability; a fit whose uncertainties are not those of a converged
minimum (``fit.caveats``) gives a band of the same standing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hifumotion.errors import InputError


@dataclass
class AimBand:
    """The aims one standard error either way along the least determined direction."""

    coordinates: tuple[str, ...]        # the fit's coordinates, in order
    direction: np.ndarray               # (p,) the step θ₊ − θ (coordinates' own units)
    parameters: tuple[dict, dict]       # the parameters at θ − step and θ + step
    aim_mm: np.ndarray                  # (2, F, 2): the aims at θ − step and θ + step (mm, image axes)
    width_mm: np.ndarray                # (F,) the larger distance of the two aims from the fit's aim
    seconds: float = 0.0                # the two runs' wall time

    def as_dict(self) -> dict:
        return {"coordinates": list(self.coordinates), "step": [float(x) for x in self.direction],
                "parameters_minus": self.parameters[0], "parameters_plus": self.parameters[1],
                "largest_width_mm": float(self.width_mm.max()) if len(self.width_mm) else 0.0,
                "seconds": self.seconds}


def least_determined_step(covariance: dict, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``√λ·v`` (module docstring) in the fit's coordinates.

    ``covariance``: ``{"coordinates": [...], "std": [...], "matrix": [[...]]}`` as the calibration
    writes it (``parameters.json``'s ``fit.correlation``; a ``null`` standard error: no data bound it)."""
    from hifumotion.estimation.fit import RELEVANCE

    wanted = (f"expected the standard errors and the {len(lower)} × {len(lower)} correlation of the fit's "
              "coordinates, as calibrate writes them")
    try:
        names = list(covariance.get("coordinates") or [])
        corr = np.asarray(covariance.get("matrix") or [], float)
        sd = np.array([np.inf if v is None else float(v) for v in (covariance.get("std") or [])])
    except (AttributeError, TypeError, ValueError):
        raise InputError(wanted, "fit.correlation") from None
    if (not names or any(n not in RELEVANCE for n in names) or corr.shape != (len(names), len(names))
            or len(sd) != len(names) or len(lower) != len(names)):
        raise InputError(wanted, "fit.correlation")
    prior = 0.5 * (np.asarray(upper, float) - np.asarray(lower, float))
    sd = np.where(np.isfinite(sd), sd, prior)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    np.fill_diagonal(corr, 1.0)
    relevance = np.array([RELEVANCE[n] for n in names])
    scaled = corr * np.outer(sd / relevance, sd / relevance)
    values, vectors = np.linalg.eigh(scaled)
    v = vectors[:, -1] * np.sqrt(max(values[-1], 0.0))
    return v * relevance


#: the coordinate → the parameters.json entry whose standard error gives it (relative: a log coordinate)
_FROM_PARAMETERS = {"log_E": ("youngs_modulus_pa", True), "nu": ("poisson_ratio", False),
                    "log_beta1": ("beta1_pa_s_pow", True), "beta2": ("beta2", False), "log_mu": ("friction", True)}


def covariance_from_calibration(meta: dict) -> dict:
    """``fit.correlation`` of a calibration's ``parameters.json`` (``meta``) with the coordinates'
    standard errors: stored there, or — in a calibration written before they were — taken from the
    parameters' own (``std / value`` for a log coordinate, as the calibration reported them)."""
    fit = meta.get("fit") if isinstance(meta, dict) else None
    cov = (fit or {}).get("correlation") if isinstance(fit, dict) else None
    cov = dict(cov) if isinstance(cov, dict) else {}
    if cov.get("std") is None and isinstance(cov.get("coordinates"), list):
        params = meta.get("parameters") if isinstance(meta.get("parameters"), dict) else {}
        std = []
        for name in cov["coordinates"]:
            key, relative = _FROM_PARAMETERS.get(name, (name, False))
            entry = params.get(key) if isinstance(params.get(key), dict) else {}
            value, sd = entry.get("value"), entry.get("std")
            ok = all(isinstance(x, (int, float)) and np.isfinite(x) for x in (value, sd)) and value != 0
            std.append((sd / value if relative else sd) if ok else None)
        cov["std"] = std
    return cov


def aim_band(spec, k, reference, frames, covariance: dict, aim_mm: np.ndarray) -> AimBand:
    """Run the model at the fit ``k`` moved ± :func:`least_determined_step` (``covariance`` as there)
    and compare the aims with the fit's ``aim_mm`` ``(F, 2)``."""
    from dataclasses import replace

    from hifumotion.estimation.space import FRICTION_BOUNDS, FRICTION_NAME, SearchSpace
    from hifumotion.prediction.physics import predict_frames

    names = tuple(covariance.get("coordinates", []))
    space = SearchSpace(force_n=k.force_n, friction=FRICTION_BOUNDS if FRICTION_NAME in names else None)
    if names != space.names:
        raise InputError(f"the fit's coordinates are {', '.join(names) or 'missing'}; expected "
                         f"{', '.join(space.names)} (calibrate again)", "fit.correlation")
    theta = space.theta(k)
    step = least_determined_step(covariance, space.lower, space.upper)
    ks = [space.parameters(np.clip(theta + sign * step, space.lower, space.upper)) for sign in (-1.0, 1.0)]
    if space.friction is None:      # not fitted: the model's own setting, as in the fit
        ks = [replace(moved, friction=k.friction) for moved in ks]
    t0 = time.perf_counter()
    aims = []
    for moved in ks:
        aims.append(predict_frames(spec, moved, reference, frames).aim_mm)
    n = min(len(aim_mm), *(len(a) for a in aims))
    pair = np.stack([a[:n] for a in aims])
    width = np.linalg.norm(pair - np.asarray(aim_mm, float)[None, :n], axis=2).max(axis=0)
    return AimBand(names, step, (ks[0].as_dict(), ks[1].as_dict()), pair, width, time.perf_counter() - t0)


__all__ = ["AimBand", "aim_band", "covariance_from_calibration", "least_determined_step"]
