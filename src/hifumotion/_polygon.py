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


@njit(cache=True, inline="always")
def _key(ky, kx, wide):
    return ky * wide + kx


@njit(cache=True, inline="always")
def _take(first, second, count, edge):
    """The crossed edges of a cell so far, with ``edge`` added (a cell that is no saddle has two)."""
    if count == 0:
        return edge, second, 1
    return first, edge, 2


@njit(cache=True)
def boundary_curves(m):
    """The 0.5 iso-lines of a 0/1 ``uint8`` array whose border rows and columns are 0.

    Marching squares: each cell that the line crosses gives a segment between
    midpoints of its edges; a saddle cell (two diagonal corners set) gives two,
    cutting off each set corner (the set pixels meet only along edges, as
    scikit-image's ``find_contours`` with ``fully_connected="low"``). Each
    segment is oriented with the set corners on the same side, so the segments
    chain into closed curves, each traced from its first cell in row-major order.
    Returns ``(points, starts)``: ``(P, 2)`` float ``(x, y)`` pixel coordinates and
    the ``C + 1`` offsets of the ``C`` curves in them.
    """
    h, w = m.shape
    wide = 2 * w + 1
    n = 0
    for i in range(h - 1):
        for j in range(w - 1):
            code = m[i, j] + 2 * m[i, j + 1] + 4 * m[i + 1, j + 1] + 8 * m[i + 1, j]
            if code == 5 or code == 10:
                n += 2
            elif code != 0 and code != 15:
                n += 1
    # doubled coordinates (2y, 2x) of each segment's ends: the edge midpoints of a cell
    ends = np.empty((n, 4), np.int64)
    q = 0
    for i in range(h - 1):
        for j in range(w - 1):
            a, b, c, d = m[i, j], m[i, j + 1], m[i + 1, j + 1], m[i + 1, j]
            code = a + 2 * b + 4 * c + 8 * d
            if code == 0 or code == 15:
                continue
            top = (2 * i, 2 * j + 1)
            right = (2 * i + 1, 2 * j + 2)
            bottom = (2 * i + 2, 2 * j + 1)
            left = (2 * i + 1, 2 * j)
            if code == 5:  # a and c set, cut off separately
                pairs = ((top, left, 2 * i, 2 * j), (bottom, right, 2 * i + 2, 2 * j + 2))
            elif code == 10:  # b and d set
                pairs = ((top, right, 2 * i, 2 * j + 2), (bottom, left, 2 * i + 2, 2 * j))
            else:
                # the two edges whose ends differ, and one set corner (doubled coordinates)
                e0, e1, k = top, top, 0
                if a != b:
                    e0, e1, k = _take(e0, e1, k, top)
                if b != c:
                    e0, e1, k = _take(e0, e1, k, right)
                if c != d:
                    e0, e1, k = _take(e0, e1, k, bottom)
                if d != a:
                    e0, e1, k = _take(e0, e1, k, left)
                if a:
                    cy, cx = 2 * i, 2 * j
                elif b:
                    cy, cx = 2 * i, 2 * j + 2
                elif c:
                    cy, cx = 2 * i + 2, 2 * j + 2
                else:
                    cy, cx = 2 * i + 2, 2 * j
                pairs = ((e0, e1, cy, cx), (e0, e1, cy, cx))
            for s in range(2 if (code == 5 or code == 10) else 1):
                p, r, cy, cx = pairs[s]
                # the set corner on the right of p → r, as scikit-image orients its curves
                cross = (r[1] - p[1]) * (cy - p[0]) - (r[0] - p[0]) * (cx - p[1])
                if cross < 0:
                    p, r = r, p
                ends[q, 0], ends[q, 1], ends[q, 2], ends[q, 3] = p[0], p[1], r[0], r[1]
                q += 1
    start_keys = np.empty(n, np.int64)
    for s in range(n):
        start_keys[s] = _key(ends[s, 0], ends[s, 1], wide)
    order = np.argsort(start_keys)
    sorted_keys = start_keys[order]
    nxt = np.empty(n, np.int64)
    for s in range(n):
        k = np.searchsorted(sorted_keys, _key(ends[s, 2], ends[s, 3], wide))
        nxt[s] = order[k]
    points = np.empty((n, 2))
    starts = [0]
    seen = np.zeros(n, np.bool_)
    p = 0
    for s0 in range(n):
        if seen[s0]:
            continue
        s = s0
        while not seen[s]:
            seen[s] = True
            points[p, 0] = 0.5 * ends[s, 1]
            points[p, 1] = 0.5 * ends[s, 0]
            p += 1
            s = nxt[s]
        starts.append(p)
    return points, np.array(starts, np.int64)
