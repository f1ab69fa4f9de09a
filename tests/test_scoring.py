"""Table 4 scoring against masks whose scores are known on paper."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from hifumotion.io.writers import write_png_stack
from hifumotion.scoring import TRAINING_FRAMES, VALIDATION_FRAMES, score_masks


def _disc(shape, centre_px, radius_px):
    r, c = np.indices(shape)
    return (c - centre_px[0]) ** 2 + (r - centre_px[1]) ** 2 <= radius_px ** 2


def _lens_dice(radius, d):
    # two equal discs whose centres are d apart: overlap area / disc area
    overlap = 2 * radius ** 2 * math.acos(d / (2 * radius)) - d / 2 * math.sqrt(4 * radius ** 2 - d ** 2)
    return overlap / (math.pi * radius ** 2)


def test_shifted_disc_scores_as_geometry_says():
    pixel = 0.1
    truth = {f: _disc((300, 300), (150, 150), 80) for f in (20, 110, 115)}
    pred = {f: _disc((300, 300), (160, 150), 80) for f in (20, 110, 115)}   # 1 mm to the right
    table = score_masks(pred, truth, pixel)
    row = table.rows[0]
    assert row["dsc"] == pytest.approx(_lens_dice(80, 10), abs=0.005)
    assert row["centroid_error_mm"] == pytest.approx(1.0, abs=0.01)
    assert 0.5 < row["hd95_mm"] <= 1.05                  # the largest gap is the 1 mm shift
    summary = table.summary()
    assert summary["training"]["frames"] == [20] and summary["validation"]["frames"] == [110]
    assert summary["other"]["frames"] == [115]


def test_perfect_prediction_and_protocol_frames():
    assert TRAINING_FRAMES == (20, 30, 40, 50, 60, 70, 80, 90, 100)
    assert VALIDATION_FRAMES == (110, 120, 130, 140, 150, 160, 170, 180, 190)
    m = {110: _disc((64, 64), (30, 30), 12)}
    r = score_masks(m, m, 0.2).rows[0]
    assert r["dsc"] == 1.0 and r["hd95_mm"] == 0.0 and r["centroid_error_mm"] == 0.0


def test_score_cli_writes_table_and_refuses_to_overwrite(tmp_path):
    truth = tmp_path / "truth"
    pred = tmp_path / "pred"
    t = np.stack([_disc((80, 80), (40, 40), 20)] * 2)
    p = np.stack([_disc((80, 80), (42, 40), 20)] * 2)
    write_png_stack(truth / "frames", t, prefix="frame_", start=100)
    write_png_stack(pred / "frames", p, prefix="frame_", start=100)
    cmd = [sys.executable, "-m", "hifumotion", "score", str(pred), str(truth), "--spacing", "0.5"]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    data = json.loads((pred / "score" / "scores.json").read_text())
    assert data["summary"]["training"]["centroid_error_mm"]["mean"] == pytest.approx(1.0, abs=0.02)
    assert (pred / "score" / "table4.csv").read_text().startswith("frame,set,dsc")
    again = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert again.returncode == 2 and "Traceback" not in again.stderr
    # its output folder the prediction it scores: refused even with --overwrite, nothing lost
    into_itself = subprocess.run(cmd + ["-o", str(pred), "--overwrite"], capture_output=True, text=True, check=False)
    assert into_itself.returncode == 2 and "an input of this run" in into_itself.stderr
    assert len(list((pred / "frames").glob("frame_*.png"))) == 2


def test_whole_short_series_scores_on_the_scaled_protocol():
    # a whole series of 40 frames: training at 10 %…50 % of it, validation at 55 %…95 %
    truth = {f: _disc((40, 40), (20, 20), 8) for f in range(40)}
    summary = score_masks(truth, truth, 0.5).summary()
    assert summary["training"]["frames"] == list(range(4, 21, 2))
    assert summary["validation"]["frames"] == list(range(22, 39, 2))


def test_the_overlays_are_drawn_as_the_frames_files_show_them(tmp_path):
    """Row 0 at the top, as any image viewer shows a frame: a bright block in the first rows of
    the frame is in the upper half of its panel."""
    import imageio.v3 as iio

    from hifumotion.scoring import overlay_figure

    image = np.zeros((60, 80))
    image[3:15, 20:60] = 1.0
    mask = image > 0.5
    png = iio.imread(overlay_figure({0: image}, {0: mask}, {0: mask}, [0], tmp_path / "o.png", columns=1))
    grey = png[..., :3].mean(axis=2)
    rows, cols = np.nonzero(grey < 40)                  # the panel: the frame's black background
    panel = grey[rows.min():rows.max() + 1, cols.min():cols.max() + 1]
    half = panel.shape[0] // 2
    assert (panel[:half] > 200).sum() > 10 * max(1, (panel[half:] > 200).sum())
