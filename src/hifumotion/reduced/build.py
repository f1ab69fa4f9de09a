"""The reduced model made from full runs of a scene, and a scene run on it.

:func:`reduced_creep` runs the full model (:func:`~hifumotion.creep.scene_run.snapshot_run`) at a few
scenes and keeps the motion's modes (:func:`~.model.pod_basis`); :func:`reduced_from_runs` does
the same from runs made elsewhere (on a cluster's cores); :func:`simulate_reduced` runs a
scene's material, force or travel and friction on the model and returns the full path's
:class:`~hifumotion.scene.SimulationResult`, so every consumer takes either.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from hifumotion.creep.integrate import CreepResult
from hifumotion.creep.scene_run import (bar_centres, creep_solver, output_times, scene_material, scene_punch,
                                    simulation_result, snapshot_run)
from hifumotion.creep.settings import CreepSettings
from hifumotion.scene import Scene
from hifumotion.scene import SimulationResult
from hifumotion.reduced.model import ReducedCreep, ReducedSettings, pod_basis


def reduced_from_runs(scene: Scene, mesh, runs: list[CreepResult], settings=None,
                      creep: CreepSettings | None = None):
    """A :class:`~.model.ReducedCreep` of ``mesh`` whose modes are the motion of the full
    ``runs`` (:func:`~hifumotion.creep.scene_run.snapshot_run`; the first one's settled state is the model's), its
    matrices those of ``scene``'s solver (``creep``, its settings)."""
    settings = settings or ReducedSettings()
    solver, _ = creep_solver(scene, mesh, creep)
    return ReducedCreep(solver, pod_basis(runs, settings.energy, settings.max_modes), settings)


def reduced_creep(scenes: list[Scene], mesh, tissue_volume_mm3: np.ndarray, settings=None,
                  progress: Callable[[float], None] | None = None, creep: CreepSettings | None = None):
    """A :class:`~.model.ReducedCreep` of the voxel mesh ``mesh`` whose modes are the motion of
    full runs of ``scenes`` (the same tissue; other materials, forces; ``creep``, their settings),
    run one after the other here: its construction."""
    runs = []
    for i, scene in enumerate(scenes):
        tell = None if progress is None else (lambda f, i=i: progress((i + f) / len(scenes)))
        runs.append(snapshot_run(scene, mesh, tissue_volume_mm3, creep, tell))
    return reduced_from_runs(scenes[0], mesh, runs, settings, creep)


def simulate_reduced(scene: Scene, reduced, tissue_volume_mm3: np.ndarray,
                     progress: Callable[[float], None] | None = None) -> SimulationResult:
    """Run ``scene`` on the reduced model ``reduced`` (:func:`reduced_creep`, made for this
    scene's tissue and mesh): its material, its bar's force schedule and its friction; the
    result as :func:`simulate_creep`'s."""
    mesh = reduced.mesh
    punch, axis = scene_punch(scene, mesh.centres_mm, scene.particles.spacing_mm)
    force, breaks = (punch.force_n, punch.breakpoints_s) if punch is not None else ((lambda t: 0.0), ())
    travel = punch.travel_m if punch is not None else None
    result = reduced.run(scene_material(scene), force, breaks, output_times(scene), progress,
                         travel_m=travel, friction=scene.physics.friction)
    return simulation_result(scene, mesh, np.asarray(tissue_volume_mm3, float), result,
                             bar_centres(scene, punch, axis, result), "reduced")


__all__ = ["reduced_creep", "reduced_from_runs", "simulate_reduced"]
