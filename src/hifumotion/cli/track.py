"""``hifumotion track``: the target through a cine loop by speckle tracking."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer

from hifumotion.cli.app import app, parse_spacing, positive, require_frame_size
from hifumotion.console import console, log
from hifumotion.errors import InputError


def _solids_from_files(setup: Optional[Path], exclude: Optional[Path], bar: Optional[Path], frame0: np.ndarray):
    """The known solids: from a setup.json (floor and resting bar on the imaging plane) and/or
    mask PNGs (static exclusion, a rigid instrument)."""
    from hifumotion.io import read_mask
    from hifumotion.observed.solids import Solids

    shape = frame0.shape
    floor = np.zeros(shape, bool)
    rigid = np.zeros(shape, bool)
    if setup is not None:
        from hifumotion.observed.setup import read_setup
        from hifumotion.observed.solids import check_bar_in_image, imaging_plane, known_solids

        s = read_setup(setup)
        if tuple(s.imaging.image_shape) != tuple(shape):
            raise InputError(f"describes {tuple(s.imaging.image_shape)} images, the cine has {tuple(shape)}", setup)
        known = known_solids(imaging_plane(s), s)
        check_bar_in_image(frame0, known, setup)
        floor |= known.floor
        rigid |= known.bar
    for path, target in ((exclude, floor), (bar, rigid)):
        if path is not None:
            m = read_mask(path, binary=True)
            if m.shape != tuple(shape):
                raise InputError(f"mask shape {m.shape} differs from the cine's {tuple(shape)}", path)
            target |= m
    if not floor.any() and not rigid.any():
        return None
    if setup is not None and exclude is None and bar is None:
        return known     # the setup's geometry alone: its surfaces to a fraction of a pixel
    return Solids(floor, rigid & ~floor)


@app.command()
def track(
    source: Path = typer.Argument(..., help="Cine loop: DICOM/NIfTI/MHA/NRRD/video/PNG folder, or an observed/ folder (frames, initial_contour.csv, setup.json)."),
    output: Path = typer.Option(..., "--output", "-o", help="New output folder."),
    init: Optional[Path] = typer.Option(None, "--init", help="Frame 0's initial contour: init.json-style JSON, a mask PNG or a contour CSV (default: an observed folder's initial_contour.csv)."),
    setup: Optional[Path] = typer.Option(None, "--setup", help="setup.json: where the pool's floor and the bar are (default: an observed folder's)."),
    exclude: Optional[Path] = typer.Option(None, "--exclude", help="Mask PNG of static pixels that are not tissue (a floor, a membrane)."),
    bar: Optional[Path] = typer.Option(None, "--bar", help="Mask PNG of a rigid instrument on frame 0 (its motion is tracked, never read as the tissue's)."),
    boundary_offset: float = typer.Option(0.0, "--boundary-offset", min=-5.0, max=5.0, help="How far outside the true boundary your system's segmentations lie (mm, from a phantom); frame 0's free boundary moves inwards by it."),
    method: str = typer.Option("glcv", "--method", "-m", help="Level set of frame 0's segmentation: gac, cv, lcv, rsf, mslcv or glcv."),
    estimator: str = typer.Option("farneback", "--estimator", help="Optical flow: farneback (default), dis, ilk or tvl1."),
    spacing: Optional[str] = typer.Option(None, "--spacing", help="Pixel size in mm: '0.2' or 'row,col'. Overrides the file."),
    frame_interval: Optional[float] = typer.Option(None, "--frame-interval", callback=positive, help="Seconds between frames. Overrides the file."),
    points: Optional[Path] = typer.Option(None, "--points", help="CSV of points to follow from frame 0 (columns name, x_px, y_px or x_mm, y_mm): landmarks, a contour's vertices, an open curve. Without --init only the points are followed."),
    fields: bool = typer.Option(False, "--fields", help="Also write the dense displacement and its quality around the target (NIfTI, for 3D Slicer and ParaView)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Follow the target's material through a cine: frame 0 segmented, its contour carried by speckle
    tracking; and/or given points (--points) followed from frame 0."""
    from hifumotion.cli.segment import load_init
    from hifumotion.io import output_folder, read_sequence
    from hifumotion.run_info import RunRecord
    from hifumotion.segmentation import METHODS
    from hifumotion.segmentation.levelset import check_init_region
    from hifumotion.speckle import follow
    from hifumotion.speckle._flow import ESTIMATORS
    from hifumotion.speckle.displacement import displacement
    from hifumotion.speckle.follow import tracker_solids
    from hifumotion.speckle.output import write_tracking

    if method.lower() not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}", "--method")
    if estimator.lower() not in ESTIMATORS:
        raise InputError(f"unknown estimator {estimator!r}; expected one of {', '.join(ESTIMATORS)}", "--estimator")
    cine = source
    if source.is_dir() and ((source / "setup.json").exists() or (source / "setup.json").is_symlink()):
        from hifumotion.io.files import require_regular_file

        require_regular_file(source / "setup.json", "setup.json")   # a folder or a FIFO of that name: said
    if source.is_dir() and (source / "setup.json").is_file():      # an observed/ folder
        # read as calibrate reads it (frames/ by number, frames.nii.gz checked against them,
        # setup.json's pixel size and frame interval), so both follow the same images
        from hifumotion.observed import load_observed
        from hifumotion.sequence import ImageSequence

        observed = load_observed(source)
        cine = source / "frames"
        setup = setup or source / "setup.json"
        init = init or source / "initial_contour.csv"
        seq = ImageSequence.from_array(observed.frames, spacing_mm=parse_spacing(spacing) or observed.pixel_mm,
                                       frame_interval_s=frame_interval or observed.frame_interval_s,
                                       source=str(cine), value_range=(0.0, 255.0))
    elif init is None and points is None:
        raise InputError("give frame 0's initial contour with --init, points with --points, "
                         "or track an observed/ folder", "--init")
    else:
        seq = read_sequence(cine, parse_spacing(spacing), frame_interval)
    if seq.n_frames < 2:
        raise InputError(f"has {seq.n_frames} frame; tracking needs a cine of at least 2", cine)
    require_frame_size(seq.shape, cine)
    if init is None:
        # what a region needs is no use to points: said, not silently dropped
        for name, given in (("--setup", setup), ("--exclude", exclude), ("--bar", bar), ("--fields", fields or None)):
            if given is not None:
                raise InputError("applies to a region followed from frame 0; give its --init as well", name)
        _track_points_only(seq, source, points, output, overwrite)
        return
    if not seq.spacing_known:
        # the track's displacements and contours are in mm: a pixel size guessed would scale them all
        raise InputError("carries no pixel size; give it with --spacing MM (or 'ROW,COL')", cine)
    start = load_init(init, cine, None, None, seq.shape)
    check_init_region(start, seq.shape, str(init))
    solids = _solids_from_files(setup, exclude, bar, seq.frames[0])
    record = RunRecord("track", config={"source": str(source), "init": str(init), "setup": None if setup is None else str(setup),
                                        "exclude": None if exclude is None else str(exclude),
                                        "bar": None if bar is None else str(bar), "method": method,
                                        "estimator": estimator, "boundary_offset_mm": boundary_offset, "fields": fields,
                                        "spacing_mm": list(seq.spacing_mm), "frame_interval_s": seq.frame_interval_s})
    given = _read_points(points, seq) if points is not None else None
    if given is not None:
        record.config["points"] = str(points)
    with output_folder(output, overwrite, inputs=(source, init, setup, exclude, bar, points)) as out:
        with record.stage("speckle tracking"):
            series = displacement(seq.frames, seq.spacing_mm, estimator=estimator, progress=True,
                                  **tracker_solids(solids))
        with record.stage("contours"):
            result = follow(seq.frames, start, seq.spacing_mm, solids=solids, boundary_offset_mm=boundary_offset,
                            method=method, series=series)
        point_summary = None
        if given is not None:
            with record.stage("points"):
                point_summary = _follow_and_write_points(out, seq, given)
        with record.stage("write"):
            summary = write_tracking(out, seq.frames, result, seq.frame_interval_s,
                                     {"source": str(source), "method": method,
                                      **({"points": point_summary} if point_summary else {})}, fields=fields)
        record.extra["frames"] = seq.n_frames
        record.extra["ms_per_frame_mean"] = summary["ms_per_frame_mean"]
        record.write(out)
    if result.first is not None and result.first.given_region_kept:
        from hifumotion.speckle.follow import REGION_MARGIN

        log.warning("frame 0's segmentation left the given region (%.0f %% of it lay more than %.2g of the "
                    "region's radius outside): the given region was followed instead",
                    100 * result.first.outside_fraction, REGION_MARGIN)
    shift = summary["centroid_shift_mm"]
    log.info("speckle tracking: %d frames, %.1f ms per frame", seq.n_frames, summary["ms_per_frame_mean"] or 0.0)
    console.print(f"tracked {seq.n_frames} frames: the target's centroid moved up to {max(shift):.2f} mm; "
                  f"results in {output.resolve()}", highlight=False)


def _read_points(path: Path, seq):
    from hifumotion.io.points import read_points_csv
    from hifumotion.speckle.points import check_points

    xy, names = read_points_csv(path, seq.spacing_mm if seq.spacing_known else None)
    try:
        check_points(xy, seq.shape)
    except InputError as exc:
        raise InputError(exc.reason, path) from None
    return xy, names


def _follow_and_write_points(out: Path, seq, given) -> dict:
    """Follow the points through ``seq`` and write ``points.csv`` and ``points.png``; the summary."""
    from hifumotion.speckle.output import write_point_track
    from hifumotion.speckle.points import track_points

    xy, names = given
    result = track_points(seq.frames, xy, names=names, progress=True)
    return write_point_track(out, seq.frames, result, seq.spacing_mm if seq.spacing_known else None,
                             seq.frame_interval_s)


def _track_points_only(seq, source: Path, points: Path, output: Path, overwrite: bool) -> None:
    """``track --points`` without a region: the points' trajectories, in px (and mm where the
    cine carries a pixel size)."""
    from hifumotion.io import output_folder, write_json
    from hifumotion.run_info import RunRecord

    given = _read_points(points, seq)
    record = RunRecord("track", config={"source": str(source), "points": str(points),
                                        "spacing_mm": list(seq.spacing_mm) if seq.spacing_known else None,
                                        "frame_interval_s": seq.frame_interval_s})
    with output_folder(output, overwrite, inputs=(source, points)) as out:
        with record.stage("points"):
            summary = _follow_and_write_points(out, seq, given)
        write_json(out / "tracking.json", {"source": str(source), "frames": seq.n_frames, "points": summary})
        record.extra["frames"] = seq.n_frames
        record.extra["ms_per_frame_mean"] = summary["ms_per_frame_mean"]
        record.write(out)
    log.info("followed %d points over %d frames, %.2f ms per frame", len(given[1]), seq.n_frames,
             summary["ms_per_frame_mean"] or 0.0)
    unit = "mm" if seq.spacing_known else "px"
    console.print(f"followed {len(given[1])} points over {seq.n_frames} frames: they moved up to "
                  f"{summary['largest_shift_' + unit]:.2f} {unit}; results in {output.resolve()}", highlight=False)
