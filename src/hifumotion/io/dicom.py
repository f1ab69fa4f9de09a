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


def ultrasound_region_spacing_mm(ds: pydicom.Dataset) -> tuple[float, float] | None:
    """``(row, col)`` mm from the largest calibrated region of ``SequenceOfUltrasoundRegions``, if any."""
    best, best_area = None, -1
    for region in ds.get("SequenceOfUltrasoundRegions", []) or []:
        if region.get("PhysicalUnitsXDirection") != UNIT_CM or region.get("PhysicalUnitsYDirection") != UNIT_CM:
            continue
        dx, dy = region.get("PhysicalDeltaX"), region.get("PhysicalDeltaY")
        if dx is None or dy is None or float(dx) == 0 or float(dy) == 0:
            continue
        x0, x1 = region.get("RegionLocationMinX0", 0), region.get("RegionLocationMaxX1", 0)
        y0, y1 = region.get("RegionLocationMinY0", 0), region.get("RegionLocationMaxY1", 0)
        area = abs((x1 - x0) * (y1 - y0))
        if area > best_area:
            best, best_area = (abs(float(dy)) * 10.0, abs(float(dx)) * 10.0), area
    return best


def dicom_spacing_mm(ds: pydicom.Dataset) -> tuple[tuple[float, float] | None, str]:
    """Pixel spacing ``(row, col)`` in mm and the attribute it came from (or ``(None, "")``)."""
    us = ultrasound_region_spacing_mm(ds)
    if us is not None:
        return us, "SequenceOfUltrasoundRegions"
    if "PixelSpacing" in ds and ds.PixelSpacing:
        return (float(ds.PixelSpacing[0]), float(ds.PixelSpacing[1])), "PixelSpacing"
    for group in ("SharedFunctionalGroupsSequence", "PerFrameFunctionalGroupsSequence"):
        seq = ds.get(group)
        if seq and "PixelMeasuresSequence" in seq[0]:
            ps = seq[0].PixelMeasuresSequence[0].get("PixelSpacing")
            if ps:
                return (float(ps[0]), float(ps[1])), f"{group}.PixelMeasuresSequence"
    if "ImagerPixelSpacing" in ds and ds.ImagerPixelSpacing:
        return (float(ds.ImagerPixelSpacing[0]), float(ds.ImagerPixelSpacing[1])), "ImagerPixelSpacing"
    return None, ""


def dicom_frame_interval_s(ds: pydicom.Dataset) -> tuple[float | None, str]:
    """Frame interval in seconds and the attribute it came from (or ``(None, "")``)."""
    if ds.get("FrameTime") not in (None, "") and float(ds.FrameTime) > 0:
        return float(ds.FrameTime) / 1000.0, "FrameTime"
    ftv = ds.get("FrameTimeVector")
    if ftv is not None and len(ftv) > 1:
        steps = np.asarray([float(v) for v in ftv][1:])
        if np.all(steps > 0):
            return float(steps.mean()) / 1000.0, "FrameTimeVector"
    if ds.get("CineRate") not in (None, "") and float(ds.CineRate) > 0:
        return 1.0 / float(ds.CineRate), "CineRate"
    return None, ""


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
        pixels = ds.pixel_array  # pydicom >= 3 converts YBR colour to RGB by default
    except Exception as exc:
        raise InputError(f"cannot decode DICOM pixel data ({brief(exc)})", path) from None
    frames = int(ds.get("NumberOfFrames", 1) or 1)
    colour = int(ds.get("SamplesPerPixel", 1)) > 1
    frame_ndim = 2
    if frames == 1:
        pixels = pixels[None]
    pixels = to_grey(pixels, colour and has_channels(pixels, frame_ndim + 1))
    if pixels.ndim != 3:
        raise InputError(f"unexpected DICOM pixel array shape {pixels.shape}", path)
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


def _slice_position_mm(ds: pydicom.Dataset) -> float | None:
    ipp, iop = ds.get("ImagePositionPatient"), ds.get("ImageOrientationPatient")
    if ipp is None or iop is None:
        return None
    normal = np.cross(np.asarray(iop[:3], float), np.asarray(iop[3:], float))
    return float(np.dot(np.asarray(ipp, float), normal))


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
    positions = [_slice_position_mm(ds) for ds in datasets]
    first = datasets[0]
    spacing, spacing_from = dicom_spacing_mm(first)
    meta = _metadata(first) | {"format": "DICOM series", "files": len(files), "spacing_from": spacing_from}
    if all(p is not None for p in positions) and np.ptp(positions) > 0:
        order = np.argsort(positions, kind="stable")
        if len(set(np.round(positions, 6))) != len(positions):
            raise InputError("two DICOM images of the sweep share one slice position", folder)
        interval, positions_mm = None, np.asarray(positions)[order]
    else:
        numbers = [int(ds.get("InstanceNumber", i)) for i, ds in enumerate(datasets)]
        order = np.argsort(numbers, kind="stable")
        interval, interval_from = dicom_frame_interval_s(first)
        meta["frame_interval_from"] = interval_from
        positions_mm = None
    array = np.concatenate([stacks[i] for i in order])
    return {"array": array, "value_range": _value_range(first, array), "spacing_mm": spacing,
            "frame_interval_s": interval, "slice_positions_mm": positions_mm, "metadata": meta}
