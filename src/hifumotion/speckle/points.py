"""Given points followed through a cine loop: landmarks, a contour's vertices, open curves.

A region is followed by carrying frame 0's contour through the dense speckle field
(:mod:`.follow`); a handful of points a user names — an anatomical landmark, the vertices of a
tongue surface — need only their own neighbourhoods. Each point is moved from frame to frame by
two independent estimators of the same motion, the step taken is their mean, and the result is
registered once more straight to the point's anchor frame, so steps do not add up their bias:

* pyramidal Lucas–Kanade on the point's window (Bouguet 2000, OpenCV ``calcOpticalFlowPyrLK``):
  sub-pixel, local, fooled by a window that straddles two motions;
* DIS dense flow (Kroeger et al. 2016, OpenCV ``DISOpticalFlow``, its fast preset), sampled
  bilinearly at the point: regularised over the image, smoother across boundaries.

Their errors are little correlated on real cine, so their mean errs less than either
(docs/decisions.md, "Following points in real cine"); where they disagree the point is
uncertain, and that disagreement (px) is kept per point and frame as its quality measure.
The anchor is frame 0 until the point's neighbourhood there no longer matches the current
frame's, then the frame where that happened (:meth:`PointTracker._anchored`). Frame ``t``'s
positions use frames ≤ ``t`` only, so :class:`PointTracker` runs on frames as a
scanner delivers them and :func:`track_points` over a recorded cine gives the same positions.

References
----------
J.-Y. Bouguet, "Pyramidal implementation of the Lucas Kanade feature tracker", Intel Corp., 2000.
T. Kroeger, R. Timofte, D. Dai, L. Van Gool, "Fast optical flow using dense inverse search",
ECCV 2016.
I. Matthews, T. Ishikawa, S. Baker, "The template update problem", IEEE TPAMI 26(6), 2004.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hifumotion.errors import InputError

#: Side (px) of the Lucas–Kanade window, at the finest of its levels.
WINDOW_PX = 31
#: Pyramid levels above the finest (each halves the image): steps of up to ≈ 2**LEVELS × the window.
LEVELS = 3
#: The finest pyramid level DIS estimates on (0 = full resolution, each level halves it). At a
#: quarter of the resolution its steps on speckle are biased by up to a tenth of a pixel (half the
#: resolution: a hundredth), which the anchoring removes; on the real cine both scored alike, and
#: a quarter costs 3 ms a frame at 320 × 240 where a half costs 7 (docs/decisions.md).
DIS_FINEST_SCALE = 2
#: A point's direct registration to its anchor frame replaces the chained position when the two
#: agree within this (px); further apart, the anchor is renewed (:meth:`PointTracker._anchored`).
ANCHOR_TOLERANCE_PX = 0.5
#: … and when the two neighbourhoods still look alike: normalised cross-correlation at least this.
ANCHOR_NCC = 0.9


@dataclass
class PointTrack:
    """Every frame's positions of the given points.

    Attributes
    ----------
    positions_px
        float ``(T, N, 2)``: (x, y) = (column, row) px of each point in each frame; frame 0's
        are the points given.
    disagreement_px
        float ``(T, N)``: distance (px) between the two estimators' steps into each frame
        (0 at frame 0) — large where the motion is not resolved.
    seconds_per_frame
        Wall time of each frame (s); frame 0 is 0.
    names
        The points' names (``point_<i>`` where none were given).
    """

    positions_px: np.ndarray
    disagreement_px: np.ndarray
    seconds_per_frame: np.ndarray
    names: tuple[str, ...] = ()

    @property
    def n_frames(self) -> int:
        return int(self.positions_px.shape[0])

    def positions_mm(self, spacing_mm) -> np.ndarray:
        """``(T, N, 2)`` (x, y) mm for a pixel size ``spacing_mm`` (mm, scalar or (row, col))."""
        from hifumotion.sequence import as_spacing_mm

        row, col = as_spacing_mm(spacing_mm)
        return self.positions_px * np.array([col, row])


def check_points(points_px, shape: tuple[int, int]) -> np.ndarray:
    """``points_px`` as float32 ``(N, 2)`` (x, y) px, checked to be finite and on an image of ``shape`` (H, W)."""
    p = np.asarray(points_px, float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise InputError(f"expected points as an (N, 2) array of (x, y) px with N ≥ 1, got shape {p.shape}",
                         "points")
    if not np.all(np.isfinite(p)):
        raise InputError("points hold NaN or infinite coordinates", "points")
    h, w = shape
    outside = (p[:, 0] < 0) | (p[:, 0] > w - 1) | (p[:, 1] < 0) | (p[:, 1] > h - 1)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise InputError(f"point {i} at ({p[i, 0]:g}, {p[i, 1]:g}) px lies outside the {w} × {h} px image",
                         "points")
    return p.astype(np.float32)


def _patch_ncc(a: np.ndarray, pa: np.ndarray, b: np.ndarray, pb: np.ndarray, size: int) -> np.ndarray:
    """Normalised cross-correlation of the ``size`` × ``size`` patches of ``a`` around ``pa`` and
    of ``b`` around ``pb`` (``(N, 2)`` px each, sampled bilinearly), one value a pair."""
    import cv2

    offsets = np.arange(size, dtype=np.float32) - (size - 1) / 2.0

    def patches(image, p):
        mx = (p[:, 0, None, None] + offsets[None, None, :]).astype(np.float32)
        my = (p[:, 1, None, None] + offsets[None, :, None]).astype(np.float32)
        mx, my = np.broadcast_to(mx, (len(p), size, size)), np.broadcast_to(my, (len(p), size, size))
        got = cv2.remap(image.astype(np.float32), np.ascontiguousarray(mx.reshape(-1, size)),
                        np.ascontiguousarray(my.reshape(-1, size)), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        got = got.reshape(len(p), -1)
        return got - got.mean(axis=1, keepdims=True)

    if len(pa) == 0:
        return np.zeros(0)
    x, y = patches(a, pa), patches(b, pb)
    return (x * y).sum(1) / np.maximum(np.sqrt((x * x).sum(1) * (y * y).sum(1)), 1e-12)


def _u8(frame: np.ndarray) -> np.ndarray:
    """One frame as 8-bit grey (what both estimators take), as the region tracker makes it:
    uint8 kept, anything else to [0, 1] (:func:`~.displacement.unit_frames`) and scaled."""
    from hifumotion.speckle._flow import _u8 as flow_u8
    from hifumotion.speckle.displacement import unit_frames

    f = np.asarray(frame)
    return f if f.dtype == np.uint8 else flow_u8(unit_frames(f[None])[0])


class PointTracker:
    """Points followed one frame at a time (what :func:`track_points` runs over a cine).

    Parameters
    ----------
    frame0
        The first frame, ``(H, W)``: uint8, or grey levels in [0, 1].
    points_px
        ``(N, 2)`` (x, y) px of the points on ``frame0``.
    window_px
        Side of the Lucas–Kanade window (px, odd, ≥ 5).
    levels
        Pyramid levels of the Lucas–Kanade search (0 = the full resolution only).
    """

    def __init__(self, frame0: np.ndarray, points_px, *, window_px: int = WINDOW_PX, levels: int = LEVELS):
        import cv2

        frame0 = np.asarray(frame0)
        if frame0.ndim != 2 or min(frame0.shape) < 8:
            raise InputError(f"expected one frame (H, W) of at least 8 × 8 px, got shape {frame0.shape}", "frames")
        if int(window_px) < 5:
            raise InputError(f"expected a window of at least 5 px, got {window_px}", "window_px")
        if not 0 <= int(levels) <= 6:
            raise InputError(f"expected 0 … 6 pyramid levels, got {levels}", "levels")
        self.shape = frame0.shape
        self.window = int(window_px) | 1
        self.levels = int(levels)
        self.points = check_points(points_px, self.shape)
        self.previous = _u8(frame0)
        self.dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_FAST)
        self.dis.setFinestScale(DIS_FINEST_SCALE)
        self.criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        self.frames_seen = 1
        # each point's anchor: the frame it is registered to directly, and where it was there
        self.anchor_frame = np.zeros(len(self.points), int)
        self.anchor_points = self.points.copy()
        self.anchor_images = {0: self.previous}

    def update(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The next frame: the points' positions ``(N, 2)`` px and the estimators' disagreement ``(N,)`` px."""
        current = _u8(frame)
        if current.shape != self.shape:
            raise InputError(f"expected a frame of shape {self.shape}, got {current.shape}", "frame")
        step, disagreement = self._step(current)
        h, w = self.shape
        # a point carried off the image stays on its edge (its window has nothing beyond)
        chained = np.column_stack([np.clip(self.points[:, 0] + step[:, 0], 0, w - 1),
                                   np.clip(self.points[:, 1] + step[:, 1], 0, h - 1)]).astype(np.float32)
        self.points = self._anchored(current, chained)
        self.previous = current
        self.frames_seen += 1
        return self.points.astype(float), disagreement.astype(float)

    def _step(self, current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each point's step from the previous frame (px): the mean of Lucas–Kanade's and DIS's;
        and their disagreement (px)."""
        import cv2

        p = self.points
        moved, status, _ = cv2.calcOpticalFlowPyrLK(self.previous, current, p.reshape(-1, 1, 2), None,
                                                    winSize=(self.window, self.window), maxLevel=self.levels,
                                                    criteria=self.criteria)
        step_lk = moved.reshape(-1, 2) - p
        flow = self.dis.calc(self.previous, current, None)
        step_dis = cv2.remap(flow, p[:, 0].reshape(1, -1), p[:, 1].reshape(1, -1), cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE).reshape(-1, 2)
        lost = (status.ravel() == 0) | ~np.all(np.isfinite(step_lk), axis=1)
        step_lk[lost] = step_dis[lost]       # a window the search lost: the dense flow alone
        return 0.5 * (step_lk + step_dis), np.hypot(*(step_lk - step_dis).T)

    def _anchored(self, current: np.ndarray, chained: np.ndarray) -> np.ndarray:
        """The chained positions corrected against each point's anchor frame.

        A chain of frame-to-frame steps adds up every step's bias (a few hundredths of a pixel
        on speckle, pixels over a cine). Each point is registered again, from where it was on
        its anchor frame (frame 0 at first) straight to the current frame, starting at the
        chained position; if that lands within :data:`ANCHOR_TOLERANCE_PX` of the chain it is
        the same match without the chain's bias, and it is kept. If not, the anchor no longer
        looks like this frame (the tissue has deformed or turned): the chained position is kept
        and the current frame becomes the point's anchor, so the error accumulates only from
        one such change to the next, not from frame to frame (Matthews et al. 2004).
        """
        import cv2

        out = chained.copy()
        failed = np.zeros(len(out), bool)
        for a in np.unique(self.anchor_frame):
            sel = np.flatnonzero(self.anchor_frame == a)
            found, status, _ = cv2.calcOpticalFlowPyrLK(
                self.anchor_images[a], current, self.anchor_points[sel].reshape(-1, 1, 2),
                chained[sel].reshape(-1, 1, 2).copy(), winSize=(self.window, self.window), maxLevel=1,
                criteria=self.criteria, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
            found = found.reshape(-1, 2)
            ok = ((status.ravel() > 0) & np.all(np.isfinite(found), axis=1)
                  & (np.hypot(*(found - chained[sel]).T) < ANCHOR_TOLERANCE_PX))
            ok[ok] = _patch_ncc(self.anchor_images[a], self.anchor_points[sel[ok]], current, found[ok],
                                self.window) >= ANCHOR_NCC
            out[sel[ok]] = found[ok]
            failed[sel[~ok]] = True
        if failed.any():
            t = self.frames_seen
            self.anchor_frame[failed] = t
            self.anchor_points[failed] = chained[failed]
            self.anchor_images[t] = current
            used = set(self.anchor_frame.tolist())
            self.anchor_images = {k: v for k, v in self.anchor_images.items() if k in used}
        return out


def track_points(frames, points_px, *, names=None, window_px: int = WINDOW_PX, levels: int = LEVELS,
                 progress: bool = False) -> PointTrack:
    """Follow given points from frame 0 through a cine loop.

    Parameters
    ----------
    frames
        ``(T, H, W)`` uint8 or grey levels in [0, 1], or an :class:`~hifumotion.sequence.ImageSequence`.
    points_px
        ``(N, 2)`` (x, y) px of the points on frame 0 (column, row; pixel centres at integers).
    names
        Names of the points (``N`` strings; default ``point_0`` …), kept with the track.
    window_px, levels
        :class:`PointTracker`'s.
    progress
        Show a progress bar.

    Returns
    -------
    PointTrack
    """
    from hifumotion.sequence import ImageSequence

    if isinstance(frames, ImageSequence):
        frames = frames.frames
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.shape[0] < 1:
        raise InputError(f"expected frames (T, H, W), got shape {frames.shape}", "frames")
    tracker = PointTracker(frames[0], points_px, window_px=window_px, levels=levels)
    if names is None:
        names = tuple(f"point_{i}" for i in range(len(tracker.points)))
    names = tuple(str(n) for n in names)
    if len(names) != len(tracker.points):
        raise InputError(f"expected {len(tracker.points)} names, got {len(names)}", "names")
    positions = [tracker.points.astype(float)]
    disagreement = [np.zeros(len(tracker.points))]
    seconds = [0.0]
    steps = range(1, frames.shape[0])
    if progress:
        from hifumotion.console import track as progress_bar

        steps = progress_bar(steps, "following points", total=len(steps))
    for t in steps:
        t0 = time.perf_counter()
        p, d = tracker.update(frames[t])
        seconds.append(time.perf_counter() - t0)
        positions.append(p)
        disagreement.append(d)
    return PointTrack(np.stack(positions), np.stack(disagreement), np.array(seconds), names)


__all__ = ["ANCHOR_TOLERANCE_PX", "LEVELS", "PointTrack", "PointTracker", "WINDOW_PX", "check_points", "track_points"]
