"""The fast path: the tissue's quasi-static creep, integrated implicitly with contacts as constraints.

The explicit particle framework (:mod:`hifumotion.particles`) keeps the paper's dynamics
(Eq. 8–20: SPH water, penalty contacts, explicit steps of microseconds). This package
solves the same tissue — its particles as the voxels of a hexahedral mesh
(:mod:`.voxels`), small-strain elasticity and Eq. 16's rheological viscosity as a
Kelvin–Voigt stress (:mod:`.hexahedra`) — by backward Euler with steps of the frame
interval or longer (:mod:`.integrate`), the floor, the tank walls and the bar's end as
rigid constraints with Coulomb friction (:mod:`.contact`). :func:`~.scene.simulate_creep`
runs a :class:`~hifumotion.scene.Scene` with it.
"""

from hifumotion._lazy import lazy_exports

# names → the module that defines them, imported on first use: the solvers pull Numba, SciPy
# and PARDISO, which a command that only reads the settings (``--help``, a configuration's
# validation) should not pay for
_WHERE = {"ContactPlane": "contact", "Punch": "contact", "CreepMaterial": "integrate", "CreepResult": "integrate",
          "CreepSolver": "integrate", "Surroundings": "integrate", "CreepSettings": "settings",
          "ReducedSettings": "settings", "VoxelMesh": "voxels", "voxel_mesh": "voxels"}


__getattr__ = lazy_exports(__name__, _WHERE)
__all__ = sorted(_WHERE)
