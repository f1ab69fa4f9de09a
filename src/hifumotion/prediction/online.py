"""The online loop: frames in one at a time, the aim for t + k out before the next arrives.

:class:`OnlineSession` runs a calibrated model beside a scanner. It is made from what is known
before the push (the calibration, ``setup.json``, frame 0 and its target), then takes each
frame as it arrives (:meth:`OnlineSession.push`):

1. **track**: speckle tracking registers the frame to frame 0 (:class:`~hifumotion.speckle.SpeckleTracker`,
   from frames ≤ t only) — the displacement of the contour points A and of the target's
   material boundary;
2. **assimilate**: the :class:`~hifumotion.prediction.assimilate.OnlineAssimilator` corrects
   the reduced model's state and the push's scale with the points' tracked displacement;
3. **aim**: for each horizon k the section at t + k — the frame-0 section moved as the
   polygon of the points A — and its centroid; anchored (the default,
   ``AssimilationSettings.anchor_to_tracking``), the aim is the tracked section's centroid at
   t moved by the model's motion from t to t + k: the present from the image, the motion
   ahead from the physics.

Beside the physics, the session runs the **surrogate** that knows the same inputs: the tracked
centroid regressed on the push's known program, updated at every frame by recursive least squares
(:class:`~hifumotion.prediction.surrogates.OnlineDriveRegression`); its aims are recorded beside
the physics' (``surrogate_mm``), outside the physics' latency.

Each frame's wall time, from the frame in memory to its aims, is its latency (tracking
included). :func:`online_loop` replays a recorded cine through a session; ``hifumotion
online`` replays one, at its frame rate if asked, or watches a folder a scanner writes into
(:func:`watch_frames`).
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
        The push's estimated scale (force over the calibrated schedule; a driven bar's travel over its
        program) after each frame.
    latency_ms
        Each frame's wall time from the frame in memory to its aims (tracking, assimilation
        and every horizon's prediction).
    construction_s
        The reduced model's construction before the first frame (s).
    tracking_ms, filter_ms
        The parts of each frame's latency: speckle tracking, and the filter's step (with the
        predictions).
    surrogate_mm
        horizon k → ``(len(frames), 2)`` the online surrogate's aim at t + k (the tracked
        centroid regressed on the known program; NaN where nothing was tracked yet).
    """

    frames: np.ndarray
    frame_interval_s: float
    predicted_mm: dict
    tracked_mm: np.ndarray
    scale: np.ndarray
    scale_std: np.ndarray
    latency_ms: np.ndarray
    construction_s: float
    tracking_ms: np.ndarray
    filter_ms: np.ndarray
    stats: dict = field(default_factory=dict)
    surrogate_mm: dict = field(default_factory=dict)

    @property
    def tracking_ms_per_frame(self) -> float:
        """Speckle tracking's mean wall time a frame (ms)."""
        return float(np.mean(self.tracking_ms)) if len(self.tracking_ms) else float("nan")

    def _actual(self, truth_mm: np.ndarray | None) -> np.ndarray:
        """The tracked centroids, or the true ones' motion re-anchored on the tracked frame 0 (the
        error of the motion, not of frame 0's segmentation, which every method shares)."""
        if truth_mm is None:
            return self.tracked_mm
        truth = np.asarray(truth_mm, float)
        return truth - truth[0] + self.tracked_mm[0]

    def _misses_mm(self, aims: np.ndarray, k: int, truth_mm: np.ndarray | None) -> np.ndarray:
        """``(len(frames),)`` |aim made at t − actual(t + k)| (NaN beyond the cine)."""
        actual = self._actual(truth_mm)
        target = self.frames + k
        out = np.full(len(self.frames), np.nan)
        ok = target < len(actual)
        out[ok] = np.linalg.norm(aims[ok] - actual[target[ok]], axis=1)
        return out

    def errors_mm(self, k: int, truth_mm: np.ndarray | None = None) -> np.ndarray:
        """``(len(frames),)`` |predicted − actual| at t + k (NaN beyond the cine): actual the
        tracked centroid, or the true one's motion (``truth_mm`` ``(T, 2)``, :meth:`_actual`)."""
        return self._misses_mm(self.predicted_mm[k], k, truth_mm)

    def hold_errors_mm(self, k: int, truth_mm: np.ndarray | None = None) -> np.ndarray:
        """The same for holding the last tracked frame: |tracked(t) − actual(t + k)|."""
        return self._misses_mm(self.tracked_mm[self.frames], k, truth_mm)

    def surrogate_errors_mm(self, k: int, truth_mm: np.ndarray | None = None) -> np.ndarray:
        """The same for the online surrogate's aim: |surrogate(t + k) − actual(t + k)|."""
        if k not in self.surrogate_mm:
            return np.full(len(self.frames), np.nan)
        return self._misses_mm(self.surrogate_mm[k], k, truth_mm)

    def summary(self) -> dict:
        """Latency (median, 99th percentile, tracking included; the frames whose aims came after
        the next frame was due), the push's last scale and, per horizon, the mean error against
        the tracked section beside holding still."""
        lat, filt = self.latency_ms, self.filter_ms
        deadline_ms = 1000.0 * self.frame_interval_s
        out = {"frames": int(len(self.frames)), "frame_interval_s": self.frame_interval_s,
               "latency_with_tracking_ms": {"median": float(np.median(lat)), "p99": float(np.percentile(lat, 99)),
                                            "max": float(lat.max())},
               "filter_ms": {"median": float(np.median(filt)), "p99": float(np.percentile(filt, 99))},
               "tracking_ms_per_frame": self.tracking_ms_per_frame,
               "frames_late": int(np.sum(lat > deadline_ms)),
               "push_scale_last": float(self.scale[-1]), "push_scale_std_last": float(self.scale_std[-1]),
               "reduced_model_construction_s": self.construction_s, "horizons": {}}
        for k in self.predicted_mm:
            e, h = self.errors_mm(k), self.hold_errors_mm(k)
            out["horizons"][str(k)] = {"ms": 1000.0 * k * self.frame_interval_s,
                                       "error_vs_tracked_mean_mm": float(np.nanmean(e)),
                                       "hold_error_vs_tracked_mean_mm": float(np.nanmean(h))}
            if k in self.surrogate_mm:
                sur = self.surrogate_errors_mm(k)
                out["horizons"][str(k)]["surrogate_error_vs_tracked_mean_mm"] = \
                    float(np.nanmean(sur)) if np.isfinite(sur).any() else None
        return out

    def to_csv(self) -> str:
        """``online.csv``: one row per frame and horizon."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["frame", "time_s", "horizon_frames", "horizon_ms", "target_frame", "predicted_x_mm",
                    "predicted_y_mm", "tracked_x_mm", "tracked_y_mm", "error_mm", "push_scale", "push_scale_std",
                    "latency_ms", "tracking_ms", "filter_ms", "surrogate_x_mm", "surrogate_y_mm"])
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
                row += [f"{self.scale[i]:.5f}", f"{self.scale_std[i]:.5f}", f"{self.latency_ms[i]:.3f}",
                        f"{self.tracking_ms[i]:.3f}", f"{self.filter_ms[i]:.3f}"]
                sur = self.surrogate_mm.get(k)
                row += ([f"{sur[i][0]:.4f}", f"{sur[i][1]:.4f}"] if sur is not None and np.isfinite(sur[i]).all()
                        else ["", ""])
                w.writerow(row)
        return buf.getvalue()


@dataclass
class OnlineStep:
    """What :meth:`OnlineSession.push` returns for frame t (mm in the image plane: x along its
    columns, y along its rows).

    ``predicted_mm``: horizon k (frames) → the predicted section centroid at t + k (the aim);
    ``tracked_mm``: the tracked section's centroid at t; ``scale``/``scale_std``: the push's
    estimated scale; ``tracking_ms``/``filter_ms``/``latency_ms``: the frame's wall times
    (the latency from the frame in memory to its aims, tracking included); ``surrogate_mm``:
    horizon k → the online surrogate's aim at t + k."""

    frame: int
    time_s: float
    predicted_mm: dict
    tracked_mm: np.ndarray
    scale: float
    scale_std: float
    tracking_ms: float
    filter_ms: float
    latency_ms: float
    surrogate_mm: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        """A JSON-ready record (``hifumotion online --stream`` prints one a line)."""
        return {"frame": self.frame, "time_s": round(self.time_s, 6),
                "aim_mm": {str(k): [round(float(v), 4) for v in p] for k, p in self.predicted_mm.items()},
                "tracked_mm": [round(float(v), 4) for v in self.tracked_mm],
                "push_scale": round(self.scale, 5), "push_scale_std": round(self.scale_std, 5),
                "latency_ms": round(self.latency_ms, 3),
                "surrogate_aim_mm": {str(k): [round(float(v), 4) for v in p] for k, p in self.surrogate_mm.items()}}


class OnlineSession:
    """The online loop fed one frame at a time (module docstring).

    Parameters
    ----------
    spec, k
        The calibrated model (:class:`~hifumotion.estimation.model.ModelSpec`) and its
        parameters; it runs on its reduced model (made here around ``k`` when ``spec`` is not
        reduced yet: two full runs, before the first frame).
    setup
        What the operator knows (:class:`~hifumotion.observed.setup.Setup`): the imaging plane,
        the pixel size, the frame interval, the floor and the bar.
    frame0
        ``(H, W)`` frame 0, uint8 or grey levels in [0, 1].
    mask0
        ``(H, W)`` bool: the target on frame 0 (its segmentation, the boundary offset applied).
    horizons_frames
        How far ahead to aim, in frames (each ≥ 1).
    frames_expected
        How long the push is expected to last, in frames (the reduced model's runs span it);
        default ``setup.frames``. Frames past it are still taken.
    settings
        The filter's (:class:`~hifumotion.prediction.assimilate.AssimilationSettings`).
    surrogate_memory_s
        The online surrogate's memory (s); default the span of the paper's training frames
        scaled to ``setup.frames`` (the data the offline surrogate and the calibration see).
    """

    def __init__(self, spec, k, setup, frame0: np.ndarray, mask0: np.ndarray, horizons_frames, *,
                 frames_expected: int | None = None, settings=None, progress=None,
                 surrogate_memory_s: float | None = None):
        import time

        from hifumotion.contour import Contour
        from hifumotion.creep.scene_run import scene_material
        from hifumotion.estimation.model import scene_for
        from hifumotion.metrics import centroid
        from hifumotion.observed.solids import imaging_plane, known_solids
        from hifumotion.prediction.assimilate import OnlineAssimilator, points_observation
        from hifumotion.speckle import SpeckleTracker
        from hifumotion.speckle.follow import tracker_solids

        tell = progress or (lambda stage, fraction: None)
        self.horizons = sorted({int(h) for h in horizons_frames})
        if not self.horizons or self.horizons[0] < 1:
            raise InputError(f"horizons must be whole frames ≥ 1, got {horizons_frames}", "horizons")
        frame0 = np.asarray(frame0)
        mask0 = np.asarray(mask0, bool)
        if frame0.ndim != 2 or mask0.shape != frame0.shape:
            raise InputError(f"expected frame 0 and its target mask of one shape (H, W), got {frame0.shape} "
                             f"and {mask0.shape}", "frame0")
        if not mask0.any():
            raise InputError("frame 0's target mask is empty", "mask0")
        self.dt = float(spec.frame_interval_s)
        self.pixel_mm = float(setup.pixel_mm)
        last = max(int(frames_expected or setup.frames) - 1, max(self.horizons) + 1)
        t0 = time.perf_counter()
        self.model = spec.reduced(k, last, progress=lambda f: tell("reduced model", f))
        self.construction_s = time.perf_counter() - t0
        scene = scene_for(spec, k, last)
        plane = imaging_plane(setup)
        axes = np.stack([np.asarray(plane.u, float), np.asarray(plane.v, float)])
        h = points_observation(self.model, spec.points_mm, axes, spec.spacing_mm)
        if scene.bar.enabled and scene.bar.control == "travel":
            # a driven bar: the scale multiplies its programmed travel, and its force is a result
            travel_mm = scene.bar.travel_schedule()
            self.filter = OnlineAssimilator(self.model, scene_material(scene), lambda t: 0.0, h, self.dt, settings,
                                            travel_m=lambda t: float(travel_mm(t)) * 1e-3)
        else:
            self.filter = OnlineAssimilator(self.model, scene_material(scene), scene.bar.schedule(), h, self.dt,
                                            settings)
        solids = known_solids(plane, setup)
        self.tracker = SpeckleTracker(frame0, self.pixel_mm, **tracker_solids(solids))
        self.shape = frame0.shape
        self.points_px = plane.to_pixels(spec.points_mm)            # the model's points A on frame 0
        self.a0 = spec.points_mm @ axes.T - np.asarray(plane.origin_mm, float) @ axes.T   # the same, image mm
        # the target's material boundary on frame 0, carried as follow() carries it
        self.contour0 = Contour.from_mask(mask0, self.pixel_mm)
        self.boundary_px = self.contour0.resampled(1.0).points_px
        self.tracked0 = np.asarray(centroid(mask0, self.pixel_mm), float)
        # the predicted section: the tracked frame-0 section moved as the polygon of the points A
        self.base = self.tracked0 - polygon_centroid(self.a0)
        self.steps: list[OnlineStep] = []
        self.surrogate = self._surrogate(setup, last, surrogate_memory_s)
        self.surrogate.update(0, self.tracked0)

    def _surrogate(self, setup, last: int, memory_s: float | None):
        """The online surrogate on ``setup``'s program over the frames the session expects."""
        from hifumotion.estimation.protocol import default_frames
        from hifumotion.prediction.surrogates import OnlineDriveRegression

        if memory_s is None:
            training = default_frames(setup.frames)[0] if setup.frames >= 20 else [0, setup.frames - 1]
            memory_s = max(max(training) - min(training), 1) * self.dt
        program = setup.push.program(np.arange(last + max(self.horizons) + 1) * self.dt)
        return OnlineDriveRegression(program, self.dt, memory_s)

    @classmethod
    def start(cls, spec, k, setup, frame0: np.ndarray, initial_contour, horizons_frames, *,
              boundary_offset_mm: float = 0.0, continue_bloom: bool = False,
              bloom_shape_mm: np.ndarray | None = None, **options) -> "OnlineSession":
        """A session from what a scanner gives before the push: frame 0 and the clinician's
        contour on it (``initial_contour``, anything :func:`~hifumotion.segmentation.segment`
        takes). Frame 0's target is segmented as the calibration's tracking segments it (GLCV,
        the known solids out, moved inwards by ``boundary_offset_mm``, the bar's bloom continued
        where ``continue_bloom``, by ``bloom_shape_mm`` where the calibration's reconstruction
        decided it: :func:`~hifumotion.speckle.segment_target`); ``options`` are the constructor's."""
        from hifumotion.observed.solids import check_bar_in_image, imaging_plane, known_solids
        from hifumotion.speckle import segment_target
        from hifumotion.speckle.displacement import unit_frames

        frame0 = np.asarray(frame0)
        if frame0.ndim != 2 or tuple(frame0.shape) != tuple(setup.imaging.image_shape):
            raise InputError(f"frame 0 has shape {frame0.shape}; setup.json's imaging.image_shape is "
                             f"{tuple(setup.imaging.image_shape)}", "frame0")
        solids = known_solids(imaging_plane(setup), setup)
        check_bar_in_image(frame0, solids, "setup.json")
        first = segment_target(unit_frames(frame0[None])[0], initial_contour, setup.pixel_mm, solids=solids,
                               boundary_offset_mm=boundary_offset_mm, continue_bloom=continue_bloom,
                               bloom_shape_mm=bloom_shape_mm)
        return cls(spec, k, setup, frame0, first.mask, horizons_frames, **options)

    @property
    def frame(self) -> int:
        """The last frame taken (0 before the first :meth:`push`)."""
        return len(self.steps)

    def push(self, frame: np.ndarray) -> OnlineStep:
        """Take the next frame (``(H, W)``, uint8 or [0, 1]): track it, assimilate it, aim ahead."""
        import time

        from hifumotion.contour import Contour
        from hifumotion.metrics import centroid
        from hifumotion.speckle import sample_field
        from hifumotion.speckle.follow import carry_points

        started = time.perf_counter()
        field_mm, quality = self.tracker.update(frame)
        tracked_at = time.perf_counter()
        d, q = sample_field(field_mm, quality, self.points_px)
        seen = np.isfinite(d).all(1) & (q > 0)
        y = np.where(seen[:, None], d, np.nan).ravel()
        est = self.filter.assimilate(y, self.horizons, np.repeat(np.where(seen, q, 1.0), 2))
        predicted = {h: self.base + polygon_centroid(self.a0 + est.predicted_mm[h].reshape(-1, 2))
                     for h in self.horizons}

        def tracked_section():
            boundary, _ = carry_points(self.boundary_px, field_mm, quality, self.tracker.spacing_mm)
            mask = Contour(boundary, self.contour0.spacing_mm).to_mask(self.shape)
            return np.asarray(centroid(mask, self.pixel_mm), float) if mask.any() else np.full(2, np.nan)

        anchored = self.filter.settings.anchor_to_tracking
        if anchored:
            # the present from the image, the motion ahead from the model
            tracked = tracked_section()
            now = self.base + polygon_centroid(self.a0 + est.analysed_mm.reshape(-1, 2))
            if np.isfinite(tracked).all():
                predicted = {h: tracked + p - now for h, p in predicted.items()}
        aimed = time.perf_counter()
        if not anchored:
            # the tracked section (for the record and the hold baseline: not on the aim's path)
            tracked = tracked_section()
        t = len(self.steps) + 1
        # the surrogate that knows the same inputs, beside the physics (outside its latency)
        self.surrogate.update(t, tracked)
        surrogate = self.surrogate.predict(t, self.horizons)
        step = OnlineStep(t, t * self.dt, predicted, tracked, est.scale, est.scale_std,
                          1000.0 * (tracked_at - started), est.latency_ms, 1000.0 * (aimed - started), surrogate)
        self.steps.append(step)
        return step

    def result(self) -> "OnlineResult":
        """Every frame taken so far as an :class:`OnlineResult`."""
        steps = self.steps
        frames = np.array([s.frame for s in steps], int)
        predicted = {h: np.array([s.predicted_mm[h] for s in steps]).reshape(-1, 2) for h in self.horizons}
        tracked = np.vstack([self.tracked0[None]] + [s.tracked_mm[None] for s in steps])
        return OnlineResult(frames, self.dt, predicted, tracked,
                            np.array([s.scale for s in steps]), np.array([s.scale_std for s in steps]),
                            np.array([s.latency_ms for s in steps]), self.construction_s,
                            np.array([s.tracking_ms for s in steps]), np.array([s.filter_ms for s in steps]),
                            dict(self.filter.stats),
                            {h: np.array([s.surrogate_mm[h] for s in steps]).reshape(-1, 2) for h in self.horizons})


def online_loop(spec, k, observation, horizons_frames, settings=None, progress=None) -> OnlineResult:
    """Replay the cine of ``observation`` (a :class:`~hifumotion.estimation.prepare.Observation`)
    through an :class:`OnlineSession` of the calibrated model ``spec`` at ``k``, frame by frame
    from frame 1, predicting ``horizons_frames`` frames ahead. The session tracks the frames
    itself, as it would a scanner's; frame 0's target is the observation's."""
    tell = progress or (lambda stage, fraction: None)
    observed = observation.observed
    frames = observed.frames
    session = OnlineSession(spec, k, observed.setup, frames[0], observation.frame_masks[0], horizons_frames,
                            frames_expected=len(frames), settings=settings, progress=tell)
    for t in range(1, len(frames)):
        session.push(frames[t])
        tell("online", t / (len(frames) - 1))
    return session.result()


def watch_frames(folder, first: int = 1, prefix: str = "frame_", timeout_s: float = 10.0, poll_s: float = 0.002,
                 stop=None):
    """The frames a scanner writes into ``folder`` as ``PREFIXNNNN.png`` (numbered from 0), in
    order from number ``first``, each yielded ``(number, (H, W) array)`` as soon as it can be
    read. A file still being written (not yet a whole PNG) is read again until it is; the
    watch ends when the next number has not appeared for ``timeout_s`` seconds, or when
    ``stop()`` is true. A frame written out of turn (``frame_0012`` before ``frame_0011``)
    waits for its turn."""
    import time
    from pathlib import Path

    from hifumotion.io.raster import read_raster_array

    root = Path(folder)
    number = int(first)
    waited_since = time.perf_counter()
    while stop is None or not stop():
        path = next((p for p in (root / f"{prefix}{number:04d}.png", root / f"{prefix}{number}.png") if p.is_file()),
                    None)
        if path is not None:
            try:
                image = read_raster_array(path)[0]
            except InputError:
                image = None                # not yet whole: the scanner is still writing it
            if image is not None:
                yield number, image
                number += 1
                waited_since = time.perf_counter()
                continue
        if time.perf_counter() - waited_since > timeout_s:
            return
        time.sleep(poll_s)


__all__ = ["OnlineResult", "OnlineSession", "OnlineStep", "online_loop", "polygon_centroid", "watch_frames"]
