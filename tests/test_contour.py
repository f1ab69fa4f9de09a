"""Contours, ellipses and clicked points: conventions and round trips."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import disc

from hifumotion.contour import ClickedPoints, Contour, Ellipse, parse_init_entry
from hifumotion.errors import InputError
from hifumotion.io import load_initial_contours, read_mask
from hifumotion.metrics import dice


def test_mask_to_contour_to_mask_round_trip():
    mask = disc((120, 150), 70, 55, 30)
    mask[40:50, 90:110] = True  # not convex
    back = Contour.from_mask(mask).to_mask(mask.shape)
    assert dice(mask, back) > 0.995


def test_contour_geometry_in_mm():
    # a 40 x 20 px rectangle with 0.5 mm rows and 0.25 mm columns is 10 mm wide and 10 mm high
    pts = np.array([[10, 10], [50, 10], [50, 30], [10, 30]], float)
    c = Contour(pts, spacing_mm=(0.5, 0.25))
    assert c.area_mm2 == pytest.approx(100.0)
    assert c.length_mm == pytest.approx(40.0)
    assert np.allclose(c.centroid_mm, [30 * 0.25, 20 * 0.5])
    assert np.allclose(Contour.from_mm(c.points_mm, (0.5, 0.25)).points_px, pts)


def test_ellipse_follows_the_data_readme_convention():
    e = Ellipse(cx=60, cy=50, a=40, b=20, angle_deg=90)  # a along +y (down)
    pts = e.points(4)
    assert np.allclose(pts[0], [60, 90])  # t = 0: cx + a cos A, cy + a sin A
    mask = e.to_mask((100, 120))
    assert mask[85, 60] and not mask[50, 85]
    assert mask.sum() == pytest.approx(np.pi * 40 * 20, rel=0.01)


def test_clicked_points_smooth_curve_passes_through_each_point():
    pts = np.array([[50, 20], [80, 50], [50, 80], [20, 50], [30, 28]], float)
    curve = ClickedPoints(pts).smooth(n=2000).points_px
    for p in pts:
        assert np.min(np.linalg.norm(curve - p, axis=1)) < 0.2


def test_parse_init_entry_kinds_and_errors():
    entry = {"ellipse": {"cx": 1, "cy": 2, "a": 3, "b": 4, "angle_deg": 5}, "points": [[0, 0], [5, 0], [5, 5]]}
    assert isinstance(parse_init_entry(entry), Ellipse)
    assert isinstance(parse_init_entry(entry, "points"), ClickedPoints)
    with pytest.raises(InputError, match="no 'points'"):
        parse_init_entry({"ellipse": entry["ellipse"]}, "points")
    with pytest.raises(InputError, match="semi-axes"):
        parse_init_entry({"ellipse": {"cx": 1, "cy": 2, "a": -3, "b": 4}})


def test_shared_init_contours_score_as_documented(shared_data):
    """The data README: the rough starts overlap the expert masks with DSC ≈ 0.66."""
    inits = load_initial_contours(shared_data / "ddti" / "init.json")
    init_points = load_initial_contours(shared_data / "ddti" / "init.json", kind="points")
    dsc_e, dsc_p = [], []
    for name in sorted(inits)[:20]:
        truth = read_mask(shared_data / "ddti" / "masks" / name)
        dsc_e.append(dice(inits[name].to_mask(truth.shape), truth))
        dsc_p.append(dice(init_points[name].to_mask(truth.shape, smooth=False), truth))
    assert 0.55 < np.mean(dsc_e) < 0.75
    assert 0.55 < np.mean(dsc_p) < 0.75


def test_init_json_errors(tmp_path):
    bad = tmp_path / "init.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_initial_contours(bad)
    bad.write_text(json.dumps({"a.png": {"points": [[1, 2]]}}))
    with pytest.raises(InputError, match=r"a.png.*at least 3"):
        load_initial_contours(bad)


def test_mask_boundaries_are_scikit_images_iso_lines():
    """The compiled marching squares give scikit-image's 0.5 iso-lines of the padded mask: the
    same closed curves, point for point up to where each starts, in the same orientation,
    holes and diagonal (saddle) contacts included."""
    from scipy import ndimage
    from skimage.measure import find_contours

    from hifumotion.contour import _polygon_area, mask_boundaries_px

    rows, cols = np.mgrid[0:60, 0:70]
    r = np.hypot(cols - 30, rows - 28)
    diagonal = np.zeros((60, 70), bool)
    diagonal[10, 10] = diagonal[11, 11] = True
    textured = [ndimage.gaussian_filter(np.random.default_rng(k).random((60, 70)), 2) > 0.5 for k in range(3)]
    edge = np.zeros((60, 70), bool)
    edge[:20, 50:] = True  # touches the image's border
    for mask in [r < 15, (r < 20) & ~(r < 8), diagonal, edge, *textured]:
        ours = mask_boundaries_px(mask)
        theirs = [c[:-1, ::-1] - 1.0 for c in find_contours(np.pad(mask.astype(float), 1), 0.5)]
        assert len(ours) == len(theirs) > 0
        for c in theirs:
            match = [o for o in ours if len(o) == len(c) and np.any(np.all(np.isclose(o, c[0]), axis=1))]
            assert len(match) == 1
            o = match[0]
            k = int(np.flatnonzero(np.all(np.isclose(o, c[0]), axis=1))[0])
            np.testing.assert_allclose(np.roll(o, -k, axis=0), c, atol=1e-12)
            assert np.sign(_polygon_area(o)) == np.sign(_polygon_area(c))
