"""``hifumotion score``: Table 4 — predicted masks against the truth, per frame and by set."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app, pixel_size
from hifumotion.console import console
from hifumotion.errors import InputError


@app.command()
def score(
    prediction_dir: Path = typer.Argument(..., help="Folder with frames/frame_NNNN.png predicted masks (0/255)."),
    truth_dir: Path = typer.Argument(..., help="Folder with frames/frame_NNNN.png true masks (an experiment's truth/)."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="New folder for table4.csv and scores.json (the names a run gives them) (default PREDICTION_DIR/score)."),
    spacing: Optional[float] = typer.Option(None, "--spacing", callback=pixel_size, help="Pixel size in mm (default: the truth's parameters.json)."),
    images: Optional[Path] = typer.Option(None, "--images", help="The observed frames (frame_NNNN.png) for the overlays (default: TRUTH_DIR/../observed/frames if present)."),
    calibration: Optional[Path] = typer.Option(None, "--calibration", help="The calibration folder the prediction came from: its tracked frames, training frames and the push's program (the observed setup.json) put the predictors that know the same inputs beside it (holding still, Kalman, the drive surrogates)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Score predicted contours: DSC, HD95 and centroid error per frame; training and validation summaries."""
    from hifumotion.io import output_folder, write_json
    from hifumotion.io.files import write_text
    from hifumotion.run_info import RunRecord
    from hifumotion.scoring import overlay_figure, pixel_size_mm, read_frame_masks, score_masks

    for folder in (prediction_dir, truth_dir):
        if not folder.is_dir():
            raise InputError("no such folder (expected frames/frame_NNNN.png masks)", folder)
    # the masks first, in the order given: a folder without them is named before any setting is sought
    predicted, truth = read_frame_masks(prediction_dir), read_frame_masks(truth_dir)
    pixel = spacing if spacing is not None else pixel_size_mm(truth_dir)
    record = RunRecord("score", config={"prediction_dir": str(prediction_dir), "truth_dir": str(truth_dir),
                                        "pixel_mm": pixel})
    with record.stage("score"):
        table = score_masks(predicted, truth, pixel)
        peers = None
        if calibration is not None:
            validation = [r["frame"] for r in table.rows if r["set"] == "validation"]
            peers = _peer_scores(calibration, predicted, truth, validation, pixel)
    frames_dir = images if images is not None else truth_dir.parent / "observed" / "frames"
    if images is not None and not images.is_dir():
        raise InputError("no such folder of observed frames", images)
    if images is not None and not any((images / f"frame_{r['frame']:04d}.png").is_file() for r in table.rows):
        raise InputError("none of the scored frames is here as frame_NNNN.png to draw the overlays on", images)
    out_dir = output if output is not None else prediction_dir / "score"
    with output_folder(out_dir, overwrite, inputs=(prediction_dir, truth_dir, images, calibration)) as out:
        write_text(out / "table4.csv", table.to_csv())
        write_json(out / "scores.json", {"pixel_mm": pixel, "summary": table.summary(), "frames": table.rows,
                                        **({"peers": peers} if peers is not None else {})})
        if frames_dir.is_dir():
            from hifumotion.io.raster import read_raster_array

            wanted = [r["frame"] for r in table.rows if r["set"] in ("training", "validation")] or \
                [r["frame"] for r in table.rows]
            pictures = {f: read_raster_array(p)[0] for f in wanted
                        if (p := frames_dir / f"frame_{f:04d}.png").is_file()}
            if pictures:
                overlay_figure(pictures, truth, predicted, wanted, out / "overlays.png")

        record.write(out)
    for name, s in table.summary().items():
        console.print(f"{name:10s} {len(s['frames']):3d} frames  DSC mean {s['dsc']['mean']:.4f} min "
                      f"{s['dsc']['min']:.4f}  HD95 mean {s['hd95_mm']['mean']:.2f} mm  centroid error mean "
                      f"{s['centroid_error_mm']['mean']:.2f} mm max {s['centroid_error_mm']['max']:.2f} mm",
                      highlight=False)
    if peers is not None:
        for name, p in peers["peers"].items():
            if p.get("frames"):
                console.print(f"  {name.replace('_', ' '):14s} validation DSC mean {p['dsc_mean']:.4f}  centroid error "
                              f"mean {p['centroid_mean_mm']:.2f} mm", highlight=False)
        console.print(f"of every predictor: {peers['verdict']}", highlight=False)
    console.print(f"scores in {out_dir.resolve()}", highlight=False)


def _peer_scores(calibration: Path, predicted: dict, truth: dict, validation: list[int], pixel_mm: float) -> dict:
    """The peers beside the prediction, from what ``calibration`` recorded (its tracked frames,
    training frames and frame interval, and the observed ``setup.json``'s program)."""
    from hifumotion.io.structured import read_structured
    from hifumotion.observed.setup import read_setup
    from hifumotion.prediction.evaluate import peer_scores
    from hifumotion.scoring import read_frame_masks

    params_path = calibration / "parameters.json"
    if not params_path.is_file():
        raise InputError("no parameters.json: expected a calibration folder (hifumotion calibrate's output)", calibration)
    params = read_structured(params_path, "json", "parameters.json")
    if not isinstance(params, dict) or not params.get("training_frames") or not params.get("frame_interval_s"):
        raise InputError("expected training_frames and frame_interval_s (a calibration's parameters.json)", params_path)
    if len(validation) < 2:
        raise InputError("fewer than two validation frames among the predicted masks", "PREDICTION_DIR")
    tracked = read_frame_masks(calibration / "observation")
    program = None
    if params.get("observed"):
        setup_path = (calibration / params["observed"]).resolve() / "setup.json"
        if setup_path.is_file():
            setup = read_setup(setup_path)
            program = setup.program_at_frames(max(setup.frames, max(validation) + 1))
    if program is None:
        console.print("the observed setup.json was not found: the drive surrogates are left out", highlight=False)
    return peer_scores(predicted, tracked, truth, params["training_frames"], validation, program,
                       float(params["frame_interval_s"]), pixel_mm)
