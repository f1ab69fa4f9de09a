"""How the calibration searches: two strategies behind one protocol.

:func:`~.calibrate.calibrate` prepares the search (the training data, the search and final
models, the :class:`~.evaluator.Evaluator`), hands it to a strategy as a :class:`SearchJob`,
and turns what comes back (:class:`SearchOutcome`) into a
:class:`~.calibrate.Calibration`. A strategy runs the search, the uncertainty at its fit
(:func:`assess`, on the model the fit was made on) and whatever moves the fit to the final
model; it leaves a typed record of what it did, which ``parameters.json`` holds under
``fit.strategy``.

* :class:`SpaceMapping` — an implicit search model (``search_integrator = "implicit"``): the
  search on the coarse model, then output space mapping to the final model (Bandler et al.
  2004): a run of the final model at the fit, the difference of its residuals from the
  search model's held fixed, a Gauss–Newton step with the search model's Jacobian, repeated;
  the search model is kept where it fits the training frames better.
* :class:`ReducedTrustRegion` — a reduced search model (``search_integrator = "reduced"``):
  each search on a reduced model made around a point, each fit checked by one run of the
  full model (a :class:`Check`), the model made again where the two disagree (one
  :class:`Round` per search); where the final model is finer, a second pass on its own
  reduced model. A trust-region method with reduced models (Arian, Fahl & Sachs 2000;
  Alexandrov, Dennis, Lewis & Torczon 1998 for the zero-order correction).
"""

from __future__ import annotations

import logging
import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from typing import Callable, Protocol

import numpy as np

from hifumotion.estimation import fit as fitting
from hifumotion.estimation.evaluator import Evaluator
from hifumotion.estimation.iterative import iterative_estimate
from hifumotion.estimation.model import ModelSpec, forward_model
from hifumotion.estimation.objective import frame_sums_mm
from hifumotion.estimation.settings import CalibrationSettings
from hifumotion.estimation.space import FRICTION_NAME, SearchSpace

log = logging.getLogger(__name__)

#: Largest space-mapping move per coordinate, in units of 10 finite-difference steps
#: (ln E, ln β1 by 1.0: a factor 2.7; ν by 0.2; β2 by 1.0).
MAX_MAPPING_STEP = 2.0


# -- records ------------------------------------------------------------------------------------

@dataclass
class Check:
    """The full model run at ``theta`` beside the reduced model's run there: residuals (mm,
    ``(n, M)`` of the training frames) of each, and whether their training costs agree within
    the settings' ``reduced_agreement``."""

    theta: np.ndarray
    r_reduced: np.ndarray
    r_full: np.ndarray
    agrees: bool

    @property
    def cost_reduced_mm(self) -> float:
        return float(np.abs(self.r_reduced).sum())

    @property
    def cost_full_mm(self) -> float:
        return float(np.abs(self.r_full).sum())

    def summary(self) -> dict:
        """One line of ``parameters.json``."""
        return {"theta": self.theta.tolist(), "cost_reduced_model_mm": self.cost_reduced_mm,
                "cost_full_model_mm": self.cost_full_mm, "agrees": self.agrees}

    def as_dict(self) -> dict:
        """The costs, per-frame sums and agreement (``parameters.json``'s check at the fit)."""
        return {"cost_reduced_model_mm": self.cost_reduced_mm, "cost_full_model_mm": self.cost_full_mm,
                "S_t_reduced_model_mm": frame_sums_mm(self.r_reduced).round(3).tolist(),
                "S_t_full_model_mm": frame_sums_mm(self.r_full).round(3).tolist(), "agrees": self.agrees}


def run_checks(ev: Evaluator, thetas: list, agreement: float) -> list[Check]:
    """Runs of the full model at each ``θ`` (in parallel, kept as snapshots:
    :meth:`Evaluator.full_runs`) beside the reduced model's; they agree where the larger training
    cost is at most ``agreement`` times the smaller."""
    out = []
    for theta, r_full, r_reduced in zip(thetas, ev.full_runs(thetas), ev.residuals(thetas)):
        full, reduced = float(np.abs(r_full).sum()), float(np.abs(r_reduced).sum())
        low, high = min(full, reduced), max(full, reduced)
        ratio = 1.0 if high == 0 else (high / low if low > 0 else np.inf)
        out.append(Check(np.asarray(theta, float).copy(), r_reduced, r_full, bool(ratio <= agreement)))
    return out


@dataclass
class Round:
    """One search on one reduced model: the point the model was made around, the search's fit,
    the full model's check of it (None without ``full_model_check``, or where the search stayed
    on a point already checked), whether the search converged and whether it stopped at the
    edge of its friction trust region."""

    centre: np.ndarray
    theta: np.ndarray
    check: Check | None
    converged: bool
    at_trust_edge: bool


@dataclass
class SpaceMappingRecord:
    """What :class:`SpaceMapping` did: the search model's fit and cost, the final model's costs at
    each mapped point, the point kept and which model is kept (empty where one model only)."""

    theta_search: np.ndarray | None = None
    theta_final: np.ndarray | None = None
    cost_search_model_mm: float | None = None
    final_model_costs_mm: list[float] = field(default_factory=list)
    r_final: np.ndarray | None = None
    model_kept: str | None = None           # "search" or "final"

    name = "space_mapping"

    @property
    def fit_check(self) -> Check | None:
        """No reduced model, no check."""
        return None

    def as_dict(self) -> dict:
        out: dict = {"name": self.name}
        if self.model_kept is None:
            return out
        return {**out, "theta_search": self.theta_search.tolist(), "theta_final": self.theta_final.tolist(),
                "cost_search_model_mm": self.cost_search_model_mm,
                "final_model_costs_mm": list(self.final_model_costs_mm),
                "cost_final_model_mm": min(self.final_model_costs_mm),
                "S_t_final_model_mm": frame_sums_mm(self.r_final).round(3).tolist(),
                "model_kept": self.model_kept}


@dataclass
class TrustRegionRecord:
    """What :class:`ReducedTrustRegion` did: the full model's checks of the design's starts, the
    points each reduced model was made around (in order), the rounds of each pass (the search
    model's, then the final model's) and the check at the fit."""

    start_checks: list[Check] = field(default_factory=list)
    centres: list[np.ndarray] = field(default_factory=list)
    passes: list[list[Round]] = field(default_factory=list)
    fit_check: Check | None = None

    name = "reduced_trust_region"

    def as_dict(self) -> dict:
        out: dict = {"name": self.name, "reduced_model_centres": [np.asarray(c).tolist() for c in self.centres]}
        if self.start_checks:
            out["start_checks"] = [c.summary() for c in self.start_checks]
        if self.fit_check is not None:
            # every check the last pass made, beside the one at the fit
            last = self.passes[-1] if self.passes else []
            out["full_model_check"] = {**self.fit_check.as_dict(),
                                       "rounds": [r.check.summary() for r in last if r.check is not None]}
        out["rounds"] = [[{"centre": np.asarray(r.centre).tolist(), "theta": r.theta.tolist(),
                           "converged": r.converged, "at_trust_edge": r.at_trust_edge} for r in rounds]
                         for rounds in self.passes]
        return out


SearchRecord = SpaceMappingRecord | TrustRegionRecord


@dataclass
class Assessment:
    """The fit's uncertainty (:func:`~.fit.uncertainty`), its Jacobian (mm per coordinate), the
    residuals (mm, ``(n, M)``) whose scatter it used and, where asked, the F–E–β1 scaling's
    costs (:func:`~.fit.degeneracy`), all on the model the fit was made on."""

    uncertainty: fitting.Uncertainty
    jacobian: np.ndarray
    degeneracy: list
    residuals_mm: np.ndarray


def assess(ev: Evaluator, theta: np.ndarray, s: CalibrationSettings,
           residuals_mm: np.ndarray | None = None) -> Assessment:
    """The :class:`Assessment` at ``theta`` on ``ev``'s model; ``residuals_mm``: the scatter to
    use instead of the model's own (the full model's at the fit, where a reduced one gives the
    Jacobian)."""
    j = fitting.jacobian(ev, theta)
    r = ev.one(theta) if residuals_mm is None else np.asarray(residuals_mm, float)
    unc = fitting.uncertainty(ev, theta, r, jacobian_mm=j)
    return Assessment(unc, j, fitting.degeneracy(ev, theta) if s.degeneracy_check else [], r)


@dataclass
class SearchJob:
    """What a strategy is given: the evaluator of the search model (its cluster running), the
    settings, the search and final models, whether a driven bar's friction is fitted, where to
    put timings, and the progress callback."""

    ev: Evaluator
    settings: CalibrationSettings
    search: ModelSpec
    final: ModelSpec
    driven: bool
    timings: dict
    tell: Callable[[str, float], None]

    @property
    def space(self) -> SearchSpace:
        return self.ev.space

    @property
    def finer_final(self) -> bool:
        """Whether the final model has more particles than the search model."""
        return self.search.settings.tissue_particles < self.final.settings.tissue_particles


@dataclass
class SearchOutcome:
    """What a strategy returns: the fit, the search's own result (or Table 1's), its
    :class:`Assessment`, the model the calibration keeps and the strategy's record."""

    theta: np.ndarray
    fit: fitting.FitResult | None
    table1: object | None
    assessment: Assessment
    model: ModelSpec
    record: SearchRecord


class SearchStrategy(Protocol):
    """Search, assess the fit, and move it to the final model: :class:`SearchJob` → :class:`SearchOutcome`."""

    def run(self, job: SearchJob) -> SearchOutcome: ...


def strategy_for(settings: CalibrationSettings) -> SearchStrategy:
    """The strategy the settings' search model asks for: a reduced model's trust region, or an
    implicit search with space mapping."""
    return ReducedTrustRegion() if forward_model(settings.search_integrator).is_reduced else SpaceMapping()


def search_once(ev: Evaluator, s: CalibrationSettings, theta0: np.ndarray):
    """``s.method`` from ``theta0`` on ``ev``'s model: ``(fit result, Table 1 result, θ)``."""
    if s.method == "least_squares":
        fit_result = fitting.least_squares_fit(ev, theta0, s.max_evaluations)
        return fit_result, None, fit_result.theta
    if s.method == "cmaes":
        fit_result = fitting.cmaes_fit(ev, theta0, s.cma_generations, seed=s.seed)
        return fit_result, None, fit_result.theta
    table1 = iterative_estimate(ev, theta0, s.threshold_mm_per_point, s.table1_max_runs)
    return None, table1, table1.theta


# -- space mapping --------------------------------------------------------------------------------

class SpaceMapping:
    """Search on the implicit search model, assess there, then map the fit to the final model.

    The mapping (where the final model is finer and ``space_mapping``): a run of the final
    model at the current point; the difference of its residuals from the search model's is
    taken as fixed, and a Gauss–Newton step with the search model's Jacobian (only in the
    coordinates it sees sharply, :attr:`~.fit.Uncertainty.sharp`, at most :data:`MAX_MAPPING_STEP` step units a coordinate)
    moves the point; ``mapping_runs`` times at most, stopping when a step makes the final model
    fit worse. The best point the final model was run at is kept — or the search model, where it
    fits the training frames better (``keep_better_model``)."""

    def run(self, job: SearchJob) -> SearchOutcome:
        ev, s, t = job.ev, job.settings, job.timings
        started = time.perf_counter()
        theta0, _ = fitting.initial_guess(ev)
        fit, table1, theta = search_once(ev, s, theta0)
        t["search_s"] = time.perf_counter() - started
        assessed = time.perf_counter()
        assessment = assess(ev, theta, s)
        t["uncertainty_s"] = time.perf_counter() - assessed
        job.tell("search", 1.0)
        record = SpaceMappingRecord()
        model = job.final
        if s.space_mapping and s.mapping_runs > 0 and job.finer_final:
            mapped_at = time.perf_counter()
            theta, model = self._map(job, theta, assessment, record)
            t["space_mapping_s"] = time.perf_counter() - mapped_at
            job.tell("map", 1.0)
        return SearchOutcome(theta, fit, table1, assessment, model, record)

    @staticmethod
    def _map(job: SearchJob, theta: np.ndarray, assessment: Assessment, record: SpaceMappingRecord):
        ev, s, space = job.ev, job.settings, job.space
        r_search = ev.one(theta)
        free = np.array([assessment.uncertainty.sharp[n] for n in space.names])
        limit = MAX_MAPPING_STEP * space.steps * 10
        j = assessment.jacobian
        tried = []
        current = theta
        with ev.sibling(job.final) as fine_ev:
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
                job.tell("map", len(tried) / s.mapping_runs)
        best_cost, best_theta, best_r = min(tried, key=lambda item: item[0])
        search_cost = float(np.abs(r_search).sum())
        keep_search = s.keep_better_model and search_cost < best_cost
        record.theta_search, record.theta_final = theta, best_theta
        record.cost_search_model_mm, record.final_model_costs_mm = search_cost, [c for c, _, _ in tried]
        record.r_final, record.model_kept = best_r, "search" if keep_search else "final"
        # the same training frames, the same objective: the model that fits them better is kept
        return (theta, job.search) if keep_search else (best_theta, job.final)


# -- the reduced model's trust region ---------------------------------------------------------------

class ReducedTrustRegion:
    """Search on reduced models, each fit checked by the full model.

    1. The first reduced model is made around the design's centre (every start is within a
       factor 4 of it; a driven bar with a fitted friction: :meth:`_first_model`).
    2. The design's best start — with ``full_model_check``, the full model run at the best
       start of each of the design's friction levels picks it (a reduced model may slide where
       the full one sticks) — and the model made again around it.
    3. A pass (:meth:`_pass`): search, check, make the model again around the best point
       checked where the check disagrees, ``reduced_rounds`` times at most.
    4. Where the final model is finer, a second pass on the final model's own reduced model
       made around the first pass's fit, so that the fit ends on the final model near its own
       parameters (no space mapping between two resolutions is left to do).
    5. The uncertainty on the model of the last pass, with the full model's scatter at the fit.
    """

    def run(self, job: SearchJob) -> SearchOutcome:
        ev, s, space, t = job.ev, job.settings, job.space, job.timings
        record = TrustRegionRecord()
        made: list[float] = []
        started = time.perf_counter()
        record.centres.append(np.mean(space.initial_design(), axis=0))
        made.append(self._first_model(ev, s, record.centres[-1], job.driven))
        theta0, design = fitting.initial_guess(ev)
        start = None
        if s.full_model_check:
            record.start_checks = run_checks(ev, _design_starts(design, space), s.reduced_agreement)
            start = min(record.start_checks, key=lambda c: c.cost_full_mm)
            theta0 = start.theta
        record.centres.append(theta0)
        made.append(ev.reduce_around(theta0, new_runs=not s.full_model_check))
        fit, table1, theta, rounds = self._pass(ev, s, theta0, record, made, start)
        record.passes.append(rounds)
        second = job.finer_final
        fit_spec = job.final
        if second:
            job.final.voxels()      # made once here: the workers' snapshot runs and this process share it
            fit_spec = replace(job.final, settings=replace(job.final.settings, integrator="reduced"))
            record.centres.append(theta)
        with (ev.sibling(fit_spec) if second else nullcontext(ev)) as fit_ev:
            if second:
                made.append(fit_ev.reduce_around(theta))
                start = None    # the search model's checks were of another model
                fit, table1, theta, rounds = self._pass(fit_ev, s, theta, record, made)
                record.passes.append(rounds)
            t["reduced_models_s"] = made
            t["reduced_model_s"] = sum(made)
            t["reductions"] = ev.reductions + (fit_ev.reductions if second else [])
            t["search_s"] = time.perf_counter() - started
            if s.full_model_check:
                # the full model at the fit (a fit found again by a later round: the check of the
                # round that found it first)
                pool = [r.check for r in rounds if r.check is not None] + ([start] if start is not None else [])
                record.fit_check = next(c for c in pool if np.array_equal(c.theta, theta))
            assessed = time.perf_counter()
            assessment = assess(fit_ev, theta, s, None if record.fit_check is None else record.fit_check.r_full)
            t["uncertainty_s"] = time.perf_counter() - assessed
            job.tell("search", 1.0)
        check = record.fit_check
        if check is not None and not check.agrees:
            log.warning("the full model's training cost at the fit is %.2f× the reduced model's (%.1f against "
                        "%.1f mm): the reduced model does not hold there; calibrate with "
                        "search_integrator = implicit", check.cost_full_mm / check.cost_reduced_mm,
                        check.cost_full_mm, check.cost_reduced_mm)
        return SearchOutcome(theta, fit, table1, assessment, job.final, record)

    @staticmethod
    def _first_model(ev: Evaluator, s: CalibrationSettings, centre: np.ndarray, driven: bool) -> float:
        """Make the first reduced model, around the design's ``centre``; seconds taken.

        Its snapshots are the spec's (:meth:`~.model.ModelSpec.snapshot_scenes`: F/E, or a driven
        bar's travel, × 0.5 and × 2) — except where a driven bar's friction is fitted and the full
        model checks the search: a driven bar's travel is known, so its runs are at the program's
        own travel, at each of the design's friction levels instead (a slide and a near-stick, the
        two the design is ranked on; run in parallel and kept, ``Evaluator.full_runs``), the model
        made around the first."""
        space = ev.space
        if not (driven and space.friction and s.full_model_check):
            return ev.reduce_around(centre)
        started = time.perf_counter()
        mu = space.index(FRICTION_NAME)
        levels = sorted({float(d[mu]) for d in space.initial_design()})
        at = [space.with_value(centre, FRICTION_NAME, level) for level in levels]
        ev.full_runs(at)
        ran = time.perf_counter() - started
        return ran + ev.reduce_around(at[0], new_runs=False)

    @staticmethod
    def _pass(ev: Evaluator, s: CalibrationSettings, theta0: np.ndarray, record: TrustRegionRecord,
              made: list, start: Check | None = None):
        """Searches on ``ev``'s reduced model, made at ``record.centres[-1]``, checked by the full model.

        With ``s.full_model_check`` each search's fit is run once on the full model
        (:func:`run_checks`). A fit is accepted where the two agree (within
        ``s.reduced_agreement``), the full model fits it better than every point checked before
        (``start``, the full model's check of ``theta0``, among them) and the search converged
        there (not stopped by its budget). Otherwise the reduced model is made again — its modes
        now including that run (a greedy enrichment of the snapshots, as in trust-region POD:
        Arian, Fahl & Sachs 2000) — around the best point checked so far, and searched again
        from there, ``s.reduced_rounds`` times at most; the point the full model fits best is
        returned. A search that does not leave a point the full model has run ends the rounds
        without running it again.

        With a fitted friction each search keeps μ_f within ``s.reduced_friction_trust`` of the
        μ_f the model was made at: two sliding snapshots hold a slide near the μ_f they were made
        at, not a stick far above it (a search free to go there ended at μ_f 0.95 on
        slide_stop_s49, where the full model's cost was 28× the reduced one's; docs/decisions.md).
        A fit that stops at that edge — not at the space's own bound — has the model made again
        around it too. Each search's full-model miss at the model's centre is added to the reduced
        model's residuals (``s.reduced_correction``, :func:`_correction_at`).

        Returns ``(fit result, Table 1 result, θ, rounds)``; ``record.centres`` and ``made``
        (seconds) grow with each model made."""
        whole = ev.space
        rounds: list[Round] = []
        best: tuple[Check, tuple] | None = None
        if start is not None:
            kept = fitting.FitResult(start.theta, start.r_reduced, "design", 0, 0, [],
                                     "the design's start: the full model fits no searched fit better")
            best = (start, (kept, None, start.theta))
        for round_ in range(s.reduced_rounds + 1):
            centre = record.centres[-1]
            trusted = whole.friction_within(centre, s.reduced_friction_trust)
            correction = _correction_at(ev, best[0] if best is not None else None, centre, s)
            with ev.within(trusted), ev.corrected(correction):
                result = search_once(ev, s, theta0)
            theta = result[2]
            edge = trusted is not whole and _at_trust_edge(theta, trusted, whole)
            converged = result[0] is None or result[0].converged
            last = round_ == s.reduced_rounds
            if not s.full_model_check:
                rounds.append(Round(centre, theta, None, converged, edge))
                if not edge or last:
                    return (*result, rounds)
                record.centres.append(theta)
                made.append(ev.reduce_around(theta))
                theta0 = theta
                continue
            checked = ([best[0]] if best is not None else []) + [r.check for r in rounds if r.check is not None]
            if any(np.array_equal(c.theta, theta) for c in checked):
                # the search stayed where the full model has run (its start: the centre, where the
                # corrected model is the full one). Its step is zero; a model made again there from
                # the same runs is the same model, so no later round moves either: converged
                rounds.append(Round(centre, theta, None, converged, edge))
                break
            with ev.corrected(correction):    # the searched model's cost beside the full model's
                check, = run_checks(ev, [theta], s.reduced_agreement)
            rounds.append(Round(centre, theta, check, converged, edge))
            better = best is None or check.cost_full_mm < best[0].cost_full_mm
            if better:
                best = (check, result)
            # a search stopped by its budget, not at the model's optimum, goes on from its fit
            if (check.agrees and better and converged and not edge) or last:
                break
            # made again from every run so far, around the best point (the fit, or the point before
            # it where the full model fits this fit worse), and searched from there
            theta0 = best[0].theta
            record.centres.append(theta0)
            made.append(ev.reduce_around(theta0, new_runs=False))
        return best[1][0], best[1][1], best[0].theta, rounds


def _correction_at(ev: Evaluator, centre_check: Check | None, centre: np.ndarray, s: CalibrationSettings):
    """The full model's miss (mm, residuals) at the point ``ev``'s reduced model was made around,
    added to its residuals while it is searched (``s.reduced_correction``): zero-order consistency,
    as a trust-region method asks of its model (Alexandrov, Dennis, Lewis & Torczon 1998). A
    reduced model misses even its own snapshot's run where the sample sticks and slips (1.4× its
    cost on slide_stop_s50); uncorrected, the search follows that miss. None without a full run
    at that point (``centre_check``)."""
    if not (s.reduced_correction and centre_check is not None
            and np.array_equal(np.asarray(centre_check.theta, float), np.asarray(centre, float))):
        return None
    return centre_check.r_full - ev.one(centre)


def _design_starts(design: list, space: SearchSpace) -> list[np.ndarray]:
    """The design's best start (``design``: :func:`~.fit.initial_guess`'s ``(cost, θ)``), and with
    a fitted friction the best of each of its friction levels: on a reduced model the level that
    slides the most may be ranked by a slide the full model does not make."""
    ranked = sorted(design, key=lambda d: d[0])
    if not space.friction:
        return [np.asarray(ranked[0][1], float)]
    mu = space.index(FRICTION_NAME)
    levels: dict = {}
    for cost, theta in ranked:
        levels.setdefault(round(float(theta[mu]), 9), np.asarray(theta, float))
    return list(levels.values())


def _at_trust_edge(theta: np.ndarray, trusted: SearchSpace, whole: SearchSpace) -> bool:
    """Whether ``theta``'s friction went nine tenths of the way to a bound of ``trusted`` that is
    not ``whole``'s (a bounded search stops near a bound, not on it)."""
    mu = whole.index(FRICTION_NAME)
    log_mu = float(theta[mu])
    low, high = trusted.lower[mu], trusted.upper[mu]
    edge = 0.05 * (high - low)
    return bool((log_mu <= low + edge and low > whole.lower[mu] + edge)
                or (log_mu >= high - edge and high < whole.upper[mu] - edge))


__all__ = ["Assessment", "Check", "MAX_MAPPING_STEP", "ReducedTrustRegion", "Round", "SearchJob", "SearchOutcome",
           "SearchRecord", "SearchStrategy", "SpaceMapping", "SpaceMappingRecord", "TrustRegionRecord", "assess",
           "run_checks", "search_once", "strategy_for"]
