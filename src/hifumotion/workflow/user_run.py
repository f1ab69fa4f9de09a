"""``hifumotion run CONFIG.toml``: the pipeline on a user's own files.

A run configuration names the spatial sweep and the time series (DICOM, NIfTI/MHA/NRRD,
a folder of PNGs, or a video), the clicked initial contour, where the images sit in the
pool, the pool and the bar, and how to estimate (``[estimation]``, see
:class:`~hifumotion.workflow.pipeline.EstimationConfig`). :func:`assemble_observed`
turns it into the ``observed/`` layout the pipeline reads (the same the synthetic
experiment writes, :mod:`hifumotion.observed`); :func:`run_user` runs the
pipeline and writes the report. Lengths in mm, times in s; relative paths are relative
to the configuration file. ``hifumotion run --example`` prints a complete example.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
from pydantic import Field, model_validator

from hifumotion.config import ConfigModel
from hifumotion.errors import InputError
from hifumotion.observed import BarSetup, PushSchedule, Setup, TankSetup
from hifumotion.observed.setup import check_bar_in_tank
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


class ExpertMasksConfig(ConfigModel):
    masks: Path | None = Field(None, description="folder of expert masks frame_NNNN.png (0/255) on the frames' grid, to score against")


class UserRunConfig(ConfigModel):
    """A ``hifumotion run`` configuration (TOML or YAML)."""

    output: Path | None = Field(None, description="output folder (default: given with -o)")
    sweep: SweepConfig
    frames: FramesConfig
    initial_contour: ContourConfig
    geometry: GeometryConfig
    tank: TankSetup
    bar: BarSetup
    push: PushSchedule = Field(default_factory=PushSchedule, description="the shape of the push's force schedule")
    estimation: EstimationConfig = EstimationConfig()
    training_contours: Path | None = Field(None, description="CSV of expert contours of training frames (frame, x_px, y_px), used instead of the tracked contours")
    truth: ExpertMasksConfig = ExpertMasksConfig()

    @model_validator(mode="after")
    def _positions(self):
        if self.sweep.positions_mm is not None and len(self.sweep.positions_mm) < 2:
            raise ValueError("sweep.positions_mm needs at least two planes")
        check_bar_in_tank(self.bar, self.tank)
        return self


def example_config() -> UserRunConfig:
    """A complete, valid run configuration (the one ``hifumotion run --example`` prints)."""
    return UserRunConfig(
        output=Path("results"),
        sweep=SweepConfig(path=Path("sweep/"), spacing_mm=0.2, gap_mm=1.0, first_z_mm=4.7),
        frames=FramesConfig(path=Path("cine.dcm"), frame_interval_s=0.05),
        initial_contour=ContourConfig(path=Path("initial_contour.csv"), frame=0),
        geometry=GeometryConfig(row0_col0_mm=(1.0, -8.0), frames_plane_z_mm=18.7),
        tank=TankSetup(size_mm=(44.0, 40.0, 36.0), water_depth_mm=6.0),
        bar=BarSetup(radius_mm=6.0, length_mm=12.0, direction=(0.0, -1.0, 0.0), tip_at_rest_mm=(22.6, 19.0, 18.7)),
        push=PushSchedule(shape="ramp_hold", ramp_s=0.5),
        estimation=EstimationConfig(training_frames="20:101:10", validation_frames="110:191:10"))


def example_text() -> str:
    """:func:`example_config` as TOML, every field with its description (and unit) as a comment."""
    from hifumotion.config import dump_toml

    return ("# hifumotion run configuration: lengths in mm, times in s; paths relative to this file.\n"
            "# Fields shown as '(not set)' are optional: remove the '#' and give a value to set them.\n\n"
            + dump_toml(example_config()))


def load_run_config(path: str | Path, settings: list[str] | None = None) -> tuple[UserRunConfig, Path]:
    """The configuration, with ``settings`` (``KEY=VALUE``: :func:`~hifumotion.config.apply_settings`)
    changed, and the folder its relative paths are relative to."""
    from hifumotion.config import apply_settings, read_config_file, validate_config

    p = Path(path)
    return validate_config(UserRunConfig, apply_settings(read_config_file(p), settings), p), p.resolve().parent


def run_inputs(cfg: UserRunConfig, base: Path) -> list[Path]:
    """Every file and folder a run configuration reads (resolved against ``base``)."""
    paths = [cfg.sweep.path, cfg.frames.path, cfg.initial_contour.path, cfg.training_contours, cfg.truth.masks]
    return [_resolve(base, p) for p in paths if p is not None]


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


def assemble_observed(cfg: UserRunConfig, base: Path, folder: str | Path) -> Path:
    """Write the ``observed/`` layout (``setup.json``, ``sweep/``, ``frames/``, ``sweep_positions.csv``,
    ``initial_contour.csv``) from the user's files; every missing or inconsistent piece is one
    :class:`~hifumotion.errors.InputError` naming the file or field."""
    from hifumotion.config import validate_config
    from hifumotion.io import read_sequence
    from hifumotion.io.writers import read_contours_csv
    from hifumotion.observed import write_observed

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

    imaging = {"image_shape": tuple(frames.frames.shape[1:]), "pixel_mm": float(frames.spacing_mm[0]),
               "row0_col0_mm": tuple(cfg.geometry.row0_col0_mm),
               "frames_plane_z_mm": cfg.geometry.frames_plane_z_mm, "sweep_z_mm": z.tolist()}
    setup = validate_config(Setup, {
        "description": "assembled by hifumotion run from the user's files",
        "frame_interval_s": float(frames.frame_interval_s), "frames": int(len(frames.frames)),
        "initial_contour_frame": cfg.initial_contour.frame, "imaging": imaging,
        "tank": cfg.tank, "bar": cfg.bar, "push": cfg.push,
        "sources": {"sweep": str(sweep_path), "frames": str(frames_path)}}, "the images' geometry")
    write_observed(folder, setup, _as_uint8(sweep.frames, cfg.sweep.flip_rows), z,
                   _as_uint8(frames.frames, cfg.frames.flip_rows), wanted[0])
    return folder


def run_user(cfg: UserRunConfig, base: Path, out: Path, record, progress: Progress | None = None) -> dict:
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


__all__ = ["run_inputs", "UserRunConfig", "example_config", "example_text", "load_run_config", "assemble_observed", "run_user"]
