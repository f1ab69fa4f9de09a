"""The twin's truth by finite elements: the sample's creep under the bar (:mod:`hifumotion.reference.creep_fe`,
or at finite strain :mod:`hifumotion.reference.finite_strain_push`, ``truth.solver``).

The fitted model is the voxel fast path (:mod:`hifumotion.creep`); the truth must not share
its errors, so it comes from a solver that shares only the physics (module docstring of
:mod:`~hifumotion.reference.creep_fe`). Its displacement field is sampled at the truth's
lattice (``resolution.truth_particle_factor`` × the model's particles), which carries the
speckle and maps the exact rest shape into every frame, as the particle truth did.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.errors import InputError
from hifumotion.experiment.blob import Blob
from hifumotion.scene import SimulationResult
from hifumotion.reference.creep_fe import CreepFESettings, CreepFESolution, CreepingTissue, creep_reference


def bar_schedule(bar) -> tuple[Callable[[float], float], tuple[float, ...]]:
    """The bar's push F(t) (N) and its breakpoints (s); no push for a driven bar (its travel is given)."""
    if bar.control == "travel":
        return (lambda t: 0.0), bar.breakpoints_s()
    schedule = bar.schedule()
    return (lambda t: max(float(schedule(t)), 0.0)), bar.breakpoints_s()


def fe_problem(cfg, blob: Blob, placement_mm: np.ndarray) -> tuple[CreepingTissue, np.ndarray]:
    """The sample of ``cfg`` on the floor of its tank; returns the problem and the surface's
    lift (mm) that put its lowest point on the floor (its coarse surface's cut sits within
    a fraction of the fine one's)."""
    surface = blob.star_surface(cfg.truth.surface_subdivisions)
    vertices = np.asarray(surface.vertices, float) + placement_mm
    lift = np.array([0.0, -vertices[:, 1].min(), 0.0])
    vertices = vertices + lift
    axis = np.asarray(cfg.bar.direction, float)
    axis /= np.linalg.norm(axis)
    if cfg.bar.tip_mm is not None:
        tip = np.asarray(cfg.bar.tip_mm, float)
    else:
        # on the axis through the sample's centre, outside it: the face comes down to rest on it
        centre = 0.5 * (vertices.min(0) + vertices.max(0))
        tip = centre - axis * (np.ptp(vertices, axis=0).max() + cfg.bar.radius_mm)
    force, breaks = bar_schedule(cfg.bar)
    travel = None
    if cfg.bar.control == "travel":
        travel_mm = cfg.bar.travel_schedule()
        travel = lambda t: float(travel_mm(t))  # noqa: E731
    elif not cfg.bar.weight_supported:
        volume = math.pi * (cfg.bar.radius_mm * 1e-3) ** 2 * cfg.bar.length_mm * 1e-3
        wet = cfg.tank.water_depth_mm > 0
        rho = cfg.bar.density_kg_m3 - (cfg.physics.water_density_kg_m3 if wet else 0.0)
        extra = rho * volume * cfg.physics.gravity_m_s2 * float(-axis[1])
        push = force
        force = lambda t: max(push(t) + extra, 0.0)  # noqa: E731
    t = cfg.tissue
    problem = CreepingTissue(
        vertices, np.asarray(surface.faces, np.int64), t.youngs_modulus_pa, t.poisson_ratio, t.beta1, t.beta2,
        t.rate_floor_per_s, tuple(tip), tuple(axis), cfg.bar.radius_mm, force, breaks,
        density_kg_m3=t.density_kg_m3, water_density_kg_m3=cfg.physics.water_density_kg_m3,
        water_line_mm=cfg.tank.water_depth_mm if cfg.tank.water_depth_mm > 0 else None,
        gravity_m_s2=cfg.physics.gravity_m_s2, floor_friction=cfg.physics.friction,
        bar_friction=cfg.physics.friction, max_volume_mm3=cfg.truth.max_volume_mm3, travel_mm=travel,
        edge_radius_mm=cfg.bar.edge_radius_mm)
    return problem, lift


#: the largest penetration of a contact a twin may have, as a fraction of the particle spacing
PENETRATION_OF_SPACING = 0.01


def physicality(stats: dict, spacing_mm: float) -> dict:
    """A finite-strain truth's checks: no inverted element (J > 0 at every
    quadrature point of every frame), no tissue node inside the floor or the bar (its face, rim
    or side) by more than ``PENETRATION_OF_SPACING`` of the particle spacing, and the largest
    strain the law was held to."""
    penetration = max(stats["floor_penetration_mm"], stats["face_penetration_mm"])
    return {"smallest_jacobian": stats["smallest_jacobian"], "inverted_elements": bool(stats["smallest_jacobian"] <= 0.0),
            "largest_strain": stats["largest_strain"], "largest_penetration_mm": penetration,
            "penetration_within_limit": bool(penetration <= PENETRATION_OF_SPACING * spacing_mm)}


def simulate_fe_truth(cfg, blob: Blob, lattice_mm: np.ndarray, spacing_mm: float, placement_mm: np.ndarray,
                      folder: str | Path | None = None, progress: Callable[[float], None] | None = None
                      ) -> tuple[SimulationResult, CreepFESolution]:
    """Run the sample's push by finite elements; the lattice ``lattice_mm`` (rest, tank frame)
    moved by it frame by frame, as a :class:`~hifumotion.scene.SimulationResult`."""
    problem, lift = fe_problem(cfg, blob, placement_mm)
    im = cfg.imaging
    times = np.arange(im.frames) / im.frame_rate_hz
    physical = None
    if cfg.truth.solver == "finite_strain":
        from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

        solution = finite_strain_reference(problem, times, FiniteStrainSettings(step_s=cfg.truth.step_s), progress)
        kind = "finite_strain (P2 tetrahedra on FElupe: neo-Hooke, Eq. 16 viscosity, backward Euler, Coulomb contacts)"
        physical = physicality(solution.stats, spacing_mm)
        if physical["inverted_elements"]:
            driven = cfg.bar.control == "travel"
            raise InputError(f"the push inverts the tissue (smallest volume ratio J = "
                             f"{physical['smallest_jacobian']:.3g}): lower the bar's {'travel' if driven else 'force'}",
                             "bar.travel_mm" if driven else "bar.force_n")
    else:
        solution = creep_reference(problem, times, CreepFESettings(tolerance_mm=cfg.truth.tolerance_mm), progress)
        kind = "finite_elements (P2 tetrahedra, BDF2, Coulomb contacts)"
    # the lattice rides with the sample's rest shape: lifted as its surface was
    displacement = solution.displacement_at(lattice_mm + lift)
    positions = lattice_mm[None] + lift + displacement
    axis = np.asarray(problem.axis, float)
    face0 = np.asarray(problem.tip_mm) + solution.stats["advance_at_rest_mm"] * axis
    if cfg.bar.enabled:
        face = face0[None] + solution.advance_mm[:, None] * axis[None]
        bar_centre = face - 0.5 * cfg.bar.length_mm * axis[None]
    else:
        bar_centre = np.full((len(times), 3), np.nan)
    facts = {"truth_solver": kind,
             "bar_axis": axis.tolist(), "bar_tip_mm": face0.tolist(), "spacing_mm": spacing_mm,
             "counts": {"tissue": int(len(lattice_mm))}, "bar_force_n": solution.force_n.tolist(),
             **{f"fe_{k}": v for k, v in solution.stats.items()}}
    if physical is not None:
        facts["physicality"] = physical
    sim = SimulationResult(times, positions, np.full(len(lattice_mm), spacing_mm ** 3), bar_centre, spacing_mm,
                           int(solution.stats["steps"]), facts, None)
    if folder is not None:
        write_fe_frames(Path(folder), solution, cfg.run.particle_frames_every)
    return sim, solution


def write_fe_frames(folder: Path, solution: CreepFESolution, every: int) -> Path:
    """``finite_elements/fe_0000.vtu`` … (the ten-node tetrahedra moved, point data
    ``displacement_mm``) and ``finite_elements.pvd``, for ParaView."""
    import meshio

    from hifumotion.io.files import atomic_path
    from hifumotion.particles.output import write_pvd

    (folder / "finite_elements").mkdir(parents=True, exist_ok=True)
    p2 = solution.p2
    cells = p2.tetra10_cells()
    rest_mm = p2.points_m * 1e3
    entries = []
    for k in range(0, len(solution.times_s), every):
        u = solution.displacement_m[k][p2.dof_xyz] * 1e3
        grid = meshio.Mesh(rest_mm + u, [("tetra10", cells)], point_data={"displacement_mm": u})
        path = folder / "finite_elements" / f"fe_{k:04d}.vtu"
        with atomic_path(path) as tmp:
            meshio.write(tmp, grid, file_format="vtu", binary=True)
        entries.append((float(solution.times_s[k]), path.relative_to(folder)))
    return write_pvd(folder / "finite_elements.pvd", entries)
