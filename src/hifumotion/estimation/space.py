"""The search space of the estimation: which parameters are fitted, in which coordinates.

A quasi-static push is (to first order) unchanged when the force, Young's modulus
and the viscosity β1 are scaled together: only F/E and β1/E show in the
displacement (gravity's small share breaks the symmetry only weakly). So the
fit holds the force at a nominal value ``force_n`` (the operator's estimate; the
paper's 0.25 N by default) and fits

=============  ==================  ===========================
coordinate     parameter           default bounds
=============  ==================  ===========================
``log_E``      ln E (Pa)           E in 1 kPa … 300 kPa
``nu``         ν                   0.30 … 0.495
``log_beta1``  ln β1 (Pa·s^1+β2)   β1 in 10² … 10⁸
``beta2``      β2                  0.1 … 1.0
``log_mu``     ln μ_f (friction)   μ_f in 0.02 … 1.0, when fitted
=============  ==================  ===========================

The friction of the floor and the bar's face is a coordinate only when the space is given its
bounds (``friction``): a driven bar's slide is set by it — with a force-held bar the
push hardly slides the sample, and it stays the model's setting.

The reported E and β1 are then "at the nominal force": what the data determine are
F/E and β1/E, and :func:`~hifumotion.estimation.fit.degeneracy` shows it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hifumotion.estimation.model import Parameters

NAMES = ("log_E", "nu", "log_beta1", "beta2")
#: Finite-difference steps of the Jacobian in each coordinate (5 % of E and β1).
STEPS = np.array([0.05, 0.01, 0.05, 0.05])
#: The friction's coordinate, its step (5 % of μ_f) and the bounds of μ_f, when it is fitted.
FRICTION_NAME, FRICTION_STEP, FRICTION_BOUNDS = "log_mu", 0.05, (0.02, 1.0)


@dataclass(frozen=True)
class SearchSpace:
    force_n: float = 0.25
    youngs_pa: tuple[float, float] = (1e3, 3e5)
    poisson: tuple[float, float] = (0.30, 0.495)
    beta1: tuple[float, float] = (1e2, 1e8)
    beta2: tuple[float, float] = (0.1, 1.0)
    friction: tuple[float, float] | None = None   # μ_f's bounds when it is fitted; None: not a coordinate

    @property
    def names(self) -> tuple[str, ...]:
        """The coordinates, in order."""
        return NAMES + ((FRICTION_NAME,) if self.friction else ())

    @property
    def steps(self) -> np.ndarray:
        """Each coordinate's finite-difference step."""
        return np.append(STEPS, [FRICTION_STEP] if self.friction else [])

    @property
    def lower(self) -> np.ndarray:
        return np.array([np.log(self.youngs_pa[0]), self.poisson[0], np.log(self.beta1[0]), self.beta2[0]]
                        + ([np.log(self.friction[0])] if self.friction else []))

    @property
    def upper(self) -> np.ndarray:
        return np.array([np.log(self.youngs_pa[1]), self.poisson[1], np.log(self.beta1[1]), self.beta2[1]]
                        + ([np.log(self.friction[1])] if self.friction else []))

    def index(self, name: str) -> int:
        """The position of coordinate ``name`` in θ (:attr:`names`)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"{name!r} is not a coordinate of this space ({', '.join(self.names)})") from None

    def with_value(self, theta, name: str, value: float) -> np.ndarray:
        """A copy of ``theta`` with coordinate ``name`` set to ``value``."""
        out = np.array(theta, float)
        out[self.index(name)] = value
        return out

    def parameters(self, theta) -> Parameters:
        t = dict(zip(self.names, np.clip(np.asarray(theta, float), self.lower, self.upper)))
        return Parameters(force_n=self.force_n, youngs_modulus_pa=float(np.exp(t["log_E"])),
                          poisson_ratio=float(t["nu"]), beta1=float(np.exp(t["log_beta1"])), beta2=float(t["beta2"]),
                          friction=float(np.exp(t[FRICTION_NAME])) if self.friction else None)

    def theta(self, k: Parameters) -> np.ndarray:
        base = [np.log(k.youngs_modulus_pa), k.poisson_ratio, np.log(k.beta1), k.beta2]
        if self.friction:
            if k.friction is None:
                raise ValueError("the space fits the friction: the parameters must carry one")
            base.append(np.log(k.friction))
        return np.array(base)

    def friction_within(self, theta, factor: float) -> "SearchSpace":
        """This space with μ_f kept within ``factor`` of ``theta``'s (and within its own bounds):
        the trust region of a reduced model made at ``theta`` (its friction's modes hold near it);
        a space without the friction is returned as it is."""
        if not self.friction:
            return self
        i = self.index(FRICTION_NAME)
        mu = float(np.exp(np.clip(theta[i], self.lower[i], self.upper[i])))
        return replace(self, friction=(max(self.friction[0], mu / factor), min(self.friction[1], mu * factor)))

    def initial_design(self) -> list[np.ndarray]:
        """A small spread of starts (E × β1 at mid ν, β2), data-free: the best one seeds the search."""
        lo, hi = self.lower, self.upper
        out = []
        for fe in (0.25, 0.5, 0.75):
            for fb in (0.35, 0.65):
                start = [lo[0] + fe * (hi[0] - lo[0]), 0.45, lo[2] + fb * (hi[2] - lo[2]), 0.5]
                if not self.friction:
                    out.append(np.array(start))
                    continue
                # the friction decides whether a driven sample slides at all: two levels of it
                for fm in (0.35, 0.65):
                    i = self.index(FRICTION_NAME)
                    out.append(np.array(start + [lo[i] + fm * (hi[i] - lo[i])]))
        return out


__all__ = ["SearchSpace", "NAMES", "STEPS", "FRICTION_NAME", "FRICTION_STEP", "FRICTION_BOUNDS"]
