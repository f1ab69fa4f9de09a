"""The experiment as data, shared by every path: the scene (tank, tissue, bar, physics, run;
:mod:`.config`), its solids as points (:mod:`.geometry`), the bar's program (:mod:`.schedule`),
what a forward run produced (:mod:`.result`) and an imaging plane (:mod:`.plane`). Light:
importing it loads no solver; the particle path (:mod:`hifumotion.particles`), the fast path
(:mod:`hifumotion.creep`) and the truths (:mod:`hifumotion.reference`) build on it.
"""

from hifumotion.scene.config import (BYTES_PER_PARTICLE, MAX_FORCE_N, BarConfig, ParticleConfig, PhysicsConfig,
                                     RunConfig, Scene, TankConfig, TissueConfig, TissueMaterial, estimated_particles,
                                     load_scene, read_particles_csv)
from hifumotion.scene.plane import Plane
from hifumotion.scene.result import SimulationResult
from hifumotion.scene.schedule import ForceSchedule, piecewise_linear_schedule

__all__ = ["BYTES_PER_PARTICLE", "MAX_FORCE_N", "BarConfig", "ForceSchedule", "ParticleConfig", "PhysicsConfig",
           "Plane", "RunConfig", "Scene", "SimulationResult", "TankConfig", "TissueConfig", "TissueMaterial",
           "estimated_particles", "load_scene", "piecewise_linear_schedule", "read_particles_csv"]
