"""``read_sequence``: one entry point for every supported format."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from hifumotion.errors import InputError
from hifumotion.io.files import require_regular_file
from hifumotion.io.naming import ITK_SUFFIXES, RASTER_SUFFIXES, VIDEO_SUFFIXES, full_suffix, looks_like_dicom
from hifumotion.sequence import ImageSequence, as_spacing_mm

Kind = Literal["auto", "cine", "sweep"]

SUPPORTED = ("PNG/JPEG/BMP/TIFF (file or folder of frames), DICOM (file or folder), "
             "NIfTI (.nii, .nii.gz), MetaImage (.mha, .mhd), NRRD (.nrrd, .nhdr), video (.mp4, .avi, .mov, .mkv, .gif)")


def _read_fields(path: Path, kind: Kind) -> dict[str, Any]:
    from hifumotion.io import dicom, itk, raster, video  # imported on use: each pulls a heavy library

    if path.is_dir():
        if any(looks_like_dicom(p) for p in path.iterdir() if p.is_file()):
            return dicom.read_dicom_folder(path)
        array, files = raster.read_raster_folder(path)
        return {"array": array, "value_range": None if array.dtype != "uint8" else (0.0, 255.0),
                "spacing_mm": None, "frame_interval_s": None, "slice_positions_mm": None,
                "metadata": {"format": "image folder", "files": [f.name for f in files][:5] + (["…"] if len(files) > 5 else [])}}
    suffix = full_suffix(path)
    if suffix in ITK_SUFFIXES:
        return itk.read_itk_file(path, kind)
    if suffix in VIDEO_SUFFIXES:
        return video.read_video_file(path)
    if suffix in RASTER_SUFFIXES:
        array = raster.read_raster_array(path)
        return {"array": array, "value_range": None if array.dtype != "uint8" else (0.0, 255.0),
                "spacing_mm": None, "frame_interval_s": None, "slice_positions_mm": None,
                "metadata": {"format": suffix.lstrip(".").upper()}}
    if looks_like_dicom(path):
        return dicom.read_dicom_file(path)
    raise InputError(f"unsupported format '{suffix or 'no suffix'}'; expected {SUPPORTED}", path)


def read_sequence(
    path: str | Path,
    spacing_mm: float | tuple[float, float] | None = None,
    frame_interval_s: float | None = None,
    *,
    kind: Kind = "auto",
    slice_positions_mm=None,
) -> ImageSequence:
    """Read images from any supported file or folder as an :class:`ImageSequence`.

    Parameters
    ----------
    path
        A file (PNG/JPEG/TIFF, DICOM, NIfTI/MHA/NRRD, video) or a folder of
        image frames (natural order) or of DICOM files (one series).
    spacing_mm
        Pixel size in mm, scalar or ``(row, col)``. Overrides what the file says;
        needed for formats that carry none (PNG, video).
    frame_interval_s
        Time between frames in seconds. Overrides the file; given for a 3D
        NIfTI/MHA/NRRD it also makes the third axis time.
    kind
        ``"cine"`` or ``"sweep"`` to say how to read the third axis of a 3D
        volume file; ``"auto"`` reads it as a sweep unless the file marks it as time.
    slice_positions_mm
        Positions of the planes of a sweep in mm (overrides the file), e.g. for a
        folder of PNG slices.

    Returns
    -------
    ImageSequence
        Frames in [0, 1] as float32 ``(T, H, W)``, with spacing, frame interval
        or slice positions, ``spacing_known`` and the source's metadata.

    Raises
    ------
    InputError
        Missing file, unsupported or corrupt format, no pixel data, bad spacing.
    """
    p = Path(path)
    if not p.exists():
        raise InputError("no such file or folder", p)
    if not p.is_dir():
        require_regular_file(p, "image file")
    if kind not in ("auto", "cine", "sweep"):
        raise InputError(f"kind must be 'auto', 'cine' or 'sweep', got {kind!r}", "kind")
    user_spacing = None if spacing_mm is None else as_spacing_mm(spacing_mm, "spacing_mm")
    if frame_interval_s is not None and kind == "auto":
        kind = "cine"
    fields = _read_fields(p, kind)
    spacing = user_spacing or fields["spacing_mm"]
    interval = frame_interval_s if frame_interval_s is not None else fields["frame_interval_s"]
    positions = slice_positions_mm if slice_positions_mm is not None else fields["slice_positions_mm"]
    if kind == "sweep" and positions is None:
        raise InputError("read as a sweep, but the file gives no slice positions; pass slice_positions_mm", p)
    try:
        return ImageSequence.from_array(
            fields["array"],
            spacing_mm=spacing,
            frame_interval_s=interval,
            slice_positions_mm=positions,
            source=str(p),
            metadata=fields["metadata"],
            value_range=fields["value_range"],
        )
    except InputError as exc:
        raise InputError(exc.reason, p) from None
