"""File-name helpers shared by the readers."""

from __future__ import annotations

import re
from pathlib import Path

RASTER_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}
ITK_SUFFIXES = {".nii", ".nii.gz", ".mha", ".mhd", ".nrrd", ".nhdr"}
VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".m4v", ".wmv", ".gif"}
DICOM_SUFFIXES = {".dcm", ".dicom"}


def full_suffix(path: str | Path) -> str:
    """Lower-case suffix, keeping ``.nii.gz`` whole."""
    name = Path(path).name.lower()
    if name.endswith(".nii.gz"):
        return ".nii.gz"
    return Path(name).suffix


def natural_key(path: str | Path) -> list:
    """Sort key that orders ``frame_2`` before ``frame_10``."""
    parts = re.split(r"(\d+)", Path(path).name.lower())
    return [int(p) if p.isdigit() else p for p in parts]


def looks_like_dicom(path: str | Path) -> bool:
    """True for a ``.dcm`` name or a file with the DICOM preamble marker ``DICM`` at byte 128."""
    p = Path(path)
    if full_suffix(p) in DICOM_SUFFIXES:
        return True
    try:
        with open(p, "rb") as fh:
            fh.seek(128)
            return fh.read(4) == b"DICM"
    except OSError:
        return False
