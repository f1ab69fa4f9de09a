"""What ``setup.json`` holds: the operator's knowledge of the experiment, typed and versioned.

One model, :class:`Setup`, written by the synthetic twin and by ``hifumotion run`` through
:func:`write_setup` and read by everything downstream through :func:`read_setup`: the
image geometry in the pool's frame, the frame interval, the pool, the bar and the *shape*
of the push (how its force rises; not how large it is, which the estimation finds).

Frame of reference: the pool's, in mm, y up, the floor at y = 0. Image rows run upwards
from the probe (depth), columns along x; ``row0_col0_mm`` is the pool (x, y) of the centre
of pixel (row 0, column 0) and a plane's z its position along the pool's z.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hifumotion.apparatus import BAR_CONTROL, BAR_DIRECTION, BAR_EDGE_RADIUS_MM, BAR_LENGTH_MM, BAR_RADIUS_MM
from hifumotion.config import ConfigModel, validate_config
from hifumotion.errors import InputError

#: The version of the ``setup.json`` layout this code writes and reads.
SCHEMA_VERSION = 1

Vector3 = tuple[float, float, float]


class ImagingGeometry(ConfigModel):
    """Where the images lie in the pool."""

    image_shape: tuple[int, int] = Field(description="rows, columns of every image (px)")
    pixel_mm: float = Field(gt=0, le=10, description="square pixel size (mm)")
    column_axis: Vector3 = Field((1.0, 0.0, 0.0), description="pool direction of increasing column")
    row_axis: Vector3 = Field((0.0, 1.0, 0.0), description="pool direction of increasing row (up, away from the probe)")
    row0_col0_mm: tuple[float, float] = Field(description="pool (x, y) of the centre of pixel (row 0, column 0), mm")
    frames_plane_z_mm: float = Field(description="pool z of the time series' imaging plane (mm)")
    sweep_z_mm: list[float] = Field(default_factory=list, description="pool z of each sweep plane (mm)")

    @field_validator("image_shape")
    @classmethod
    def _shape(cls, v):
        if min(v) < 8:
            raise ValueError("images must be at least 8 × 8 px")
        return v

    @model_validator(mode="after")
    def _axes(self):
        if not (np.allclose(self.column_axis, (1, 0, 0)) and np.allclose(self.row_axis, (0, 1, 0))):
            raise ValueError("only planes with columns along x and rows along y (z = the plane's position) "
                             "are supported")
        return self


class TankSetup(ConfigModel):
    """The water pool."""

    size_mm: Vector3 = Field(description="inner size of the pool (x, y up, z) in mm")
    water_depth_mm: float = Field(ge=0, description="water above the floor in mm")

    @field_validator("size_mm")
    @classmethod
    def _positive(cls, v):
        if any(not (s > 0) for s in v):
            raise ValueError("every side of the pool must be positive (mm)")
        return v


class BarSetup(ConfigModel):
    """The pushing bar: a rigid cylinder, its end face the tip."""

    enabled: bool = Field(True, description="whether a bar pushes the tissue")
    radius_mm: float = Field(BAR_RADIUS_MM, gt=0, description="radius of the cylindrical bar in mm")
    length_mm: float = Field(BAR_LENGTH_MM, gt=0, description="length of the bar in mm")
    direction: Vector3 = Field(BAR_DIRECTION, description="direction the bar pushes along (normalised on reading)")
    tip_at_rest_mm: Vector3 = Field(description="pool position of the bar's tip before the push, mm")
    weight_supported: bool = Field(True, description="a hand carries the bar's weight")
    edge_radius_mm: float = Field(BAR_EDGE_RADIUS_MM, gt=0, description="rounding of the edge of the bar's pushing end in mm (a machined bar's edge break; at most radius_mm); the model rounds its rim at the larger of this and half a voxel spacing")

    @model_validator(mode="after")
    def _edge_within_radius(self):
        if self.edge_radius_mm > self.radius_mm:
            raise ValueError(f"edge_radius_mm ({self.edge_radius_mm:g}) must be at most radius_mm ({self.radius_mm:g})")
        return self

    @field_validator("direction")
    @classmethod
    def _unit(cls, v):
        n = float(np.linalg.norm(v))
        if not n > 0 or not np.isfinite(n):
            raise ValueError("the bar's direction must be a non-zero vector")
        return tuple(float(c) / n for c in v)


class PushSchedule(ConfigModel):
    """The push's schedule: the shape of its force (its magnitude is what the estimation finds)
    or, for a bar driven in travel control, its travel itself (the stage's program: known)."""

    control: Literal["force", "travel"] = Field(BAR_CONTROL, description="force: the bar pushes with a force of known shape and unknown size; travel: the bar is driven along its axis by travel_mm at times_s (its force is a result)")
    shape: Literal["ramp_hold", "piecewise_linear"] = Field("ramp_hold", description="ramp_hold: a linear rise over ramp_s, then held; piecewise_linear: the force at times_s is relative_force × its unknown peak (travel control: the travel is travel_mm), linear in between")
    ramp_s: float = Field(0.0, ge=0, description="duration of the rise (s)")
    times_s: list[float] | None = Field(None, description="piecewise_linear: the schedule's times (s), increasing")
    relative_force: list[float] | None = Field(None, description="piecewise_linear, force control: the force at each time over the peak force (0 … 1)")
    travel_mm: list[float] | None = Field(None, description="travel control: the bar's travel along its axis at each of times_s, in mm (≥ 0), from where it rests on the settled tissue")

    @model_validator(mode="after")
    def _piecewise(self):
        if self.control == "travel":
            if self.shape != "piecewise_linear" or self.times_s is None or self.travel_mm is None \
                    or len(self.times_s) != len(self.travel_mm) or len(self.times_s) < 2:
                raise ValueError("travel control needs shape piecewise_linear with times_s and travel_mm of the "
                                 "same length (≥ 2)")
            if any(not (x >= 0) for x in self.travel_mm):
                raise ValueError("travel_mm must be ≥ 0 mm: the bar pushes, it does not pull")
        elif self.travel_mm is not None:
            raise ValueError("travel_mm is the schedule of a bar in travel control (control = travel)")
        if self.shape == "piecewise_linear":
            if self.times_s is None or len(self.times_s) < 2:
                raise ValueError("piecewise_linear needs times_s (≥ 2)")
            if any(b <= a for a, b in zip(self.times_s, self.times_s[1:])):
                raise ValueError("times_s must increase")
        if self.shape == "piecewise_linear" and self.control == "force":
            if self.relative_force is None or len(self.times_s) != len(self.relative_force):
                raise ValueError("piecewise_linear needs times_s and relative_force of the same length (≥ 2)")
            if any(not 0.0 <= f <= 1.0 for f in self.relative_force) or max(self.relative_force) <= 0:
                raise ValueError("relative_force must lie in 0 … 1 with a positive peak")
        return self

    def program(self, times_s) -> np.ndarray:
        """The push's known program at ``times_s`` (s from the push's start): the driven bar's
        travel in mm (travel control), or the force over its unknown peak, 0 … 1 (force
        control). What the operator knows before the push; a surrogate predictor regresses the
        target's motion on it (:mod:`hifumotion.prediction.surrogates`)."""
        t = np.asarray(times_s, float)
        if self.control == "travel":
            return np.interp(t, self.times_s, self.travel_mm)
        if self.shape == "piecewise_linear":
            return np.interp(t, self.times_s, self.relative_force)
        if self.ramp_s > 0:
            return np.clip(t / self.ramp_s, 0.0, 1.0)
        return np.where(t >= 0, 1.0, 0.0)

    def schedule(self, peak_force_n: float) -> dict:
        """The :class:`~hifumotion.scene.BarConfig` fields of this shape at ``peak_force_n``
        (travel control: the travel itself; no force is read)."""
        if self.control == "travel":
            return {"control": "travel", "schedule_times_s": list(self.times_s),
                    "schedule_travel_mm": list(self.travel_mm), "schedule_force_n": None, "ramp_s": 0.0,
                    "force_n": peak_force_n}
        if self.shape == "piecewise_linear":
            return {"schedule_times_s": list(self.times_s),
                    "schedule_force_n": [peak_force_n * f for f in self.relative_force],
                    "force_n": peak_force_n, "ramp_s": 0.0}
        return {"force_n": peak_force_n, "ramp_s": self.ramp_s, "schedule_times_s": None, "schedule_force_n": None}


def check_bar_in_tank(bar: BarSetup, tank: TankSetup) -> None:
    """Raise ``ValueError`` when an enabled bar's tip lies outside the pool."""
    if bar.enabled:
        tip = np.asarray(bar.tip_at_rest_mm)
        if np.any(tip < -1e-9) or np.any(tip > np.asarray(tank.size_mm) + 1e-9):
            raise ValueError(f"the bar's tip {tuple(bar.tip_at_rest_mm)} mm is outside the pool "
                             f"(0 … {tuple(tank.size_mm)} mm)")


class Setup(ConfigModel):
    """The contents of ``setup.json`` (see the module docstring)."""

    schema_version: Literal[1] = Field(SCHEMA_VERSION, description="version of this layout")
    description: str = Field("", description="free text")
    frame_interval_s: float = Field(gt=0, description="time between frames (s)")
    frames: int = Field(ge=2, description="number of frames of the time series")
    initial_contour_frame: int = Field(0, ge=0, description="the frame the clicked contour outlines")
    imaging: ImagingGeometry
    tank: TankSetup
    bar: BarSetup
    push: PushSchedule = Field(default_factory=PushSchedule, description="the force's schedule, shape only")
    sources: dict[str, str] = Field(default_factory=dict, description="where the images came from")

    @model_validator(mode="after")
    def _consistent(self):
        if self.initial_contour_frame >= self.frames:
            raise ValueError(f"initial_contour_frame {self.initial_contour_frame} is not one of the "
                             f"{self.frames} frames")
        check_bar_in_tank(self.bar, self.tank)
        if self.tank.water_depth_mm > self.tank.size_mm[1]:
            raise ValueError(f"tank.water_depth_mm ({self.tank.water_depth_mm:g}) is deeper than the pool is high "
                             f"(tank.size_mm[1] = {self.tank.size_mm[1]:g})")
        return self

    @property
    def pixel_mm(self) -> float:
        return self.imaging.pixel_mm

    def program_at_frames(self, frames: int | None = None) -> np.ndarray:
        """``(frames,)`` the push's known program (:meth:`PushSchedule.program`) at frames
        0 … frames − 1 (default: every frame of the series), frame t at t × frame_interval_s."""
        n = self.frames if frames is None else int(frames)
        return self.push.program(np.arange(n) * self.frame_interval_s)

    @property
    def image_origin_mm(self) -> np.ndarray:
        """``(3,)`` pool position of the image origin, pixel (0, 0), at z = 0 (mm)."""
        x0, y0 = self.imaging.row0_col0_mm
        return np.array([x0, y0, 0.0])


def write_setup(path: str | Path, setup: Setup) -> Path:
    """Write ``setup`` as JSON (atomically)."""
    from hifumotion.io import write_json

    return write_json(path, setup.model_dump(mode="json"))


def read_setup(path: str | Path) -> Setup:
    """``setup.json`` as a :class:`Setup`; a missing, malformed or invalid file is one
    :class:`~hifumotion.errors.InputError` naming the file and the field."""
    from hifumotion.io.structured import read_structured

    p = Path(path)
    data = read_structured(p, "json", "setup.json")
    if not isinstance(data, dict):
        raise InputError("expected a JSON object", p)
    if isinstance(data.get("bar"), dict) and "force_ramp_s" in data["bar"] and "push" not in data:
        # written before the schedule had a section of its own: the bar carried the ramp
        bar = dict(data["bar"])
        data = {**data, "bar": bar, "push": {"shape": "ramp_hold", "ramp_s": bar.pop("force_ramp_s")}}
    for key in ("frame_files", "sweep_files"):     # the earlier layout named its (fixed) file patterns
        data.pop(key, None)
    data.setdefault("schema_version", SCHEMA_VERSION)
    if data["schema_version"] != SCHEMA_VERSION:
        raise InputError(f"schema_version {data['schema_version']!r}; this hifumotion reads version {SCHEMA_VERSION}", p)
    return validate_config(Setup, data, p)


__all__ = ["SCHEMA_VERSION", "Setup", "ImagingGeometry", "TankSetup", "BarSetup", "PushSchedule",
           "read_setup", "write_setup"]
