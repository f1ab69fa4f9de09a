"""PNG, JPEG, BMP and TIFF: single images, multi-page TIFF, and folders of frames."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tifffile

from hifumotion.errors import InputError, brief
from hifumotion.io.grey import has_channels, to_grey
from hifumotion.io.naming import RASTER_SUFFIXES, full_suffix, natural_key


def _grey_page(page: np.ndarray) -> np.ndarray:
    return to_grey(page, has_channels(page, 2))


def _read_tiff(path: Path) -> np.ndarray:
    """Frames ``(T, H, W)`` of a (multi-page) TIFF, using tifffile's axis labels.

    ``S`` is the colour-sample axis (turned into grey), ``Y``/``X`` the image
    plane; every other axis (pages, time, depth …) is flattened into frames. A file
    whose pages were written one by one holds one series per page: every series is
    read, in order, and they must share one image size (a page of another size is no
    frame of the same cine, and dropping it silently would lose the user's data).
    """
    with tifffile.TiffFile(path) as tif:
        series = [(s.asarray(), s.axes) for s in tif.series]
    frames = [_tiff_frames(data, axes, path) for data, axes in series]
    shapes = sorted({f.shape[-2:] for f in frames})
    if len(shapes) > 1:
        raise InputError(f"its {len(frames)} image series have different sizes "
                         f"({', '.join(f'{h}×{w}' for h, w in shapes)} px); expected frames of one size", path)
    return np.concatenate(frames) if len(frames) > 1 else frames[0]


def _tiff_frames(data: np.ndarray, axes: str, path: Path) -> np.ndarray:
    """One TIFF series as grey frames ``(T, H, W)``."""
    if "S" in axes:
        data = to_grey(np.moveaxis(data, axes.index("S"), -1), True)
        axes = axes.replace("S", "")
    if not axes.endswith("YX"):
        raise InputError(f"unexpected TIFF axes {axes!r}", path)
    return data.reshape((-1,) + data.shape[-2:])


def read_raster_array(path: Path) -> np.ndarray:
    """Grey frames ``(T, H, W)`` of one image file, in the file's own dtype."""
    from hifumotion.io.files import require_regular_file

    require_regular_file(path, "image file")      # a FIFO among the frames would block the read for ever
    suffix = full_suffix(path)
    try:
        if suffix in (".tif", ".tiff"):
            array = _read_tiff(path)
        else:
            image = iio.imread(path)
            array = _grey_page(image)[None]
    except InputError:
        raise
    except Exception as exc:  # the libraries raise many types for a corrupt file
        raise InputError(f"cannot read as an image ({brief(exc)})", path) from None
    if array.ndim != 3:
        raise InputError(f"expected a 2D grey or colour image, got pixel array of shape {array.shape}", path)
    return array


def raster_files(folder: Path) -> list[Path]:
    """The image files of ``folder`` in natural order (``frame_2`` before ``frame_10``)."""
    files = [p for p in folder.iterdir() if p.is_file() and full_suffix(p) in RASTER_SUFFIXES and not p.name.startswith(".")]
    return sorted(files, key=natural_key)


def read_raster_folder(folder: Path) -> tuple[np.ndarray, list[Path]]:
    """Stack every image of ``folder`` (natural order) into ``(T, H, W)``; all must share one size."""
    files = raster_files(folder)
    if not files:
        raise InputError("folder holds no PNG, JPEG, BMP or TIFF images", folder)
    frames = [read_raster_array(f) for f in files]
    shape = frames[0].shape[1:]
    for f, fr in zip(files, frames):
        if fr.shape[1:] != shape:
            raise InputError(f"frame size {fr.shape[1:]} differs from {shape} of {files[0].name}", f)
    return np.concatenate(frames), files
