"""The synthetic experiment (small preset): files, determinism, physics and imaging sanity."""

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.experiment import Blob, generate_twin, twin_config
from hifumotion.io.writers import read_contours_csv
from hifumotion.metrics import dice


@pytest.fixture(scope="module")
def twin(small_twin):
    return small_twin


def _digest(folder: Path, pattern: str) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.glob(pattern)):
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def test_blob_is_seeded_and_has_its_size():
    a = Blob.random((30, 18, 24), 0.12, 6, 0.2, seed=1)
    b = Blob.random((30, 18, 24), 0.12, 6, 0.2, seed=1)
    c = Blob.random((30, 18, 24), 0.12, 6, 0.2, seed=2)
    pts = a.particles(1.0)
    assert np.array_equal(pts, b.particles(1.0))
    assert not np.array_equal(pts, c.particles(1.0)[: len(pts)])
    extent = pts.max(0) - pts.min(0) + 1.0
    assert np.allclose(extent, (30, 18, 24), rtol=0.25)
    assert pts[:, 1].min() == pytest.approx(0.5)          # resting on its cut face
    # every particle is inside the body, in the body's own frame
    assert a.inside(pts - a.offset_mm()).all()
    assert a.inside(a.particles(0.7) - a.offset_mm()).all()
    assert len(pts) * 1.0 == pytest.approx(a.volume_mm3(), rel=0.03)
    # with no lumps and no cut it is the ellipsoid: π/6 abc
    e = Blob.random((30, 18, 24), 0.0, 6, 0.0, seed=0)
    assert e.volume_mm3() == pytest.approx(np.pi / 6 * 30 * 18 * 24, rel=0.01)


def test_observed_and_truth_folders(twin):
    folder, result = twin
    obs, tru = folder / "observed", folder / "truth"
    frames = sorted((obs / "frames").glob("frame_*.png"))
    masks = sorted((tru / "frames").glob("frame_*.png"))
    assert len(frames) == len(masks) == 40
    assert len(sorted((obs / "sweep").glob("slice_*.png"))) == len(sorted((tru / "sweep").glob("slice_*.png")))
    img, mask = iio.imread(frames[5]), iio.imread(masks[5])
    assert img.shape == mask.shape and set(np.unique(mask)) <= {0, 255}
    setup = json.loads((obs / "setup.json").read_text())
    assert setup["frame_interval_s"] == pytest.approx(1 / result.config.imaging.frame_rate_hz)
    # nothing of the truth in observed/
    names = {p.name for p in obs.rglob("*")}
    assert not any(k in n for n in names for k in ("truth", "parameters", "particles", "motion"))
    params = json.loads((tru / "parameters.json").read_text())
    assert params["youngs_modulus_pa"] == 13e3 and params["external_force_n"] == 0.25
    assert (tru / "particles" / "frames.pvd").is_file()
    assert result.facts["truth_tissue_particles"] >= 2 * 500 * 0.9


def test_truth_section_is_the_blob_at_rest(twin):
    # frame 0's true mask against the blob's own shape in that plane (placed as the scene
    # places it), independent of the particles: only settling separates them
    folder, result = twin
    cfg = result.config
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut,
                       int(np.random.default_rng(cfg.seed).integers(0, 2**31 - 1, 8)[0]))
    tank = np.asarray(cfg.tank.size_mm)
    placed = np.array([tank[0] / 2, 0.0, tank[2] / 2]) + blob.offset_mm()   # the floor's middle
    pts = result.probe.plane(result.probe.z_frames_mm).points_mm().reshape(-1, 3)
    shape = blob.inside(pts - placed).reshape(result.probe.shape)
    assert dice(shape, result.frame_masks[0]) > 0.93


def test_motion_is_visible_and_physical(twin):
    folder, _ = twin
    motion = json.loads((folder / "truth" / "motion.json").read_text())
    assert motion["centroid_displacement_mm"] > 0.3      # the bar pushes it visibly
    assert motion["area_change_mm2"] != 0
    checks = motion["checks"]
    assert not checks["sinks_through_floor"] and not checks["leaves_tank"] and not checks["explodes"]
    assert checks["section_empty_frames"] == 0


def test_clicked_contour_is_rough_but_near(twin):
    folder, result = twin
    clicked = list(read_contours_csv(folder / "observed" / "initial_contour.csv").values())[0]
    truth = result.frame_masks[0]
    from scipy import ndimage

    edge = truth ^ ndimage.binary_erosion(truth)
    dist_px = ndimage.distance_transform_edt(~edge)
    pts = np.rint(clicked.points_px).astype(int)
    err_mm = dist_px[pts[:, 1], pts[:, 0]] * result.probe.pixel_mm
    assert len(pts) == result.config.clinician.points
    assert 0.1 < err_mm.mean() < 1.5                       # σ = 0.6 mm: mean |error| ≈ 0.48


def test_images_show_the_tissue(twin):
    folder, result = twin
    img = result.frames[10].astype(float)
    mask = result.frame_masks[10]
    from scipy import ndimage

    ring = ndimage.binary_dilation(mask, iterations=8) & ~ndimage.binary_dilation(mask, iterations=3)
    assert img[mask].mean() > img[ring].mean() + 20      # tissue brighter than water/air around it


def test_same_seed_same_files_other_seed_other_files(twin, tmp_path):
    folder, _ = twin
    again = tmp_path / "again"
    generate_twin(twin_config("small", seed=1), again)
    for pattern in ("observed/frames/*.png", "observed/sweep/*.png", "truth/frames/*.png", "observed/*.csv"):
        assert _digest(folder, pattern) == _digest(again, pattern), pattern
    other = tmp_path / "other"
    generate_twin(twin_config("small", seed=2), other)
    assert _digest(folder, "truth/sweep/*.png") != _digest(other, "truth/sweep/*.png")
    a = iio.imread(folder / "observed/frames/frame_0000.png")
    b = iio.imread(other / "observed/frames/frame_0000.png")
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] < 0.9


def test_config_overrides_and_errors(tmp_path):
    toml = tmp_path / "twin.toml"
    toml.write_text("seed = 5\n[tissue]\nyoungs_modulus_pa = 9000.0\n[bar]\nforce_n = 0.2\n")
    cfg = twin_config("small", config_file=toml)
    assert cfg.seed == 5 and cfg.tissue.youngs_modulus_pa == 9000.0 and cfg.bar.force_n == 0.2
    assert cfg.resolution.model_tissue_particles == 500           # the preset still applies
    assert twin_config("small", config_file=toml, seed=7).seed == 7
    toml.write_text("[tissue]\npoisson_ratio = 0.7\n")
    with pytest.raises(InputError, match="tissue.poisson_ratio"):
        twin_config(config_file=toml)
    with pytest.raises(InputError, match="preset"):
        twin_config("huge")


def test_cli_print_config_and_existing_folder(tmp_path):
    run = [sys.executable, "-m", "hifumotion"]
    out = subprocess.run(run + ["experiment", "--print-config"], capture_output=True, text=True)
    assert out.returncode == 0
    assert "youngs_modulus_pa = 13000.0" in out.stdout and "in Pa" in out.stdout
    (tmp_path / "exists").mkdir()
    (tmp_path / "exists" / "keep.txt").write_text("mine")
    out = subprocess.run(run + ["experiment", "--preset", "small", "-o", str(tmp_path / "exists")],
                         capture_output=True, text=True)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert (tmp_path / "exists" / "keep.txt").read_text() == "mine"


def test_settling_is_critically_damped_for_the_slowest_mode():
    from hifumotion.experiment.twin import settling

    cfg = twin_config("small")
    duration, damping = settling(cfg, height_mm=18.0)
    omega = 0.5 * np.pi * np.sqrt(13e3 / 1050.0) / 0.018 / np.sqrt(cfg.run.mass_scaling)
    assert damping == pytest.approx(2 * omega) and duration == pytest.approx(6 / omega)
    cfg.run.settle_s, cfg.run.settle_damping_per_s = 0.5, 10.0
    assert settling(cfg, 18.0) == (0.5, 10.0)


def test_mass_scaling_keeps_the_frames(twin, tmp_path):
    # the speed-up's tolerance: the same truth with a quarter of the inertia multiplier
    from hifumotion.experiment.twin import simulate_truth, truth_sections

    _, result = twin
    cfg = result.config.model_copy(deep=True)
    cfg.run.mass_scaling /= 4
    cfg.run.particle_frames_every = 1000
    other = simulate_truth(cfg, tmp_path)
    masks = np.stack([s.mask for s in truth_sections(other, result.probe)[0]])
    dsc = np.array([dice(a, b) for a, b in zip(result.frame_masks, masks)])
    # measured on this coarse preset: min 0.94, mean ≈ 0.99 (docs/decisions.md)
    assert dsc.min() > 0.92 and dsc.mean() > 0.98


def test_load_observed_reads_what_the_twin_wrote(twin, tmp_path):
    from hifumotion.observed import load_observed

    folder, result = twin
    obs = load_observed(folder / "observed")
    assert np.array_equal(obs.frames, result.frames) and np.array_equal(obs.sweep, result.sweep)
    assert np.allclose(obs.sweep_z_mm, result.probe.sweep_z_mm, atol=1e-4)
    assert obs.frame_interval_s == pytest.approx(1 / result.config.imaging.frame_rate_hz)
    assert obs.initial_frame == 0 and len(obs.initial_contour.points_px) == result.config.clinician.points
    with pytest.raises(InputError, match="setup.json"):
        load_observed(tmp_path)


def test_observed_frames_are_read_in_the_order_of_their_numbers(twin, tmp_path):
    # frames named without zero padding sort as text frame_0, frame_1, frame_10, frame_11, …,
    # frame_2: they must be read by number; a gap, a number twice or a count from 1 is refused
    import shutil

    from hifumotion.observed import load_observed

    folder, result = twin
    copy = tmp_path / "observed"
    shutil.copytree(folder / "observed", copy)
    frames = sorted((copy / "frames").glob("frame_*.png"))
    assert len(frames) > 11
    for p in frames:
        p.rename(p.with_name(f"frame_{int(p.stem[6:])}.png"))
    assert np.array_equal(load_observed(copy).frames, result.frames)
    (copy / "frames" / "frame_5.png").rename(copy / "frames" / "frame_0005.png")
    with pytest.raises(InputError, match="number 5 twice"):
        shutil.copy(copy / "frames" / "frame_0005.png", copy / "frames" / "frame_5.png")
        load_observed(copy)
    (copy / "frames" / "frame_0005.png").unlink()
    (copy / "frames" / "frame_7.png").unlink()
    with pytest.raises(InputError, match="frame_0007.png is missing"):
        load_observed(copy)
    (copy / "frames" / "frame_0.png").unlink()
    with pytest.raises(InputError, match="numbered from 1"):
        load_observed(copy)


def test_shift_boundary_moves_a_disc_edge_by_the_offset():
    from hifumotion.observed import shift_boundary
    from conftest import disc

    px = 0.1                                        # mm; a disc of radius 2 mm
    mask = disc((80, 80), 40, 40, 20)
    for offset, radius in ((0.5, 1.5), (-0.4, 2.4)):
        area = shift_boundary(mask, offset, px).sum() * px * px
        assert area == pytest.approx(np.pi * radius**2, rel=0.06)
    assert shift_boundary(mask, 5.0, px).sum() == mask.sum()     # never erases the target


def test_edge_offset_of_a_grown_disc_is_how_much_it_grew():
    """Discs of known radii drawn on the pixel grid: the boundary of one 2.5 px bigger lies
    2.5 px outside the smaller's (the mask's boundary, half a pixel beyond its edge pixels),
    within the quarter pixel that distances between pixel centres can resolve."""
    from hifumotion.experiment.boundary_offset import edge_offset_mm

    rows, cols = np.mgrid[0:200, 0:200]
    r = np.hypot(rows - 100.3, cols - 99.6)
    truth = r <= 40.0
    assert edge_offset_mm(truth, truth, 0.3) == pytest.approx(0.0, abs=0.075)
    for grown_px in (2.5, -4.0):
        assert edge_offset_mm(r <= 40.0 + grown_px, truth, 0.3) == pytest.approx(0.3 * grown_px, abs=0.075)


def test_log_compressed_bmode_blooms_the_boundary_outwards():
    """A phantom of known shape in anechoic water: the segmented edge lies outside the true
    one (the PSF's tails show in a 50 dB display), by less than the lateral resolution."""
    from hifumotion.experiment.boundary_offset import measure_boundary_offset

    imaging = twin_config("small").imaging
    off = measure_boundary_offset(imaging, "glcv", planes=3)
    assert 0.0 < off.offset_mm < imaging.lateral_fwhm_mm
    assert len(off.per_plane_mm) == 3 and off.std_mm < 0.5


def test_rest_sweep_is_the_twins_sweep_without_its_physics(small_twin):
    """The rest sweep images the same sample in the same planes as the full twin: its true
    sections match the twin's (which settled under gravity first) and so does the clicked start."""
    from hifumotion.experiment.rest_sweep import rest_sweep
    from hifumotion.metrics import dice

    _, twin = small_twin
    rs = rest_sweep(twin.config)
    assert rs.images.shape == twin.sweep.shape and rs.images.dtype == np.uint8
    # the planes centre on the sample's mean z: its lattice here, the settled truth's there
    np.testing.assert_allclose(rs.z_mm, twin.observed.sweep_z_mm, atol=0.2)
    big = twin.sweep_masks.sum((1, 2)) > 0.3 * twin.sweep_masks.sum((1, 2)).max()
    assert min(dice(a, b) for a, b in zip(rs.masks[big], twin.sweep_masks[big])) > 0.9
    assert rs.volume_mm3 == pytest.approx(twin.parameters["facts"]["blob_volume_mm3"])
    assert rs.start == int(np.argmin(np.abs(twin.observed.sweep_z_mm - twin.observed.setup.imaging.frames_plane_z_mm)))


def test_observed_nifti_must_hold_what_the_pngs_hold(twin, tmp_path):
    """frames.nii.gz and sweep.nii.gz beside the PNGs are the same images on the same grid, or
    the folder is refused (track once read the NIfTI, calibrate the PNGs); without them the
    PNGs alone are read."""
    import shutil

    import SimpleITK as sitk

    from hifumotion.io.writers import write_nifti
    from hifumotion.observed import load_observed

    folder, result = twin
    copy = tmp_path / "observed"
    shutil.copytree(folder / "observed", copy)
    cine = copy / "frames.nii.gz"
    image = sitk.ReadImage(str(cine))
    assert image.GetSize()[-1] == len(result.frames) and image.GetSpacing()[-1] == pytest.approx(
        1 / result.config.imaging.frame_rate_hz)
    px = result.config.imaging.pixel_mm
    interval = 1 / result.config.imaging.frame_rate_hz
    edited = result.frames.copy()
    edited[3] = 255 - edited[3]                                # one frame of the NIfTI changed
    write_nifti(cine, edited, (px, px), frame_interval_s=interval)
    with pytest.raises(InputError, match="image 3 differs from frames/"):
        load_observed(copy)
    write_nifti(cine, result.frames, (px, px), frame_interval_s=2 * interval)   # another frame rate
    with pytest.raises(InputError, match="frame_interval_s"):
        load_observed(copy)
    write_nifti(cine, result.frames[:-1], (px, px), frame_interval_s=interval)
    with pytest.raises(InputError, match="shape"):
        load_observed(copy)
    cine.unlink()
    write_nifti(copy / "sweep.nii.gz", result.sweep, (2 * px, 2 * px), slice_positions_mm=result.probe.sweep_z_mm)
    with pytest.raises(InputError, match="pixel_mm"):
        load_observed(copy)
    (copy / "sweep.nii.gz").unlink()
    assert np.array_equal(load_observed(copy).frames, result.frames)
