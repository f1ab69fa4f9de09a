"""The online loop: frames in one at a time, the aim for t + k out before the next arrives.

:func:`online_loop` runs a calibrated model alongside a tracked cine: at every frame t it
hands the tracked displacement of the contour points A to the
:class:`~hifumotion.prediction.assimilate.OnlineAssimilator` (the reduced model's state and
the push's scale corrected), then predicts the section at t + k for each horizon k: the
frame-0 contour moved by the predicted displacement of its points, and its centroid —
the aim. Each frame's wall time (the filter and the predictions) is kept.

The tracking is speckle tracking's (:mod:`hifumotion.speckle`), which is causal — frame t's
displacement is computed from frames ≤ t — so a cine replayed here sees what a scanner
feeding frames would; its own cost per frame is measured beside the loop's.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field

import numpy as np

from hifumotion.contour import polygon_centroid
from hifumotion.errors import InputError


@dataclass
class OnlineResult:
    """What the loop produced, per frame t (mm in the image plane: x along its columns, y its rows).

    Attributes
    ----------
    frames
        The frames t the loop took in (1 … T − 1).
    predicted_mm
        horizon k → ``(len(frames), 2)`` the predicted section centroid at t + k.
    tracked_mm
        ``(T, 2)`` the tracked section's centroid at every frame (NaN where the mask is empty).
    scale, scale_std
        The push's estimated scale (force over the calibrated schedule) after each frame.
    latency_ms
        The loop's wall time at each frame (assimilation and every horizon's prediction).
    tracking_ms_per_frame
        Speckle tracking's wall time per frame.
    """

    frames: np.ndarray
    frame_interval_s: float
    predicted_mm: dict
    tracked_mm: np.ndarray
    scale: np.ndarray
    scale_std: np.ndarray
    latency_ms: np.ndarray
    tracking_ms_per_frame: float
    construction_s: float
    stats: dict = field(default_factory=dict)

    def _actual(self, truth_mm: np.ndarray | None) -> np.ndarray:
        """The tracked centroids, or the true ones' motion re-anchored on the tracked frame 0 (the
        error of the motion, not of frame 0's segmentation, which every method shares)."""
        if truth_mm is None:
            return self.tracked_mm
        truth = np.asarray(truth_mm, float)
        return truth - truth[0] + self.tracked_mm[0]

    def errors_mm(self, k: int, truth_mm: np.ndarray | None = None) -> np.ndarray:
        """``(len(frames),)`` |predicted − actual| at t + k (NaN beyond the cine): actual the
        tracked centroid, or the true one's motion (``truth_mm`` ``(T, 2)``, :meth:`_actual`)."""
        actual = self._actual(truth_mm)
        target = self.frames + k
        out = np.full(len(self.frames), np.nan)
        ok = target < len(actual)
        out[ok] = np.linalg.norm(self.predicted_mm[k][ok] - actual[target[ok]], axis=1)
        return out

    def hold_errors_mm(self, k: int, truth_mm: np.ndarray | None = None) -> np.ndarray:
        """The same for holding the last tracked frame: |tracked(t) − actual(t + k)|."""
        actual = self._actual(truth_mm)
        target = self.frames + k
        out = np.full(len(self.frames), np.nan)
        ok = target < len(actual)
        out[ok] = np.linalg.norm(self.tracked_mm[self.frames[ok]] - actual[target[ok]], axis=1)
        return out

    def summary(self) -> dict:
        """Latency (median, 99th percentile, with tracking), the push's last scale and, per
        horizon, the mean error against the tracked section beside holding still."""
        lat = self.latency_ms
        out = {"frames": int(len(self.frames)), "frame_interval_s": self.frame_interval_s,
               "latency_ms": {"median": float(np.median(lat)), "p99": float(np.percentile(lat, 99)),
                              "max": float(lat.max())},
               "tracking_ms_per_frame": self.tracking_ms_per_frame,
               "latency_with_tracking_ms": {"median": float(np.median(lat)) + self.tracking_ms_per_frame,
                                            "p99": float(np.percentile(lat, 99)) + self.tracking_ms_per_frame},
               "push_scale_last": float(self.scale[-1]), "push_scale_std_last": float(self.scale_std[-1]),
               "reduced_model_construction_s": self.construction_s, "horizons": {}}
        for k in self.predicted_mm:
            e, h = self.errors_mm(k), self.hold_errors_mm(k)
            out["horizons"][str(k)] = {"ms": 1000.0 * k * self.frame_interval_s,
                                       "error_vs_tracked_mean_mm": float(np.nanmean(e)),
                                       "hold_error_vs_tracked_mean_mm": float(np.nanmean(h))}
        return out

    def to_csv(self) -> str:
        """``online.csv``: one row per frame and horizon."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["frame", "time_s", "horizon_frames", "horizon_ms", "target_frame", "predicted_x_mm",
                    "predicted_y_mm", "tracked_x_mm", "tracked_y_mm", "error_mm", "push_scale", "push_scale_std",
                    "latency_ms"])
        dt = self.frame_interval_s
        for i, t in enumerate(self.frames):
            for k in sorted(self.predicted_mm):
                p = self.predicted_mm[k][i]
                f = int(t + k)
                row = [int(t), f"{t * dt:.4f}", k, f"{1000 * k * dt:.1f}", f, f"{p[0]:.4f}", f"{p[1]:.4f}"]
                if f < len(self.tracked_mm) and np.isfinite(self.tracked_mm[f]).all():
                    o = self.tracked_mm[f]
                    row += [f"{o[0]:.4f}", f"{o[1]:.4f}", f"{np.hypot(*(p - o)):.4f}"]
                else:
                    row += ["", "", ""]
                row += [f"{self.scale[i]:.5f}", f"{self.scale_std[i]:.5f}", f"{self.latency_ms[i]:.3f}"]
                w.writerow(row)
        return buf.getvalue()


def online_loop(spec, k, observation, horizons_frames, settings=None, progress=None) -> OnlineResult:
    """Run the calibrated model ``spec`` at ``k`` alongside the tracked ``observation`` frame by
    frame (module docstring); predictions ``horizons_frames`` frames ahead.

    ``spec`` runs on its reduced model (made here, around ``k``, if it is not yet: two full
    runs); ``observation`` is a :class:`~hifumotion.estimation.prepare.Observation` tracked by
    speckle (its displacement series carries the points A).
    """
    import time

    from hifumotion.creep.scene import scene_material
    from hifumotion.estimation.model import scene_for
    from hifumotion.prediction.assimilate import OnlineAssimilator, points_observation

    tell = progress or (lambda stage, fraction: None)
    horizons = sorted({int(h) for h in horizons_frames})
    if not horizons or horizons[0] < 1:
        raise InputError(f"horizons must be whole frames ≥ 1, got {horizons_frames}", "horizons")
    if observation.motion is None:
        raise InputError("the online loop reads the speckle tracking's displacement; track with speckle", "tracking")
    n = len(observation.frame_masks)
    last = n - 1
    dt = float(spec.frame_interval_s)
    t0 = time.perf_counter()
    model = spec.reduced(k, last, progress=lambda f: tell("reduced model", f))
    construction_s = time.perf_counter() - t0
    scene = scene_for(spec, k, last)
    plane = observation.frame_plane
    axes = np.stack([np.asarray(plane.u, float), np.asarray(plane.v, float)])
    h = points_observation(model, spec.points_mm, axes, spec.spacing_mm)
    filt = OnlineAssimilator(model, scene_material(scene), scene.bar.schedule(), h, dt, settings)
    series = observation.motion.displacement
    px = plane.to_pixels(spec.points_mm)
    from hifumotion.metrics import centroid

    a0 = spec.points_mm @ axes.T - np.asarray(plane.origin_mm, float) @ axes.T      # frame-0 points, image mm
    pixel = float(observation.pixel_mm)
    tracked = np.array([centroid(m, pixel) if m.any() else (np.nan, np.nan) for m in observation.frame_masks])
    # the predicted section: the tracked frame-0 section moved as the polygon of the points A
    base = tracked[0] - polygon_centroid(a0)
    frames = np.arange(1, n)
    predicted = {h_: np.full((len(frames), 2), np.nan) for h_ in horizons}
    scale, scale_std, latency = (np.zeros(len(frames)) for _ in range(3))
    for i, t in enumerate(frames):
        d, q = series.at(px, int(t))
        seen = np.isfinite(d).all(1) & (q > 0)
        y = np.where(seen[:, None], d, np.nan).ravel()
        est = filt.assimilate(y, horizons, np.repeat(np.where(seen, q, 1.0), 2))
        for h_ in horizons:
            predicted[h_][i] = base + polygon_centroid(a0 + est.predicted_mm[h_].reshape(-1, 2))
        scale[i], scale_std[i], latency[i] = est.scale, est.scale_std, est.latency_ms
        tell("online", (i + 1) / len(frames))
    track_ms = 1000.0 * float(observation.timings_s.get("track_s", np.nan)) / n
    return OnlineResult(frames, dt, predicted, tracked, scale, scale_std, latency, track_ms, construction_s,
                        dict(filt.stats))


__all__ = ["OnlineResult", "online_loop", "polygon_centroid"]
