"""The known solids' geometry on the imaging plane, against distances computed another way."""

from __future__ import annotations

import numpy as np
import pytest

from hifumotion.observed.setup import BarSetup
from hifumotion.observed.solids import bar_distance_mm


def _brute_force_distance(points, tip, axis, radius, length, edge, n=240):
    """Distance (mm) from each point to a dense sampling of the bar's surface — the two end
    discs less their rims, the two rim quarter-tori, the side — signed by whether the point
    lies inside the rounded solid (inside the sharp cylinder and not in a rim's corner)."""
    u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.outer(np.cos(phi), u) + np.outer(np.sin(phi), v)            # unit radial directions
    surface = []
    for end, sign in ((0.0, 1.0), (-length, -1.0)):                     # the two end faces
        for r in np.linspace(0.0, radius - edge, n // 4):
            surface.append(tip + end * axis + r * ring)
        for t in np.linspace(0.0, np.pi / 2, n // 8):                    # the rim
            r = radius - edge + edge * np.sin(t)
            a = end - sign * edge + sign * edge * np.cos(t)
            surface.append(tip + a * axis + r * ring)
    for a in np.linspace(-length + edge, -edge, n // 2):                 # the side
        surface.append(tip + a * axis + radius * ring)
    surface = np.concatenate(surface)
    d = np.array([np.min(np.linalg.norm(surface - p, axis=1)) for p in points])
    rel = points - tip
    along = rel @ axis
    radial = np.linalg.norm(rel - np.outer(along, axis), axis=1)
    corner_a = np.clip(along, -length + edge, -edge)
    in_corner = (np.abs(along - corner_a) > 0) & (radial > radius - edge)
    inside = (along <= 0) & (along >= -length) & (radial <= radius)
    inside &= ~in_corner | (np.hypot(along - corner_a, radial - (radius - edge)) <= edge)
    return np.where(inside, -d, d)


@pytest.mark.parametrize("edge", [0.0, 0.8])
def test_the_bars_signed_distance_is_the_distance_to_its_surface(edge):
    """Points around the face, the rim, the side and inside a tilted bar: ``bar_distance_mm``
    never farther than the nearest of a dense sampling of the surface and within 0.04 mm of it,
    with its sign."""
    axis = np.array([0.6, -0.8, 0.0])
    bar = BarSetup(radius_mm=5.0, length_mm=12.0, direction=tuple(axis), tip_at_rest_mm=(10.0, 20.0, 5.0),
                   edge_radius_mm=max(edge, 1e-9))
    rng = np.random.default_rng(7)
    tip = np.array(bar.tip_at_rest_mm)
    points = tip + rng.uniform(-7.0, 7.0, (300, 3)) + np.outer(rng.uniform(-8.0, 2.0, 300), axis)
    expected = _brute_force_distance(points, tip, axis, 5.0, 12.0, edge)
    got = bar_distance_mm(points, bar, edge_radius_mm=edge)
    assert ((got > 0) == (expected > 0)).all()
    # a sampled surface is never nearer than the surface, and no farther than its sampling (≤ 0.07 mm)
    assert (np.abs(got) <= np.abs(expected) + 1e-9).all()
    assert (np.abs(expected) - np.abs(got)).max() < 0.04


def test_the_known_solids_masks_are_where_their_distances_are_not_positive():
    """A tilted bar 1 mm off the imaging plane, and the floor: their masks are the pixels their
    signed distances put inside, and a point on the bar's axis in front of its tip is as far
    from it as it is along the axis."""
    from hifumotion.observed import BarSetup, ImagingGeometry, PushSchedule, Setup, TankSetup
    from hifumotion.observed.solids import imaging_plane, known_solids

    imaging = ImagingGeometry(image_shape=[90, 120], pixel_mm=0.3, column_axis=[1.0, 0.0, 0.0],
                              row_axis=[0.0, 1.0, 0.0], row0_col0_mm=[0.0, -3.0], frames_plane_z_mm=10.0,
                              sweep_z_mm=[10.0])
    bar = BarSetup(radius_mm=4.0, length_mm=10.0, direction=(0.5, -0.866, 0.0), tip_at_rest_mm=(18.0, 15.0, 11.0))
    setup = Setup(frame_interval_s=0.05, frames=2, initial_contour_frame=0, imaging=imaging,
                  tank=TankSetup(size_mm=(40.0, 30.0, 20.0), water_depth_mm=25.0), bar=bar,
                  push=PushSchedule(shape="ramp_hold", ramp_s=0.1))
    solids = known_solids(imaging_plane(setup), setup)
    assert solids.bar.sum() > 500 and solids.floor.any()
    assert np.array_equal(solids.bar, (solids.bar_distance_px <= 0) & ~solids.floor)
    assert np.array_equal(solids.floor, solids.floor_distance_px < 0)
    axis = np.asarray(bar.direction) / np.linalg.norm(bar.direction)
    ahead = np.asarray(bar.tip_at_rest_mm) + 2.0 * axis
    assert bar_distance_mm(ahead[None], bar)[0] == pytest.approx(2.0, abs=1e-9)
