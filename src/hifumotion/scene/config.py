"""A scene as data: a water tank, a tissue resting on its floor and a pushing bar (TOML).

Interface units are mm, s, kg/m³, Pa and N; :func:`~hifumotion.particles.scene_system.build_scene`
converts them to SI for the particle solver. The tank frame has y up (gravity along −y); the tank's inner
box runs from (0, 0, 0) to ``tank.size_mm``. A minimal ``scene.toml``::

    [tank]
    size_mm = [50.0, 40.0, 40.0]
    water_depth_mm = 24.0

    [tissue]
    shape = "ellipsoid"          # "ellipsoid", "box" or "particles" (a CSV from `hifumotion reconstruct`)
    size_mm = [30.0, 18.0, 24.0]

    [bar]
    force_n = 0.25
    ramp_s = 0.2

    [run]
    duration_s = 1.0
    output_interval_s = 0.05

``hifumotion simulate --print-scene`` prints every field with its unit.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hifumotion import paper
from hifumotion.apparatus import BAR_CONTROL, BAR_DIRECTION, BAR_EDGE_RADIUS_MM, BAR_LENGTH_MM, BAR_RADIUS_MM, FRICTION
from hifumotion.config import ConfigModel
from hifumotion.errors import InputError
from hifumotion.numerics import CFL, EXPLICIT_MASS_SCALING, EXPLICIT_MAX_STEP_S, SUPPORT_FACTOR
from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.resources import MAX_FRAMES
from hifumotion.rheology import RATE_FLOOR_PER_S
from hifumotion.scene.schedule import piecewise_linear_schedule


class TankConfig(ConfigModel):
    size_mm: tuple[float, float, float] = Field((50.0, 40.0, 40.0), description="inner size of the tank (x, y up, z) in mm")
    water_depth_mm: float = Field(24.0, ge=0, description="height of the water above the floor in mm (0: no water)")
    wall_layers: int = Field(2, ge=1, le=4, description="layers of wall particles")
    wall_height_mm: float | None = Field(None, gt=0, description="height of the wall particles in mm; default: the water line + 3 spacings (nothing above the water touches the walls, and walls cost neighbour work)")

    @field_validator("size_mm")
    @classmethod
    def _positive(cls, v):
        if any(s <= 0 for s in v):
            raise ValueError("tank sizes must be positive (mm)")
        return v

    @model_validator(mode="after")
    def _water_in_the_tank(self):
        if self.water_depth_mm > self.size_mm[1]:
            raise ValueError(f"water_depth_mm ({self.water_depth_mm:g}) exceeds the tank's height size_mm[1] "
                             f"({self.size_mm[1]:g} mm)")
        return self


class TissueMaterial(ConfigModel):
    """The tissue's material (Table 3's parameters and the model's options)."""

    density_kg_m3: float = Field(TISSUE_DENSITY_KG_M3, gt=0, description="tissue density in kg/m³")
    youngs_modulus_pa: float = Field(paper.YOUNGS_MODULUS_PA, gt=0, description="Young's modulus E in Pa (Table 3: 13 kPa)")
    poisson_ratio: float = Field(paper.POISSON_RATIO, gt=-1, lt=0.5, description="Poisson's ratio (Table 3: 0.47)")
    beta1: float = Field(paper.BETA1, ge=0, description="rheological viscosity β1 in Pa·s^(1+β2) (Table 3: 1)")
    beta2: float = Field(paper.BETA2, gt=-1.0, le=3.0, description="rheological viscosity exponent β2 (Table 3: 0.5); the flow index 1 + β2 must be positive")
    rate_floor_per_s: float = Field(RATE_FLOOR_PER_S, gt=0, description="floor of the shear rate in the rheological viscosity μ = β1 max(rate, floor)^β2, in 1/s")
    volume_stiffness_pa: float = Field(0.0, ge=0, description="k_v of the volume-conservation force (Eq. 15–16) in Pa")
    hourglass: float = Field(1.0, ge=0, description="hourglass control α (0: off)")
    corotated: bool = Field(False, description="corotated linear elasticity instead of Saint-Venant–Kirchhoff")
    mls_order: Literal[1, 2] = Field(2, description="MLS gradient: 1 (the paper's linear) or 2 (quadratic)")


class TissueConfig(TissueMaterial):
    shape: Literal["ellipsoid", "box", "particles"] = Field("ellipsoid", description="ellipsoid, box, or particles from a CSV")
    size_mm: tuple[float, float, float] = Field((30.0, 18.0, 24.0), description="extent (x, y, z) of an ellipsoid or box in mm")
    centre_mm: tuple[float, float, float] | None = Field(None, description="centre in the tank (mm); default: centred on the floor")
    particles_csv: Path | None = Field(None, description="CSV with x_mm,y_mm,z_mm[,volume_mm3] (hifumotion reconstruct --particle-spacing)")

    @model_validator(mode="after")
    def _source(self):
        if self.shape == "particles" and self.particles_csv is None:
            raise ValueError("shape 'particles' needs particles_csv")
        return self


#: Largest push a scene takes (N): a hand-held bar on a tissue sample, with room to spare
#: (a push of 10³⁰⁰ N ran until the tissue left the tank, with NumPy's overflow warnings).
MAX_FORCE_N = 1000.0


class BarConfig(ConfigModel):
    enabled: bool = Field(True, description="whether there is a pushing bar")
    radius_mm: float = Field(BAR_RADIUS_MM, gt=0, description="radius of the cylindrical bar (its flat pushing end) in mm")
    length_mm: float = Field(BAR_LENGTH_MM, gt=0, description="length of the bar in mm")
    edge_radius_mm: float = Field(BAR_EDGE_RADIUS_MM, gt=0, description="rounding of the edge of the bar's pushing end in mm (a machined bar's edge break; at most radius_mm); the finite-strain truth's bar is this solid; the fast path rounds its rim at the larger of this and half a voxel spacing; the particle path and the small-strain truth push with the end's flat disc")
    direction: tuple[float, float, float] = Field(BAR_DIRECTION, description="unit vector the bar points and pushes along (default: down onto the tissue)")
    tip_mm: tuple[float, float, float] | None = Field(None, description="position of the bar's tip (mm); default: touching the tissue (one spacing from the first tissue particle under its end face), on the axis through the tissue's centre")
    density_kg_m3: float = Field(7800.0, gt=0, description="density of the bar (steel) in kg/m³")
    weight_supported: bool = Field(True, description="the hand holding the bar carries its weight, so the push on the tissue is force_n alone")
    control: Literal["force", "travel"] = Field(BAR_CONTROL, description="what drives the bar: force (it pushes with force_n or schedule_force_n, and how far it goes is a result) or travel (its end is driven along its axis by travel_mm or schedule_travel_mm from where it rests on the settled tissue, and the force it takes is a result)")
    force_n: float = Field(paper.FORCE_N, ge=0, le=MAX_FORCE_N, description="pushing force held after the ramp, in N (Table 3: 0.25; at most 1,000); the bar pushes, it does not pull")
    travel_mm: float = Field(0.0, ge=0, le=1000.0, description="travel control: how far the bar's end is driven along its axis by the end of the ramp, in mm, from where it rests on the settled tissue")
    ramp_s: float = Field(0.2, ge=0, description="time over which the force (travel control: the travel) rises linearly from 0, in s")
    schedule_times_s: list[float] | None = Field(None, description="explicit schedule: times in s (overrides force_n or travel_mm, and ramp_s)")
    schedule_force_n: list[float] | None = Field(None, description="explicit force schedule: forces in N at schedule_times_s")
    schedule_travel_mm: list[float] | None = Field(None, description="travel control: explicit schedule of the travel in mm at schedule_times_s (≥ 0: the bar never pulls the tissue; a travel that falls lifts the bar off as the tissue lets it)")

    @model_validator(mode="after")
    def _schedule(self):
        values = self.schedule_travel_mm if self.control == "travel" else self.schedule_force_n
        name = "schedule_travel_mm" if self.control == "travel" else "schedule_force_n"
        other = "schedule_force_n" if self.control == "travel" else "schedule_travel_mm"
        if getattr(self, other) is not None:
            raise ValueError(f"{other} does not drive a bar in {self.control} control; give {name}")
        if (self.schedule_times_s is None) != (values is None):
            raise ValueError(f"give both schedule_times_s and {name}, or neither")
        if self.schedule_times_s is not None:
            piecewise_linear_schedule(self.schedule_times_s, values)
            if any(not (f >= 0) for f in values):
                raise ValueError(f"{name}: the bar pushes, it does not pull; values must be ≥ 0")
            top = MAX_FORCE_N if self.control == "force" else 1000.0
            if any(f > top for f in values):
                raise ValueError(f"{name}: values must be at most {top:g} ({'N' if self.control == 'force' else 'mm'})")
        if np.linalg.norm(self.direction) == 0:
            raise ValueError("direction must not be zero")
        if self.edge_radius_mm > self.radius_mm:
            raise ValueError(f"edge_radius_mm ({self.edge_radius_mm:g}) must be at most radius_mm ({self.radius_mm:g})")
        return self

    def schedule(self):
        """The push F(t) (N) of a bar in force control (none in travel control: the force is a result)."""
        if self.control == "travel":
            raise ValueError("a bar in travel control has no force schedule: its force is a result")
        return self._piecewise(self.schedule_force_n, self.force_n)

    def travel_schedule(self):
        """The travel (mm) of a bar in travel control at time t (s), from where it rests on the settled tissue."""
        if self.control != "travel":
            raise ValueError("a bar in force control has no travel schedule: its travel is a result")
        return self._piecewise(self.schedule_travel_mm, self.travel_mm)

    def breakpoints_s(self) -> tuple[float, ...]:
        """Where the schedule bends (s): a time stepper lands a step on each."""
        if self.schedule_times_s is not None:
            return tuple(self.schedule_times_s)
        return (self.ramp_s,) if self.ramp_s > 0 else ()

    def _piecewise(self, values, held):
        if self.schedule_times_s is not None:
            return piecewise_linear_schedule(self.schedule_times_s, values)
        if self.ramp_s > 0:
            return piecewise_linear_schedule([0.0, self.ramp_s], [0.0, held])
        return lambda t: held


class ParticleConfig(ConfigModel):
    spacing_mm: float = Field(1.5, gt=0, description="particle spacing Δx in mm")
    support_factor: float = Field(SUPPORT_FACTOR, ge=1.5, le=3.0, description="kernel support radius h in spacings")


class PhysicsConfig(ConfigModel):
    gravity_m_s2: float = Field(STANDARD_GRAVITY_M_S2, ge=0, description="gravitational acceleration in m/s²")
    water_density_kg_m3: float = Field(WATER_DENSITY_KG_M3, gt=0, description="rest density ρ0 of the water in kg/m³")
    water_viscosity_pa_s: float = Field(0.02, ge=0, description="μ of Eq. 12 for the water in Pa·s")
    sound_speed_m_s: float | None = Field(None, gt=0, description="numerical speed of sound of the water (√K) in m/s; default from the depth")
    contact_coefficient: float | None = Field(None, ge=0, description="K_c of Eq. 18 between solids in N·m⁴/kg²; default from E")
    contact_pressure_factor: float = Field(4.0, gt=0, description="default K_c makes the largest tissue–bar pair force this × E × Δx²")
    fluid_coefficient: float = Field(0.0, ge=0, description="K_c of Eq. 18 between water and solids in N·m⁴/kg²")
    friction: float = Field(FRICTION, ge=0, description="Coulomb friction between solids (tissue–floor, tissue–bar)")


class RunConfig(ConfigModel):
    duration_s: float = Field(1.0, gt=0, description="simulated time after settling, in s (rounded down to whole output intervals)")
    output_interval_s: float = Field(0.05, gt=0, description="time between written frames, in s")
    settle_s: float = Field(0.2, ge=0, description="settling under gravity (damped, bar held) before t = 0, in s")
    settle_damping_per_s: float = Field(40.0, ge=0, description="velocity damping while settling, in 1/s")
    mass_scaling: float = Field(EXPLICIT_MASS_SCALING, ge=1.0, description="inertia multiplier for quasi-static runs (weights unchanged)")
    cfl: float = Field(CFL, gt=0, le=1.0, description="safety factor on the time step")
    max_step_s: float = Field(EXPLICIT_MAX_STEP_S, gt=0, description="largest time step in s")
    write_vtu: bool = Field(True, description="write VTU files of the particles (with a PVD index)")
    vtu_every: int = Field(1, ge=1, description="write every n-th output frame as VTU")

    @model_validator(mode="after")
    def _bounded_work(self):
        frames = self.duration_s / self.output_interval_s
        if frames > MAX_FRAMES:
            raise ValueError(f"duration_s / output_interval_s = {frames:.3g} frames; a run records at most "
                             f"{MAX_FRAMES:,} (a longer interval or a shorter run)")
        if self.duration_s / self.max_step_s > 1e9:
            raise ValueError(f"duration_s / max_step_s = {self.duration_s / self.max_step_s:.3g} steps at the least; "
                             "expected at most 10⁹")
        return self


class Scene(ConfigModel):
    """A scene: tank, tissue, bar, particles, physics and run settings."""

    tank: TankConfig = TankConfig()
    tissue: TissueConfig = TissueConfig()
    bar: BarConfig = BarConfig()
    particles: ParticleConfig = ParticleConfig()
    physics: PhysicsConfig = PhysicsConfig()
    run: RunConfig = RunConfig()

    @model_validator(mode="after")
    def _bar_in_tank(self):
        if self.bar.enabled and self.bar.tip_mm is not None:
            tip, size = np.asarray(self.bar.tip_mm, float), np.asarray(self.tank.size_mm, float)
            if np.any(tip < 0) or np.any(tip > size):
                raise ValueError(f"bar.tip_mm {tuple(self.bar.tip_mm)} lies outside the tank (0 … {tuple(self.tank.size_mm)} mm)")
        return self


#: Memory per particle of a run (bytes): state, neighbour lists of ~ 30–60 entries, kernel
#: values and gradients, the elastic rest neighbourhoods; measured ≈ 2 kB on the paper-sized
#: scene, doubled for the peaks of the neighbour search.
BYTES_PER_PARTICLE = 4096


def estimated_particles(scene: Scene) -> float:
    """How many particles ``scene`` builds, before building them: water and walls fill the
    tank up to the water line and a few layers around it, the tissue its box."""
    dx = scene.particles.spacing_mm
    x, y, z = scene.tank.size_mm
    wet = max(scene.tank.water_depth_mm, 0.0) + 3 * dx
    layers = 3 * dx * scene.particles.support_factor
    walls = layers * (x * z + 2 * (x + z) * wet)
    tissue = float(np.prod(scene.tissue.size_mm)) if scene.tissue.shape != "particles" else 0.0
    return (x * z * wet + walls + tissue) / dx ** 3


def load_scene(path: str | Path | None, settings: list[str] | None = None) -> Scene:
    """A :class:`Scene` from a TOML or YAML file (relative CSV paths are relative to it; None:
    the defaults), with ``settings`` (``KEY=VALUE``, :func:`~hifumotion.config.apply_settings`) changed."""
    from hifumotion.config import apply_settings, read_config_file, validate_config

    data = read_config_file(path) if path is not None else {}
    scene = validate_config(Scene, apply_settings(data, settings), path if path is not None else "--set")
    if path is not None and scene.tissue.particles_csv is not None and not scene.tissue.particles_csv.is_absolute():
        scene.tissue.particles_csv = Path(path).parent / scene.tissue.particles_csv
    return scene


def read_particles_csv(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Positions (mm) and volumes (mm³, if present) from a particle CSV."""
    if not Path(path).is_file():
        raise InputError("no such particle file", path)
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except ValueError as exc:
        raise InputError(f"cannot read particles ({exc})", path) from None
    names = data.dtype.names or ()
    if not {"x_mm", "y_mm", "z_mm"} <= set(names):
        raise InputError("expected columns x_mm,y_mm,z_mm[,volume_mm3]", path)
    data = np.atleast_1d(data)
    pts = np.stack([data["x_mm"], data["y_mm"], data["z_mm"]], axis=1)
    vol = np.asarray(data["volume_mm3"], float) if "volume_mm3" in names else None
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise InputError("has no particles or non-numeric positions", path)
    return pts, vol
