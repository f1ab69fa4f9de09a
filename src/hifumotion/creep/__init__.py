"""The fast path: the tissue's quasi-static creep, integrated implicitly with contacts as constraints.

The explicit particle framework (:mod:`hifumotion.particles`) keeps the paper's dynamics
(Eq. 8–20: SPH water, penalty contacts, explicit steps of microseconds). This package
solves the same tissue — its particles as the voxels of a hexahedral mesh
(:mod:`.voxels`), small-strain elasticity and Eq. 16's rheological viscosity as a
Kelvin–Voigt stress (:mod:`.hexahedra`) — by backward Euler with steps of the frame
interval or longer (:mod:`.integrate`), the floor, the tank walls and the bar's end as
rigid constraints with Coulomb friction (:mod:`.contact`). :func:`~.scene.simulate_creep`
runs a :class:`~hifumotion.particles.scene.Scene` with it.
"""

from hifumotion.creep.contact import Plane, Punch
from hifumotion.creep.integrate import CreepMaterial, CreepResult, CreepSettings, CreepSolver, Surroundings
from hifumotion.creep.voxels import VoxelMesh, voxel_mesh

__all__ = ["Plane", "Punch", "CreepMaterial", "CreepResult", "CreepSettings", "CreepSolver", "Surroundings",
           "VoxelMesh", "voxel_mesh"]
