"""Whether the fitted model is resolved: the fit run again on twice the particles.

A fit can do no better than its model. Where the model's lattice is too coarse for the
sample under its bar, the fit makes up for the discretisation with wrong parameters. The
training frames cannot show that, since the fit matches them either way. On the slide
slide_stop_s50 the 1,000-particle model at the true parameters missed the validation frames by
0.47 mm and the 4,399-particle one by 0.10 mm. The fit's points A moved up to 0.54 mm apart
between 1,000 and 2,000 particles, against 0.22–0.24 mm on three slides the 1,000-particle model
does resolve (docs/decisions.md, "A resolution check on the fit").

:func:`resolution_check` runs the fitted model at the fit on the model's lattice and on one with
``factor`` times the particles (a convergence check on the mesh, as any finite-element study
makes). It compares the points A's motion frame by frame. A model whose own discretisation moves
the points by more than a pixel of the frames it was fitted to cannot be fitted to pixel accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hifumotion.estimation.model import ModelSpec, Parameters, model_spec, run_model
from hifumotion.estimation.objective import TrainingData, residuals_mm


@dataclass(frozen=True)
class ResolutionCheck:
    """The fit on two lattices: ``particles`` and ``spacing_mm`` of each (the model's first),
    ``difference_mm`` the RMS over the points A of the difference of their displacements since
    frame 0, at each of frames 0 … ``last_frame``, and the frames' ``pixel_mm``."""

    particles: tuple[int, int]
    spacing_mm: tuple[float, float]
    difference_mm: np.ndarray
    pixel_mm: float
    last_frame: int
    #: coordinate → how far the finer model's fit lies from this one (a Gauss–Newton step on the
    #: finer model's training residuals at the fit); None where no training data were given
    parameter_shift: dict | None = None
    #: where the first finer lattice moved the points by more than a pixel and a second, finer again,
    #: was run to decide: the first's particles and largest difference (mm); the check is the second's
    overruled: dict | None = None

    @property
    def largest_mm(self) -> float:
        """The largest difference over the frames (mm)."""
        return float(np.max(self.difference_mm, initial=0.0))

    @property
    def resolved(self) -> bool:
        """Whether the finer lattice moves the points A by at most a pixel at every frame."""
        return self.largest_mm <= self.pixel_mm

    def as_dict(self) -> dict:
        return {"particles": list(self.particles), "spacing_mm": list(self.spacing_mm),
                "last_frame": self.last_frame, "difference_mm": np.round(self.difference_mm, 4).tolist(),
                "largest_mm": self.largest_mm, "pixel_mm": self.pixel_mm, "resolved": self.resolved,
                "parameter_shift": self.parameter_shift, "overruled": self.overruled}

    def with_numerical_error(self, std: dict) -> dict:
        """Each coordinate's standard error ``std`` with the model's numerical error added in
        quadrature, ``√(σ² + Δ²)``, Δ its :attr:`parameter_shift` (the validation uncertainty of
        ASME V&V 20, u² = u_input² + u_num²: the data's error and the discretisation's, independent);
        ``std`` unchanged where there is no shift."""
        shift = self.parameter_shift or {}
        return {n: float(np.hypot(sd, shift[n])) if n in shift and np.isfinite(shift[n]) else float(sd)
                for n, sd in std.items()}


def displacement_difference_mm(points_a_mm: np.ndarray, points_b_mm: np.ndarray) -> np.ndarray:
    """``(F,)`` the RMS over the points of the difference between two runs' displacements since
    their own frame 0 (mm), from two ``(F, M, 3)`` trajectories of the same points (mm)."""
    a, b = (np.asarray(p, float) for p in (points_a_mm, points_b_mm))
    if a.shape != b.shape or a.ndim != 3:
        raise ValueError(f"two (F, M, 3) trajectories of the same points expected, got {a.shape} and {b.shape}")
    d = (a - a[:1]) - (b - b[:1])
    return np.sqrt((d ** 2).sum(axis=-1).mean(axis=-1))


def parameter_shift(jacobian: np.ndarray, residuals_mm_here: np.ndarray, residuals_mm_there: np.ndarray) -> np.ndarray:
    """``(p,)`` the Gauss–Newton step from a fit to where another model's residuals would put it:
    ``−(JᵀJ)⁻¹ Jᵀ (r_there − r_here)`` (at a least-squares fit ``Jᵀ r_here`` vanishes, so the step
    on the other model's residuals is the step on their difference). ``jacobian`` ``(N, p)`` of the
    residuals (mm per coordinate unit), both residuals of ``N`` values."""
    j = np.asarray(jacobian, float)
    d = np.asarray(residuals_mm_there, float).ravel() - np.asarray(residuals_mm_here, float).ravel()
    if j.ndim != 2 or j.shape[0] != d.size:
        raise ValueError(f"a ({d.size}, p) Jacobian expected for {d.size} residuals, got {j.shape}")
    return -np.linalg.lstsq(j, d, rcond=None)[0]


def resolution_check(spec: ModelSpec, k: Parameters, observation, last_frame: int, factor: float = 2.0,
                     data: TrainingData | None = None, jacobian: np.ndarray | None = None,
                     names=(), confirm: bool = True) -> ResolutionCheck:
    """The fitted model ``spec`` at ``k`` on its own lattice and on one with ``factor`` times the
    particles, frames 0 … ``last_frame`` (module docstring). A reduced model is checked on the
    full model it reduces: a reduced model of the finer lattice would need its own snapshots.

    With ``confirm``, where that lattice moves the points A by more than a pixel, one with
    ``factor²`` times the particles decides, and the check is against it (the first recorded as
    :attr:`~ResolutionCheck.overruled`). A lattice's error is not monotone in its spacing: one
    lattice can sit badly against the sample's surface or the bar's rim. On slide_reverse_s51
    twice the particles moved the points 0.30 mm, four and eight times 0.05 mm
    (docs/decisions.md, "A resolution check on the fit").

    With the fit's training ``data``, its ``jacobian`` and its coordinates' ``names``, also how
    far the finer model would move the fit (:func:`parameter_shift`): the model's own error in
    the parameters, which the fit's standard errors do not contain."""
    if not factor > 1.0:
        raise ValueError(f"the finer lattice needs more particles: factor {factor}")
    pixel_mm = float(observation.pixel_mm)
    here = run_model(spec, k, last_frame, full=True)
    finer, there = _finer_run(spec, k, observation, last_frame, factor)
    difference = displacement_difference_mm(here.points_mm, there.points_mm)
    overruled = None
    if confirm and float(np.max(difference, initial=0.0)) > pixel_mm:
        overruled = {"particles": len(finer.tissue_mm), "largest_mm": float(np.max(difference))}
        finer, there = _finer_run(spec, k, observation, last_frame, factor * factor)
        difference = displacement_difference_mm(here.points_mm, there.points_mm)
    shift = None
    if data is not None and jacobian is not None:
        r_here, r_there = (residuals_mm(r.points_mm, data, None, r.bar_centre_mm) for r in (here, there))
        shift = dict(zip(names, parameter_shift(jacobian, r_here, r_there).tolist()))
    return ResolutionCheck((len(spec.tissue_mm), len(finer.tissue_mm)), (spec.spacing_mm, finer.spacing_mm),
                           difference, pixel_mm, int(last_frame), shift, overruled)


def _finer_run(spec: ModelSpec, k: Parameters, observation, last_frame: int, factor: float):
    """``spec``'s model on ``factor`` times its particles, and its run at ``k`` to ``last_frame``."""
    finer = model_spec(observation, replace(spec.settings,
                                            tissue_particles=int(round(factor * spec.settings.tissue_particles))))
    return finer, run_model(finer, k, last_frame, full=True)


__all__ = ["ResolutionCheck", "displacement_difference_mm", "parameter_shift", "resolution_check"]
