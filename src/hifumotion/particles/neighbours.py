"""Neighbour search: a cell-linked list built by counting sort (Numba).

Space is cut into cubic cells of edge ``h`` (the kernel's support radius), so
every neighbour of a particle lies in its own cell or one of the 26 around it.
Particles are bucketed by a counting sort (two passes, no Python loop), then
each query particle scans its 27 cells in parallel and writes its neighbours
into its own row of a fixed-width table. When a row overflows, the table is
rebuilt wider, so no neighbour is ever dropped.

A skin (Verlet list) lets a table serve several steps: it is built with radius
``h (1 + skin)`` and rebuilt once any particle has moved ``skin h / 2`` since
(:meth:`CellGrid.stale`); kernels still test ``r < h`` pair by pair.

The elastic tissue does not use this: it keeps the neighbourhoods of its rest
configuration for the whole run (total Lagrangian, :mod:`.elastic`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _cell_index(x, lo, inv_cell, dims):
    n = x.shape[0]
    cid = np.empty(n, np.int64)
    for i in range(n):
        c = np.empty(3, np.int64)
        for a in range(3):
            k = int(np.floor((x[i, a] - lo[a]) * inv_cell))
            if k < 0:
                k = 0
            elif k >= dims[a]:
                k = dims[a] - 1
            c[a] = k
        cid[i] = (c[2] * dims[1] + c[1]) * dims[0] + c[0]
    return cid


@njit(cache=True)
def _counting_sort(cid, ncell):
    start = np.zeros(ncell + 1, np.int64)
    for i in range(cid.size):
        start[cid[i] + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(cid.size, np.int64)
    for i in range(cid.size):
        c = cid[i]
        order[fill[c]] = i
        fill[c] += 1
    return start, order


@njit(cache=True, parallel=True)
def _fill_table(x, q0, q1, lo, inv_cell, dims, start, order, h, group, table, counts):
    h2 = h * h
    width = table.shape[1]
    for row in prange(q1 - q0):
        i = q0 + row
        cx = min(max(int(np.floor((x[i, 0] - lo[0]) * inv_cell)), 0), dims[0] - 1)
        cy = min(max(int(np.floor((x[i, 1] - lo[1]) * inv_cell)), 0), dims[1] - 1)
        cz = min(max(int(np.floor((x[i, 2] - lo[2]) * inv_cell)), 0), dims[2] - 1)
        n = 0
        for dz in range(-1, 2):
            z = cz + dz
            if z < 0 or z >= dims[2]:
                continue
            for dy in range(-1, 2):
                y = cy + dy
                if y < 0 or y >= dims[1]:
                    continue
                for dx in range(-1, 2):
                    xx = cx + dx
                    if xx < 0 or xx >= dims[0]:
                        continue
                    c = (z * dims[1] + y) * dims[0] + xx
                    for k in range(start[c], start[c + 1]):
                        j = order[k]
                        if j == i or (group[i] >= 0 and group[j] == group[i]):
                            continue
                        d0 = x[j, 0] - x[i, 0]
                        d1 = x[j, 1] - x[i, 1]
                        d2 = x[j, 2] - x[i, 2]
                        if d0 * d0 + d1 * d1 + d2 * d2 < h2:
                            if n < width:
                                table[row, n] = j
                            n += 1
        counts[row] = n


@njit(cache=True)
def _max_displacement(x, x_then):
    worst = 0.0
    for i in range(x.shape[0]):
        d = (x[i, 0] - x_then[i, 0]) ** 2 + (x[i, 1] - x_then[i, 1]) ** 2 + (x[i, 2] - x_then[i, 2]) ** 2
        if d > worst:
            worst = d
    return np.sqrt(worst)


@dataclass
class NeighbourTable:
    """Neighbours of the query particles ``first … first + len(counts) − 1``.

    Row ``k`` lists, in ``indices[k, :counts[k]]``, the particles within the
    support radius of particle ``first + k`` (itself excluded).
    """

    first: int
    indices: np.ndarray
    counts: np.ndarray


class CellGrid:
    """A reusable cell-linked list over a fixed box (m).

    Particles outside the box are kept in its border cells: still found, only
    more slowly; leaving the domain is reported by the solver's divergence check.
    """

    def __init__(self, lo_m, hi_m, h_m: float, width: int = 64, skin: float = 0.0):
        self.skin = float(skin)
        h_m = float(h_m) * (1.0 + self.skin)
        self.lo = np.asarray(lo_m, np.float64) - h_m
        hi = np.asarray(hi_m, np.float64) + h_m
        self.h = float(h_m)
        self.built_at: np.ndarray | None = None
        self.inv_cell = 1.0 / self.h
        self.dims = np.maximum(np.ceil((hi - self.lo) * self.inv_cell).astype(np.int64), 1)
        if int(np.prod(self.dims)) > 50_000_000:
            raise ValueError(f"neighbour grid of {self.dims.tolist()} cells is too large; "
                             "the domain is too big for the smoothing length")
        self.width = int(width)

    def stale(self, x_m: np.ndarray) -> bool:
        """Whether some particle moved more than half the skin since the last :meth:`query`."""
        if self.built_at is None or self.built_at.shape != x_m.shape:
            return True
        limit = 0.5 * self.skin * self.h / (1.0 + self.skin)
        return _max_displacement(x_m, self.built_at) > limit

    def query(self, x_m: np.ndarray, first: int, last: int, group: np.ndarray | None = None
              ) -> NeighbourTable:
        """Neighbours (within ``h (1 + skin)``) of particles ``first … last − 1`` among all of ``x_m``.

        With ``group`` (one int per particle), a particle of group g ≥ 0 does not list
        particles of its own group (a solid's own particles, which interact otherwise);
        group −1 lists everything.
        """
        x = np.ascontiguousarray(x_m, np.float64)
        self.built_at = x[:last].copy()
        cid = _cell_index(x, self.lo, self.inv_cell, self.dims)
        start, order = _counting_sort(cid, int(np.prod(self.dims)))
        n = max(last - first, 0)
        if group is None:
            group = np.full(len(x), -1, np.int64)
        while True:
            table = np.empty((n, self.width), np.int64)
            counts = np.zeros(n, np.int64)
            if n:
                _fill_table(x, first, last, self.lo, self.inv_cell, self.dims, start, order,
                            self.h, group, table, counts)
            most = int(counts.max()) if n else 0
            if most <= self.width:
                return NeighbourTable(first, table, counts)
            self.width = int(most * 1.25) + 1
