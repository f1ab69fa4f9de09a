"""The frame-0 shape of the target, which the model's displacement carries to later frames.

The reference shape is the frame-0 contour in the imaging plane, continued out of the
plane by the reconstructed tissue, so a tissue that moves across the plane brings its
neighbouring section into view:

    d(X) = d₀(X_plane) + [d_rec(X) − d_rec(X projected onto the plane)]   (mm, > 0 inside)

with d₀ the signed distance to the frame-0 contour and d_rec the reconstruction's. The
observation builds it (:meth:`~hifumotion.estimation.prepare.Observation.reference_shape`),
the calibration folder stores it and the prediction uses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from hifumotion.estimation.objective import signed_distance_px
from hifumotion.scene import Plane


@dataclass
class ReferenceShape:
    """The tissue at frame 0 as a signed distance (mm, positive inside) in the tank frame.

    Attributes
    ----------
    frame0_mask
        The target in the imaging plane at frame 0 (observed grid).
    plane
        The imaging plane.
    rec_distance_mm, rec_voxel_mm, rec_origin_mm
        The reconstruction's signed distance grid ``(Z, Y, X)`` in the tank frame
        (``None``: the in-plane shape only).
    """

    frame0_mask: np.ndarray
    plane: Plane
    rec_distance_mm: np.ndarray | None = None
    rec_voxel_mm: float = 1.0
    rec_origin_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        self._d0 = signed_distance_px(self.frame0_mask) * self.plane.pixel_mm

    def _rec(self, p: np.ndarray) -> np.ndarray:
        idx = (p[:, ::-1] - np.asarray(self.rec_origin_mm)[::-1]) / self.rec_voxel_mm
        return ndimage.map_coordinates(self.rec_distance_mm, idx.T, order=1, mode="nearest")

    def distance(self, points_mm: np.ndarray) -> np.ndarray:
        p = np.asarray(points_mm, float).reshape(-1, 3)
        xy = self.plane.to_pixels(p)
        d = ndimage.map_coordinates(self._d0, [xy[:, 1], xy[:, 0]], order=1, mode="nearest")
        if self.rec_distance_mm is not None:
            normal = np.cross(np.asarray(self.plane.u, float), np.asarray(self.plane.v, float))
            off = (p - np.asarray(self.plane.origin_mm, float)) @ normal
            d = d + self._rec(p) - self._rec(p - off[:, None] * normal)
        return d

    def inside(self, points_mm: np.ndarray) -> np.ndarray:
        return self.distance(points_mm) > 0

    def reconstruction_distance(self, points_mm: np.ndarray) -> np.ndarray | None:
        """The reconstruction's own signed distance (mm, positive inside) at ``points_mm``
        ``(..., 3)`` (tank frame), without the frame-0 contour; ``None`` without a reconstruction."""
        if self.rec_distance_mm is None:
            return None
        p = np.asarray(points_mm, float)
        return self._rec(p.reshape(-1, 3)).reshape(p.shape[:-1])


__all__ = ["ReferenceShape"]
