"""The paper's iterative parameter estimation (Table 1, rules (1)–(2)), as stated.

For training times t = 1 … n (the training frames) and S_t = Σ_{a∈A} |D̂_t(a) − D_t(a)|:

* Step 1: at t = 1, adjust K̂₁ until S₁ ≤ T/2;
* Step 2: at t + 1, run the model with K̂_{t−1}; keep it if S_i ≤ T for every
  i ≤ t (rule 1), otherwise adjust it until they all are (rule 2);
* Step 3: repeat to t = n; K̂_n is the estimate.

The paper does not say how K is "adjusted". Here an adjustment is a compass
(pattern) search, one of the oldest step-iterative methods: from K, try ± one
step in each coordinate of the search space (these 2p runs go to Dask
together), move to the best trial if it lowers ``max_i S_i / limit_i``, else
halve the steps; stop when the rule holds, the steps are below a floor, or the
run budget is spent. Runs stop at the current training time t, so early
adjustments are cheap — the paper's advantage 3.

The threshold T is ``threshold_mm_per_point × |A|`` (mm): the paper gives no value;
one pixel per point by default.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hifumotion.estimation.evaluator import Evaluator
from hifumotion.estimation.objective import frame_sums_mm

#: Initial compass steps per coordinate (ln E, ν, ln β1, β2) and the floor below which the search stops.
INITIAL_STEPS = np.array([0.5, 0.02, 1.0, 0.1])
MIN_STEP_FRACTION = 1 / 16


@dataclass
class IterativeResult:
    theta: np.ndarray
    accepted: bool                    # every S_t ≤ T at the end
    threshold_mm: float               # T
    frame_sums_mm: np.ndarray         # S_t of the final K over all training frames
    runs: int
    events: list = field(default_factory=list)   # what happened at each training time


def _score(ev: Evaluator, theta: np.ndarray, t: int, limits: np.ndarray) -> tuple[float, np.ndarray]:
    s = frame_sums_mm(ev.one(theta, upto=t))
    return float(np.max(s / limits)), s


def _adjust(ev: Evaluator, theta: np.ndarray, t: int, limits: np.ndarray, budget: int) -> tuple[np.ndarray, int]:
    """Compass search on ``max_i S_i / limit_i`` (i ≤ t) until it is ≤ 1 (rule 2)."""
    lo, hi = ev.space.lower, ev.space.upper
    # the friction's coordinate (ln μ_f), when fitted, starts at a factor 1.6, as ln E's
    initial = np.append(INITIAL_STEPS, [0.5] * (len(theta) - len(INITIAL_STEPS)))
    steps = initial.copy()
    best, s = _score(ev, theta, t, limits)
    used = 0
    while best > 1.0 and used < budget and np.any(steps > initial * MIN_STEP_FRACTION):
        trials = []
        for i in range(len(theta)):
            for sign in (1.0, -1.0):
                trial = theta.copy()
                trial[i] = np.clip(trial[i] + sign * steps[i], lo[i], hi[i])
                if not np.allclose(trial, theta):
                    trials.append(trial)
        results = ev.residuals(trials, upto=t)
        used += len(trials)
        scores = [float(np.max(frame_sums_mm(r) / limits)) for r in results]
        k = int(np.argmin(scores))
        if scores[k] < best:
            theta, best = trials[k], scores[k]
        else:
            steps /= 2.0
    return theta, used


def iterative_estimate(ev: Evaluator, theta0: np.ndarray, threshold_mm_per_point: float | None = None,
                       max_runs: int = 120) -> IterativeResult:
    """Table 1 from ``theta0`` (module docstring); at most ``max_runs`` forward runs."""
    n = len(ev.data.frames)
    points = ev.data.width(len(ev.spec.points_mm))
    per_point = threshold_mm_per_point if threshold_mm_per_point is not None else ev.data.pixel_mm
    big_t = per_point * points
    theta = np.asarray(theta0, float).copy()
    events = []
    runs = 0
    # each training time gets its share of the runs, so an unreachable S_1 ≤ T/2 cannot spend them all
    share = max(max_runs // n, 4 * len(theta))
    # Step 1: t = 1, S_1 ≤ T/2
    theta, used = _adjust(ev, theta, 1, np.array([big_t / 2]), min(share, max_runs))
    runs += used
    events.append({"t": 1, "frame": int(ev.data.frames[0]), "rule": "step 1 (S_1 ≤ T/2)", "runs": used,
                   "S_mm": frame_sums_mm(ev.one(theta, upto=1)).round(3).tolist()})
    # Steps 2–3
    for t in range(2, n + 1):
        limits = np.full(t, big_t)
        score, s = _score(ev, theta, t, limits)
        if score <= 1.0:
            events.append({"t": t, "frame": int(ev.data.frames[t - 1]), "rule": "1 (kept)", "runs": 1,
                           "S_mm": s.round(3).tolist()})
            continue
        theta, used = _adjust(ev, theta, t, limits, min(share, max(max_runs - runs, 0)))
        runs += used
        events.append({"t": t, "frame": int(ev.data.frames[t - 1]), "rule": "2 (adjusted)", "runs": used,
                       "S_mm": frame_sums_mm(ev.one(theta, upto=t)).round(3).tolist()})
    final = frame_sums_mm(ev.one(theta))
    return IterativeResult(theta, bool(np.all(final <= big_t)), big_t, final, runs, events)


__all__ = ["IterativeResult", "iterative_estimate"]
