"""The GAC's global solver: the circular shortest path against exhaustive search, and the
least-length contour on shapes whose answer is known."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hifumotion.contour import Ellipse
from hifumotion.errors import InputError
from hifumotion.metrics import dice
from hifumotion.segmentation import segment
from hifumotion.segmentation._minimal_path import closed_geodesic


def brute_force(g, rho_min, rho, dtheta, slope):
    """The least weighted length over every closed path, by enumeration."""
    nt, nr = g.shape
    best = np.inf
    for path in itertools.product(range(nr), repeat=nt):
        if any(path[t] < rho_min[t] for t in range(nt)):
            continue
        if any(abs(path[t] - path[t - 1]) > slope for t in range(nt)):  # t = 0 closes the curve
            continue
        length = sum(g[t, path[t]] * np.hypot(rho[path[t]] * dtheta, rho[path[t]] - rho[path[t - 1]]) for t in range(nt))
        best = min(best, length)
    return best


@pytest.mark.parametrize("seed", range(12))
def test_the_closed_path_is_the_shortest_of_all(seed):
    rng = np.random.default_rng(seed)
    nt, nr = 6, 6
    g = rng.random((nt, nr)) + 0.05
    rho = 1.0 + 0.5 * np.arange(nr)
    rho_min = rng.integers(0, 3, nt)
    path, length = closed_geodesic(g, rho_min, rho, 2 * np.pi / nt, 1)
    assert np.all(path >= rho_min)
    assert np.all(np.abs(np.diff(np.r_[path, path[0]])) <= 1)  # closed, within the slope
    assert length == pytest.approx(brute_force(g, rho_min, rho, 2 * np.pi / nt, 1), rel=1e-12)


def star(shape, cx, cy, radius, harmonics):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    theta = np.arctan2(rows - cy, cols - cx)
    r = radius * (1 + sum(a * np.cos(k * theta + p) for k, a, p in harmonics))
    return np.hypot(cols - cx, rows - cy) < r


def speckled(mask, inside, outside, seed):
    """Fully developed speckle: Rayleigh amplitudes of the region's mean, log-compressed."""
    rng = np.random.default_rng(seed)
    mean = np.where(mask, inside, outside)
    amplitude = mean * np.hypot(rng.standard_normal(mask.shape), rng.standard_normal(mask.shape)) / np.sqrt(2)
    return np.clip(np.log1p(20 * amplitude) / np.log1p(40), 0, 1)


@pytest.mark.parametrize("harmonics", [(), ((3, 0.12, 0.3), (5, 0.05, 1.1))])
def test_the_least_length_contour_finds_a_star_shaped_target_in_speckle(harmonics):
    truth = star((200, 220), 112.0, 96.0, 55.0, harmonics)
    img = speckled(truth, 0.35, 1.0, seed=3)  # a dark target in brighter tissue
    start = Ellipse(108, 100, 30, 26, 15)    # off centre, about a quarter of the area
    result = segment(img, start, "gac")
    assert result.params["solver"] == "global"
    assert dice(result.mask, truth) > 0.97
    # the descent from the same start, for scale: the global solver is not worse
    assert dice(result.mask, truth) >= dice(segment(img, start, "gac", solver="descent").mask, truth) - 0.01


def test_the_contour_surrounds_its_start_even_without_an_edge():
    img = np.full((120, 120), 0.5)
    start = Ellipse(60, 60, 20, 15, 0)
    result = segment(img, start, "gac")
    assert result.mask[start.to_mask(img.shape)].mean() > 0.995  # up to the rasterising of the start
    # no edge anywhere: the least-length curve is the tightest one around the start
    assert result.mask.sum() < 1.3 * start.to_mask(img.shape).sum()


def test_an_unknown_solver_is_named():
    with pytest.raises(InputError, match="solver"):
        segment(np.zeros((40, 40)), Ellipse(20, 20, 8, 8, 0), "gac", solver="annealing")


def test_glcv_carried_globally_and_by_its_balloon_find_the_target_in_speckle():
    truth = star((200, 220), 112.0, 96.0, 55.0, ((3, 0.12, 0.3), (5, 0.05, 1.1)))
    img = speckled(truth, 0.35, 1.0, seed=5)
    start = Ellipse(108, 100, 30, 26, 15)
    carried = segment(img, start, "glcv")  # the default
    assert carried.params["carry"] == "global" and carried.params["geodesic_length_px"] > 0
    assert dice(carried.mask, truth) > 0.97
    balloon = segment(img, start, "glcv", carry="balloon")  # the paper's way
    assert balloon.params["carry"] == "balloon"
    assert dice(carried.mask, truth) >= dice(balloon.mask, truth)
    with pytest.raises(InputError, match="carry"):
        segment(img, start, "glcv", carry="rope")


def test_tracking_refines_locally_so_a_shrinking_target_is_followed():
    """The global solvers keep their start inside the curve; tracking must not: its start, the
    previous contour, lies on the boundary, and here the target shrinks by 8 % a frame."""
    from hifumotion.segmentation import track

    frames, truths = [], []
    for k, radius in enumerate((50.0, 46.0, 42.0)):
        truth = star((180, 180), 90.0, 90.0, radius, ())
        frames.append(speckled(truth, 0.35, 1.0, seed=10 + k))
        truths.append(truth)
    result = track(np.stack(frames), Ellipse(90, 90, 30, 30, 0), "gac")
    assert result.results[0].params["solver"] == "global" and dice(result.results[0].mask, truths[0]) > 0.97
    assert all(r.params["solver"] == "descent" for r in result.results[1:])
    result = track(np.stack(frames), Ellipse(90, 90, 30, 30, 0), "glcv", carry="global")
    assert all(r.params["carry"] == "global" for r in result.results)  # what the caller asks for is kept
    from hifumotion.segmentation import local_params

    assert local_params("glcv") == {"carry": "balloon"} and local_params("lcv") == {}
    result = track(np.stack(frames), Ellipse(90, 90, 30, 30, 0), "glcv")
    # a globally carried contour could not have shrunk below its start, the previous frame
    assert result.results[-1].mask.sum() < result.results[0].mask.sum()


def test_polar_sampling_is_scipys_bilinear_interpolation():
    """The compiled sampler against SciPy's order-1 interpolation continued by the border values,
    at points inside and beyond the image."""
    from scipy import ndimage

    from hifumotion.segmentation._minimal_path import _bilinear

    rng = np.random.default_rng(0)
    img = rng.random((40, 50))
    rows, cols = rng.uniform(-5, 45, (30, 70)), rng.uniform(-5, 55, (30, 70))
    expected = ndimage.map_coordinates(img, [rows, cols], order=1, mode="nearest")
    np.testing.assert_allclose(_bilinear(img, rows, cols), expected, rtol=0, atol=1e-12)
