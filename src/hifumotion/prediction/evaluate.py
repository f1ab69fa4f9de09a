"""Score a prediction and its baselines on one truth: the paper's Table 4, side by side.

One function, :func:`evaluate`, used by the end-to-end pipeline (``hifumotion demo`` /
``hifumotion run``) and by ``benchmarks/bench_estimation.py``:

* the physics per frame (DSC, HD95, centroid error in mm) on the training and the
  validation frames (:func:`~hifumotion.scoring.score_masks`);
* the baselines on the validation window, from the same observation the physics had
  (frame 0 and the training frames): **no motion** (the last training contour held),
  a **Kalman** filter on the contour's centroid and shape and, where the push's program is
  known, the **surrogates** — the tracked centroid regressed on the program, static and
  lagged (:mod:`~hifumotion.prediction.surrogates`);
* the physics' margin over each, and the ranking of all by the validation centroid error;
* the **online** mode: at each frame t, predict t + k from what was seen up to t — the
  physics re-anchored on the tracked frame t, holding frame t, the **NCC** template
  tracker's frame t, a Kalman filter over the last ten tracked frames and, with the
  program, the surrogate updated at every frame (recursive least squares).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hifumotion.scoring import ScoreTable, score_masks


def summary(masks: dict, truth: dict, pixel_mm: float, frames) -> dict:
    """DSC mean/min, HD95 mean (mm), centroid error mean/max (mm) over ``frames``."""
    from hifumotion.metrics import centroid_distance, dice, hausdorff

    frames = [f for f in frames if f in masks and f in truth]
    if not frames:
        return {"frames": 0}
    d = [dice(masks[f], truth[f]) for f in frames]
    h = [hausdorff(masks[f], truth[f], pixel_mm, percentile=95) if masks[f].any() else float("inf") for f in frames]
    c = [centroid_distance(masks[f], truth[f], pixel_mm) if masks[f].any() else float("inf") for f in frames]
    return {"frames": len(frames), "dsc_mean": float(np.mean(d)), "dsc_min": float(np.min(d)),
            "hd95_mean_mm": float(np.mean(h)), "centroid_mean_mm": float(np.mean(c)),
            "centroid_max_mm": float(np.max(c))}


def aim_summary(aims_mm: dict, truth: dict, pixel_mm: float, frames) -> dict:
    """The aims' distance (mm) to the true section's centroid over ``frames``: mean and max."""
    from hifumotion.metrics import centroid

    frames = [f for f in frames if f in aims_mm and f in truth and truth[f].any()]
    if not frames:
        return {"frames": 0}
    d = [float(np.linalg.norm(np.asarray(aims_mm[f], float) - centroid(truth[f], pixel_mm))) for f in frames]
    return {"frames": len(frames), "centroid_mean_mm": float(np.mean(d)), "centroid_max_mm": float(np.max(d))}


def margin_over(masks: dict, baseline: dict, truth: dict, pixel_mm: float, frames) -> dict:
    """The prediction's margin over a baseline frame by frame: DSC(pred) − DSC(baseline) and
    centroid error (baseline − pred, mm), each's mean and spread (standard deviation over the
    frames), and ``verdict``: ``"better"`` when both means are positive and the DSC margin or
    the centroid margin exceeds its spread, ``"worse"`` when both are negative beyond it,
    else ``"no better"`` — a margin within its spread is not a win."""
    from hifumotion.metrics import centroid_distance, dice

    frames = [f for f in frames if f in masks and f in baseline and f in truth and masks[f].any() and baseline[f].any()]
    if len(frames) < 2:
        return {"frames": len(frames), "verdict": None}
    d = np.array([dice(masks[f], truth[f]) - dice(baseline[f], truth[f]) for f in frames])
    c = np.array([centroid_distance(baseline[f], truth[f], pixel_mm) - centroid_distance(masks[f], truth[f], pixel_mm)
                  for f in frames])
    dm, ds, cm, cs = float(d.mean()), float(d.std(ddof=1)), float(c.mean()), float(c.std(ddof=1))
    if dm > 0 and cm > 0 and (dm > ds or cm > cs):
        verdict = "better"
    elif dm < 0 and cm < 0 and (-dm > ds or -cm > cs):
        verdict = "worse"
    else:
        verdict = "no better"
    return {"frames": len(frames), "dsc_margin_mean": dm, "dsc_margin_std": ds, "centroid_margin_mean_mm": cm,
            "centroid_margin_std_mm": cs, "verdict": verdict}


@dataclass
class Evaluation:
    """What :func:`evaluate` measured (JSON-ready through :meth:`as_dict`)."""

    table: ScoreTable                     # the physics, per frame (Table 4)
    physics: dict                         # training / validation summaries
    baselines: dict                       # method -> validation summary
    online: dict = field(default_factory=dict)   # horizon (frames, as str) -> method -> summary
    baseline_masks: dict = field(default_factory=dict)   # method -> frame -> mask (validation)
    online_predictions: object = None     # prediction.pipeline.OnlinePredictions: the physics' online masks and aims

    def as_dict(self) -> dict:
        return {"physics": self.physics, "baselines_validation": self.baselines, "online": self.online,
                "per_frame": self.table.rows}


def ranking(physics: dict, baselines: dict) -> list[dict]:
    """The physics and every baseline ordered by validation centroid error (then DSC), each
    ``{"method", "centroid_mean_mm", "dsc_mean"}``; the first is the best."""
    rows = [{"method": "physics", "centroid_mean_mm": physics.get("centroid_mean_mm"),
             "dsc_mean": physics.get("dsc_mean")}]
    rows += [{"method": name, "centroid_mean_mm": s.get("centroid_mean_mm"), "dsc_mean": s.get("dsc_mean")}
             for name, s in baselines.items()]
    rows = [r for r in rows if r["centroid_mean_mm"] is not None]
    return sorted(rows, key=lambda r: (r["centroid_mean_mm"], -(r["dsc_mean"] or 0.0)))


def verdict(rank: list[dict]) -> str:
    """One line: which predictor the validation frames favour, by how much, on which metric."""
    if not rank:
        return "nothing to rank"
    best = rank[0]
    name = best["method"].replace("_", " ")
    if len(rank) == 1:
        return f"{name}: centroid {best['centroid_mean_mm']:.3f} mm"
    second = rank[1]
    ratio = second["centroid_mean_mm"] / best["centroid_mean_mm"] if best["centroid_mean_mm"] > 0 else float("inf")
    return (f"{name} predicts best by the centroid: {best['centroid_mean_mm']:.3f} mm, {ratio:.1f}× better than "
            f"{second['method'].replace('_', ' ')} ({second['centroid_mean_mm']:.3f} mm)")


def evaluate(pred, spec, reference, tracked: np.ndarray, images: np.ndarray, truth: dict, training, validation,
             frame_interval_s: float, horizons=(), online_from=(), program: np.ndarray | None = None,
             choice=None) -> Evaluation:
    """Score ``pred`` (:class:`~hifumotion.prediction.physics.Prediction`) and the baselines.

    Parameters
    ----------
    pred, spec, reference
        The fitted model's prediction, its model and the frame-0 shape it carries.
    tracked
        ``(T, H, W)`` bool: the target as the user's pipeline saw it in every frame
        (tracked, or given contours); the baselines see only these.
    images
        ``(T, H, W)`` the B-mode frames (for the NCC tracker).
    truth
        Frame → true mask; the scores' reference.
    training, validation
        Frame numbers of the two sets.
    horizons, online_from
        Online mode: horizons k (frames) and the frames t it predicts t + k from.
    program
        ``(T,)`` the push's known program at every frame
        (:meth:`~hifumotion.observed.setup.PushSchedule.program`): with it the surrogates
        are scored beside the physics.
    choice
        A :class:`~hifumotion.prediction.choice.HoldoutRanking` made on the training frames:
        its winner's validation scores are recorded as the product's choice (``physics["choice"]``),
        beside how far it falls behind the validation's best predictor.
    """
    from hifumotion.prediction.baselines import kalman_predict, ncc_track
    from hifumotion.prediction.choice import peer_masks
    from hifumotion.prediction.pipeline import online_predictions
    from hifumotion.prediction.surrogates import anchored_to_last, residual_corrected

    pixel = float(pred.pixel_mm)
    training, validation = [int(f) for f in training], [int(f) for f in validation]
    scored = {f: pred.masks[f] for f in training + validation if f in pred.masks}
    table = score_masks(scored, truth, pixel, training=training, validation=validation)
    physics = {"training": summary(pred.masks, truth, pixel, training),
               "validation": summary(pred.masks, truth, pixel, validation)}
    seen = {f: tracked[f] for f in [0, *training]}
    masks, fits = peer_masks(seen, training, validation, program, frame_interval_s, pixel)
    if program is not None:
        masks["physics_anchored"] = anchored_to_last(pred.masks, seen, validation, pixel)
        # the physics with its miss on the training frames regressed on the program and taken out
        m, fit = residual_corrected(pred.masks, seen, training, validation, program, frame_interval_s, pixel)
        masks["physics_corrected"], fits["physics_corrected"] = m, fit.as_dict()
    baselines = {name: summary(m, truth, pixel, validation) for name, m in masks.items()}
    for name, fit in fits.items():
        baselines[name]["fit"] = fit
    physics["margin_over_no_motion"] = margin_over(pred.masks, masks["no_motion"], truth, pixel, validation)
    physics["margin_over"] = {name: margin_over(pred.masks, m, truth, pixel, validation) for name, m in masks.items()}
    physics["ranking"] = ranking(physics["validation"], baselines)
    physics["verdict"] = verdict(physics["ranking"])
    if choice is not None:
        every = {"physics": pred.masks, **masks}
        physics["choice"] = choice.as_dict()
        if choice.winner in every:      # (a winner that needs the program is scored where it is given)
            physics["choice"].update(_choice_on_validation(every, choice.winner, physics["ranking"], truth, pixel,
                                                           validation))

    online: dict = {}
    physics_online = None
    n = len(tracked)
    now = [int(t) for t in online_from]
    if horizons and now:
        from hifumotion.metrics import centroid

        physics_online = online_predictions(pred, spec, reference, tracked, list(horizons), now)
        ncc = ncc_track(images, tracked[0])
        if program is not None:
            surrogate, surrogate_aims = _online_surrogate(tracked, program, frame_interval_s, pixel, horizons,
                                                          training)
        for h in horizons:
            targets = [t + h for t in now if t + h < n and t + h in physics_online.masks[h] and t + h in truth]
            entry: dict = {"horizon_frames": int(h), "horizon_ms": 1000.0 * h * frame_interval_s}
            entry["physics"] = summary(physics_online.masks[h], truth, pixel, targets)
            entry["no_motion"] = summary({t + h: tracked[t] for t in now}, truth, pixel, targets)
            entry["ncc"] = summary({t + h: ncc[t] for t in now if t in ncc}, truth, pixel, targets)
            kalman = {}
            for t in now:
                if t + h in targets:
                    past = {f: tracked[f] for f in range(max(0, t - 10), t + 1)}
                    kalman.update(kalman_predict(past, [t + h], frame_interval_s, pixel))
            entry["kalman"] = summary(kalman, truth, pixel, targets)
            # the aims: where each predictor puts the centroid, before its mask rounds it to the pixel grid
            aims = {"physics": physics_online.aims_mm[h],
                    "no_motion": {t + h: centroid(tracked[t], pixel) for t in now if t + h in targets},
                    "kalman": {f: centroid(m, pixel) for f, m in kalman.items() if m.any()}}
            if program is not None:
                entry["surrogate"] = summary({t + h: surrogate(t, h) for t in now if t + h in targets},
                                             truth, pixel, targets)
                aims["surrogate"] = {t + h: surrogate_aims[h][t] for t in now
                                     if t + h in targets and np.isfinite(surrogate_aims[h][t]).all()}
            entry["aim"] = {name: aim_summary(a, truth, pixel, targets) for name, a in aims.items()}
            online[str(h)] = entry
    return Evaluation(table, physics, baselines, online, masks, physics_online)


def peer_scores(predicted: dict, tracked: dict, truth: dict, training, validation, program: np.ndarray | None,
                frame_interval_s: float, pixel_mm: float) -> dict:
    """A prediction on its validation frames beside the peers that know the same inputs
    (holding still, the Kalman filter and, with the program, the drive surrogates, each from
    the tracked frame 0 and training frames), their ranking and the verdict — what ``hifumotion
    score --calibration`` prints."""
    from hifumotion.prediction.choice import peer_masks

    validation = [int(f) for f in validation]
    masks = peer_masks(tracked, [int(f) for f in training], validation, program, frame_interval_s, pixel_mm)[0]
    peers = {name: summary(m, truth, pixel_mm, validation) for name, m in masks.items()}
    physics = summary(predicted, truth, pixel_mm, validation)
    rank = ranking(physics, peers)
    return {"prediction": physics, "peers": peers, "ranking": rank, "verdict": verdict(rank),
            "margin_over": {name: margin_over(predicted, m, truth, pixel_mm, validation) for name, m in masks.items()}}


def _choice_on_validation(masks: dict, chosen: str, rank: list[dict], truth: dict, pixel_mm: float, frames) -> dict:
    """The chosen predictor on the validation frames beside the best one there: its summary, and
    its excess centroid error over the best's (mean and spread over the frames, mm)."""
    from hifumotion.metrics import centroid_distance

    best = rank[0]["method"] if rank else chosen
    frames = [f for f in frames if f in truth and all(f in masks[m] and masks[m][f].any() for m in (chosen, best))]
    out = {"chosen": chosen, "validation": summary(masks[chosen], truth, pixel_mm, frames), "validation_best": best}
    if len(frames) >= 2:
        excess = np.array([centroid_distance(masks[chosen][f], truth[f], pixel_mm)
                           - centroid_distance(masks[best][f], truth[f], pixel_mm) for f in frames])
        out.update(excess_over_best_mm=float(excess.mean()), excess_spread_mm=float(excess.std(ddof=1)))
    return out


def _online_surrogate(tracked: np.ndarray, program: np.ndarray, frame_interval_s: float, pixel_mm: float, horizons,
                      training):
    """The online surrogate over the tracked frames (causal: the aim at t from frames ≤ t), its
    memory the training window's span: ``(t, k) -> mask`` (the tracked frame t moved to the aim)
    and the aims themselves (horizon k → ``(T, 2)`` mm, the aim made at t for t + k)."""
    from hifumotion.metrics import centroid
    from hifumotion.prediction.surrogates import online_drive_regression, shift_mask

    c = np.array([centroid(m, pixel_mm) if m.any() else (np.nan, np.nan) for m in tracked], float)
    memory_s = max(max(training) - min(training), 1) * frame_interval_s
    aims = online_drive_regression(c, program, frame_interval_s, horizons, memory_s)

    def mask(t: int, k: int) -> np.ndarray:
        shift = aims[k][t] - c[t]
        return shift_mask(tracked[t], shift, pixel_mm) if np.isfinite(shift).all() else tracked[t]
    return mask, aims


def online_schedule(training, validation, horizons, n_frames: int, samples: int = 40) -> tuple[list[int], list[int]]:
    """The frames t the online mode predicts from (about ``samples`` of them, from the first
    training frame to the last validation frame less the shortest horizon) and every frame
    the model must keep for it (t and t + k)."""
    if not horizons:
        return [], []
    first, last = min(training), max(validation)
    now = list(range(first, last - min(horizons) + 1, max(1, n_frames // samples)))
    keep = sorted({f for t in now for h in [0, *horizons] if (f := t + h) < n_frames})
    return now, keep


__all__ = ["Evaluation", "aim_summary", "evaluate", "summary", "margin_over", "online_schedule", "peer_scores", "ranking", "verdict"]
