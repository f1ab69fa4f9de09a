"""The versatile particle framework (Section 2.2.1, Eq. 8–20): water, tissue, bar, tank.

SI units inside (m, kg, s, Pa, N). Modules: :mod:`.kernels` (cubic spline),
:mod:`.neighbours` (cell lists), :mod:`.fluid` (SPH water and coupling),
:mod:`.elastic` (tissue), :mod:`.rigid` (bar), :mod:`.system` (state),
:mod:`.solver` (time stepping).
"""

from hifumotion.particles._numba import FLUID, RIGID, TISSUE, WALL
from hifumotion.particles.elastic import TissueParameters
from hifumotion.particles.rigid import RigidBody
from hifumotion.particles.solver import SimulationDiverged, Solver, SolverSettings
from hifumotion.particles.system import (CouplingParameters, FluidParameters, ParticleSystem,
                                         build_system, lattice, tank_walls)

__all__ = [
    "FLUID", "TISSUE", "RIGID", "WALL",
    "TissueParameters", "FluidParameters", "CouplingParameters",
    "RigidBody",
    "ParticleSystem", "build_system", "lattice", "tank_walls",
    "Solver", "SolverSettings", "SimulationDiverged",
]
