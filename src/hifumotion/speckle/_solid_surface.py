"""No material inside a known solid: tracked points that the field carried into one go back to its surface.

Tissue the bar covers in a frame is occluded: its displacement is filled from the visible tissue
around it, which does not see the bar's own motion. Under a pushing bar that fill lags the
push — on the ``push_change`` twins the top of the tracked section moved 0.4 mm where the bar
moved 1.9 mm and the tissue under it 1.5 mm, and the section's centroid was 0.17 mm off
(docs/decisions.md, "Tissue cannot enter the bar"). Whatever the fill says, material cannot be
inside a solid, so a point the field puts there is moved to the solid's surface: a moving
solid's along its motion (the bar's advance pushed it there), a static one's along its
normal. It is a bound, not a measurement — a point the bar has not reached keeps the fill's
value, and the point's quality stays what the speckle said.
"""

from __future__ import annotations

import numpy as np

from hifumotion.errors import InputError


class SolidSurface:
    """A solid on frame 0's pixel grid as a signed distance and a unit normal.

    ``distance_px`` is negative inside the solid and positive outside: the one given (the
    solid's geometry, :attr:`~hifumotion.observed.solids.Solids.bar_distance_px`), else the
    mask's own, zero on its pixel edges — a surface known to half a pixel, a staircase where
    the face is tilted. ``normal`` points out of the solid (unit, (x, y)).
    """

    def __init__(self, mask: np.ndarray, distance_px: np.ndarray | None = None):
        from scipy import ndimage

        mask = np.asarray(mask, bool)
        rows, cols = np.nonzero(mask)
        self.shape = mask.shape
        #: the mask's bounding box (first row, last row + 1, first column, last column + 1)
        self.box = (int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1)
        if distance_px is not None:
            distance_px = np.asarray(distance_px, np.float32)
            if distance_px.shape != mask.shape:
                raise InputError(f"expected a signed distance of shape {mask.shape}, got {distance_px.shape}",
                                 "distance_px")
            self.distance_px = np.ascontiguousarray(distance_px)
        else:
            outside = ndimage.distance_transform_edt(~mask) - 0.5
            inside = ndimage.distance_transform_edt(mask) - 0.5
            self.distance_px = np.where(mask, -inside, outside).astype(np.float32)
        gy, gx = np.gradient(self.distance_px)
        norm = np.hypot(gx, gy)
        norm[norm == 0] = 1.0
        self.normal = (np.ascontiguousarray(gx / norm, np.float32), np.ascontiguousarray(gy / norm, np.float32))

    def push_out(self, x_px: np.ndarray, y_px: np.ndarray, shift_px=(0.0, 0.0), along=None,
                 iterations: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(x, y)`` (px, arrays of one shape) with those inside the solid — translated
        by ``shift_px`` (x, y) from frame 0 — moved onto its surface.

        ``along``: the direction (x, y) a moving solid pushes what it meets (its motion); a point
        inside goes that way until it is out, as the solid's advance would have carried it
        (sphere tracing: each step is the point's depth, which cannot cross the surface).
        Without it, or for a point still inside after ``iterations`` steps, along the solid's
        normal: the nearest surface."""
        import cv2

        sx, sy = float(shift_px[0]), float(shift_px[1])
        shape = np.shape(x_px)
        # OpenCV samples on 2-D maps: a list of points is one column
        x = np.ascontiguousarray(x_px, np.float32).reshape(shape if len(shape) == 2 else (-1, 1))
        y = np.ascontiguousarray(y_px, np.float32).reshape(x.shape)

        def sample(image, mx, my):
            return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

        direction = None
        if along is not None and np.hypot(*along) > 0:
            direction = np.asarray(along, np.float32) / np.float32(np.hypot(*along))
        # along the motion first (if any), then the normal for what is still inside
        for d in ([direction] * iterations if direction is not None else []) + [None, None]:
            mx, my = x - np.float32(sx), y - np.float32(sy)
            depth = sample(self.distance_px, mx, my)
            inside = depth < 0
            if not inside.any():
                break
            if d is None:
                dx, dy = sample(self.normal[0], mx, my), sample(self.normal[1], mx, my)
            else:
                dx, dy = d
            x = np.where(inside, x - depth * dx, x)
            y = np.where(inside, y - depth * dy, y)
        return x.reshape(shape), y.reshape(shape)

    def keep_out(self, displacement_px: np.ndarray, shift_px=(0.0, 0.0), along=None) -> np.ndarray:
        """A field ``(H, W, 2)`` (px, (x, y)) of frame-0 pixels' displacement with the material it
        carries inside the solid (translated by ``shift_px``) moved onto its surface
        (:meth:`push_out`). Only the pixels that can reach the solid — its box, moved and grown
        by the field's largest displacement — are looked at: the solid is small beside the frame."""
        reach = int(np.ceil(float(np.abs(displacement_px).max(initial=0.0)))) + 2
        h, w = self.shape
        sx, sy = int(np.floor(shift_px[0])), int(np.floor(shift_px[1]))
        r0, r1 = max(self.box[0] + sy - reach, 0), min(self.box[1] + sy + reach + 1, h)
        c0, c1 = max(self.box[2] + sx - reach, 0), min(self.box[3] + sx + reach + 1, w)
        if r0 >= r1 or c0 >= c1:
            return displacement_px
        sub = displacement_px[r0:r1, c0:c1]
        gy, gx = np.mgrid[r0:r1, c0:c1].astype(np.float32)
        x0, y0 = gx + sub[..., 0], gy + sub[..., 1]
        x, y = self.push_out(x0, y0, shift_px, along)
        moved = (x != x0) | (y != y0)
        if not moved.any():
            return displacement_px
        out = displacement_px.copy()
        # only the moved pixels are written: the others keep their values to the last bit
        out[r0:r1, c0:c1, 0] = np.where(moved, x - gx, sub[..., 0])
        out[r0:r1, c0:c1, 1] = np.where(moved, y - gy, sub[..., 1])
        return out


__all__ = ["SolidSurface"]
