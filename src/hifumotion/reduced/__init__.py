"""The reduced model: a POD–Galerkin reduction of the fast path (:mod:`hifumotion.creep`).

Its modes are the motion of a few full runs around a parameter set (:mod:`.build`:
:func:`~.build.reduced_creep`, :func:`~.build.reduced_from_runs`); :class:`~.model.ReducedCreep`
steps the creep in them, with the contacts' non-penetration held through the modes, Coulomb's
friction on the contact candidates (:mod:`.friction`), the bar's rows (:mod:`.bar_rows`),
Eq. 16's viscosity on ECSW's sampled voxels (:mod:`.hyper`), a corotational mesh's turned
elastic force (:mod:`.corotated_force`) and the contact solve's warm-started NNLS
(:mod:`.nnls`). :func:`~.build.simulate_reduced` runs a scene on it. The calibration's search,
the online filter and the prediction's band run it (``ModelSettings.integrator = "reduced"``).
"""

from hifumotion._lazy import lazy_exports

# names → the module that defines them, imported on first use (the model pulls Numba and SciPy)
_WHERE = {"ReducedCreep": "model", "ReducedBasis": "model", "pod_basis": "model",
          "reduced_creep": "build", "reduced_from_runs": "build", "simulate_reduced": "build"}


__getattr__ = lazy_exports(__name__, _WHERE)
__all__ = sorted(_WHERE)
