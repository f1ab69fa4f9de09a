"""NIfTI, MetaImage (MHA/MHD) and NRRD through SimpleITK: 2D images, 3D sweeps, 2D+t cine loops.

Axis conventions: SimpleITK's array of an image of size ``(x, y, z[, t])`` is
``[t,] z, y, x``; rows are ``y`` and columns ``x``, so the pixel spacing is
``(spacing[1], spacing[0])``.

* 2D image → one frame.
* 3D image → a spatial sweep along ``z`` (slice positions ``origin_z + k·spacing_z``
  in mm), unless the caller asks for a cine loop or the file marks its third
  axis as time (NRRD ``kinds`` = ``time``), in which case ``spacing_z`` is the
  frame interval in seconds.
* 4D image with one ``z`` slice → a cine loop, frame interval from the fourth
  spacing, in the NIfTI time unit (``xyzt_units``: s, ms or µs).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import SimpleITK as sitk

from hifumotion.errors import InputError, brief
from hifumotion.io.grey import to_grey

# NIfTI-1 xyzt_units time codes → seconds per unit
_NIFTI_TIME_UNITS = {8: 1.0, 16: 1e-3, 24: 1e-6}


def _meta(image: sitk.Image, key: str) -> str | None:
    return image.GetMetaData(key) if image.HasMetaDataKey(key) else None


def _time_unit_s(image: sitk.Image) -> float:
    units = _meta(image, "xyzt_units")
    if units is None:
        return 1.0
    return _NIFTI_TIME_UNITS.get(int(units) & 0x38, 1.0)


def _third_axis_is_time(image: sitk.Image) -> bool:
    kind = _meta(image, "NRRD_kinds[2]")
    return kind is not None and kind.strip().lower() == "time"


def read_itk_file(path: Path, kind: str = "auto") -> dict[str, Any]:
    """Read a NIfTI/MHA/MHD/NRRD file into the fields of an :class:`ImageSequence`.

    ``kind`` is ``"auto"``, ``"cine"`` or ``"sweep"`` and only matters for 3D files.
    """
    try:
        image = sitk.ReadImage(str(path))
    except Exception as exc:
        raise InputError(f"cannot read as a NIfTI/MHA/NRRD image ({brief(exc)})", path) from None
    dim = image.GetDimension()
    array = sitk.GetArrayFromImage(image)
    array = to_grey(array, image.GetNumberOfComponentsPerPixel() in (3, 4))
    spacing = image.GetSpacing()
    origin = image.GetOrigin()
    meta: dict[str, Any] = {"format": image.GetMetaData("ITK_InputFilterName") if image.HasMetaDataKey("ITK_InputFilterName") else "ITK",
                            "dimension": dim, "origin_mm": list(origin)}
    out: dict[str, Any] = {"spacing_mm": (spacing[1], spacing[0]), "frame_interval_s": None,
                           "slice_positions_mm": None, "metadata": meta}
    if image.GetNumberOfComponentsPerPixel() not in (1, 3, 4):
        raise InputError(f"expected grey or RGB pixels, got {image.GetNumberOfComponentsPerPixel()} components", path)
    if dim == 2:
        array = array[None]
    elif dim == 3:
        as_cine = kind == "cine" or (kind == "auto" and _third_axis_is_time(image))
        if as_cine:
            out["frame_interval_s"] = float(spacing[2]) * _time_unit_s(image)
        else:
            out["slice_positions_mm"] = origin[2] + spacing[2] * np.arange(array.shape[0])
    elif dim == 4:
        if array.shape[1] != 1:
            raise InputError(f"a 3D+t volume ({array.shape[1]} slices per time point) is not a 2D sequence; "
                             "expected a 4D image with one slice", path)
        array = array[:, 0]
        out["frame_interval_s"] = float(spacing[3]) * _time_unit_s(image)
    else:
        raise InputError(f"expected a 2D, 3D or 2D+t image, got {dim} dimensions", path)
    out["array"] = array
    out["value_range"] = (0.0, 255.0) if array.dtype == np.uint8 else None
    return out
