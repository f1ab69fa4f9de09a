"""The estimation objective: how far the model's contour points are from the observed contours.

The paper (Section 2.2.2) compares the displacement D̂_t the model gives the
contour points A with the observed one D_t and sums ``S_t = Σ_{a∈A} |D̂_t(a) − D_t(a)|``.
A contour only shows where the boundary is, not which material point sits where
along it, so the observed D_t(a) is known only across the boundary. Here the
difference for point a is therefore the **signed distance (mm) of the model's
point a at frame t to the observed contour of frame t** — the normal component of
D̂_t(a) − D_t(a), exact for small steps (see ``docs/decisions.md``).

The observed contours enter as signed distance maps (px, positive inside),
sampled bilinearly at the model's points projected into the imaging plane.

With speckle tracking (:mod:`hifumotion.speckle`) the observation also measures the
material points' displacement itself, along the boundary as well as across it. The
objective can then add, for each point a and training frame t, the in-plane difference
``(D̂_t(a) − D_t(a)) · q_t(a)`` (mm, both components), weighted by the tracking's quality
``q`` at a (0 where the point was occluded): the paper's S_t with the tangential part
that a contour alone cannot give (:meth:`TrainingData.with_displacement`). Since the model's
points A follow the material (:func:`~hifumotion.particles.section.material_displacement`),
as the tracked ones do, this is the default wherever speckle tracking observed the motion
(``CalibrationSettings.objective = "auto"``; docs/decisions.md, "The points A follow the material; the floor re-measured; the displacement fitted").

The contour residuals themselves can be weighted by the same quality
(:meth:`TrainingData.with_contour_weights`, ``quality_weights``; on by default since the
top under the bar is continued and the bar's travel fitted, docs/decisions.md, "The top under
the bar, the bar's travel"): a point whose speckle the image does not show — under the bar's blur, on the floor —
was carried by a displacement filled in from its neighbours, and so was the observed
boundary there (docs/decisions.md, "The benchmark on four twins: what limits the fit, quality weights").

The bar is observed too: its echo is a large rigid body the speckle tracker follows to a few
per cent (:attr:`~hifumotion.speckle.DisplacementSeries.rigid_shift_mm`), and under a
force-controlled push its travel is what F/E sets most directly. With
:meth:`TrainingData.with_bar` the objective adds, per training frame, the in-plane difference
(mm, x and y) of the model's bar displacement and the tracked one, weighted by √M (M points A):
the bar's shift is estimated from its whole echo, so it counts as much as the whole contour
(docs/decisions.md, "The top under the bar, the bar's travel, quality weights on").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from hifumotion.errors import InputError
from hifumotion.scene import Plane


def signed_distance_px(mask: np.ndarray) -> np.ndarray:
    """Signed distance (px, positive inside) to the 0.5 iso-line of a mask."""
    m = np.asarray(mask, bool)
    inside = ndimage.distance_transform_edt(m)
    outside = ndimage.distance_transform_edt(~m)
    return np.where(m, inside - 0.5, -(outside - 0.5))


@dataclass
class TrainingData:
    """The observed contours the model is fitted to.

    Attributes
    ----------
    frames
        Training frame numbers (the paper's protocol: 20, 30, …, 100).
    distance_px
        ``(n, H, W)`` signed distance maps (px) of the observed masks of those frames.
    plane
        The imaging plane (tank frame).
    """

    frames: np.ndarray
    distance_px: np.ndarray
    plane: Plane
    displacement_mm: np.ndarray | None = None     # (n, M, 2) observed in-plane D_t of the points A
    displacement_weight: np.ndarray | None = None  # (n, M) its quality (0: not observed)
    contour_weight: np.ndarray | None = None       # (n, M) weight of each point's contour residual (None: 1)
    bar_shift_mm: np.ndarray | None = None         # (n, 2) tracked in-plane displacement of the bar (mm)
    bar_weight: float = 0.0                        # weight of its residuals (√M, :meth:`with_bar`)

    def with_bar(self, rigid_shift_mm: np.ndarray, points: int) -> "TrainingData":
        """These data plus the bar's tracked displacement (``(T, 2)`` x, y in mm from frame 0,
        every frame) at the training frames, weighted by √``points`` (module docstring)."""
        from dataclasses import replace

        shift = np.asarray(rigid_shift_mm, float)
        if shift.ndim != 2 or shift.shape[1] != 2 or len(shift) <= self.last_frame:
            raise InputError(f"expected the bar's shift for every frame up to {self.last_frame}, (T, 2) mm; "
                             f"got shape {shift.shape}", "bar_shift_mm")
        if not np.isfinite(shift[self.frames]).all():
            raise InputError("the bar's tracked shift is not finite at every training frame", "bar_shift_mm")
        return replace(self, bar_shift_mm=shift[self.frames], bar_weight=float(np.sqrt(points)))

    def with_contour_weights(self, series, points_mm: np.ndarray) -> "TrainingData":
        """These data with each contour residual weighted by the speckle tracking's quality
        (clipped to [0, 1]) at the model's point A (``points_mm``, ``(M, 3)`` on the frame-0
        contour, pool frame) in each training frame, read from a
        :class:`~hifumotion.speckle.DisplacementSeries` on the imaging plane."""
        from dataclasses import replace

        _, w = self._observed_at(series, points_mm)
        if not (w > 0).any():
            raise InputError("the speckle tracking sees none of the contour points in any training frame; "
                             "calibrate without quality weights", "quality_weights")
        return replace(self, contour_weight=w)

    def with_displacement(self, series, points_mm: np.ndarray) -> "TrainingData":
        """These data plus the observed displacement of the model's points A (``points_mm``,
        ``(M, 3)`` on the frame-0 contour, pool frame) at the training frames, read from a
        :class:`~hifumotion.speckle.DisplacementSeries` on the imaging plane."""
        from dataclasses import replace

        disp, weight = self._observed_at(series, points_mm)
        return replace(self, displacement_mm=disp, displacement_weight=weight)

    def _observed_at(self, series, points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(n, M, 2)`` tracked displacement (mm, 0 where unknown) and ``(n, M)`` quality in
        [0, 1] (0 where unknown) of the points at the training frames."""
        px = self.plane.to_pixels(points_mm)
        disp, weight = [], []
        for f in self.frames:
            d, q = series.at(px, int(f))
            ok = np.isfinite(d).all(1)
            disp.append(np.where(ok[:, None], d, 0.0))
            weight.append(np.where(ok, np.clip(q, 0.0, 1.0), 0.0))
        return np.stack(disp), np.stack(weight)

    def width(self, points: int) -> int:
        """Residuals per training frame for ``points`` points A: 1 each, 3 with displacements;
        2 more with the bar."""
        return points * (3 if self.displacement_mm is not None else 1) + (2 if self.bar_shift_mm is not None else 0)

    @classmethod
    def from_masks(cls, masks: np.ndarray, frames, plane: Plane) -> "TrainingData":
        frames = np.asarray(sorted(int(f) for f in frames))
        if len(frames) == 0:
            raise InputError("no training frames", "training_frames")
        if frames[0] <= 0 or frames[-1] >= len(masks):
            raise InputError(f"training frames must lie in 1 … {len(masks) - 1}, got {frames.tolist()}",
                             "training_frames")
        empty = [int(f) for f in frames if not masks[f].any()]
        if empty:
            raise InputError(f"no target in training frames {empty}", "training_frames")
        return cls(frames, np.stack([signed_distance_px(masks[f]) for f in frames]), plane)

    @property
    def last_frame(self) -> int:
        return int(self.frames[-1])

    @property
    def pixel_mm(self) -> float:
        return float(self.plane.pixel_mm)


def residuals_mm(points_mm: np.ndarray, data: TrainingData, upto: int | None = None,
                 bar_mm: np.ndarray | None = None) -> np.ndarray:
    """``(n, M)`` signed distances (mm) of the model's points to the observed contours; with
    observed displacements, ``(n, 3M)``: those, then the weighted in-plane displacement
    differences (mm) of each point, x and y in turn; with the bar's (``data.bar_shift_mm``),
    two more columns: the weighted in-plane difference (mm) of the model's bar displacement
    (``bar_mm``, the run's ``(F, 3)`` bar centre) and the tracked one.

    ``points_mm`` is a run's ``(F, M, 3)`` point positions indexed by frame number;
    row i belongs to training frame ``data.frames[i]``; ``upto`` keeps the first
    ``upto`` training frames. Positive: the model's point lies inside the observed contour.
    With ``data.contour_weight`` each point's distance is multiplied by its weight.
    """
    n = len(data.frames) if upto is None else int(upto)
    m = points_mm.shape[1]
    if data.bar_shift_mm is not None and bar_mm is None:
        raise InputError("the objective compares the bar's motion but the run gave no bar positions", "bar_mm")
    out = np.empty((n, data.width(m)))
    axes = np.stack([np.asarray(data.plane.u, float), np.asarray(data.plane.v, float)])   # (2, 3)
    for i in range(n):
        f = int(data.frames[i])
        if f >= len(points_mm):
            raise InputError(f"the run ended before training frame {f}", "run")
        xy = data.plane.to_pixels(points_mm[f])
        out[i, :m] = ndimage.map_coordinates(data.distance_px[i], [xy[:, 1], xy[:, 0]], order=1,
                                             mode="nearest") * data.pixel_mm
        if data.contour_weight is not None:
            out[i, :m] *= data.contour_weight[i]
        if data.displacement_mm is not None:
            model = (points_mm[f] - points_mm[0]) @ axes.T                     # (M, 2) in-plane, mm
            diff = (model - data.displacement_mm[i]) * data.displacement_weight[i][:, None]
            out[i, m:3 * m] = diff.ravel()
        if data.bar_shift_mm is not None:
            moved = (np.asarray(bar_mm[f], float) - np.asarray(bar_mm[0], float)) @ axes.T
            out[i, -2:] = (moved - data.bar_shift_mm[i]) * data.bar_weight
    return out


def frame_sums_mm(residuals: np.ndarray) -> np.ndarray:
    """S_t = Σ_{a∈A} |D̂_t(a) − D_t(a)| (mm) per training frame."""
    return np.abs(residuals).sum(axis=1)


__all__ = ["TrainingData", "residuals_mm", "frame_sums_mm", "signed_distance_px"]
