"""The fitted model's numerical settings, as plain data (no solver imported).

:class:`ModelSettings` holds every setting of a forward run that is not fitted: the
resolution, the integrator and each integrator's own settings (the fast path's
:class:`~hifumotion.creep.settings.CreepSettings`, its reduced model's
:class:`~hifumotion.creep.settings.ReducedSettings`, the explicit path's fields). A run's
configuration reaches it as ``[estimation.model]`` (and ``--set model.creep.tolerance=…``),
validated by the annotations; its defaults live here only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from annotated_types import Ge, Gt, Le

from hifumotion import paper
from hifumotion.creep.settings import CreepSettings, ReducedSettings
from hifumotion.errors import InputError

#: The forward models (``estimation.model.FORWARD_MODELS``), by ``ModelSettings.integrator``.
INTEGRATORS = ("implicit", "explicit", "reduced")


@dataclass
class ModelSettings:
    """Numerical settings of the fitted model (not fitted themselves)."""

    tissue_particles: Annotated[int, Ge(100), Le(1_000_000)] = paper.TISSUE_PARTICLES  # the paper's count
    support_factor: Annotated[float, Ge(1.5), Le(3.0)] = 2.0   # kernel support h in spacings
    mass_scaling: Annotated[float, Ge(1.0)] = 2.0e4    # inertia multiplier of the quasi-static push
    settle_periods: Annotated[float, Gt(0)] = 6.0      # settling time in 1/ω of the slowest elastic mode
    cfl: Annotated[float, Gt(0), Le(1.0)] = 0.4        # safety factor on the time step
    max_step_s: Annotated[float, Gt(0)] = 5e-3         # largest time step (s)
    force_ramp_s: Annotated[float, Ge(0)] | None = None  # the force's linear rise (s); default: setup.json's push.ramp_s
    tissue_density_kg_m3: Annotated[float, Gt(0)] = 1050.0
    rate_floor_per_s: Annotated[float, Gt(0)] = 0.02   # floor of the shear rate in Eq. 16's μ (1/s); a regularisation, not fitted
    contour_points: Annotated[int, Ge(8), Le(10_000)] = 64   # size of the point set A
    integrator: Literal["implicit", "explicit", "reduced"] = "implicit"  # one of INTEGRATORS: "implicit", the fast path (hifumotion.creep);
                                        # "explicit", Eq. 8–20 as the paper; "reduced", the fast path's
                                        # POD–Galerkin model (hifumotion.creep.reduced)
    reduced_span: tuple[float, float] = (0.5, 2.0)   # F/E multiples of the full runs the reduced model's modes come from
    creep: CreepSettings = field(default_factory=CreepSettings)        # the implicit path's (and the snapshots')
    reduced: ReducedSettings = field(default_factory=ReducedSettings)  # the reduced model's

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise InputError(f"unknown integrator {self.integrator!r}; expected {', '.join(INTEGRATORS)}",
                             "integrator")
        # from parameters.json: the nested settings arrive as dicts
        for name, kind in (("creep", CreepSettings), ("reduced", ReducedSettings)):
            value = getattr(self, name)
            if isinstance(value, dict):
                unknown = sorted(set(value) - set(kind.__dataclass_fields__))
                if unknown:
                    raise InputError(f"unknown settings {unknown}; expected some of "
                                     f"{sorted(kind.__dataclass_fields__)}", f"model_settings.{name}")
                setattr(self, name, kind(**value))
            elif not isinstance(value, kind):
                raise InputError(f"expected {kind.__name__}, got {type(value).__name__}", f"model_settings.{name}")
        span = tuple(float(x) for x in self.reduced_span)
        if len(span) != 2 or not (0 < span[0] < span[1] and np.isfinite(span[1])):
            raise InputError(f"expected two F/E multiples 0 < low < high, got {self.reduced_span}", "reduced_span")
        self.reduced_span = span


__all__ = ["INTEGRATORS", "ModelSettings"]
