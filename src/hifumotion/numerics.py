"""Numerical settings that several solvers' settings share, once (the physical ones are in
:mod:`hifumotion.physical`). Light: reading a setting imports no solver."""

from __future__ import annotations

#: Safety factor of the explicit step on its stability limit (the acoustic and elastic CFL
#: conditions): the particle solver's, a scene's ``[run]``, the twin's and the fitted model's default.
CFL = 0.4
#: Inertia multiplier of a dynamic explicit run (none) and its largest step (s): the particle
#: solver's and a scene's ``[run]`` defaults.
EXPLICIT_MASS_SCALING = 1.0
EXPLICIT_MAX_STEP_S = 1e-3
#: Kernel support radius h in particle spacings: the particle solver's, the twin's and the
#: fitted model's default.
SUPPORT_FACTOR = 2.0
#: Inertia multiplier of a quasi-static push on the explicit path (weights unchanged): the twin's
#: and the fitted model's (docs/decisions.md has the tolerance it keeps).
QUASI_STATIC_MASS_SCALING = 2.0e4
#: Largest step of a quasi-static push on the explicit path (s): the twin's and the fitted model's.
QUASI_STATIC_MAX_STEP_S = 5e-3
#: The small-strain finite-element truth: local error of a time step (mm).
TRUTH_TOLERANCE_MM = 0.002
#: The finite-strain truth: its largest backward-Euler step (s).
TRUTH_STEP_S = 0.05

__all__ = ["CFL", "EXPLICIT_MASS_SCALING", "EXPLICIT_MAX_STEP_S", "QUASI_STATIC_MASS_SCALING", "QUASI_STATIC_MAX_STEP_S", "SUPPORT_FACTOR",
           "TRUTH_STEP_S", "TRUTH_TOLERANCE_MM"]
