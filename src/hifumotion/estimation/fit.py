"""The estimators on the training residuals: bounded least squares (default) and CMA-ES.

Both minimise the residuals of :mod:`.objective` over the coordinates of
:mod:`.space`, with every batch of forward runs in parallel on Dask (:class:`~.evaluator.Evaluator`):

* :func:`least_squares_fit` — trust-region reflective least squares (``scipy.optimize.least_squares``,
  bounded), robust ``soft_l1`` loss with scale one pixel (so Σ|r|, the paper's S, and
  Σ r² agree for small residuals and outliers of the tracking weigh little), and a
  forward-difference Jacobian whose p runs go to Dask together;
* :func:`cmaes_fit` — CMA-ES (the ``cma`` package) on Σ_t S_t itself, each generation's
  population in parallel; derivative-free, slower, indifferent to a rough objective.

:func:`uncertainty` turns the Jacobian at the optimum into standard errors
(Gauss–Newton covariance, and the frames' own scatter: a frame's points share its
errors) and an identifiability table; :func:`degeneracy`
runs the scaling F, E, β1 → c F, c E, c β1 that a quasi-static push cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hifumotion.estimation.evaluator import Evaluator


@dataclass
class FitResult:
    theta: np.ndarray
    residuals_mm: np.ndarray          # (n, M) at theta
    method: str
    iterations: int
    runs: int
    trace: list = field(default_factory=list)   # (cost_mm, theta) per iteration / generation
    message: str = ""
    converged: bool = True          # False: stopped by its budget of evaluations or generations

    @property
    def cost_mm(self) -> float:
        """Σ_t S_t: the summed absolute residual (mm) over all training frames and points."""
        return float(np.abs(self.residuals_mm).sum())


def initial_guess(ev: Evaluator) -> tuple[np.ndarray, list]:
    """The best of the search space's data-free initial design (run in parallel)."""
    design = ev.space.initial_design()
    res = ev.residuals(design)
    costs = [float(np.abs(r).sum()) for r in res]
    best = int(np.argmin(costs))
    return design[best], [(c, d.tolist()) for c, d in zip(costs, design)]


def jacobian(ev: Evaluator, theta: np.ndarray) -> np.ndarray:
    """Forward-difference Jacobian ``(n·M, p)`` of the residuals (mm per coordinate unit), runs in parallel.

    A step that would leave the bounds is taken backwards instead."""
    step = ev.space.steps
    steps = np.where(theta + step > ev.space.upper, -step, step)
    points = [theta + np.eye(len(theta))[i] * steps[i] for i in range(len(theta))]
    base, *shifted = ev.residuals([theta] + points)
    return np.stack([(r - base).ravel() / s for r, s in zip(shifted, steps)], axis=1)


def least_squares_fit(ev: Evaluator, theta0: np.ndarray, max_evaluations: int = 8) -> FitResult:
    """Bounded robust least squares from ``theta0`` (module docstring)."""
    from scipy.optimize import least_squares

    trace: list = []
    f_scale = ev.data.pixel_mm

    def fun(theta):
        r = ev.one(theta)
        trace.append((float(np.abs(r).sum()), np.asarray(theta).tolist()))
        return r.ravel()

    lo, hi = ev.space.lower, ev.space.upper
    x0 = np.clip(theta0, lo + 1e-9, hi - 1e-9)
    sol = least_squares(fun, x0, jac=lambda t: jacobian(ev, t), bounds=(lo, hi), method="trf",
                        loss="soft_l1", f_scale=f_scale, x_scale=ev.space.steps * 10, max_nfev=max_evaluations,
                        xtol=1e-3, ftol=1e-3, gtol=1e-6)
    r = ev.one(sol.x)
    return FitResult(sol.x, r, "least_squares", int(sol.nfev), ev.runs, trace, str(sol.message), sol.status > 0)


def cmaes_fit(ev: Evaluator, theta0: np.ndarray, max_generations: int = 12, popsize: int | None = None,
              seed: int = 0) -> FitResult:
    """CMA-ES on Σ_t S_t in coordinates scaled to the bounds (module docstring)."""
    import cma

    lo, hi = ev.space.lower, ev.space.upper
    span = hi - lo

    def to_theta(z):
        return lo + np.clip(z, 0.0, 1.0) * span

    z0 = np.clip((theta0 - lo) / span, 0.01, 0.99)
    opts = {"bounds": [0.0, 1.0], "seed": int(seed) + 1, "maxiter": int(max_generations), "verbose": -9}
    if popsize:
        opts["popsize"] = int(popsize)
    es = cma.CMAEvolutionStrategy(z0.tolist(), 0.15, opts)
    trace: list = []
    generations = 0
    while not es.stop():
        zs = es.ask()
        res = ev.residuals([to_theta(np.asarray(z)) for z in zs])
        costs = [float(np.abs(r).sum()) for r in res]
        es.tell(zs, costs)
        generations += 1
        best = int(np.argmin(costs))
        trace.append((costs[best], to_theta(np.asarray(zs[best])).tolist()))
    theta = to_theta(np.asarray(es.result.xbest))
    stop = dict(es.stop())
    return FitResult(theta, ev.one(theta), "cmaes", generations, ev.runs, trace, str(stop), "maxiter" not in stop)


#: How large an error in each coordinate matters (a coordinate is *determined* below it): 20 % of
#: E, β1 and μ_f, 0.05 of ν, 0.2 of β2.
RELEVANCE = {"log_E": 0.2, "nu": 0.05, "log_beta1": 0.2, "beta2": 0.2, "log_mu": 0.2}


def below_relevance(name: str, std: float) -> bool:
    """Whether a standard error ``std`` of coordinate ``name`` is below its :data:`RELEVANCE`
    scale — the first condition for *determined*."""
    return bool(std < RELEVANCE[name])


@dataclass
class Uncertainty:
    """Standard errors of the fitted coordinates and what the data determine."""

    std: np.ndarray                 # (p,) standard error per coordinate: the larger of the two below
    correlation: np.ndarray         # (p, p)
    singular_values: np.ndarray     # of the Jacobian scaled by the coordinates' steps
    sigma_mm: float                 # residual scatter per point (mm)
    determined: dict                # coordinate -> bool (``std`` below its relevance scale)
    std_independent: np.ndarray     # (p,) as if every point's error were its own: s² (JᵀJ)⁻¹
    std_frames: np.ndarray          # (p,) from the frames' own scatter (delete-one-frame jackknife)
    #: coordinate -> bool: what ``std_independent`` would call determined — which directions the
    #: Jacobian sees sharply, what a Gauss–Newton step may move, not how well they are known
    sharp: dict = field(default_factory=dict)
    #: coordinate -> bool: the fit lies within half a finite-difference step of its search bound
    at_bound: dict = field(default_factory=dict)


def frame_jackknife_covariance(j: np.ndarray, r: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """The delete-one-frame jackknife covariance of the fit, linearised (Gauss–Newton).

    ``j``: ``(n·w, p)`` Jacobian (mm per coordinate) whose rows follow ``r``'s ``(n, w)``
    residuals (mm) frame by frame; ``seen``: ``(k, p)`` orthonormal rows spanning the
    directions the whole Jacobian sees. Leaving frame t out moves the fit by
    ``d_t = (A − A_t)⁻¹ J_tᵀ r_t`` (``A = JᵀJ``, ``A_t = J_tᵀJ_t``); the covariance is
    ``(n − 1)/n Σ_t (d_t − d̄)(d_t − d̄)ᵀ`` (the cluster-robust CR3 estimator; Bell and
    McCaffrey 2002, MacKinnon and White 1985). Why: a contour's points share one tracking
    error and one model error — a section drawn a little too wide moves all its points
    together — so the frames, not the points, are the independent units. Measured on a
    linear model with nine frames whose errors are shared by their points: the
    independent-point errors are 4–12× too small and cover 20–40 % at 3σ; this one is within
    5 % of the true scatter and covers 99 % (docs/decisions.md, "A fit's standard errors
    count frames, not points"). A direction only one frame sees has no scatter to measure:
    its coordinates get an infinite variance."""
    n = r.shape[0]
    jv = j @ seen.T                                  # the Jacobian in the seen directions
    per_frame = jv.reshape(n, -1, jv.shape[1])
    a = jv.T @ jv
    steps, lost = [], np.zeros(len(seen), bool)
    for t in range(n):
        rest = a - per_frame[t].T @ per_frame[t]
        values, vectors = np.linalg.eigh(rest)
        keep = values > 1e-10 * max(values.max(), 1e-300)
        lost |= (vectors[:, ~keep] ** 2).sum(axis=1) > 1e-6
        steps.append(vectors[:, keep] @ ((vectors[:, keep].T @ (per_frame[t].T @ r[t])) / values[keep]))
    d = np.asarray(steps)
    d -= d.mean(axis=0)
    cov_seen = (n - 1) / n * d.T @ d
    cov = seen.T @ cov_seen @ seen
    if lost.any():
        blind = (seen[lost] ** 2).sum(axis=0) > 1e-6
        cov[blind, :] = cov[:, blind] = 0.0
        cov[blind, blind] = np.inf
    return cov


def uncertainty(ev: Evaluator, theta: np.ndarray, residuals_mm: np.ndarray | None = None,
                jacobian_mm: np.ndarray | None = None) -> Uncertainty:
    """Standard errors of the fit at ``theta``: the larger, coordinate by coordinate, of the
    Gauss–Newton covariance ``s² (JᵀJ)⁻¹`` and the delete-one-frame jackknife
    (:func:`frame_jackknife_covariance`; with one training frame, the first alone).

    ``s`` is the residual scatter per point, but at least half a pixel: no contour is
    known better, and a perfect fit must not make every coordinate look determined. The
    scatter is ``residuals_mm``' (mm, ``(n, M)``: another model's at ``theta``, such as the full
    model's where a reduced one gives the Jacobian) or, by default, ``ev``'s own at ``theta``.
    ``jacobian_mm``: the Jacobian at ``theta`` where the caller has it (:func:`jacobian`'s).
    Directions the Jacobian does not see (singular values below 10⁻⁸ of the largest)
    give the coordinates along them an infinite error. The independent-point covariance
    treats the hundreds of points of a frame as hundreds of measurements; they share the
    frame's error, and a fit whose model misses the tissue in a way the frames repeat is
    no better known for having more points — the jackknife sees that scatter. A
    coordinate is *determined* when its standard error is below its relevance scale
    (20 % for ln E, ln β1 and ln μ_f, 0.05 for ν, 0.2 for β2) and the fit does not lie on its
    search bound (within half a finite-difference step): there the minimum is the bound's, not
    the data's — the data ask for a value the search may not give — and a local error says
    nothing of how far off it is (measured: ν on its 0.495 bound, 7σ from the truth by the
    errors)."""
    j = jacobian(ev, theta) if jacobian_mm is None else np.asarray(jacobian_mm, float)
    r2 = np.asarray(ev.one(theta) if residuals_mm is None else residuals_mm, float)
    r2 = r2.reshape(len(r2), -1)
    r = r2.ravel()
    m, p = j.shape
    s2 = max(float(r @ r) / max(m - p, 1), (0.5 * ev.data.pixel_mm) ** 2)
    _, sv, vt = np.linalg.svd(j, full_matrices=False)
    seen = sv > 1e-8 * max(sv.max(), 1e-300)
    bread = (vt[seen].T / sv[seen] ** 2) @ vt[seen]
    independent = s2 * bread
    frames = frame_jackknife_covariance(j, r2, vt[seen]) if len(r2) > 1 else np.zeros_like(independent)
    # the larger variance per coordinate; the independent one's excess added on the diagonal
    # keeps the matrix a covariance (positive semi-definite)
    finite = np.isfinite(np.diag(frames))
    frames_finite = np.where(np.outer(finite, finite), frames, 0.0)
    deficit = np.maximum(np.diag(independent) - np.diag(frames_finite), 0.0)
    cov = frames_finite + np.diag(deficit)
    blind = (vt[~seen].T ** 2).sum(axis=1) > 1e-6
    var_independent, var_frames, var = np.diag(independent).copy(), np.diag(frames).copy(), np.diag(cov).copy()
    var[~finite] = np.inf
    for v in (var_independent, var_frames, var):
        v[blind] = np.inf
    std = np.sqrt(var)
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(d, d)
    scaled_sv = np.linalg.svd(j * ev.space.steps, compute_uv=False)
    names = ev.space.names
    half_step = 0.5 * np.asarray(ev.space.steps, float)
    at = np.asarray(theta, float)
    bound = (at - np.asarray(ev.space.lower, float) < half_step) | (np.asarray(ev.space.upper, float) - at < half_step)
    return Uncertainty(std, corr, scaled_sv, float(np.sqrt(s2)),
                       {name: below_relevance(name, x) and not b for name, x, b in zip(names, std, bound)},
                       np.sqrt(var_independent), np.sqrt(var_frames),
                       {name: below_relevance(name, x) for name, x in zip(names, np.sqrt(var_independent))},
                       {name: bool(b) for name, b in zip(names, bound)})


def degeneracy(ev: Evaluator, theta: np.ndarray, factors=(0.5, 2.0)) -> list[dict]:
    """Σ_t S_t when F, E and β1 are all scaled by each factor (what a quasi-static push hides)."""
    k = ev.space.parameters(theta)
    base = float(np.abs(ev.one(theta)).sum())
    ks = [k.replaced(force_n=k.force_n * c, youngs_modulus_pa=k.youngs_modulus_pa * c, beta1=k.beta1 * c)
          for c in factors]
    out = [{"factor": 1.0, "cost_mm": base}]
    for c, r in zip(factors, ev.parameter_runs(ks)):
        out.append({"factor": float(c), "cost_mm": float(np.abs(r).sum())})
    return out


__all__ = ["RELEVANCE", "below_relevance", "FitResult", "initial_guess", "jacobian", "least_squares_fit", "cmaes_fit", "Uncertainty",
           "frame_jackknife_covariance", "uncertainty", "degeneracy"]
