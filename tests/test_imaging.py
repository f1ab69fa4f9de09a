"""The B-mode simulator against physics: speckle statistics, speckle size, attenuation,
speckle attached to moving tissue; and the phantoms' layout."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hifumotion.imaging import Scatterers, Transducer, make_phantom, simulate_frame, write_phantom

SHAPE, SPACING = (256, 256), (0.1, 0.1)
EXTENT = (SHAPE[0] * SPACING[0], SHAPE[1] * SPACING[1])


def uniform(positions):
    return np.ones(len(positions))


def quiet(**kw):
    """No attenuation, no TGC, no noise: the speckle alone."""
    return Transducer(attenuation_db_cm_mhz=0.0, tgc_error=0.0, tgc_ripple_db=0.0, noise_db=-120.0,
                      focus_depth_mm=12.8, rayleigh_length_mm=1e6, **kw)


def test_fully_developed_speckle_is_rayleigh():
    """Envelope mean/std of fully developed speckle: √(π/(4−π)) = 1.913 (Rayleigh)."""
    tr = quiet()
    ratios = []
    for seed in range(3):
        frame = simulate_frame(uniform, Scatterers.uniform(EXTENT, tr, seed), None, SHAPE, SPACING, tr)
        env = frame.envelope[20:-20, 20:-20]
        ratios.append(env.mean() / env.std())
    assert np.mean(ratios) == pytest.approx(np.sqrt(np.pi / (4 - np.pi)), rel=0.05)


def fwhm_of_autocovariance(intensity: np.ndarray, axis: int, spacing: float) -> float:
    x = intensity - intensity.mean()
    spectrum = np.abs(np.fft.fft(x, axis=axis, n=2 * x.shape[axis])) ** 2
    acf = np.real(np.fft.ifft(spectrum, axis=axis)).mean(axis=1 - axis)
    acf = acf[: x.shape[axis] // 4] / acf[0]
    k = int(np.argmax(acf < 0.5))
    half = (k - 1) + (acf[k - 1] - 0.5) / (acf[k - 1] - acf[k])  # linear interpolation of the crossing
    return 2.0 * half * spacing


def test_speckle_size_matches_the_psf():
    """For a Gaussian PSF the intensity autocovariance has the PSF amplitude's FWHM."""
    tr = quiet(axial_fwhm_mm=0.5, lateral_fwhm_mm=1.2)
    ax, lat = [], []
    for seed in range(3):
        frame = simulate_frame(uniform, Scatterers.uniform(EXTENT, tr, seed), None, SHAPE, SPACING, tr)
        intensity = frame.envelope[20:-20, 20:-20] ** 2
        ax.append(fwhm_of_autocovariance(intensity, 0, SPACING[0]))
        lat.append(fwhm_of_autocovariance(intensity, 1, SPACING[1]))
    assert np.mean(ax) == pytest.approx(0.5, rel=0.15)
    assert np.mean(lat) == pytest.approx(1.2, rel=0.15)


def test_attenuation_slope_without_tgc():
    """Mean log-brightness falls with depth at 2 α f0 (round trip) when nothing compensates."""
    alpha, f0 = 0.7, 4.0
    tr = Transducer(center_frequency_mhz=f0, attenuation_db_cm_mhz=alpha, tgc_error=1.0, tgc_ripple_db=0.0,
                    noise_db=-150.0, rayleigh_length_mm=1e6)
    db_rows = []
    for seed in range(2):
        frame = simulate_frame(uniform, Scatterers.uniform(EXTENT, tr, seed), None, SHAPE, SPACING, tr)
        db_rows.append((20 * np.log10(frame.envelope[10:-10] + 1e-30)).mean(axis=1))
    depth_mm = np.arange(10, SHAPE[0] - 10) * SPACING[0]
    slope_db_per_mm = np.polyfit(depth_mm, np.mean(db_rows, axis=0), 1)[0]
    expected = -2 * alpha * f0 / 10.0
    assert slope_db_per_mm == pytest.approx(expected, rel=0.10)


def test_speckle_moves_with_the_tissue():
    """Translating the scatterers translates the speckle: consecutive frames stay correlated."""
    tr = quiet()
    scat = Scatterers.uniform(EXTENT, tr, 5)
    shift_mm = np.array([1.0, 0.0])  # 10 px laterally
    a = simulate_frame(uniform, scat, None, SHAPE, SPACING, tr).envelope
    b = simulate_frame(uniform, scat, scat.positions_mm + shift_mm, SHAPE, SPACING, tr).envelope
    crop_a, crop_b = a[20:-20, 20:-40], b[20:-20, 30:-30]
    assert np.corrcoef(crop_a.ravel(), crop_b.ravel())[0, 1] > 0.95
    fresh = simulate_frame(uniform, Scatterers.uniform(EXTENT, tr, 6), None, SHAPE, SPACING, tr).envelope
    assert abs(np.corrcoef(a[20:-20, 20:-40].ravel(), fresh[20:-20, 30:-30].ravel())[0, 1]) < 0.1


def test_phantom_is_reproducible_and_seeded():
    a = make_phantom("irregular", "medium", seed=4)
    b = make_phantom("irregular", "medium", seed=4)
    c = make_phantom("irregular", "medium", seed=5)
    assert np.array_equal(a["image"], b["image"]) and np.array_equal(a["mask"], b["mask"])
    assert not np.array_equal(a["image"], c["image"])
    assert a["image"].dtype == np.uint8


def test_phantom_initial_contours_follow_the_data_readme(tmp_path):
    from hifumotion.io import load_initial_contours, read_mask
    from hifumotion.metrics import dice

    scores = []
    for seed in range(4):
        ph = make_phantom("ellipse" if seed % 2 else "irregular", "easy", seed=seed)
        write_phantom(tmp_path / f"p{seed}", ph)
        inits = load_initial_contours(tmp_path / f"p{seed}" / "init.json")
        truth = read_mask(tmp_path / f"p{seed}" / "masks" / "phantom.png")
        scores.append(dice(inits["phantom.png"].to_mask(truth.shape), truth))
        entry = json.loads((tmp_path / f"p{seed}" / "init.json").read_text())["phantom.png"]
        assert len(entry["points"]) == 6
    assert 0.55 < np.mean(scores) < 0.75  # the ellipse at 70 % of the axes: about half the area


def test_echogenicity_map_sets_the_inclusion_contrast():
    """A disc of backscatter power 0.25 (−6 dB) images 6 dB darker than the background."""
    from hifumotion.imaging import simulate_image

    rows, cols = np.mgrid[0:256, 0:256]
    disc = np.hypot(rows - 128, cols - 128) < 50
    echo = np.where(disc, 0.25, 1.0)
    contrasts = []
    for seed in range(3):
        frame = simulate_image(echo, SPACING, quiet(), seed=seed)
        inner = np.hypot(rows - 128, cols - 128) < 40
        outer = (np.hypot(rows - 128, cols - 128) > 65) & (rows > 20) & (rows < 236) & (cols > 20) & (cols < 236)
        contrasts.append(10 * np.log10(np.mean(frame.envelope[inner] ** 2) / np.mean(frame.envelope[outer] ** 2)))
    assert np.mean(contrasts) == pytest.approx(10 * np.log10(0.25), abs=0.6)


def test_bad_echogenicity_is_a_clear_error():
    from hifumotion.errors import InputError
    from hifumotion.imaging import simulate_image

    with pytest.raises(InputError, match="echogenicity"):
        simulate_image(-np.ones((32, 32)), SPACING)
