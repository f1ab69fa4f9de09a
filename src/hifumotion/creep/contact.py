"""Contacts as constraints: rigid planes (floor, tank walls) and the bar's flat end (SI).

A node in contact is held *on* the solid's surface — its normal displacement is
prescribed, so no tissue crosses the floor or the bar, at any spacing. Along the surface
it meets Coulomb's friction with an elastic stick (the FE reference's law,
:mod:`hifumotion.reference.creep_fe`): the tangential force is

    f = μ_f λ_n d / max(|d|, ε),

``d`` the node's tangential displacement from its anchor and ε the stick's reach
(``CreepSettings.stick_mm``) — a contact sticks elastically up to ε and slides beyond it at μ_f λ_n, its
anchor dragged along to ε (:meth:`ContactSet.slide`). Unlike the rigid stick/slip
switch the law is continuous, so the motion is a continuous function of the load and
the parameters (a release does not hang on which node switches first).
:func:`friction_linearised` gives its tangent for the integrator's rounds. The set
changes by the usual active-set rules (Wriggers, *Computational Contact Mechanics*, §6):

* a free node that has crossed a surface becomes a contact, anchored where it is; until
  its first reaction is known, its friction's size μ_f λ_n takes the mean normal reaction
  of the solid's other contacts (the integrator gives the bar's first ones their share of
  its force). Without friction in that round, a body touching at a few points and then
  at many swings out of place, and the next rounds' friction, lagging the normal
  reactions, does not bring it back;
* a contact that pulls (λ_n < 0) is released — but not on its first reaction, which that
  guessed friction made (it takes a zero one and the next round decides); one released
  within a step comes back in that step only if it crosses by ``left_tolerance_m`` (an
  edge node of a rough patch can otherwise chatter on and off the surface, as the FE
  reference's rule has it);
* a contact of the bar that has slid beyond its face's rim is released: the face is a disc,
  and a node held on its plane beyond the rim would be pushed by a face that is not there.

The bar is a solid cylinder, not only its face: a node that comes inside it nearer its side
than its face — tissue beside the rim, behind the face's plane, that the sliding sample
brings under the disc — touches the **side**, held on the cylinder's tangent plane where it
touched (its own normal, radial; released when it pulls or comes out in front of the face).
Held on the face instead, it would be moved the whole depth it is behind the face's plane in
one step, by a force that grows as the step shrinks (docs/decisions.md, issue 41).

A bonded plane (a clamp) holds its nodes rigidly: their tangential displacement is
prescribed too (status STICK), and they are never released.

The bar is a rigid punch translating along its axis only (a bar in a guide, as the
explicit path's): its advance ``s`` (m) is one more unknown, and its force schedule F(t)
(N) is balanced by the normal reactions of the nodes under its face.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

#: a node's status: free, held rigidly (a bonded plane's), or in frictional contact
FREE, STICK, SLIP = 0, 1, 2


@dataclass
class FrictionLinearised:
    """Coulomb's regularised law linearised at ``d0`` for ``nodes``: f ≈ c + S d (N; d in m,
    the node's tangential displacement from its anchor in its contact frame's tangents)."""

    nodes: np.ndarray          # (m,) node indices
    anchor_t: np.ndarray       # (m, 2) the anchors in the tangents (m)
    constant_n: np.ndarray     # (m, 2) c (N)
    stiffness_n_m: np.ndarray  # (m, 2, 2) S (N/m)

    def error_n(self, d_m: np.ndarray, limit_n: np.ndarray, eps_m: float) -> np.ndarray:
        """|f(d) − (c + S d)| per node (N), f at the given limits μ_f λ_n."""
        exact = friction_force(d_m, limit_n, eps_m)
        approx = self.constant_n + np.einsum("nab,nb->na", self.stiffness_n_m, d_m)
        return np.linalg.norm(exact - approx, axis=1)


def friction_force(d_m: np.ndarray, limit_n: np.ndarray, eps_m: float) -> np.ndarray:
    """The regularised Coulomb force μ_f λ_n d / max(|d|, ε) (N, (m, 2)) opposing ``d`` (m, (m, 2))."""
    size = np.linalg.norm(d_m, axis=1)
    return limit_n[:, None] * d_m / np.maximum(size, eps_m)[:, None]


def friction_linearised(nodes: np.ndarray, anchor_t: np.ndarray, d0_m: np.ndarray, limit_n: np.ndarray,
                        eps_m: float, newton: bool = True) -> FrictionLinearised:
    """The law's linearisation at ``d0`` (m, (m, 2)).

    Inside the stick (|d0| ≤ ε) it is exact: S = μ_f λ_n/ε I, c = 0. Beyond it, ``newton``
    takes the tangent: S = μ_f λ_n/|d0| (I − d̂0 d̂0ᵀ), c = μ_f λ_n d̂0 (the force's size is
    fixed, only its direction turns); otherwise the secant S = μ_f λ_n/|d0| I, c = 0, whose
    rounds always settle (iteratively reweighted, as the FE reference's) but only linearly."""
    size = np.linalg.norm(d0_m, axis=1)
    stiffness = (limit_n / np.maximum(size, eps_m))[:, None, None] * np.eye(2)
    constant = np.zeros_like(d0_m)
    if newton:
        beyond = size > eps_m
        unit = d0_m[beyond] / size[beyond, None]
        stiffness[beyond] -= (limit_n[beyond] / size[beyond])[:, None, None] * np.einsum("na,nb->nab", unit, unit)
        constant[beyond] = limit_n[beyond, None] * unit
    return FrictionLinearised(nodes, anchor_t, constant, stiffness)


@dataclass(frozen=True)
class Plane:
    """A rigid plane the tissue stays on the ``normal`` side of (m; unit normal).

    ``bonded``: nodes that touch it are held for good (a clamp: never released, never slip).
    """

    point_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    friction: float = 0.5
    bonded: bool = False


@dataclass(frozen=True)
class Punch:
    """The bar's flat end: a disc of ``radius_m`` at ``tip_m``, pushed along unit ``axis``.

    ``force_n(t)`` is the push (N) at time t (s); ``breakpoints_s`` the times where the
    schedule bends (the integrator lands a step on each). With ``travel_m`` (travel control)
    the bar is driven instead: its end is ``travel_m(t)`` (m) along the axis beyond where it
    rests on the settled tissue, ``force_n`` is not read, and the force it takes is a result.
    """

    tip_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_m: float
    force_n: Callable[[float], float]
    friction: float = 0.5
    breakpoints_s: tuple[float, ...] = ()
    travel_m: Callable[[float], float] | None = None

    @property
    def driven(self) -> bool:
        """Whether the bar's travel is given (travel control) rather than its force."""
        return self.travel_m is not None


def _frames(normals: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` orthonormal frames with the normal as first row."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return np.stack([n, t1, t2], axis=1)


class ContactSet:
    """Which nodes touch which solid, stuck or slipping.

    ``body[i]``: −1 free, ``0 … P−1`` the planes, ``P`` the punch's face, ``P + 1`` its side
    (:attr:`side_index`; each such contact has its own frame in ``node_frames``); ``status[i]`` FREE,
    STICK (held rigidly by a bonded plane) or SLIP (in frictional contact); ``anchor[i]``
    the displacement (m) its friction pulls it back to (module docstring); ``pressure[i]``
    its last normal reaction (N); ``fresh[i]``: touched, its first reaction not yet known.
    """

    def __init__(self, rest_m: np.ndarray, planes: list[Plane], punch: Punch | None):
        self.rest = np.asarray(rest_m, float)
        n = len(self.rest)
        self.planes = list(planes)
        self.punch = punch
        self.body = np.full(n, -1, np.int64)
        self.status = np.zeros(n, np.int64)
        self.anchor = np.zeros((n, 3))
        self.pressure = np.zeros(n)
        self.fresh = np.zeros(n, bool)
        self.left = np.zeros(n, bool)   # released within the current step
        normals = [np.asarray(p.normal, float) for p in self.planes]
        if punch is not None:
            # the face's frame, and a stand-in for the side's (its contacts' own are in node_frames)
            normals += [np.asarray(punch.axis, float)] * 2
        self.body_frames = _frames(np.array(normals)) if normals else np.zeros((0, 3, 3))
        self.node_frames = np.zeros((n, 3, 3))
        self.friction = np.array([p.friction for p in self.planes] + ([punch.friction] * 2 if punch else []))
        self.bonded = np.array([p.bonded for p in self.planes] + ([False] * 2 if punch else []), bool)
        self.version = 0  # bumped whenever the constrained set changes

    @property
    def punch_index(self) -> int:
        """The body index of the bar's face."""
        return len(self.planes)

    @property
    def side_index(self) -> int:
        """The body index of the bar's side (the cylinder's wall)."""
        return len(self.planes) + 1

    def on_bar(self) -> np.ndarray:
        """The nodes touching the bar, its face or its side."""
        return np.flatnonzero((self.body == self.punch_index) | (self.body == self.side_index))

    def gaps(self, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Smallest signed gap (m) of every node to the solids and which solid (−1: none near)."""
        x = self.rest + u
        best = np.full(len(x), np.inf)
        which = np.full(len(x), -1, np.int64)
        for k, plane in enumerate(self.planes):
            g = (x - np.asarray(plane.point_m)) @ self.body_frames[k, 0]
            closer = g < best
            best[closer], which[closer] = g[closer], k
        if self.punch is not None:
            along, across = self._in_bar(u, advance_m)
            radius = self.punch.radius_m
            under = across <= radius
            # inside the cylinder the nearer of its face and its side: the larger (less negative) gap
            side = under & (along < 0.0) & (across - radius > along)
            gap = np.where(side, across - radius, along)
            under &= gap < best
            best[under] = gap[under]
            which[under] = np.where(side[under], self.side_index, self.punch_index)
        return best, which

    def _in_bar(self, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Every node's distance (m) beyond the face's plane along the axis, and from the axis."""
        a = self.body_frames[self.punch_index, 0]
        rel = self.rest + u - (np.asarray(self.punch.tip_m) + advance_m * a)
        along = rel @ a
        return along, np.linalg.norm(rel - along[:, None] * a, axis=1)

    def under_face(self, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Every node's distance (m) beyond the punch's face along its axis, and whether it is under the face."""
        along, across = self._in_bar(u, advance_m)
        return along, across <= self.punch.radius_m

    def prescribed_normal(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For contact nodes: the normal displacement that closes their gap, as
        ``constant + coefficient × s`` (m; the coefficient is 1 for the punch)."""
        const = np.zeros(len(nodes))
        coef = np.zeros(len(nodes))
        for k, plane in enumerate(self.planes):
            on = self.body[nodes] == k
            const[on] = -(self.rest[nodes[on]] - np.asarray(plane.point_m)) @ self.body_frames[k, 0]
        if self.punch is not None:
            on = self.body[nodes] == self.punch_index
            a = self.body_frames[self.punch_index, 0]
            const[on] = -(self.rest[nodes[on]] - np.asarray(self.punch.tip_m)) @ a
            coef[on] = 1.0
            # the side: the tangent plane R from the axis along the node's own (radial) normal;
            # the bar moves along its axis, across that normal, so s does not enter
            side = np.flatnonzero(self.body[nodes] == self.side_index)
            normal = self.node_frames[nodes[side], 0]
            rel = self.rest[nodes[side]] - np.asarray(self.punch.tip_m)
            const[side] = self.punch.radius_m - np.einsum("nk,nk->n", rel, normal)
        return const, coef

    def touch(self, nodes: np.ndarray, bodies: np.ndarray, u: np.ndarray) -> None:
        """Make ``nodes`` contacts of ``bodies``, anchored where they are now."""
        if len(nodes) == 0:
            return
        held = (self.body >= 0) & (self.pressure > 0)
        for b in np.unique(bodies):
            mine = held & (self.body == b)
            self.pressure[nodes[bodies == b]] = self.pressure[mine].mean() if mine.any() else 0.0
        self.body[nodes] = bodies
        side = nodes[bodies == self.side_index] if self.punch is not None else nodes[:0]
        if len(side):
            # the side's normal where the node touches it: radial, out of the bar
            a = self.body_frames[self.punch_index, 0]
            rel = self.rest[side] + u[side] - np.asarray(self.punch.tip_m)
            radial = rel - (rel @ a)[:, None] * a
            radial /= np.linalg.norm(radial, axis=1, keepdims=True)
            self.node_frames[side] = np.stack([radial, np.broadcast_to(a, radial.shape),
                                               np.cross(radial, a)], axis=1)
        self.fresh[nodes] = True
        self.status[nodes] = np.where(self.bonded[bodies], STICK, SLIP)
        self.anchor[nodes] = u[nodes]
        self.version += 1

    def release(self, nodes: np.ndarray) -> None:
        if len(nodes) == 0:
            return
        self.body[nodes] = -1
        self.status[nodes] = FREE
        self.pressure[nodes] = 0.0
        self.fresh[nodes] = False
        self.version += 1

    def frames_of(self, nodes: np.ndarray) -> np.ndarray:
        """``(m, 3, 3)`` contact frames of ``nodes`` (normal first): their body's, or their own on the bar's side."""
        frames = self.body_frames[self.body[nodes]]
        if self.punch is not None:
            side = self.body[nodes] == self.side_index
            frames[side] = self.node_frames[nodes[side]]
        return frames

    def frictional(self) -> np.ndarray:
        """The contacts whose tangential motion meets friction (not bonded, μ_f > 0)."""
        contact = np.flatnonzero(self.status == SLIP)
        return contact[self.friction[self.body[contact]] > 0]

    def friction_limit(self, nodes: np.ndarray) -> np.ndarray:
        """μ_f λ_n (N) of ``nodes`` at their last normal reactions: the largest friction they take."""
        return self.friction[self.body[nodes]] * self.pressure[nodes]

    def tangential(self, nodes: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``nodes``' displacement (m) in their contact frames' tangents, ``(m, 2)``."""
        return np.einsum("nk,nak->na", u[nodes], self.frames_of(nodes)[:, 1:])

    def slide(self, u: np.ndarray, eps_m: float) -> None:
        """End of a step: a contact farther than ε from its anchor has slid; its anchor follows to ε."""
        nodes = self.frictional()
        if len(nodes) == 0:
            return
        frames = self.frames_of(nodes)[:, 1:]
        d = self.tangential(nodes, u) - self.tangential(nodes, self.anchor)
        size = np.linalg.norm(d, axis=1)
        far = size > eps_m
        shift = d[far] * (1.0 - eps_m / size[far])[:, None]
        self.anchor[nodes[far]] += np.einsum("na,nak->nk", shift, frames[far])

    def record_pressure(self, reaction: np.ndarray) -> np.ndarray:
        """The contacts' normal reactions (N) from the constraint forces ``reaction`` (N, (n, 3)),
        kept (≥ 0) in ``pressure``; returned signed, in the order of the contacts."""
        contact = np.flatnonzero(self.body >= 0)
        normal = np.einsum("nk,nk->n", reaction[contact], self.frames_of(contact)[:, 0])
        self.pressure[contact] = np.maximum(normal, 0.0)
        return normal

    def update(self, u: np.ndarray, reaction: np.ndarray, advance_m: float, tolerance_m: float,
               left_tolerance_m: float) -> bool:
        """One round of the active-set rules (module docstring); True if the set changed.

        ``u`` the displacement just solved (m), ``reaction`` the constraint forces on the
        nodes (N, (n, 3)); the contacts' normal reactions are kept in ``pressure``. A free
        node touches when it is ``tolerance_m`` behind a surface, one released in this step
        (``left``, cleared by the caller at a step's start) ``left_tolerance_m``.
        """
        changed_set = False
        contact = np.flatnonzero(self.body >= 0)
        if len(contact):
            normal = self.record_pressure(reaction)
            scale = max(np.abs(reaction).max(), 1e-300)
            fresh = self.fresh[contact]
            pulling = (normal < -1e-9 * scale) & ~self.bonded[self.body[contact]] & ~fresh
            if fresh.any():
                self.fresh[contact] = False
                changed_set = True
            if pulling.any():
                self.release(contact[pulling])
                self.left[contact[pulling]] = True
                changed_set = True
        if self.punch is not None:
            # the face is a disc: a node slid beyond its rim has nothing to hold it (held on the
            # face's plane it would be pushed by a face that is not there); one on the side that
            # has come out in front of the face is beside the bar no more
            along, under = self.under_face(u, advance_m)
            on_face = self.body == self.punch_index
            on_side = self.body == self.side_index
            off = np.flatnonzero((on_face & ~under) | (on_side & (along > 0.0)))
            if len(off):
                self.release(off)
                self.left[off] = True
                changed_set = True
        gap, which = self.gaps(u, advance_m)
        gate = np.where(self.left, left_tolerance_m, tolerance_m)
        crossing = np.flatnonzero((self.body < 0) & (which >= 0) & (gap < -gate))
        if len(crossing):
            self.touch(crossing, which[crossing], u)
            changed_set = True
        return changed_set


__all__ = ["Plane", "Punch", "ContactSet", "FrictionLinearised", "friction_force", "friction_linearised",
           "FREE", "STICK", "SLIP"]
