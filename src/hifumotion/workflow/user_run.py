"""``hifumotion run CONFIG.toml``: the pipeline on a user's own files.

A run configuration names the spatial sweep and the time series (DICOM, NIfTI/MHA/NRRD,
a folder of PNGs, or a video), the clicked initial contour, where the images sit in the
pool, the pool and the bar, and how to estimate (``[estimation]``, see
:class:`~hifumotion.workflow.pipeline.EstimationConfig`). :func:`assemble_observed`
turns it into the ``observed/`` layout the pipeline reads (the same the synthetic
experiment writes, :mod:`hifumotion.experiment.observed`); :func:`run_user` runs the
pipeline and writes the report. Lengths in mm, times in s; relative paths are relative
to the configuration file. ``hifumotion run --example`` prints a complete example.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Callable

import numpy as np
from pydantic import Field, model_validator

from hifumotion.config import ConfigModel
from hifumotion.errors import InputError
from hifumotion.workflow.pipeline import EstimationConfig, outcome_summary, run_pipeline

Progress = Callable[[str, float], None]


class ImagesConfig(ConfigModel):
    path: Path = Field(description="file or folder: DICOM (file or series folder), NIfTI/MHA/NRRD, PNG folder, video")
    spacing_mm: float | None = Field(None, gt=0, description="square pixel size in mm, if the file carries none (PNG, video) or to override it")
    flip_rows: bool = Field(False, description="flip the images upside down first: row 0 must be on the probe's side, rows running away from it")


class SweepConfig(ImagesConfig):
    positions_mm: list[float] | None = Field(None, description="the planes' positions along the pool's z in mm (default: from the file, or gap_mm)")
    gap_mm: float | None = Field(None, gt=0, description="distance between the planes in mm, when the file gives no positions")
    first_z_mm: float | None = Field(None, description="pool z of the first plane in mm (default: the file's or positions_mm as given)")


class FramesConfig(ImagesConfig):
    frame_interval_s: float | None = Field(None, gt=0, description="time between frames in s, if the file carries none")


class ContourConfig(ConfigModel):
    path: Path = Field(description="CSV of the clicked contour: columns frame, x_px, y_px (or x_mm, y_mm)")
    frame: int = Field(0, ge=0, description="the frame it outlines (the push starts after it)")


class GeometryConfig(ConfigModel):
    row0_col0_mm: tuple[float, float] = Field(description="pool (x, y) in mm of the centre of pixel (row 0, column 0); y up, the floor at y = 0")
    frames_plane_z_mm: float = Field(description="pool z in mm of the time series' imaging plane")


class TankSetup(ConfigModel):
    size_mm: tuple[float, float, float] = Field(description="inner size of the pool (x, y up, z) in mm")
    water_depth_mm: float = Field(ge=0, description="water above the floor in mm")


class BarSetup(ConfigModel):
    enabled: bool = Field(True, description="whether a bar pushes the tissue")
    radius_mm: float = Field(6.0, gt=0, description="radius of the cylindrical bar in mm")
    length_mm: float = Field(12.0, gt=0, description="length of the bar in mm")
    direction: tuple[float, float, float] = Field((0.0, -1.0, 0.0), description="unit vector the bar pushes along")
    tip_at_rest_mm: tuple[float, float, float] = Field(description="pool position of the bar's tip before the push, mm")
    force_ramp_s: float = Field(0.0, ge=0, description="time over which the push rises to its full force, s")
    weight_supported: bool = Field(True, description="a hand carries the bar's weight")


class TruthConfig(ConfigModel):
    masks: Path | None = Field(None, description="folder of expert masks frame_NNNN.png (0/255) on the frames' grid, to score against")


class RunConfig(ConfigModel):
    """A ``hifumotion run`` configuration (TOML or YAML)."""

    output: Path | None = Field(None, description="output folder (default: given with -o)")
    sweep: SweepConfig
    frames: FramesConfig
    initial_contour: ContourConfig
    geometry: GeometryConfig
    tank: TankSetup
    bar: BarSetup
    estimation: EstimationConfig = EstimationConfig()
    training_contours: Path | None = Field(None, description="CSV of expert contours of training frames (frame, x_px, y_px), used instead of GLCV tracking")
    truth: TruthConfig = TruthConfig()

    @model_validator(mode="after")
    def _positions(self):
        if self.sweep.positions_mm is not None and len(self.sweep.positions_mm) < 2:
            raise ValueError("sweep.positions_mm needs at least two planes")
        return self


EXAMPLE = '''# hifumotion run configuration: lengths in mm, times in s; paths relative to this file.
output = "results"

[sweep]                      # parallel planes through the resting tissue
path = "sweep/"              # a folder of PNGs, a DICOM series, or sweep.nii.gz / .mha / .nrrd
spacing_mm = 0.2             # pixel size (PNGs carry none)
gap_mm = 1.0                 # distance between planes (when the file gives no positions)
first_z_mm = 4.7             # pool z of the first plane

[frames]                     # the imaging plane's time series during the push
path = "cine.dcm"            # DICOM cine, 2D+t NIfTI/MHA, a PNG folder or a video
frame_interval_s = 0.05      # if the file carries none

[initial_contour]
path = "initial_contour.csv" # frame, x_px, y_px: points clicked around the target
frame = 0

[geometry]                   # where the images are in the pool (y up, floor at 0)
row0_col0_mm = [1.0, -8.0]   # pool (x, y) of pixel (0, 0); rows run up from the probe
frames_plane_z_mm = 18.7

[tank]
size_mm = [44.0, 40.0, 36.0]
water_depth_mm = 6.0

[bar]
radius_mm = 6.0
length_mm = 12.0
direction = [0.0, -1.0, 0.0]
tip_at_rest_mm = [22.6, 19.0, 18.7]
force_ramp_s = 0.5

[estimation]
method = "least_squares"     # or "cmaes", "table1" (the paper's algorithm)
training_frames = "20:101:10"
validation_frames = "110:191:10"
particles = 4399
search_particles = 1000
max_evaluations = 8
horizons_frames = [4, 6, 8]
boundary_offset_mm = 0.0     # your system's segmentation bias, from a phantom of known size

# training_contours = "expert_contours.csv"   # a physician's contours instead of GLCV tracking
# [truth]
# masks = "expert_masks/"                      # frame_NNNN.png masks to score the prediction against
'''


def load_run_config(path: str | Path) -> tuple[RunConfig, Path]:
    """The configuration and the folder its relative paths are relative to."""
    from hifumotion.config import load_config

    p = Path(path)
    return load_config(p, RunConfig), p.resolve().parent


def _resolve(base: Path, p: Path | None) -> Path | None:
    return None if p is None else (p if p.is_absolute() else base / p)


def _frame_number(label: str) -> int | None:
    try:
        return int(float(label))
    except ValueError:
        return None


def _as_uint8(frames: np.ndarray, flip: bool) -> np.ndarray:
    """Frames in [0, 1] (the readers' convention) as 8-bit grey, optionally flipped upside down."""
    out = np.clip(np.rint(np.asarray(frames, float) * 255.0), 0, 255).astype(np.uint8)
    return out[:, ::-1, :].copy() if flip else out


def assemble_observed(cfg: RunConfig, base: Path, folder: str | Path) -> Path:
    """Write the ``observed/`` layout (``setup.json``, ``sweep/``, ``frames/``, ``sweep_positions.csv``,
    ``initial_contour.csv``) from the user's files; every missing or inconsistent piece is one
    :class:`~hifumotion.errors.InputError` naming the file or field."""
    from hifumotion.io import read_sequence, write_json
    from hifumotion.io.files import write_text
    from hifumotion.io.writers import read_contours_csv, write_contours_csv, write_png_stack

    folder = Path(folder)
    sweep_path, frames_path = _resolve(base, cfg.sweep.path), _resolve(base, cfg.frames.path)
    if cfg.sweep.positions_mm is None and cfg.sweep.gap_mm is None:
        sweep = read_sequence(sweep_path, spacing_mm=cfg.sweep.spacing_mm, kind="sweep")   # positions from the file
    else:
        sweep = read_sequence(sweep_path, spacing_mm=cfg.sweep.spacing_mm)
    frames = read_sequence(frames_path, spacing_mm=cfg.frames.spacing_mm, frame_interval_s=cfg.frames.frame_interval_s,
                           kind="cine")
    if not sweep.spacing_known:
        raise InputError("the sweep's file gives no pixel size: set sweep.spacing_mm", sweep_path)
    if not frames.spacing_known:
        raise InputError("the time series' file gives no pixel size: set frames.spacing_mm", frames_path)
    if frames.frame_interval_s is None:
        raise InputError("the time series' file gives no frame interval: set frames.frame_interval_s", frames_path)
    for name, seq, where in (("sweep", sweep, sweep_path), ("frames", frames, frames_path)):
        if abs(seq.spacing_mm[0] - seq.spacing_mm[1]) > 1e-6 * seq.spacing_mm[0]:
            raise InputError(f"{name}: square pixels expected, got {seq.spacing_mm} mm", where)
    if abs(sweep.spacing_mm[0] - frames.spacing_mm[0]) > 1e-6 or sweep.frames.shape[1:] != frames.frames.shape[1:]:
        raise InputError(f"the sweep ({sweep.frames.shape[1:]} px of {sweep.spacing_mm[0]} mm) and the time series "
                         f"({frames.frames.shape[1:]} px of {frames.spacing_mm[0]} mm) must share one image grid",
                         "sweep.path / frames.path")
    if cfg.sweep.positions_mm is not None:
        z = np.asarray(cfg.sweep.positions_mm, float)
    elif cfg.sweep.gap_mm is not None:
        z = np.arange(len(sweep.frames)) * cfg.sweep.gap_mm
    else:
        z = np.asarray(sweep.slice_positions_mm, float)
    if len(z) != len(sweep.frames):
        raise InputError(f"{len(z)} positions for {len(sweep.frames)} sweep images", "sweep.positions_mm")
    if cfg.sweep.first_z_mm is not None:
        z = z - z[0] + cfg.sweep.first_z_mm
    if cfg.initial_contour.frame >= len(frames.frames):
        raise InputError(f"frame {cfg.initial_contour.frame} of {len(frames.frames)} frames", "initial_contour.frame")
    contour_path = _resolve(base, cfg.initial_contour.path)
    contours = read_contours_csv(contour_path, spacing_mm=frames.spacing_mm)
    wanted = [c for label, c in contours.items() if _frame_number(label) == cfg.initial_contour.frame]
    if not wanted:
        raise InputError(f"no contour of frame {cfg.initial_contour.frame} (initial_contour.frame); frames given: "
                         f"{', '.join(contours)}", contour_path)

    write_png_stack(folder / "sweep", _as_uint8(sweep.frames, cfg.sweep.flip_rows), prefix="slice_", digits=3)
    write_png_stack(folder / "frames", _as_uint8(frames.frames, cfg.frames.flip_rows), prefix="frame_", digits=4)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["slice", "z_mm"])
    w.writerows([i, f"{v:.6f}"] for i, v in enumerate(z))
    write_text(folder / "sweep_positions.csv", buf.getvalue())
    write_contours_csv(folder / "initial_contour.csv", {cfg.initial_contour.frame: wanted[0]})
    pixel = float(frames.spacing_mm[0])
    write_json(folder / "setup.json", {
        "description": "assembled by hifumotion run from the user's files",
        "frame_interval_s": float(frames.frame_interval_s), "frames": int(len(frames.frames)),
        "initial_contour_frame": cfg.initial_contour.frame,
        "imaging": {"image_shape": list(frames.frames.shape[1:]), "pixel_mm": pixel,
                    "column_axis": [1.0, 0.0, 0.0], "row_axis": [0.0, 1.0, 0.0],
                    "row0_col0_mm": list(cfg.geometry.row0_col0_mm),
                    "frames_plane_z_mm": cfg.geometry.frames_plane_z_mm, "sweep_z_mm": z.tolist()},
        "tank": cfg.tank.model_dump(mode="json"),
        "bar": cfg.bar.model_dump(mode="json"),
        "sources": {"sweep": str(sweep_path), "frames": str(frames_path)},
    })
    return folder


def run_user(cfg: RunConfig, base: Path, out: Path, record, progress: Progress | None = None) -> dict:
    """Assemble ``out/observed``, run the pipeline, write ``out/report/report.html``."""
    from hifumotion.report.build import ReportInputs, output_links, write_report
    from hifumotion.scoring import read_frame_masks

    with record.stage("read the user's files"):
        observed = assemble_observed(cfg, base, out / "observed")
    truth = None
    if cfg.truth.masks is not None:
        truth = read_frame_masks(_resolve(base, cfg.truth.masks))
    outcome = run_pipeline(observed, out, cfg.estimation, contours_csv=_resolve(base, cfg.training_contours),
                           truth_masks=truth, truth_kind="expert masks", record=record, progress=progress)
    with record.stage("report"):
        page = write_report(out / "report", outcome, truth, ReportInputs(
            title="hifumotion run", timings_s=dict(record.timings_s), links=output_links(out),
            experiment_note=f"Sweep {cfg.sweep.path}, time series {cfg.frames.path}."))
    summary = outcome_summary(outcome)
    summary["report"] = page.relative_to(out).as_posix()
    return summary


__all__ = ["RunConfig", "EXAMPLE", "load_run_config", "assemble_observed", "run_user"]
