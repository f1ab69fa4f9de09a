"""Numba set-up shared by the particle kernels, and the phase codes.

Threading: Numba's default layer (OpenMP where present) is kept. Measured on the
paper-sized scene (2 cores, benchmarks/bench_particles.py): alone, OpenMP ran
115–125 steps/s and the ``workqueue`` layer 82–84; with two simulations at once,
OpenMP fell to 28 steps/s each and workqueue held 50. So a single run uses both
cores with OpenMP, and work that runs several simulations side by side (Dask
workers, pytest-xdist) gives each process one thread (``NUMBA_NUM_THREADS=1``),
which is also the fastest way to run independent simulations. A user can still
choose with ``NUMBA_THREADING_LAYER`` (docs/decisions.md).
"""

from __future__ import annotations

# Phases (particle kinds); particles of one phase are stored contiguously.
FLUID = 0
TISSUE = 1
RIGID = 2
WALL = 3
PHASE_NAMES = ("fluid", "tissue", "rigid", "wall")
