"""A user's mistakes, as a new user makes them: every one ends with one line naming the
file or field, exit status 2, no traceback, and nothing that was there before changed.

The cases run in-process through :func:`hifumotion.cli.main` (the console script), in a
scratch folder that holds valid inputs (a phantom, masks, a scene) beside hostile ones
(a FIFO, a device, empty, truncated, NaN-filled and grey-valued files). Each case is a
class of mistake, not one listed input: a bad value of an option of any command, an
unreadable file of any format, an output folder that would destroy something.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hifumotion.cli import main

CLI = [sys.executable, "-m", "hifumotion"]


# ---------------------------------------------------------------- the scratch folder
def _write_png(path: Path, array: np.ndarray) -> None:
    import imageio.v3 as iio

    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, array)


def _nifti(path: Path, array: np.ndarray, spacing=(0.2, 0.2)) -> None:
    import SimpleITK as sitk

    image = sitk.GetImageFromArray(array)
    image.SetSpacing(tuple(spacing)[::-1] + (() if array.ndim == 2 else (1.0,)))
    sitk.WriteImage(image, str(path))


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    """Valid and hostile inputs; the tests run with this as the working folder."""
    return build_scratch(tmp_path_factory.mktemp("hostile"))


def build_scratch(root: Path) -> Path:
    old = os.getcwd()
    os.chdir(root)
    try:
        assert _main(["phantom", "--seed", "1", "--size", "96", "-o", "ph"])[0] == 0
    finally:
        os.chdir(old)
    rng = np.random.default_rng(0)
    image = (rng.random((64, 64)) * 255).astype(np.uint8)
    _write_png(root / "image.png", image)
    yy, xx = np.mgrid[:64, :64]
    disc = ((yy - 32) ** 2 + (xx - 30) ** 2 < 15 ** 2)
    for k in range(3):                                     # a prediction's masks, frame by frame
        _write_png(root / "frame_masks" / f"frame_{k:04d}.png", (disc * 255).astype(np.uint8))
    for k in range(4):                                     # a sweep of binary masks
        _write_png(root / "masks" / f"slice_{k:03d}.png", (disc * 255).astype(np.uint8))
        _write_png(root / "grey_masks" / f"slice_{k:03d}.png", (disc * 128 + 40).astype(np.uint8))
    _write_png(root / "grey_mask.png", (disc * 128 + 40).astype(np.uint8))
    _write_png(root / "mask40.png", (disc[12:52, 12:52] * 255).astype(np.uint8))    # fits good.nii.gz's 40 × 40
    _write_png(root / "small_mask.png", np.zeros((10, 10), np.uint8))
    _write_png(root / "whole40.png", np.full((40, 40), 255, np.uint8))               # every pixel of good.nii.gz
    (root / "empty.png").write_bytes(b"")
    (root / "garbage.png").write_bytes(rng.bytes(300))
    (root / "afile.txt").write_text("not a folder\n")
    (root / "notes").mkdir()
    (root / "notes" / "keep.txt").write_text("a user's own file\n")
    (root / "empty_folder").mkdir()
    nan = rng.random((3, 32, 32)).astype(np.float32)
    nan[1, 5:9, 5:9] = np.nan
    _nifti(root / "nan.mha", nan)       # MetaImage keeps NaN (ITK's NIfTI writer does not)
    inf = rng.random((32, 32)).astype(np.float32)
    inf[0, 0] = np.inf
    _nifti(root / "inf.mha", inf)
    _nifti(root / "good.nii.gz", (rng.random((4, 40, 40)) * 255).astype(np.uint8))
    data = gzip.decompress((root / "good.nii.gz").read_bytes())
    (root / "truncated.nii.gz").write_bytes(gzip.compress(data[: len(data) // 2]))
    raw = bytearray(gzip.decompress((root / "good.nii.gz").read_bytes()))
    pixdim = np.frombuffer(bytes(raw[76:108]), "<f4").copy()
    pixdim[1] = -0.2                                       # a negative pixel size
    raw[76:108] = pixdim.astype("<f4").tobytes()
    (root / "negative_pixdim.nii").write_bytes(bytes(raw))
    os.mkfifo(root / "fifo.png")
    init = json.loads((root / "ph" / "init.json").read_text())
    key = next(iter(init))
    import imageio.v3 as iio

    phantom_shape = iio.imread(root / "ph" / "images" / "phantom.png").shape[:2]
    _write_png(root / "whole_phantom.png", np.full(phantom_shape, 255, np.uint8))
    _write_png(root / "empty_phantom.png", np.zeros(phantom_shape, np.uint8))
    (root / "whole_init.json").write_text(json.dumps({"ellipse": {"cx": 48, "cy": 48, "a": 200, "b": 200, "angle_deg": 0}}))
    (root / "huge_init.json").write_text(json.dumps({"ellipse": {"cx": 40, "cy": 40, "a": 1e9, "b": 1e9, "angle_deg": 0}}))
    (root / "negative_init.json").write_text(json.dumps({"ellipse": {"cx": 40, "cy": 40, "a": -3, "b": 5, "angle_deg": 0}}))
    (root / "outside_init.json").write_text(json.dumps({"ellipse": {"cx": 4000, "cy": -900, "a": 5, "b": 5, "angle_deg": 0}}))
    (root / "bad.json").write_text("{ not json")
    (root / "ph_init_key.txt").write_text(key)
    (root / "scene_fine.toml").write_text("[particles]\nspacing_mm = 0.01\n")
    (root / "scene_tip.toml").write_text("[bar]\ntip_mm = [500.0, 19.0, 20.0]\n")
    (root / "scene_force.toml").write_text("[bar]\nforce_n = -1.0\n")
    (root / "scene_key.toml").write_text("[bar]\nforse_n = 1.0\n")
    (root / "scene_broken.toml").write_text("[bar\nforce_n = 1.0\n")
    (root / "scene_schedule.toml").write_text("[bar]\nschedule_times_s = [0.0, 1.0]\nschedule_force_n = [0.0, -2.0]\n")
    (root / "resume.jsonl").write_text("this is not a search log\n")
    (root / "run_tip.toml").write_text(_run_config(tip="[500.0, 19.0, 18.7]"))
    (root / "run_key.toml").write_text(_run_config(extra="\n[estimation]\nparticels = 300\n"))
    (root / "run_particles.toml").write_text(_run_config(extra="\n[estimation]\nparticles = 1000000000\n"))
    (root / "run_horizons.toml").write_text(_run_config(extra="\n[estimation]\nhorizons_frames = [-4, 0]\n"))
    (root / "run_force.toml").write_text(_run_config(extra="\n[estimation]\nforce_n = 1e300\n"))
    (root / "run_threshold.toml").write_text(_run_config(extra="\n[estimation]\nthreshold_mm_per_point = 1e300\n"))
    # nested thousands of levels (a RecursionError in any parser), a few hundred (past the parser)
    deep = "[" * 5000 + "]" * 5000
    (root / "deep_scene.toml").write_text(f"a = {deep}\n")
    (root / "deep_run.yaml").write_text(f"a: {deep}\n")
    (root / "deep_init.json").write_text(deep)
    # YAML aliases: nine lists of nine nested nine deep (9⁹ values once expanded), and a node inside itself
    laughs = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [" + ",".join([f"*{chr(97 + i)}"] * 9) + "]\n" for i in range(8))
    (root / "laughs_run.yaml").write_text(laughs)
    (root / "laughs_scene.yaml").write_text(laughs)
    (root / "self_alias.yaml").write_text("a: &a [1, *a]\n")
    # contour CSVs: a row short of a field, a coordinate that is not a finite number
    (root / "short_row.csv").write_text("frame,x_px,y_px\n0,10,10\n0,20\n0,20,20\n")
    (root / "nan_point.csv").write_text("frame,x_px,y_px\n0,10,10\n0,20,nan\n0,20,20\n")
    # points to follow: off the image, not numbers, named twice, a row short, no rows, mm without a size
    (root / "points_ok.csv").write_text("name,x_px,y_px\na,10,12\nb,20.5,30\n")
    (root / "points_outside.csv").write_text("x_px,y_px\n10,12\n400,3\n")
    (root / "points_negative.csv").write_text("x_px,y_px\n-1,12\n")
    (root / "points_nan.csv").write_text("x_px,y_px\nnan,12\n")
    (root / "points_word.csv").write_text("x_px,y_px\nten,12\n")
    (root / "points_twice.csv").write_text("name,x_px,y_px\nhyoid,1,2\nhyoid,3,4\n")
    (root / "points_short.csv").write_text("name,x_px,y_px\na,1,2\nb,3\n")
    (root / "points_header.csv").write_text("name,x_px,y_px\n")
    (root / "points_columns.csv").write_text("name,col,row\na,1,2\n")
    (root / "points_mm.csv").write_text("x_mm,y_mm\n1,2\n")
    (root / "points_many.csv").write_text("x_px,y_px\n" + "1,1\n" * 10_001)
    (root / "deep_resume.jsonl").write_text(deep + "\n")
    # a video of random bytes and an empty one; a PNG whose header claims 10¹⁰ pixels
    (root / "garbage.mp4").write_bytes(rng.bytes(2000))
    (root / "empty.avi").write_bytes(b"")
    (root / "bomb.png").write_bytes(_png_bomb(100_000, 100_000))
    # a sweep whose masks differ in size; predicted and true masks of different sizes
    for k, pad in enumerate((0, 5)):
        _write_png(root / "mixed_masks" / f"slice_{k:03d}.png", np.pad(disc[12:52, 12:52] * 255, pad).astype(np.uint8))
        _write_png(root / "masks50" / f"frame_{k:04d}.png", np.pad(disc[12:52, 12:52] * 255, 5).astype(np.uint8))
    _write_png(root / "tiny.png", np.zeros((2, 2), np.uint8))
    _nifti(root / "tiny_cine.nii.gz", np.zeros((3, 4, 4), np.uint8))
    (root / "observed_deep").mkdir()
    (root / "observed_deep" / "setup.json").write_text('{"a": ' + deep + "}")
    (root / "scene_nested.toml").write_text("[bar]\nforce_n = " + "[" * 200 + "]" * 200 + "\n")
    (root / "scene_digits.toml").write_text("[bar]\nforce_n = " + "9" * 5000 + "\n")
    (root / "scene_interval.toml").write_text("[run]\noutput_interval_s = 1e-12\n")
    (root / "scene_duration.toml").write_text("[run]\nduration_s = 1e9\n")
    (root / "scene_steps.toml").write_text("[run]\nduration_s = 5000.0\noutput_interval_s = 1.0\nmax_step_s = 1e-9\n")
    (root / "twin_seed.toml").write_text("seed = -5\n")
    (root / "scene_water.toml").write_text("[tank]\nwater_depth_mm = 1e9\n")
    (root / "scene_beta2.toml").write_text("[tissue]\nbeta2 = -3.0\n")
    (root / "scene_negative_size.toml").write_text("[tissue]\nsize_mm = [30.0, -18.0, 24.0]\n")
    (root / "twin_water.toml").write_text("[tank]\nwater_depth_mm = 1e9\n")
    (root / "twin_blob0.toml").write_text("[blob]\nsize_mm = [0.0, 18.0, 24.0]\n")
    (root / "twin_blob_tiny.toml").write_text("[blob]\nsize_mm = [0.01, 0.01, 0.01]\n")
    (root / "twin_blob_nan.toml").write_text("[blob]\nsize_mm = [nan, 18.0, 24.0]\n")
    (root / "twin_frames.toml").write_text("[imaging]\nframes = 100000000\n")
    os.symlink("loop", root / "loop")                      # a symbolic link to itself
    # headers whose data file is a device, a FIFO or some other file of the system
    meta = "ObjectType = Image\nNDims = 2\nDimSize = 8 8\nElementType = MET_UCHAR\nElementSpacing = 0.2 0.2\n"
    (root / "urandom.mhd").write_text(meta + "ElementDataFile = /dev/urandom\n")
    (root / "system.mhd").write_text(meta + f"ElementDataFile = {Path(__file__).resolve()}\n")
    (root / "fifo_data.mhd").write_text(meta + "ElementDataFile = fifo.png\n")
    (root / "urandom.nhdr").write_text("NRRD0004\ntype: uint8\ndimension: 2\nsizes: 8 8\nencoding: raw\n"
                                       "data file: /dev/urandom\n")
    # DICOM attributes malformed as they are in the wild
    _dicom(root / "spacing_abc.dcm", PixelSpacing=[0.25, 0.25], FrameTime=50.25, patch={"0.25\\0.25": "abc\\0.25 "})
    _dicom(root / "spacing_one.dcm", PixelSpacing=[0.25, 0.25], FrameTime=50.25, patch={"0.25\\0.25": "0.25     "})
    _dicom(root / "frametime_fast.dcm", PixelSpacing=[0.25, 0.25], FrameTime=50.25, patch={"50.25 ": "fast  "})
    for k in range(3):
        _dicom(root / "orientation3" / f"s{k}.dcm", frames=1, PixelSpacing=[0.25, 0.25], ImagePositionPatient=[0, 0, k],
               ImageOrientationPatient=[1, 0, 0, 0, 1, 0], patch={"1.0\\0.0\\0.0\\0.0\\1.0\\0.0": "1.0\\0.0\\0.0            "})
        _dicom(root / "instance_x" / f"s{k}.dcm", frames=1, PixelSpacing=[0.25, 0.25], InstanceNumber=k + 10,
               patch={b"\x13\x00IS\x02\x00" + str(k + 10).encode(): b"\x13\x00IS\x02\x00x "})
    import pydicom

    for declared, name in ((0, "frames_zero.dcm"), (1, "frames_one_of_three.dcm"), (7, "frames_seven_of_three.dcm")):
        _dicom(root / name, PixelSpacing=[0.25, 0.25], FrameTime=50.0)       # three frames of pixel data
        ds = pydicom.dcmread(root / name)
        ds.NumberOfFrames = declared
        ds.save_as(root / name)
    (root / "observed_setup_folder" / "setup.json").mkdir(parents=True)       # setup.json a folder
    (root / "observed_setup_fifo").mkdir()
    os.mkfifo(root / "observed_setup_fifo" / "setup.json")                   # … or a FIFO
    bad_setup = root / "observed_bad"
    bad_setup.mkdir()
    (bad_setup / "setup.json").write_text("{ broken")
    missing_field = root / "observed_field"
    missing_field.mkdir()
    (missing_field / "setup.json").write_text(json.dumps({"frame_interval_s": 0.05, "frames": 10}))
    return root


def _png_bomb(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width × height`` grey pixels over a few bytes of data."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\x00" * 1000))
            + chunk(b"IEND", b""))


def _dicom(path: Path, frames: int = 3, patch: dict | None = None, **attrs) -> None:
    """A small ultrasound DICOM; ``patch`` {valid text: malformed text of the same length} edits its
    bytes (pydicom refuses to write malformed values, scanners do not)."""
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import ExplicitVRLittleEndian, generate_uid

    meta = FileMetaDataset()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.3.1"
    meta.MediaStorageSOPInstanceUID = generate_uid()
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID, ds.SOPInstanceUID, ds.Modality = meta.MediaStorageSOPClassUID, meta.MediaStorageSOPInstanceUID, "US"
    ds.Rows = ds.Columns = 40
    ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 8, 8, 7, 0
    if frames > 1:
        ds.NumberOfFrames = frames
    ds.PixelData = (np.random.default_rng(frames).random((frames, 40, 40)) * 255).astype(np.uint8).tobytes()
    for key, value in attrs.items():
        setattr(ds, key, value)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.save_as(path, enforce_file_format=True)
    raw = path.read_bytes()
    for valid, malformed in (patch or {}).items():
        valid, malformed = (x.encode() if isinstance(x, str) else x for x in (valid, malformed))
        assert len(valid) == len(malformed) and raw.count(valid) == 1
        raw = raw.replace(valid, malformed)
    path.write_bytes(raw)


def _run_config(tip: str = "[22.6, 19.0, 18.7]", extra: str = "") -> str:
    return f'''
[sweep]
path = "masks"
spacing_mm = 0.2
gap_mm = 1.0
[frames]
path = "good.nii.gz"
frame_interval_s = 0.05
[initial_contour]
path = "contour.csv"
[geometry]
row0_col0_mm = [1.0, -8.0]
frames_plane_z_mm = 18.7
[tank]
size_mm = [44.0, 40.0, 36.0]
water_depth_mm = 6.0
[bar]
tip_at_rest_mm = {tip}
''' + extra


def _main(argv: list[str]) -> tuple[int, str]:
    """Run the console script in-process; (exit status, what it wrote to standard error)."""
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main(argv)
            status = 0
        except SystemExit as exc:
            status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return status, err.getvalue()


def _snapshot(root: Path) -> dict[str, str]:
    out = {}
    for p in root.rglob("*"):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(root))] = hashlib.sha1(p.read_bytes()).hexdigest()
    return out


# ---------------------------------------------------------------- the cases
# (arguments, a word the one-line error must contain); paths are relative to the scratch folder
CASES = [
    # hifumotion info: files that are not images, values that are not values
    (["info", "missing.png"], "missing.png"),
    (["info", "fifo.png"], "fifo.png"),
    (["info", "/dev/null"], "/dev/null"),
    (["info", "empty.png"], "empty.png"),
    (["info", "garbage.png"], "garbage.png"),
    (["info", "truncated.nii.gz"], "truncated.nii.gz"),
    (["info", "nan.mha"], "nan.mha"),
    (["info", "inf.mha"], "inf.mha"),
    (["info", "negative_pixdim.nii"], "negative_pixdim.nii"),
    (["info", "empty_folder"], "empty_folder"),
    (["info", "image.png", "--spacing", "-1"], "--spacing"),
    (["info", "image.png", "--spacing", "abc"], "--spacing"),
    (["info", "image.png", "--spacing", "nan"], "--spacing"),
    (["info", "image.png", "--kind", "nope"], "kind"),
    (["info", "image.png", "--frame-interval", "0"], "--frame-interval"),
    # videos that are none, a decompression bomb, images of the wrong size for what they go with
    (["info", "garbage.mp4"], "garbage.mp4"),
    (["info", "empty.avi"], "empty.avi"),
    (["track", "garbage.mp4", "--init", "mask40.png", "-o", "out"], "garbage.mp4"),
    (["segment", "empty.avi", "--init", "ph/init.json", "-o", "out"], "empty.avi"),
    (["info", "bomb.png"], "bomb.png"),
    (["segment", "bomb.png", "--init", "ph/init.json", "-o", "out"], "bomb.png"),
    (["segment", "ph/images/phantom.png", "--init", "bomb.png", "-o", "out"], "bomb.png"),
    (["reconstruct", "mixed_masks", "--slice-spacing", "1", "--spacing", "0.2", "-o", "out"], "slice_001.png"),
    (["score", "frame_masks", "masks50", "--spacing", "0.2"], "differ in size"),
    (["segment", "tiny.png", "--init", "ph/init.json", "--name", "phantom.png", "-o", "out"], "tiny.png"),
    (["segment", "tiny_cine.nii.gz", "--init", "ph/init.json", "--name", "phantom.png", "-o", "out"], "tiny_cine"),
    (["track", "tiny_cine.nii.gz", "--points", "points_ok.csv", "-o", "out"], "tiny_cine"),
    # one kind of file where another is due: points as a contour, a contour or a mask as points
    (["track", "good.nii.gz", "--init", "points_ok.csv", "-o", "out"], "points_ok.csv"),
    (["track", "good.nii.gz", "--points", "mask40.png", "-o", "out"], "mask40.png"),
    (["track", "good.nii.gz", "--points", "ph/init.json", "-o", "out"], "init.json"),
    (["track", "good.nii.gz", "--points", "short_row.csv", "-o", "out"], "short_row.csv"),
    # a DICOM whose NumberOfFrames is not what its pixel data holds
    (["info", "frames_zero.dcm"], "NumberOfFrames"),
    (["info", "frames_one_of_three.dcm"], "NumberOfFrames"),
    (["info", "frames_seven_of_three.dcm"], "frames_seven_of_three.dcm"),
    (["track", "frames_one_of_three.dcm", "--init", "mask40.png", "-o", "out"], "NumberOfFrames"),
    # hifumotion segment
    # hifumotion track: a cine and what it needs
    (["track", "good.nii.gz", "-o", "out"], "--init"),
    (["track", "image.png", "--init", "mask40.png", "-o", "out"], "frame"),
    (["track", "good.nii.gz", "--init", "missing.json", "-o", "out"], "missing.json"),
    (["track", "good.nii.gz", "--init", "grey_mask.png", "-o", "out"], "grey_mask.png"),
    (["track", "good.nii.gz", "--init", "small_mask.png", "-o", "out"], "small_mask.png"),
    (["track", "good.nii.gz", "--init", "mask40.png", "--estimator", "magic", "-o", "out"], "estimator"),
    (["track", "good.nii.gz", "--init", "mask40.png", "--bar", "small_mask.png", "-o", "out"], "small_mask.png"),
    (["track", "good.nii.gz", "--init", "mask40.png", "--setup", "observed_bad/setup.json", "-o", "out"], "setup.json"),
    (["track", "observed_field", "-o", "out"], "setup.json"),
    *[([command, f"observed_setup_{kind}", "-o", "out"], "setup.json")
      for command in ("track", "calibrate") for kind in ("folder", "fifo")],
    # hifumotion track --points: the points file's faults, each named with the file
    *[(["track", "good.nii.gz", "--points", f"points_{kind}.csv", "-o", "out"], f"points_{kind}.csv")
      for kind in ("outside", "negative", "nan", "word", "twice", "short", "header", "columns", "many")],
    (["track", "image.png", "--points", "points_ok.csv", "-o", "out"], "frame"),
    (["track", "good.nii.gz", "--points", "points_ok.csv", "--fields", "-o", "out"], "--fields"),
    (["track", "good.nii.gz", "--points", "points_ok.csv", "--bar", "mask40.png", "-o", "out"], "--bar"),
    (["track", "frame_masks", "--points", "points_mm.csv", "-o", "out"], "points_mm.csv"),
    (["calibrate", "observed_field", "--objective", "shape", "-o", "out"], "--objective"),
    (["calibrate", "observed_field", "--tracking", "magic", "-o", "out"], "--tracking"),
    (["calibrate", "observed_field", "--force", "1e-300", "-o", "out"], "--force"),
    (["segment", "ph/images/phantom.png", "--init", "missing.json", "-o", "out"], "missing.json"),
    # an initial contour around the whole image, or around nothing; a --name the file does not hold
    (["segment", "ph/images/phantom.png", "--init", "whole_phantom.png", "-o", "out"], "whole_phantom.png"),
    (["segment", "ph/images/phantom.png", "--init", "empty_phantom.png", "-o", "out"], "empty_phantom.png"),
    (["segment", "ph/images/phantom.png", "--init", "whole_init.json", "-o", "out"], "whole_init.json"),
    (["track", "good.nii.gz", "--init", "whole40.png", "-o", "out"], "whole40.png"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "--name", "other.png", "-o", "out"], "other.png"),
    (["segment", "ph/images/phantom.png", "--init", "short_row.csv", "-o", "out"], "line 3"),
    (["segment", "ph/images/phantom.png", "--init", "nan_point.csv", "-o", "out"], "finite"),
    (["segment", "ph/images/phantom.png", "--init", "bad.json", "-o", "out"], "bad.json"),
    (["segment", "ph/images/phantom.png", "--init", "huge_init.json", "-o", "out"], "huge_init.json"),
    (["segment", "ph/images/phantom.png", "--init", "negative_init.json", "-o", "out"], "negative_init.json"),
    (["segment", "ph/images/phantom.png", "--init", "outside_init.json", "-o", "out"], "outside_init.json"),
    (["segment", "ph/images/phantom.png", "--init", "grey_mask.png", "-o", "out"], "grey_mask.png"),
    (["segment", "ph/images/phantom.png", "--init", "small_mask.png", "-o", "out"], "small_mask.png"),
    (["segment", "ph/images/phantom.png", "--init", "fifo.png", "-o", "out"], "fifo.png"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-m", "nope", "-o", "out"], "--method"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "--init-kind", "nope", "-o", "out"], "--init-kind"),
    (["segment", "nan.mha", "--init", "ph/init.json", "-o", "out"], "nan.mha"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "ph", "--overwrite"], "ph"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", ".", "--overwrite"], "working folder"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "notes", "--overwrite"], "notes"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "notes"], "notes"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "afile.txt/sub"], "afile.txt"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "afile.txt"], "afile.txt"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "/proc/hifumotion-out"], "/proc"),
    # hifumotion compare
    (["compare", "ph", "--limit", "-1", "-o", "out"], "--limit"),
    (["compare", "ph", "--limit", "0", "-o", "out"], "--limit"),
    (["compare", "missing_dir", "-o", "out"], "missing_dir"),
    (["compare", "empty_folder", "-o", "out"], "empty_folder"),
    (["compare", "ph", "--methods", "nope", "-o", "out"], "--methods"),
    (["compare", "ph", "--init-kind", "nope", "-o", "out"], "--init-kind"),
    # hifumotion phantom
    (["phantom", "--seed", "-1", "-o", "out"], "--seed"),
    (["phantom", "--size", "60000", "-o", "out"], "--size"),
    (["phantom", "--size", "10", "-o", "out"], "--size"),
    (["phantom", "--spacing", "0", "-o", "out"], "--spacing"),
    (["phantom", "--spacing", "inf", "-o", "out"], "--spacing"),
    (["phantom", "--shape", "nope", "-o", "out"], "--shape"),
    (["phantom", "--preset", "nope", "-o", "out"], "--preset"),
    (["phantom", "-o", ".", "--overwrite"], "working folder"),
    (["phantom", "-o", "/proc/hifumotion-out"], "/proc"),
    (["phantom", "-o", "afile.txt/sub"], "afile.txt"),
    # hifumotion reconstruct
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "--voxel", "0", "-o", "out"], "--voxel"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "--voxel", "0.001", "-o", "out"], "--voxel"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "--voxel", "1e9", "-o", "out"], "--voxel"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "--particle-spacing", "0.001", "-o", "out"],
     "--particle-spacing"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "--particle-spacing", "-1", "-o", "out"],
     "--particle-spacing"),
    (["reconstruct", "masks", "--slice-spacing", "-1", "-o", "out"], "--slice-spacing"),
    (["reconstruct", "grey_masks", "--slice-spacing", "1", "-o", "out"], "grey_masks"),
    (["reconstruct", "image.png", "--slice-spacing", "1", "-o", "out"], "image.png"),
    # hifumotion simulate / validate
    (["simulate", "scene_fine.toml", "-o", "out"], "spacing_mm"),
    (["simulate", "scene_tip.toml", "-o", "out"], "tip_mm"),
    (["simulate", "scene_force.toml", "-o", "out"], "force_n"),
    (["simulate", "scene_schedule.toml", "-o", "out"], "schedule"),
    (["simulate", "scene_key.toml", "-o", "out"], "forse_n"),
    (["simulate", "scene_broken.toml", "-o", "out"], "scene_broken.toml"),
    (["simulate", "missing_scene.toml", "-o", "out"], "missing_scene.toml"),
    (["simulate", "fifo.png", "-o", "out"], "fifo.png"),
    (["simulate"], "--output"),
    (["validate", "nope"], "nope"),
    # hifumotion experiment
    (["experiment", "--config", "missing.toml", "-o", "out"], "missing.toml"),
    (["experiment", "--preset", "nope", "-o", "out"], "nope"),
    (["experiment", "--seed", "-1", "-o", "out"], "--seed"),
    # images no machine holds: refused before the physics runs, naming the imaging settings
    (["experiment", "--preset", "small", "--set", "imaging.pixel_mm=0.0001", "-o", "out"], "imaging"),
    (["experiment", "--preset", "small", "--set", "imaging.width_mm=1000000", "-o", "out"], "imaging"),
    (["experiment", "--preset", "small", "--set", "imaging.sweep_gap_mm=1e-300", "-o", "out"], "sweep_gap_mm"),
    # values no probe, clinician or bar has (each was simulated, or ran for ever, or a pydantic traceback)
    *[(["experiment", "--preset", "small", "--set", f"{key}={value}", "-o", "out"], key.split(".")[-1])
      for key, value in (("imaging.frame_rate_hz", "1e-300"), ("imaging.frame_rate_hz", "1e300"),
                         ("imaging.frame_rate_hz", "0.001"), ("imaging.dynamic_range_db", "1e300"),
                         ("imaging.center_frequency_mhz", "1e300"), ("clinician.error_mm", "1e300"),
                         ("bar.force_n", "1e300"))],
    (["experiment", "--preset", "small"], "--output"),
    # hifumotion calibrate / predict / score
    (["calibrate", "ph", "-o", "out"], "setup.json"),
    (["calibrate", "missing_dir", "-o", "out"], "missing_dir"),
    (["calibrate", "observed_bad", "-o", "out"], "setup.json"),
    (["calibrate", "observed_field", "-o", "out"], "setup.json"),
    (["calibrate", "ph", "-o", "out", "--particles", "0"], "--particles"),
    (["calibrate", "ph", "-o", "out", "--particles", "1000000000"], "--particles"),
    (["calibrate", "ph", "-o", "out", "--search-particles", "0"], "--search-particles"),
    (["calibrate", "ph", "-o", "out", "--force", "-1"], "--force"),
    (["calibrate", "ph", "-o", "out", "--workers", "0"], "--workers"),
    (["calibrate", "ph", "-o", "out", "--max-evaluations", "0"], "--max-evaluations"),
    (["calibrate", "ph", "-o", "out", "--boundary-offset", "100"], "--boundary-offset"),
    (["calibrate", "ph", "-o", "out", "--resume", "resume.jsonl"], "resume.jsonl"),
    (["calibrate", "ph", "-o", "out", "--resume", "missing.jsonl"], "missing.jsonl"),
    (["calibrate", "ph", "-o", "out", "--method", "nope"], "--method"),
    (["predict", "ph", "-o", "out"], "ph"),
    (["predict", "missing_dir", "-o", "out"], "missing_dir"),
    (["score", "missing_dir", "ph"], "missing_dir"),
    (["score", "ph", "ph", "--spacing", "-1"], "--spacing"),
    (["score", "frame_masks", "frame_masks", "--spacing", "1e-300"], "--spacing"),
    (["score", "frame_masks", "frame_masks", "--spacing", "0.2", "--images", "empty_folder", "-o", "out"],
     "empty_folder"),
    (["score", "frame_masks", "frame_masks", "--spacing", "1e-320"], "--spacing"),
    (["segment", "ph/images/phantom.png", "--init", "short_row.csv", "--spacing", "1e-320", "-o", "out"], "--spacing"),
    # hifumotion demo / run
    (["demo", "--particles", "0", "-o", "out"], "--particles"),
    (["demo", "--preset", "nope", "-o", "out"], "--preset"),
    (["demo", "--images", "-1", "-o", "out"], "--images"),
    (["demo", "--workers", "0", "-o", "out"], "--workers"),
    (["demo", "--max-evaluations", "0", "-o", "out"], "--max-evaluations"),
    (["demo", "--dataset", "missing_dir", "-o", "out"], "missing_dir"),
    (["demo", "-o", ".", "--overwrite"], "working folder"),
    (["run", "missing.toml"], "missing.toml"),
    (["run"], "CONFIG"),
    (["run", "run_tip.toml", "-o", "out"], "tip"),
    (["run", "run_key.toml", "-o", "out"], "particels"),
    (["run", "run_particles.toml", "-o", "out"], "particles"),
    (["run", "run_horizons.toml", "-o", "out"], "horizons_frames"),
    (["run", "run_force.toml", "-o", "out"], "force_n"),
    (["run", "run_threshold.toml", "-o", "out"], "threshold_mm_per_point"),
    (["run", "fifo.png", "-o", "out"], "fifo.png"),
    # nesting thousands of levels deep, or a few hundred, in every structured file a command reads
    (["simulate", "deep_scene.toml", "-o", "out"], "deep_scene.toml"),
    (["simulate", "scene_nested.toml", "-o", "out"], "scene_nested.toml"),
    (["experiment", "--config", "deep_scene.toml", "-o", "out"], "deep_scene.toml"),
    (["run", "deep_run.yaml", "-o", "out"], "deep_run.yaml"),
    (["run", "laughs_run.yaml", "-o", "out"], "laughs_run.yaml"),
    (["simulate", "laughs_scene.yaml", "-o", "out"], "laughs_scene.yaml"),
    (["run", "self_alias.yaml", "-o", "out"], "self_alias.yaml"),
    (["track", "observed_deep", "-o", "out"], "setup.json"),
    (["calibrate", "observed_deep", "-o", "out"], "setup.json"),
    (["segment", "ph/images/phantom.png", "--init", "deep_init.json", "-o", "out"], "deep_init.json"),
    (["calibrate", "ph", "-o", "out", "--resume", "deep_resume.jsonl"], "deep_resume.jsonl"),
    # numbers no setting holds, and work no run could finish
    (["simulate", "scene_digits.toml", "-o", "out"], "scene_digits.toml"),
    (["simulate", "scene_interval.toml", "-o", "out"], "output_interval_s"),
    (["simulate", "scene_duration.toml", "-o", "out"], "duration_s"),
    (["simulate", "scene_steps.toml", "-o", "out"], "max_step_s"),
    (["simulate", "scene_interval.toml", "--integrator", "implicit", "-o", "out"], "output_interval_s"),
    # an integrator that cannot run a scene alone, or none of that name: refused naming the option
    (["simulate", "--integrator", "reduced", "-o", "out"], "--integrator"),
    (["simulate", "--integrator", "implicitt", "-o", "out"], "--integrator"),
    (["experiment", "--config", "twin_seed.toml", "-o", "out"], "seed"),
    # physics no tank or tissue has: refused by the scene's validation, naming the setting
    (["simulate", "scene_water.toml", "-o", "out"], "water_depth_mm"),
    (["simulate", "scene_beta2.toml", "-o", "out"], "beta2"),
    (["simulate", "scene_negative_size.toml", "-o", "out"], "tissue.size_mm"),
    (["experiment", "--preset", "small", "--config", "twin_water.toml", "-o", "out"], "water_depth_mm"),
    *[(["experiment", "--preset", "small", "--config", f"twin_blob{kind}.toml", "-o", "out"], "blob.size_mm")
      for kind in ("0", "_tiny", "_nan")],
    (["experiment", "--config", "twin_frames.toml", "-o", "out"], "frames"),
    # an output path that is a symbolic link to itself
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "loop"], "loop"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "loop/sub"], "loop"),
    (["phantom", "-o", "loop"], "loop"),
    (["calibrate", "ph", "-o", "out", "--scheduler-address", "garbage"], "--scheduler-address"),
    (["calibrate", "ph", "-o", "out", "--scheduler-address", "tcp://host:99999"], "--scheduler-address"),
    # a header's data file: a device, a FIFO, a file of the system
    (["info", "urandom.mhd"], "urandom"),
    (["info", "system.mhd"], "system.mhd"),
    (["info", "fifo_data.mhd"], "fifo"),
    (["info", "urandom.nhdr"], "urandom"),
    (["segment", "urandom.mhd", "--init", "ph/init.json", "-o", "out"], "urandom"),
    (["track", "urandom.mhd", "--init", "mask40.png", "-o", "out"], "urandom"),
    # malformed DICOM attributes: no pixel size is guessed from them, no sweep order
    (["track", "spacing_abc.dcm", "--init", "mask40.png", "-o", "out"], "--spacing"),
    (["track", "spacing_one.dcm", "--init", "mask40.png", "-o", "out"], "--spacing"),
    (["info", "orientation3"], "ImageOrientationPatient"),
    (["reconstruct", "orientation3", "-o", "out"], "ImageOrientationPatient"),
    (["info", "instance_x"], "InstanceNumber"),
    # the online loop: a recorded cine paced, or frames watched for — not both; a wait of no time
    (["online", "ph", "ph", "-o", "out", "--watch", "--pace"], "--pace"),
    (["online", "ph", "ph", "-o", "out", "--watch", "--timeout", "0"], "--timeout"),
    (["online", "ph", "ph", "-o", "out", "--watch", "--timeout", "nan"], "--timeout"),
]


# every argument that names a file or folder, given each kind of path a user gets wrong: one that
# does not exist, a FIFO (reading it would block), a device, an empty file, bytes of nothing, a
# folder where a file is due, a symbolic link to itself
PATH_SLOTS = [
    ["info", "{}"],
    ["segment", "{}", "--init", "ph/init.json", "-o", "out"],
    ["segment", "ph/images/phantom.png", "--init", "{}", "-o", "out"],
    ["compare", "{}", "-o", "out"],
    ["reconstruct", "{}", "--slice-spacing", "1", "--spacing", "0.2", "-o", "out"],
    ["track", "{}", "--init", "mask40.png", "-o", "out"],
    ["track", "good.nii.gz", "--init", "{}", "-o", "out"],
    ["track", "good.nii.gz", "--init", "mask40.png", "--setup", "{}", "-o", "out"],
    ["track", "good.nii.gz", "--init", "mask40.png", "--exclude", "{}", "-o", "out"],
    ["track", "good.nii.gz", "--init", "mask40.png", "--bar", "{}", "-o", "out"],
    ["track", "good.nii.gz", "--points", "{}", "-o", "out"],
    ["track", "good.nii.gz", "--init", "mask40.png", "--points", "{}", "-o", "out"],
    ["simulate", "{}", "-o", "out"],
    ["experiment", "--config", "{}", "-o", "out"],
    ["calibrate", "{}", "-o", "out"],
    ["calibrate", "ph", "--resume", "{}", "-o", "out"],
    ["predict", "{}", "-o", "out"],
    ["online", "{}", "ph", "-o", "out"],
    ["score", "{}", "frame_masks", "--spacing", "0.2"],
    ["score", "frame_masks", "{}", "--spacing", "0.2"],
    ["run", "{}", "-o", "out"],
    ["demo", "--dataset", "{}", "-o", "out"],
]
HOSTILE_PATHS = ["no_such_path", "fifo.png", "/dev/null", "empty.png", "garbage.png", "empty_folder", "loop"]
CASES += [([a.format(path) for a in slot], path) for slot in PATH_SLOTS for path in HOSTILE_PATHS
          if not (slot[0] == "info" and path in ("fifo.png", "/dev/null", "empty.png", "garbage.png", "empty_folder"))]
# every option that takes a positive length or time, given what is no such number
POSITIVE_OPTIONS = [
    (["phantom", "-o", "out", "--spacing", "{}"], "--spacing"),
    (["reconstruct", "masks", "--spacing", "0.2", "-o", "out", "--slice-spacing", "{}"], "--slice-spacing"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "-o", "out", "--voxel", "{}"], "--voxel"),
    (["reconstruct", "masks", "--slice-spacing", "1", "--spacing", "0.2", "-o", "out", "--particle-spacing", "{}"],
     "--particle-spacing"),
    (["calibrate", "ph", "-o", "out", "--force", "{}"], "--force"),
    (["info", "image.png", "--frame-interval", "{}"], "--frame-interval"),
    (["track", "good.nii.gz", "--init", "mask40.png", "-o", "out", "--frame-interval", "{}"], "--frame-interval"),
    (["track", "good.nii.gz", "--init", "mask40.png", "-o", "out", "--spacing", "{}"], "--spacing"),
    (["track", "good.nii.gz", "--points", "points_ok.csv", "-o", "out", "--spacing", "{}"], "--spacing"),
    (["track", "good.nii.gz", "--points", "points_ok.csv", "-o", "out", "--frame-interval", "{}"], "--frame-interval"),
    (["segment", "ph/images/phantom.png", "--init", "ph/init.json", "-o", "out", "--spacing", "{}"], "--spacing"),
    (["segment", "good.nii.gz", "--init", "mask40.png", "-o", "out", "--frame-interval", "{}"], "--frame-interval"),
    (["reconstruct", "masks", "--slice-spacing", "1", "-o", "out", "--spacing", "{}"], "--spacing"),
    (["score", "frame_masks", "frame_masks", "--spacing", "{}"], "--spacing"),
]
CASES += [([a.format(value) for a in argv], word) for argv, word in POSITIVE_OPTIONS
          for value in ("nan", "inf", "-inf", "-1", "0", "abc", "1e400")]


@pytest.mark.parametrize("argv, word", CASES, ids=[" ".join(c[0])[:60] for c in CASES])
def test_a_mistake_is_one_line_naming_it_and_changes_nothing(scratch, argv, word, monkeypatch):
    monkeypatch.chdir(scratch)
    before = _snapshot(scratch)
    status, err = _main(argv)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2, err
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert "Traceback" not in err
    assert word.lower() in lines[0].lower(), lines[0]
    after = _snapshot(scratch)
    assert {k: v for k, v in after.items() if k in before} == before     # nothing there before changed
    assert not (scratch / "out").exists()                                # and no output was left
    assert not [p for p in scratch.iterdir() if p.name.endswith(".partial")]


def test_a_model_its_solver_cannot_factor_is_one_line_and_changes_nothing(scratch, monkeypatch):
    """PARDISO's failure deep inside a command (here made to happen where ``score`` works) is the
    model's settings' fault, not a bug: one line, status 2, no output."""
    import hifumotion.scoring as scoring
    from hifumotion.creep.linear import FactorError

    def singular(*args, **kwargs):
        raise FactorError("PARDISO phase 22 failed with error -4")

    monkeypatch.chdir(scratch)
    monkeypatch.setattr(scoring, "score_masks", singular)
    before = _snapshot(scratch)
    status, err = _main(["score", "frame_masks", "frame_masks", "--spacing", "0.2", "-o", "out"])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "linear system could not be solved" in lines[0] and "PARDISO phase 22" in lines[0]
    assert _snapshot(scratch) == before and not (scratch / "out").exists()


def test_a_runs_frames_are_checked_against_each_other_before_any_work():
    from hifumotion.errors import InputError
    from hifumotion.workflow.pipeline import check_protocol

    check_protocol([20, 30], [110, 120], [4, 6], 200)          # the paper's protocol passes
    with pytest.raises(InputError, match="validation_frames"):
        check_protocol([20, 30, 110], [110, 120], [4], 200)    # frame 110 both fitted and scored
    with pytest.raises(InputError, match="horizons_frames"):
        check_protocol([20, 30], [110, 120], [4, 100_000], 200)


def test_enough_hostile_cases():
    assert len(CASES) >= 450 and len({c[0][0] for c in CASES}) >= 15


def test_overwrite_replaces_only_what_hifumotion_wrote(scratch, monkeypatch):
    monkeypatch.chdir(scratch)
    assert _main(["phantom", "--seed", "2", "--size", "64", "-o", "again"])[0] == 0
    first = (scratch / "again" / "images" / "phantom.png").read_bytes()
    status, err = _main(["phantom", "--seed", "2", "--size", "64", "-o", "again"])
    assert status == 2 and "--overwrite" in err
    assert _main(["phantom", "--seed", "3", "--size", "64", "-o", "again", "--overwrite"])[0] == 0
    assert (scratch / "again" / "images" / "phantom.png").read_bytes() != first
    assert (scratch / "notes" / "keep.txt").read_text() == "a user's own file\n"


def test_a_malformed_dicom_attribute_is_reported_not_guessed(scratch, monkeypatch):
    """A file with a malformed pixel size or frame time still opens; the value is unknown, the
    attribute named; given on the command line, it is used."""
    from hifumotion.io.reader import read_sequence

    monkeypatch.chdir(scratch)
    seq = read_sequence(scratch / "spacing_abc.dcm")
    assert not seq.spacing_known and "PixelSpacing" in seq.metadata["spacing_from"]
    assert seq.frame_interval_s == pytest.approx(0.05025)
    seq = read_sequence(scratch / "frametime_fast.dcm")
    assert seq.frame_interval_s is None and "FrameTime" in seq.metadata["frame_interval_from"]
    assert seq.spacing_mm == (0.25, 0.25)
    seq = read_sequence(scratch / "spacing_one.dcm", spacing_mm=0.3)
    assert seq.spacing_mm == (0.3, 0.3)


def test_info_prints_its_table_on_standard_output(scratch):
    proc = subprocess.run(CLI + ["info", str(scratch / "image.png"), "--spacing", "0.2"], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0 and "spacing_mm" in proc.stdout and "spacing_mm" not in proc.stderr


@pytest.mark.parametrize("argv", [["info", "instance_x"], ["info", "spacing_abc.dcm", "--frame-interval", "nan"],
                                  ["info", "urandom.mhd"], ["simulate", "deep_scene.toml", "-o", "out"],
                                  ["calibrate", "ph", "-o", "out", "--scheduler-address", "garbage"]])
def test_a_libraries_warnings_do_not_add_to_the_one_line(scratch, argv):
    """In a real process (warnings and logging go to standard error there, not to pytest)."""
    proc = subprocess.run(CLI + argv, cwd=scratch, capture_output=True, text=True, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), proc.stderr


def test_a_fifo_is_refused_at_once(scratch):
    proc = subprocess.run(CLI + ["info", str(scratch / "fifo.png")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "fifo.png" in proc.stderr and "regular file" in proc.stderr


def test_a_fifo_among_an_observed_folders_frames_is_refused_not_waited_on(tmp_path):
    """Every frame of an observed folder is read through one reader, which takes regular files
    only: a FIFO named like a frame would block the read for ever."""
    import imageio.v3 as iio

    from hifumotion.errors import InputError
    from hifumotion.observed.folder import _stack

    frames = tmp_path / "frames"
    frames.mkdir()
    iio.imwrite(frames / "frame_0000.png", np.zeros((16, 16), np.uint8))
    os.mkfifo(frames / "frame_0001.png")
    with pytest.raises(InputError, match="frame_0001.png"):
        _stack(frames, "frame_", (16, 16))


def _twin_being_written(folder: Path, pattern: str = ".twin.*.partial", **popen) -> subprocess.Popen:
    """``experiment --preset small -o twin`` started in ``folder``, once its staging folder (``pattern``) exists."""
    proc = subprocess.Popen(CLI + ["-q", "experiment", "--preset", "small", "--seed", "5", "-o", "twin"],
                            cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)
    deadline = time.time() + 90
    while time.time() < deadline and not list(folder.glob(pattern)):
        time.sleep(0.2)
    assert list(folder.glob(pattern)), "the run never started writing"
    return proc


def test_sigterm_leaves_no_partial_folder(tmp_path):
    proc = _twin_being_written(tmp_path)
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0
    assert not list(tmp_path.glob(".twin*")) and not (tmp_path / "twin").exists(), err


def test_a_frame_range_is_checked_by_its_ends_before_any_list_is_made():
    from hifumotion.errors import InputError
    from hifumotion.estimation.protocol import parse_frames

    assert parse_frames("20:101:10", 200, "--frames") == list(range(20, 101, 10))
    assert parse_frames("30,20,20", 200, "--frames") == [20, 30]
    for text, word in (("1:2:3:4", "expected"), ("1:150000000", "1 … 199"), ("5:1", "no frame"),
                       ("0:4", "1 … 199"), ("1:10:0", "expected"), ("9" * 5000, "expected"), ("-4,0", "1 … 199")):
        with pytest.raises(InputError, match=word) as caught:
            parse_frames(text, 200, "--frames")
        assert len(str(caught.value)) < 200          # the message quotes the input, it does not list it


def test_valid_detached_headers_still_read(tmp_path):
    """The data-file check refuses devices and foreign files, not SimpleITK's own MHD and NRRD."""
    import SimpleITK as sitk

    from hifumotion.io.itk import read_itk_file

    rng = np.random.default_rng(3)
    for name, compressed, dtype in (("a.mhd", False, np.uint8), ("b.mhd", True, np.float32),
                                    ("c.nhdr", False, np.int16), ("d.nhdr", True, np.uint16)):
        array = (rng.random((3, 20, 30)) * 100).astype(dtype)
        image = sitk.GetImageFromArray(array)
        image.SetSpacing((0.2, 0.2, 1.0))
        sitk.WriteImage(image, str(tmp_path / name), useCompression=compressed)
        read = read_itk_file(tmp_path / name)["array"]
        assert read.shape == (3, 20, 30)


def test_yaml_aliases_are_walked_once_and_refused_when_they_expand_past_the_limit():
    from hifumotion.errors import InputError
    from hifumotion.io.structured import MAX_VALUES, parse_text, value_shape

    # shared nodes: a list used twice counts twice, but is walked once
    shared = [1, 2, 3]
    assert value_shape({"a": shared, "b": shared}) == (2, 1 + 2 * 4)
    laughs = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [" + ",".join([f"*{chr(97 + i)}"] * 9) + "]\n" for i in range(8))
    with pytest.raises(InputError, match="aliases are expanded"):
        parse_text(laughs, "yaml", "x.yaml")
    # the same aliases a few levels deep are a valid file (9⁵ values)
    few = laughs.split("f:")[0]
    assert value_shape(parse_text(few, "yaml", "x.yaml"))[1] < MAX_VALUES
    with pytest.raises(InputError, match="refers to itself"):
        parse_text("a: &a [1, *a]\n", "yaml", "x.yaml")


def test_nesting_depth_is_counted_without_recursion():
    from hifumotion.io.structured import MAX_DEPTH, nesting_depth

    assert nesting_depth(3.0) == 0 and nesting_depth({"a": [1, 2]}) == 2
    deep: list = []
    for _ in range(10_000):
        deep = [deep]
    assert nesting_depth(deep) == MAX_DEPTH + 1      # stops counting past the limit


def test_a_killed_runs_staging_folder_is_removed_by_the_next_run(tmp_path):
    """A SIGKILLed run leaves its hidden staging folder; the next run into the same output removes
    it (its process is gone) and leaves a live run's, an older version's and the user's alone."""
    from hifumotion.io.files import output_folder

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".out.{dead.pid}.abc123.partial"
    live = tmp_path / f".out.{os.getpid()}.def456.partial"
    older = tmp_path / ".out.xyz789.partial"
    user = tmp_path / ".out.notes"
    for folder in (stale, live, older, user):
        folder.mkdir()
        (folder / "file.txt").write_text("x")
    with output_folder(tmp_path / "out") as staging:
        (staging / "result.txt").write_text("done")
    assert not stale.exists()
    assert live.exists() and older.exists() and user.exists()
    assert (tmp_path / "out" / "result.txt").read_text() == "done"


def test_sigkill_then_the_same_command_leaves_no_staging_folder(tmp_path):
    proc = _twin_being_written(tmp_path)
    proc.kill()
    proc.communicate(timeout=60)
    assert list(tmp_path.glob(".twin.*.partial"))                  # what SIGKILL leaves
    # the next run into the same folder clears it before it starts
    again = subprocess.run(CLI + ["phantom", "--size", "64", "-o", "twin"], cwd=tmp_path, capture_output=True,
                           text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert not list(tmp_path.glob(".twin.*.partial"))


@pytest.mark.slow
def test_ctrl_c_during_a_calibration_is_one_line_and_leaves_nothing(small_twin, tmp_path):
    """Ctrl-C reaches the whole process group, Dask's workers too: they ignore it, the command
    closes them and says one line (it printed ~70 lines of worker tracebacks)."""
    folder, _ = small_twin
    proc = subprocess.Popen(CLI + ["calibrate", str(folder / "observed"), "-o", "cal", "--particles", "300",
                                   "--search-particles", "150", "--workers", "2"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            # as from a terminal: a test runner's worker may ignore SIGINT, and an
                            # ignored signal stays ignored in the child (Python then installs no
                            # KeyboardInterrupt)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 240
    # the search has begun once its log exists in the staging folder
    while time.time() < deadline and not list(tmp_path.glob(".cal.*.partial/search_log.jsonl")):
        time.sleep(0.2)
    assert list(tmp_path.glob(".cal.*.partial/search_log.jsonl")), "the search never started"
    os.killpg(proc.pid, signal.SIGINT)                 # as a terminal's Ctrl-C: the whole group
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip() and "%" not in ln]   # progress bars aside
    assert proc.returncode == 130, err
    assert "Traceback" not in err and len(lines) <= 2, err
    assert not list(tmp_path.glob(".cal*")) and not (tmp_path / "cal").exists()


def _tiny_observed(folder: Path, sweep_z_mm=None, water_depth_mm: float = 6.0) -> Path:
    """A minimal observed folder (4 sweep planes, 20 frames of 24 × 24 px) written by hifumotion's own writer."""
    from hifumotion.contour import Contour
    from hifumotion.observed.folder import write_observed
    from hifumotion.observed.setup import Setup

    setup = Setup(frame_interval_s=0.05, frames=20,
                  imaging={"image_shape": (24, 24), "pixel_mm": 0.5, "row0_col0_mm": (0.0, 0.0),
                           "frames_plane_z_mm": 5.0, "sweep_z_mm": sweep_z_mm or []},
                  tank={"size_mm": (12.0, 12.0, 12.0), "water_depth_mm": water_depth_mm},
                  bar={"tip_at_rest_mm": (6.0, 11.0, 5.0)})
    images = np.zeros((20, 24, 24), np.uint8)
    square = Contour(np.array([[8.0, 8.0], [16.0, 8.0], [16.0, 16.0], [8.0, 16.0]]), 0.5)
    return write_observed(folder, setup, images[:4], np.arange(4) * 1.0 + 3.5, images, square)


def test_setup_that_contradicts_its_own_folder_is_refused(tmp_path):
    from hifumotion.errors import InputError
    from hifumotion.observed import load_observed
    from hifumotion.observed.setup import read_setup

    ok = _tiny_observed(tmp_path / "ok", sweep_z_mm=[3.5, 4.5, 5.5, 6.5])
    assert len(load_observed(ok).sweep_z_mm) == 4
    wrong = _tiny_observed(tmp_path / "wrong", sweep_z_mm=[3.5, 4.5])      # two positions for four planes
    with pytest.raises(InputError, match="sweep_z_mm"):
        load_observed(wrong)
    deep = _tiny_observed(tmp_path / "deep")
    data = json.loads((deep / "setup.json").read_text())
    data["tank"]["water_depth_mm"] = 1e9                                   # deeper than the pool is high
    (deep / "setup.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="water_depth_mm"):
        read_setup(deep / "setup.json")


def test_a_truncated_volume_in_an_observed_folder_is_said_to_be_truncated(tmp_path):
    """``frames.nii.gz`` cut short beside ``frames/``: it read as zeros and was reported as
    images that differ from the PNGs; now the volume is named truncated, with how much it holds."""
    import gzip

    from hifumotion.errors import InputError
    from hifumotion.observed import load_observed

    folder = _tiny_observed(tmp_path / "obs")
    volume = folder / "frames.nii.gz"
    assert volume.is_file()
    raw = gzip.decompress(volume.read_bytes())
    volume.write_bytes(gzip.compress(raw)[: len(gzip.compress(raw)) // 2])
    with pytest.raises(InputError, match="truncated") as exc:
        load_observed(folder)
    assert "frames.nii.gz" in str(exc.value)
