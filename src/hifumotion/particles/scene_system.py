"""A :class:`~hifumotion.scene.Scene` as a particle system (Eq. 8–20): the tissue's, the water's,
the walls' and the bar's particles, in SI for the solver, and the solver's settings."""

from __future__ import annotations

import math

import numpy as np

from hifumotion.errors import InputError
from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.solver import SolverSettings
from hifumotion.particles.system import (CouplingParameters, FluidParameters, ParticleSystem,
                                         build_system, lattice, tank_walls)
from hifumotion.resources import check_memory
from hifumotion.scene.config import (BYTES_PER_PARTICLE, BarConfig, Scene, TankConfig, TissueConfig, TissueMaterial,
                                     estimated_particles, read_particles_csv)

MM = 1e-3


def tissue_parameters(material: TissueMaterial) -> TissueParameters:
    """The particle solver's tissue law (Eq. 13–16) of a scene's tissue material."""
    return TissueParameters(youngs_modulus_pa=material.youngs_modulus_pa, poisson_ratio=material.poisson_ratio,
                            volume_stiffness_pa=material.volume_stiffness_pa, beta1=material.beta1,
                            beta2=material.beta2, rate_floor_per_s=material.rate_floor_per_s,
                            hourglass=material.hourglass, corotated=material.corotated, mls_order=material.mls_order)


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
                          tissue=tissue_parameters(scene.tissue), coupling=coupling,
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
