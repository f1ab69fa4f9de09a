"""Which predictor the data support: a temporal hold-out over the training frames.

The validation frames are the future: nothing may be chosen on them. The training frames are
split in time — every predictor is fitted on the earlier ones and scored on every frame of the
last quarter's span (at least two training frames held out), by the centroid error against
the tracked sections, the frames the operator has. The predictors are the physics (calibrated on the earlier frames only, by the
caller), the drive surrogates (:mod:`~hifumotion.prediction.surrogates`), the
constant-velocity Kalman filter and holding still — each predicting from the same last seen
frame, as they will for the validation frames — the physics' motion from that frame
(:func:`~hifumotion.prediction.surrogates.anchored_to_last`) and the physics corrected by a
regression of its miss on the drive (:func:`~hifumotion.prediction.surrogates.residual_corrected`).

The winner is the one with the smallest held-out centroid error; a predictor whose error lies
within the spread of the winner's margin over it (the standard deviation over the held-out
frames of the frame-by-frame difference) is "as good" — the data do not tell them apart.

A hold-out in which the tracked section hardly moves cannot rank motion predictors: holding
still is exact there whatever comes next (a drive drawn back while friction holds the sample,
then driven on again). When the tracked section moves less than half a pixel over the held-out
frames (:data:`RESOLVED_PX`), the choice stays with the physics, which is fitted on every
training frame and knows the push's whole program, and the sentence says why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.errors import InputError

#: the share of the training frames held out at their end
HELD_OUT_SHARE = 0.25
#: the least motion of the tracked section over the held-out frames (px) that can rank motion
#: predictors: below it every anchored predictor is exact to within the images' resolution
RESOLVED_PX = 0.5


def holdout_split(training) -> tuple[list[int], list[int]]:
    """``(fit, held)``: the training frames before their last quarter (≥ 2 held out), and every
    frame after the last of those up to the last training frame — the frames between the
    training frames are observed too, and each adds a held-out sample."""
    frames = sorted(int(f) for f in training)
    if len(frames) < 4:
        raise InputError(f"a hold-out needs at least 4 training frames, got {len(frames)}", "training_frames")
    fit = frames[:-max(2, int(round(HELD_OUT_SHARE * len(frames))))]
    return fit, list(range(fit[-1] + 1, frames[-1] + 1))


@dataclass
class HoldoutRanking:
    """The predictors on the held-out training frames.

    Attributes
    ----------
    fit_frames, held_frames
        The frames each predictor was fitted on and scored on.
    centroid_mm
        method → the mean centroid error on the held-out frames (mm, against the tracked sections).
    dsc
        method → the mean DSC there.
    margin_spread_mm
        method → the spread (standard deviation over the frames) of the held-out best's
        frame-by-frame margin over it (mm); 0 for the best.
    held_motion_mm, resolved_mm
        How far the tracked section moved over the held-out frames from the last fitted one
        (mm), and the least motion that ranks predictors (:data:`RESOLVED_PX` pixels, mm).
    """

    fit_frames: list[int]
    held_frames: list[int]
    centroid_mm: dict
    dsc: dict
    margin_spread_mm: dict
    held_motion_mm: float = float("inf")
    resolved_mm: float = 0.0

    @property
    def order(self) -> list[str]:
        return sorted(self.centroid_mm, key=lambda m: self.centroid_mm[m])

    @property
    def informative(self) -> bool:
        """Whether the held-out frames moved enough to rank motion predictors."""
        return self.held_motion_mm >= self.resolved_mm

    @property
    def winner(self) -> str:
        if not self.informative and "physics" in self.centroid_mm:
            return "physics"
        return self.order[0]

    def as_good(self, method: str) -> bool:
        """Whether ``method`` is within the spread of the held-out best's margin over it."""
        return self.centroid_mm[method] - self.centroid_mm[self.order[0]] <= self.margin_spread_mm[method]

    def sentence(self) -> str:
        """What the operator reads: which predictor the training frames favour, against which."""
        if self.winner != self.order[0]:
            return (f"the tracked section moved {self.held_motion_mm:.3f} mm over the held-out training frames "
                    f"{self.held_frames[0]}–{self.held_frames[-1]}, less than the images resolve "
                    f"({self.resolved_mm:.3f} mm): they cannot rank the predictors; predicting with the physics")
        best = self.winner
        others = [m for m in self.order if m != best]
        if not others:
            return f"only {_label(best)} could be scored on the held-out training frames"
        rival = "physics" if best != "physics" and "physics" in others else others[0]
        e_best, e_rival = self.centroid_mm[best], self.centroid_mm[rival]
        span = f"held-out training frames {self.held_frames[0]}–{self.held_frames[-1]}"
        if self.as_good(rival):
            return (f"{_label(best)} and {_label(rival)} are as good on the {span} ({e_best:.3f} and {e_rival:.3f} mm, "
                    f"within the margin's spread {self.margin_spread_mm[rival]:.3f} mm): predicting with {_label(best)}")
        ratio = e_rival / e_best if e_best > 0 else float("inf")
        return f"{_label(best)} predicts {ratio:.1f}× better than {_label(rival)} on the {span} ({e_best:.3f} against {e_rival:.3f} mm)"

    def as_dict(self) -> dict:
        return {"fit_frames": [self.fit_frames[0], self.fit_frames[-1]], "held_frames": self.held_frames,
                "centroid_mm": self.centroid_mm, "dsc": self.dsc, "margin_spread_mm": self.margin_spread_mm,
                "order": self.order, "winner": self.winner, "held_motion_mm": self.held_motion_mm,
                "resolved_mm": self.resolved_mm, "informative": self.informative, "sentence": self.sentence()}


def _label(method: str) -> str:
    return {"physics": "the physics", "no_motion": "holding still", "kalman": "the Kalman filter",
            "drive_static": "a regression on the drive", "drive_lagged": "a lagged regression on the drive",
            "physics_corrected": "the physics corrected by a regression of its miss on the drive",
            "physics_anchored": "the physics' motion from the last seen section"
            }.get(method, method.replace("_", " "))


def peer_masks(tracked: dict, fit_frames, frames, program: np.ndarray | None, frame_interval_s: float,
               pixel_mm: float) -> tuple[dict[str, dict[int, np.ndarray]], dict[str, dict]]:
    """The peers' masks at ``frames`` from the tracked masks of ``fit_frames`` (and frame 0):
    holding still, the Kalman filter and, with the program, the drive surrogates. Returns
    ``(method → frame → mask, surrogate → its fit as a dict)``."""
    from hifumotion.prediction.baselines import hold_last, kalman_predict
    from hifumotion.prediction.surrogates import drive_regression_predict

    seen = {f: tracked[f] for f in sorted({0, *fit_frames}) if f in tracked}
    out = {"no_motion": hold_last(seen, frames), "kalman": kalman_predict(seen, frames, frame_interval_s, pixel_mm)}
    fits = {}
    if program is not None:
        for lagged in (False, True):
            masks, fit = drive_regression_predict(seen, frames, program, frame_interval_s, pixel_mm, lagged)
            out[fit.name], fits[fit.name] = masks, fit.as_dict()
    return out, fits


def rank_on_holdout(tracked: dict, training, program: np.ndarray | None, frame_interval_s: float, pixel_mm: float,
                    physics: dict | None = None) -> HoldoutRanking:
    """Rank the predictors on the last quarter of the training frames (module docstring).

    Parameters
    ----------
    tracked
        Frame → the tracked (or given) section's mask: what the predictors see and are scored against.
    training
        The training frames; :func:`holdout_split` splits them.
    program
        ``(T,)`` the push's known program at every frame, or None (no surrogates).
    physics
        Frame → the physics' masks at the held-out frames (and, for its drive-corrected form,
        at the earlier ones), from a calibration on the earlier frames only (None: the physics
        is not ranked).
    """
    from hifumotion.metrics import centroid_distance, dice
    from hifumotion.prediction.surrogates import anchored_to_last, mask_centroids_mm, residual_corrected

    fit, held = holdout_split(training)
    held = [f for f in held if f in tracked and np.asarray(tracked[f]).any()]
    if len(held) < 2:
        raise InputError("fewer than two held-out training frames have a tracked section", "training_frames")
    masks = peer_masks(tracked, fit, held, program, frame_interval_s, pixel_mm)[0]
    if physics is not None and any(f not in physics for f in held):
        raise InputError(f"the physics' masks must cover the held-out frames {held[0]}–{held[-1]}", "physics")
    if physics is not None:
        seen = {f: tracked[f] for f in sorted({0, *fit}) if f in tracked}
        masks = {"physics": physics, **masks}
        if max(seen) in physics:
            masks["physics_anchored"] = anchored_to_last(physics, seen, held, pixel_mm)
        if program is not None and sum(f in physics for f in fit) >= 2:
            masks["physics_corrected"] = residual_corrected(physics, seen, fit, held, program, frame_interval_s,
                                                            pixel_mm)[0]
    errors, dsc = {}, {}
    for name, m in masks.items():
        e = [centroid_distance(m[f], tracked[f], pixel_mm) if m[f].any() else np.inf for f in held]
        errors[name] = np.array(e, float)
        dsc[name] = float(np.mean([dice(m[f], tracked[f]) for f in held]))
    best = min(errors, key=lambda n: float(np.mean(errors[n])))
    spread = {n: 0.0 if n == best else float(np.std(e - errors[best], ddof=1)) for n, e in errors.items()}
    anchor = max(f for f in fit if f in tracked and np.asarray(tracked[f]).any())
    frames, c = mask_centroids_mm({f: tracked[f] for f in [anchor, *held]}, pixel_mm)
    moved = float(np.linalg.norm(c - c[list(frames).index(anchor)], axis=1).max())
    return HoldoutRanking(list(fit), held, {n: float(np.mean(e)) for n, e in errors.items()}, dsc, spread,
                          moved, RESOLVED_PX * pixel_mm)


def holdout_physics(observation, settings, training, log_path=None, progress=None) -> tuple[dict[int, np.ndarray], object]:
    """The physics' masks on the training frames, calibrated on the earlier ones only (the
    held-out ones its prediction).

    ``observation`` (:class:`~hifumotion.estimation.prepare.Observation`) and ``settings``
    (:class:`~hifumotion.estimation.settings.CalibrationSettings`) are the main calibration's;
    only the training frames change. Costs one more calibration. Returns ``(frame → mask, the
    calibration on the earlier frames)``: the main fit is compared with the latter
    (:meth:`~hifumotion.estimation.calibrate.Calibration.compare_with_earlier`)."""
    from hifumotion.estimation.calibrate import calibrate
    from hifumotion.prediction.pipeline import predict_calibrated

    fit, held = holdout_split(training)
    # no online loop runs on the hold-out's fit: its online model would be two runs for nothing
    cal = calibrate(observation, settings.model_copy(update={"training_frames": fit, "online_model": False}),
                    log_path=log_path, progress=progress)
    pred = predict_calibrated(cal.spec, cal.parameters, observation.reference_shape(), fit + held)
    return {f: pred.masks[f] for f in fit + held if f in pred.masks}, cal


def write_chosen(folder, method: str, masks: dict[int, np.ndarray], frame_interval_s: float, pixel_mm: float) -> None:
    """The chosen predictor's sections into ``folder``: ``frames/frame_NNNN.png`` (0/255) and
    ``sections.csv`` (frame, time, the section's centroid in mm, the method) — what to aim at
    when the data favour a predictor other than the physics."""
    from pathlib import Path

    from hifumotion.io.files import write_text
    from hifumotion.io.writers import write_png_stack
    from hifumotion.metrics import centroid

    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    rows = ["frame,time_s,section_centroid_x_mm,section_centroid_y_mm,method"]
    for f in sorted(masks):
        write_png_stack(folder / "frames", masks[f], prefix="frame_", start=int(f), digits=4)
        if masks[f].any():
            x, y = centroid(masks[f], pixel_mm)
            rows.append(f"{int(f)},{f * frame_interval_s:.4f},{x:.4f},{y:.4f},{method}")
    write_text(folder / "sections.csv", "\n".join(rows) + "\n")


__all__ = ["HELD_OUT_SHARE", "RESOLVED_PX", "HoldoutRanking", "holdout_physics", "holdout_split", "peer_masks",
           "rank_on_holdout", "write_chosen"]
