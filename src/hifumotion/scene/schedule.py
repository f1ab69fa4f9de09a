"""A bar's program over time: a force (N) or a travel (mm) through given points, held past both ends."""

from __future__ import annotations

from typing import Callable

import numpy as np

ForceSchedule = Callable[[float], float]


def piecewise_linear_schedule(times_s, values) -> ForceSchedule:
    """A schedule through ``(time s, value)`` points, held constant past both ends."""
    t = np.asarray(times_s, float)
    y = np.asarray(values, float)
    if t.ndim != 1 or t.shape != y.shape or len(t) == 0 or np.any(np.diff(t) < 0):
        raise ValueError("a schedule needs increasing times and as many values")
    return lambda time: float(np.interp(time, t, y))


__all__ = ["ForceSchedule", "piecewise_linear_schedule"]
