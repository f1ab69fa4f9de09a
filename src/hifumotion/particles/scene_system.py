"""A :class:`~hifumotion.scene.Scene` as a particle system (Eq. 8–20): the tissue's, the water's,
the walls' and the bar's particles, in SI for the solver, and the solver's settings."""

from __future__ import annotations

import numpy as np

from hifumotion.errors import InputError
from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.solver import SolverSettings
from hifumotion.particles.system import CouplingParameters, FluidParameters, ParticleSystem, build_system, tank_walls
from hifumotion.resources import check_memory
from hifumotion.scene.config import BYTES_PER_PARTICLE, Scene, TissueMaterial, estimated_particles
from hifumotion.scene.geometry import bar_particles_mm, lattice, tissue_particles_mm

MM = 1e-3


def tissue_parameters(material: TissueMaterial) -> TissueParameters:
    """The particle solver's tissue law (Eq. 13–16) of a scene's tissue material."""
    return TissueParameters(youngs_modulus_pa=material.youngs_modulus_pa, poisson_ratio=material.poisson_ratio,
                            volume_stiffness_pa=material.volume_stiffness_pa, beta1=material.beta1,
                            beta2=material.beta2, rate_floor_per_s=material.rate_floor_per_s,
                            hourglass=material.hourglass, corotated=material.corotated, mls_order=material.mls_order)


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
