"""Numba set-up shared by the particle kernels.

Numba's default OpenMP threading layer slowed several-fold here when the two
cores were shared with another process; the ``workqueue`` layer held up, so it
is chosen unless the user set ``NUMBA_THREADING_LAYER`` (docs/decisions.md).
It must be chosen before the first parallel kernel runs, hence this module is
imported first by :mod:`hifumotion.particles`.
"""

from __future__ import annotations

import os

import numba

if "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

# Phases (particle kinds); particles of one phase are stored contiguously.
FLUID = 0
TISSUE = 1
RIGID = 2
WALL = 3
PHASE_NAMES = ("fluid", "tissue", "rigid", "wall")
