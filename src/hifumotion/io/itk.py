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


def _nifti_dims_bytes(path: Path) -> tuple[np.ndarray, np.ndarray, int] | None:
    """``dim``, ``pixdim`` and the byte count a NIfTI-1 file's header promises (single file
    ``.nii``/``.nii.gz``), or None when it is not one."""
    import gzip

    opener = gzip.open if path.name.lower().endswith(".gz") else open
    try:
        with opener(path, "rb") as fh:
            header = fh.read(348)
    except (OSError, EOFError):
        return None
    if len(header) < 348:
        return None
    for order in ("<", ">"):
        if int(np.frombuffer(header[:4], f"{order}i4")[0]) == 348:
            break
    else:
        return None
    if header[344:347] not in (b"n+1", b"ni1"):
        return None
    dim = np.frombuffer(header[40:56], f"{order}i2").astype(int)
    pixdim = np.frombuffer(header[76:108], f"{order}f4").astype(float)
    bitpix = int(np.frombuffer(header[72:74], f"{order}i2")[0])
    offset = int(np.frombuffer(header[108:112], f"{order}f4")[0])
    n = int(np.prod(np.maximum(dim[1:1 + max(min(dim[0], 7), 0)], 1)))
    return dim, pixdim, (max(offset, 352) + n * bitpix // 8) if header[344:347] == b"n+1" else -1


def _file_bytes(path: Path, limit: int) -> int:
    """Bytes in ``path`` after decompression (counted up to ``limit``)."""
    import gzip

    if not path.name.lower().endswith(".gz"):
        return path.stat().st_size
    total = 0
    try:
        with gzip.open(path, "rb") as fh:
            while total < limit:
                # small reads: a truncated stream raises on the read that meets its end, and what
                # the reads before it gave is what the file holds
                chunk = fh.read(1 << 16)
                if not chunk:
                    break
                total += len(chunk)
    except (OSError, EOFError):
        pass
    return total


def check_nifti(path: Path) -> None:
    """Refuse a NIfTI file whose header and data disagree: a non-positive voxel size (ITK
    would take its absolute value from the orientation matrix, silently) or fewer bytes than
    the header promises (a truncated file, which would read as zeros)."""
    facts = _nifti_dims_bytes(path)
    if facts is None:
        return
    dim, pixdim, expected = facts
    ndim = int(dim[0])
    if not 1 <= ndim <= 7:
        raise InputError(f"NIfTI header: dim[0] = {ndim}; expected 1 … 7 dimensions", path)
    sizes = pixdim[1:1 + ndim]
    if np.any(~np.isfinite(sizes)) or np.any(sizes[: min(ndim, 3)] <= 0):
        raise InputError(f"NIfTI header: voxel sizes (pixdim) {sizes.round(6).tolist()}; expected positive numbers", path)
    if expected > 0:
        found = _file_bytes(path, expected)
        if found < expected:
            raise InputError(f"truncated: the header promises {expected} bytes, the file holds {found}", path)


#: Bytes per element of MetaImage's and NRRD's element types.
_META_BYTES = {"MET_UCHAR": 1, "MET_CHAR": 1, "MET_USHORT": 2, "MET_SHORT": 2, "MET_UINT": 4, "MET_INT": 4,
               "MET_ULONG": 8, "MET_LONG": 8, "MET_ULONG_LONG": 8, "MET_LONG_LONG": 8, "MET_FLOAT": 4,
               "MET_DOUBLE": 8}
_NRRD_BYTES = {**{t: 1 for t in ("uchar", "signed char", "unsigned char", "uint8", "int8", "uint8_t", "int8_t")},
               **{t: 2 for t in ("short", "ushort", "unsigned short", "int16", "uint16", "int16_t", "uint16_t",
                                 "short int", "signed short", "unsigned short int")},
               **{t: 4 for t in ("int", "uint", "unsigned int", "int32", "uint32", "int32_t", "uint32_t", "float",
                                 "signed int")},
               **{t: 8 for t in ("double", "longlong", "ulonglong", "int64", "uint64", "int64_t", "uint64_t",
                                 "long long", "unsigned long long")}}


def _header_fields(path: Path, separator: str) -> dict[str, str]:
    """The ``key <separator> value`` lines of a text header (its first 64 kB), keys lower-case."""
    try:
        with open(path, "rb") as fh:
            text = fh.read(1 << 16).decode("latin-1")
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", path) from None
    fields = {}
    for line in text.splitlines():
        if separator in line and not line.startswith("#"):
            key, value = line.split(separator, 1)
            fields.setdefault(key.strip().lower(), value.strip())
    return fields


def check_detached_data(path: Path) -> None:
    """Refuse a MetaImage (``.mhd``) or NRRD (``.nhdr``) header whose data file is not a
    regular file (``/dev/urandom``, a FIFO: endless or blocking reads) or does not hold the
    bytes the header describes (another file of the system read as pixels). Compressed data
    is checked by kind only: its size is not known before it is decompressed."""
    from hifumotion.io.files import require_regular_file

    name = path.name.lower()
    if name.endswith(".mhd"):
        fields = _header_fields(path, "=")
        data = fields.get("elementdatafile")
        if data is None or data.upper() == "LOCAL" or data.upper().startswith("LIST") or "%" in data:
            return      # data inline, or a list of slice files (each read by ITK as named)
        try:
            dims = [int(x) for x in fields.get("dimsize", "").split()]
            element = _META_BYTES[fields.get("elementtype", "").upper()]
            channels = int(fields.get("elementnumberofchannels", "1"))
            skip = int(fields.get("headersize", "0"))
        except (KeyError, ValueError):
            raise InputError("MetaImage header: expected DimSize, a known ElementType and whole numbers", path) from None
        compressed = fields.get("compresseddata", "false").lower() == "true"
    elif name.endswith(".nhdr"):
        fields = _header_fields(path, ":")
        data = fields.get("data file", fields.get("datafile"))
        if data is None or data.upper().startswith("LIST") or len(data.split()) > 1:
            return
        try:
            dims = [int(x) for x in fields.get("sizes", "").split()]
            element = _NRRD_BYTES[" ".join(fields.get("type", "").lower().split())]
            channels = 1
            skip = int(fields.get("byte skip", fields.get("byteskip", "0")))
            if int(fields.get("line skip", fields.get("lineskip", "0"))) != 0:
                skip = -1
        except (KeyError, ValueError):
            raise InputError("NRRD header: expected sizes, a known type and whole numbers", path) from None
        compressed = fields.get("encoding", "raw").lower() not in ("raw",)
    else:
        return
    target = Path(data)
    if not target.is_absolute():
        target = path.parent / target
    require_regular_file(target, f"data file named by {path.name}")
    if compressed or not dims or min(dims) < 1:
        return
    expected = int(np.prod(dims, dtype=np.int64)) * element * max(channels, 1)
    size = target.stat().st_size
    ok = size >= expected if skip < 0 else size == expected + skip
    if not ok:
        raise InputError(f"its data file {target} holds {size} bytes; the header describes {expected + max(skip, 0)}"
                         " (not this image's pixels?)", path)


def read_itk_file(path: Path, kind: str = "auto") -> dict[str, Any]:
    """Read a NIfTI/MHA/MHD/NRRD file into the fields of an :class:`ImageSequence`.

    ``kind`` is ``"auto"``, ``"cine"`` or ``"sweep"`` and only matters for 3D files.
    """
    if path.name.lower().endswith((".nii", ".nii.gz")):
        check_nifti(path)
    check_detached_data(path)
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
