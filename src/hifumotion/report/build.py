"""``report/report.html``: what a run found, for a person to read.

:func:`write_report` takes a :class:`~hifumotion.workflow.pipeline.PipelineOutcome` and
the run's other results (segmentation comparisons, timings) and writes the page and its
PNGs into one folder: the segmentation comparison (the paper's Table 2, Figures 2–3),
the reconstructed tissue, the fitted parameters with their uncertainty beside the truth
(Table 3), per-frame DSC (Table 4) with the overlays (Fig. 4), the baselines, the online
mode, the aim trajectory, the timings, and how to open the 3D output in ParaView and
3D Slicer.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hifumotion.report import figures
from hifumotion.report.html import esc, figure, fmt, page, paragraph, table

PARAMETER_ROWS = [
    ("external_force_n", "external force F", "N"),
    ("youngs_modulus_pa", "Young's modulus E", "Pa"),
    ("poisson_ratio", "Poisson's ratio ν", "—"),
    ("beta1_pa_s_pow", "β1", "Pa·s^β2"),
    ("beta2", "β2", "—"),
    ("force_over_youngs_m2", "F/E (what a push fixes)", "m²"),
    ("beta1_over_youngs_s_pow", "β1/E", "s^β2"),
]


@dataclass
class SegmentationSection:
    """One segmentation comparison for the report (see :mod:`hifumotion.segmentation.compare`)."""

    title: str
    comparison: object                  # segmentation.compare.Comparison
    figure2: Path
    figure3: Path
    note: str = ""


@dataclass
class ReportInputs:
    """Everything :func:`write_report` draws on besides the pipeline's outcome."""

    title: str = "hifumotion run"
    segmentation: list[SegmentationSection] = field(default_factory=list)
    timings_s: dict = field(default_factory=dict)
    experiment_note: str = ""
    experiment_facts: dict = field(default_factory=dict)
    true_centroid_mm: np.ndarray | None = None     # (T, 2) the truth's section centroid per frame (twin)
    true_push_scale: np.ndarray | None = None      # (T,) the true push over the announced program (twin): relative_push
    links: dict = field(default_factory=dict)      # label -> path of output files worth opening


def output_links(out: str | Path, extra: dict | None = None) -> dict:
    """The files of a pipeline's output folder ``out`` worth opening, by label (plus ``extra``)."""
    out = Path(out)
    links = {"prediction/tissue.pvd — the fitted model's tissue, predicted frames (ParaView)":
             out / "prediction" / "tissue.pvd",
             "calibration/observation/tissue.vtp — reconstructed surface (ParaView)":
             out / "calibration" / "observation" / "tissue.vtp",
             "calibration/observation/tissue_volume.nii.gz — reconstructed volume (3D Slicer)":
             out / "calibration" / "observation" / "tissue_volume.nii.gz",
             "calibration/parameters.json — fitted parameters": out / "calibration" / "parameters.json",
             "prediction/aim.csv — where to aim, every frame": out / "prediction" / "aim.csv",
             "scores/table4.csv — per-frame scores": out / "scores" / "table4.csv",
             "observed/frames.nii.gz — the time series as read (3D Slicer)": out / "observed" / "frames.nii.gz"}
    links.update(extra or {})
    return links


def _rel(target: Path, folder: Path) -> str:
    return Path(os.path.relpath(Path(target).resolve(), folder.resolve())).as_posix()


def _copy(src: Path, folder: Path, name: str | None = None) -> str:
    dst = folder / (name or Path(src).name)
    if Path(src).resolve() != dst.resolve():
        shutil.copyfile(src, dst)
    return dst.name


def _segmentation_parts(results: list[SegmentationSection], folder: Path) -> list[str]:
    parts = [paragraph("Every method starts from the same initial contour on every image and is scored against "
                       "the reference masks: DSC (higher is better), MSSD, Hausdorff distance and its 95th "
                       "percentile in pixels (lower is better), and the time per image.")]
    for i, r in enumerate(results):
        cmp = r.comparison
        rows = [[m.upper(), cmp.mean(m, "dsc"), cmp.mean(m, "mssd"), cmp.mean(m, "hausdorff"), cmp.mean(m, "hd95"),
                 cmp.mean(m, "seconds")] for m in cmp.methods]
        best = max(cmp.methods, key=lambda m: cmp.mean(m, "dsc"))
        parts.append(f"<h3>{esc(r.title)}</h3>")
        if r.note:
            parts.append(paragraph(r.note))
        parts.append(table(["method", "DSC", "MSSD (px²)", "Hausdorff (px)", "HD95 (px)", "s / image"], rows,
                           f"Table 2 on {len(cmp.images)} images; best DSC: {best.upper()}"))
        parts.append(figure(_copy(r.figure2, folder, f"segmentation_{i}_figure2.png"),
                            "Figure 2: the segmentations (each method's contour over the image; reference in green)"))
        parts.append(figure(_copy(r.figure3, folder, f"segmentation_{i}_figure3.png"),
                            "Figure 3: the scores per image"))
    return parts


def _parameter_parts(outcome) -> list[str]:
    from hifumotion.estimation.calibrate import recovered_parameters

    cal = outcome.calibration
    rep = cal.report()
    truth = outcome.truth_parameters
    recovered = recovered_parameters(rep, cal.parameters, truth) if truth else {}
    truth_values = {}
    if truth:
        e = truth["youngs_modulus_pa"]
        truth_values = {"external_force_n": truth["external_force_n"], "youngs_modulus_pa": e,
                        "poisson_ratio": truth["poisson_ratio"], "beta1_pa_s_pow": truth["beta1_pa_s_pow"],
                        "beta2": truth["beta2"],
                        "force_over_youngs_m2": (None if truth["external_force_n"] is None
                                                 else truth["external_force_n"] / e),
                        "beta1_over_youngs_s_pow": truth["beta1_pa_s_pow"] / e}
    rows = []
    for key, label, unit in PARAMETER_ROWS:
        entry = rep[key]
        rel = recovered.get(key, {}).get("rel_error")
        rows.append([label, unit, entry["value"], entry["std"], entry["determined"], truth_values.get(key),
                     "—" if rel is None else f"{100 * rel:+.1f} %"])
    parts = [table(["parameter", "unit", "fitted", "std. error", "determined by the data", "truth", "error"], rows,
                   "Table 3: the fitted parameters")]
    parts.append(paragraph(
        f"Method: {cal.search.method if cal.search is not None else 'table1'}; {cal.runs} forward runs; "
        f"training frames {cal.training_frames}. A quasi-static push is unchanged when F, E and β1 are scaled "
        "together, so the force is held at its nominal value and the data are judged on F/E and β1/E. "
        "'—' as an error: the data do not bound that direction. A standard error says how closely the "
        "training frames pin the model's parameters; it does not include the model's own error (the "
        "reconstructed geometry, the particle resolution), which can be larger."))
    caveats = cal.caveats()
    if caveats:
        parts.append(paragraph("No parameter is reported as determined by the data: " + "; ".join(caveats) + "."))
    moved = [] if cal.holdout_shift is None else cal.holdout_shift.moved
    if moved:
        from hifumotion.estimation.stability import LABELS

        parts.append(paragraph("Not determined whatever its standard error says: " + "; ".join(
            f"{LABELS.get(name, name)}: {cal.holdout_shift.reason(name)}" for name in moved) + "."))
    if cal.degeneracy:
        rows = [[f"×{d['factor']:g}", d["cost_mm"]] for d in cal.degeneracy]
        if rows:
            parts.append(table(["F, E, β1 scaled by", "Σ S_t (mm)"], rows, "The scaling the push cannot see"))
    return parts


def _prediction_parts(outcome, truth: dict, folder: Path) -> list[str]:
    from hifumotion.metrics import centroid_distance, dice

    ev = outcome.evaluation
    rows = [[r["frame"], r["set"], r["dsc"], r["hd95_mm"], r["centroid_error_mm"]] for r in ev.table.rows]
    parts = [paragraph(f"Predicted sections against the {outcome.truth_kind}: DSC, 95th-percentile Hausdorff "
                       "distance and centroid error (where the focus would be aimed) per frame.")]
    if outcome.truth_kind == "tracked contours":
        parts.append(paragraph("No independent truth was given: the scores compare the prediction with the "
                               "tracked contours, which include the tracking's own error.", "note"))
    frames = [r["frame"] for r in ev.table.rows]
    baseline_curves, centroid_curves = {}, {}
    pixel = float(outcome.prediction.pixel_mm)
    for name, masks in ev.baseline_masks.items():
        f = [fr for fr in outcome.validation if fr in masks and fr in truth]
        baseline_curves[name] = (f, [dice(masks[fr], truth[fr]) for fr in f])
        f = [fr for fr in f if masks[fr].any() and truth[fr].any()]
        centroid_curves[name] = (f, [centroid_distance(masks[fr], truth[fr], pixel) for fr in f])
    parts.append(figure(figures.dsc_per_frame(frames, [r["dsc"] for r in ev.table.rows], baseline_curves,
                                              folder / "dsc_per_frame.png", outcome.training, outcome.validation).name,
                        "Table 4 as a plot: DSC per frame, training then validation; baselines on the validation frames"))
    parts.append(figure(figures.centroid_error_per_frame(frames, [r["centroid_error_mm"] for r in ev.table.rows],
                                                         centroid_curves, folder / "centroid_per_frame.png",
                                                         outcome.training, outcome.validation).name,
                        "Where each predictor would aim: centroid error per frame, the physics beside every baseline "
                        "(the drive surrogates among them where the push's program is known)"))
    parts.append(table(["frame", "set", "DSC", "HD95 (mm)", "centroid error (mm)"], rows, "Table 4: per frame"))
    parts.append(figure(_copy(outcome.folders["scores"] / "overlays.png", folder),
                        "Figure 4: true (green) and predicted (red) contours on the observed frames"))
    return parts


def _baseline_parts(outcome, folder: Path) -> list[str]:
    ev = outcome.evaluation
    v = ev.physics["validation"]
    rows = [["physics (fitted model)", v.get("dsc_mean"), v.get("dsc_min"), v.get("hd95_mean_mm"),
             v.get("centroid_mean_mm"), v.get("centroid_max_mm")]]
    for name, s in ev.baselines.items():
        rows.append([name.replace("_", " "), s.get("dsc_mean"), s.get("dsc_min"), s.get("hd95_mean_mm"),
                     s.get("centroid_mean_mm"), s.get("centroid_max_mm")])
    best = max(rows, key=lambda r: r[1] if r[1] is not None else -1)[0]
    parts = [table(["method", "DSC mean", "DSC min", "HD95 mean (mm)", "centroid mean (mm)", "centroid max (mm)"],
                   rows, f"Validation frames {outcome.validation}: best mean DSC — {best}")]
    if ev.physics.get("verdict"):
        parts.append(paragraph(f"Of every predictor, by the validation centroid error: {ev.physics['verdict']}."))
    choice = ev.physics.get("choice")
    if choice:
        parts.append(paragraph(f"Chosen before the validation frames, on a hold-out of the training frames: "
                               f"{choice['sentence']}. On the validation frames the choice ({choice['chosen'].replace('_', ' ')}) "
                               f"scores DSC {fmt(choice['validation'].get('dsc_mean'), 4)}, centroid "
                               f"{fmt(choice['validation'].get('centroid_mean_mm'), 3)} mm."))
    parts.append(paragraph("No motion holds the last training contour; the Kalman filter runs on the contour's "
                           "centroid and radial shape; the drive surrogates regress the tracked centroid on the "
                           "push's known program (setup.json), static and with a first-order lag, and move the "
                           "last training contour by it — all from the same contours the physics was fitted to."))
    if ev.online:
        methods = [m for m in ("physics", "no_motion", "ncc", "kalman", "surrogate")
                   if all(m in e for e in ev.online.values())]
        label = {"physics": "physics", "no_motion": "no motion", "ncc": "NCC", "kalman": "Kalman",
                 "surrogate": "surrogate"}
        aimed = [m for m in methods if all(m in e.get("aim", {}) for e in ev.online.values())]
        rows = []
        for h, e in sorted(ev.online.items(), key=lambda kv: int(kv[0])):
            rows.append([f"{e['horizon_frames']} frames ({e['horizon_ms']:.0f} ms)"]
                        + [e[m].get("dsc_mean") for m in methods]
                        + [e[m].get("centroid_mean_mm") for m in methods]
                        + [e["aim"][m].get("centroid_mean_mm") for m in aimed])
        parts.append("<h3>Online mode</h3>")
        parts.append(paragraph("At each frame t, knowing the frames up to t, predict frame t + k: the physics "
                               "re-anchored on the tracked frame t, holding frame t, the NCC template tracker, "
                               "a Kalman filter over the last ten frames and, where the program is known, the "
                               "drive surrogate updated at every frame (recursive least squares)."))
        if aimed:
            parts.append(paragraph("The aim columns score where each predictor puts the centroid, before its "
                                   "mask rounds it to the pixel grid (a straight edge, such as the face on the "
                                   "floor, moves by whole rows): what the operator steers by."))
        parts.append(table(["horizon"] + [f"DSC {label[m]}" for m in methods]
                           + [f"centroid {label[m]} (mm)" for m in methods]
                           + [f"aim {label[m]} (mm)" for m in aimed], rows,
                           "Online prediction error against the horizon"))
        parts.append(figure(figures.online_horizons(ev.online, folder / "online.png").name,
                            "Online mode: error against the horizon"))
    return parts


def _nanmean(values: np.ndarray) -> float | None:
    return float(np.nanmean(values)) if np.isfinite(values).any() else None


def relative_push(true_push: np.ndarray, program: np.ndarray, reference_frame: int) -> np.ndarray:
    """The true push (force N or travel mm, per frame) over the announced program's shape, as a
    multiple of that ratio at ``reference_frame`` (the last frame the calibration saw): what the
    online filter's push scale estimates. NaN where the program is zero (before the push)."""
    true_push, program = np.asarray(true_push, float), np.asarray(program, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.abs(program) > 1e-9 * np.abs(program).max(initial=0.0), true_push / program, np.nan)
    seen = ratio[min(int(reference_frame), len(ratio) - 1)]
    return ratio / seen if np.isfinite(seen) and seen != 0 else np.full(len(ratio), np.nan)


def online_against_holding(result, truth_mm=None) -> str:
    """One sentence: at which horizons the online filter's centroid error (against the truth
    where known, else the tracking) is below holding still's, and at which it is not."""
    better, worse = [], []
    for k in sorted(result.predicted_mm):
        filt, hold = _nanmean(result.errors_mm(k, truth_mm)), _nanmean(result.hold_errors_mm(k, truth_mm))
        if filt is None or hold is None:
            continue
        ms = f"{1000 * k * result.frame_interval_s:.0f} ms ({filt:.3f} against {hold:.3f} mm)"
        (better if filt < hold else worse).append(ms)
    against = "the truth" if truth_mm is not None else "the tracked sections"
    if not better and not worse:
        return "No horizon has errors to compare with holding still."
    if not worse:
        return f"Against {against}, the filter is closer than holding still at every horizon: {'; '.join(better)}."
    if not better:
        return f"Against {against}, holding still is as close as the filter or closer at every horizon: {'; '.join(worse)}."
    return (f"Against {against}, the filter is closer than holding still at {'; '.join(better)}; holding still is "
            f"as close or closer at {'; '.join(worse)}.")


def _online_loop_parts(result, inputs: ReportInputs, folder: Path) -> list[str]:
    """The online loop (:class:`~hifumotion.prediction.online.OnlineResult`): its trace, the
    push's scale, the latency histogram and each horizon's error beside holding still."""
    truth = inputs.true_centroid_mm
    s = result.summary()
    surrogate = bool(result.surrogate_mm)
    rows = []
    for k in sorted(result.predicted_mm):
        row = [f"{k} frames ({1000 * k * result.frame_interval_s:.0f} ms)"]
        methods = [result.errors_mm, result.hold_errors_mm] + ([result.surrogate_errors_mm] if surrogate else [])
        if truth is not None:
            row += [_nanmean(m(k, truth)) for m in methods]
        row += [_nanmean(m(k)) for m in methods]
        rows.append(row)
    names = ["filter", "holding"] + (["surrogate"] if surrogate else [])
    head = ["horizon"] + ([f"{n} vs truth (mm)" for n in names] if truth is not None else []) + [
        f"{n} vs tracked (mm)" for n in names]
    lat = s["latency_with_tracking_ms"]
    return [
        paragraph("Frame by frame, as a scanner would deliver them: the tracked displacement of the contour points "
                  "corrects the reduced model's state and the push's size (an extended Kalman filter), then the "
                  "section t + k is predicted — the aim before frame t + 1 arrives. Errors are the centroid's "
                  "motion since frame 0 (against the truth's where it is known, and against the tracking's), "
                  "from frame 1 on; where the two disagree, the tracking is the one that misses what the bar hides. "
                  "The surrogate knows the same inputs without a tissue model: the tracked centroid regressed on "
                  "the push's known program, updated at every frame (recursive least squares)."),
        table(head, rows, "Online loop: centroid error of the prediction against the horizon"),
        paragraph(online_against_holding(result, truth)),
        paragraph(f"Latency a frame, tracking included: {fmt(lat['median'], 3)} ms at the median, "
                  f"{fmt(lat['p99'], 3)} ms at the 99th percentile (tracking {fmt(s['tracking_ms_per_frame'], 3)} ms "
                  f"a frame). The push ends at {fmt(s['push_scale_last'], 3)} × the calibrated one "
                  f"(± {fmt(s['push_scale_std_last'], 2)}); the reduced model took "
                  f"{fmt(s['reduced_model_construction_s'], 3)} s to make."),
        figure(figures.online_figure(result, folder / "online_loop.png", truth, inputs.true_push_scale).name,
               "Online loop: predicted, tracked and true centroid over time; the push's scale; latency a frame"),
    ]


def _aim_parts(outcome, inputs: ReportInputs, folder: Path) -> list[str]:
    pred = outcome.prediction
    dt = outcome.calibration.spec.frame_interval_s
    t = np.arange(len(pred.aim_mm)) * dt
    shift = pred.aim_mm - pred.aim_plan_mm
    true_shift = true_t = None
    if inputs.true_centroid_mm is not None:
        c = np.asarray(inputs.true_centroid_mm, float)[: len(pred.aim_mm)]
        true_shift, true_t = c - c[0], np.arange(len(c)) * dt
    band = pred.band
    png = figures.aim_trajectory(t, shift, folder / "aim.png", true_shift, true_t, outcome.validation[0] * dt,
                                 None if band is None else band.aim_mm - pred.aim_plan_mm)
    rows = []
    for f in outcome.validation:
        if f >= len(shift):
            continue
        row = [f, f * dt, shift[f, 0], shift[f, 1], float(np.hypot(*shift[f]))]
        if band is not None:
            row.append(float(band.width_mm[f]) if f < len(band.width_mm) else "")
        rows.append(row)
    parts = [paragraph("The planned focus is the target's centroid on frame 0; the model carries that material "
                       "point. Its predicted shift tells the operator where to move the focus (image axes: x along "
                       "the transducer, y in depth; mm). Every frame: prediction/aim.csv.")]
    if band is not None:
        moved = ", ".join(f"{name} {step:+.3g}" for name, step in zip(band.coordinates, band.direction))
        parts.append(paragraph(
            "The band: the aim predicted again with the fit moved one standard error either way along the "
            f"direction the training frames fix least ({moved} in the fit's coordinates), from the calibration's "
            f"Gauss–Newton covariance. Up to {band.width_mm.max():.3f} mm from the fit's aim: how far that "
            "undetermined direction moves the prediction (aim.csv band_mm)."))
    parts += [figure(png.name, "Where to aim: the predicted shift of the planned focus"),
              table(["frame", "time (s)", "shift x (mm)", "shift y (mm)", "|shift| (mm)"]
                    + (["band (mm)"] if band is not None else []), rows, "Validation frames")]
    return parts


def _paraview_parts(links: dict, folder: Path) -> list[str]:
    """Links to the files worth opening and how to open them — only the files this run wrote."""
    root = folder.parent                     # the report lives in OUTPUT/report
    there = {label: Path(p) for label, p in links.items() if Path(p).exists()}
    items = "".join(f'<li><a href="{_rel(p, folder)}">{label}</a></li>' for label, p in there.items())

    def code(path: Path) -> str:
        return f"<code>{Path(os.path.relpath(path.resolve(), root.resolve())).as_posix()}</code>"

    def first(*names: str) -> Path | None:
        return next((root / n for n in names if (root / n).exists()), None)

    parts = [f"<ul>{items}</ul>"]
    model, twin = first("prediction/tissue.pvd"), first("experiment/truth/particles/frames.pvd")
    surface, volume = first("calibration/observation/tissue.vtp"), first("calibration/observation/tissue_volume.nii.gz")
    frames = first("observed/frames.nii.gz", "experiment/observed/frames.nii.gz")
    paraview = []
    if model is not None:
        paraview.append(f"File → Open → {code(model)} (the fitted model's tissue particles, every predicted frame, "
                        "with <code>displacement_mm</code>), Apply; choose <i>Point Gaussian</i> or <i>Points</i> as "
                        "the representation and colour by <code>displacement_magnitude_mm</code>; press Play.")
    if twin is not None:
        paraview.append(f"The twin's own particles are in {code(twin)}.")
    if surface is not None:
        paraview.append(f"The reconstructed surface is {code(surface)}.")
    if paraview:
        parts.append("<p><b>ParaView</b>: " + " ".join(paraview) + "</p>")
    slicer = []
    if volume is not None:
        slicer.append(f"drag {code(volume)} (the reconstructed tissue as a label volume) into Slicer.")
    if frames is not None:
        slicer.append(f"The time series is {code(frames)} (a 2D+t volume; open it with the Sequences module).")
    if slicer:
        parts.append("<p><b>3D Slicer</b>: " + " ".join(slicer) + "</p>")
    return parts


def write_report(folder: str | Path, outcome, truth_masks: dict | None, inputs: ReportInputs) -> Path:
    """Write ``folder/report.html`` and its PNGs; return the page's path."""
    from hifumotion.io.files import write_text

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    observed_masks = outcome.calibration.observation.frame_masks
    truth = truth_masks if truth_masks is not None else {f: observed_masks[f] for f in range(len(observed_masks))}
    v = outcome.evaluation.physics["validation"]
    nm = outcome.evaluation.baselines["no_motion"]
    margin = outcome.evaluation.physics.get("margin_over_no_motion") or {}
    verdict = margin.get("verdict")
    # the metric that decided: a margin beyond its spread (prediction.evaluate.margin_over)
    beyond = [name for name, mean, spread in (("DSC", margin.get("dsc_margin_mean"), margin.get("dsc_margin_std")),
                                              ("centroid", margin.get("centroid_margin_mean_mm"),
                                               margin.get("centroid_margin_std_mm")))
              if mean is not None and spread is not None and abs(mean) > spread]
    by = f" by the {' and the '.join(beyond)}" if beyond else ""
    if verdict == "better":
        claim = ("good", f"the physics beats holding the last training contour{by}")
    elif verdict == "worse":
        claim = ("bad", f"the physics is worse than holding the last training contour{by}")
    else:
        claim = ("bad", "the physics is no better than holding the last training contour")
    spread = (f' (per frame: DSC {fmt(margin.get("dsc_margin_mean"), 4)} ± {fmt(margin.get("dsc_margin_std"), 4)}, '
              f'centroid {fmt(margin.get("centroid_margin_mean_mm"), 3)} ± {fmt(margin.get("centroid_margin_std_mm"), 3)} mm '
              f'better than holding; a margin within its spread is no win)') if margin.get("frames") else ""
    intro = [paragraph(inputs.experiment_note)] if inputs.experiment_note else []
    intro.append(
        f'<p>Validation frames {outcome.validation[0]}–{outcome.validation[-1]}: physics DSC mean '
        f'<b>{fmt(v.get("dsc_mean"))}</b> (min {fmt(v.get("dsc_min"))}), centroid error '
        f'{fmt(v.get("centroid_mean_mm"), 3)} mm; no motion {fmt(nm.get("dsc_mean"))} — '
        f'<span class="{claim[0]}">{claim[1]}</span>{spread}. Prediction took {fmt(outcome.predict_s, 3)} s, '
        f'{fmt(outcome.realtime_ratio, 3)}× the validation window\'s duration.</p>')
    sections = []
    if inputs.segmentation:
        sections.append(("segmentation", "Segmentation (Table 2, Figures 2–3)",
                         _segmentation_parts(inputs.segmentation, folder)))
    rec = outcome.calibration.observation.reconstruction
    mesh_png = figures.mesh_picture(rec.mesh.vertices, rec.mesh.faces, folder / "tissue.png",
                                    "reconstructed tissue (image mm)")
    facts = [["volume (mm³)", rec.volume_mm3], ["sweep planes", len(outcome.calibration.observation.observed.sweep)],
             ["model tissue particles", len(outcome.calibration.spec.tissue_mm)],
             ["model particle spacing (mm)", outcome.calibration.spec.spacing_mm]]
    mapping = outcome.calibration.record.as_dict()
    if "model_kept" in mapping:
        # which of the two resolutions predicts: the one that fits the training frames better
        facts.append(["model kept (training cost, mm)",
                      f'{mapping["model_kept"]} (search {mapping["cost_search_model_mm"]:.1f}, '
                      f'final {mapping["cost_final_model_mm"]:.1f})'])
    facts += [[k, val] for k, val in inputs.experiment_facts.items()]
    sections.append(("reconstruction", "Reconstructed tissue",
                     [figure(mesh_png.name, "The tissue reconstructed from the GLCV-segmented sweep"),
                      table(["", "value"], facts)]))
    motion = outcome.calibration.observation.motion
    if motion is not None:
        from hifumotion.speckle.output import motion_figure

        obs = outcome.calibration.observation.observed
        png = motion_figure(obs.frames.astype(np.float32) / 255.0, motion, folder / "motion.png")
        shift = np.linalg.norm(np.array([c.centroid_mm for c in motion.contours]) - motion.contours[0].centroid_mm, axis=1)
        first = motion.first
        rows = [["largest centroid shift of the tracked target (mm)", float(shift.max())],
                ["speckle size, axial × lateral (px)", " × ".join(fmt(v, 3) for v in first.speckle_fwhm_px)],
                ["bar blur, axial × lateral (px)", " × ".join(str(v) for v in first.bloom_px)],
                ["speckle tracking (ms per frame)", 1000 * float(np.mean(motion.seconds_per_frame[1:]))]]
        if motion.displacement.rigid_shift_mm is not None:
            rows.append(["the bar's tracked push at the last frame (mm)",
                         float(np.linalg.norm(motion.displacement.rigid_shift_mm[-1]))])
        sections.append(("motion", "Observed motion (speckle tracking)",
                         [paragraph("Frame 0 is segmented with the known solids taken out of the image; its "
                                    "contour is then carried through the frames by the tissue's displacement, "
                                    "measured from the speckle. Arrows: where each part of the tissue went by "
                                    "the last frame; right: the axial strain that displacement implies."),
                          figure(png.name, "Speckle-tracked displacement and strain"),
                          table(["", "value"], rows)]))
    sections.append(("parameters", "Fitted parameters (Table 3)", _parameter_parts(outcome)))
    sections.append(("prediction", "Prediction (Table 4, Figure 4)", _prediction_parts(outcome, truth, folder)))
    sections.append(("baselines", "Against the baselines", _baseline_parts(outcome, folder)))
    sections.append(("aim", "Where to aim", _aim_parts(outcome, inputs, folder)))
    if getattr(outcome, "online_loop", None) is not None:
        sections.append(("online-loop", "Online loop: every frame assimilated",
                         _online_loop_parts(outcome.online_loop, inputs, folder)))
    sections.append(("timings", "Timings", [table(["stage", "wall time (s)"],
                                                   [[k, v] for k, v in inputs.timings_s.items()])]))
    sections.append(("files", "Open the results (ParaView, 3D Slicer)", _paraview_parts(inputs.links, folder)))
    return write_text(folder / "report.html", page(inputs.title, intro, sections))


__all__ = ["write_report", "ReportInputs", "SegmentationSection", "output_links"]
