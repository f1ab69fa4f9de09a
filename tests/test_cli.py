"""The command line as a user runs it: a real process, its exit code and what it prints."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pydicom
import pytest

import hifumotion


def run(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hifumotion", *args], capture_output=True, text=True, cwd=cwd, timeout=120)


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error:") and "Traceback" not in proc.stderr
    for f in fragments:
        assert f in lines[0]


def test_help_and_version():
    proc = run("--help")
    assert proc.returncode == 0 and "info" in proc.stdout
    proc = run("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"hifumotion {hifumotion.__version__}"


def test_info_json_reports_what_was_read(tmp_path):
    iio.imwrite(tmp_path / "f_1.png", np.zeros((30, 40), np.uint8))
    iio.imwrite(tmp_path / "f_2.png", np.full((30, 40), 255, np.uint8))
    proc = run("info", str(tmp_path), "--spacing", "0.2,0.25", "--frame-interval", "0.05", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["frames"] == 2 and out["height_px"] == 30 and out["width_px"] == 40
    assert out["spacing_mm"] == [0.2, 0.25] and out["frame_interval_s"] == 0.05 and out["kind"] == "cine"


def test_user_errors_are_one_line_with_exit_code_2(tmp_path):
    assert_one_line_error(run("info", str(tmp_path / "missing.dcm")), "missing.dcm", "no such file")
    (tmp_path / "corrupt.png").write_bytes(b"\x89PNG garbage")
    assert_one_line_error(run("info", str(tmp_path / "corrupt.png")), "corrupt.png", "cannot read")
    (tmp_path / "data.xyz").write_text("x")
    assert_one_line_error(run("info", str(tmp_path / "data.xyz")), "unsupported format")
    iio.imwrite(tmp_path / "ok.png", np.zeros((4, 4), np.uint8))
    assert_one_line_error(run("info", str(tmp_path / "ok.png"), "--spacing", "-0.1"), "--spacing", "positive")
    ds = pydicom.Dataset()
    ds.file_meta = pydicom.dataset.FileMetaDataset()
    ds.file_meta.TransferSyntaxUID = pydicom.uid.ExplicitVRLittleEndian
    ds.file_meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.6.1"
    ds.file_meta.MediaStorageSOPInstanceUID = pydicom.uid.generate_uid()
    ds.Modality = "US"
    ds.save_as(tmp_path / "nopixels.dcm", enforce_file_format=True)
    assert_one_line_error(run("info", str(tmp_path / "nopixels.dcm")), "nopixels.dcm", "no pixel data")


def test_demo_refuses_an_existing_output_folder(tmp_path, shared_data):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    assert_one_line_error(run("demo", "-o", str(out), "--dataset", str(shared_data / "ddti")), "--overwrite")
    assert (out / "keep.txt").read_text() == "precious"


def make_dataset(root, n=2):
    """A tiny dataset in the layout of ../shared/data: noisy bright discs with their masks."""
    import json

    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    rng = np.random.default_rng(0)
    init = {}
    rows, cols = np.mgrid[0:96, 0:112]
    for k in range(n):
        cx, cy, r = 54 + 3 * k, 48, 26
        mask = (cols - cx) ** 2 + (rows - cy) ** 2 <= r * r
        img = np.clip(np.where(mask, 170, 80) + 12 * rng.standard_normal(mask.shape), 0, 255).astype(np.uint8)
        iio.imwrite(root / "images" / f"disc{k}.png", img)
        iio.imwrite(root / "masks" / f"disc{k}.png", mask.astype(np.uint8) * 255)
        init[f"disc{k}.png"] = {"ellipse": {"cx": cx, "cy": cy, "a": 20, "b": 19, "angle_deg": 0},
                                "points": [[cx - 19, cy], [cx - 8, cy - 19], [cx + 12, cy - 17], [cx + 19, cy + 2],
                                           [cx + 6, cy + 19], [cx - 14, cy + 14]]}
    (root / "init.json").write_text(json.dumps(init))
    return root


def test_segment_command_writes_masks_contours_and_run_info(tmp_path):
    data = make_dataset(tmp_path / "data", 1)
    out = tmp_path / "seg"
    proc = run("-q", "segment", str(data / "images" / "disc0.png"), "--init", str(data / "init.json"),
               "--method", "glcv", "--spacing", "0.2", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("masks/frame_0000.png", "masks.nii.gz", "contours.csv", "contours.json", "overlay.png",
                 "segmentation.json", "run_info.json"):
        assert (out / name).is_file(), name
    truth = iio.imread(data / "masks" / "disc0.png") > 0
    mask = iio.imread(out / "masks" / "frame_0000.png") > 0
    assert 2 * (mask & truth).sum() / (mask.sum() + truth.sum()) > 0.95
    info = json.loads((out / "run_info.json").read_text())
    assert info["config"]["method"] == "glcv" and "segment" in info["timings_s"]


def test_compare_command_reproduces_table2_layout(tmp_path):
    data = make_dataset(tmp_path / "data", 2)
    out = tmp_path / "cmp"
    proc = run("-q", "compare", str(data), "--methods", "cv,glcv", "--init-kind", "both", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    for tag in ("_ellipse", "_points"):
        for name in (f"comparison{tag}.csv", f"table2{tag}.md", f"figure2{tag}.png", f"figure3{tag}.png"):
            assert (out / name).is_file(), name
    table = (out / "table2_ellipse.md").read_text()
    assert "**" in table and "| mean | DSC |" in table
    csv_rows = (out / "comparison_points.csv").read_text().strip().splitlines()
    assert len(csv_rows) == 1 + 2 * 2  # header + images x methods


def test_segment_rejects_unknown_method(tmp_path):
    data = make_dataset(tmp_path / "data", 1)
    assert_one_line_error(run("segment", str(data / "images" / "disc0.png"), "--init", str(data / "init.json"),
                              "--method", "snake", "-o", str(tmp_path / "x")), "unknown method")


def test_phantom_command_writes_the_dataset_layout(tmp_path):
    out = tmp_path / "ph"
    proc = run("-q", "phantom", "--shape", "irregular", "--preset", "hard", "--seed", "3", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("images/phantom.png", "masks/phantom.png", "init.json", "run_info.json"):
        assert (out / name).is_file(), name
    assert json.loads((out / "run_info.json").read_text())["seed"] == 3
    assert_one_line_error(run("phantom", "--preset", "impossible", "-o", str(tmp_path / "x")), "--preset")


def test_reconstruct_command_from_a_folder_of_masks(tmp_path):
    rows, cols = np.mgrid[0:80, 0:90]
    zs = np.arange(-5.5, 6.0, 1.0)
    masks_dir = tmp_path / "sweep"
    masks_dir.mkdir()
    for k, z in enumerate(zs):  # an ellipsoid 14 x 11 x 12 mm (semi-axes 7, 5.5, 6) at 0.2 mm pixels
        x, y = cols * 0.2 - 9.0, rows * 0.2 - 8.0
        m = (x / 7.0) ** 2 + (y / 5.5) ** 2 <= 1 - (z / 6.0) ** 2
        iio.imwrite(masks_dir / f"slice_{k:03d}.png", m.astype(np.uint8) * 255)
    out = tmp_path / "rec"
    proc = run("-q", "reconstruct", str(masks_dir), "--slice-spacing", "1.0", "--spacing", "0.2",
               "--particle-spacing", "1.0", "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "reconstruction.json").read_text())
    assert summary["watertight"]
    assert summary["volume_mm3"] == pytest.approx(4 / 3 * np.pi * 7 * 5.5 * 6, rel=0.03)
    for name in ("tissue.stl", "tissue.ply", "tissue.vtp", "tissue_volume.nii.gz", "particles.csv", "run_info.json"):
        assert (out / name).is_file(), name
    import trimesh

    assert trimesh.load(out / "tissue.stl").is_watertight
    assert "<PolyData>" in (out / "tissue.vtp").read_text()[:300]
    assert_one_line_error(run("reconstruct", str(masks_dir), "-o", str(tmp_path / "x")), "--slice-spacing")


def test_reconstruct_reads_a_label_map_of_zeros_and_ones(tmp_path):
    """The same ellipsoid as a 0/1 label map in NIfTI, written as the twin writes its true sweep
    (``truth/sweep.nii.gz``): read as the mask it is, not as a picture whose 1 is nearly black."""
    from hifumotion.io.writers import write_masks_nifti

    rows, cols = np.mgrid[0:80, 0:90]
    zs = np.arange(-5.5, 6.0, 1.0)
    x, y = cols * 0.2 - 9.0, rows * 0.2 - 8.0
    labels = np.stack([(x / 7.0) ** 2 + (y / 5.5) ** 2 <= 1 - (z / 6.0) ** 2 for z in zs])
    write_masks_nifti(tmp_path / "sweep.nii.gz", labels, (0.2, 0.2), slice_positions_mm=zs)
    out = tmp_path / "rec"
    proc = run("-q", "reconstruct", str(tmp_path / "sweep.nii.gz"), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "reconstruction.json").read_text())
    assert summary["volume_mm3"] == pytest.approx(4 / 3 * np.pi * 7 * 5.5 * 6, rel=0.03)


def test_track_follows_the_twins_target_and_writes_its_fields(small_twin, tmp_path):
    """``hifumotion track`` on the small twin's observed folder: every file of the layout,
    the masks on the cine's grid, and contours that stay on the true section."""
    import SimpleITK as sitk

    from hifumotion.metrics import dice
    from hifumotion.scoring import read_frame_masks

    folder, result = small_twin
    out = tmp_path / "tr"
    centre = np.argwhere(read_frame_masks(folder / "truth")[0]).mean(axis=0)     # (row, col) px
    given = tmp_path / "points.csv"
    given.write_text(f"name,x_px,y_px\ncentre,{centre[1]:.2f},{centre[0]:.2f}\n")
    proc = run("track", str(folder / "observed"), "--fields", "--points", str(given), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("masks.nii.gz", "contours.csv", "displacement_x_mm.nii.gz", "displacement_y_mm.nii.gz",
                 "quality.nii.gz", "material_points.csv", "material_points.npz", "tracking.json", "motion.png",
                 "run_info.json"):
        assert (out / name).is_file(), name
    masks = sitk.GetArrayFromImage(sitk.ReadImage(str(out / "masks.nii.gz"))).reshape(result.frames.shape) > 0
    truth = read_frame_masks(folder / "truth")
    assert min(dice(masks[f], truth[f]) for f in truth) > 0.9
    summary = json.loads((out / "tracking.json").read_text())
    assert summary["frames"] == len(result.frames) and summary["material_points"]["interior"] > 10
    assert not summary["frame0_segmentation"]["given_region_kept"]
    # the given point, at the target's centre, is followed beside the region, in px and mm
    assert summary["points"]["names"] == ["centre"] and (out / "points.csv").is_file()
    assert summary["points"]["largest_shift_mm"] > 0
    # the field is cut to the target's neighbourhood and placed where it was cut from: the pixel
    # under frame 0's target centre is inside the box, and the target's material moved there
    box = summary["fields"]
    field = sitk.ReadImage(str(out / "displacement_y_mm.nii.gz"))
    row, col = summary["spacing_mm"]
    assert np.allclose(field.GetOrigin()[:2], (box["origin_px"][0] * col, box["origin_px"][1] * row))
    uy = sitk.GetArrayFromImage(field).reshape(len(result.frames), *box["shape_px"])
    quality = sitk.GetArrayFromImage(sitk.ReadImage(str(out / "quality.nii.gz"))).reshape(uy.shape)
    cy, cx = np.argwhere(masks[0]).mean(axis=0).round().astype(int)
    at = (cy - box["origin_px"][1], cx - box["origin_px"][0])
    # an estimate at the target's centre; none in the box's corner, beyond the margin
    assert quality[-1][at] > 0 and uy[-1][at] != 0 and quality[-1, 0, 0] == 0 and uy[-1, 0, 0] == 0
    points = np.load(out / "material_points.npz")
    n = summary["material_points"]["contour"] + summary["material_points"]["interior"]
    assert points["displacement_mm"].shape == (len(result.frames), n, 2) and points["rest_mm"].shape == (n, 2)
    # the contour's material moved as the truth's section did: the tracked centroid shift of
    # the last frame is that of the true masks within a pixel
    true_shift = np.linalg.norm(np.argwhere(truth[max(truth)]).mean(0) - np.argwhere(truth[min(truth)]).mean(0)) * row
    assert abs(summary["centroid_shift_mm"][max(truth)] - true_shift) < 2 * row
    # the bar's tracked push goes the way the bar points (down)
    assert summary["bar_shift_mm"][-1][1] < 0
    # PNG frames carry no pixel size: tracking them is refused, naming the option, not done in 1 mm pixels
    bare = run("track", str(folder / "observed" / "frames"), "--init", str(folder / "observed" / "initial_contour.csv"),
               "-o", str(tmp_path / "bare"))
    assert bare.returncode == 2 and "--spacing" in bare.stderr and "Traceback" not in bare.stderr
    assert not (tmp_path / "bare").exists()


def test_a_closed_pipe_is_not_an_error():
    """``hifumotion … --help | head -1``: the reader goes away early; no traceback, no error."""
    proc = subprocess.Popen([sys.executable, "-m", "hifumotion", "track", "--help"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.read(10)
    proc.stdout.close()                    # the reader has seen enough
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "Traceback" not in err and "error" not in err.lower(), err


def test_the_runs_verdict_line_shows_both_margins_it_may_rest_on():
    """A verdict earned on the centroid (DSC margin within its spread) is printed with the
    centroid margin beside the DSC one, so the line does not claim a win on 0.0003 DSC alone."""
    from hifumotion.cli.workflow import _verdict

    summary = {"physics_vs_no_motion": "better", "dsc_margin_over_no_motion": 0.0003, "dsc_margin_spread": 0.0027,
               "centroid_margin_over_no_motion_mm": 0.051, "centroid_margin_spread_mm": 0.02}
    line = _verdict(summary)
    assert line.startswith("better than holding still") and "+0.0003 ± 0.0027" in line
    assert "centroid +0.051 ± 0.020 mm" in line
    # the headline names what decided: the centroid; the DSC margin is said to be within its spread
    assert line.startswith("better than holding still by the centroid")
    assert "the DSC margin is within its spread" in line
    # a run_info.json written before has no centroid margin: the DSC one alone
    old = {k: v for k, v in summary.items() if not k.startswith("centroid")}
    assert "centroid" not in _verdict(old)


def test_flags_are_shown_as_flags_in_the_help():
    """A flag takes no value: its help line shows none (Typer printed ``--overwrite <bool>``),
    while options that take one still show its kind."""
    proc = subprocess.run([sys.executable, "-m", "hifumotion", "track", "--help"], capture_output=True, text=True,
                          timeout=60, env={**os.environ, "COLUMNS": "160"})
    assert proc.returncode == 0, proc.stderr
    overwrite = next(ln for ln in proc.stdout.splitlines() if "--overwrite" in ln)
    assert "bool" not in overwrite.lower()
    spacing = next(ln for ln in proc.stdout.splitlines() if "--spacing" in ln)
    assert "<str>" in spacing or "TEXT" in spacing


def test_long_work_prints_progress_lines_when_standard_error_is_not_a_terminal(capsys, monkeypatch):
    """A bar cannot redraw in a log file: a long stage prints a plain line now and then, and one
    when done; work shorter than the interval prints nothing (a refusal stays one line)."""
    import time

    from hifumotion import console as out

    monkeypatch.setattr(out.ProgressLines, "INTERVAL_S", 0.05)
    for _ in out.track(range(4), "frames"):
        time.sleep(0.03)
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("frames: ") and "/4)" in lines[0] and lines[-1].startswith("frames: 100 %, done in")
    monkeypatch.setattr(out.ProgressLines, "INTERVAL_S", 60.0)
    with out.progress_fraction("simulate") as update:
        update(0.5)
        update(1.0)
    assert capsys.readouterr().err == ""


def test_calibrate_options_leave_the_settings_defaults_to_the_settings():
    """Each option of ``calibrate`` that is also an ``[estimation]`` setting defaults to "not
    given", so the setting's own default applies (one home for each default): an option with a
    default of its own would silently override ``--set`` files' and the class's."""
    import typer

    from hifumotion.cli import _register_commands
    from hifumotion.cli.app import app
    from hifumotion.workflow.pipeline import EstimationConfig

    _register_commands()
    command = typer.main.get_command(app).commands["calibrate"]
    fields = set(EstimationConfig.model_fields) | {"particles"}
    aliases = {"force": "force_n", "boundary_offset": "boundary_offset_mm"}
    settings_options = [p for p in command.params
                        if p.param_type_name == "option" and aliases.get(p.name, p.name) in fields]
    assert len(settings_options) >= 8
    assert {p.name: p.default for p in settings_options if p.default is not None} == {}
