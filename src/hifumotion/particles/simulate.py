"""Run a scene from start to output: build → settle → push → frames.

1. :func:`~hifumotion.particles.scene_system.build_scene` places water, tissue, bar and walls;
2. settling: ``run.settle_s`` of damped motion under gravity with the bar held,
   so the water finds its hydrostatic pressure and the tissue rests on the floor;
3. the clock is reset to t = 0, the bar released and pushed by its force schedule;
4. every ``run.output_interval_s`` a frame is recorded (tissue positions in mm,
   bar pose) and, if asked, written as VTU (+ PVD index, bar pose CSV).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.particles.output import FrameWriter
from hifumotion.particles.scene_system import build_scene, solver_settings
from hifumotion.scene import Scene, SimulationResult
from hifumotion.particles.solver import Solver


def simulate(scene: Scene, folder: str | Path | None = None,
             progress: Callable[[float], None] | None = None,
             tissue_particles: tuple[np.ndarray, np.ndarray] | None = None) -> SimulationResult:
    """Run ``scene``; write VTU/PVD/CSV into ``folder`` (if given and ``run.write_vtu``).

    ``progress(fraction)`` is called after every frame; ``tissue_particles`` as in
    :func:`~hifumotion.particles.scene_system.build_scene`.
    """
    system, facts = build_scene(scene, tissue_particles)
    run = scene.run
    if run.settle_s > 0:
        held = [(b, b.fixed) for b in system.bodies]
        for b in system.bodies:
            b.fixed = True
        Solver(system, solver_settings(scene, settling=True)).run(run.settle_s)
        for b, was in held:
            b.fixed = was
        n = system.n_moving
        system.v[:n] = 0.0
        for b in system.bodies:
            b.velocity_m_s = np.zeros(3)
            b.angular_momentum = np.zeros(3)
    system.time_s = 0.0
    settled_steps = system.step
    solver = Solver(system, solver_settings(scene))
    writer = FrameWriter(folder, system) if folder is not None and run.write_vtu else None
    times, tissue, bar = [], [], []
    n_frames = int(math.floor(run.duration_s / run.output_interval_s + 1e-9)) + 1

    def record(_solver=None):
        times.append(system.time_s)
        tissue.append(system.x[system.tissue_slice] * 1000.0)
        bar.append(system.bodies[0].centre_m * 1000.0 if system.bodies else np.full(3, np.nan))
        if writer is not None and (len(times) - 1) % run.vtu_every == 0:
            writer.write(system, solver.pressure)
        if progress is not None:
            progress(len(times) / n_frames)

    record()
    solver.run((n_frames - 1) * run.output_interval_s, callback=record, every_s=run.output_interval_s)
    facts["settling_steps"] = settled_steps
    facts["excluded_water_particles"] = solver.excluded_water
    return SimulationResult(np.asarray(times), np.asarray(tissue),
                            system.rest_volume[system.tissue_slice] * 1e9, np.asarray(bar),
                            scene.particles.spacing_mm, system.step - settled_steps, facts, system)
