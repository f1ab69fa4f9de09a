"""Numerical settings that several solvers' settings share, once (the physical ones are in
:mod:`hifumotion.physical`). Light: reading a setting imports no solver."""

from __future__ import annotations

#: Safety factor of the explicit step on its stability limit (the acoustic and elastic CFL
#: conditions): the particle solver's, a scene's ``[run]``, the twin's and the fitted model's default.
CFL = 0.4

__all__ = ["CFL"]
