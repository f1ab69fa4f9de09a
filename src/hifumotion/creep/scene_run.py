"""Run a :class:`~hifumotion.scene.Scene` on the fast path.

The same scene file as the explicit path: its tank (the floor and the four walls are
:class:`~.contact.ContactPlane` s with the scene's friction), its water (buoyancy up to the
water line), its tissue (its particles, which must lie on a lattice, become voxels) and
its bar (a :class:`~.contact.Punch` with the scene's force schedule; a bar whose weight
is not supported adds its weight less its buoyancy to the push). Returns the explicit
path's :class:`~hifumotion.scene.SimulationResult`, so every consumer
(sections, the fit, the twin) takes either.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.creep.contact import ContactPlane, Punch
from hifumotion.creep.integrate import CreepMaterial, CreepResult, CreepSettings, CreepSolver, Surroundings
from hifumotion.creep.conform import conform
from hifumotion.creep.voxels import voxel_mesh
from hifumotion.scene import Scene
from hifumotion.scene.geometry import tissue_particles_mm, touching_tip
from hifumotion.scene import SimulationResult

MM = 1e-3


def scene_material(scene: Scene) -> CreepMaterial:
    t = scene.tissue
    return CreepMaterial(youngs_modulus_pa=t.youngs_modulus_pa, poisson_ratio=t.poisson_ratio, beta1=t.beta1,
                         beta2=t.beta2, density_kg_m3=t.density_kg_m3, rate_floor_per_s=t.rate_floor_per_s)


def tank_planes(scene: Scene) -> list[ContactPlane]:
    """The floor (y = 0) and the four side walls of the tank, with the scene's friction."""
    lx, _, lz = (s * MM for s in scene.tank.size_mm)
    mu = scene.physics.friction
    return [ContactPlane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), mu),
            ContactPlane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), mu), ContactPlane((lx, 0.0, 0.0), (-1.0, 0.0, 0.0), mu),
            ContactPlane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), mu), ContactPlane((0.0, 0.0, lz), (0.0, 0.0, -1.0), mu)]


def scene_punch(scene: Scene, tissue_mm: np.ndarray, spacing_mm: float) -> tuple[Punch | None, np.ndarray]:
    """The bar's end as a punch, and its unit axis; the tip on the scene's or touching the voxels."""
    bar = scene.bar
    axis = np.asarray(bar.direction, float)
    axis /= np.linalg.norm(axis)
    if not bar.enabled:
        return None, axis
    if bar.tip_mm is None:
        centre = tissue_mm.mean(0)
        # on the voxels' face: half a spacing out from the particles' centres
        tip = touching_tip(tissue_mm, centre, axis, bar.radius_mm, 0.5 * spacing_mm)
        tip = centre if tip is None else tip
    else:
        tip = np.asarray(bar.tip_mm, float)
    breaks = bar.breakpoints_s()
    if bar.control == "travel":
        # a driven bar: where it is, not what it weighs, is given (its guide carries the rest)
        travel_mm = bar.travel_schedule()
        return Punch(tuple(tip * MM), tuple(axis), bar.radius_mm * MM, lambda t: 0.0, scene.physics.friction, breaks,
                     travel_m=lambda t: float(travel_mm(t)) * MM, edge_radius_m=bar.edge_radius_mm * MM), axis
    schedule = bar.schedule()
    extra = 0.0
    if not bar.weight_supported:
        volume = math.pi * (bar.radius_mm * MM) ** 2 * bar.length_mm * MM
        wet = scene.tank.water_depth_mm > 0
        rho = bar.density_kg_m3 - (scene.physics.water_density_kg_m3 if wet else 0.0)
        extra = rho * volume * scene.physics.gravity_m_s2 * float(-axis[1])

    def force(t: float) -> float:
        return max(float(schedule(t)) + extra, 0.0)

    return Punch(tuple(tip * MM), tuple(axis), bar.radius_mm * MM, force, scene.physics.friction, breaks,
                 edge_radius_m=bar.edge_radius_mm * MM), axis


def tissue_surface(scene: Scene):
    """The true surface (``trimesh.Trimesh``, mm, tank frame) of an ellipsoid or box tissue; None otherwise."""
    import trimesh

    cfg = scene.tissue
    if cfg.shape == "particles":
        return None
    size = np.asarray(cfg.size_mm, float)
    centre = (np.array([scene.tank.size_mm[0] / 2, size[1] / 2, scene.tank.size_mm[2] / 2])
              if cfg.centre_mm is None else np.asarray(cfg.centre_mm, float))
    if cfg.shape == "ellipsoid":
        surface = trimesh.creation.icosphere(subdivisions=5)
        surface.apply_scale(size / 2)
    else:
        surface = trimesh.creation.box(extents=size)
    surface.apply_translation(centre)
    return surface


def tissue_mesh(scene: Scene, tissue_particles=None, surface=None):
    """The scene's tissue as a (conforming, where its surface is known) voxel mesh, and the particles' volumes (mm³)."""
    dx = scene.particles.spacing_mm
    if tissue_particles is None:
        tissue_mm, vol_mm3 = tissue_particles_mm(scene.tissue, scene.tank, dx)
        surface = tissue_surface(scene) if surface is None else surface
    else:
        tissue_mm, vol_mm3 = (np.asarray(a, float) for a in tissue_particles)
    mesh = voxel_mesh(tissue_mm, dx)
    if surface is not None:
        mesh = conform(mesh, surface)
    return mesh, vol_mm3


def creep_solver(scene: Scene, mesh, settings: CreepSettings | None = None) -> tuple[CreepSolver, np.ndarray]:
    """The fast path's solver of ``scene`` on the voxel mesh ``mesh`` (the tank's planes, the
    water's buoyancy, the bar as a punch), and the bar's unit axis."""
    punch, axis = scene_punch(scene, mesh.centres_mm, scene.particles.spacing_mm)
    water = scene.tank.water_depth_mm * MM if scene.tank.water_depth_mm > 0 else None
    surroundings = Surroundings((0.0, -scene.physics.gravity_m_s2, 0.0), scene.physics.water_density_kg_m3, water)
    return CreepSolver(mesh, scene_material(scene), surroundings, tank_planes(scene), punch, settings), axis


def output_times(scene: Scene) -> np.ndarray:
    """The scene's frame times (s): every output interval from 0 to the run's duration."""
    run = scene.run
    n_frames = int(math.floor(run.duration_s / run.output_interval_s + 1e-9)) + 1
    return np.arange(n_frames) * run.output_interval_s


def bar_centres(scene: Scene, punch, axis: np.ndarray, result: CreepResult) -> np.ndarray:
    """``(frames, 3)`` the bar's centre (mm) at each frame of ``result``; NaN without a bar."""
    if punch is None:
        return np.full((len(result.times_s), 3), np.nan)
    tip = np.asarray(punch.tip_m) / MM + result.stats["advance_at_rest_mm"] * axis
    return tip[None] + result.advance_mm[:, None] * axis[None] - 0.5 * scene.bar.length_mm * axis[None]


def simulation_result(scene: Scene, mesh, vol_mm3: np.ndarray, result: CreepResult, bar: np.ndarray,
                      integrator: str) -> SimulationResult:
    """A fast-path run as the explicit path's :class:`SimulationResult`, its facts named for ``integrator``."""
    dx = scene.particles.spacing_mm
    facts = {"spacing_mm": dx, "integrator": integrator, "nodes": mesh.n_nodes,
             "counts": {"tissue": len(mesh.centres_mm)}, "tissue_volume_mm3": float(vol_mm3.sum()),
             "bar_force_n": result.bar_force_n.tolist(), **{f"creep_{k}": v for k, v in result.stats.items()}}
    return SimulationResult(result.times_s, result.particles_mm, vol_mm3, bar, dx, int(result.stats["steps"]),
                            facts, None)


def simulate_creep(scene: Scene, folder: str | Path | None = None, progress: Callable[[float], None] | None = None,
                   tissue_particles: tuple[np.ndarray, np.ndarray] | None = None,
                   settings: CreepSettings | None = None, surface=None, mesh=None) -> SimulationResult:
    """Run ``scene`` on the fast path: settled state at t = 0, then the push (module docstring).

    ``surface`` (a closed ``trimesh.Trimesh``, mm) is the tissue's true surface, onto which
    the voxels' boundary nodes are moved (default: the scene's ellipsoid or box; none for
    particles from a CSV or memory); ``mesh`` a :class:`~.voxels.VoxelMesh` made before
    (a fit's many runs). ``folder``, if given and ``run.write_vtu``, receives the frames as VTU + PVD.
    """
    if mesh is None:
        mesh, vol_mm3 = tissue_mesh(scene, tissue_particles, surface)
    else:
        vol_mm3 = (np.asarray(tissue_particles[1], float) if tissue_particles is not None
                   else np.full(len(mesh.centres_mm), scene.particles.spacing_mm ** 3))
    sim, result = run_creep(scene, mesh, vol_mm3, settings, progress)
    if folder is not None and scene.run.write_vtu:
        from hifumotion.creep.output import write_frames

        write_frames(folder, sim, mesh, result, scene.run.vtu_every)
    return sim


def run_creep(scene: Scene, mesh, tissue_volume_mm3: np.ndarray, settings: CreepSettings | None = None,
              progress: Callable[[float], None] | None = None) -> tuple[SimulationResult, CreepResult]:
    """Run ``scene`` on the voxel mesh ``mesh``: the result as the explicit path's, and the
    solver's own :class:`~.integrate.CreepResult` (its nodes: a reduced model's snapshots)."""
    solver, axis = creep_solver(scene, mesh, settings)
    result = solver.run(output_times(scene), progress)
    sim = simulation_result(scene, mesh, np.asarray(tissue_volume_mm3, float), result,
                            bar_centres(scene, solver.punch, axis, result), "implicit")
    return sim, result


def snapshot_run(scene: Scene, mesh, tissue_volume_mm3: np.ndarray, creep: CreepSettings | None = None,
                 progress: Callable[[float], None] | None = None) -> CreepResult:
    """One full run of ``scene`` on the mesh ``mesh``, its nodes kept: a reduced model's snapshots
    (one such run is a task of its own: a model's several runs may go to several cores)."""
    return run_creep(scene, mesh, tissue_volume_mm3, creep, progress)[1]


__all__ = ["simulate_creep", "run_creep", "snapshot_run", "creep_solver", "output_times", "bar_centres", "simulation_result", "tissue_mesh", "tissue_surface", "tank_planes", "scene_punch", "scene_material"]
