"""Video files (MP4, AVI, MOV, MKV …) through imageio's PyAV plugin.

A video has no pixel size: the user gives it (``spacing_mm``). The frame
interval comes from the container's frame rate.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np

from hifumotion.errors import InputError, brief
from hifumotion.io.grey import has_channels, to_grey
from hifumotion.io.naming import full_suffix


def read_video_file(path: Path) -> dict[str, Any]:
    """Every frame of a video as grey ``(T, H, W)`` uint8, with its frame interval."""
    plugin = None if full_suffix(path) == ".gif" else "pyav"
    try:
        frames = iio.imread(path, plugin=plugin) if plugin else iio.imread(path, index=None)
        meta = iio.immeta(path, plugin=plugin) if plugin else iio.immeta(path)
    except Exception as exc:
        raise InputError(f"cannot read as a video ({brief(exc)})", path) from None
    frames = np.asarray(frames)
    if frames.ndim == 2 or (frames.ndim == 3 and has_channels(frames, 2)):
        frames = frames[None]
    frames = to_grey(frames, has_channels(frames, 3))
    fps = meta.get("fps")
    interval = None
    if fps:
        interval = 1.0 / float(fps)
    elif meta.get("duration"):  # GIF: per-frame duration in ms
        interval = float(meta["duration"]) / 1000.0
    info = {"format": "video", "codec": meta.get("codec"), "fps": fps}
    return {"array": frames, "value_range": (0.0, 255.0) if frames.dtype == np.uint8 else None,
            "spacing_mm": None, "frame_interval_s": interval, "slice_positions_mm": None, "metadata": info}
