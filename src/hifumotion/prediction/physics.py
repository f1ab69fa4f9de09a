"""Predict the imaging plane's contours with the calibrated particle model.

The predicted section of frame t is the observed frame-0 shape carried by the
model's displacement since frame 0: a pixel q is inside when its material point
``X = q − u_t(q)`` is inside the reference shape (see
:func:`~hifumotion.particles.section.displacement_at`). The reference shape
(:class:`ReferenceShape`) is the frame-0 contour in the imaging plane, continued
out of the plane by the reconstructed tissue (:mod:`hifumotion.estimation.reference`),
so a tissue that moves across the plane brings its neighbouring section into view.

The aim point is a material point — by default the frame-0 centroid — carried by
the same displacement: where the focus should go in each frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from hifumotion.estimation.model import ModelRun, ModelSpec, Parameters, run_model
from hifumotion.estimation.reference import ReferenceShape
from hifumotion.particles.section import displacement_at, plane_displacement


def predicted_mask(positions_mm: np.ndarray, rest_mm: np.ndarray, spacing_mm: float,
                   reference: ReferenceShape, stride_px: int = 1) -> np.ndarray:
    """The predicted target mask on the imaging plane's grid (module docstring).

    The displacement is interpolated from the particles (Shepard, support 2 ``spacing_mm``)
    at every pixel by default (:func:`~hifumotion.particles.section.plane_displacement`: 7 ms
    for a 133 × 147 image and 4,400 particles). ``stride_px`` > 1 interpolates on every
    ``stride_px``-th pixel with a tree search and bilinearly in between; since the splatting
    it is slower (20 ms at stride 2) and stays for comparison only.
    """
    plane = reference.plane
    points = plane.points_mm()
    q = points.reshape(-1, 3)
    mask = np.zeros(len(q), bool)
    if stride_px == 1:
        u, covered = plane_displacement(positions_mm, rest_mm, spacing_mm, plane)
        u, covered = u.reshape(-1, 3), covered.ravel()
    else:
        u, covered = _coarse_displacement(points, positions_mm, rest_mm, spacing_mm, int(stride_px))
    mask[covered] = reference.inside(q[covered] - u[covered])
    return mask.reshape(plane.shape)


def _coarse_displacement(points: np.ndarray, positions_mm, rest_mm, spacing_mm: float, stride: int):
    """:func:`displacement_at` on every ``stride``-th pixel of ``points`` ``(H, W, 3)`` (and the last
    row and column), bilinear in between; a pixel is covered where the bilinear coverage is ≥ ½."""
    from scipy.ndimage import map_coordinates

    h, w = points.shape[:2]
    rows = np.unique(np.r_[np.arange(0, h, stride), h - 1])
    cols = np.unique(np.r_[np.arange(0, w, stride), w - 1])
    coarse = points[np.ix_(rows, cols)].reshape(-1, 3)
    u, covered = displacement_at(coarse, positions_mm, rest_mm, spacing_mm)
    grid = np.concatenate([u, covered[:, None].astype(float)], axis=1).reshape(len(rows), len(cols), 4)
    # fractional coarse indices of every pixel (rows/cols are uniform but for the last one)
    ri = np.interp(np.arange(h), rows, np.arange(len(rows)))
    ci = np.interp(np.arange(w), cols, np.arange(len(cols)))
    rr, cc = np.meshgrid(ri, ci, indexing="ij")
    fine = np.stack([map_coordinates(grid[..., k], [rr, cc], order=1, mode="nearest") for k in range(4)], axis=-1)
    fine = fine.reshape(-1, 4)
    return fine[:, :3], fine[:, 3] >= 0.5


@dataclass
class Prediction:
    """Predicted masks of the frames asked for, and the aim point in every frame."""

    masks: dict                 # frame -> bool (H, W)
    aim_mm: np.ndarray          # (F, 2) in-plane position (mm, image axes) of the aim point, frames 0 … last
    aim_plan_mm: np.ndarray     # (2,) the aim point at frame 0 (the plan)
    run: ModelRun
    pixel_mm: float
    band: object = None         # prediction.band.AimBand: the aim one standard error either way, when made


def aim_point_px(mask: np.ndarray) -> np.ndarray:
    """The frame-0 centroid ``(x = col, y = row)`` in px: the default planned focus."""
    from hifumotion.metrics import centroid

    return centroid(mask)


def predict_frames(spec: ModelSpec, k: Parameters, reference: ReferenceShape, frames, last_frame: int | None = None,
                   aim_px: np.ndarray | None = None) -> Prediction:
    """Run the model with ``k`` to the last frame asked for and predict the masks and aim."""
    from dataclasses import replace

    frames = sorted(int(f) for f in frames)
    last = int(last_frame if last_frame is not None else frames[-1])
    plane = reference.plane
    aim0 = aim_point_px(reference.frame0_mask) if aim_px is None else np.asarray(aim_px, float)
    o = np.asarray(plane.origin_mm, float)
    point = o + aim0[0] * plane.pixel_mm * np.asarray(plane.u) + aim0[1] * plane.pixel_mm * np.asarray(plane.v)
    # the aim point rides along as one more tracked material point
    run = run_model(replace(spec, points_mm=np.vstack([spec.points_mm, point])), k, last, keep_frames=frames)
    masks = {f: predicted_mask(run.kept[f], run.rest_mm, spec.spacing_mm, reference) for f in frames if f in run.kept}
    aim = plane.to_pixels(run.points_mm[:, -1]) * plane.pixel_mm
    run.points_mm = run.points_mm[:, :-1]
    return Prediction(masks, aim, aim0 * plane.pixel_mm, run, float(plane.pixel_mm))


__all__ = ["predicted_mask", "Prediction", "aim_point_px", "predict_frames"]
