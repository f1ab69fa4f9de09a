"""Scenes as data: a water tank, a tissue resting on its floor and a pushing bar (TOML).

Interface units are mm, s, kg/m³, Pa and N; :func:`build_scene` converts them to
SI for the solver. The tank frame has y up (gravity along −y); the tank's inner
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

import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hifumotion.apparatus import BAR_CONTROL, BAR_DIRECTION, BAR_EDGE_RADIUS_MM, BAR_LENGTH_MM, BAR_RADIUS_MM, FRICTION
from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.config import ConfigModel
from hifumotion.errors import InputError
from hifumotion.resources import MAX_FRAMES, check_memory
from hifumotion.rheology import RATE_FLOOR_PER_S
from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.rigid import piecewise_linear_schedule
from hifumotion.numerics import CFL, SUPPORT_FACTOR
from hifumotion.particles.solver import SolverSettings
from hifumotion.particles.system import (CouplingParameters, FluidParameters, ParticleSystem,
                                         build_system, lattice, tank_walls)
from hifumotion import paper

MM = 1e-3


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

    def parameters(self) -> TissueParameters:
        return TissueParameters(youngs_modulus_pa=self.youngs_modulus_pa, poisson_ratio=self.poisson_ratio,
                                volume_stiffness_pa=self.volume_stiffness_pa, beta1=self.beta1,
                                beta2=self.beta2, rate_floor_per_s=self.rate_floor_per_s,
                                hourglass=self.hourglass, corotated=self.corotated, mls_order=self.mls_order)


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
    mass_scaling: float = Field(SolverSettings.mass_scaling, ge=1.0, description="inertia multiplier for quasi-static runs (weights unchanged)")
    cfl: float = Field(CFL, gt=0, le=1.0, description="safety factor on the time step")
    max_step_s: float = Field(SolverSettings.max_step_s, gt=0, description="largest time step in s")
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


def tissue_particles_mm(cfg: TissueConfig, tank: TankConfig, spacing_mm: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Tissue particle positions (mm, tank frame) and volumes (mm³)."""
    if cfg.shape == "particles":
        pts, vol = read_particles_csv(cfg.particles_csv)
        if vol is None:
            vol = np.full(len(pts), spacing_mm ** 3)
        lo = pts.min(0)
        hi = pts.max(0)
        if cfg.centre_mm is None:
            shift = np.array([tank.size_mm[0] / 2, 0.0, tank.size_mm[2] / 2]) - \
                np.array([(lo[0] + hi[0]) / 2, lo[1] - spacing_mm / 2, (lo[2] + hi[2]) / 2])
        else:
            shift = np.asarray(cfg.centre_mm) - (lo + hi) / 2
        return pts + shift, vol
    size = np.asarray(cfg.size_mm, float)
    centre = (np.array([tank.size_mm[0] / 2, size[1] / 2, tank.size_mm[2] / 2])
              if cfg.centre_mm is None else np.asarray(cfg.centre_mm, float))
    pts = lattice(centre - size / 2, centre + size / 2, spacing_mm)
    if cfg.shape == "ellipsoid":
        pts = pts[(((pts - centre) / (size / 2)) ** 2).sum(1) <= 1.0]
        volume = math.pi / 6 * float(np.prod(size))
    else:
        volume = float(np.prod(size))
    if len(pts) == 0:
        raise InputError(f"no particle fits in the tissue at spacing {spacing_mm} mm", "tissue.size_mm")
    return pts, np.full(len(pts), volume / len(pts))


def touching_tip(tissue_mm: np.ndarray, through_mm: np.ndarray, axis: np.ndarray, radius_mm: float,
                 spacing_mm: float) -> np.ndarray | None:
    """The bar's tip on the line through ``through_mm`` along the unit ``axis``, touching the
    tissue: one spacing (where the contact force of Eq. 18 begins) before the first tissue
    particle under the bar's end face; ``None`` when no particle is under it.

    A gap would let the force accelerate the bar freely and strike the tissue (its work
    F × gap turned into an impact), which a slow push does not do; a tip inside the tissue
    would start the push with a spurious compression."""
    rel = np.asarray(tissue_mm, float) - through_mm
    along = rel @ axis
    across = np.linalg.norm(rel - along[:, None] * axis, axis=1)
    under = across <= radius_mm
    if not under.any():
        return None
    return np.asarray(through_mm, float) + (along[under].min() - spacing_mm) * axis


def spacing_for_count(fill, spacing_mm: float, count: int, shrink: float = 0.99, tolerance: float = 1.0):
    """Shrink ``spacing_mm`` until ``fill(spacing)`` holds at least ``tolerance × count`` particles.

    A lattice misses a little of a curved surface, so the spacing that a volume and a count
    imply gives too few; ``fill`` returns the particles (any sized sequence, or a tuple
    whose first item is). Returns ``(spacing, fill(spacing))``."""
    def size(result):
        return len(result[0] if isinstance(result, tuple) else result)

    result = fill(spacing_mm)
    for _ in range(2000):
        if size(result) >= tolerance * count:
            return spacing_mm, result
        spacing_mm *= shrink
        result = fill(spacing_mm)
    raise InputError(f"no spacing gives {count} particles", "particles")


def bar_particles_mm(cfg: BarConfig, tissue_mm: np.ndarray, spacing_mm: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar particles (mm), its unit axis and its tip (mm)."""
    axis = np.asarray(cfg.direction, float)
    axis /= np.linalg.norm(axis)
    if cfg.tip_mm is None:
        # touching the tissue, on the axis through its centre
        centre = tissue_mm.mean(0)
        tip = touching_tip(tissue_mm, centre, axis, cfg.radius_mm, spacing_mm)
        if tip is None:
            tip = centre + (((tissue_mm - centre) @ axis).min() - spacing_mm) * axis
    else:
        tip = np.asarray(cfg.tip_mm, float)
    r, length = cfg.radius_mm, cfg.length_mm
    span = max(r, length) + spacing_mm
    local = lattice([-span] * 3, [span] * 3, spacing_mm)
    helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    t = local @ np.stack([axis, e1, e2], axis=1)  # coordinates along (axis, e1, e2)
    keep = (t[:, 0] <= 0) & (t[:, 0] > -length) & (np.hypot(t[:, 1], t[:, 2]) <= r)
    t = t[keep]
    pts = tip + t[:, :1] * axis + t[:, 1:2] * e1 + t[:, 2:3] * e2
    return pts, axis, tip


def build_scene(scene: Scene, tissue_particles: tuple[np.ndarray, np.ndarray] | None = None
                ) -> tuple[ParticleSystem, dict]:
    """The particle system of a scene (SI) and facts about it (counts, masses, mm geometry).

    ``tissue_particles`` — ``(positions_mm (N, 3), volumes_mm3 (N,))`` in the tank frame —
    replaces the scene's tissue shape with particles held in memory (a fitted model's
    many runs, and Dask workers that do not share the caller's files).
    """
    dx_mm = scene.particles.spacing_mm
    tank = scene.tank
    if scene.bar.enabled and scene.bar.control == "travel":
        raise InputError("the particle path (Eq. 8–20) pushes its bar by a force; a bar in travel control runs on "
                         "the implicit or reduced path, or the finite-strain truth", "bar.control")
    n = estimated_particles(scene) + (0 if tissue_particles is None else len(tissue_particles[0]))
    check_memory(n * BYTES_PER_PARTICLE, f"about {n:.3g} particles at a spacing of {dx_mm:g} mm",
                 "particles.spacing_mm")
    if tissue_particles is None:
        tissue_mm, vol_mm3 = tissue_particles_mm(scene.tissue, tank, dx_mm)
    else:
        tissue_mm = np.asarray(tissue_particles[0], float)
        vol_mm3 = np.asarray(tissue_particles[1], float)
    size = np.asarray(tank.size_mm, float)
    if np.any(tissue_mm < 0) or np.any(tissue_mm > size):
        raise InputError("the tissue does not fit inside the tank", "tissue")
    bodies = []
    facts: dict = {"spacing_mm": dx_mm}
    if scene.bar.enabled:
        bar_mm, axis, tip = bar_particles_mm(scene.bar, tissue_mm, dx_mm)
        if len(bar_mm) == 0:
            raise InputError("the bar is thinner than one particle spacing", "bar.radius_mm")
        bodies.append({"positions_m": bar_mm * MM, "density_kg_m3": scene.bar.density_kg_m3,
                       "force_n": scene.bar.schedule(), "force_direction": axis, "axis": axis,
                       "weight_supported": scene.bar.weight_supported, "name": "bar"})
        facts.update(bar_axis=axis.tolist(), bar_tip_mm=tip.tolist(), bar_particles=len(bar_mm))
    water_mm = np.zeros((0, 3))
    if tank.water_depth_mm > 0:
        water_mm = lattice([0, 0, 0], [size[0], tank.water_depth_mm, size[2]], dx_mm)
        solids = [tissue_mm] + ([bar_mm] if scene.bar.enabled else [])
        from scipy.spatial import cKDTree

        occupied = cKDTree(np.concatenate(solids))
        d, _ = occupied.query(water_mm)
        water_mm = water_mm[d >= 0.99 * dx_mm]
    wall_top = (tank.wall_height_mm if tank.wall_height_mm is not None
                else tank.water_depth_mm + 3 * dx_mm)
    walls_mm = tank_walls([0, 0, 0], [size[0], min(wall_top, size[1]), size[2]], dx_mm,
                          layers=tank.wall_layers)
    ph = scene.physics
    fluid = FluidParameters(rest_density_kg_m3=ph.water_density_kg_m3,
                            stiffness_m2_s2=None if ph.sound_speed_m_s is None else ph.sound_speed_m_s ** 2,
                            viscosity_pa_s=ph.water_viscosity_pa_s)
    coupling = CouplingParameters(fluid_coefficient=ph.fluid_coefficient,
                                  contact_coefficient=ph.contact_coefficient,
                                  contact_pressure_factor=ph.contact_pressure_factor, friction=ph.friction)
    system = build_system(spacing_m=dx_mm * MM, support_factor=scene.particles.support_factor,
                          fluid_positions_m=water_mm * MM, tissue_positions_m=tissue_mm * MM,
                          tissue_volumes_m3=vol_mm3 * MM ** 3, tissue_density_kg_m3=scene.tissue.density_kg_m3,
                          bodies=bodies, wall_positions_m=walls_mm * MM, fluid=fluid,
                          tissue=scene.tissue.parameters(), coupling=coupling,
                          gravity_m_s2=(0.0, -ph.gravity_m_s2, 0.0),
                          domain_lo_m=np.zeros(3) - 4 * dx_mm * MM, domain_hi_m=size * MM + 4 * dx_mm * MM,
                          water_depth_m=max(tank.water_depth_mm, dx_mm) * MM)
    facts.update(counts=dict(system.counts), tissue_mass_kg=float(system.mass[system.tissue_slice].sum()),
                 tissue_volume_mm3=float(vol_mm3.sum()))
    return system, facts


def solver_settings(scene: Scene, settling: bool = False) -> SolverSettings:
    run = scene.run
    return SolverSettings(cfl=run.cfl, mass_scaling=run.mass_scaling, max_step_s=run.max_step_s,
                          damping_per_s=run.settle_damping_per_s if settling else 0.0)
