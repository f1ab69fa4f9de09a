"""Given points followed through B-mode cine of scatterers moved by a known map.

The truth is the map itself: the scatterers are moved by a chosen translation, rotation or
path, the project's B-mode simulator images them, and the tracker sees only the images.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from hifumotion.errors import InputError
from hifumotion.imaging import BModeOptions, Scatterers, Transducer, simulate_frame
from hifumotion.io.points import point_track_csv, read_points_csv
from hifumotion.speckle import PointTracker, track_points

SHAPE, PX = (128, 160), 0.2
EXTENT = (SHAPE[0] * PX, SHAPE[1] * PX)
PROBE = Transducer(attenuation_db_cm_mhz=0.0, tgc_error=0.0, tgc_ripple_db=0.0, noise_db=-120.0,
                   focus_depth_mm=12.8, rayleigh_length_mm=1e6, axial_fwhm_mm=0.45, lateral_fwhm_mm=1.1)
POINTS_PX = np.array([[50.0, 40.0], [80.5, 64.0], [110.0, 90.25], [70.0, 100.0]])


@pytest.fixture(scope="module")
def scatterers():
    return Scatterers.uniform(EXTENT, PROBE, 3)


def frame(scat, positions_mm):
    return simulate_frame(lambda p: np.ones(len(p)), scat, positions_mm, SHAPE, (PX, PX), PROBE,
                          BModeOptions(seed=0)).image


def moved_cine(scat, move_px, frames: int):
    """``frames`` images of the scatterers moved by ``move_px(t, points_px)`` (px → px)."""
    p0 = scat.positions_mm / PX
    return np.stack([frame(scat, move_px(t, p0) * PX) for t in range(frames)])


def test_points_follow_a_steady_translation_without_drift(scatterers):
    """Speckle translated by (0.6, −0.35) px a frame over 30 frames (17.4 px in all): each point
    ends within 0.5 px of where the map puts it — a frame-to-frame error of a few hundredths of
    a pixel would have added up to more."""
    v = np.array([0.6, -0.35])
    frames = moved_cine(scatterers, lambda t, p: p + t * v, 30)
    track = track_points(frames, POINTS_PX)
    truth = POINTS_PX[None] + np.arange(30)[:, None, None] * v
    err = np.linalg.norm(track.positions_px - truth, axis=2)
    assert err[0].max() == 0.0
    assert err[-1].max() < 0.5, err[-1]
    assert track.positions_px.shape == (30, 4, 2) and track.disagreement_px.shape == (30, 4)


def test_points_follow_a_rotation(scatterers):
    """The speckle rotated about the image centre by 0.5° a frame (6° over 12 frames): every
    point within 0.6 px of the rotated one, though each moves along a different path."""
    c = np.array([SHAPE[1] / 2, SHAPE[0] / 2])

    def rot(t, p):
        a = np.deg2rad(0.5 * t)
        r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        return (p - c) @ r.T + c

    frames = moved_cine(scatterers, rot, 13)
    track = track_points(frames, POINTS_PX)
    assert np.linalg.norm(track.positions_px[-1] - rot(12, POINTS_PX), axis=1).max() < 0.6


def test_frames_fed_one_by_one_give_the_recorded_cines_positions(scatterers):
    frames = moved_cine(scatterers, lambda t, p: p + t * np.array([0.4, 0.2]), 6)
    whole = track_points(frames, POINTS_PX).positions_px
    tracker = PointTracker(frames[0], POINTS_PX)
    online = [POINTS_PX] + [tracker.update(f)[0] for f in frames[1:]]
    np.testing.assert_array_equal(np.stack(online), whole)


def test_points_off_the_image_or_not_finite_are_refused():
    frames = np.zeros((3, 64, 64), np.uint8)
    for bad, words in (([[70.0, 3.0]], "outside the 64 × 64 px image"), ([[np.nan, 3.0]], "NaN"),
                       (np.zeros((0, 2)), "N ≥ 1"), ([1.0, 2.0, 3.0], "(N, 2)")):
        with pytest.raises(InputError, match="points") as exc:
            track_points(frames, bad)
        assert words in str(exc.value)
    with pytest.raises(InputError, match="names"):
        track_points(frames, [[3.0, 3.0]], names=["a", "b"])


def test_the_points_csv_is_read_in_px_or_mm_and_its_faults_named(tmp_path):
    good = tmp_path / "p.csv"
    good.write_text("\ufeffname,x_mm,y_mm\nhyoid,2.0,1.0\n,4.0,3.0\n")
    xy, names = read_points_csv(good, (0.5, 0.25))     # rows 0.5 mm, columns 0.25 mm
    np.testing.assert_allclose(xy, [[8.0, 2.0], [16.0, 6.0]])
    assert names == ("hyoid", "point_1")
    for text, words in (("x,y\n1,2\n", "expected columns"), ("x_px,y_px\n1\n", "line 2 has fewer fields"),
                        ("x_px,y_px\n1,abc\n", "non-numeric"), ("x_px,y_px\n1,inf\n", "finite"),
                        ("x_px,y_px\n", "no point rows"), ("name,x_px,y_px\na,1,2\na,3,4\n", "more than once")):
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        with pytest.raises(InputError, match=words):
            read_points_csv(bad, 1.0)
    mm = tmp_path / "mm.csv"
    mm.write_text("x_mm,y_mm\n1,2\n")
    with pytest.raises(InputError, match="no pixel size"):
        read_points_csv(mm, None)


def test_the_trajectory_csv_puts_every_point_of_every_frame_in_px_and_mm():
    pos = np.array([[[1.0, 2.0]], [[3.0, 5.0]]])
    text = point_track_csv(pos, ("a",), np.array([[0.0], [0.25]]), (0.5, 0.2), 0.1).splitlines()
    assert text[0] == "frame,time_s,point,name,x_px,y_px,x_mm,y_mm,disagreement_px"
    assert text[2].split(",") == ["1", "0.100000", "0", "a", "3.000", "5.000", "0.6000", "2.5000", "0.250"]


def test_track_points_from_the_command_line(tmp_path, scatterers):
    """``hifumotion track FRAMES --points P.csv`` on PNG frames (no pixel size): px trajectories,
    the figure and the records; the points end where the map puts them."""
    import imageio.v3 as iio

    v = np.array([0.5, 0.3])
    frames = moved_cine(scatterers, lambda t, p: p + t * v, 12)
    folder = tmp_path / "frames"
    folder.mkdir()
    for t, f in enumerate(frames):
        iio.imwrite(folder / f"frame_{t:04d}.png", np.round(f * 255).astype(np.uint8))
    pts = tmp_path / "points.csv"
    pts.write_text("name,x_px,y_px\n" + "".join(f"p{i},{x},{y}\n" for i, (x, y) in enumerate(POINTS_PX)))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hifumotion", "track", str(folder), "--points", str(pts),
                           "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for name in ("points.csv", "points.png", "tracking.json", "run_info.json"):
        assert (out / name).is_file(), name
    rows = [r.split(",") for r in (out / "points.csv").read_text().splitlines()[1:]]
    assert len(rows) == 12 * len(POINTS_PX)
    last = np.array([[float(r[4]), float(r[5])] for r in rows if r[0] == "11"])
    assert np.linalg.norm(last - (POINTS_PX + 11 * v), axis=1).max() < 0.5
    summary = json.loads((out / "tracking.json").read_text())["points"]
    assert summary["names"] == ["p0", "p1", "p2", "p3"] and "largest_shift_mm" not in summary
    # a point off the image is refused before anything is written, naming the file
    pts.write_text("x_px,y_px\n500,3\n")
    bad = subprocess.run([sys.executable, "-m", "hifumotion", "track", str(folder), "--points", str(pts),
                          "-o", str(tmp_path / "bad")], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "points.csv" in bad.stderr and "outside" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "bad").exists()


def test_a_contours_vertices_are_points_to_follow(tmp_path):
    """A contour CSV as the project writes it (frame, point, x_px, y_px, x_mm, y_mm) gives its
    vertices as points; one holding several frames is refused, naming the file."""
    from hifumotion.contour import Contour
    from hifumotion.io import write_contours_csv

    square = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0]])
    one = tmp_path / "one.csv"
    write_contours_csv(one, {0: Contour(square, (0.2, 0.2))})
    xy, names = read_points_csv(one, 0.2)
    np.testing.assert_allclose(xy, square)
    assert len(set(names)) == 4
    two = tmp_path / "two.csv"
    write_contours_csv(two, {0: Contour(square, (0.2, 0.2)), 5: Contour(square + 1, (0.2, 0.2))})
    with pytest.raises(InputError, match="frames 0, 5"):
        read_points_csv(two, 0.2)
