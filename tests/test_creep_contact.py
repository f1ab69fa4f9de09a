"""The contact set's geometry: the bar is a solid cylinder with a rounded rim.

Truths by construction: the distance of a point to the bar is taken here by brute force,
from a dense sampling of its flat face, rounded rim and side, and which points are inside it
by the solid's own definition (a disc, a torus' quarter, a cylinder), independently of
:mod:`hifumotion.creep.contact`.
"""

from __future__ import annotations

import numpy as np

from hifumotion.creep.contact import ContactSet, ContactPlane, Punch

RADIUS_M = 3e-3
EDGE_M = 0.8e-3
TILT = np.deg2rad(35.0)
AXIS = np.array([np.sin(TILT), -np.cos(TILT), 0.0])
TIP_M = np.array([0.0, 10e-3, 0.0])
E1 = np.cross(AXIS, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(AXIS, [0.0, 0.0, 1.0]))
E2 = np.cross(AXIS, E1)


def _set(points_m: np.ndarray, edge_m: float = EDGE_M) -> ContactSet:
    punch = Punch(tip_m=tuple(TIP_M), axis=tuple(AXIS), radius_m=RADIUS_M, force_n=lambda t: 0.0, friction=0.3,
                  edge_radius_m=edge_m)
    floor = ContactPlane(point_m=(0.0, -1.0, 0.0), normal=(0.0, 1.0, 0.0))   # far below: never the nearest
    return ContactSet(points_m, [floor], punch)


def _at(along, across, phi):
    """Points (m) at ``along`` the axis from the face, ``across`` it, at angle ``phi`` round it."""
    return (TIP_M + np.asarray(along)[..., None] * AXIS + (np.asarray(across) * np.cos(phi))[..., None] * E1
            + (np.asarray(across) * np.sin(phi))[..., None] * E2)


def _bar_surface() -> np.ndarray:
    """A dense sampling (m) of the bar's surface: flat face to R − r/2, quarter-torus rim, side at R + r/2."""
    phi = np.linspace(0, 2 * np.pi, 541)[:, None]
    core = RADIUS_M - EDGE_M / 2
    face = _at(np.zeros((541, 200)), np.linspace(0, core, 200)[None, :] * np.ones_like(phi), phi)
    psi = np.linspace(0, np.pi / 2, 120)[None, :]
    rim = _at(-EDGE_M + EDGE_M * np.cos(psi) * np.ones_like(phi), core + EDGE_M * np.sin(psi), phi)
    side = _at(np.linspace(-EDGE_M, -6e-3, 300)[None, :] * np.ones_like(phi), (RADIUS_M + EDGE_M / 2) * np.ones((541, 300)), phi)
    return np.vstack([face.reshape(-1, 3), rim.reshape(-1, 3), side.reshape(-1, 3)])


def _inside(points_m: np.ndarray) -> np.ndarray:
    rel = points_m - TIP_M
    along = rel @ AXIS
    across = np.linalg.norm(rel - along[:, None] * AXIS, axis=1)
    core = RADIUS_M - EDGE_M / 2
    in_torus = np.hypot(across - core, along + EDGE_M) <= EDGE_M
    return (((across <= core) & (along <= 0)) | ((across <= RADIUS_M + EDGE_M / 2) & (along <= -EDGE_M))
            | (in_torus & (across >= core) & (along >= -EDGE_M)))


def test_the_bars_signed_distance_is_the_distance_to_its_face_rim_and_side():
    rng = np.random.default_rng(3)
    n = 120
    points = _at(rng.uniform(-2e-3, 1e-3, n), rng.uniform(0, 4.5e-3, n), rng.uniform(0, 2 * np.pi, n))
    cs = _set(points)
    distance, normal = cs.bar_distance(points, 0.0)
    surface = _bar_surface()
    nearest = np.array([np.linalg.norm(surface - p, axis=1).min() for p in points])
    expected = np.where(_inside(points), -nearest, nearest)
    # the sampling is within ~3e-5 m of every point of the surface
    assert np.allclose(distance, expected, atol=4e-5)
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0)
    # the normal is the distance's gradient
    h = 1e-7
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        grad = (cs.bar_distance(points + step, 0.0)[0] - cs.bar_distance(points - step, 0.0)[0]) / (2 * h)
        assert np.allclose(grad, normal[:, k], atol=1e-5)


def test_with_a_sharp_edge_the_bar_is_a_disc_on_a_cylinder():
    points = _at(np.array([0.5e-3, -0.5e-3, -0.5e-3, 0.5e-3]), np.array([1e-3, 2.9e-3, 3.2e-3, 3.2e-3]), 0.3)
    distance, normal = _set(points, 0.0).bar_distance(points, 0.0)
    # in front of the face; inside, nearer the side (0.1 mm) than the face (0.5 mm); beside it;
    # in front beyond the rim (to the rim's circle)
    assert np.allclose(distance, [0.5e-3, -0.1e-3, 0.2e-3, np.hypot(0.2e-3, 0.5e-3)], atol=1e-12)
    assert np.allclose(normal[0], AXIS) and np.allclose(normal[2] @ AXIS, 0.0)


def test_a_contact_is_held_on_the_tangent_plane_where_it_touched_which_the_bar_carries():
    # a face point and a rim point, each 0.1 mm inside the bar
    rim_dir = np.cos(0.7) * AXIS + np.sin(0.7) * E1
    rim_centre = TIP_M - EDGE_M * AXIS + (RADIUS_M - EDGE_M / 2) * E1
    points = np.array([TIP_M - 0.1e-3 * AXIS + 1e-3 * E2, rim_centre + (EDGE_M - 0.1e-3) * rim_dir])
    cs = _set(points)
    u = np.zeros_like(points)
    gap, which = cs.gaps(u, 0.0)
    assert np.allclose(gap, -0.1e-3) and np.all(which == cs.punch_index)
    cs.touch(np.array([0, 1]), which, u, 0.0)
    normal = cs.frames_of(np.array([0, 1]))[:, 0]
    assert np.allclose(normal, [AXIS, rim_dir])
    const, coef = cs.prescribed_normal(np.array([0, 1]))
    assert np.allclose(coef, [1.0, np.cos(0.7)])
    touched = points + 0.1e-3 * normal          # the surface points they touched
    for advance in (0.0, 0.4e-3):
        held = points + (const + coef * advance)[:, None] * normal
        # on the tangent plane at the point touched, moved with the bar
        assert np.allclose(np.einsum("nk,nk->n", held - touched - advance * AXIS, normal), 0.0, atol=1e-15)
    assert np.allclose(cs.bar_distance(touched, 0.0)[0], 0.0, atol=1e-15)
    # the force along the axis: each normal reaction times a·n
    cs.pressure[:] = [2.0, 3.0]
    assert np.isclose(cs.bar_force(), 2.0 + 3.0 * np.cos(0.7))


def test_a_contact_sliding_over_the_rim_turns_its_plane_and_a_face_contact_keeps_its_own():
    rim_centre = TIP_M - EDGE_M * AXIS + (RADIUS_M - EDGE_M / 2) * E1
    points = np.array([TIP_M + 1e-3 * E2, rim_centre + EDGE_M * (np.cos(0.3) * AXIS + np.sin(0.3) * E1)])
    cs = _set(points)
    u = np.zeros_like(points)
    cs.touch(np.array([0, 1]), np.array([cs.punch_index] * 2), u, 0.0)
    version, face_frame = cs.version, cs.node_frames[0].copy()
    # both slide: the face node along the face, the rim node on round the rim to 1.1 rad
    moved = np.array([TIP_M + 1.5e-3 * E2, rim_centre + EDGE_M * (np.cos(1.1) * AXIS + np.sin(1.1) * E1)])
    cs.refresh_bar(moved - points, 0.0)
    assert cs.version == version + 1
    assert np.array_equal(cs.node_frames[0], face_frame)
    assert np.allclose(cs.node_frames[1, 0], np.cos(1.1) * AXIS + np.sin(1.1) * E1)
    const, coef = cs.prescribed_normal(np.array([1]))
    held = points[1] + const * cs.node_frames[1, 0]
    assert np.isclose((held - moved[1]) @ cs.node_frames[1, 0], 0.0, atol=1e-12)
