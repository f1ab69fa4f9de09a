"""Contacts as constraints: rigid planes (floor, tank walls) and the bar's flat end (SI).

A node in contact is held *on* the solid's surface — its normal displacement is
prescribed, so no tissue crosses the floor or the bar, at any spacing — and either
**sticks** (its tangential displacement held where it touched) or **slips** (tangential
free, pushed back by the Coulomb force μ_f λ_n against the way it would go). The sets
change by the usual active-set rules (Wriggers, *Computational Contact Mechanics*, §6):

* a free node that has crossed a surface becomes a stuck contact;
* a contact that pulls (λ_n < 0) is released;
* a stuck contact whose tangential reaction exceeds μ_f λ_n slips, the friction along it;
* a slipping node that would move along its friction force sticks again.

The bar is a rigid punch translating along its axis only (a bar in a guide, as the
explicit path's): its advance ``s`` (m) is one more unknown, and its force schedule F(t)
(N) is balanced by the normal reactions of the nodes under its face.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

FREE, STICK, SLIP = 0, 1, 2


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
    schedule bends (the integrator lands a step on each).
    """

    tip_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_m: float
    force_n: Callable[[float], float]
    friction: float = 0.5
    breakpoints_s: tuple[float, ...] = ()


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

    ``body[i]``: −1 free, ``0 … P−1`` the planes, ``P`` the punch; ``status[i]`` FREE,
    STICK or SLIP; ``anchor[i]`` the held tangential displacement (m) of a stuck node;
    ``direction[i]`` the unit friction direction on a slipping one; ``pressure[i]`` its
    last normal reaction (N).
    """

    def __init__(self, rest_m: np.ndarray, planes: list[Plane], punch: Punch | None):
        self.rest = np.asarray(rest_m, float)
        n = len(self.rest)
        self.planes = list(planes)
        self.punch = punch
        self.body = np.full(n, -1, np.int64)
        self.status = np.zeros(n, np.int64)
        self.anchor = np.zeros((n, 3))
        self.direction = np.zeros((n, 3))
        self.pressure = np.zeros(n)
        normals = [np.asarray(p.normal, float) for p in self.planes]
        if punch is not None:
            normals.append(np.asarray(punch.axis, float))
        self.body_frames = _frames(np.array(normals)) if normals else np.zeros((0, 3, 3))
        self.friction = np.array([p.friction for p in self.planes] + ([punch.friction] if punch else []))
        self.bonded = np.array([p.bonded for p in self.planes] + ([False] if punch else []), bool)
        self.version = 0  # bumped whenever the constrained set changes

    @property
    def punch_index(self) -> int:
        return len(self.planes)

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
            along, under = self.under_face(u, advance_m)
            under &= along < best
            best[under], which[under] = along[under], self.punch_index
        return best, which

    def under_face(self, u: np.ndarray, advance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Every node's distance (m) beyond the punch's face along its axis, and whether it is under the face."""
        a = self.body_frames[self.punch_index, 0]
        rel = self.rest + u - (np.asarray(self.punch.tip_m) + advance_m * a)
        along = rel @ a
        across = np.linalg.norm(rel - along[:, None] * a, axis=1)
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
        return const, coef

    def touch(self, nodes: np.ndarray, bodies: np.ndarray, u: np.ndarray) -> None:
        """Make ``nodes`` stuck contacts of ``bodies``, held where they are now."""
        if len(nodes) == 0:
            return
        self.body[nodes] = bodies
        # on a frictionless solid a contact slips from the start (it has nothing to stick with)
        self.status[nodes] = np.where((self.friction[bodies] > 0) | self.bonded[bodies], STICK, SLIP)
        self.direction[nodes] = 0.0
        self.anchor[nodes] = u[nodes]
        self.version += 1

    def release(self, nodes: np.ndarray) -> None:
        if len(nodes) == 0:
            return
        self.body[nodes] = -1
        self.status[nodes] = FREE
        self.pressure[nodes] = 0.0
        self.version += 1

    def frames_of(self, nodes: np.ndarray) -> np.ndarray:
        return self.body_frames[self.body[nodes]]

    def update(self, u: np.ndarray, u_start: np.ndarray, reaction: np.ndarray, advance_m: float,
               tolerance_m: float, restick: bool = True) -> bool:
        """One round of the active-set rules (module docstring); True if anything changed.

        ``u`` the displacement just solved (m), ``u_start`` at the start of the step,
        ``reaction`` the constraint forces on the nodes (N, (n, 3)). ``restick=False``
        keeps slipping nodes slipping (within a step, so stick and slip do not chatter).
        """
        changed_set = False
        contact = np.flatnonzero(self.body >= 0)
        if len(contact):
            frames = self.frames_of(contact)
            normal = np.einsum("nk,nk->n", reaction[contact], frames[:, 0])
            scale = max(np.abs(reaction).max(), 1e-300)
            tangential = reaction[contact] - normal[:, None] * frames[:, 0]
            mu = self.friction[self.body[contact]]
            self.pressure[contact] = np.maximum(normal, 0.0)
            held = self.bonded[self.body[contact]]
            pulling = (normal < -1e-9 * scale) & ~held
            if pulling.any():
                self.release(contact[pulling])
                changed_set = True
            stick = (self.status[contact] == STICK) & ~pulling & ~held
            t_size = np.linalg.norm(tangential, axis=1)
            slides = stick & (t_size > mu * np.maximum(normal, 0.0) * (1 + 1e-6) + 1e-12 * scale)
            if slides.any():
                nodes = contact[slides]
                self.status[nodes] = SLIP
                self.direction[nodes] = tangential[slides] / t_size[slides, None]
                self.version += 1
                changed_set = True
            slip = (self.status[contact] == SLIP) & ~pulling & ~slides & (mu > 0)
            if restick and slip.any():
                nodes = contact[slip]
                moved = u[nodes] - u_start[nodes]
                moved -= np.einsum("nk,nk->n", moved, frames[slip, 0])[:, None] * frames[slip, 0]
                back = np.einsum("nk,nk->n", moved, self.direction[nodes]) > tolerance_m
                if back.any():  # moving along the friction force: it sticks where it is
                    self.status[nodes[back]] = STICK
                    self.anchor[nodes[back]] = u[nodes[back]]
                    self.version += 1
                    changed_set = True
        gap, which = self.gaps(u, advance_m)
        crossing = np.flatnonzero((self.body < 0) & (which >= 0) & (gap < -tolerance_m))
        if len(crossing):
            self.touch(crossing, which[crossing], u)
            changed_set = True
        return changed_set


__all__ = ["Plane", "Punch", "ContactSet", "FREE", "STICK", "SLIP"]
