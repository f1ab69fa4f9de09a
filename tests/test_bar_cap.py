"""The top a bar's exclusion cut from a sweep, continued under the bar (observed.bar_cap).

The truths are closed-form shapes: a body with a paraboloid top (which the quadratic the
module fits can represent exactly) and a spherical top (which it can only approximate), each
sampled on a stack of planes, cut as the sweep's segmentation is (the bar grown by a margin
excluded) and filled again.
"""

import numpy as np
import pytest

from hifumotion.observed.bar_cap import fill_under_bar

PIXEL, GAP = 0.1, 0.5          # mm: the planes' pixels and the sweep's plane spacing
RADIUS, MARGIN = 3.0, 0.5      # mm: the bar and the exclusion's margin


def _planes(shape=(80, 160), planes=25):
    """``(N, H, W, 3)`` pixel centres: columns along x, rows along y (upwards), planes along z."""
    y = np.arange(shape[0]) * PIXEL
    x = np.arange(shape[1]) * PIXEL
    z = (np.arange(planes) - planes // 2) * GAP
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    return np.stack([xx, yy, zz], axis=-1)


def _cut(body, pts, tip, axis):
    rel = pts - tip
    along = rel @ axis
    radial = np.linalg.norm(rel - along[..., None] * axis, axis=-1)
    excluded = (along <= MARGIN) & (along >= -10.0) & (radial <= RADIUS + MARGIN)
    return body & ~excluded


def _top_depths(mask, pts, tip, axis, within):
    """The first tissue's depth below the face along the axis, per (plane, column) under the face."""
    rel = pts - tip
    along = rel @ axis
    radial = np.linalg.norm(rel - along[..., None] * axis, axis=-1)
    depth = np.where(mask & (radial <= within), along, np.inf)
    first = depth.min(axis=1)                     # over rows: the bar is vertical
    return first[np.isfinite(first)]


@pytest.mark.parametrize("curvature_mm", [30.0, 12.0])
def test_a_paraboloid_top_cut_by_the_exclusion_is_filled_back_to_the_face(curvature_mm):
    pts = _planes()
    centre_x, apex_y = 8.0, 6.0
    r2 = (pts[..., 0] - centre_x) ** 2 + pts[..., 2] ** 2
    body = (pts[..., 1] <= apex_y - r2 / (2 * curvature_mm)) & (pts[..., 1] >= 0.5)
    axis = np.array([0.0, -1.0, 0.0])
    tip = np.array([centre_x, apex_y, 0.0])          # resting on the apex
    cut = _cut(body, pts, tip, axis)
    assert (body & ~cut).sum() > 200                 # the exclusion took the cap

    filled, cap = fill_under_bar(cut, pts, tip, axis, RADIUS, MARGIN, (PIXEL, GAP))

    assert cap.skipped == ""
    assert cap.apex_depth_mm == pytest.approx(0.0, abs=PIXEL)
    assert (filled & ~body).sum() <= 0.1 * (body & ~cut).sum()
    # the surface under the face is back where the paraboloid is, to a pixel
    true_top = _top_depths(body, pts, tip, axis, RADIUS)
    assert np.abs(_top_depths(filled, pts, tip, axis, RADIUS) - true_top).max() <= PIXEL + 1e-9
    assert _top_depths(cut, pts, tip, axis, RADIUS).min() > MARGIN   # before: a margin below
    missing = (body & ~filled).sum()
    assert missing <= 0.1 * (body & ~cut).sum()


def test_a_spherical_top_is_continued_to_within_two_pixels():
    pts = _planes()
    centre = np.array([8.0, 6.0 - 10.0, 0.0])
    body = (np.linalg.norm(pts - centre, axis=-1) <= 10.0) & (pts[..., 1] >= 0.5)
    axis = np.array([0.0, -1.0, 0.0])
    tip = np.array([8.0, 6.0, 0.0])
    cut = _cut(body, pts, tip, axis)
    filled, cap = fill_under_bar(cut, pts, tip, axis, RADIUS, MARGIN, (PIXEL, GAP))
    assert cap.filled_voxels > 0
    gap = _top_depths(filled, pts, tip, axis, RADIUS) - _top_depths(body, pts, tip, axis, RADIUS)
    assert np.abs(gap).max() <= 2 * PIXEL + 1e-9


def test_a_tilted_bar_on_a_tilted_plane_top_is_filled_along_its_axis():
    # the bar at 20 degrees in the planes, resting flat on a top tilted with it
    pts = _planes(shape=(100, 160))
    angle = np.radians(20.0)
    axis = np.array([np.sin(angle), -np.cos(angle), 0.0])
    tip = np.array([8.0, 7.0, 0.0])
    body = (((pts - tip) @ axis) >= 0.0) & (pts[..., 1] >= 0.5) & (np.abs(pts[..., 0] - 8.0) <= 6.0)
    cut = _cut(body, pts, tip, axis)
    filled, cap = fill_under_bar(cut, pts, tip, axis, RADIUS, MARGIN, (PIXEL, GAP))
    under = np.linalg.norm((pts - tip) - ((pts - tip) @ axis)[..., None] * axis, axis=-1) <= RADIUS
    lost = (body & ~cut & under).sum()
    assert lost > 200
    assert (body & ~filled & under).sum() <= 0.1 * lost
    assert (filled & ~body).sum() <= 0.1 * lost


def test_a_bar_clear_of_the_tissue_changes_nothing():
    pts = _planes()
    r2 = (pts[..., 0] - 8.0) ** 2 + pts[..., 2] ** 2
    body = (pts[..., 1] <= 4.0 - r2 / 60.0) & (pts[..., 1] >= 0.5)
    axis = np.array([0.0, -1.0, 0.0])
    tip = np.array([8.0, 6.0, 0.0])                   # 2 mm above the apex: outside the margin
    cut = _cut(body, pts, tip, axis)
    assert (cut == body).all()
    filled, cap = fill_under_bar(cut, pts, tip, axis, RADIUS, MARGIN, (PIXEL, GAP))
    assert (filled == body).all() and cap.filled_voxels == 0 and cap.skipped


def test_a_top_not_seen_around_the_bar_is_left_as_it_is():
    # the tissue no wider than the bar: nothing of its top outside the exclusion to continue
    pts = _planes()
    body = (np.hypot(pts[..., 0] - 8.0, pts[..., 2]) <= RADIUS) & (pts[..., 1] <= 6.0) & (pts[..., 1] >= 0.5)
    axis = np.array([0.0, -1.0, 0.0])
    tip = np.array([8.0, 6.0, 0.0])
    cut = _cut(body, pts, tip, axis)
    filled, cap = fill_under_bar(cut, pts, tip, axis, RADIUS, MARGIN, (PIXEL, GAP))
    assert (filled == cut).all() and "too little" in cap.skipped


def test_a_section_cut_under_the_bar_is_continued_up_to_the_shape_that_is_known_there():
    # one plane of the paraboloid body: its mask cut 0.8 mm under the face (a bloom wider than the
    # margin), the body's own signed distance as the 3D shape; the fill restores the cut pixels
    from hifumotion.observed.bar_cap import fill_section_under_bar

    pts = _planes(planes=1)[0]
    centre_x, apex_y, curvature = 8.0, 6.0, 30.0
    top = apex_y - (pts[..., 0] - centre_x) ** 2 / (2 * curvature)
    body = (pts[..., 1] <= top) & (pts[..., 1] >= 0.5)
    tip, axis = np.array([centre_x, apex_y, 0.0]), np.array([0.0, -1.0, 0.0])
    cut = body & ~((apex_y - pts[..., 1] <= 0.8) & (np.abs(pts[..., 0] - centre_x) <= RADIUS + MARGIN))
    lost = (body & ~cut).sum()
    assert lost > 100
    filled = fill_section_under_bar(cut, pts, top - pts[..., 1], tip, axis, RADIUS, MARGIN)
    under = np.abs(pts[..., 0] - centre_x) <= RADIUS + MARGIN
    wrong = filled[under] != body[under]      # up to two pixels whose centre lies on the surface
    assert wrong.sum() <= 2, wrong.sum()
    assert (filled[~under] == cut[~under]).all()
