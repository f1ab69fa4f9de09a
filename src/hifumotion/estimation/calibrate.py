"""Calibrate the particle model on an observed experiment: one documented order.

1. **Observe** (:func:`~.prepare.prepare`): segment the sweep, reconstruct, track the frames.
2. **Model** (:func:`~.model.model_spec`): the paper's resolution (4,399 tissue
   particles) for the final model, and a coarser *search* model (1,000 by default)
   whose runs are ~10× cheaper; or (``search_integrator = "reduced"``) the search
   model's reduced model (:mod:`hifumotion.creep.reduced`), ~50× cheaper again.
3. **Search** on the search model, every batch of runs in parallel on Dask:
   the best of a small data-free initial design, then bounded least squares
   (default), CMA-ES, or the paper's Table 1 algorithm. A reduced search model is
   made around the design's centre (its two snapshot runs in parallel; for a driven
   bar whose friction is fitted, runs at the program's own travel at the design's two
   friction levels, :func:`_centre_model`); the full model
   is run at the design's best start and the reduced model made again around it with
   that run among its snapshots; the search runs from there. Each fit of a reduced
   search is checked by one run of the full model (``full_model_check``); where the two
   disagree, the model is made again around the fit from every full run so far and
   searched again (:func:`_reduced_search`: a greedy enrichment of the snapshots; the
   checked fit the full model fits best is kept, its residual beside the reduced one's
   in ``parameters.json``, a warning where they still disagree). Where the final model
   is finer than the search model, the search runs a second time, from its optimum, on
   the final model's own reduced model made around that optimum. With a fitted friction
   each search on a reduced model keeps μ_f within a trust region around the μ_f the
   model was made at, and a fit that stops at its edge has the model made again too.
4. **Map to the paper's resolution** (implicit search only; output space mapping): a run of the final
   model at the search optimum; the difference of its residuals from the search
   model's is taken as fixed, and a Gauss–Newton step with the search model's
   Jacobian moves the parameters to where the final model fits; repeated
   (``mapping_runs`` runs of the final model), keeping the best parameters the
   final model was actually run with. If the search model at its own fit still fits the
   training frames better than the final model does at its best (``keep_better_model``),
   the search model is the one the calibration keeps: the finer mesh is not always the
   better model of a slide (its bar's trailing rim can catch the sample, docs/decisions.md).
5. **Uncertainty**: standard errors and identifiability from the Jacobian; the
   F–E–β1 scaling the push cannot see, run and reported.
6. **Resolution** (``resolution_check``, off by default): the fit run again on twice the
   particles (:mod:`.resolution`), with a warning where the points move by more than a pixel.
"""

from __future__ import annotations

import logging
import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.errors import InputError
from hifumotion.estimation import fit as fitting
from hifumotion.estimation.evaluator import Evaluator
from hifumotion.estimation.iterative import iterative_estimate
from hifumotion.estimation.model import ModelSettings, ModelSpec, Parameters, forward_model, model_spec
from hifumotion.estimation.settings import CalibrationSettings
from hifumotion.estimation.objective import TrainingData, frame_sums_mm
from hifumotion.estimation.prepare import Observation
from hifumotion.estimation.protocol import default_frames, parse_frames
from hifumotion.estimation.resolution import resolution_check
from hifumotion.estimation.space import FRICTION_BOUNDS, FRICTION_NAME, SearchSpace

log = logging.getLogger(__name__)

OBJECTIVES = ("auto", "contour", "contour+displacement")
#: Largest space-mapping move per coordinate, in units of 10 finite-difference steps
#: (ln E, ln β1 by 1.0: a factor 2.7; ν by 0.2; β2 by 1.0).
MAX_MAPPING_STEP = 2.0


@dataclass
class Calibration:
    """The outcome of :func:`calibrate`."""

    parameters: Parameters
    std: dict                       # standard error of each fitted coordinate
    determined: dict                # coordinate -> whether the data determine it
    training_frames: list[int]
    search: fitting.FitResult | None
    table1: object | None
    mapped: dict                    # the space-mapping step: before/after
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
    resolution: dict | None = None  # the fit on twice the particles (CalibrationSettings.resolution_check)

    def caveats(self) -> list[str]:
        """Why the fit's uncertainties are not to be read as those of a converged fit: the search
        stopped at its budget of evaluations (its Jacobian and residuals are of a point on the
        way, not of a minimum), or the full model's check at the fit disagreed with the model the
        search ran on. One sentence each; empty when neither holds."""
        out = []
        if self.search is not None and not self.search.converged:
            out.append(f"the search stopped at its budget of evaluations ({self.search.message.strip() or 'no message'}) "
                       "before it converged: its uncertainties are of a point on the way, not of a minimum")
        check = (self.mapped or {}).get("full_model_check")
        if check is not None and not check.get("agrees", True):
            ratio = check["cost_full_model_mm"] / max(check["cost_reduced_model_mm"], 1e-12)
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
        if self.caveats():
            for entry in out.values():
                if entry["determined"]:
                    entry["determined"] = False
                    entry["not_determined_because"] = "the fit's caveats (fit.caveats)"
        return out


def calibrate(observation: Observation, settings: CalibrationSettings | None = None,
              log_path: str | Path | None = None, progress: Callable[[str, float], None] | None = None
              ) -> Calibration:
    """Steps 2–5 of the module docstring on a prepared observation."""
    s = settings or CalibrationSettings()
    tell = progress or (lambda stage, fraction: None)
    timings: dict[str, float] = {}
    n_frames = len(observation.frame_masks)
    frames = parse_frames(s.training_frames, n_frames, "training_frames") or default_frames(n_frames)[0]
    data = TrainingData.from_masks(observation.frame_masks, frames, observation.frame_plane)
    t0 = time.perf_counter()
    final = model_spec(observation, s.model)
    driven = final.scene.bar.enabled and final.scene.bar.control == "travel"
    fit_friction = driven if s.fit_friction is None else s.fit_friction
    space = SearchSpace(force_n=s.force_n, friction=FRICTION_BOUNDS if fit_friction else None)
    search_settings = ModelSettings(**{**s.model.__dict__, "integrator": s.search_integrator,
                                       "tissue_particles": min(s.search_particles, s.model.tissue_particles)})
    search = model_spec(observation, search_settings)
    if s.objective not in OBJECTIVES:
        raise InputError(f"unknown objective {s.objective!r}; expected {', '.join(OBJECTIVES)}", "objective")
    objective = objective_for(s.objective, observation)
    if objective == "contour+displacement":
        if observation.motion is None:
            raise InputError("the displacement objective needs speckle tracking (tracking = speckle)", "objective")
        # both models carry the same points A (frame 0's contour resampled), so one set serves both
        data = data.with_displacement(observation.motion.displacement, search.points_mm)
    if s.quality_weights and observation.motion is not None and observation.contour_source == "speckle":
        try:
            data = data.with_contour_weights(observation.motion.displacement, search.points_mm)
        except InputError:
            pass    # the speckle shows none of the points: every point keeps weight 1, as without weights
    shift = None if observation.motion is None else observation.motion.displacement.rigid_shift_mm
    if s.bar_motion and shift is not None and observation.observed.setup.bar.enabled:
        data = data.with_bar(shift, len(search.points_mm))
    timings["model_s"] = time.perf_counter() - t0

    asked = {"n": 0}

    def on_run(done, total):
        asked["n"] += 1
        tell("search", min(asked["n"] / _expected_runs(s), 0.99))

    ev = Evaluator(search, data, space, log_path=log_path, scheduler_address=s.scheduler_address,
                   workers=s.workers, progress=on_run)
    fit_result = table1 = None
    mapped: dict = {}
    degeneracy: list = []
    with ev.cluster():
        t1 = time.perf_counter()
        reduced = forward_model(search_settings).is_reduced
        centres = []
        checks: list[dict] = []
        if reduced:     # the modes around the design's centre: every start is within a factor 4 of it
            centres.append(np.mean(space.initial_design(), axis=0))
            timings["reduced_models_s"] = [_centre_model(ev, s, centres[-1], driven)]
        theta0, design = fitting.initial_guess(ev)
        start = None
        if reduced:
            # the design's best start may be a factor 4 from the centre, where the centre's model may
            # not hold (a reduced model slides on where the full one sticks): the full model at the
            # best start of each of the design's friction levels (one run each, in parallel) picks
            # the start, and the model is made again around it from those runs and the centre's
            if s.full_model_check:
                starts = _checks(ev, _design_starts(design, space), s)
                mapped["start_checks"] = [_summary(c) for c in starts]
                start = min(starts, key=lambda c: c["cost_full_model_mm"])
                theta0 = start["theta"]
            centres.append(theta0)
            timings["reduced_models_s"].append(ev.reduce_around(theta0, new_runs=not s.full_model_check))
        fit_result, table1, theta = (_reduced_search(ev, s, theta0, centres, timings["reduced_models_s"], checks,
                                                     start) if reduced else _search(ev, s, theta0))
        fit_spec = final
        # the search model was coarser than the final one: a second pass on the final model's own
        second_pass = reduced and search_settings.tissue_particles < s.model.tissue_particles
        if second_pass:
            # the final model's own reduced model, its modes around the first optimum, so that the
            # fit ends on the final model near its own parameters (no space mapping between two
            # resolutions is left to do)
            final.voxels()      # made once here: the workers' snapshot runs and this process share it
            fit_spec = replace(final, settings=replace(final.settings, integrator="reduced"))
            centres.append(theta)
        with (ev.sibling(fit_spec) if second_pass else nullcontext(ev)) as fit_ev:
            if second_pass:
                timings["reduced_models_s"].append(fit_ev.reduce_around(theta))
                checks = []     # the search model's checks were of another model
                fit_result, table1, theta = _reduced_search(fit_ev, s, theta, centres, timings["reduced_models_s"],
                                                            checks)
            if reduced:
                timings["reduced_model_s"] = sum(timings["reduced_models_s"])
                timings["reductions"] = ev.reductions + (fit_ev.reductions if second_pass else [])
                mapped["reduced_model_centres"] = [c.tolist() for c in centres]
            timings["search_s"] = time.perf_counter() - t1
            check = None
            if reduced and s.full_model_check:
                # the full model at the fit (the check the search ended with)
                pool = checks + ([start] if start is not None and not second_pass else [])
                # (a fit found again by a later round: the check of the round that found it first)
                check = next(c for c in pool if np.array_equal(c["theta"], theta))
            t2 = time.perf_counter()
            # the errors from the scatter of the model that was fitted (the full model's at the
            # fit, where it was run), the reduced model's Jacobian
            unc = fitting.uncertainty(fit_ev, theta, None if check is None else check["r_full"])
            j = fitting.jacobian(fit_ev, theta)
            if s.degeneracy_check:
                degeneracy = fitting.degeneracy(fit_ev, theta)
            timings["uncertainty_s"] = time.perf_counter() - t2
            tell("search", 1.0)
            if check is not None:
                # its residual beside the reduced model's (parameters.json), and every check of the search
                mapped["full_model_check"] = {key: value for key, value in check.items() if key not in ("theta", "r_reduced", "r_full")}
                mapped["full_model_check"]["rounds"] = [_summary(c) for c in checks]
                if not check["agrees"]:
                    log.warning("the full model's training cost at the fit is %.2f× the reduced model's (%.1f against "
                                "%.1f mm): the reduced model does not hold there; calibrate with "
                                "search_integrator = implicit", check["cost_full_model_mm"] / check["cost_reduced_model_mm"],
                                check["cost_full_model_mm"], check["cost_reduced_model_mm"])

        # one model only (the search ran at the final resolution): nothing to map
        coarser = search_settings.tissue_particles < s.model.tissue_particles
        if s.space_mapping and s.mapping_runs > 0 and coarser and not reduced:
            t3 = time.perf_counter()
            r_search = ev.one(theta)
            # only the coordinates the data determine move, by at most MAX_MAPPING_STEP step units
            # a step: the search model's Jacobian is a linearisation, not a licence for long jumps
            free = np.array([unc.determined[n] for n in space.names])
            limit = MAX_MAPPING_STEP * space.steps * 10
            tried = []
            current = theta
            with ev.sibling(final) as fine_ev:
                for _ in range(s.mapping_runs):
                    r_fine = fine_ev.one(current)
                    tried.append((float(np.abs(r_fine).sum()), current, r_fine))
                    if len(tried) > 1 and tried[-1][0] >= tried[-2][0]:
                        break   # the last step made the final model fit worse: stop there
                    step = np.zeros_like(current)
                    if free.any():
                        sub, *_ = np.linalg.lstsq(j[:, free], -r_fine.ravel(), rcond=None)
                        step[free] = sub
                    current = np.clip(current + np.clip(step, -limit, limit), space.lower, space.upper)
                    tell("map", len(tried) / s.mapping_runs)
            best_cost, best_theta, best_r = min(tried, key=lambda t: t[0])
            search_cost = float(np.abs(r_search).sum())
            keep_search = s.keep_better_model and search_cost < best_cost
            mapped = {**mapped, "theta_search": theta.tolist(), "theta_final": best_theta.tolist(),
                      "cost_search_model_mm": search_cost,
                      "final_model_costs_mm": [c for c, _, _ in tried],
                      "cost_final_model_mm": best_cost,
                      "S_t_final_model_mm": frame_sums_mm(best_r).round(3).tolist(),
                      "model_kept": "search" if keep_search else "final"}
            if keep_search:
                # the same training frames, the same objective: the search model fits them better
                final = search
            else:
                theta = best_theta
            timings["space_mapping_s"] = time.perf_counter() - t3
            tell("map", 1.0)
    std = {n: float(v) for n, v in zip(space.names, unc.std)}   # inf: not seen by the data
    resolution = None
    if s.resolution_check:
        t4 = time.perf_counter()
        tell("resolution", 0.0)
        check = resolution_check(final, space.parameters(theta), observation, int(max(frames)))
        resolution = check.as_dict()
        timings["resolution_check_s"] = time.perf_counter() - t4
        tell("resolution", 1.0)
        if not check.resolved:
            log.warning("the fitted model is not resolved: on %d particles its points A move %.2f mm from where "
                        "%d put them (more than a %.2f mm pixel); fit with more particles", check.particles[1],
                        check.largest_mm, check.particles[0], check.pixel_mm)
    return Calibration(space.parameters(theta), std, unc.determined, list(map(int, frames)), fit_result, table1,
                       mapped, degeneracy, unc.correlation.round(3).tolist(), final, search, observation,
                       ev.runs, timings, ev.failed, objective, resolution=resolution)


def _reduced_search(ev: Evaluator, s: CalibrationSettings, theta0: np.ndarray, centres: list, made_s: list,
                    checks: list, start: dict | None = None):
    """:func:`_search` on ``ev``'s reduced model, made at ``centres[-1]``, checked by the full model.

    With ``s.full_model_check`` each search's fit is run once on the full model (:func:`_checks`,
    appended to ``checks``). A fit is accepted where the two agree (within
    ``s.reduced_agreement``), the full model fits it better than every point checked before
    (``start``, the full model's check of ``theta0``, among them) and the search converged there
    (not stopped by its budget). Otherwise the reduced model is
    made again — its modes now including that run (a greedy enrichment of the snapshots, as in
    trust-region POD: Arian, Fahl & Sachs 2000) — around the best point checked so far, and
    searched again from there, ``s.reduced_rounds`` times at most; the point the full model fits
    best is returned. A search that does not leave a point the full model has run ends the
    rounds without running it again.

    With a fitted friction each search keeps μ_f within ``s.reduced_friction_trust`` of the μ_f the
    model was made at: two sliding snapshots hold a slide near the μ_f they were made at, not a
    stick far above it (a search free to go there ended at μ_f 0.95 on slide_stop_s49, where the
    full model's cost was 28× the reduced one's; docs/decisions.md, issue 41, session 35). A fit
    that stops at that edge — not at the space's own bound — has the model made again around it
    too. ``centres`` and ``made_s`` (seconds) grow with each model made."""
    whole = ev.space
    best = None
    if start is not None:
        kept = fitting.FitResult(start["theta"], start["r_reduced"], "design", 0, 0, [],
                                 "the design's start: the full model fits no searched fit better")
        best = (start, (kept, None, start["theta"]))
    for round_ in range(s.reduced_rounds + 1):
        trusted = whole.friction_within(centres[-1], s.reduced_friction_trust)
        correction = _correction_at(ev, best[0] if best is not None else None, centres[-1], s)
        with ev.within(trusted), ev.corrected(correction):
            result = _search(ev, s, theta0)
        theta = result[2]
        edge = trusted is not whole and _at_trust_edge(theta[4], trusted, whole)
        last = round_ == s.reduced_rounds
        if not s.full_model_check:
            if not edge or last:
                return result
            centres.append(theta)
            made_s.append(ev.reduce_around(theta))
            theta0 = theta
            continue
        if any(np.array_equal(c["theta"], theta) for c in ([best[0]] if best is not None else []) + checks):
            # the search stayed where the full model has run (its start: the centre, where the
            # corrected model is the full one). Its step is zero; a model made again there from
            # the same runs is the same model, so no later round moves either: converged
            break
        with ev.corrected(correction):    # the searched model's cost beside the full model's
            check, = _checks(ev, [theta], s)
        checks.append(check)
        better = best is None or check["cost_full_model_mm"] < best[0]["cost_full_model_mm"]
        if better:
            best = (check, result)
        # a search stopped by its budget, not at the model's optimum, goes on from its fit
        converged = result[0] is None or result[0].converged
        if (check["agrees"] and better and converged and not edge) or last:
            break
        # made again from every run so far, around the best point (the fit, or the point before
        # it where the full model fits this fit worse), and searched from there
        theta0 = best[0]["theta"]
        centres.append(theta0)
        made_s.append(ev.reduce_around(theta0, new_runs=False))
    return best[1][0], best[1][1], best[0]["theta"]


def _correction_at(ev: Evaluator, centre_check: dict | None, centre: np.ndarray, s: CalibrationSettings):
    """The full model's miss (mm, residuals) at the point ``ev``'s reduced model was made around,
    added to its residuals while it is searched (``s.reduced_correction``): zero-order consistency,
    as a trust-region method asks of its model (Alexandrov, Dennis, Lewis & Torczon 1998). A
    reduced model misses even its own snapshot's run where the sample sticks and slips (1.4× its
    cost on slide_stop_s50); uncorrected, the search follows that miss. None without a full run
    at that point (``centre_check``: its check, with its residuals ``r_full``)."""
    if not (s.reduced_correction and centre_check is not None
            and np.array_equal(np.asarray(centre_check["theta"], float), np.asarray(centre, float))):
        return None
    return centre_check["r_full"] - ev.one(centre)


def _centre_model(ev: Evaluator, s: CalibrationSettings, centre: np.ndarray, driven: bool) -> float:
    """Make ``ev``'s first reduced model, around the design's ``centre``; seconds taken.

    Its snapshots are the spec's (:meth:`~.model.ModelSpec.snapshot_scenes`: F/E, or a driven bar's
    travel, × 0.5 and × 2) — except where a driven bar's friction is fitted and the full model
    checks the search: a driven bar's travel is known, so its runs are at the program's own travel,
    at each of the design's friction levels instead (a slide and a near-stick, the two the design
    is ranked on; run in parallel and kept, ``Evaluator.full_runs``), the model made around the
    first. docs/decisions.md, issue 41, session 36."""
    space = ev.space
    if not (driven and space.friction and s.full_model_check):
        return ev.reduce_around(centre)
    started = time.perf_counter()
    levels = sorted({float(d[4]) for d in space.initial_design()})
    at = [np.append(np.asarray(centre, float)[:4], mu) for mu in levels]
    ev.full_runs(at)
    ran = time.perf_counter() - started
    return ran + ev.reduce_around(at[0], new_runs=False)


def _design_starts(design: list, space: SearchSpace) -> list[np.ndarray]:
    """The design's best start (``design``: :func:`~.fit.initial_guess`'s ``(cost, θ)``), and with
    a fitted friction the best of each of its friction levels: on a reduced model the level that
    slides the most may be ranked by a slide the full model does not make."""
    ranked = sorted(design, key=lambda d: d[0])
    if not space.friction:
        return [np.asarray(ranked[0][1], float)]
    levels = {}
    for cost, theta in ranked:
        levels.setdefault(round(float(theta[4]), 9), np.asarray(theta, float))
    return list(levels.values())


def _summary(check: dict) -> dict:
    """A check (:func:`_checks`) as a line of ``parameters.json``."""
    return {"theta": check["theta"].tolist(), "cost_reduced_model_mm": check["cost_reduced_model_mm"],
            "cost_full_model_mm": check["cost_full_model_mm"], "agrees": check["agrees"]}


def _checks(ev: Evaluator, thetas: list, s: CalibrationSettings) -> list[dict]:
    """Runs of the full model at each ``θ`` (in parallel, kept as snapshots:
    :meth:`Evaluator.full_runs`) beside the reduced model's: their training costs, per-frame sums
    and whether they agree (within ``s.reduced_agreement`` of each other)."""
    out = []
    for theta, r_full, r_reduced in zip(thetas, ev.full_runs(thetas), ev.residuals(thetas)):
        full, reduced = float(np.abs(r_full).sum()), float(np.abs(r_reduced).sum())
        low, high = min(full, reduced), max(full, reduced)
        ratio = 1.0 if high == 0 else (high / low if low > 0 else np.inf)
        out.append({"theta": np.asarray(theta, float).copy(), "r_reduced": r_reduced, "r_full": r_full,
                    "cost_reduced_model_mm": reduced, "cost_full_model_mm": full,
                    "S_t_reduced_model_mm": frame_sums_mm(r_reduced).round(3).tolist(),
                    "S_t_full_model_mm": frame_sums_mm(r_full).round(3).tolist(),
                    "agrees": bool(ratio <= s.reduced_agreement)})
    return out


def _at_trust_edge(log_mu: float, trusted: SearchSpace, whole: SearchSpace) -> bool:
    """Whether ``log_mu`` went nine tenths of the way to a bound of ``trusted`` that is not
    ``whole``'s (a bounded search stops near a bound, not on it)."""
    low, high = trusted.lower[4], trusted.upper[4]
    edge = 0.05 * (high - low)
    return bool((log_mu <= low + edge and low > whole.lower[4] + edge)
                or (log_mu >= high - edge and high < whole.upper[4] - edge))


def _search(ev: Evaluator, s: CalibrationSettings, theta0: np.ndarray):
    """``s.method`` from ``theta0`` on ``ev``'s model: ``(fit result, Table 1 result, θ)``."""
    if s.method == "least_squares":
        fit_result = fitting.least_squares_fit(ev, theta0, s.max_evaluations)
        return fit_result, None, fit_result.theta
    if s.method == "cmaes":
        fit_result = fitting.cmaes_fit(ev, theta0, s.cma_generations, seed=s.seed)
        return fit_result, None, fit_result.theta
    table1 = iterative_estimate(ev, theta0, s.threshold_mm_per_point, s.table1_max_runs)
    return None, table1, table1.theta


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
