"""The contact set's geometry: the bar is a solid cylinder (face and side), its face a disc.

Truths by construction: the distance of a point to a cylinder is taken here by brute force,
from sampled points of its face and side, independently of :mod:`hifumotion.creep.contact`.
"""

from __future__ import annotations

import numpy as np

from hifumotion.creep.contact import FREE, SLIP, ContactSet, Plane, Punch

RADIUS_M = 3e-3
TILT = np.deg2rad(35.0)
AXIS = np.array([np.sin(TILT), -np.cos(TILT), 0.0])
TIP_M = np.array([0.0, 10e-3, 0.0])


def _set(points_m: np.ndarray) -> ContactSet:
    punch = Punch(tip_m=tuple(TIP_M), axis=tuple(AXIS), radius_m=RADIUS_M, force_n=lambda t: 0.0, friction=0.3)
    floor = Plane(point_m=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.0))   # far below: never the nearest
    return ContactSet(points_m, [floor], punch)


def _depth_inside_cylinder(points_m: np.ndarray) -> np.ndarray:
    """How deep (m) each point is inside the bar (a cylinder from its face backwards): the
    distance to the nearest of a dense sampling of its face disc and side wall."""
    helper = np.cross(AXIS, [0.0, 0.0, 1.0])
    e1 = helper / np.linalg.norm(helper)
    e2 = np.cross(AXIS, e1)
    r, phi = np.meshgrid(np.linspace(0, RADIUS_M, 300), np.linspace(0, 2 * np.pi, 721))
    face = TIP_M + (r * np.cos(phi)).ravel()[:, None] * e1 + (r * np.sin(phi)).ravel()[:, None] * e2
    back, phi = np.meshgrid(np.linspace(0, 8e-3, 400), np.linspace(0, 2 * np.pi, 721))
    side = (TIP_M - back.ravel()[:, None] * AXIS + RADIUS_M * (np.cos(phi).ravel()[:, None] * e1
                                                               + np.sin(phi).ravel()[:, None] * e2))
    wall = np.vstack([face, side])
    return np.array([np.linalg.norm(wall - p, axis=1).min() for p in points_m])


def _points_inside(rng: np.random.Generator, n: int) -> np.ndarray:
    """Points inside the bar within 1 mm of its face."""
    helper = np.cross(AXIS, [0.0, 0.0, 1.0])
    e1 = helper / np.linalg.norm(helper)
    e2 = np.cross(AXIS, e1)
    r = RADIUS_M * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    back = rng.uniform(0.0, 1e-3, n)
    return TIP_M - back[:, None] * AXIS + (r * np.cos(phi))[:, None] * e1 + (r * np.sin(phi))[:, None] * e2


def test_a_point_inside_the_bar_is_given_to_its_nearer_wall_at_its_depth():
    points = _points_inside(np.random.default_rng(3), 60)
    cs = _set(points)
    gap, which = cs.gaps(np.zeros_like(points), 0.0)
    depth = _depth_inside_cylinder(points)
    # the sampled walls are within ~1.5e-5 m of every point of the true ones
    assert np.allclose(-gap, depth, atol=2e-5)
    assert set(which) == {cs.punch_index, cs.side_index}
    # the side wins exactly where the rim is nearer than the face's plane
    along = (points - TIP_M) @ AXIS
    across = np.linalg.norm(points - TIP_M - along[:, None] * AXIS, axis=1)
    assert np.array_equal(which == cs.side_index, RADIUS_M - across < -along)


def test_a_side_contact_is_held_on_the_cylinder_and_its_normal_points_out_of_the_bar():
    points = _points_inside(np.random.default_rng(4), 60)
    cs = _set(points)
    u = np.zeros_like(points)
    gap, which = cs.gaps(u, 0.0)
    side = np.flatnonzero(which == cs.side_index)
    assert len(side) > 5
    cs.touch(side, which[side], u)
    const, coef = cs.prescribed_normal(side)
    assert np.all(coef == 0.0)   # the bar moves along its axis, across the side's normal
    normal = cs.frames_of(side)[:, 0]
    held = points[side] + const[:, None] * normal
    along = (held - TIP_M) @ AXIS
    across = np.linalg.norm(held - TIP_M - along[:, None] * AXIS, axis=1)
    assert np.allclose(across, RADIUS_M, atol=1e-12)
    assert np.all(const > 0)     # moved outwards, by the depth the gap gave
    assert np.allclose(const, -gap[side], atol=1e-12)
    frames = cs.frames_of(side)
    assert np.allclose(np.einsum("nij,nkj->nik", frames, frames), np.eye(3), atol=1e-12)


def test_a_face_contact_beyond_the_rim_and_a_side_contact_in_front_of_the_face_are_released():
    # on the face's plane: one inside the disc, one beyond its rim; one beside the rim behind the plane
    helper = np.cross(AXIS, [0.0, 0.0, 1.0])
    e1 = helper / np.linalg.norm(helper)
    points = np.array([TIP_M + 0.5 * RADIUS_M * e1, TIP_M + 1.2 * RADIUS_M * e1,
                       TIP_M + 0.999 * RADIUS_M * e1 - 0.5e-3 * AXIS])
    cs = _set(points)
    cs.touch(np.array([0, 1]), np.array([cs.punch_index, cs.punch_index]), np.zeros((3, 3)))
    cs.touch(np.array([2]), np.array([cs.side_index]), np.zeros((3, 3)))
    cs.fresh[:] = False
    reaction = np.zeros((3, 3))
    reaction[:2] = 1e-3 * AXIS              # pressing on the face (the reaction along its normal)
    reaction[2] = 1e-3 * cs.frames_of(np.array([2]))[0, 0]
    # the third node comes out in front of the face (its advance pulled back 1 mm)
    cs.update(np.zeros((3, 3)), reaction, -1e-3, 1e-6, 1e-6)
    assert cs.body[0] == cs.punch_index and cs.status[0] == SLIP
    assert cs.body[1] == -1 and cs.status[1] == FREE and cs.left[1]
    assert cs.body[2] == -1 and cs.left[2]
