"""From a calibration folder to predicted frames, aim points and the online mode.

:func:`predict_calibrated` runs the fitted model (paper resolution) to the last
frame asked for and returns the masks of the training and validation frames and
the aim point of every frame. :func:`online_predictions` is the clinic's mode:
at frame t, knowing the frames up to t, predict frame t + k; the cheap re-fit is
a translation — the model's section at t is moved onto the observed one
(centroids) — applied to the model's section at t + k.
:func:`write_prediction` writes what ``hifumotion predict`` promises.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hifumotion.metrics import centroid
from hifumotion.prediction.masks import shift_mask
from hifumotion.prediction.physics import Prediction, predict_frames, predicted_mask


@dataclass
class OnlinePredictions:
    """The online mode's predictions: per horizon k, per frame t + k, the model's section moved onto
    the tracked one (a mask), and the aim (mm, image axes): the tracked centroid at t carried by the
    motion of the model's section centroid from t to t + k.

    The aim is what the operator steers by. Moving a binary mask realises a position only to the
    pixel grid's quantisation (a section's straight edge, such as its face on the floor, moves by
    whole rows), so the aim is not read back from the moved mask. The model's own sections are
    rasterised too, but their centroids' motion is the section's (the material point at the frame-0
    centroid drifts from it as the section slides and turns: on the reversal twins it predicted
    the true centroid 1.1–2.5× worse)."""

    masks: dict = field(default_factory=dict)       # k -> {t + k: bool (H, W)}
    aims_mm: dict = field(default_factory=dict)     # k -> {t + k: (2,) mm}


def online_predictions(pred: Prediction, spec, reference, observed_masks: np.ndarray, horizons_frames,
                       now_frames) -> OnlinePredictions:
    """At each ``t`` in ``now_frames`` and each horizon k, the model's section of t + k moved by
    the offset between the observed and the model's section at t (model masks from ``pred.run``),
    and the aim (:class:`OnlinePredictions`)."""
    run = pred.run
    cache: dict[int, np.ndarray] = {}

    def model_mask(f):
        if f not in cache:
            cache[f] = predicted_mask(run.kept[f], run.rest_mm, spec.spacing_mm, reference)
        return cache[f]

    out = OnlinePredictions({int(k): {} for k in horizons_frames}, {int(k): {} for k in horizons_frames})
    for t in now_frames:
        if not observed_masks[t].any() or t not in run.kept:
            continue
        m_t = model_mask(t)
        if not m_t.any():
            continue
        offset = centroid(observed_masks[t]) - centroid(m_t)   # (x, y) px
        for k in horizons_frames:
            f = t + int(k)
            if f in run.kept and model_mask(f).any():
                out.masks[int(k)][f] = shift_mask(model_mask(f), offset)
                out.aims_mm[int(k)][f] = (centroid(model_mask(f)) + offset) * pred.pixel_mm
    return out


def online_csv(predictions: OnlinePredictions, observed_masks: np.ndarray, pixel_mm: float,
               frame_interval_s: float) -> str:
    """``horizon_frames, horizon_ms, frame, predicted_x_mm, predicted_y_mm, tracked_x_mm, tracked_y_mm, error_mm``:
    the online aims (the predicted centroids) against the tracked section of the same frame (when there is one)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["horizon_frames", "horizon_ms", "frame", "predicted_x_mm", "predicted_y_mm", "tracked_x_mm",
                "tracked_y_mm", "error_mm"])
    for k in sorted(predictions.aims_mm):
        for f in sorted(predictions.aims_mm[k]):
            p = np.asarray(predictions.aims_mm[k][f], float)
            row = [k, f"{1000 * k * frame_interval_s:.1f}", f, f"{p[0]:.4f}", f"{p[1]:.4f}"]
            if f < len(observed_masks) and observed_masks[f].any():
                o = centroid(observed_masks[f], pixel_mm)
                row += [f"{o[0]:.4f}", f"{o[1]:.4f}", f"{np.hypot(*(p - o)):.4f}"]
            else:
                row += ["", "", ""]
            w.writerow(row)
    return buf.getvalue()


def predict_calibrated(spec, k, reference, frames, online_frames=()) -> Prediction:
    """The fitted model's masks of ``frames`` (and of ``online_frames``, kept for the online mode)."""
    wanted = sorted(set(int(f) for f in frames) | set(int(f) for f in online_frames))
    return predict_frames(spec, k, reference, wanted)


def aim_csv(pred: Prediction, frame_interval_s: float, masks: dict | None = None) -> str:
    """``frame, time_s, aim_x_mm, aim_y_mm, shift_x_mm, shift_y_mm, shift_mm, section_centroid_x_mm,
    section_centroid_y_mm`` and, with the prediction's band (:mod:`hifumotion.prediction.band`),
    ``band_mm, aim_minus_x_mm, aim_minus_y_mm, aim_plus_x_mm, aim_plus_y_mm``.

    Image axes (x = column, y = row) in mm from pixel (0, 0)'s centre; the shift is from the plan (frame 0)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    band = pred.band
    w.writerow(["frame", "time_s", "aim_x_mm", "aim_y_mm", "shift_x_mm", "shift_y_mm", "shift_mm",
                "section_centroid_x_mm", "section_centroid_y_mm"]
               + (["band_mm", "aim_minus_x_mm", "aim_minus_y_mm", "aim_plus_x_mm", "aim_plus_y_mm"]
                  if band is not None else []))
    for f, a in enumerate(pred.aim_mm):
        d = a - pred.aim_plan_mm
        c = ("", "")
        if masks is not None and f in masks and masks[f].any():
            c = tuple(f"{v:.4f}" for v in centroid(masks[f], pred.pixel_mm))
        row = [f, f"{f * frame_interval_s:.4f}", f"{a[0]:.4f}", f"{a[1]:.4f}", f"{d[0]:.4f}", f"{d[1]:.4f}",
               f"{np.hypot(*d):.4f}", *c]
        if band is not None:
            row += ([f"{band.width_mm[f]:.4f}", *(f"{v:.4f}" for v in band.aim_mm[:, f].ravel())]
                    if f < len(band.width_mm) else [""] * 5)
        w.writerow(row)
    return buf.getvalue()


def write_prediction(folder: str | Path, pred: Prediction, frames, frame_interval_s: float) -> None:
    """``frames/frame_NNNN.png`` (0/255), ``contours.csv`` and ``aim.csv`` into ``folder``."""
    from hifumotion.contour import Contour
    from hifumotion.io.files import write_text
    from hifumotion.io.writers import write_contours_csv, write_png_stack

    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    frames = [int(f) for f in frames if int(f) in pred.masks]
    for f in frames:
        write_png_stack(folder / "frames", pred.masks[f], prefix="frame_", start=f, digits=4)
    contours = {f: Contour.from_mask(pred.masks[f], pred.pixel_mm) for f in frames if pred.masks[f].any()}
    write_contours_csv(folder / "contours.csv", contours)
    write_text(folder / "aim.csv", aim_csv(pred, frame_interval_s, pred.masks))


def write_particles(folder: str | Path, pred: Prediction, frame_interval_s: float) -> Path:
    """The model's tissue in the frames it kept: ``particles/frame_NNNN.vtu`` (positions in mm,
    ``displacement_mm`` since frame 0) and ``tissue.pvd`` to play them in ParaView."""
    from hifumotion.particles.output import write_points_vtu, write_pvd

    folder = Path(folder)
    (folder / "particles").mkdir(parents=True, exist_ok=True)
    rest = pred.run.rest_mm
    entries = []
    for f in sorted(pred.run.kept):
        name = f"particles/frame_{f:04d}.vtu"
        x = pred.run.kept[f]
        write_points_vtu(folder / name, x, {"displacement_mm": x - rest,
                                            "displacement_magnitude_mm": np.linalg.norm(x - rest, axis=1)})
        entries.append((f * frame_interval_s, name))
    return write_pvd(folder / "tissue.pvd", entries)


def write_prediction_folder(folder: str | Path, pred: Prediction, frames, frame_interval_s: float,
                            validation, seconds: float) -> dict:
    """Everything ``prediction/`` holds, for ``hifumotion predict`` and the pipeline alike:
    masks, ``contours.csv``, ``aim.csv`` (:func:`write_prediction`), ``tissue.pvd``
    (:func:`write_particles`) and ``prediction.json`` — the frames, the parameters, the
    prediction's wall time, the simulated span and the validation window (s) and their ratio
    (below 1: faster than the window lasts). Returns ``prediction.json``'s contents."""
    from hifumotion.io import write_json

    frames = sorted(int(f) for f in frames)
    write_prediction(folder, pred, frames, frame_interval_s)
    write_particles(folder, pred, frame_interval_s)
    validation = sorted(int(f) for f in validation)
    window = (validation[-1] - validation[0]) * frame_interval_s if len(validation) > 1 else None
    summary = {"frames": frames, "parameters": pred.run.parameters.as_dict(), "seconds": seconds,
               "simulated_s": max(frames) * frame_interval_s, "validation_frames": validation,
               "validation_window_s": window, "realtime_ratio": None if not window else seconds / window}
    if pred.band is not None:
        summary["band"] = pred.band.as_dict()
    write_json(Path(folder) / "prediction.json", summary)
    return summary


__all__ = ["OnlinePredictions", "write_prediction_folder", "online_predictions", "online_csv", "predict_calibrated", "write_prediction", "write_particles", "aim_csv",
           "shift_mask"]
