"""Surrogate predictors: the target's motion regressed on the program the operator already knows.

Before the push the operator knows its program (``setup.json``'s ``push``,
:meth:`~hifumotion.observed.setup.PushSchedule.program`): a driven bar's travel in mm, or
the shape of a pushing bar's force. A target that moves with the drive is then predicted by a
regression of its tracked position on that program, with no tissue model at all. Motion
compensation in radiotherapy calls such a map from a known signal to the target's position a
*correlation* or *surrogate* model [1]_; it is the predictor a physical model must beat with
the same inputs.

Two batch forms, fitted by least squares on the tracked section centroids of the training
frames, each image axis on its own:

* **static** — ``c(t) = c₀ + a·u(t)``: the target moves in proportion to the drive;
* **lagged** — ``c(t) = c₀ + a·u(t) + b·(h_τ ∗ u)(t)``, ``h_τ`` a first-order lag of time
  constant τ (``τ·v' = u − v``, at rest at t = 0): the instantaneous and the delayed response of
  a standard linear solid to its drive (a creep kernel), a linear input–output model in
  output-error form [2]_ — simulated from the input, not one step ahead from the output, so it
  predicts any horizon. τ is the best of a log-spaced grid from one frame interval to the
  training span, by the residual, then refined between its neighbours; the rest is linear.

The predicted section at frame f is the last seen section moved by ``c(f) − c(t_last)``: the
present from the image, the motion ahead from the regression (as the anchored physics).

Online, :class:`OnlineDriveRegression` updates the same regressions at every frame by
recursive least squares with exponential forgetting [2]_ and, per horizon, aims with the
member (static, or lagged at each τ of the grid) whose own past aims at that horizon missed
least — a prequential choice: each member is judged on frames it had not seen when it aimed.

Lengths in mm, times in s, the program in its own unit (mm of travel, or the force over its
peak); columns are image x, rows image y.

References
----------
.. [1] J. R. McClelland et al., "Respiratory motion models: a review", Medical Image Analysis
       17(1), 19–42 (2013).
.. [2] L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall (1999),
       §4.2 (output-error models) and §11.2 (recursive least squares).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, signal

from hifumotion.errors import InputError

#: the lag grid's size: τ log-spaced from one frame interval to the training span
LAG_GRID = 24


def lagged_program(program: np.ndarray, frame_interval_s: float, lag_s: float) -> np.ndarray:
    """The program through a first-order lag ``τ·v' = u − v``, ``v(0) = u(0)`` (at rest), exact
    for a program linear between frames (first-order hold).

    ``program``: ``(T,)`` the program at frames 0 … T − 1; returns ``(T,)``."""
    u = np.asarray(program, float)
    if lag_s <= 0:
        return u.copy()
    h = frame_interval_s / lag_s
    e = np.exp(-h)
    # v[n] = e·v[n-1] + b0·u[n] + b1·u[n-1]  (the first-order-hold discretisation)
    b0 = 1.0 - (1.0 - e) / h
    b = np.array([b0, (1.0 - e) - b0])
    a = np.array([1.0, -e])
    zi = signal.lfilter_zi(b, a) * u[0]
    return signal.lfilter(b, a, u, zi=zi)[0]


def lag_grid_s(frame_interval_s: float, span_s: float, count: int = LAG_GRID) -> np.ndarray:
    """The lags τ a lagged regression tries: log-spaced from one frame interval to ``span_s``."""
    lo = float(frame_interval_s)
    hi = max(float(span_s), 2.0 * lo)
    return np.geomspace(lo, hi, count)


@dataclass(frozen=True)
class DriveRegression:
    """A fitted surrogate: ``c(t) = θᵀ φ(t)``, ``φ = [1, u]`` (static) or ``[1, u, v_τ]`` (lagged).

    Attributes
    ----------
    lag_s
        τ of the lagged term (s), or None for the static regression.
    coefficients
        ``(p, 2)`` θ for image x and y (mm per unit of the program; the first row mm).
    residual_rms_mm
        The fit's RMS residual over the fitted frames (mm, both axes).
    frames
        The frames it was fitted on.
    """

    lag_s: float | None
    coefficients: np.ndarray
    residual_rms_mm: float
    frames: tuple[int, ...]

    @property
    def name(self) -> str:
        return "drive_static" if self.lag_s is None else "drive_lagged"

    def features(self, program: np.ndarray, frame_interval_s: float) -> np.ndarray:
        """``(T, p)`` the regressors at every frame of ``program``."""
        return _features(np.asarray(program, float), frame_interval_s, self.lag_s)

    def centroids_mm(self, program: np.ndarray, frame_interval_s: float) -> np.ndarray:
        """``(T, 2)`` the regression's centroid at every frame of ``program`` (mm)."""
        return self.features(program, frame_interval_s) @ self.coefficients

    def as_dict(self) -> dict:
        return {"kind": self.name, "lag_s": self.lag_s, "coefficients": self.coefficients.tolist(),
                "residual_rms_mm": self.residual_rms_mm, "frames": [self.frames[0], self.frames[-1]]}


def _features(u: np.ndarray, dt: float, lag_s: float | None) -> np.ndarray:
    columns = [np.ones_like(u), u]
    if lag_s is not None:
        columns.append(lagged_program(u, dt, lag_s))
    return np.stack(columns, axis=1)


def fit_drive_regression(centroids_mm: np.ndarray, frames, program: np.ndarray, frame_interval_s: float,
                         lagged: bool = False) -> DriveRegression:
    """Fit a surrogate to tracked centroids by least squares.

    Parameters
    ----------
    centroids_mm
        ``(n, 2)`` the tracked section's centroid (mm) at ``frames``.
    frames
        ``n`` frame numbers (≥ 2 distinct), indices into ``program``.
    program
        ``(T,)`` the known program at every frame 0 … T − 1 (the lag runs from frame 0).
    frame_interval_s
        Time between frames (s).
    lagged
        Fit the lagged form (τ from :func:`lag_grid_s` over the fitted frames' span).
    """
    c = np.asarray(centroids_mm, float)
    f = np.asarray(frames, int)
    u = np.asarray(program, float)
    if c.ndim != 2 or c.shape != (len(f), 2) or len(f) < 2:
        raise InputError(f"expected (n ≥ 2, 2) centroids at n frames, got {c.shape} at {len(f)}", "centroids_mm")
    if f.min() < 0 or f.max() >= len(u):
        raise InputError(f"frames {f.min()}…{f.max()} outside the program's {len(u)} frames", "frames")
    ok = np.isfinite(c).all(1)
    if ok.sum() < 2:
        raise InputError("fewer than two tracked centroids to fit a surrogate to", "centroids_mm")
    c, f = c[ok], f[ok]

    def fitted(lag: float | None) -> DriveRegression:
        phi = _features(u, frame_interval_s, lag)[f]
        theta, *_ = np.linalg.lstsq(phi, c, rcond=None)
        rms = float(np.sqrt(np.mean((phi @ theta - c) ** 2)))
        return DriveRegression(None if lag is None else float(lag), theta, rms, tuple(int(x) for x in f))

    if not lagged:
        return fitted(None)
    grid = lag_grid_s(frame_interval_s, (f.max() - f.min()) * frame_interval_s)
    fits = [fitted(lag) for lag in grid]
    i = int(np.argmin([r.residual_rms_mm for r in fits]))
    # τ refined between the grid's neighbours of the best (the residual is smooth in log τ)
    lo, hi = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, len(grid) - 1)])
    found = optimize.minimize_scalar(lambda x: fitted(float(np.exp(x))).residual_rms_mm, bounds=(lo, hi),
                                     method="bounded", options={"xatol": 1e-4})
    refined = fitted(float(np.exp(found.x)))
    return refined if refined.residual_rms_mm <= fits[i].residual_rms_mm else fits[i]


def shift_mask(mask: np.ndarray, shift_mm, pixel_mm: float) -> np.ndarray:
    """``mask`` translated by ``shift_mm`` (x along columns, y along rows, mm) to a fraction of a
    pixel (:func:`hifumotion.prediction.masks.shift_mask`)."""
    from hifumotion.prediction.masks import shift_mask as shift_px

    return shift_px(mask, np.asarray(shift_mm, float) / pixel_mm)


def mask_centroids_mm(masks: dict, pixel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """``(frames, (n, 2) centroids in mm)`` of the non-empty masks, frames in order."""
    from hifumotion.metrics import centroid

    frames = np.array(sorted(f for f, m in masks.items() if np.asarray(m).any()), int)
    return frames, np.array([centroid(masks[f], pixel_mm) for f in frames], float).reshape(-1, 2)


def drive_regression_predict(observed: dict[int, np.ndarray], frames, program: np.ndarray, frame_interval_s: float,
                             pixel_mm: float, lagged: bool = False) -> tuple[dict[int, np.ndarray], DriveRegression]:
    """The surrogate's masks at ``frames``: fitted on the observed masks' centroids, the last
    observed mask moved by the regression's motion from its frame. Returns ``(masks, fit)``."""
    if not observed:
        raise InputError("the surrogate needs observed frames to fit", "observed")
    seen, c = mask_centroids_mm(observed, pixel_mm)
    fit = fit_drive_regression(c, seen, program, frame_interval_s, lagged)
    path = fit.centroids_mm(program, frame_interval_s)
    last = int(seen[-1])
    base = observed[last]
    return {int(f): shift_mask(base, path[int(f)] - path[last], pixel_mm) for f in frames}, fit


def anchored_to_last(model_masks: dict[int, np.ndarray], seen: dict[int, np.ndarray], frames,
                     pixel_mm: float) -> dict[int, np.ndarray]:
    """A model's motion from the last seen frame: the last seen mask moved by the model's
    centroid motion from that frame to each of ``frames`` — the present from the image, the
    motion ahead from the model (the surrogates' and the online aim's anchoring)."""
    last = max(f for f in seen if np.asarray(seen[f]).any())
    wanted = {int(f) for f in [last, *frames]}
    found, c = mask_centroids_mm({f: model_masks[f] for f in wanted}, pixel_mm)
    if len(found) != len(wanted):
        raise InputError("the model's section is empty at a frame asked for", "model_masks")
    at = dict(zip(found.tolist(), c))
    return {int(f): shift_mask(seen[last], at[f] - at[last], pixel_mm) for f in frames}


def residual_corrected(model_masks: dict[int, np.ndarray], tracked: dict[int, np.ndarray], fit_frames, frames,
                       program: np.ndarray, frame_interval_s: float, pixel_mm: float
                       ) -> tuple[dict[int, np.ndarray], DriveRegression]:
    """A model's masks corrected by a regression of its miss on the program: the tracked minus
    the model's centroid on ``fit_frames`` fitted by the lagged regression, and each of the
    model's masks at ``frames`` moved by the fitted miss there (the physics' systematic error
    that follows the drive, and its offset, taken out). Returns ``(masks, fit)``."""
    both = [f for f in fit_frames if f in model_masks and f in tracked
            and np.asarray(model_masks[f]).any() and np.asarray(tracked[f]).any()]
    if len(both) < 2:
        raise InputError("fewer than two frames with both the model's and the tracked section", "fit_frames")
    _, model_c = mask_centroids_mm({f: model_masks[f] for f in both}, pixel_mm)
    _, seen_c = mask_centroids_mm({f: tracked[f] for f in both}, pixel_mm)
    fit = fit_drive_regression(seen_c - model_c, both, program, frame_interval_s, lagged=True)
    miss = fit.centroids_mm(program, frame_interval_s)
    return {int(f): shift_mask(model_masks[f], miss[int(f)], pixel_mm) for f in frames}, fit


class _Member:
    """One recursive least-squares regression with forgetting (information form) and a fixed
    ridge prior: the data's information decays, the prior does not, so a direction the recent
    frames no longer excite (a drive held still) relaxes towards no motion instead of winding up."""

    def __init__(self, lag_s: float | None, forgetting: float, p: int, regularisation: float):
        self.lag_s = lag_s
        self.forgetting = forgetting
        self.prior = regularisation * np.eye(p)
        self.A = np.zeros((p, p))
        self.B = np.zeros((p, 2))
        self.theta = np.zeros((p, 2))

    def update(self, phi: np.ndarray, c: np.ndarray) -> None:
        self.A = self.forgetting * self.A + np.outer(phi, phi)
        self.B = self.forgetting * self.B + np.outer(phi, c)
        self.theta = np.linalg.solve(self.A + self.prior, self.B)


class OnlineDriveRegression:
    """The surrogates updated at every frame (recursive least squares), aiming ahead.

    Members: the static regression and the lagged one at each τ of :func:`lag_grid_s` (one
    frame interval to ``memory_s``). At each frame every member is updated with the tracked
    centroid; the aim at t + k is the tracked centroid at t moved by the member's motion from t
    to t + k, the member being the one whose past aims at horizon k (those whose frame has come)
    missed least, weighted with the same forgetting.

    Parameters
    ----------
    program
        ``(T,)`` the known program at frames 0 … T − 1 (frames past T hold its last value).
    frame_interval_s
        Time between frames (s).
    memory_s
        The forgetting's memory (s): data ``memory_s`` old weigh e⁻¹ as much as the newest.
    """

    def __init__(self, program: np.ndarray, frame_interval_s: float, memory_s: float, lagged: bool = True):
        u = np.asarray(program, float)
        if u.ndim != 1 or len(u) < 2 or not np.isfinite(u).all():
            raise InputError("the program must be a finite series over ≥ 2 frames", "program")
        if not (frame_interval_s > 0 and memory_s > 0):
            raise InputError("frame_interval_s and memory_s must be > 0", "memory_s")
        self.dt = float(frame_interval_s)
        self.forgetting = float(np.exp(-self.dt / memory_s))
        lags = [None] + (list(lag_grid_s(self.dt, memory_s)) if lagged else [])
        scale = max(float(np.abs(u).max()), 1e-12)
        # a weak prior on θ (the program's scale): the first frames' solves stay defined
        self.members = [_Member(lag, self.forgetting, 2 if lag is None else 3, 1e-6 * scale ** 2) for lag in lags]
        self.phi = [_features(u, self.dt, m.lag_s) for m in self.members]
        self.pending: dict[int, list] = {}        # target frame -> [(horizon, every member's aim)]
        self.scores: dict[int, np.ndarray] = {}   # horizon -> forgetting-weighted squared miss per member
        self.last_frame = -1
        self.seen: tuple[int, np.ndarray] | None = None

    def _phi(self, i: int, frame: int) -> np.ndarray:
        table = self.phi[i]
        return table[min(frame, len(table) - 1)]

    def update(self, frame: int, centroid_mm) -> None:
        """Take the tracked centroid (mm) at ``frame`` (frames in increasing order)."""
        c = np.asarray(centroid_mm, float)
        if frame <= self.last_frame:
            raise InputError(f"frame {frame} after frame {self.last_frame}: frames must increase", "frame")
        self.last_frame = int(frame)
        due = self.pending.pop(frame, [])
        if not np.isfinite(c).all():
            return
        for k, aims in due:
            miss = np.array([float(np.sum((aim - c) ** 2)) for aim in aims])
            self.scores[k] = self.forgetting * self.scores.get(k, np.zeros(len(self.members))) + miss
        for i, m in enumerate(self.members):
            m.update(self._phi(i, frame), c)
        self.seen = (int(frame), c)

    def predict(self, frame: int, horizons) -> dict[int, np.ndarray]:
        """The aim (mm) at ``frame + k`` for each horizon k, from the centroid taken at ``frame``."""
        out = {}
        for k in horizons:
            k = int(k)
            if self.seen is None:
                out[k] = np.full(2, np.nan)
                continue
            at, now = self.seen       # the last frame tracked (frame itself, unless it was lost)
            aims = [now + (self._phi(i, frame + k) - self._phi(i, at)) @ m.theta
                    for i, m in enumerate(self.members)]
            self.pending.setdefault(frame + k, []).append((k, aims))
            best = int(np.argmin(self.scores[k])) if k in self.scores else 0
            out[k] = aims[best]
        return out

    def chosen(self, horizon: int) -> str:
        """Which member aims at ``horizon`` now: ``static`` or ``lag <τ> s``."""
        s = self.scores.get(int(horizon))
        lag = self.members[int(np.argmin(s)) if s is not None else 0].lag_s
        return "static" if lag is None else f"lag {lag:.3g} s"


def online_drive_regression(centroids_mm: np.ndarray, program: np.ndarray, frame_interval_s: float, horizons,
                            memory_s: float, lagged: bool = True) -> dict[int, np.ndarray]:
    """Replay :class:`OnlineDriveRegression` over tracked centroids ``(T, 2)`` (NaN where not
    seen): horizon k → ``(T, 2)`` the aim made at each frame t for t + k (NaN before the first
    seen frame)."""
    c = np.asarray(centroids_mm, float)
    reg = OnlineDriveRegression(program, frame_interval_s, memory_s, lagged)
    out = {int(k): np.full((len(c), 2), np.nan) for k in horizons}
    for t in range(len(c)):
        reg.update(t, c[t])
        for k, aim in reg.predict(t, out).items():
            out[k][t] = aim
    return out


__all__ = ["DriveRegression", "OnlineDriveRegression", "drive_regression_predict", "fit_drive_regression",
           "anchored_to_last", "residual_corrected",
           "lag_grid_s", "lagged_program", "mask_centroids_mm", "online_drive_regression", "shift_mask"]
