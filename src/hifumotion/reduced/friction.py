"""Coulomb's friction in the reduced model (SI inside): the full model's law on reduced coordinates.

The reduced model (:mod:`.model`) keeps non-penetration through its modes and a small
contact solve, but a mode that slides along the floor or the bar's face cost nothing
beyond its elastic part: the full model's floor resists it with Coulomb's friction
(:mod:`hifumotion.creep.contact`). Measured on the oblique twin, where the tilted bar slides the sample,
the reduced model without friction was 6–19 % off the full model's contour motion
(docs/decisions.md, "Friction in the reduced model"). This module gives it the same law:

* **Where.** The candidates are the surface nodes near a frictional solid (a plane with
  μ_f > 0 that is not bonded, the bar's face) at the settled state — every one, including
  those every mode keeps on its solid (their non-penetration needs no row in the contact
  solve, but their sliding meets friction all the same).
* **How hard they press.** A node's normal reaction λ_n is what its own equation of
  motion lacks — the normal part of ``K u + C(μ) u̇ − b`` at the node (elastic, Eq. 16's
  viscous and body forces; the full model's reaction ``A u − rhs`` without the inertia,
  which a creep of seconds does not feel) with ``u = u₀ + V q``. The elastic and body parts
  are rows of the full matrices on the modes, made once (E and ν scale two of them); the
  viscous part takes each neighbouring voxel's μ at the lagged rates. A node presses while
  its gap is below ``touch`` spacings and λ_n > 0; λ_n is lagged a step, as the full model's
  rounds take the last round's.
* **The law.** Each pressing node's tangential displacement from its anchor, ``d = W q −
  a`` (W: its modes in the contact's tangents), meets ``f = μ_f λ_n d / max(|d|, ε)``
  (:func:`~hifumotion.creep.contact.friction_force`); a step linearises it (:func:`~hifumotion.creep.contact.friction_linearised`,
  Newton's tangent) and re-solves until the law holds to ``friction_rtol`` of μ_f λ_n at
  the solution, and after the step an anchor farther than ε is dragged to ε
  (:meth:`~hifumotion.creep.contact.ContactSet.slide`'s rule). A node that stops pressing forgets its
  anchor and takes a new one where it touches again.

Projected, the linearised force adds ``Wᵀ S W`` to the step's matrix and ``Wᵀ (S a − c)``
to its right-hand side: two products of (2m × r) arrays, a few hundred microseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from hifumotion.creep.contact import friction_linearised

MM = 1e-3


@dataclass(frozen=True)
class FrictionState:
    """The candidates' anchors (m, ``(m, 2)``, tangential displacement in their contact's
    tangents) and friction limits μ_f λ_n (N, ``(m,)``; 0 for a node that does not press)."""

    anchor_t_m: np.ndarray
    limit_n: np.ndarray

    @property
    def pressing(self) -> np.ndarray:
        return np.flatnonzero(self.limit_n > 0)


class ReducedFriction:
    """Coulomb's friction on the contact candidates of a reduced model (module docstring).

    ``solver``: the full model (:class:`~hifumotion.creep.integrate.CreepSolver`) whose mesh, matrices,
    contacts and body force the modes were made on; ``node_modes_m`` ``(3n, r)``,
    ``advance_modes_m`` ``(r,)`` and ``settled_nodes_mm`` the reduced basis'; ``reach_m``: a
    node farther than this from a solid at the settled state is no candidate.
    """

    def __init__(self, solver, node_modes_m: np.ndarray, advance_modes_m: np.ndarray, settled_nodes_mm: np.ndarray,
                 advance_at_rest_mm: float, reach_m: float, stick_m: float, touch_m: float):
        contacts = solver.contacts
        v = node_modes_m
        r = v.shape[1]
        settled = settled_nodes_mm * MM
        modes = v.reshape(len(settled), 3, r)
        surface = np.unique(solver.mesh.surface_faces())
        nodes, body, gap0, gap_modes = [], [], [], []
        for k, plane in enumerate(contacts.planes):
            if plane.bonded or plane.friction <= 0:
                continue
            normal = contacts.body_frames[k, 0]
            gap = (settled[surface] - np.asarray(plane.point_m)) @ normal
            near = gap < reach_m
            nodes.append(surface[near])
            body.append(np.full(int(near.sum()), k))
            gap0.append(gap[near])
            gap_modes.append(np.einsum("k,nkr->nr", normal, modes[surface[near]]))
        self._face = None
        if contacts.punch is not None and contacts.punch.friction > 0:
            a = contacts.body_frames[contacts.punch_index, 0]
            rel = settled[surface] - (np.asarray(contacts.punch.tip_m) + advance_at_rest_mm * MM * a)
            along = rel @ a
            lateral = rel - along[:, None] * a
            near = (along < reach_m) & (np.linalg.norm(lateral, axis=1) <= contacts.punch.radius_m + reach_m)
            first = sum(len(n) for n in nodes)
            nodes.append(surface[near])
            body.append(np.full(int(near.sum()), contacts.punch_index))
            gap0.append(along[near])
            normal_modes = np.einsum("k,nkr->nr", a, modes[surface[near]])
            gap_modes.append(normal_modes - advance_modes_m[None])
            lateral_modes = modes[surface[near]] - normal_modes[:, None, :] * a[None, :, None]
            self._face = (slice(first, first + int(near.sum())), lateral[near], lateral_modes, contacts.punch.radius_m)
        self.nodes = np.concatenate(nodes) if nodes else np.zeros(0, np.int64)
        self.body = np.concatenate(body) if body else np.zeros(0, np.int64)
        self.gap0_m = np.concatenate(gap0) if gap0 else np.zeros(0)
        self.gap_modes = np.vstack(gap_modes) if gap_modes else np.zeros((0, r))
        self.coefficient = contacts.friction[self.body] if len(self.body) else np.zeros(0)
        # the model's solids share the scene's one μ_f (floor, walls, the bar's face): a run at
        # another μ_f scales every limit by μ_f / made_coefficient (:meth:`state`)
        self.made_coefficient = float(self.coefficient.max()) if len(self.coefficient) else 0.0
        self.stick_m, self.touch_m = stick_m, touch_m
        frames = contacts.body_frames[self.body] if len(self.body) else np.zeros((0, 3, 3))
        normals = self.normals = frames[:, 0]
        node_modes = modes[self.nodes]                                          # (m, 3, r)
        self.tangent_modes = np.einsum("nak,nkr->nar", frames[:, 1:], node_modes)  # W: (m, 2, r)
        self._tangent_flat = self.tangent_modes.reshape(-1, r)                     # (2m, r)
        # the normal reaction's elastic and body parts: rows of the full matrices on the modes
        dofs = (3 * self.nodes[:, None] + np.arange(3)).ravel()
        m = solver.matrices
        displaced = settled.ravel() - solver.rest_m.ravel()
        project = sp.csr_matrix((normals.ravel(), (np.repeat(np.arange(len(self.nodes)), 3), np.arange(len(dofs)))),
                                shape=(len(self.nodes), len(dofs)))
        self.elastic_modes, self.elastic_settled = [], []
        for unit in (m.matrix(1.0, 0.0, 0.0), m.matrix(0.0, 1.0, 0.0)):   # per unit 2G, per unit κ
            rows = project @ unit[dofs]
            self.elastic_modes.append(np.asarray(rows @ v))
            self.elastic_settled.append(rows @ displaced)
        self.weight_n = np.einsum("nk,nk->n", normals, solver.body_force[self.nodes])
        # what the floor and the bar's face carry in all (the balance of the whole sample, which
        # the candidates' own rows do not keep: Galerkin's equations hold on the modes, not node
        # by node, and no mode moves the sample into the floor): the net weight (N, its buoyancy
        # less) and the bar's axis
        self.net_weight_n = solver.body_force.sum(axis=0)
        self.floor = np.array([k for k, plane in enumerate(contacts.planes)
                               if not plane.bonded and contacts.body_frames[k, 0, 1] > 0.99], np.int64)
        self.punch_index = contacts.punch_index if contacts.punch is not None else None
        self.bar_axis = (np.asarray(contacts.punch.axis, float) / np.linalg.norm(contacts.punch.axis)
                         if contacts.punch is not None else np.zeros(3))
        # the viscous part: the voxels around the candidates, each C_e V_e on its 24 unknowns,
        # and which of their entries are a candidate's normal force
        touching = np.isin(m.elements, self.nodes).any(axis=1)
        self.voxels = np.flatnonzero(touching)
        edofs = (3 * m.elements[self.voxels][:, :, None] + np.arange(3)).reshape(len(self.voxels), 24)
        blocks = np.broadcast_to(m.cube.viscous, (len(self.voxels), 24, 24)).copy()
        own = m.own_blocks(self.voxels)                       # a distorted voxel's own block
        blocks[own >= 0] = m.visc[own[own >= 0]]
        # each (voxel, candidate corner) pair's normal viscous force per unit μ and q̇: one
        # (pairs × r) product a step, summed per candidate
        per_voxel = np.matmul(blocks, v[edofs])                                 # (voxels, 24, r)
        # (a node near two solids — a floor–wall corner — gets its viscous part on its last
        # candidate only; its elastic and body parts on both)
        position = np.full(len(settled), -1)
        position[self.nodes] = np.arange(len(self.nodes))
        corner = position[m.elements[self.voxels]]                              # (voxels, 8)
        e_idx, c_idx = np.nonzero(corner >= 0)
        self._pair_node = corner[e_idx, c_idx]
        self._pair_voxel = self.voxels[e_idx]
        rows = per_voxel.reshape(len(self.voxels), 8, 3, r)[e_idx, c_idx]      # (pairs, 3, r)
        self.viscous_modes = np.ascontiguousarray(np.einsum("pk,pkr->pr", normals[self._pair_node], rows))

    @property
    def size(self) -> int:
        return len(self.nodes)

    def gaps_m(self, q: np.ndarray) -> np.ndarray:
        """Every candidate's gap to its solid at ``q`` (m); +inf for a bar-face candidate off the face."""
        gap = self.gap0_m + self.gap_modes @ q
        if self._face is not None:
            where, lateral, modes, radius = self._face
            # ``where`` is a slice (the face's candidates are contiguous): gap[where] is a view, set in place
            _off_face(lateral, modes, np.ascontiguousarray(q, float), radius, gap[where])
        return gap

    def normal_reactions_n(self, two_g: float, kappa: float, q: np.ndarray, qdot: np.ndarray,
                           mu_pa_s: np.ndarray | None, elastic_n: np.ndarray | None = None) -> np.ndarray:
        """λ_n (N) of every candidate at ``q`` moving at ``qdot``, Eq. 16's μ per voxel of the
        mesh (None: no viscosity) — the normal part of what its equation of motion lacks.
        ``elastic_n``: each candidate's elastic force along its normal (N) when the elasticity is
        not the small-strain K's rows (a corotational model's, :class:`~.corotated_force.CandidateForces`)."""
        if elastic_n is None:
            elastic_n = (two_g * (self.elastic_modes[0] @ q + self.elastic_settled[0])
                         + kappa * (self.elastic_modes[1] @ q + self.elastic_settled[1]))
        lam = elastic_n - self.weight_n
        if mu_pa_s is not None:
            lam += np.bincount(self._pair_node, mu_pa_s[self._pair_voxel] * (self.viscous_modes @ qdot),
                               minlength=len(lam))
        return lam

    def balanced(self, reactions_n: np.ndarray, gaps_m: np.ndarray, bar_force_n: float) -> np.ndarray:
        """``reactions_n`` with the floor's and the bar's face's pressing candidates scaled so that
        each solid carries what the sample's balance gives it: the face the bar's push
        ``bar_force_n`` (N, along its axis), the floor the net weight and the push's vertical part;
        each node's share is its own row's (the walls' are left as they are)."""
        out = np.array(reactions_n, float)
        pressing = (out > 0) & (gaps_m <= self.touch_m)
        push = max(float(bar_force_n), 0.0)
        # the floor's normal is +y: it carries −(net weight + push)_y
        targets = [(np.isin(self.body, self.floor), -(self.net_weight_n[1] + push * self.bar_axis[1]))]
        if self.punch_index is not None:
            targets.append((self.body == self.punch_index, push))
        for on, total in targets:
            share = on & pressing
            carried = float(out[share].sum())
            if carried > 0.0 and total > 0.0:
                out[share] *= total / carried
        return out

    def state(self, q: np.ndarray, reactions_n: np.ndarray, previous: FrictionState | None,
              slide: bool = True, scale: float = 1.0, gaps_m: np.ndarray | None = None) -> FrictionState:
        """The friction at ``q`` with the candidates' ``reactions_n``: limits μ_f λ_n of the nodes
        that press, a new contact anchored where it is, one that stops pressing let go; ``slide``
        (a step's end): an anchor farther than ε dragged to ε. ``scale``: this run's μ_f over the
        one the model was made at (the candidates and their modes do not depend on it).
        ``gaps_m``: :meth:`gaps_m` at ``q``, when the caller has it."""
        position = (self._tangent_flat @ q).reshape(-1, 2)                # (m, 2)
        gaps = self.gaps_m(q) if gaps_m is None else gaps_m
        anchor = np.empty_like(position)
        limit = np.empty(len(position))
        fresh = previous is None
        _friction_state(position, np.asarray(reactions_n, float), gaps, self.touch_m, scale * self.coefficient,
                        position if fresh else previous.anchor_t_m, limit if fresh else previous.limit_n, fresh,
                        slide, self.stick_m, anchor, limit)
        return FrictionState(anchor, limit)

    def linearised(self, state: FrictionState, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
        """The law linearised at ``q`` (Newton's tangent), projected: ``(Wᵀ S W, Wᵀ (S a − c), law)``
        — add the first to the step's matrix and the second to its right-hand side."""
        nodes = state.pressing
        w = self.tangent_modes[nodes]                                      # (p, 2, r)
        anchor = state.anchor_t_m[nodes]
        law = friction_linearised(nodes, anchor, np.einsum("par,r->pa", w, q) - anchor, state.limit_n[nodes],
                                  self.stick_m)
        s = law.stiffness_n_m
        # S W per node, its 2 × 2 blocks written out (a batched matmul of 2 × 2s is slower)
        sw = np.empty_like(w)
        sw[:, 0] = s[:, 0, :1] * w[:, 0] + s[:, 0, 1:] * w[:, 1]
        sw[:, 1] = s[:, 1, :1] * w[:, 0] + s[:, 1, 1:] * w[:, 1]
        flat = w.reshape(-1, w.shape[2])
        matrix = flat.T @ sw.reshape(-1, w.shape[2])
        rhs = flat.T @ (np.einsum("nab,nb->na", s, anchor) - law.constant_n).ravel()
        return matrix, rhs, law

    def law_error(self, state: FrictionState, law, q: np.ndarray) -> float:
        """The largest |f(d) − (c + S d)| at ``q`` over the pressing nodes, per μ_f λ_n."""
        nodes = law.nodes
        if len(nodes) == 0:
            return 0.0
        d = np.einsum("par,r->pa", self.tangent_modes[nodes], q) - law.anchor_t
        limit = state.limit_n[nodes]
        return float(np.max(law.error_n(d, limit, self.stick_m) / limit))


@njit(cache=True)
def _off_face(lateral, modes, q, radius, gap):
    """``gap`` set to +inf for the bar-face candidates whose distance from the bar's axis at ``q``
    (``lateral + modes @ q``, m) is beyond the face's ``radius``."""
    for i in range(lateral.shape[0]):
        size = 0.0
        for k in range(3):
            x = lateral[i, k]
            for j in range(q.shape[0]):
                x += modes[i, k, j] * q[j]
            size += x * x
        if np.sqrt(size) > radius:
            gap[i] = np.inf


@njit(cache=True)
def _friction_state(position, reactions, gaps, touch, coefficient, previous_anchor, previous_limit, fresh, slide,
                    stick, anchor, limit):
    """:meth:`ReducedFriction.state` node by node: a pressing node's limit μ_f λ_n; its anchor kept
    from the last state if it pressed then (dragged to within ``stick`` of where it is, with
    ``slide``), else where it is; a node that does not press is anchored where it is."""
    for i in range(position.shape[0]):
        pressing = reactions[i] > 0.0 and gaps[i] <= touch
        limit_i = coefficient[i] * reactions[i] if pressing else 0.0
        x0, x1 = position[i, 0], position[i, 1]
        a0, a1 = x0, x1
        if pressing and not fresh and previous_limit[i] > 0.0:
            a0, a1 = previous_anchor[i, 0], previous_anchor[i, 1]
            if slide:
                d0, d1 = x0 - a0, x1 - a1
                size = np.sqrt(d0 * d0 + d1 * d1)
                if size > stick:
                    a0, a1 = x0 - stick * d0 / size, x1 - stick * d1 / size
        anchor[i, 0], anchor[i, 1] = a0, a1
        limit[i] = limit_i


__all__ = ["FrictionState", "ReducedFriction"]
