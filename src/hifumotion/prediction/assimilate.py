"""Online assimilation: the reduced model corrected by every tracked frame, and the push re-estimated.

The paper's Discussion asks that estimating the parameters and predicting the motion be
"carried out consecutively and repetitively" while the tissue moves. Here the reduced
model (:mod:`hifumotion.reduced.model`) is stepped one frame at a time and an extended
Kalman filter (the reduced-order filter of Moireau & Chapelle, ESAIM: COCV 2011, as SOFA's
Optimus runs it) corrects its state with each frame's tracked displacement:

* **State** ``x = [q; a]``: the reduced coordinates and the push's scale a — the force is
  ``a F(t)``, F the calibrated schedule (the announced shape at the fitted magnitude); for a
  bar in travel control (driven by a stage) the drive is ``a s(t)``, s the programmed travel,
  and the force it takes is a result. The
  scale is the one parameter a push that changes unannounced makes unknown again (E, ν,
  β1, β2 stay the calibration's); it follows a random walk of ``scale_walk_per_sqrt_s``
  per √s, so after a change the filter lets the data move it.
* **Forecast.** One backward-Euler step of the frame interval from the corrected state
  (:meth:`~hifumotion.reduced.model.ReducedCreep.step`, contacts and Eq. 16 whole). Its
  Jacobian is the step's own linearisation
  (:meth:`~hifumotion.reduced.model.ReducedCreep.solve_response`): the step's matrix A
  (its friction's tangent included) inverted on the subspace its pressed contacts leave
  free, on ``∂rhs/∂q = C_r/Δt + M_r/Δt²`` and ``∂rhs/∂a = F(t₊) v_s`` (a driven bar:
  ``k s(t₊) v_s``, k the penalty that holds its advance, :func:`~hifumotion.reduced.model.driven_bar`).
* **Analysis.** The observation is the in-plane displacement since frame 0 (mm) of
  material points (the contour points A that speckle tracking carries), linear in q:
  ``y = H (q − q₀)``; its noise ``observation_noise_mm`` per coordinate.
* **Prediction** of frame t + k: one step of k frames from the analysed state, at the
  scaled schedule's force at t + k.

Everything is r + 1 dimensional (r ≈ 20–40 modes): a frame costs one reduced step and one more
per horizon.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from hifumotion.creep.integrate import CreepMaterial
from hifumotion.reduced.model import ReducedCreep, ReducedState, driven_bar, step_counters
from hifumotion.errors import InputError

MM = 1e-3


@dataclass
class AssimilationSettings:
    """How much the filter trusts the tracking, the model and the push.

    Attributes
    ----------
    observation_noise_mm
        Standard deviation of one tracked in-plane displacement coordinate (mm).
    model_noise_mm
        Standard deviation per frame of the model's error in each reduced coordinate (mm).
    scale_walk_per_sqrt_s
        The push scale's random walk (per √s): how fast the filter lets the force move.
    initial_scale_std
        The calibrated push's relative standard deviation at the start.
    anchor_to_tracking
        Aim at the tracked section of frame t moved by the model's motion from t to t + k,
        rather than at the model's own section at t + k: where the tracking sees the section
        better than the model reproduces it (the model's error is an offset it carries), the
        present is read from the image and only the motion ahead from the physics. On by
        default (docs/decisions.md, "The online aim": on both push_change twins the anchored
        aim is the better one, 300 ms ahead).
    """

    observation_noise_mm: float = 0.05
    model_noise_mm: float = 0.002
    scale_walk_per_sqrt_s: float = 0.5
    initial_scale_std: float = 0.1
    anchor_to_tracking: bool = True

    def __post_init__(self):
        for name in ("observation_noise_mm", "model_noise_mm", "scale_walk_per_sqrt_s", "initial_scale_std"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"must be a finite number > 0, got {value}", name)


@dataclass
class FrameEstimate:
    """The filter after frame t: the push's scale and force (N), the scale's uncertainty, the
    analysed and the predicted displacement of the observed points at t + k (mm, as the
    observation), with the frame's wall time (ms)."""

    frame: int
    scale: float
    force_n: float
    scale_std: float
    observed_mm: np.ndarray
    analysed_mm: np.ndarray
    predicted_mm: dict = field(default_factory=dict)   # horizon (frames) -> displacement (mm)
    latency_ms: float = 0.0


class OnlineAssimilator:
    """The reduced model run alongside the scanner, one frame at a time (module docstring).

    Parameters
    ----------
    model
        The reduced model (its modes should span the pushes the filter may meet).
    material
        The calibrated tissue (E, ν, β1, β2).
    force_n
        The calibrated push, ``F(t)`` (N at t s, t = 0 at frame 0): the schedule the scale multiplies.
    observation
        ``(n_observed, r)``: each observed displacement coordinate (metres) per metre of each
        reduced coordinate (:func:`points_observation`).
    frame_interval_s
        Time between frames (s).
    travel_m
        A bar in travel control: its programmed travel ``s(t)`` (m at t s, from where it rests on
        the settled tissue), which the scale multiplies; ``force_n`` is then not read.
    """

    def __init__(self, model: ReducedCreep, material: CreepMaterial, force_n, observation: np.ndarray,
                 frame_interval_s: float, settings: AssimilationSettings | None = None, travel_m=None):
        if not (np.isfinite(frame_interval_s) and frame_interval_s > 0):
            raise InputError(f"must be a finite number of seconds > 0, got {frame_interval_s}", "frame_interval_s")
        self.model = model
        self.settings = s = settings or AssimilationSettings()
        self.loads = model.loads(material)
        self.h = np.asarray(observation, float)
        r = model.basis.size
        if self.h.ndim != 2 or self.h.shape[1] != r:
            raise InputError(f"expected an (m, {r}) observation matrix, got {self.h.shape}", "observation")
        self.dt = float(frame_interval_s)
        self.schedule = force_n
        self.travel = travel_m
        self.state = model.settle(self.loads, 0.0 if travel_m is not None else float(force_n(0.0)))
        self.q0 = self.state.q.copy()
        # a driven bar's travel counts from its place on the settled tissue (as the model's runs)
        self.rest_m = float(model.basis.advance_modes_m @ self.q0)
        self.scale = 1.0
        self.cov = np.zeros((r + 1, r + 1))
        self.cov[r, r] = s.initial_scale_std ** 2
        self.frame = 0
        self.stats = step_counters(model)

    def _forecast(self, state: ReducedState, scale: float, dt: float) -> tuple[ReducedState, float]:
        """One step of ``dt`` at the push's (or drive's) ``scale``: the new state and the bar's force (N)."""
        if self.travel is None:
            force = scale * float(self.schedule(state.t_s + dt))
            new, _ = self.model.step(state, self.loads, dt, force, self.stats, error=False)
            return new, force
        advance = self.rest_m + scale * float(self.travel(state.t_s + dt))
        new, _ = self.model.step(state, self.loads, dt, 0.0, self.stats, error=False, advance_m=advance)
        return new, float(self.stats["bar_force_n"])

    def assimilate(self, observed_mm: np.ndarray, horizons_frames=(), quality: np.ndarray | None = None
                   ) -> FrameEstimate:
        """Frame t + 1: forecast one frame, correct by its tracked displacement ``observed_mm``
        (``(n_observed,)``, mm since frame 0; NaN where tracking saw nothing), predict t + 1 + k for each
        horizon k (frames). ``quality`` ``(n_observed,)`` in (0, 1], the tracking's confidence in each
        coordinate, divides its noise (the speckle tracking's NCC quality: a boundary the image
        does not show counts for little)."""
        started = time.perf_counter()
        s = self.settings
        y = np.asarray(observed_mm, float).ravel()
        if y.shape != (len(self.h),):
            raise InputError(f"expected {len(self.h)} displacement coordinates, got {y.shape}", "observed_mm")
        r = self.model.basis.size
        dt = self.dt
        nominal, taken = self._forecast(self.state, self.scale, dt)   # a driven bar's force: what it took
        # the forecast's Jacobian, the step's own linearisation: its last round's matrix (friction
        # included) on the subspace its pressed contacts leave free, applied to what q and a
        # bring to its right-hand side (M/Δt² + C/Δt per unit q; F(t₊) v_s per unit a, a driven
        # bar's k s(t₊) v_s)
        v_s = self.model.basis.advance_modes_m
        if self.travel is None:
            push = float(self.schedule(self.state.t_s + dt)) * v_s
        else:
            step_matrix = self.loads.stiffness + self.state.viscous / dt + self.model.mass / dt ** 2
            push = driven_bar(step_matrix, v_s) * float(self.travel(self.state.t_s + dt)) * v_s
        response = self.model.solve_response(
            np.column_stack([self.state.viscous / dt + self.model.mass / dt ** 2, push]))
        jac = np.zeros((r + 1, r + 1))
        jac[:r] = response
        jac[r, r] = 1.0
        noise = np.zeros(r + 1)
        noise[:r] = (s.model_noise_mm * MM) ** 2
        noise[r] = s.scale_walk_per_sqrt_s ** 2 * dt
        cov = jac @ self.cov @ jac.T + np.diag(noise)
        # analysis on the coordinates tracking saw (H maps q in m to mm)
        seen = np.isfinite(y)
        h = np.zeros((int(seen.sum()), r + 1))
        h[:, :r] = self.h[seen] / MM
        innovation = y[seen] - self.h[seen] @ (nominal.q - self.q0) / MM
        x = np.append(nominal.q, self.scale)
        if len(innovation):
            sigma = np.full(len(innovation), s.observation_noise_mm)
            if quality is not None:
                sigma = sigma / np.clip(np.asarray(quality, float).ravel()[seen], 0.05, 1.0)
            gain_t = np.linalg.solve(h @ cov @ h.T + np.diag(sigma ** 2), h @ cov)
            x = x + gain_t.T @ innovation
            cov = cov - gain_t.T @ (h @ cov)
        self.cov = 0.5 * (cov + cov.T)
        self.scale = max(float(x[r]), 0.0)    # the bar pushes; it does not pull
        analysed = ReducedState(nominal.t_s, x[:r], nominal.qdot + (x[:r] - nominal.q) / dt, nominal.viscous,
                                 nominal.friction)
        self.state = self.model.lag_viscosity(
            analysed, self.loads, taken if self.travel is not None else self.scale * float(self.schedule(nominal.t_s)))
        self.frame += 1
        predicted = {}
        for k in horizons_frames:
            ahead, _ = self._forecast(self.state, self.scale, int(k) * dt)
            predicted[int(k)] = self.h @ (ahead.q - self.q0) / MM
        force = self.scale * float(self.schedule(self.state.t_s)) if self.travel is None else taken
        return FrameEstimate(self.frame, self.scale, force, float(np.sqrt(self.cov[r, r])), y,
                             self.h @ (self.state.q - self.q0) / MM, predicted,
                             1000.0 * (time.perf_counter() - started))


def particle_observation(model: ReducedCreep, particles: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """``(len(particles) · len(axes), r)``: the displacement (m per unit q) of the model's particles
    ``particles`` along the unit ``axes`` (e.g. the image plane's u and v), point by point."""
    modes = model.particle_modes_mm.reshape(-1, 3, model.basis.size)[np.asarray(particles, int)] * MM
    return np.einsum("pkr,ak->par", modes, np.asarray(axes, float)).reshape(-1, model.basis.size)


def points_observation(model: ReducedCreep, points_mm: np.ndarray, axes: np.ndarray, spacing_mm: float) -> np.ndarray:
    """``(len(points) · len(axes), r)``: the displacement (m per unit q) of material points
    ``points_mm`` (``(M, 3)``, where they are at frame 0: the contour points A) along the unit
    ``axes``, point by point — the model's particles' displacement carried to them by
    :func:`~hifumotion.particles.section.material_weights` (as :func:`~hifumotion.estimation.model.run_model`)."""
    from hifumotion.particles.section import material_weights

    r = model.basis.size
    phi, _ = material_weights(np.asarray(points_mm, float), model.settled_particles_mm, spacing_mm)
    moved = (phi @ model.particle_modes_mm.reshape(-1, 3 * r)).reshape(-1, 3, r) * MM
    return np.einsum("pkr,ak->par", moved, np.asarray(axes, float)).reshape(-1, r)


__all__ = ["AssimilationSettings", "FrameEstimate", "OnlineAssimilator", "particle_observation", "points_observation"]
