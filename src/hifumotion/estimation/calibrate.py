"""Calibrate the particle model on an observed experiment: one documented order.

1. **Observe** (:func:`~.prepare.prepare`): segment the sweep, reconstruct, track the frames.
2. **Prepare the search**: the training data (:class:`~.objective.TrainingData`), the final
   model at the paper's resolution (4,399 tissue particles) and a coarser *search* model
   (1,000 by default, ~10× cheaper a run; with ``search_integrator = "reduced"`` its
   reduced model, ~50× cheaper again) (:func:`~.model.model_spec`), the search space (a
   driven bar's friction a coordinate, :mod:`.space`) and the evaluator that runs every batch
   of forward runs in parallel on Dask (:class:`~.evaluator.Evaluator`).
3. **Search, assess, and reach the final model** — one strategy
   (:mod:`.strategies`, chosen by the search model): the best of a small data-free initial
   design, then bounded least squares (default), CMA-ES or the paper's Table 1 algorithm, and
   the fit's standard errors from the Jacobian with the F–E–β1 scaling the push cannot see.

   * :class:`~.strategies.SpaceMapping` (implicit search model): output space mapping moves
     the fit to where the final model fits, or keeps the search model where it fits better.
   * :class:`~.strategies.ReducedTrustRegion` (reduced search model): each fit checked by one
     run of the full model and the reduced model made again where they disagree; a second
     pass on the final model's own reduced model where it is finer.
4. **Resolution** (``resolution_check``, off by default): the fit run again on twice the
   particles (:mod:`.resolution`), with a warning where the points move by more than a pixel;
   how far that finer model would move each coordinate is the model's numerical error, added in
   quadrature to the data's standard error (ASME V&V 20) before "determined" is read off it.
5. **The online model** (``online_model``, on by default): the fitted model's reduced model's
   two full runs over the whole series, on the cluster's cores while it is up, kept with the
   calibration (:class:`~.model.ReducedSnapshots`) and saved with it, so that the online loop
   makes its model from them instead of running them before its first frame.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.errors import InputError, brief
from hifumotion.estimation import fit as fitting
from hifumotion.estimation.evaluator import Evaluator
from hifumotion.estimation.model import (ModelSettings, ModelSpec, Parameters, ReducedSnapshots, forward_model,
                                         model_spec)
from hifumotion.estimation.objective import TrainingData
from hifumotion.estimation.prepare import Observation
from hifumotion.estimation.protocol import default_frames, parse_frames
from hifumotion.estimation.resolution import ResolutionCheck, resolution_check
from hifumotion.estimation.settings import CalibrationSettings
from hifumotion.estimation.space import FRICTION_BOUNDS, FRICTION_NAME, SearchSpace
from hifumotion.estimation.stability import HoldoutShift, holdout_shift
from hifumotion.estimation.strategies import Assessment, SearchJob, SearchRecord, strategy_for

log = logging.getLogger(__name__)

OBJECTIVES = ("auto", "contour", "contour+displacement")


@dataclass
class Calibration:
    """The outcome of :func:`calibrate`."""

    parameters: Parameters
    std: dict                       # standard error of each fitted coordinate
    determined: dict                # coordinate -> whether the data determine it
    training_frames: list[int]
    search: fitting.FitResult | None
    table1: object | None
    record: SearchRecord            # what the search strategy did (strategies.SpaceMappingRecord or TrustRegionRecord)
    degeneracy: list
    correlation: list
    spec: ModelSpec                 # the model kept: the final (paper-resolution) one, or the search model if it fits better
    search_spec: ModelSpec
    observation: Observation
    runs: int
    timings_s: dict = field(default_factory=dict)
    failed_runs: int = 0            # forward runs that failed (logged, not used as data)
    objective: str = "contour"      # what was fitted (CalibrationSettings.objective resolved)
    summary: dict | None = None     # parameters.json, once written
    resolution: dict | None = None  # the fit on twice the particles (CalibrationSettings.resolution_check); std_data: the errors before its numerical error was added
    assessment: Assessment | None = None   # the Jacobian and residuals the uncertainty came from
    holdout_shift: HoldoutShift | None = None   # the fit against the fit on the earlier training frames
    online_snapshots: ReducedSnapshots | None = None   # the online loop's reduced model's runs (CalibrationSettings.online_model)

    def coordinates(self) -> dict:
        """The fit's coordinates by name (:mod:`.space`: ln E, ν, ln β1, β2 and ln μ_f if fitted)."""
        space = SearchSpace(force_n=self.parameters.force_n,
                            friction=FRICTION_BOUNDS if FRICTION_NAME in self.std else None)
        return dict(zip(space.names, space.theta(self.parameters).tolist()))

    def compare_with_earlier(self, earlier: "Calibration") -> HoldoutShift:
        """Compare this fit with ``earlier``, the same calibration on the earlier training frames
        only (:mod:`.stability`); :meth:`report` then reports a coordinate that moved by more than
        the earlier fit's errors allow as not determined, and says why."""
        self.holdout_shift = holdout_shift(self.coordinates(), earlier.coordinates(), earlier.std,
                                           earlier.training_frames)
        return self.holdout_shift

    def caveats(self) -> list[str]:
        """Why the fit's uncertainties are not to be read as those of a converged fit: the search
        stopped at its budget of evaluations (its Jacobian and residuals are of a point on the
        way, not of a minimum), or the full model's check at the fit disagreed with the model the
        search ran on. One sentence each; empty when neither holds."""
        out = []
        if self.search is not None and not self.search.converged:
            out.append(f"the search stopped at its budget of evaluations ({self.search.message.strip() or 'no message'}) "
                       "before it converged: its uncertainties are of a point on the way, not of a minimum")
        check = self.record.fit_check
        if check is not None and not check.agrees:
            ratio = check.cost_full_mm / max(check.cost_reduced_mm, 1e-12)
            out.append(f"the full model's training cost at the fit is {ratio:.2f}× the reduced model's: the model "
                       "the search ran on does not hold there")
        return out

    def report(self) -> dict:
        """Values with uncertainties and what is identifiable, as written to ``parameters.json``.

        Where :meth:`caveats` lists a reason, no value is reported as determined: a standard
        error from a search that did not converge, or from a model the check refuted, is no
        measure of how well the data fix a parameter."""
        k = self.parameters
        rel = {n: float(s) for n, s in self.std.items()}
        e_std = k.youngs_modulus_pa * rel["log_E"]
        b_std = k.beta1 * rel["log_beta1"]
        out = {
            "external_force_n": {"value": k.force_n, "std": None, "determined": False,
                                 "note": "held at the nominal force: a quasi-static push shows only F/E"},
            "youngs_modulus_pa": {"value": k.youngs_modulus_pa, "std": e_std, "determined": self.determined["log_E"],
                                  "note": "at the nominal force; F/E is what the data fix"},
            "poisson_ratio": {"value": k.poisson_ratio, "std": rel["nu"], "determined": self.determined["nu"]},
            "beta1_pa_s_pow": {"value": k.beta1, "std": b_std, "determined": self.determined["log_beta1"],
                               "note": "at the nominal force; β1/E is what the data fix"},
            "beta2": {"value": k.beta2, "std": rel["beta2"], "determined": self.determined["beta2"]},
            "force_over_youngs_m2": {"value": k.force_n / k.youngs_modulus_pa,
                                     "std": k.force_n / k.youngs_modulus_pa * rel["log_E"],
                                     "determined": self.determined["log_E"]},
            "beta1_over_youngs_s_pow": {"value": k.beta1 / k.youngs_modulus_pa,
                                        "std": k.beta1 / k.youngs_modulus_pa * float(np.hypot(rel["log_E"], rel["log_beta1"])),
                                        "determined": self.determined["log_beta1"]},
        }
        if FRICTION_NAME in rel:
            out["friction"] = {"value": k.friction, "std": k.friction * rel[FRICTION_NAME],
                               "determined": self.determined[FRICTION_NAME],
                               "note": "Coulomb's μ_f of the floor and the bar's face, fitted (a driven bar's slide)"}
        for entry in out.values():   # an error no data bound is "unknown", not a number
            if entry["std"] is not None and not np.isfinite(entry["std"]):
                entry["std"] = None
        at_bound = {} if self.assessment is None else self.assessment.uncertainty.at_bound
        for coordinate, entries in _REPORTED_BY.items():
            if at_bound.get(coordinate):
                for name in entries:
                    if name in out:
                        out[name]["not_determined_because"] = "the fit lies on its search bound"
        for coordinate in ([] if self.holdout_shift is None else self.holdout_shift.moved):
            for name in _REPORTED_BY.get(coordinate, ()):
                if name in out and out[name]["determined"]:
                    out[name]["determined"] = False
                    out[name]["not_determined_because"] = self.holdout_shift.reason(coordinate)
        if self.caveats():
            for entry in out.values():
                if entry["determined"]:
                    entry["determined"] = False
                    entry["not_determined_because"] = "the fit's caveats (fit.caveats)"
        return out


def calibrate(observation: Observation, settings: CalibrationSettings | None = None,
              log_path: str | Path | None = None, progress: Callable[[str, float], None] | None = None
              ) -> Calibration:
    """Steps 2–5 of the module docstring on a prepared observation: the training data and the
    models, then the strategy (:func:`~.strategies.strategy_for`) on the search model's
    evaluator and the online model's runs, then the uncertainty it assessed and the resolution
    check."""
    s = settings or CalibrationSettings()
    tell = progress or (lambda stage, fraction: None)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    frames, data, objective, (final, search, space, driven) = _prepare_search(observation, s)
    timings["model_s"] = time.perf_counter() - t0
    asked = {"n": 0}

    def on_run(done, total):
        asked["n"] += 1
        tell("search", min(asked["n"] / _expected_runs(s), 0.99))

    ev = Evaluator(search, data, space, log_path=log_path, scheduler_address=s.scheduler_address,
                   workers=s.workers, progress=on_run)
    with ev.cluster():
        outcome = strategy_for(s).run(SearchJob(ev, s, search, final, driven, timings, tell))
        online = _online_snapshots(ev, outcome.model, space.parameters(outcome.theta), observation, timings, tell) \
            if s.online_model else None
    theta, unc = outcome.theta, outcome.assessment.uncertainty
    std = {n: float(v) for n, v in zip(space.names, unc.std)}   # inf: not seen by the data
    determined = dict(unc.determined)
    resolution = None
    if s.resolution_check:
        check = _resolution(outcome.model, space.parameters(theta), observation, frames, timings, tell,
                            data, outcome.assessment.jacobian, space.names)
        resolution = {**check.as_dict(), "std_data": std}
        # the model's numerical error joins the data's: what is determined is read off both
        std = check.with_numerical_error(std)
        determined = {n: determined[n] and fitting.below_relevance(n, std[n]) for n in determined}
    return Calibration(space.parameters(theta), std, determined, list(map(int, frames)), outcome.fit,
                       outcome.table1, outcome.record, outcome.assessment.degeneracy,
                       unc.correlation.round(3).tolist(), outcome.model, search, observation, ev.runs, timings,
                       ev.failed, objective, resolution=resolution, assessment=outcome.assessment,
                       online_snapshots=online)


def _prepare_search(observation: Observation, s: CalibrationSettings):
    """Step 2: the training frames and data, the objective, the final and search models and the
    search space (a driven bar's friction a coordinate unless ``fit_friction`` says otherwise)."""
    n_frames = len(observation.frame_masks)
    frames = parse_frames(s.training_frames, n_frames, "training_frames") or default_frames(n_frames)[0]
    final = model_spec(observation, s.model)
    driven = final.scene.bar.enabled and final.scene.bar.control == "travel"
    fit_friction = driven if s.fit_friction is None else s.fit_friction
    space = SearchSpace(force_n=s.force_n, friction=FRICTION_BOUNDS if fit_friction else None)
    search_settings = ModelSettings(**{**s.model.__dict__, "integrator": s.search_integrator,
                                       "tissue_particles": min(s.search_particles, s.model.tissue_particles)})
    search = model_spec(observation, search_settings)
    data, objective = _training_data(observation, s, frames, search.points_mm)
    return frames, data, objective, (final, search, space, driven)


def _training_data(observation: Observation, s: CalibrationSettings, frames, points_mm: np.ndarray):
    """The training frames' contours, with the speckle's displacements, its quality weights and the
    bar's tracked shift where the settings ask for them and the observation has them; and the
    objective resolved. ``points_mm`` are the points A both models carry (frame 0's contour
    resampled), so one set serves the search and the final model."""
    data = TrainingData.from_masks(observation.frame_masks, frames, observation.frame_plane)
    if s.objective not in OBJECTIVES:
        raise InputError(f"unknown objective {s.objective!r}; expected {', '.join(OBJECTIVES)}", "objective")
    objective = objective_for(s.objective, observation)
    if objective == "contour+displacement":
        if observation.motion is None:
            raise InputError("the displacement objective needs speckle tracking (tracking = speckle)", "objective")
        data = data.with_displacement(observation.motion.displacement, points_mm)
    if s.quality_weights and observation.motion is not None and observation.contour_source == "speckle":
        try:
            data = data.with_contour_weights(observation.motion.displacement, points_mm)
        except InputError:
            pass    # the speckle shows none of the points: every point keeps weight 1, as without weights
    shift = None if observation.motion is None else observation.motion.displacement.rigid_shift_mm
    if s.bar_motion and shift is not None and observation.observed.setup.bar.enabled:
        data = data.with_bar(shift, len(points_mm))
    return data, objective


def _online_snapshots(ev: Evaluator, model: ModelSpec, k: Parameters, observation: Observation, timings: dict,
                      tell) -> ReducedSnapshots | None:
    """Step 5: the full runs the online loop's reduced model of the fitted ``model`` around ``k``
    is made from, over the whole series, in parallel on the cluster: offered to ``model`` and
    saved with the calibration, they spare the online loop two full runs before its first frame.
    A failure costs the calibration nothing: the online loop then runs them itself (said in one
    line)."""
    t0 = time.perf_counter()
    tell("online model", 0.0)
    last = len(observation.frame_masks) - 1
    try:
        runs = ev.snapshot_runs(model, k, last)
    except Exception as exc:       # noqa: BLE001 — the fit stands; only the online loop's head start is lost
        log.warning("the online loop's reduced model was not made (%s); hifumotion online will make it", brief(exc))
        return None
    finally:
        timings["online_model_s"] = time.perf_counter() - t0
    tell("online model", 1.0)
    snapshots = ReducedSnapshots(k, last, tuple(runs))
    model.offer_reduced(snapshots)     # the calibration held in memory (hifumotion run) uses them too
    return snapshots


def _resolution(model: ModelSpec, parameters: Parameters, observation: Observation, frames,
                timings: dict, tell, data: TrainingData, jacobian: np.ndarray, names) -> ResolutionCheck:
    """Step 4: the fit run again on twice the particles, with a warning where it is not resolved,
    and how far the finer model would move each coordinate (its numerical error)."""
    t0 = time.perf_counter()
    tell("resolution", 0.0)
    check = resolution_check(model, parameters, observation, int(max(frames)), data=data, jacobian=jacobian,
                             names=names)
    timings["resolution_check_s"] = time.perf_counter() - t0
    tell("resolution", 1.0)
    if not check.resolved:
        log.warning("the fitted model is not resolved: on %d particles its points A move %.2f mm from where "
                    "%d put them (more than a %.2f mm pixel); fit with more particles", check.particles[1],
                    check.largest_mm, check.particles[0], check.pixel_mm)
    return check


#: the fitted coordinate → the parameters.json entries its value and error give
_REPORTED_BY = {"log_E": ("youngs_modulus_pa", "force_over_youngs_m2"), "nu": ("poisson_ratio",),
                "log_beta1": ("beta1_pa_s_pow", "beta1_over_youngs_s_pow"), "beta2": ("beta2",),
                FRICTION_NAME: ("friction",)}


def recovered_parameters(report: dict, k: Parameters, truth: dict) -> dict:
    """The fit beside the truth (a twin's ``truth/parameters.json``) on what the data can fix:
    F/E and β1/E (the push's scaling leaves only these), ν and β2 — value, truth, relative
    error and whether the data determine it (``report``: :meth:`Calibration.report`)."""
    e = truth["youngs_modulus_pa"]
    pairs = {
        "force_over_youngs_m2": (k.force_n / k.youngs_modulus_pa, truth["external_force_n"] / e),
        "beta1_over_youngs_s_pow": (k.beta1 / k.youngs_modulus_pa, truth["beta1_pa_s_pow"] / e),
        "poisson_ratio": (k.poisson_ratio, truth["poisson_ratio"]),
        "beta2": (k.beta2, truth["beta2"]),
    } if truth.get("external_force_n") is not None else {
        # a driven bar (travel control): no force was pushed, so there is no F/E to recover
        "beta1_over_youngs_s_pow": (k.beta1 / k.youngs_modulus_pa, truth["beta1_pa_s_pow"] / e),
        "poisson_ratio": (k.poisson_ratio, truth["poisson_ratio"]),
        "beta2": (k.beta2, truth["beta2"]),
    }
    if "friction" in report and truth.get("friction"):
        pairs["friction"] = (k.friction, truth["friction"])
    return {name: {"fit": fit, "truth": true, "rel_error": fit / true - 1, "std": report[name]["std"],
                   "determined": report[name]["determined"]} for name, (fit, true) in pairs.items()}


def objective_for(asked: str, observation: Observation) -> str:
    """The objective ``asked`` for (:data:`OBJECTIVES`) on this observation: ``"auto"`` is
    ``contour+displacement`` where speckle tracking observed the motion, ``contour`` where
    the contours were given or re-segmented (no tracked displacement exists)."""
    if asked != "auto":
        return asked
    return "contour+displacement" if observation.motion is not None else "contour"


def _expected_runs(s: CalibrationSettings) -> int:
    """A rough count of search runs, for the progress bar."""
    p = 4
    reduced = forward_model(s.search_integrator).is_reduced
    passes = 2 if reduced and s.search_particles < s.model.tissue_particles else 1
    if s.method == "least_squares":
        return 6 + passes * s.max_evaluations * (p + 1) + 2 * p + 3
    if s.method == "cmaes":
        return 6 + passes * s.cma_generations * (4 + int(3 * np.log(p))) + 2 * p + 3
    return 6 + passes * s.table1_max_runs + 2 * p + 3


__all__ = ["CalibrationSettings", "Calibration", "calibrate", "objective_for", "OBJECTIVES"]
