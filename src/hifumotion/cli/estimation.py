"""``hifumotion calibrate`` and ``hifumotion predict``: fit the particle model, then predict the frames."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app, positive
from hifumotion.console import console, log
from hifumotion.errors import InputError


@app.command()
def calibrate(
    observed_dir: Path = typer.Argument(..., help="An observed experiment folder (setup.json, sweep/, frames/, initial_contour.csv)."),
    output: Path = typer.Option(..., "--output", "-o", help="New calibration folder."),
    method: Optional[str] = typer.Option(None, "--method", help="least_squares, cmaes, or table1 (the paper's iterative algorithm). Default: the setting's (least_squares)."),
    training: Optional[str] = typer.Option(None, "--training", help="Training frames: '20,30,40' or '20:101:10' (default: the paper's protocol)."),
    contours: Optional[Path] = typer.Option(None, "--contours", help="CSV of training contours (frame, x_px, y_px or x_mm, y_mm) instead of tracking."),
    objective: Optional[str] = typer.Option(None, "--objective", help="auto (contour+displacement where speckle tracking observed the motion, else contour), contour (the paper's S_t) or contour+displacement (also the speckle-tracked displacement of the contour points). Default: the setting's (auto)."),
    tracking: Optional[str] = typer.Option(None, "--tracking", help="speckle (frame 0's contour carried by speckle tracking) or glcv (re-segment every frame, as the paper). Default: the setting's (speckle)."),
    force: Optional[float] = typer.Option(None, "--force", callback=positive, min=1e-6, max=1e3, help="Nominal pushing force in N (only F/E is determined; E is reported at this force). Default: the setting's (the paper's 0.25 N)."),
    particles: Optional[int] = typer.Option(None, "--particles", min=100, max=1_000_000, help="Tissue particles of the fitted model (default 4,399, the paper's; short for --set model.tissue_particles=N)."),
    search_particles: Optional[int] = typer.Option(None, "--search-particles", min=100, max=1_000_000, help="Tissue particles of the coarser model the search runs on. Default: the setting's (1,000)."),
    max_evaluations: Optional[int] = typer.Option(None, "--max-evaluations", min=1, max=10_000, help="Least squares: residual evaluations (each with a p-run Jacobian). Default: the setting's (8)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, max=256, help="Dask worker processes of the local cluster (default: the cores)."),
    scheduler_address: Optional[str] = typer.Option(None, "--scheduler-address", help="Use an existing Dask cluster (tcp://host:8786)."),
    boundary_offset: Optional[float] = typer.Option(None, "--boundary-offset", min=-5.0, max=5.0, help="How far outside the true boundary your system's segmentations lie (mm, from a phantom of known size); masks move inwards by it. Default: the setting's (0)."),
    resume: Optional[Path] = typer.Option(None, "--resume", help="A search_log.jsonl of an interrupted calibration: its runs are not repeated."),
    settings_set: Optional[list[str]] = typer.Option(None, "--set", help="Change one setting: KEY=VALUE, KEY a dotted path (model.creep.tolerance=0.01, search_integrator=reduced; the fields of hifumotion run's [estimation]); repeatable."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Estimate force/Young's modulus, Poisson's ratio, β1, β2 from the training frames (Table 1 and better)."""
    from hifumotion.config import apply_settings, validate_config
    from hifumotion.console import StageBars
    from hifumotion.estimation.calibrate import OBJECTIVES
    from hifumotion.estimation.evaluator import check_search_log
    from hifumotion.estimation.settings import scheduler_address_problem
    from hifumotion.estimation.protocol import default_frames, parse_frames
    from hifumotion.io import output_folder
    from hifumotion.observed import load_observed
    from hifumotion.run_info import RunRecord
    from hifumotion.workflow.pipeline import EstimationConfig, observe_and_calibrate

    if method is not None and method not in ("least_squares", "cmaes", "table1"):
        raise InputError(f"expected least_squares, cmaes or table1, got {method!r}", "--method")
    if objective is not None and objective not in OBJECTIVES:
        raise InputError(f"expected {', '.join(OBJECTIVES)}, got {objective!r}", "--objective")
    if tracking is not None and tracking not in ("speckle", "glcv"):
        raise InputError(f"expected speckle or glcv, got {tracking!r}", "--tracking")
    if scheduler_address is not None and (problem := scheduler_address_problem(scheduler_address)):
        raise InputError(problem, "--scheduler-address")
    if resume is not None:
        check_search_log(resume)
    # only what was given: every other setting keeps its one default, in the settings' class
    given = {"method": method, "force_n": force, "search_particles": search_particles,
             "max_evaluations": max_evaluations, "boundary_offset_mm": boundary_offset, "tracking": tracking,
             "objective": objective, "workers": workers, "scheduler_address": scheduler_address,
             "particles": particles}
    options = {key: value for key, value in given.items() if value is not None}
    settings = validate_config(EstimationConfig, apply_settings(options, settings_set), "options")
    observed = load_observed(observed_dir)
    frames = parse_frames(training, len(observed.frames), "--training") or default_frames(len(observed.frames))[0]
    record = RunRecord("calibrate", config={"observed": str(observed_dir), "training": frames,
                                            "contours": None if contours is None else str(contours),
                                            **settings.model_dump(mode="json")})
    with output_folder(output, overwrite, inputs=(observed_dir, contours, resume)) as out:
        with StageBars() as progress:
            _, cal = observe_and_calibrate(observed, out, settings, frames, contours, record=record,
                                           progress=progress, observed_dir=observed_dir, resume_log=resume)
        summary = cal.summary
        record.extra["fit"] = {k: summary["fit"][k] for k in ("method", "cost_mm", "runs", "failed_runs")}
        record.write(out)
    p = summary["parameters"]
    console.print(f"calibrated on frames {summary['training_frames']} with {summary['fit']['method']} "
                  f"({summary['fit']['runs']} runs): F/E = {p['force_over_youngs_m2']['value']:.3g} m² "
                  f"(E = {p['youngs_modulus_pa']['value']:.0f} Pa at {settings.force_n:g} N), ν = {p['poisson_ratio']['value']:.3f}, "
                  f"β1 = {p['beta1_pa_s_pow']['value']:.3g}, β2 = {p['beta2']['value']:.2f}"
                  + (f", μ_f = {p['friction']['value']:.3f}" if "friction" in p else ""), highlight=False)
    rc = summary["fit"].get("resolution_check")
    if rc:
        console.print(f"on {rc['particles'][1]} particles the fit's points A move {rc['largest_mm']:.2f} mm from where "
                      f"{rc['particles'][0]} put them: {'resolved' if rc['resolved'] else 'NOT resolved'} "
                      f"(a pixel is {rc['pixel_mm']:.2f} mm)", highlight=False)
    for caveat in summary["fit"].get("caveats", []):
        console.print(f"not to be trusted as determined: {caveat}", highlight=False)
    undetermined = [n for n, v in p.items() if not v["determined"]]
    if undetermined:
        console.print(f"not determined by these frames: {', '.join(undetermined)}", highlight=False)
    console.print(f"calibration in {output.resolve()} (parameters.json)", highlight=False)


@app.command()
def predict(
    calibration_dir: Path = typer.Argument(..., help="A folder written by hifumotion calibrate."),
    output: Path = typer.Option(..., "--output", "-o", help="New prediction folder."),
    frames: Optional[str] = typer.Option(None, "--frames", help="Frames to predict: '110,120' or '110:191:10' (default: training and validation frames of the paper's protocol)."),
    online: Optional[str] = typer.Option(None, "--online", help="Online mode: horizons in frames, e.g. '4,6,8' — at each frame t predict t + k from the tracked frames up to t (online.csv)."),
    band: bool = typer.Option(True, "--band/--no-band", help="Also predict the aim one standard error either way along the direction the training frames fix least (two more runs): aim.csv's band_mm."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Predict the imaging plane's contours with the fitted model: frames/frame_NNNN.png, contours.csv, aim.csv, tissue.pvd."""
    import time

    from hifumotion.console import StageBars
    from hifumotion.estimation.protocol import default_frames, parse_frames
    from hifumotion.estimation.store import load_calibration
    import numpy as np

    from hifumotion.io import output_folder
    from hifumotion.io.files import write_text
    from hifumotion.prediction.pipeline import predict_calibrated, write_prediction_folder
    from hifumotion.run_info import RunRecord

    spec, k, reference, meta = load_calibration(calibration_dir)
    n = int(meta["frames"])
    train, valid = default_frames(n)
    wanted = parse_frames(frames, n, "--frames") or sorted(set(meta["training_frames"]) | set(valid))
    horizons = parse_frames(online, n, "--online") if online else []
    now = list(range(min(wanted), max(wanted) - min(horizons) + 1)) if horizons else []
    online_frames = sorted({t + h for t in now for h in [0, *horizons] if t + h <= max(wanted)})
    record = RunRecord("predict", config={"calibration": str(calibration_dir), "frames": wanted,
                                          "parameters": k.as_dict()})
    with output_folder(output, overwrite, inputs=(calibration_dir,)) as out:
        with StageBars() as progress, record.stage("predict"):
            progress("predict", 0.0)
            t0 = time.perf_counter()
            pred = predict_calibrated(spec, k, reference, wanted, online_frames)
            seconds = time.perf_counter() - t0
            progress("predict", 1.0)
        if band:
            with record.stage("band"):
                from hifumotion.prediction.band import aim_band, covariance_from_calibration

                try:
                    pred.band = aim_band(spec, k, reference, wanted, covariance_from_calibration(meta), pred.aim_mm)
                except InputError as exc:      # the prediction stands; say why it has no band
                    log.warning(f"no band: {exc} (parameters.json)")
        if horizons:
            with record.stage("online"):
                from hifumotion.prediction.pipeline import online_csv, online_predictions
                from hifumotion.scoring import read_frame_masks

                tracked = read_frame_masks(calibration_dir / "observation")
                observed = np.stack([tracked[f] for f in range(n)])
                write_text(out / "online.csv", online_csv(
                    online_predictions(pred, spec, reference, observed, horizons, now), observed, pred.pixel_mm,
                    spec.frame_interval_s))
        with record.stage("write"):
            write_prediction_folder(out, pred, wanted, spec.frame_interval_s, valid, seconds)
        record.write(out)
    console.print(f"predicted {len(wanted)} frames in {seconds:.0f} s; masks, contours.csv and aim.csv in "
                  f"{output.resolve()}", highlight=False)
    if pred.band is not None:
        console.print(f"the aim one standard error either way along the least determined direction: up to "
                      f"{pred.band.width_mm.max():.2f} mm from the fit's (aim.csv band_mm)", highlight=False)


@app.command()
def online(
    calibration_dir: Path = typer.Argument(..., help="A folder written by hifumotion calibrate."),
    observed_dir: Path = typer.Argument(..., help="The experiment: setup.json, initial_contour.csv and frames/frame_NNNN.png (recorded, or being written with --watch)."),
    output: Path = typer.Option(..., "--output", "-o", help="New folder for online.csv, online.json, online.png."),
    horizons: str = typer.Option("4,6,8", "--horizons", help="How far ahead to aim, in frames: '4,6,8' (at 20 frames/s: 200–400 ms)."),
    boundary_offset: float = typer.Option(0.0, "--boundary-offset", min=-5.0, max=5.0, help="As given to hifumotion calibrate (mm)."),
    watch: bool = typer.Option(False, "--watch", help="Take the frames as a scanner writes them into OBSERVED_DIR/frames/, each as soon as it is whole; stop when none has come for --timeout seconds."),
    timeout: float = typer.Option(10.0, "--timeout", min=0.01, max=86400.0, help="--watch: seconds to wait for the next frame before stopping."),
    pace: bool = typer.Option(False, "--pace", help="Replay a recorded cine at its frame rate (each frame handed over when it would have arrived), not as fast as it can be read."),
    stream: bool = typer.Option(False, "--stream", help="Print each frame's aims as one JSON line on standard output the moment they exist."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Run the online loop: each frame tracked, the reduced model and the push's size corrected by it, the aim for t + k written before the next frame."""
    import sys
    import time

    from hifumotion.console import StageBars
    from hifumotion.estimation.store import frame0_fingerprint, load_calibration
    from hifumotion.io import output_folder, write_json
    from hifumotion.io.files import write_text
    from hifumotion.io.writers import json_text
    from hifumotion.observed import load_observed, read_initial_contour, read_setup
    from hifumotion.observed.solids import imaging_plane
    from hifumotion.prediction.online import OnlineSession, watch_frames
    from hifumotion.report.figures import online_figure
    from hifumotion.run_info import RunRecord

    if watch and pace:
        raise InputError("--pace replays a recorded cine; --watch takes frames as they are written: give one", "--pace")
    spec, k, reference, meta = load_calibration(calibration_dir)
    from hifumotion.io.files import require_regular_file

    if not (observed_dir / "setup.json").exists() and not (observed_dir / "setup.json").is_symlink():
        raise InputError("not an observed experiment folder (no setup.json)", observed_dir)
    setup = read_setup(require_regular_file(observed_dir / "setup.json", "setup.json"))
    try:
        ahead = sorted({int(h) for h in horizons.split(",") if h.strip()})
    except ValueError:
        raise InputError(f"expected whole frames separated by commas, got {horizons!r}", "--horizons") from None
    if not ahead or ahead[0] < 1 or ahead[-1] >= setup.frames:
        raise InputError(f"expected horizons from 1 to {setup.frames - 1} frames, got {horizons!r}", "--horizons")
    if tuple(setup.imaging.image_shape) != tuple(reference.plane.shape):
        raise InputError(f"its frames are {tuple(setup.imaging.image_shape)} pixels, the calibration's "
                         f"{tuple(reference.plane.shape)}: not the experiment that was calibrated", observed_dir / "setup.json")
    if abs(setup.frame_interval_s - spec.frame_interval_s) > 1e-9 * spec.frame_interval_s:
        raise InputError(f"the cine's frame interval ({setup.frame_interval_s} s) is not the calibration's "
                         f"({spec.frame_interval_s} s)", observed_dir / "setup.json")
    initial = read_initial_contour(observed_dir, setup)
    if setup.initial_contour_frame != 0:
        raise InputError("the initial contour must be on frame 0 for the online loop", observed_dir / "initial_contour.csv")
    if watch:
        arriving = watch_frames(observed_dir / "frames", first=0, timeout_s=timeout)
        first = next(arriving, None)
        if first is None:
            raise InputError(f"no frame_0000.png came within {timeout:g} s", observed_dir / "frames")
        frame0 = first[1]
        frames = (image for _, image in arriving)
    else:
        recorded = load_observed(observed_dir).frames
        frame0, frames = recorded[0], iter(recorded[1:])
    if tuple(frame0.shape) != tuple(setup.imaging.image_shape):
        raise InputError(f"frame 0 has shape {frame0.shape}; setup.json's imaging.image_shape is "
                         f"{tuple(setup.imaging.image_shape)}", observed_dir / "frames")
    if meta.get("observed_frame0_sha256") not in (None, frame0_fingerprint(frame0[None])):
        raise InputError("its frame 0 is not the calibrated experiment's (parameters.json's "
                         "observed_frame0_sha256)", observed_dir)
    record = RunRecord("online", config={"calibration": str(calibration_dir), "observed": str(observed_dir),
                                         "horizons_frames": ahead, "boundary_offset_mm": boundary_offset,
                                         "watch": watch, "pace": pace, "parameters": k.as_dict()})
    with output_folder(output, overwrite, inputs=(calibration_dir, observed_dir)) as out:
        with StageBars() as progress:
            with record.stage("reduced model, frame 0"):
                # frame 0 segmented as the calibration's tracking segmented it
                seen = meta.get("observation") or {}
                continued = bool(seen.get("bloom_continuation", False))
                shape = None
                if continued and seen.get("bloom_continued_by") == "reconstruction":
                    plane = imaging_plane(setup)
                    shape = reference.reconstruction_distance(plane.points_mm())
                session = OnlineSession.start(spec, k, setup, frame0, initial, ahead,
                                              boundary_offset_mm=boundary_offset, continue_bloom=continued,
                                              bloom_shape_mm=shape, progress=progress)
            with record.stage("online"):
                due = time.perf_counter()
                for frame in frames:
                    if pace:            # hand the frame over when the scanner would have
                        due += setup.frame_interval_s
                        time.sleep(max(0.0, due - time.perf_counter()))
                    step = session.push(frame)
                    if stream:
                        sys.stdout.write(json_text(step.as_dict(), indent=None) + "\n")
                        sys.stdout.flush()
                    progress("online", min(step.frame / max(setup.frames - 1, 1), 1.0))
        if not session.steps:
            raise InputError("no frame after frame 0 to follow", observed_dir / "frames")
        result = session.result()
        summary = result.summary()
        write_text(out / "online.csv", result.to_csv())
        write_json(out / "online.json", summary)
        online_figure(result, out / "online.png")
        record.extra["online"] = summary
        record.write(out)
    lat = summary["latency_with_tracking_ms"]
    console.print(f"{summary['frames']} frames: {lat['median']:.1f} ms a frame at the median, {lat['p99']:.1f} ms at "
                  f"the 99th percentile (tracking included), {summary['frames_late']} after the next frame was due; "
                  f"push at {summary['push_scale_last']:.2f} × the calibrated one at the end; online.csv and "
                  f"online.png in {output.resolve()}", highlight=False)
    for k, h in summary["horizons"].items():
        sur = h.get("surrogate_error_vs_tracked_mean_mm")
        sur_text = "" if sur is None else f", the drive surrogate {sur:.3f} mm"
        console.print(f"{h['ms']:.0f} ms ahead, against the tracked section: physics {h['error_vs_tracked_mean_mm']:.3f} "
                      f"mm, holding still {h['hold_error_vs_tracked_mean_mm']:.3f} mm{sur_text}", highlight=False)
