"""How to calibrate and the fitted model's numerical settings, as plain data (no solver imported).

:class:`CalibrationSettings` holds every setting of :func:`~hifumotion.estimation.calibrate.calibrate`
— the run configuration's ``[estimation]`` is one (:class:`~hifumotion.workflow.pipeline.EstimationConfig`
adds only what the pipeline around the calibration needs), so a setting has one name, one
default and one check. :class:`ModelSettings` holds every setting of a forward run that is not fitted: the
resolution, the integrator and each integrator's own settings (the fast path's
:class:`~hifumotion.creep.settings.CreepSettings`, its reduced model's
:class:`~hifumotion.creep.settings.ReducedSettings`, the explicit path's fields). A run's
configuration reaches it as ``[estimation.model]`` (and ``--set model.creep.tolerance=…``),
validated by the annotations; its defaults live here only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

import numpy as np
from annotated_types import Ge, Gt, Le

from hifumotion.apparatus import FRICTION
from hifumotion.numerics import CFL, QUASI_STATIC_MASS_SCALING, QUASI_STATIC_MAX_STEP_S, SUPPORT_FACTOR
from hifumotion.physical import TISSUE_DENSITY_KG_M3
from hifumotion import paper
from hifumotion.config import ConfigModel
from hifumotion.creep.settings import CreepSettings, ReducedSettings
from hifumotion.errors import InputError
from hifumotion.rheology import RATE_FLOOR_PER_S

#: The forward models (``estimation.model.FORWARD_MODELS``), by ``ModelSettings.integrator``.
INTEGRATORS = ("implicit", "explicit", "reduced")

#: What gives frame 0's target the strip the bar's bloom hides (:func:`prepare`): the
#: reconstruction's top continued under the bar, also the image's bloom edge where there is no
#: such top, or nothing.
BLOOM_RULES = ("reconstruction", "image", "off")
#: The rule a calibration uses unless told otherwise (docs/decisions.md, "Frame 0's target reaches the bar").
DEFAULT_BLOOM_RULE = "reconstruction"


def scheduler_address_problem(address: str) -> str | None:
    """Why ``address`` is not a Dask scheduler's address (``tcp://host:8786``, ``tls://…``,
    ``host:8786``), or None when it is one."""
    import re

    m = re.fullmatch(r"(?:(tcp|tls|ucx|ws|wss)://)?(\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.\-]+):(\d{1,5})", address.strip())
    if m is None:
        return f"expected a scheduler address such as tcp://host:8786, got {address[:60]!r}"
    if not 0 < int(m.group(3)) < 65536:
        return f"port {m.group(3)} is not in 1 … 65535"
    return None


@dataclass
class ModelSettings:
    """Numerical settings of the fitted model (not fitted themselves)."""

    tissue_particles: Annotated[int, Ge(100), Le(1_000_000)] = paper.TISSUE_PARTICLES  # the paper's count
    support_factor: Annotated[float, Ge(1.5), Le(3.0)] = SUPPORT_FACTOR   # kernel support h in spacings
    mass_scaling: Annotated[float, Ge(1.0)] = QUASI_STATIC_MASS_SCALING    # inertia multiplier of the quasi-static push
    settle_periods: Annotated[float, Gt(0)] = 6.0      # settling time in 1/ω of the slowest elastic mode
    cfl: Annotated[float, Gt(0), Le(1.0)] = CFL        # safety factor on the time step
    max_step_s: Annotated[float, Gt(0)] = QUASI_STATIC_MAX_STEP_S         # largest time step (s)
    force_ramp_s: Annotated[float, Ge(0)] | None = None  # the force's linear rise (s); default: setup.json's push.ramp_s
    tissue_density_kg_m3: Annotated[float, Gt(0)] = TISSUE_DENSITY_KG_M3
    rate_floor_per_s: Annotated[float, Gt(0)] = RATE_FLOOR_PER_S   # floor of the shear rate in Eq. 16's μ (1/s; hifumotion.rheology)
    friction: Annotated[float, Ge(0)] = FRICTION            # Coulomb friction of the tissue on the floor and the bar's face
                                        # (the operator's estimate, not fitted; a sample that slides depends on it)
    contour_points: Annotated[int, Ge(8), Le(10_000)] = 64   # size of the point set A
    integrator: Literal["implicit", "explicit", "reduced"] = "implicit"  # one of INTEGRATORS: "implicit", the fast path (hifumotion.creep);
                                        # "explicit", Eq. 8–20 as the paper; "reduced", the fast path's
                                        # POD–Galerkin model (hifumotion.reduced.model)
    reduced_span: tuple[float, float] = (0.5, 2.0)   # F/E multiples of the full runs the reduced model's modes come from
    creep: CreepSettings = field(default_factory=CreepSettings)        # the implicit path's (and the snapshots')
    reduced: ReducedSettings = field(default_factory=ReducedSettings)  # the reduced model's

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise InputError(f"unknown integrator {self.integrator!r}; expected {', '.join(INTEGRATORS)}",
                             "integrator")
        # from parameters.json: the nested settings arrive as dicts
        for name, kind in (("creep", CreepSettings), ("reduced", ReducedSettings)):
            value = getattr(self, name)
            if isinstance(value, dict):
                unknown = sorted(set(value) - set(kind.__dataclass_fields__))
                if unknown:
                    raise InputError(f"unknown settings {unknown}; expected some of "
                                     f"{sorted(kind.__dataclass_fields__)}", f"model_settings.{name}")
                setattr(self, name, kind(**value))
            elif not isinstance(value, kind):
                raise InputError(f"expected {kind.__name__}, got {type(value).__name__}", f"model_settings.{name}")
        span = tuple(float(x) for x in self.reduced_span)
        if len(span) != 2 or not (0 < span[0] < span[1] and np.isfinite(span[1])):
            raise InputError(f"expected two F/E multiples 0 < low < high, got {self.reduced_span}", "reduced_span")
        self.reduced_span = span


class CalibrationSettings(ConfigModel):
    """How to calibrate (:func:`~hifumotion.estimation.calibrate.calibrate`); every field has a default."""

    method: Literal["least_squares", "cmaes", "table1"] = Field(
        "least_squares", description="estimator: bounded least squares, CMA-ES, or the paper's Table 1 algorithm")
    training_frames: str | list[int] | None = Field(
        None, description="training frames, '20,30,40', '20:101:10' or a list (default: the paper's protocol scaled to the series)")
    force_n: float = Field(paper.FORCE_N, ge=1e-6, le=1e3, description="nominal pushing force in N, 10⁻⁶ … 10³ (the data fix only F/E)")
    search_particles: int = Field(1000, ge=100, le=1_000_000, description="tissue particles of the coarser model the search runs on")
    search_integrator: Literal["implicit", "reduced"] = Field(
        "implicit", description="the search model's integrator: implicit (its full runs) or reduced (its POD–Galerkin model, made around the design's centre from two full runs, again from every full run so far wherever a full run finds it off — at the design's best start and at a fit — then, if the final model is finer, the final model's own around the search's optimum; docs/decisions.md, \"Calibration on reduced models\")")
    reduced_friction_trust: float = Field(
        1.25, gt=1.0, le=100.0, description="with the reduced search and a fitted friction: each search on a reduced model keeps μ_f within this factor of the μ_f the model was made at (two sliding snapshots do not show a stick far above it: docs/decisions.md, \"The reduced search fits the friction within its trust region\")")
    reduced_rounds: int = Field(
        3, ge=0, le=20, description="with the reduced search: how many more times the reduced model is made again around a fit where the full model disagrees with it (or whose μ_f stopped at the edge of the trust region), and searched from there")
    reduced_agreement: float = Field(
        1.1, gt=1.0, le=10.0, description="with the reduced search: the reduced model holds at a fit where its training cost and the full model's are within this factor of each other")
    full_model_check: bool = Field(
        True, description="with the reduced search: each fit checked by one run of the full model, which becomes a snapshot of the model made again where the two disagree; the check's residuals recorded beside the reduced model's")
    reduced_correction: bool = Field(
        True, description="with the reduced search and its full-model checks: each search runs on the reduced model's residuals plus the full model's miss at the point the model was made around (the residuals' difference there, known from its check), so that the searched model and the full one agree there (zero-order consistency of a trust-region model: Alexandrov et al. 1998; docs/decisions.md, \"The reduced search corrected by the full model's miss at its centre\")")
    max_evaluations: int = Field(8, ge=1, le=10_000, description="least squares: residual evaluations (each with a Jacobian)")
    cma_generations: int = Field(12, ge=1, le=10_000, description="CMA-ES: generations")
    threshold_mm_per_point: float | None = Field(
        None, gt=0, le=100.0, description="Table 1's threshold T per contour point in mm (default: one pixel; at most 100)")
    table1_max_runs: int = Field(120, ge=1, le=100_000, description="Table 1: most forward runs")
    space_mapping: bool = Field(True, description="implicit search: map the search model's fit to the final model (output space mapping)")
    mapping_runs: int = Field(3, ge=1, le=100, description="runs of the final model in the space mapping (each verified)")
    keep_better_model: bool = Field(True, description="implicit search: after the space mapping, predict with whichever "
                                    "model — the search model at its fit or the final model at its best mapped "
                                    "parameters — fits the training frames better (both costs in parameters.json)")
    degeneracy_check: bool = Field(True, description="run and report the F–E–β1 scaling the push cannot see")
    resolution_check: bool = Field(
        False, description="run the fitted model at the fit again on twice the particles (and, where that moves "
                           "them by more than a pixel, on four times, which decides) and report how far its "
                           "points A move apart over the training frames (parameters.json → fit.resolution_check; "
                           "a warning where it is more than a pixel: the model is too coarse for the fit to be "
                           "trusted); how far the finer model would move each fitted value is added to its "
                           "standard error in quadrature. Off by default: one run of the finer model, 2–5× the "
                           "model's own")
    online_model: bool = Field(
        True, description="after the fit, run the fitted model's reduced model's two full runs (the snapshots the "
                          "online loop's reduced model is made from) over the whole series, in parallel, and save "
                          "them with the calibration (model/reduced_snapshots.npz): hifumotion online then makes "
                          "its model from them in seconds instead of running them before its first frame")
    fit_friction: bool | None = Field(
        None, description="fit the friction of the floor and the bar's face (ln μ_f, 0.02 … 1) as a fifth "
                          "coordinate; unset: when the bar is driven (its slide is set by the friction), "
                          "otherwise held at [estimation.model] friction")
    objective: Literal["auto", "contour", "contour+displacement"] = Field(
        "auto", description="what the fit matches: the observed contours (the paper's S_t), or also the speckle-tracked displacement of the contour points; auto: the displacement too where speckle tracking observed it")
    quality_weights: bool = Field(
        True, description="weight each contour point's residual by the speckle tracking's quality there (speckle tracking only): a boundary the image does not show (under the bar's blur, on the floor) counts for little")
    bar_motion: bool = Field(
        True, description="also fit the bar's tracked displacement (speckle tracking with a bar in setup.json): under a force-controlled push the bar's travel is what F/E sets most directly")
    workers: int | None = Field(None, ge=1, le=1024, description="Dask worker processes of the local cluster (default: the cores)")
    scheduler_address: str | None = Field(None, description="an existing Dask cluster, tcp://host:8786")
    seed: int = Field(0, ge=0, lt=2 ** 63, description="seed of the search's random draws (CMA-ES)")
    model: ModelSettings = Field(
        default_factory=ModelSettings, description="the fitted model's settings: its tissue particles (the paper: 4,399), integrator and each integrator's own (creep: the fast path's; reduced: its reduced model's); particles is short for model.tissue_particles")

    @model_validator(mode="before")
    @classmethod
    def _particles_are_the_models(cls, data):
        # ``particles`` (the option's and earlier configurations' name) is the model's tissue
        # particles: one setting, one home
        if isinstance(data, dict) and "particles" in data:
            data = dict(data)
            model = data.get("model")
            model = dict(model) if isinstance(model, dict) else ({} if model is None else model)
            if isinstance(model, dict):
                if "tissue_particles" in model:
                    raise ValueError("particles and model.tissue_particles are one setting; give it once")
                model["tissue_particles"] = data.pop("particles")
                data["model"] = model
        return data

    @field_validator("scheduler_address")
    @classmethod
    def _an_address(cls, v):
        problem = None if v is None else scheduler_address_problem(v)
        if problem:
            raise ValueError(problem)
        return v


__all__ = ["INTEGRATORS", "CalibrationSettings", "ModelSettings", "scheduler_address_problem"]
