"""Polygon rasterisation in Numba: a leaf module, so :mod:`hifumotion.contour` needs no
other package (the segmentation imports the contour, not the other way round)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def fill_polygon(xs, ys, h, w):
    """Pixels whose centre is inside a closed polygon (even-odd rule), as a bool ``(h, w)`` mask.

    A scanline fill: for each row, the crossings of the horizontal line through
    the pixel centres with the polygon's edges, sorted, fill alternate spans.
    """
    n = xs.shape[0]
    out = np.zeros((h, w), np.bool_)
    crossings = np.empty(n)
    y_lo = max(int(np.ceil(ys.min())), 0)
    y_hi = min(int(np.floor(ys.max())), h - 1)
    for i in range(y_lo, y_hi + 1):
        m = 0
        for k in range(n):
            x0, y0 = xs[k], ys[k]
            x1, y1 = xs[(k + 1) % n], ys[(k + 1) % n]
            if (y0 <= i) != (y1 <= i):  # half-open rule: a vertex on the line counts once
                crossings[m] = x0 + (i - y0) * (x1 - x0) / (y1 - y0)
                m += 1
        c = np.sort(crossings[:m])
        for q in range(0, m - 1, 2):
            j0 = max(int(np.ceil(c[q])), 0)
            j1 = min(int(np.floor(c[q + 1])), w - 1)
            for j in range(j0, j1 + 1):
                out[i, j] = True
    return out


__all__ = ["fill_polygon"]
