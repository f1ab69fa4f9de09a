"""The twin that ships with the package: made by the command it names, whole, and what ``hifumotion
demo`` runs on by default."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.experiment import TwinConfig, twin_config
from hifumotion.experiment.stored import BUNDLED_PRESET, BUNDLED_SEED, bundled_twin, read_twin
from hifumotion.metrics import centroid, dice


@pytest.fixture(scope="module")
def twin():
    return read_twin(bundled_twin())


def test_it_was_made_by_the_experiment_command_at_todays_preset():
    info = json.loads((bundled_twin() / "run_info.json").read_text())
    assert info["command"] == "experiment" and info["preset"] == BUNDLED_PRESET and info["seed"] == BUNDLED_SEED
    assert info["versions"]["hifumotion"]
    # a preset changed since the twin was made leaves it stale: make it again (scripts/bundle_demo_twin.py).
    # Its settings are read by today's code, so a setting added since, whose default is what the
    # twin was made without, leaves it as it was; a changed value or default does not
    today = json.loads(twin_config(BUNDLED_PRESET, seed=BUNDLED_SEED).model_dump_json())
    stored = json.loads(TwinConfig(**info["config"]).model_dump_json())
    assert stored == today, "the bundled twin is stale: run scripts/bundle_demo_twin.py"
    assert set(_leaves(info["config"])) <= set(_leaves(today)), "a setting the twin was made with is gone"


def _leaves(tree: dict, prefix: str = "") -> list[str]:
    """The dotted names of a nested settings dict's values."""
    out = []
    for key, value in tree.items():
        out += _leaves(value, f"{prefix}{key}.") if isinstance(value, dict) else [prefix + key]
    return out


def test_its_observation_and_truth_belong_together(twin):
    n = twin.observed.setup.frames
    assert twin.frame_masks.shape == twin.observed.frames.shape == (n, *twin.observed.frames.shape[1:])
    assert twin.sweep_masks.shape == twin.sweep.shape and len(twin.sweep) == len(twin.observed.sweep_z_mm)
    assert all(m.any() for m in twin.frame_masks)
    # the clinician's rough clicks (0.6 mm off, 8 points) outline frame 0's true section
    clicked = twin.observed.initial_contour.to_mask(twin.frame_masks.shape[1:])
    assert dice(clicked, twin.frame_masks[0]) > 0.85
    # the recorded centroid path is the true sections' (within a pixel)
    path = np.asarray(twin.motion["centroid_mm"], float)
    masks = np.array([centroid(m, twin.pixel_mm) for m in twin.frame_masks])
    assert path.shape == masks.shape and np.abs(path - masks).max() < twin.pixel_mm
    assert twin.parameters["youngs_modulus_pa"] == twin.config.tissue.youngs_modulus_pa


def test_it_is_a_few_megabytes():
    size = sum(p.stat().st_size for p in bundled_twin().rglob("*") if p.is_file())
    assert size < 10e6


def test_a_folder_that_is_not_a_twin_is_one_line(tmp_path):
    (tmp_path / "observed").mkdir()
    with pytest.raises(InputError, match="observed/ and truth/"):
        read_twin(tmp_path)


def _edited_twin(tmp_path, edit):
    folder = tmp_path / "twin"
    shutil.copytree(bundled_twin(), folder)
    edit(folder / "truth")
    return folder


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: (t / "frames" / "frame_0007.png").unlink(), "199 frame_"),
    (lambda t: shutil.copy(t.parent / "observed" / "frames" / "frame_0007.png", t / "frames" / "frame_0007.png"),
     "frame_0007.png"),
    (lambda t: (t / "parameters.json").write_text('{"config": "preset"}'), "parameters.json"),
    (lambda t: (t / "parameters.json").write_text('{"config": {"imaging": {"frames": "many"}}}'), "imaging.frames"),
    (lambda t: (t / "motion.json").write_text("[1, 2]"), "motion.json"),
    (lambda t: (t / "motion.json").write_text("{"), "motion.json"),
])
def test_a_damaged_twin_is_one_error_naming_the_file(tmp_path, edit, fragment):
    with pytest.raises(InputError) as err:
        read_twin(_edited_twin(tmp_path, edit))
    assert fragment in str(err.value) and "\n" not in str(err.value)


@pytest.mark.slow
def test_the_demo_runs_on_it_by_default(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "hifumotion", "demo", "-o", str(out), "--workers", "1",
                           "--max-evaluations", "1", "--images", "1"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    info = json.loads((out / "run_info.json").read_text())
    assert info["config"]["twin"].startswith("the package's twin")
    assert "experiment: generate the synthetic twin" not in info["timings_s"]
    # the twin's own record travels with it
    assert json.loads((out / "experiment" / "run_info.json").read_text())["command"] == "experiment"
    summary = info["summary"]
    assert summary["truth"] == "twin's true sections" and summary["validation_dsc_mean"] > 0.9
    assert (out / "report" / "report.html").is_file()
