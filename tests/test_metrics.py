"""Metrics against answers known on paper."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import disc

from hifumotion.contour import Contour
from hifumotion.errors import InputError
from hifumotion.metrics import boundary_distances, centroid_distance, dice, hausdorff, mssd, score


def lens_area(r: float, d: float) -> float:
    """Area of the intersection of two discs of radius r whose centres are d apart."""
    return 2 * r**2 * np.arccos(d / (2 * r)) - (d / 2) * np.sqrt(4 * r**2 - d**2)


def circle(r: float, cx: float = 0.0, cy: float = 0.0, n: int = 2000) -> Contour:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return Contour(np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)]))


@pytest.mark.parametrize("d", [0.0, 10.0, 25.0, 60.0])
def test_dice_of_offset_discs_matches_lens_formula(d):
    r = 40.0
    a = disc((200, 260), 100, 100, r)
    b = disc((200, 260), 100 + d, 100, r)
    expected = lens_area(r, d) / (np.pi * r**2)
    assert dice(a, b) == pytest.approx(expected, abs=0.005)


def test_disjoint_and_identical_masks():
    a = disc((100, 100), 25, 50, 10)
    b = disc((100, 100), 75, 50, 10)
    assert dice(a, b) == 0.0
    assert dice(a, a) == 1.0
    assert hausdorff(a, a) == 0.0
    assert mssd(a, a) == 0.0
    assert centroid_distance(a, a) == 0.0


def test_concentric_circles_exact_contours():
    inner, outer = circle(20.0), circle(35.0)
    d_ab, d_ba = boundary_distances(inner, outer)
    assert np.allclose(d_ab, 15.0, atol=1e-3)
    assert np.allclose(d_ba, 15.0, atol=1e-3)


def test_concentric_circles_masks_hausdorff_and_mssd():
    a = disc((160, 160), 80, 80, 20)
    b = disc((160, 160), 80, 80, 50)
    # The 0.5 iso-line of a rasterised circle deviates from the circle by under one pixel.
    assert hausdorff(a, b) == pytest.approx(30.0, abs=1.0)
    assert hausdorff(a, b, percentile=95) == pytest.approx(30.0, abs=1.0)
    assert mssd(a, b) == pytest.approx(30.0**2, rel=0.05)


def test_spacing_is_row_then_column():
    # A circle of radius 10 mm and one of 15 mm drawn on a grid of 0.5 mm rows, 0.25 mm columns.
    row_mm, col_mm = 0.5, 0.25
    rows, cols = np.mgrid[0:120, 0:240]
    x_mm, y_mm = (cols - 120) * col_mm, (rows - 60) * row_mm
    r = np.hypot(x_mm, y_mm)
    a, b = r <= 10.0, r <= 15.0
    assert hausdorff(a, b, spacing=(row_mm, col_mm)) == pytest.approx(5.0, abs=0.5)
    # the swapped spacing describes other shapes (ellipses), whose distance is not 5 mm
    assert abs(hausdorff(a, b, spacing=(col_mm, row_mm)) - 5.0) > 1.0


def test_centroid_distance_of_offset_discs_in_mm():
    a = disc((150, 200), 60, 50, 20)
    b = disc((150, 200), 60 + 30, 50 + 40, 20)
    assert centroid_distance(a, b) == pytest.approx(50.0, abs=1e-9)
    assert centroid_distance(a, b, spacing=0.1) == pytest.approx(5.0, abs=1e-9)


def test_hd95_ignores_a_thin_spike():
    a = np.zeros((300, 300), bool)
    a[30:270, 30:270] = True
    b = a.copy()
    b[148:151, 270:290] = True  # a 20 px spike: 4 % of the boundary
    assert hausdorff(a, b) == pytest.approx(20.0, abs=1.0)
    assert hausdorff(a, b, percentile=95) < 3.0


def test_score_with_an_empty_prediction():
    truth = disc((50, 50), 25, 25, 10)
    out = score(np.zeros_like(truth), truth)
    assert out["dsc"] == 0.0 and np.isinf(out["hausdorff"])


def test_bad_inputs_raise_clear_errors():
    a = disc((50, 50), 25, 25, 10)
    with pytest.raises(InputError, match="differ in shape"):
        dice(a, a[:40])
    with pytest.raises(InputError, match="no foreground"):
        hausdorff(a, np.zeros_like(a))
    with pytest.raises(InputError, match="positive"):
        hausdorff(a, a, spacing=-1)
