"""An imaging plane in the tank frame: where a frame's pixels lie (mm)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Plane:
    """An imaging plane in the tank frame (mm).

    ``origin_mm`` is the position of pixel (0, 0)'s centre; ``u`` the direction of
    increasing column (image x), ``v`` of increasing row (image y, usually depth:
    downwards); ``shape`` (rows, cols) and ``pixel_mm`` the image grid.
    """

    origin_mm: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]
    shape: tuple[int, int]
    pixel_mm: float

    def points_mm(self) -> np.ndarray:
        """``(rows, cols, 3)`` positions (mm) of the pixel centres."""
        r = np.arange(self.shape[0]) * self.pixel_mm
        c = np.arange(self.shape[1]) * self.pixel_mm
        o = np.asarray(self.origin_mm, float)
        return o + r[:, None, None] * np.asarray(self.v, float) + c[None, :, None] * np.asarray(self.u, float)

    def to_pixels(self, points_mm: np.ndarray) -> np.ndarray:
        """In-plane pixel coordinates ``(x = col, y = row)`` of 3D points (mm)."""
        d = np.asarray(points_mm, float) - np.asarray(self.origin_mm, float)
        return np.stack([d @ np.asarray(self.u, float), d @ np.asarray(self.v, float)], axis=-1) / self.pixel_mm


__all__ = ["Plane"]
