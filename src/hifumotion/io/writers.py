"""Writers: masks (PNG, NIfTI), image sequences (PNG stack, NIfTI), contours (CSV, JSON).

Every file is written atomically (:func:`hifumotion.io.files.atomic_path`).
NIfTI files carry the geometry so 3D Slicer and ParaView place them in mm:
a sweep is a 3D volume whose third spacing is the slice step; a cine loop is a
4D image ``(x, y, 1, t)`` whose fourth spacing is the frame interval in seconds.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import imageio.v3 as iio
import numpy as np
import SimpleITK as sitk

from hifumotion.contour import Contour, as_mask
from hifumotion.errors import InputError, brief
from hifumotion.io.files import atomic_path, write_text
from hifumotion.sequence import ImageSequence, as_spacing_mm

CONTOUR_CSV_COLUMNS = ("frame", "point", "x_px", "y_px", "x_mm", "y_mm")


def write_mask_png(path: str | Path, mask: np.ndarray) -> Path:
    """A mask as an 8-bit PNG: 0 background, 255 target (the layout of ``../shared/data``)."""
    m = as_mask(mask, str(path), require_foreground=False)
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, (m.astype(np.uint8) * 255), extension=".png")
    return Path(path)


def read_mask(path: str | Path, binary: bool = True) -> np.ndarray:
    """A mask from a PNG (non-zero = target) as a 2D bool array; raises if it has no foreground.

    With ``binary`` (the default) the image must hold at most two grey levels, 0 and one
    other: a B-mode image given where a mask belongs is refused, not thresholded."""
    from hifumotion.io.files import require_regular_file

    p = require_regular_file(path, "mask image")
    try:
        image = iio.imread(p)
    except Exception as exc:
        raise InputError(f"cannot read as an image ({brief(exc)})", p) from None
    if binary:
        check_binary(image, p)
    return as_mask(image, str(p))


def check_binary(image: np.ndarray, where: str | Path) -> None:
    """Raise unless ``image`` holds at most two values, one of them 0 (a mask, not a picture)."""
    values = np.unique(np.asarray(image))
    if values.size > 2 or (values.size == 2 and values[0] != 0):
        raise InputError(f"expected a mask (0 and one other value), got an image with {values.size} grey levels "
                         f"({values.min():g} … {values.max():g})", where)


def _volume_image(volume: np.ndarray, spacing_mm, frame_interval_s, slice_positions_mm) -> sitk.Image:
    row, col = as_spacing_mm(spacing_mm)
    if frame_interval_s is not None and volume.shape[0] > 1:
        image = sitk.GetImageFromArray(volume[:, None], isVector=False)  # (t, z=1, y, x)
        image.SetSpacing((col, row, 1.0, float(frame_interval_s)))
        return image
    image = sitk.GetImageFromArray(volume, isVector=False)
    if volume.shape[0] > 1 and slice_positions_mm is not None:
        pos = np.asarray(slice_positions_mm, float)
        steps = np.diff(pos)
        if steps.size and not np.allclose(steps, steps[0], rtol=1e-3, atol=1e-6):
            raise InputError("NIfTI needs evenly spaced slices; resample the sweep first", "slice_positions_mm")
        dz = float(steps[0]) if steps.size else 1.0
        image.SetSpacing((col, row, abs(dz)))
        image.SetOrigin((0.0, 0.0, float(pos.min())))
    elif volume.shape[0] > 1:
        image.SetSpacing((col, row, 1.0))
    else:
        image = sitk.GetImageFromArray(volume[0], isVector=False)
        image.SetSpacing((col, row))
    return image


def write_nifti(path: str | Path, volume: np.ndarray, spacing_mm, frame_interval_s: float | None = None,
                slice_positions_mm=None, origin_px: tuple[float, float] | None = None) -> Path:
    """Write ``(T, H, W)`` (or ``(H, W)``) data as NIfTI with its geometry; see the module notes.

    ``origin_px`` ``(x, y)``: where the data's first pixel lies on the full image (a crop), so a
    viewer places it over the image it was cut from."""
    vol = np.asarray(volume)
    if vol.ndim == 2:
        vol = vol[None]
    if vol.ndim != 3:
        raise InputError(f"expected (T, H, W) data, got shape {vol.shape}", path)
    if slice_positions_mm is not None:
        order = np.argsort(np.asarray(slice_positions_mm, float))
        vol, slice_positions_mm = vol[order], np.asarray(slice_positions_mm, float)[order]
    image = _volume_image(vol, spacing_mm, frame_interval_s, slice_positions_mm)
    if origin_px is not None:
        row, col = as_spacing_mm(spacing_mm)
        origin = list(image.GetOrigin())
        origin[0], origin[1] = float(origin_px[0]) * col, float(origin_px[1]) * row
        image.SetOrigin(origin)
    with atomic_path(path) as tmp:
        sitk.WriteImage(image, str(tmp), useCompression=True)
    return Path(path)


def write_masks_nifti(path: str | Path, masks: np.ndarray, spacing_mm, frame_interval_s: float | None = None,
                      slice_positions_mm=None) -> Path:
    """Masks ``(T, H, W)`` as a uint8 0/1 label map NIfTI (3D Slicer's segmentation convention)."""
    return write_nifti(path, (np.asarray(masks) != 0).astype(np.uint8), spacing_mm, frame_interval_s, slice_positions_mm)


def write_sequence_nifti(path: str | Path, sequence: ImageSequence) -> Path:
    """An image sequence as uint8 NIfTI (grey 0–255), geometry included."""
    frames = np.rint(sequence.frames * 255.0).astype(np.uint8)
    return write_nifti(path, frames, sequence.spacing_mm, sequence.frame_interval_s, sequence.slice_positions_mm)


def write_png_stack(folder: str | Path, frames: np.ndarray, prefix: str = "frame_", start: int = 0, digits: int = 4) -> list[Path]:
    """Frames ``(T, H, W)`` as ``folder/prefix0000.png`` …: floats in [0, 1] become 0–255, bools 0/255."""
    arr = np.asarray(frames)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.dtype == np.bool_:
        data = arr.astype(np.uint8) * 255
    elif np.issubdtype(arr.dtype, np.floating):
        data = np.rint(np.clip(arr, 0.0, 1.0) * 255.0).astype(np.uint8)
    else:
        data = arr.astype(np.uint8)
    out = []
    for k, frame in enumerate(data):
        p = Path(folder) / f"{prefix}{start + k:0{digits}d}.png"
        with atomic_path(p) as tmp:
            iio.imwrite(tmp, frame, extension=".png")
        out.append(p)
    return out


def _as_labelled(contours: Mapping[Any, Contour] | Sequence[Contour]) -> list[tuple[Any, Contour]]:
    if isinstance(contours, Mapping):
        return list(contours.items())
    return list(enumerate(contours))


def write_contours_csv(path: str | Path, contours: Mapping[Any, Contour] | Sequence[Contour]) -> Path:
    """Contours as CSV rows ``frame, point, x_px, y_px, x_mm, y_mm`` (a list is numbered from 0)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CONTOUR_CSV_COLUMNS)
    for label, c in _as_labelled(contours):
        mm = c.points_mm
        for k, (px, pmm) in enumerate(zip(c.points_px, mm)):
            writer.writerow([label, k, f"{px[0]:.4f}", f"{px[1]:.4f}", f"{pmm[0]:.5f}", f"{pmm[1]:.5f}"])
    return write_text(path, buf.getvalue())


def read_contours_csv(path: str | Path, spacing_mm=None) -> dict[str, Contour]:
    """Contours from a CSV with columns ``frame`` and either ``x_px, y_px`` or ``x_mm, y_mm``.

    Pixel columns are used when present; mm columns need ``spacing_mm`` to
    place them on an image grid (without it, 1 px = 1 mm). Points keep file order.
    """
    from hifumotion.io.files import require_regular_file

    p = require_regular_file(path, "contour CSV")
    try:
        with open(p, newline="", encoding="utf-8-sig") as fh:     # a spreadsheet's byte-order mark is no column name
            rows = list(csv.DictReader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read as a contour CSV ({brief(exc)})", p) from None
    if not rows:
        raise InputError("no contour rows", p)
    cols = set(rows[0])
    use_px = {"x_px", "y_px"} <= cols
    if "frame" not in cols or not (use_px or {"x_mm", "y_mm"} <= cols):
        raise InputError(f"expected columns 'frame' and 'x_px, y_px' or 'x_mm, y_mm', got {sorted(cols)}", p)
    sp = as_spacing_mm(spacing_mm)
    grouped: dict[str, list[tuple[float, float]]] = {}
    names = ("frame", "x_px", "y_px") if use_px else ("frame", "x_mm", "y_mm")
    for line, r in enumerate(rows, start=2):           # line 1 is the header
        if any(r.get(n) is None for n in names):
            raise InputError(f"line {line} has fewer fields than the header (expected {', '.join(names)})", p)
        try:
            x, y = float(r[names[1]]), float(r[names[2]])
        except ValueError:
            raise InputError(f"line {line}: non-numeric coordinate ({r[names[1]]!r}, {r[names[2]]!r})", p) from None
        if not (np.isfinite(x) and np.isfinite(y)):
            raise InputError(f"line {line}: coordinates must be finite numbers, got ({x}, {y})", p)
        grouped.setdefault(r["frame"], []).append((x, y) if use_px else (x / sp[1], y / sp[0]))
    try:
        return {k: Contour(np.asarray(v), sp) for k, v in grouped.items()}
    except InputError as exc:
        raise InputError(exc.reason, p) from None


def write_contours_json(path: str | Path, contours: Mapping[Any, Contour] | Sequence[Contour]) -> Path:
    """Contours as JSON: ``{"contours": {label: {points_px, points_mm, spacing_mm, area_mm2, centroid_mm}}}``."""
    data = {"contours": {str(label): c.to_dict() for label, c in _as_labelled(contours)}}
    return write_json(path, data)


def write_json(path: str | Path, data: Any) -> Path:
    """JSON, indented, numpy values converted, written atomically (:func:`json_text`)."""
    return write_text(path, json_text(data) + "\n")


def json_text(data: Any, indent: int | None = 2) -> str:
    """``data`` as standard JSON (RFC 8259): numpy values and arrays, paths and pydantic models
    converted, and a number that is not finite (an error no data bound, a predictor whose
    section left the image) written ``null``. Python's own ``Infinity`` and ``NaN`` are not
    JSON: JavaScript's and jq's parsers refuse the whole file on them."""
    return json.dumps(_finite(data), indent=indent, allow_nan=False)


def _finite(obj: Any) -> Any:
    """``obj`` with every non-finite float made None and every other value JSON knows."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if obj is None or isinstance(obj, (str, bool, int)):
        return obj
    if isinstance(obj, dict):
        return {_key(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.generic):
        return _finite(obj.item())
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "model_dump"):
        return _finite(obj.model_dump(mode="json"))
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def _key(key: Any) -> Any:
    """A mapping's key as JSON writes keys: numpy scalars as their Python value, a float that is
    not finite as its name (a key cannot be null)."""
    if isinstance(key, np.generic):
        key = key.item()
    if isinstance(key, float) and not math.isfinite(key):
        return str(key)
    if key is None or isinstance(key, (str, bool, int, float)):
        return key
    raise TypeError(f"cannot write a key of type {type(key).__name__} as JSON")
