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
* a contact that pulls (λ_n below −``release_rtol`` of the largest reaction: a pull smaller than
  what the round's solve resolves is no pull) is released — but not on its first reaction, which that
  guessed friction made (it takes a zero one and the next round decides); one released
  within a step comes back in that step only if it crosses by ``left_tolerance_m`` (an
  edge node of a rough patch can otherwise chatter on and off the surface, as the FE
  reference's rule has it).

The bar is a solid cylinder of ``radius_m`` whose end's edge is rounded (``edge_radius_m``,
centred on the real edge): a flat face, a quarter-torus rim and a side. A node touches it
where its signed distance to that solid is below the tolerance, and is held on the solid's **tangent plane where it
touched** (its own normal ``n``), which the bar carries along its axis ``a``: its normal
displacement is prescribed as ``const + (a·n) s``. At each step's end the tangent planes are
taken again where the contacts now are (:meth:`ContactSet.refresh_bar`): a node that slides
off the face turns over the rim onto the side, whose normal, across the axis, no longer
pushes it. Why the whole solid and a rounded edge (docs/decisions.md, "The bar is a solid with a rounded rim"): a node
held on the face's unbounded plane beyond the rim is pushed by a face that is not there;
released there, tissue beside the rim that a sliding sample brings under the disc is
already behind the face's plane, and held on it at once is moved that whole depth in one
step, by a force that grows as the step shrinks; held on a sharp rim's side it hooks the
sample. A rounded edge lets it pass under, as it does under a real bar.

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
from numba import njit

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
class ContactPlane:
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

    ``edge_radius_m``: the bar's own rounding of its rim (m; None: not known). The solver rounds
    the rim at the larger of it and ``CreepSettings.bar_edge_spacings`` spacings — a voxel mesh
    cannot see a sharper edge. ``force_n(t)`` is the push (N) at time t
    (s); ``breakpoints_s`` the times where the schedule bends (the integrator lands a step on each). With ``travel_m`` (travel control)
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
    edge_radius_m: float | None = None

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

    ``body[i]``: −1 free, ``0 … P−1`` the planes, ``P`` the bar (each of its contacts has its own
    tangent plane: frame ``node_frames[i]``, normal first, at ``node_offset[i]`` along it when
    the bar's advance is 0); ``status[i]`` FREE,
    STICK (held rigidly by a bonded plane) or SLIP (in frictional contact); ``anchor[i]``
    the displacement (m) its friction pulls it back to (module docstring); ``pressure[i]``
    its last normal reaction (N); ``fresh[i]``: touched, its first reaction not yet known.
    """

    def __init__(self, rest_m: np.ndarray, planes: list[ContactPlane], punch: Punch | None):
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
            normals.append(np.asarray(punch.axis, float))
            if punch.edge_radius_m is None or not 0.0 <= punch.edge_radius_m <= punch.radius_m:
                raise ValueError("the bar's edge radius must be set, between 0 and its radius")
        self.body_frames = _frames(np.array(normals)) if normals else np.zeros((0, 3, 3))
        self.node_frames = np.zeros((n, 3, 3))
        self.node_offset = np.zeros(n)
        self.friction = np.array([p.friction for p in self.planes] + ([punch.friction] if punch else []))
        self.bonded = np.array([p.bonded for p in self.planes] + ([False] if punch else []), bool)
        self.version = 0  # bumped whenever the constrained set changes

    @property
    def punch_index(self) -> int:
        """The body index of the bar."""
        return len(self.planes)

    def on_bar(self) -> np.ndarray:
        """The nodes touching the bar."""
        return np.flatnonzero(self.body == self.punch_index)

    def bar_force(self) -> float:
        """The force (N) the bar takes along its axis: its contacts' normal reactions, each times a·n."""
        nodes = self.on_bar()
        axis = self.body_frames[self.punch_index, 0]
        return float(self.pressure[nodes] @ (self.node_frames[nodes, 0] @ axis))

    def _core_radius_m(self) -> float:
        """The radius (m) where the flat face ends and the rounded rim begins: R − r/2."""
        return self.punch.radius_m - 0.5 * float(self.punch.edge_radius_m)

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
            gap, _ = self.bar_distance(self.rest + u, advance_m)
            closer = gap < best
            best[closer], which[closer] = gap[closer], self.punch_index
        return best, which

    def _in_bar(self, x_m: np.ndarray, advance_m: float):
        """Positions ``x_m`` (m) relative to the bar: along its axis beyond the face's plane, from
        the axis (m), and the unit radial direction (any unit vector across the axis on it)."""
        a = self.body_frames[self.punch_index, 0]
        rel = x_m - (np.asarray(self.punch.tip_m) + advance_m * a)
        along = rel @ a
        lateral = rel - along[:, None] * a
        across = np.linalg.norm(lateral, axis=1)
        on_axis = across < 1e-300
        radial = np.where(on_axis[:, None], self.body_frames[self.punch_index, 1],
                          lateral / np.where(on_axis, 1.0, across)[:, None])
        return along, across, radial

    def bar_distance(self, x_m: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (m; negative inside) of positions ``x_m`` (m) to the bar, and its
        outward unit normal there: the solid is a cylinder of radius R − r/2 whose face is r behind
        the real one, grown by a ball of radius r — a flat face to R − r/2, a rim rounded at r
        centred on the real one (the face neither shrunk nor grown on average), a side at R + r/2."""
        x = np.ascontiguousarray(x_m, float).reshape(-1, 3)
        distance = np.empty(len(x))
        normal = np.empty((len(x), 3))
        _bar_distances(x, *self.bar_geometry(advance_m), distance, normal)
        return distance, normal

    def bar_geometry(self, advance_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """The bar's face centre (m) advanced by ``advance_m``, its axis, a unit vector across it,
        the rounded core's radius R − r/2 (m) and the rim's radius r (m): :func:`bar_point`'s."""
        frame = self.body_frames[self.punch_index]
        a = np.ascontiguousarray(frame[0], float)
        tip = np.asarray(self.punch.tip_m, float) + advance_m * a
        return tip, a, np.ascontiguousarray(frame[1], float), self._core_radius_m(), float(self.punch.edge_radius_m)

    def under_face(self, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """How far (m) the bar must advance along its axis to touch each node (its gap along the
        axis to the face or the rounded rim), and whether the node is under the bar at all."""
        along, across, _ = self._in_bar(self.rest + u, advance_m)
        r = float(self.punch.edge_radius_m)
        out = np.clip(across - self._core_radius_m(), 0.0, r)
        # the rim recedes behind the face's plane by r − √(r² − out²)
        return along + r - np.sqrt(r * r - out * out), across <= self.punch.radius_m + 0.5 * r

    def prescribed_normal(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For contact nodes: the normal displacement that closes their gap, as
        ``constant + coefficient × s`` (m; the coefficient is 1 for the punch)."""
        const = np.zeros(len(nodes))
        coef = np.zeros(len(nodes))
        for k, plane in enumerate(self.planes):
            on = self.body[nodes] == k
            const[on] = -(self.rest[nodes[on]] - np.asarray(plane.point_m)) @ self.body_frames[k, 0]
        if self.punch is not None:
            # the tangent plane where the node touched, carried along the axis: n·x = offset + (a·n) s
            on = np.flatnonzero(self.body[nodes] == self.punch_index)
            normal = self.node_frames[nodes[on], 0]
            const[on] = self.node_offset[nodes[on]] - np.einsum("nk,nk->n", self.rest[nodes[on]], normal)
            coef[on] = normal @ self.body_frames[self.punch_index, 0]
        return const, coef

    def touch(self, nodes: np.ndarray, bodies: np.ndarray, u: np.ndarray, advance_m: float = 0.0) -> None:
        """Make ``nodes`` contacts of ``bodies``, anchored where they are now (the bar at ``advance_m``)."""
        if len(nodes) == 0:
            return
        held = (self.body >= 0) & (self.pressure > 0)
        for b in np.unique(bodies):
            mine = held & (self.body == b)
            self.pressure[nodes[bodies == b]] = self.pressure[mine].mean() if mine.any() else 0.0
        self.body[nodes] = bodies
        if self.punch is not None:
            on_bar = nodes[bodies == self.punch_index]
            self.node_frames[on_bar], self.node_offset[on_bar] = self._tangent_planes(on_bar, u, advance_m)
        self.fresh[nodes] = True
        self.status[nodes] = np.where(self.bonded[bodies], STICK, SLIP)
        self.anchor[nodes] = u[nodes]
        self.version += 1

    def _tangent_planes(self, nodes: np.ndarray, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The bar's tangent planes at its surface point nearest each of ``nodes``: their frames
        ``(m, 3, 3)`` (normal first) and offsets (m) along the normal at advance 0."""
        x = self.rest[nodes] + u[nodes]
        gap, normal = self.bar_distance(x, advance_m)
        a = self.body_frames[self.punch_index, 0]
        # the surface point x − gap n lies on the plane; at advance 0 the plane is (a·n) advance back
        return _frames(normal), np.einsum("nk,nk->n", x, normal) - gap - advance_m * (normal @ a)

    def refresh_bar(self, u: np.ndarray, advance_m: float, turn_rad: float = 1e-6) -> None:
        """End of a step: each bar contact's tangent plane taken again where it now is, if its
        normal turned by more than ``turn_rad`` (a node sliding over the rounded rim); the others
        keep theirs exactly (a face contact's never changes)."""
        nodes = self.on_bar()
        if len(nodes) == 0:
            return
        frames, offset = self._tangent_planes(nodes, u, advance_m)
        cos = np.einsum("nk,nk->n", frames[:, 0], self.node_frames[nodes, 0])
        turned = np.arccos(np.clip(cos, -1.0, 1.0)) > turn_rad
        if turned.any():
            self.node_frames[nodes[turned]], self.node_offset[nodes[turned]] = frames[turned], offset[turned]
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
        """``(m, 3, 3)`` contact frames of ``nodes`` (normal first): their plane's, or their own on the bar."""
        frames = self.body_frames[self.body[nodes]]
        if self.punch is not None:
            bar = self.body[nodes] == self.punch_index
            frames[bar] = self.node_frames[nodes[bar]]
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
               left_tolerance_m: float, release_rtol: float = 1e-9) -> bool:
        """One round of the active-set rules (module docstring); True if the set changed.

        ``u`` the displacement just solved (m), ``reaction`` the constraint forces on the
        nodes (N, (n, 3)); the contacts' normal reactions are kept in ``pressure``. A free
        node touches when it is ``tolerance_m`` behind a surface, one released in this step
        (``left``, cleared by the caller at a step's start) ``left_tolerance_m``. A contact
        pulls when its normal reaction is below −``release_rtol`` of the largest reaction: the
        caller's solve is accurate to about that, and a release decided below it is decided by
        the solver's rounding (measured: a single-precision factor whose solutions moved in their
        7th digit after another PARDISO call in the process released a pressed block's every
        contact with the bar).
        """
        changed_set = False
        contact = np.flatnonzero(self.body >= 0)
        if len(contact):
            normal = self.record_pressure(reaction)
            scale = max(np.abs(reaction).max(), 1e-300)
            fresh = self.fresh[contact]
            pulling = (normal < -release_rtol * scale) & ~self.bonded[self.body[contact]] & ~fresh
            if fresh.any():
                self.fresh[contact] = False
                changed_set = True
            if pulling.any():
                self.release(contact[pulling])
                self.left[contact[pulling]] = True
                changed_set = True
        gap, which = self.gaps(u, advance_m)
        gate = np.where(self.left, left_tolerance_m, tolerance_m)
        crossing = np.flatnonzero((self.body < 0) & (which >= 0) & (gap < -gate))
        if len(crossing):
            self.touch(crossing, which[crossing], u, advance_m)
            changed_set = True
        return changed_set


@njit(cache=True)
def bar_point(x0, x1, x2, tip, a, across_unit, core_m, rim_m, normal):
    """The signed distance (m; negative inside) of the point (x0, x1, x2) (m) to the bar's rounded
    solid (:meth:`ContactSet.bar_distance`), its outward unit normal into ``normal`` (3,)."""
    r0, r1, r2 = x0 - tip[0], x1 - tip[1], x2 - tip[2]
    along = r0 * a[0] + r1 * a[1] + r2 * a[2]
    l0, l1, l2 = r0 - along * a[0], r1 - along * a[1], r2 - along * a[2]
    across = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
    if across < 1e-300:          # on the axis: any direction across it is radial
        l0, l1, l2 = across_unit[0], across_unit[1], across_unit[2]
    else:
        l0, l1, l2 = l0 / across, l1 / across, l2 / across
    front = along + rim_m        # beyond the core's face
    out = across - core_m        # beyond the core's side
    if out > 0.0 and front > 0.0:                    # the rounded rim
        corner = np.hypot(out, front)
        normal[0] = (out * l0 + front * a[0]) / corner
        normal[1] = (out * l1 + front * a[1]) / corner
        normal[2] = (out * l2 + front * a[2]) / corner
        return corner - rim_m
    if out > 0.0 or (front <= 0.0 and out > front):  # beside, or inside and nearer the side
        normal[0], normal[1], normal[2] = l0, l1, l2
        return out - rim_m
    normal[0], normal[1], normal[2] = a[0], a[1], a[2]   # before the face, or inside and nearer it
    return front - rim_m


@njit(cache=True)
def _bar_distances(x, tip, a, across_unit, core_m, rim_m, distance, normal):
    for i in range(x.shape[0]):
        distance[i] = bar_point(x[i, 0], x[i, 1], x[i, 2], tip, a, across_unit, core_m, rim_m, normal[i])


__all__ = ["ContactPlane", "Punch", "ContactSet", "FrictionLinearised", "friction_force", "friction_linearised",
           "FREE", "STICK", "SLIP"]
