"""Readers and writers: real files written by the libraries themselves, read back."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest
import SimpleITK as sitk
import tifffile
import imageio.v3 as iio
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sequence import Sequence as DicomSequence
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

from hifumotion.contour import Contour
from hifumotion.errors import InputError, OutputExistsError
from hifumotion.io import (
    output_folder,
    read_contours_csv,
    read_mask,
    read_sequence,
    write_contours_csv,
    write_contours_json,
    write_mask_png,
    write_masks_nifti,
    write_png_stack,
    write_sequence_nifti,
)
from hifumotion.io.files import write_text
from hifumotion.sequence import ImageSequence

US_MULTIFRAME = "1.2.840.10008.5.1.4.1.1.3.1"
US_IMAGE = "1.2.840.10008.5.1.4.1.1.6.1"


def ramp(t: int = 3, h: int = 32, w: int = 48) -> np.ndarray:
    """Distinct, smooth uint8 frames: each frame a gradient plus its index."""
    rows, cols = np.mgrid[0:h, 0:w]
    return np.stack([(rows * 3 + cols * 2 + 20 * k) % 256 for k in range(t)]).astype(np.uint8)


def dicom_dataset(pixels: np.ndarray, sop_class: str = US_MULTIFRAME, **attrs) -> Dataset:
    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.MediaStorageSOPClassUID = sop_class
    ds.file_meta.MediaStorageSOPInstanceUID = generate_uid()
    ds.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID
    ds.Modality = "US"
    colour = pixels.shape[-1] == 3 and pixels.ndim in (3, 4) and attrs.pop("colour", False)
    frames = pixels.shape[0] if pixels.ndim == (4 if colour else 3) else 1
    ds.Rows, ds.Columns = pixels.shape[-3:-1] if colour else pixels.shape[-2:]
    ds.SamplesPerPixel = 3 if colour else 1
    ds.PhotometricInterpretation = "RGB" if colour else "MONOCHROME2"
    if colour:
        ds.PlanarConfiguration = 0
    ds.BitsAllocated = ds.BitsStored = 8
    ds.HighBit = 7
    ds.PixelRepresentation = 0
    if frames > 1:
        ds.NumberOfFrames = frames
    for k, v in attrs.items():
        setattr(ds, k, v)
    ds.PixelData = np.ascontiguousarray(pixels).tobytes()
    return ds


def us_region(dx_cm: float, dy_cm: float, h: int, w: int) -> Dataset:
    r = Dataset()
    r.RegionSpatialFormat = 1
    r.RegionDataType = 1
    r.RegionLocationMinX0, r.RegionLocationMinY0 = 0, 0
    r.RegionLocationMaxX1, r.RegionLocationMaxY1 = w - 1, h - 1
    r.PhysicalUnitsXDirection = 3
    r.PhysicalUnitsYDirection = 3
    r.PhysicalDeltaX, r.PhysicalDeltaY = dx_cm, dy_cm
    return r


# --- raster images --------------------------------------------------------------------------


def test_png_single_image_keeps_grey_levels(tmp_path):
    img = ramp(1)[0]
    iio.imwrite(tmp_path / "a.png", img)
    seq = read_sequence(tmp_path / "a.png", spacing_mm=0.3)
    assert seq.frames.shape == (1, 32, 48) and seq.frames.dtype == np.float32
    assert np.array_equal(np.rint(seq.frames[0] * 255).astype(np.uint8), img)
    assert seq.spacing_mm == (0.3, 0.3) and seq.spacing_known and seq.kind == "image"


def test_png_without_spacing_is_flagged_unknown(tmp_path):
    iio.imwrite(tmp_path / "a.png", ramp(1)[0])
    seq = read_sequence(tmp_path / "a.png")
    assert seq.spacing_mm == (1.0, 1.0) and not seq.spacing_known


def test_rgb_png_of_grey_content_reads_as_grey(tmp_path):
    img = ramp(1)[0]
    iio.imwrite(tmp_path / "c.png", np.repeat(img[..., None], 3, axis=-1))
    seq = read_sequence(tmp_path / "c.png")
    assert np.array_equal(np.rint(seq.frames[0] * 255).astype(np.uint8), img)


def test_folder_of_frames_in_natural_order(tmp_path):
    for k in (10, 2, 1):
        iio.imwrite(tmp_path / f"frame_{k}.png", np.full((8, 9), k * 10, np.uint8))
    seq = read_sequence(tmp_path, spacing_mm=(0.2, 0.25), frame_interval_s=0.1)
    assert np.allclose(seq.frames[:, 0, 0] * 255, [10, 20, 100])
    assert seq.kind == "cine" and seq.frame_interval_s == 0.1 and seq.spacing_mm == (0.2, 0.25)


def test_multipage_tiff_uint16(tmp_path):
    stack = (ramp(4).astype(np.uint16) * 200 + 1000)
    tifffile.imwrite(tmp_path / "s.tif", stack, photometric="minisblack")
    seq = read_sequence(tmp_path / "s.tif")
    assert seq.n_frames == 4
    # one min-max scale for the whole stack keeps the frames comparable
    restored = seq.frames * (stack.max() - stack.min()) + stack.min()
    assert np.allclose(restored, stack, atol=0.1)


def test_rgb_tiff_becomes_grey(tmp_path):
    grey = ramp(1)[0]
    tifffile.imwrite(tmp_path / "rgb.tif", np.repeat(grey[..., None], 3, -1), photometric="rgb")
    seq = read_sequence(tmp_path / "rgb.tif")
    assert seq.n_frames == 1 and np.array_equal(np.rint(seq.frames[0] * 255).astype(np.uint8), grey)


def test_a_tiff_written_page_by_page_keeps_every_page(tmp_path):
    # each page written alone is its own series in tifffile; the second must not be dropped
    pages = [np.full((6, 7), 10 * (k + 1), np.uint8) for k in range(3)]
    with tifffile.TiffWriter(tmp_path / "pages.tif") as w:
        for page in pages:
            w.write(page)
    seq = read_sequence(tmp_path / "pages.tif")
    assert seq.n_frames == 3
    assert np.all(np.diff(seq.frames[:, 0, 0]) > 0)       # in the order written


def test_a_tiff_with_pages_of_two_sizes_is_refused_by_name(tmp_path):
    with tifffile.TiffWriter(tmp_path / "mixed.tif") as w:
        w.write(np.zeros((6, 7), np.uint8))
        w.write(np.zeros((3, 7), np.uint8))
    with pytest.raises(InputError, match=r"mixed\.tif.*different sizes"):
        read_sequence(tmp_path / "mixed.tif")


# --- DICOM ----------------------------------------------------------------------------------


def test_ultrasound_multiframe_dicom_spacing_and_frame_time(tmp_path):
    frames = ramp(5, 40, 60)
    ds = dicom_dataset(frames, FrameTime="33.3", SequenceOfUltrasoundRegions=DicomSequence([us_region(0.02, 0.025, 40, 60)]))
    path = tmp_path / "cine.dcm"
    ds.save_as(path, enforce_file_format=True)
    seq = read_sequence(path)
    assert seq.n_frames == 5 and seq.shape == (40, 60)
    assert seq.spacing_mm == pytest.approx((0.25, 0.2))  # cm → mm, (row, col) = (ΔY, ΔX)
    assert seq.frame_interval_s == pytest.approx(0.0333)
    assert seq.metadata["spacing_from"] == "SequenceOfUltrasoundRegions"
    assert np.array_equal(np.rint(seq.frames * 255).astype(np.uint8), frames)


def test_dicom_cine_rate_and_pixel_spacing(tmp_path):
    ds = dicom_dataset(ramp(3), CineRate=25, PixelSpacing=[0.3, 0.4])
    path = tmp_path / "cine_rate.dcm"
    ds.save_as(path, enforce_file_format=True)
    seq = read_sequence(path)
    assert seq.frame_interval_s == pytest.approx(0.04)
    assert seq.spacing_mm == pytest.approx((0.3, 0.4))


def test_colour_ultrasound_dicom_becomes_grey(tmp_path):
    grey = ramp(2)
    rgb = np.repeat(grey[..., None], 3, axis=-1)
    ds = dicom_dataset(rgb, colour=True, FrameTime="50")
    path = tmp_path / "rgb.dcm"
    ds.save_as(path, enforce_file_format=True)
    seq = read_sequence(path)
    assert np.array_equal(np.rint(seq.frames * 255).astype(np.uint8), grey)


def test_dicom_without_pixel_data_is_a_clear_error(tmp_path):
    ds = dicom_dataset(ramp(1)[0], US_IMAGE)
    del ds.PixelData
    path = tmp_path / "empty.dcm"
    ds.save_as(path, enforce_file_format=True)
    with pytest.raises(InputError, match="empty.dcm: DICOM has no pixel data"):
        read_sequence(path)


def test_dicom_folder_is_a_sweep_sorted_by_position(tmp_path):
    z_mm = [4.0, 0.0, 6.0, 2.0]
    for k, z in enumerate(z_mm):
        ds = dicom_dataset(np.full((16, 20), int(z * 10), np.uint8), US_IMAGE, PixelSpacing=[0.5, 0.5],
                           ImagePositionPatient=[0, 0, z], ImageOrientationPatient=[1, 0, 0, 0, 1, 0], InstanceNumber=k + 1)
        ds.save_as(tmp_path / f"IM{k}", enforce_file_format=True)  # no suffix, found by the DICM marker
    seq = read_sequence(tmp_path)
    assert seq.kind == "sweep"
    assert np.allclose(seq.slice_positions_mm, [0, 2, 4, 6])
    assert np.allclose(seq.frames[:, 0, 0] * 255, [0, 20, 40, 60])


# --- NIfTI, MHA, NRRD ------------------------------------------------------------------------


def test_nifti_2d_plus_t(tmp_path):
    frames = ramp(6)
    image = sitk.GetImageFromArray(frames[:, None], isVector=False)  # (t, z=1, y, x)
    image.SetSpacing((0.2, 0.3, 1.0, 0.1))
    sitk.WriteImage(image, str(tmp_path / "cine.nii.gz"))
    seq = read_sequence(tmp_path / "cine.nii.gz")
    assert seq.kind == "cine" and seq.n_frames == 6
    assert seq.frame_interval_s == pytest.approx(0.1)
    assert seq.spacing_mm == pytest.approx((0.3, 0.2))
    assert np.array_equal(np.rint(seq.frames * 255).astype(np.uint8), frames)


def test_nifti_3d_is_a_sweep_with_positions(tmp_path):
    image = sitk.GetImageFromArray(ramp(4))
    image.SetSpacing((0.2, 0.3, 1.5))
    image.SetOrigin((0.0, 0.0, 10.0))
    sitk.WriteImage(image, str(tmp_path / "sweep.nii"))
    seq = read_sequence(tmp_path / "sweep.nii")
    assert seq.kind == "sweep"
    assert np.allclose(seq.slice_positions_mm, [10.0, 11.5, 13.0, 14.5])


@pytest.mark.parametrize("suffix", [".mha", ".nrrd"])
def test_mha_and_nrrd_read_as_cine_when_asked(tmp_path, suffix):
    image = sitk.GetImageFromArray(ramp(3))
    image.SetSpacing((0.25, 0.25, 0.05))
    sitk.WriteImage(image, str(tmp_path / f"v{suffix}"))
    seq = read_sequence(tmp_path / f"v{suffix}", kind="cine")
    assert seq.kind == "cine" and seq.frame_interval_s == pytest.approx(0.05)
    assert seq.spacing_mm == pytest.approx((0.25, 0.25))


# --- video -----------------------------------------------------------------------------------


def test_mp4_frames_and_frame_rate(tmp_path):
    rows, cols = np.mgrid[0:64, 0:80]
    frames = np.stack([((np.sin(cols / 9 + k / 3) + 1) * 100 + 20) for k in range(10)]).astype(np.uint8)
    iio.imwrite(tmp_path / "loop.mp4", np.repeat(frames[..., None], 3, -1), plugin="pyav", codec="libx264", fps=20)
    seq = read_sequence(tmp_path / "loop.mp4", spacing_mm=0.2)
    assert seq.n_frames == 10 and seq.shape == (64, 80)
    assert seq.frame_interval_s == pytest.approx(0.05)
    # lossy codec: grey levels agree on average within a few levels
    assert np.abs(seq.frames * 255 - frames).mean() < 4.0


# --- bad input -------------------------------------------------------------------------------


def test_bad_inputs(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_sequence(tmp_path / "missing.png")
    (tmp_path / "notes.xyz").write_text("hello")
    with pytest.raises(InputError, match="unsupported format '.xyz'"):
        read_sequence(tmp_path / "notes.xyz")
    (tmp_path / "broken.png").write_bytes(b"not a png at all")
    with pytest.raises(InputError, match="broken.png: cannot read"):
        read_sequence(tmp_path / "broken.png")
    (tmp_path / "broken.nii").write_bytes(b"\x00" * 40)
    with pytest.raises(InputError, match="broken.nii"):
        read_sequence(tmp_path / "broken.nii")
    iio.imwrite(tmp_path / "ok.png", ramp(1)[0])
    with pytest.raises(InputError, match="spacing_mm"):
        read_sequence(tmp_path / "ok.png", spacing_mm=-0.2)


# --- writers ---------------------------------------------------------------------------------


def test_sequence_nifti_round_trip_keeps_geometry(tmp_path):
    cine = ImageSequence.from_array(ramp(4), spacing_mm=(0.3, 0.2), frame_interval_s=0.1)
    write_sequence_nifti(tmp_path / "c.nii.gz", cine)
    back = read_sequence(tmp_path / "c.nii.gz")
    assert back.kind == "cine" and back.frame_interval_s == pytest.approx(0.1)
    assert back.spacing_mm == pytest.approx((0.3, 0.2))
    assert np.allclose(back.frames, cine.frames, atol=0.5 / 255)

    sweep = ImageSequence.from_array(ramp(3), spacing_mm=0.25, slice_positions_mm=[5.0, 6.0, 7.0])
    write_sequence_nifti(tmp_path / "s.nii.gz", sweep)
    back = read_sequence(tmp_path / "s.nii.gz")
    assert np.allclose(back.slice_positions_mm, [5.0, 6.0, 7.0])


def test_mask_writers(tmp_path):
    mask = np.zeros((20, 30), bool)
    mask[5:15, 8:20] = True
    write_mask_png(tmp_path / "m.png", mask)
    assert set(np.unique(iio.imread(tmp_path / "m.png"))) == {0, 255}
    assert np.array_equal(read_mask(tmp_path / "m.png"), mask)
    write_masks_nifti(tmp_path / "m.nii.gz", np.stack([mask, ~mask]), spacing_mm=0.5, frame_interval_s=0.1)
    arr = sitk.GetArrayFromImage(sitk.ReadImage(str(tmp_path / "m.nii.gz")))
    assert arr.shape == (2, 1, 20, 30) and set(np.unique(arr)) == {0, 1}
    paths = write_png_stack(tmp_path / "stack", np.stack([mask, mask]))
    assert [p.name for p in paths] == ["frame_0000.png", "frame_0001.png"]
    empty = tmp_path / "empty.png"
    write_mask_png(empty, np.zeros((5, 5), bool))
    with pytest.raises(InputError, match="no foreground"):
        read_mask(empty)


def test_contours_csv_round_trip(tmp_path):
    c = Contour(np.array([[1.5, 2.0], [10.25, 2.0], [10.25, 8.5], [1.5, 8.5]]), spacing_mm=(0.5, 0.25))
    write_contours_csv(tmp_path / "c.csv", {20: c, 30: c})
    back = read_contours_csv(tmp_path / "c.csv", spacing_mm=(0.5, 0.25))
    assert set(back) == {"20", "30"}
    assert np.allclose(back["20"].points_px, c.points_px)
    assert np.allclose(back["30"].points_mm, c.points_mm)
    write_contours_json(tmp_path / "c.json", [c])
    assert '"area_mm2"' in (tmp_path / "c.json").read_text()


def test_output_folder_never_clobbers(tmp_path):
    target = tmp_path / "run"
    with output_folder(target) as out:
        (out / "result.txt").write_text("first")
        (out / "run_info.json").write_text("{}")       # what makes it hifumotion's: --overwrite may replace it
    assert (target / "result.txt").read_text() == "first"
    with pytest.raises(OutputExistsError, match="--overwrite"):
        with output_folder(target):
            pass
    with pytest.raises(RuntimeError):
        with output_folder(target, overwrite=True) as out:
            (out / "result.txt").write_text("half")
            raise RuntimeError("the run failed")
    assert (target / "result.txt").read_text() == "first"  # a failed run leaves the old results
    with output_folder(target, overwrite=True) as out:
        (out / "result.txt").write_text("second")
        (out / "run_info.json").write_text("{}")
    assert (target / "result.txt").read_text() == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging folder left behind


def test_overwrite_never_deletes_what_hifumotion_did_not_write(tmp_path, capsys):
    target = tmp_path / "run"
    with output_folder(target) as out:
        (out / "figures").mkdir()
        (out / "figures" / "a.png").write_bytes(b"png")
        (out / "run_info.json").write_text("{}")
    listed = json.loads((target / "run_info.json").read_text())["outputs"]
    assert listed == ["figures", "figures/a.png", "run_info.json"]
    # the user's notes beside the results: --overwrite refuses, naming them, and deletes nothing
    (target / "notes.txt").write_text("mine")
    (target / "figures" / "sketch.svg").write_text("mine too")
    with pytest.raises(InputError, match=r"notes\.txt") as refused:
        with output_folder(target, overwrite=True) as out:
            (out / "run_info.json").write_text("{}")
    assert "figures/sketch.svg" in str(refused.value)
    assert (target / "notes.txt").read_text() == "mine" and (target / "figures" / "a.png").is_file()
    (target / "notes.txt").unlink()
    (target / "figures" / "sketch.svg").unlink()
    with output_folder(target, overwrite=True) as out:
        (out / "run_info.json").write_text("{}")
    assert not (target / "figures").exists()          # all of it was the earlier run's: replaced
    # a folder whose run_info.json lists nothing (an older version's): its files cannot be told
    # from the user's, so it is moved aside, not deleted
    (target / "run_info.json").write_text("{}")
    (target / "maybe_mine.txt").write_text("?")
    with output_folder(target, overwrite=True) as out:
        (out / "run_info.json").write_text("{}")
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("run.replaced-")]
    assert len(aside) == 1 and (aside[0] / "maybe_mine.txt").read_text() == "?"
    # and the move is said, naming where the files went
    assert aside[0].name in " ".join(capsys.readouterr().err.split())
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("run.replaced-")) == ["run"]


def test_a_file_put_into_the_output_folder_during_the_run_is_kept(tmp_path):
    target = tmp_path / "run"
    with output_folder(target) as out:
        (out / "run_info.json").write_text("{}")
    with pytest.raises(InputError, match="this run's output is in"):
        with output_folder(target, overwrite=True) as out:
            (out / "result.txt").write_text("new")
            (out / "run_info.json").write_text("{}")
            (target / "late.txt").write_text("the user's")      # written while the run goes on
    assert (target / "late.txt").read_text() == "the user's"
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("run.new-")]
    assert len(kept) == 1 and (kept[0] / "result.txt").read_text() == "new"


def test_outputs_follow_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with output_folder(tmp_path / "run") as out:
            write_text(out / "a.txt", "x")
            (out / "run_info.json").write_text("{}")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "run").stat().st_mode) == 0o750
    assert stat.S_IMODE((tmp_path / "run" / "a.txt").stat().st_mode) == 0o640
    assert stat.S_IMODE((tmp_path / "run" / "run_info.json").stat().st_mode) == 0o640


def test_output_path_through_a_missing_folder_is_checked_where_it_resolves(tmp_path):
    # "missing/../notes.txt" does not exist as typed, but the run would land on notes.txt
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    with pytest.raises(InputError, match="not a folder"):
        with output_folder(tmp_path / "missing" / ".." / "notes.txt"):
            pass
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "data.csv").write_text("mine")
    with pytest.raises(OutputExistsError):
        with output_folder(tmp_path / "missing" / ".." / "kept"):
            pass
    assert notes.read_text() == "mine" and (kept / "data.csv").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept", "notes.txt"]


def test_a_bar_rounded_beyond_its_radius_is_refused_naming_the_field():
    from hifumotion.observed.setup import BarSetup

    with pytest.raises(Exception, match="edge_radius_mm"):
        BarSetup(radius_mm=3.0, edge_radius_mm=4.0, tip_at_rest_mm=(0.0, 0.0, 0.0))
    assert BarSetup(tip_at_rest_mm=(0.0, 0.0, 0.0)).edge_radius_mm == 0.5   # a setup.json written before has none


def test_a_byte_order_mark_is_no_content(tmp_path):
    """Files saved by Windows editors and spreadsheets start with a UTF-8 byte-order mark: a
    contour CSV and an init JSON read as without it (the mark was read as part of the first
    column's name, and JSON refused)."""
    import json

    from hifumotion.io import read_contours_csv
    from hifumotion.io.init_json import read_init_json

    csv_path = tmp_path / "c.csv"
    csv_path.write_text("frame,x_px,y_px\n0,1,1\n0,9,1\n0,9,9\n", encoding="utf-8-sig")
    contour = next(iter(read_contours_csv(csv_path).values()))
    assert contour.points_px.shape == (3, 2)
    init = tmp_path / "init.json"
    init.write_text(json.dumps({"a.png": {"ellipse": {"cx": 5, "cy": 5, "a": 3, "b": 2, "angle_deg": 0}}}),
                    encoding="utf-8-sig")
    assert "a.png" in read_init_json(init)


def test_json_is_standard_where_a_number_is_not_finite(tmp_path):
    """RFC 8259 has no Infinity or NaN: a strict parser (constants refused) must read every file
    hifumotion writes, a non-finite number coming back as null and every finite one unchanged."""
    from hifumotion.io.writers import json_text, write_json

    def strict(text):
        def refuse(name):
            raise ValueError(f"{name} is not JSON")
        return json.loads(text, parse_constant=refuse)

    data = {"inf": float("inf"), "nan": float("nan"), "neg": -np.inf, "kept": 0.125,
            "numpy": np.float32(np.inf), "array": np.array([1.5, np.nan, 3.0]), "nested": [{"x": (np.inf, 2)}],
            "int": np.int64(7), "flag": np.bool_(True), "path": tmp_path}
    back = strict(write_json(tmp_path / "a.json", data).read_text())
    assert back == {"inf": None, "nan": None, "neg": None, "kept": 0.125, "numpy": None,
                    "array": [1.5, None, 3.0], "nested": [{"x": [None, 2]}], "int": 7, "flag": True,
                    "path": str(tmp_path)}
    assert strict(json_text([np.nan], indent=None)) == [None]
    assert strict(json_text({np.int64(20): np.inf}, indent=None)) == {"20": None}     # frame-numbered keys
    with pytest.raises(TypeError, match="object"):
        json_text({"x": object()})
