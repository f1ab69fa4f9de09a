"""DICOM: single-frame images, ultrasound multi-frame cine loops, and series in a folder (pydicom).

Geometry, in order of preference:

* pixel spacing from the ultrasound region calibration
  (``SequenceOfUltrasoundRegions``: ``PhysicalDeltaX/Y`` where
  ``PhysicalUnitsX/YDirection`` = 3, i.e. cm; converted to mm), else
  ``PixelSpacing`` (mm, row then column), else the enhanced multi-frame
  ``PixelMeasuresSequence``, else ``ImagerPixelSpacing``;
* frame interval from ``FrameTime`` (ms), else ``FrameTimeVector`` (ms, mean
  of the increments), else ``CineRate`` (frames per second);
* for a folder of single-frame files: slice positions along the plane normal
  from ``ImagePositionPatient`` and ``ImageOrientationPatient`` (a spatial
  sweep), else the ``InstanceNumber`` order (a time series).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pydicom
from pydicom.errors import InvalidDicomError

from hifumotion.errors import InputError, brief
from hifumotion.io.grey import has_channels, to_grey
from hifumotion.io.naming import looks_like_dicom, natural_key

#: DICOM code of the physical unit "cm" in PhysicalUnitsX/YDirection (PS3.3 C.8.5.5.1.15).
UNIT_CM = 3
_PIXEL_KEYWORDS = ("PixelData", "FloatPixelData", "DoubleFloatPixelData")


def _open(path: Path) -> pydicom.Dataset:
    try:
        return pydicom.dcmread(path)
    except InvalidDicomError as exc:
        raise InputError(f"not a DICOM file ({exc})", path) from None
    except Exception as exc:
        raise InputError(f"cannot read DICOM ({brief(exc)})", path) from None


class _Malformed(ValueError):
    """An attribute that is present but not the numbers the standard says it holds."""

    def __init__(self, keyword: str, value: object, expected: str):
        self.keyword = keyword
        super().__init__(f"{keyword} is {str(value)[:40]!r}; expected {expected}")


def _numbers(ds: pydicom.Dataset, keyword: str, count: int | None = None, positive: bool = False,
             expected: str = "numbers") -> tuple[float, ...] | None:
    """``keyword``'s values as finite floats; None when absent or empty. Present but not
    ``count`` finite (``positive``) numbers — ``PixelSpacing`` "abc" or one value, ``FrameTime``
    "fast": common in the wild — raises :class:`_Malformed` (pydicom reads such values lazily,
    so the access itself may fail)."""
    try:
        with warnings.catch_warnings():     # pydicom warns of a value it cannot validate: ours is the one line
            warnings.simplefilter("ignore")
            value = ds.get(keyword)
            if value is None or value == "":
                return None
            items = list(value) if isinstance(value, (list, tuple, pydicom.multival.MultiValue)) else [value]
            numbers = tuple(float(v) for v in items)
    except (TypeError, ValueError, OverflowError):
        raise _Malformed(keyword, _raw(ds, keyword), expected) from None
    if ((count is not None and len(numbers) != count) or not np.all(np.isfinite(numbers))
            or (positive and not all(x > 0 for x in numbers))):
        raise _Malformed(keyword, _raw(ds, keyword), expected)
    return numbers


def _raw(ds: pydicom.Dataset, keyword: str) -> str:
    """The attribute's stored text (for a message), whatever it holds."""
    try:
        element = ds.data_element(keyword)
        value = element.value if element is not None else None
    except Exception:
        return "?"
    return value.decode("latin-1", "replace").strip() if isinstance(value, bytes) else str(value)


def ultrasound_region_spacing_mm(ds: pydicom.Dataset) -> tuple[float, float] | None:
    """``(row, col)`` mm from the largest calibrated region of ``SequenceOfUltrasoundRegions``, if any
    (a region whose deltas are not numbers is skipped, as one without calibration)."""
    best, best_area = None, -1
    for region in ds.get("SequenceOfUltrasoundRegions", []) or []:
        if region.get("PhysicalUnitsXDirection") != UNIT_CM or region.get("PhysicalUnitsYDirection") != UNIT_CM:
            continue
        try:
            dx, dy = _numbers(region, "PhysicalDeltaX", 1), _numbers(region, "PhysicalDeltaY", 1)
            box = [_numbers(region, k, 1) or (0.0,) for k in
                   ("RegionLocationMinX0", "RegionLocationMaxX1", "RegionLocationMinY0", "RegionLocationMaxY1")]
        except _Malformed:
            continue
        if dx is None or dy is None or dx[0] == 0 or dy[0] == 0:
            continue
        (x0,), (x1,), (y0,), (y1,) = box
        area = abs((x1 - x0) * (y1 - y0))
        if area > best_area:
            best, best_area = (abs(dy[0]) * 10.0, abs(dx[0]) * 10.0), area
    return best


def dicom_spacing_mm(ds: pydicom.Dataset) -> tuple[tuple[float, float] | None, str]:
    """Pixel spacing ``(row, col)`` in mm and the attribute it came from (or ``(None, why)``).

    A malformed attribute is passed over, as if absent, and named in the second value: the
    file gives no pixel size then, and a command that needs one asks for ``--spacing``.
    """
    us = ultrasound_region_spacing_mm(ds)
    if us is not None:
        return us, "SequenceOfUltrasoundRegions"
    sources = [(ds, "PixelSpacing", "PixelSpacing")]
    for group in ("SharedFunctionalGroupsSequence", "PerFrameFunctionalGroupsSequence"):
        seq = ds.get(group)
        if seq and "PixelMeasuresSequence" in seq[0] and seq[0].PixelMeasuresSequence:
            sources.append((seq[0].PixelMeasuresSequence[0], "PixelSpacing", f"{group}.PixelMeasuresSequence"))
    sources.append((ds, "ImagerPixelSpacing", "ImagerPixelSpacing"))
    malformed = []
    for holder, keyword, name in sources:
        try:
            values = _numbers(holder, keyword, 2, positive=True, expected="two positive numbers (mm)")
        except _Malformed as exc:
            malformed.append(str(exc))
            continue
        if values is not None:
            return (values[0], values[1]), name
    return None, ("malformed: " + "; ".join(malformed)) if malformed else ""


def dicom_frame_interval_s(ds: pydicom.Dataset) -> tuple[float | None, str]:
    """Frame interval in seconds and the attribute it came from (or ``(None, why)``; a malformed
    attribute is passed over and named, as in :func:`dicom_spacing_mm`)."""
    malformed = []
    for keyword, to_seconds in (("FrameTime", lambda v: v[0] / 1000.0),
                                ("FrameTimeVector", lambda v: float(np.mean(np.asarray(v[1:]))) / 1000.0),
                                ("CineRate", lambda v: 1.0 / v[0])):
        try:
            values = _numbers(ds, keyword, 1 if keyword != "FrameTimeVector" else None,
                              expected="a number" if keyword != "FrameTimeVector" else "numbers (ms)")
        except _Malformed as exc:
            malformed.append(str(exc))
            continue
        if values is None:
            continue
        if keyword == "FrameTimeVector":
            if len(values) > 1 and all(v > 0 for v in values[1:]):
                return to_seconds(values), keyword
        elif values[0] > 0:
            return to_seconds(values), keyword
    return None, ("malformed: " + "; ".join(malformed)) if malformed else ""


def _value_range(ds: pydicom.Dataset, pixels: np.ndarray) -> tuple[float, float] | None:
    """Scale integer data by the stored bit depth, so grey levels keep their meaning."""
    if np.issubdtype(pixels.dtype, np.unsignedinteger):
        bits = int(ds.get("BitsStored", pixels.dtype.itemsize * 8))
        return (0.0, float(2**bits - 1))
    return None


def _pixels(ds: pydicom.Dataset, path: Path) -> np.ndarray:
    """Grey frames ``(T, H, W)`` of one dataset in its stored dtype."""
    if not any(k in ds for k in _PIXEL_KEYWORDS):
        raise InputError("DICOM has no pixel data (no PixelData element)", path)
    try:
        declared = _numbers(ds, "NumberOfFrames", 1, expected="a whole number of frames ≥ 1")
    except _Malformed as exc:
        raise InputError(str(exc), path) from None
    if declared is not None and not (declared[0] >= 1 and float(declared[0]).is_integer()):
        raise InputError(f"NumberOfFrames is {declared[0]:g}; expected a whole number of frames ≥ 1", path)
    frames = 1 if declared is None else int(declared[0])
    try:
        with warnings.catch_warnings():
            # pydicom warns, then returns what it guessed, where the pixel data and NumberOfFrames
            # disagree: the disagreement is checked below and named instead
            warnings.simplefilter("ignore")
            pixels = ds.pixel_array  # pydicom >= 3 converts YBR colour to RGB by default
    except Exception as exc:
        raise InputError(f"cannot decode DICOM pixel data ({brief(exc)})", path) from None
    colour = int(ds.get("SamplesPerPixel", 1)) > 1
    frame_ndim = 2
    if frames == 1:
        pixels = pixels[None]
    pixels = to_grey(pixels, colour and has_channels(pixels, frame_ndim + 1))
    if pixels.ndim != 3 or pixels.shape[0] != frames:
        held = pixels.shape[1] if pixels.ndim == 4 and frames == 1 else None
        if held is not None:
            raise InputError(f"NumberOfFrames is {frames}; the pixel data holds {held} frames", path)
        raise InputError(f"unexpected DICOM pixel array shape {pixels.shape} for {frames} frame(s)", path)
    return pixels


def _metadata(ds: pydicom.Dataset) -> dict[str, Any]:
    keep = ("Modality", "Manufacturer", "ManufacturerModelName", "SOPClassUID", "PhotometricInterpretation",
            "TransducerData", "SeriesDescription", "StudyDate")
    out = {k: str(ds.get(k)) for k in keep if ds.get(k) not in (None, "")}
    return out


def read_dicom_file(path: Path) -> dict[str, Any]:
    """Read one DICOM file (single- or multi-frame) into the fields of an :class:`ImageSequence`."""
    ds = _open(path)
    pixels = _pixels(ds, path)
    spacing, spacing_from = dicom_spacing_mm(ds)
    interval, interval_from = dicom_frame_interval_s(ds) if pixels.shape[0] > 1 else (None, "")
    meta = _metadata(ds) | {"format": "DICOM", "spacing_from": spacing_from, "frame_interval_from": interval_from}
    return {"array": pixels, "value_range": _value_range(ds, pixels), "spacing_mm": spacing,
            "frame_interval_s": interval, "slice_positions_mm": None, "metadata": meta}


def _slice_position_mm(ds: pydicom.Dataset, path: Path) -> float | None:
    """The image's position along its plane's normal (mm), None without the attributes; malformed
    ones (a three-value ``ImageOrientationPatient``) are an :class:`InputError`: a sweep's order
    and spacing would be guessed."""
    try:
        ipp = _numbers(ds, "ImagePositionPatient", 3, expected="three numbers (mm)")
        iop = _numbers(ds, "ImageOrientationPatient", 6, expected="six numbers (two direction cosines)")
    except _Malformed as exc:
        raise InputError(str(exc), path) from None
    if ipp is None or iop is None:
        return None
    normal = np.cross(np.asarray(iop[:3]), np.asarray(iop[3:]))
    if not np.linalg.norm(normal) > 0.5:
        raise InputError(f"ImageOrientationPatient {list(iop)} is not two perpendicular unit directions", path)
    return float(np.dot(np.asarray(ipp), normal))


def read_dicom_folder(folder: Path) -> dict[str, Any]:
    """Read a folder of DICOM files as one series: a spatial sweep or a time series."""
    files = sorted((p for p in folder.iterdir() if p.is_file() and looks_like_dicom(p)), key=natural_key)
    if not files:
        raise InputError("folder holds no DICOM files", folder)
    if len(files) == 1:
        return read_dicom_file(files[0])
    datasets = [_open(f) for f in files]
    stacks = [_pixels(ds, f) for ds, f in zip(datasets, files)]
    if any(s.shape[0] != 1 for s in stacks):
        raise InputError("a folder of DICOM files must hold single-frame images; read a multi-frame file on its own", folder)
    shapes = {s.shape for s in stacks}
    if len(shapes) != 1:
        raise InputError(f"DICOM images in the folder differ in size: {sorted(shapes)}", folder)
    positions = [_slice_position_mm(ds, f) for ds, f in zip(datasets, files)]
    first = datasets[0]
    spacing, spacing_from = dicom_spacing_mm(first)
    meta = _metadata(first) | {"format": "DICOM series", "files": len(files), "spacing_from": spacing_from}
    if all(p is not None for p in positions) and np.ptp(positions) > 0:
        order = np.argsort(positions, kind="stable")
        if len(set(np.round(positions, 6))) != len(positions):
            raise InputError("two DICOM images of the sweep share one slice position", folder)
        interval, positions_mm = None, np.asarray(positions)[order]
    else:
        numbers = []
        for i, (ds, f) in enumerate(zip(datasets, files)):
            try:
                number = _numbers(ds, "InstanceNumber", 1, expected="a whole number")
            except _Malformed as exc:
                raise InputError(str(exc), f) from None
            numbers.append(i if number is None else number[0])
        order = np.argsort(numbers, kind="stable")
        interval, interval_from = dicom_frame_interval_s(first)
        meta["frame_interval_from"] = interval_from
        positions_mm = None
    array = np.concatenate([stacks[i] for i in order])
    return {"array": array, "value_range": _value_range(first, array), "spacing_mm": spacing,
            "frame_interval_s": interval, "slice_positions_mm": positions_mm, "metadata": meta}
