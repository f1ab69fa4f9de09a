"""The bar's non-penetration in the reduced model (SI inside): the full model's rounded solid,
its tangent planes taken again at each step's start.

The full model (:mod:`hifumotion.creep.contact`) holds a node that touches the bar on the solid's tangent
plane where it touched: a flat face, a rim rounded at the edge radius, a side. The reduced
model's contact solve (:meth:`.reduced.ReducedCreep._solve`) takes linear rows ``G q ≥ h``,
so each candidate's signed distance to that solid is linearised at the step's start ``q̄``:

    d(q) ≈ d(q̄) + nᵀ V_i (q − q̄) − (a·n) v_sᵀ (q − q̄)

with ``n`` the outward normal at the surface point nearest the node, ``V_i`` its modes and
``v_s`` the bar's advance per coordinate. Why not the face's plane alone, as a disc that holds
only under itself: tissue beside the rim that a sliding sample brings under the disc is
already behind the face's plane there, and the row that appears under it moves it that whole
depth in one step whatever the step's size — a jump no step controller can shrink (measured:
an ellipsoid slid by a tilted bar, 0.04 mm at every step from 0.1 s down to 5·10⁻⁸ s, whose
rate then threw the sample 766 mm; docs/decisions.md, "The reduced bar's rounded rim"). On
the rounded solid that node meets the side's or the rim's tangent plane first and is turned
under the face over the rim, as in the full model.

The tangent plane of a convex solid bounds a half-space that lies wholly outside it, so the
linearised row never lets a node in; a node found inside (by at most a step's overshoot) may
not go deeper, as the plane rows' rule has it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from hifumotion.creep.contact import bar_point

MM = 1e-3


class ReducedBarRows:
    """The bar's contact rows on the candidates near it (module docstring).

    ``contacts``: the full model's :class:`~hifumotion.creep.contact.ContactSet` (its bar's rounded geometry);
    ``settled_m`` ``(n, 3)`` and ``node_modes`` ``(n, 3, r)`` the reduced basis' settled nodes
    (m) and their modes; ``advance_modes_m`` ``(r,)``; ``advance_at_rest_m`` the bar's advance
    from its scene tip at q = 0; ``surface`` the mesh's surface nodes; ``reach_m``: a surface node
    farther than this from the bar at q = 0 is no candidate.
    """

    def __init__(self, contacts, settled_m: np.ndarray, node_modes: np.ndarray, advance_modes_m: np.ndarray,
                 advance_at_rest_m: float, surface: np.ndarray, reach_m: float):
        self.contacts = contacts
        distance, _ = contacts.bar_distance(settled_m[surface], advance_at_rest_m)
        self.nodes = surface[distance < reach_m]
        self.settled_m = np.ascontiguousarray(settled_m[self.nodes])
        self.modes = np.ascontiguousarray(node_modes[self.nodes])          # (m, 3, r)
        self.advance_modes_m = advance_modes_m
        self.advance_at_rest_m = float(advance_at_rest_m)
        self.axis = contacts.body_frames[contacts.punch_index, 0]
        # a row whose coefficients are this small against the largest mode entry is no row: a node
        # every mode keeps on the face (reduced.held_on_solids)
        self._negligible = 1e-9 * max(float(np.abs(node_modes).max()), float(np.abs(advance_modes_m).max()))

    @property
    def size(self) -> int:
        return len(self.nodes)

    def distances_m(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every candidate's signed distance (m) to the bar at ``q`` and the outward normal there."""
        x = self.settled_m + self.modes @ q
        return self.contacts.bar_distance(x, self.advance_at_rest_m + float(self.advance_modes_m @ q))

    def rows_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows linearised at ``q``: ``(G, h, holds)`` with ``G q₊ ≥ h`` for the candidates
        where ``holds`` (a row that does not vanish)."""
        q = np.ascontiguousarray(q, float)
        n, r = len(self.nodes), len(q)
        rows, bound, holds = np.empty((n, r)), np.empty(n), np.empty(n, np.bool_)
        geometry = self.contacts.bar_geometry(self.advance_at_rest_m + float(self.advance_modes_m @ q))
        _bar_rows(self.settled_m, self.modes, q, self.advance_modes_m, *geometry, self._negligible, rows, bound, holds)
        return rows, bound, holds


@njit(cache=True)
def _bar_rows(settled, modes, q, advance_modes, tip, a, across_unit, core_m, rim_m, negligible, rows, bound, holds):
    """Each candidate's row ``nᵀ V_i − (a·n) v_s``, its bound ``row·q − max(d, 0)`` and whether it
    holds (a coefficient above ``negligible``), n and d the bar's normal and distance at ``q``."""
    r = q.shape[0]
    normal = np.empty(3)
    x = np.empty(3)
    for i in range(settled.shape[0]):
        for k in range(3):
            acc = settled[i, k]
            for j in range(r):
                acc += modes[i, k, j] * q[j]
            x[k] = acc
        distance = bar_point(x[0], x[1], x[2], tip, a, across_unit, core_m, rim_m, normal)
        axial = normal[0] * a[0] + normal[1] * a[1] + normal[2] * a[2]
        dot = 0.0
        largest = 0.0
        for j in range(r):
            g = normal[0] * modes[i, 0, j] + normal[1] * modes[i, 1, j] + normal[2] * modes[i, 2, j] - axial * advance_modes[j]
            rows[i, j] = g
            dot += g * q[j]
            largest = max(largest, abs(g))
        bound[i] = dot - max(distance, 0.0)
        holds[i] = largest > negligible


__all__ = ["ReducedBarRows"]
