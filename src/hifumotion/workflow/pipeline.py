"""The whole system on one observed experiment, in one documented order.

:func:`run_pipeline` is what ``hifumotion demo`` (on the built-in synthetic experiment)
and ``hifumotion run CONFIG.toml`` (on a user's files) share:

1. **observe** (:func:`~hifumotion.estimation.prepare.prepare`): segment the sweep with
   GLCV, reconstruct the tissue in 3D, track the time series from the clicked contour by
   speckle tracking (or take the user's training contours);
2. **calibrate** (:func:`~hifumotion.estimation.calibrate.calibrate`) on the training
   frames → ``calibration/`` (``parameters.json``, the model, the reconstruction);
3. **predict** the training and validation frames with the fitted model, the online
   mode's frames and the aim point of every frame → ``prediction/`` (masks, contours,
   ``aim.csv``, ``online.csv``, ``tissue.pvd`` for ParaView);
4. **online loop** (:func:`~hifumotion.prediction.online.online_loop`): the cine frame by
   frame, each tracked frame assimilated by the reduced model, t + k predicted →
   ``prediction/online_loop.csv`` (each frame's latency), ``online_loop.json``;
5. **choose** (``choose_predictor``): the physics and the predictors that know the same
   inputs ranked on the last quarter of the training frames → ``prediction/choice.json``,
   and where another predictor wins, its validation sections → ``prediction/chosen/``;
6. **score** the physics and the baselines (no motion, Kalman, the drive surrogates, NCC
   online) against the truth — a twin's, or the user's expert masks; without either, against the tracked
   contours, and the report says so → ``scores/`` (Table 4 CSV/JSON, overlays).

Each step's output folder is written inside ``out``, which the caller created with
:func:`~hifumotion.io.output_folder` (new, atomic).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Literal

import numpy as np
from pydantic import Field, field_validator

from hifumotion.errors import InputError
from hifumotion.estimation.settings import DEFAULT_BLOOM_RULE, CalibrationSettings

if TYPE_CHECKING:      # the observed folder's reader pulls the image stack: imported where it runs
    from hifumotion.observed import Observed

Progress = Callable[[str, float], None]


class EstimationConfig(CalibrationSettings):
    """How to calibrate and predict (``[estimation]`` of a run configuration): the calibration's
    settings (:class:`~hifumotion.estimation.settings.CalibrationSettings`, one home for each)
    and what the pipeline around it adds."""

    training_frames: str | None = Field(
        None, description="training frames, '20,30,40' or '20:101:10' (default: the paper's protocol scaled to the series)")
    validation_frames: str | None = Field(
        None, description="validation frames, same forms (default: the paper's protocol scaled to the series)")
    tracking: Literal["speckle", "glcv"] = Field(
        "speckle", description="how the time series is observed: frame 0's contour carried by speckle tracking, or GLCV re-segmenting every frame (the paper)")
    boundary_offset_mm: float = Field(0.0, ge=-5, le=5, description="how far outside the true boundary the imaging system's segmentations lie (mm), measured on a phantom of known size; masks are moved inwards by it (0: none, as the paper)")
    horizons_frames: list[int] = Field([4, 6, 8], description="online mode: horizons in frames (empty: no online mode)")
    bloom_continuation: Literal["reconstruction", "image", "off"] = Field(
        DEFAULT_BLOOM_RULE, description="speckle tracking: what gives frame 0's target the strip the bar's bloom hides (tissue pressed by the bar reaches it): reconstruction — where the reconstruction, its top continued under the bar, holds tissue (without that, the strip stays cut); image — also, without it, where tissue is seen at the bloom's edge; off — the strip stays cut. It removes the tracked section's bias towards the side away from the bar (docs/decisions.md, \"Frame 0's target reaches the bar\"); true and false read as image and off")
    online_loop: bool = Field(True, description="also run the online loop: every frame assimilated by the reduced model (its state and the push's size), t + k predicted (speckle tracking only)")
    prediction_band: bool = Field(True, description="also predict the aim one standard error either way along the direction the training frames fix least (two more runs of the model): aim.csv's band_mm, prediction.json's band, the report")
    @field_validator("horizons_frames")
    @classmethod
    def _horizons(cls, v):
        from hifumotion.resources import MAX_FRAMES

        if any(not 1 <= h <= MAX_FRAMES for h in v):
            raise ValueError(f"horizons are whole frames from 1 to {MAX_FRAMES:,} ahead, got {v}")
        return sorted(set(v))

    @field_validator("bloom_continuation", mode="before")
    @classmethod
    def _bloom_rule(cls, v):
        # a yes/no from a configuration written before the rules were named: yes was the image's rule
        return {True: "image", False: "off"}.get(v, v) if isinstance(v, bool) else v

    choose_predictor: bool = Field(False, description="rank the physics and the predictors that know the same inputs (the drive surrogates, the Kalman filter, holding still) on the last quarter of the training frames, the physics calibrated again on the earlier ones (one more calibration), and record which the data support (prediction/choice.json, the scores, the report)")


@dataclass
class PipelineOutcome:
    """What :func:`run_pipeline` computed and where it wrote it."""

    calibration: object             # estimation.calibrate.Calibration
    prediction: object              # prediction.physics.Prediction
    evaluation: object              # prediction.evaluate.Evaluation
    truth_kind: str                 # "twin", "expert masks" or "tracked contours"
    training: list[int]
    validation: list[int]
    predict_s: float
    folders: dict = field(default_factory=dict)
    truth_parameters: dict | None = None
    online_loop: object = None      # prediction.online.OnlineResult, when the online loop ran

    @property
    def realtime_ratio(self) -> float:
        """Prediction wall time over the validation window's duration (< 1: faster than real time)."""
        spec = self.calibration.spec
        window = (self.validation[-1] - self.validation[0]) * spec.frame_interval_s
        return self.predict_s / window if window > 0 else float("nan")


def check_protocol(training: list[int], validation: list[int], horizons: list[int], n_frames: int) -> None:
    """The frames of a run, checked against each other before any work: no frame both trained
    on and scored, every horizon shorter than the series (each an :class:`InputError` naming
    the setting)."""
    both = sorted(set(training) & set(validation))
    if both:
        raise InputError(f"frames {both[:5]}{'…' if len(both) > 5 else ''} are both training and validation frames; "
                         "a prediction is scored on frames the calibration did not see", "estimation.validation_frames")
    if any(h >= n_frames for h in horizons):
        raise InputError(f"horizons must be shorter than the series ({n_frames} frames), got {list(horizons)}",
                         "estimation.horizons_frames")


def observe_and_calibrate(observed: Observed, folder: str | Path, settings: EstimationConfig, training: list[int],
                          contours_csv: str | Path | None = None, record=None, progress: Progress | None = None,
                          observed_dir: str | Path | None = None, resume_log: str | Path | None = None):
    """Steps 1–2 (observe, calibrate) into ``folder`` (the calibration folder): what
    :func:`run_pipeline` and ``hifumotion calibrate`` both run. ``resume_log``: the search log
    of an interrupted calibration, whose runs are not repeated. Returns the observation and
    the :class:`~hifumotion.estimation.calibrate.Calibration`."""
    import shutil
    from contextlib import nullcontext

    from hifumotion.estimation.calibrate import calibrate
    from hifumotion.estimation.prepare import prepare
    from hifumotion.estimation.store import save_calibration

    s = settings
    folder = Path(folder)
    tell = progress or (lambda stage, fraction: None)
    stage = record.stage if record is not None else (lambda name: nullcontext())
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "search_log.jsonl"
    if resume_log is not None:
        shutil.copyfile(resume_log, log)
    with stage("observe: segment sweep, reconstruct, track"):
        observation = prepare(observed, contours_csv, progress=tell, boundary_offset_mm=s.boundary_offset_mm,
                              tracking=s.tracking, bloom_continuation=s.bloom_continuation)
    with stage("calibrate"):
        # the pipeline's training frames, parsed once for the series (EstimationConfig is a
        # CalibrationSettings: every other setting passes as it is)
        cal = calibrate(observation, s.model_copy(update={"training_frames": training}),
            log_path=log, progress=tell)
    with stage("write the calibration"):
        cal.summary = save_calibration(cal, folder, observed_dir)
    return observation, cal


def run_pipeline(observed: Observed | str | Path, out: str | Path, settings: EstimationConfig | None = None,
                 contours_csv: str | Path | None = None, truth_masks: dict | None = None,
                 truth_kind: str = "expert masks", truth_parameters: dict | None = None,
                 record=None, progress: Progress | None = None,
                 observed_dir: str | Path | None = None) -> PipelineOutcome:
    """Steps 1–4 of the module docstring on ``observed``; outputs under ``out``.

    ``observed`` is an :class:`~hifumotion.observed.Observed` in memory, or an ``observed/``
    folder to read; ``observed_dir``, where an in-memory one was written (the calibration
    records it).

    ``truth_masks`` (frame → bool mask) is what the scores are measured against; a twin's
    ``truth_parameters`` (``truth/parameters.json``) puts the truth beside the fit.
    ``record`` (a :class:`~hifumotion.run_info.RunRecord`) gets each step's time.
    """
    from contextlib import nullcontext

    from hifumotion.estimation.protocol import default_frames, parse_frames
    from hifumotion.observed import Observed, load_observed
    from hifumotion.io import write_json
    from hifumotion.io.files import write_text
    from hifumotion.prediction.evaluate import evaluate, online_schedule
    from hifumotion.prediction.pipeline import online_csv, predict_calibrated, write_prediction_folder
    from hifumotion.scoring import overlay_figure

    s = settings or EstimationConfig()
    out = Path(out)
    tell = progress or (lambda stage, fraction: None)
    stage = record.stage if record is not None else (lambda name: nullcontext())
    if not isinstance(observed, Observed):
        observed_dir = observed
        observed = load_observed(observed)
    n = len(observed.frames)
    auto_train, auto_valid = default_frames(n)
    training = parse_frames(s.training_frames, n, "estimation.training_frames") or auto_train
    validation = parse_frames(s.validation_frames, n, "estimation.validation_frames") or auto_valid
    check_protocol(training, validation, s.horizons_frames, n)

    observation, cal = observe_and_calibrate(observed, out / "calibration", s, training, contours_csv,
                                             record=record, progress=tell, observed_dir=observed_dir)

    with stage("predict"):
        tell("predict", 0.0)
        now, keep = online_schedule(training, validation, s.horizons_frames, n)
        reference = observation.reference_shape()
        t0 = time.perf_counter()
        pred = predict_calibrated(cal.spec, cal.parameters, reference, sorted(set(training) | set(validation)), keep)
        predict_s = time.perf_counter() - t0
        if s.prediction_band:
            from hifumotion.prediction.band import aim_band, covariance_from_calibration

            pred.band = aim_band(cal.spec, cal.parameters, reference, sorted(set(training) | set(validation)),
                                 covariance_from_calibration(cal.summary), pred.aim_mm)
        folder = out / "prediction"
        prediction_summary = write_prediction_folder(folder, pred, sorted(set(training) | set(validation)),
                                                     observed.frame_interval_s, validation, predict_s)
        tell("predict", 1.0)

    program = observed.setup.program_at_frames(n)
    choice = None
    if s.choose_predictor:
        with stage("choose the predictor"):
            from hifumotion.prediction.choice import holdout_physics, rank_on_holdout

            held, earlier = holdout_physics(observation, s.model_copy(update={"training_frames": training}), training,
                                            log_path=out / "calibration" / "holdout_search_log.jsonl", progress=tell)
            choice = rank_on_holdout({f: observation.frame_masks[f] for f in range(n)}, training, program,
                                     observed.frame_interval_s, float(observed.pixel_mm), held)
            write_json(folder / "choice.json", choice.as_dict())
            # the ranking beside the parameters it qualifies and the prediction it may overrule;
            # the earlier frames' fit qualifies what the parameters call determined
            prediction_summary["choice"] = cal.summary["predictor_choice"] = choice.as_dict()
            cal.summary["fit"]["holdout_shift"] = cal.compare_with_earlier(earlier).as_dict()
            cal.summary["parameters"] = cal.report()
            write_json(folder / "prediction.json", prediction_summary)
            write_json(out / "calibration" / "parameters.json", cal.summary)

    live = None
    if s.online_loop and s.horizons_frames and observation.motion is not None:
        with stage("online loop"):
            from hifumotion.prediction.online import online_loop

            horizons = [h for h in s.horizons_frames if 1 <= h < n]
            if horizons:
                live = online_loop(cal.spec, cal.parameters, observation, horizons, progress=tell)
                write_text(folder / "online_loop.csv", live.to_csv())
                write_json(folder / "online_loop.json", live.summary())

    with stage("score"):
        if truth_masks is None:
            truth_masks = {f: observation.frame_masks[f] for f in range(n)}
            truth_kind = "tracked contours"
        ev = evaluate(pred, cal.spec, reference, observation.frame_masks, observed.frames, truth_masks,
                      training, validation, observed.frame_interval_s, s.horizons_frames, now,
                      program=program, choice=choice)
        if choice is not None and choice.winner != "physics" and choice.winner in ev.baseline_masks:
            # the data favour another predictor: its sections beside the physics', for the aim
            from hifumotion.prediction.choice import write_chosen

            write_chosen(folder / "chosen", choice.winner, ev.baseline_masks[choice.winner],
                         observed.frame_interval_s, float(observed.pixel_mm))
        if ev.online_predictions is not None:
            write_text(folder / "online.csv", online_csv(ev.online_predictions, observation.frame_masks,
                                                         pred.pixel_mm, observed.frame_interval_s))
        scores = out / "scores"
        write_text(scores / "table4.csv", ev.table.to_csv())
        write_json(scores / "scores.json", {"truth": truth_kind, "pixel_mm": pred.pixel_mm,
                                            "training_frames": training, "validation_frames": validation,
                                            **ev.as_dict()})
        images = {f: observed.frames[f] for f in training + validation}
        overlay_figure(images, truth_masks, pred.masks, training + validation, scores / "overlays.png")
    outcome = PipelineOutcome(cal, pred, ev, truth_kind, training, validation, predict_s,
                              {"calibration": out / "calibration", "prediction": folder, "scores": scores},
                              truth_parameters, live)
    return outcome


def outcome_summary(o: PipelineOutcome) -> dict:
    """The figures a run records (``run_info.json``) and prints."""
    v = o.evaluation.physics["validation"]
    margin = o.evaluation.physics.get("margin_over_no_motion") or {}
    out = {"truth": o.truth_kind, "validation_dsc_mean": v.get("dsc_mean"), "validation_dsc_min": v.get("dsc_min"),
           "validation_centroid_mean_mm": v.get("centroid_mean_mm"),
           "no_motion_validation_dsc_mean": o.evaluation.baselines["no_motion"].get("dsc_mean"),
           "kalman_validation_dsc_mean": o.evaluation.baselines["kalman"].get("dsc_mean"),
           "physics_vs_no_motion": margin.get("verdict"),
           "verdict": o.evaluation.physics.get("verdict"),
           "choice": (o.evaluation.physics.get("choice") or {}).get("sentence"),
           "ranking": [r["method"] for r in o.evaluation.physics.get("ranking", [])],
           "dsc_margin_over_no_motion": margin.get("dsc_margin_mean"),
           "dsc_margin_spread": margin.get("dsc_margin_std"),
           "centroid_margin_over_no_motion_mm": margin.get("centroid_margin_mean_mm"),
           "centroid_margin_spread_mm": margin.get("centroid_margin_std_mm"),
           "online_loop_latency_with_tracking_ms_median": (o.online_loop.summary()["latency_with_tracking_ms"]["median"]
                                                           if o.online_loop is not None else None),
           "online_loop_push_scale_last": float(o.online_loop.scale[-1]) if o.online_loop is not None else None,
           "aim_band_largest_mm": (float(o.prediction.band.width_mm.max())
                                   if o.prediction.band is not None else None),
           "calibration_runs": o.calibration.runs, "predict_s": o.predict_s,
           "predict_over_realtime": o.realtime_ratio, "parameters": o.calibration.parameters.as_dict()}
    return {k: (round(v, 5) if isinstance(v, float) and np.isfinite(v) else v) for k, v in out.items()}


__all__ = ["EstimationConfig", "PipelineOutcome", "check_protocol", "observe_and_calibrate", "run_pipeline",
           "outcome_summary"]
