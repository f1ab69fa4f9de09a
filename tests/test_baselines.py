"""Baselines against motions whose answer is known: constant velocity, a known image shift."""

import numpy as np
import pytest

from hifumotion.metrics import centroid, dice
from hifumotion.prediction import hold_last, kalman_predict, ncc_shift, ncc_track, star_descriptor, star_mask


def _ellipse(shape, cx, cy, a, b):
    r, c = np.indices(shape)
    return ((c - cx) / a) ** 2 + ((r - cy) / b) ** 2 <= 1.0


def test_star_descriptor_round_trip():
    m = _ellipse((120, 140), 70.3, 55.8, 30, 20)
    d = star_descriptor(m, 64, 0.2)
    assert d[:2] == pytest.approx([70.3 * 0.2, 55.8 * 0.2], abs=0.05)
    assert d[2] == pytest.approx(30 * 0.2, abs=0.2) and d[2 + 16] == pytest.approx(20 * 0.2, abs=0.2)
    assert dice(star_mask(d, m.shape, 0.2), m) > 0.97


def test_hold_last_holds_the_last():
    a, b = _ellipse((50, 50), 20, 20, 8, 6), _ellipse((50, 50), 25, 20, 8, 6)
    out = hold_last({10: a, 20: b}, [30, 40])
    assert np.array_equal(out[30], b) and np.array_equal(out[40], b)


def test_kalman_extrapolates_a_constant_velocity():
    # an ellipse moving 0.5 mm/s in x and shrinking 0.1 mm/s in its half-height, seen every
    # 0.5 s for 5 s: the filter must carry both on to 9.5 s
    pixel, shape = 0.1, (200, 300)
    def at(t):
        return _ellipse(shape, 100 + 5.0 * t, 100, 40, 30 - 1.0 * t)
    observed = {f: at(f * 0.05) for f in range(20, 101, 10)}      # frames at 20 Hz
    pred = kalman_predict(observed, [190], 0.05, pixel)
    truth = at(190 * 0.05)
    c_err = np.linalg.norm(centroid(pred[190], pixel) - centroid(truth, pixel))
    held = np.linalg.norm(centroid(observed[100], pixel) - centroid(truth, pixel))
    assert c_err < 0.25 * held and c_err < 0.2
    assert dice(pred[190], truth) > max(0.95, dice(observed[100], truth) + 0.05)


def test_ncc_finds_a_known_shift_of_speckle():
    rng = np.random.default_rng(0)
    from scipy import ndimage

    img = ndimage.gaussian_filter(rng.random((120, 160)), 1.5)
    moved = np.roll(img, (3, -5), axis=(0, 1))            # 3 rows down, 5 columns left
    mask = _ellipse(img.shape, 80, 60, 20, 15)
    assert ncc_shift(img, moved, mask) == (-5, 3)
    frames = np.stack([np.roll(img, (k, -2 * k), axis=(0, 1)) for k in range(4)])
    track = ncc_track(frames, mask)
    assert np.array_equal(track[3], np.roll(mask, (3, -6), axis=(0, 1)))


def test_a_margin_within_its_spread_over_the_frames_is_no_win():
    from conftest import disc

    from hifumotion.prediction.evaluate import margin_over

    frames = list(range(8))
    truth = {f: disc((60, 60), 20 + f, 30, 10) for f in frames}
    hold = {f: disc((60, 60), 20, 30, 10) for f in frames}
    # exactly the truth: better than holding still
    assert margin_over(truth, hold, truth, 0.2, frames)["verdict"] == "better"
    # 2 px off on even frames, exact on odd, against a baseline 1 px off on all: no better
    alternating = {f: disc((60, 60), 20 + f + (2 if f % 2 == 0 else 0), 30, 10) for f in frames}
    near = {f: disc((60, 60), 21 + f, 30, 10) for f in frames}
    assert margin_over(alternating, near, truth, 0.2, frames)["verdict"] == "no better"
    # moving away from the truth: worse than holding still
    away = {f: disc((60, 60), 20 - 2 * f, 30, 10) for f in frames}
    assert margin_over(away, hold, truth, 0.2, frames)["verdict"] == "worse"
