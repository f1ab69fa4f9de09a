"""The image sequence: the one container every reader returns and every stage takes.

A single B-mode image is a sequence of one frame. A cine loop has a frame
interval in seconds; a spatial sweep (parallel planes through the tissue) has
slice positions in mm instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from hifumotion.errors import InputError


#: the pixel sizes an image may have (mm): 0.1 µm (below any ultrasound microscope's) to 10 cm
PIXEL_MM_RANGE = (1e-4, 100.0)


def as_spacing_mm(spacing: float | tuple[float, float] | np.ndarray | None, what: str = "spacing_mm") -> tuple[float, float]:
    """Return a pixel spacing as ``(row_mm, col_mm)``; a scalar means square pixels.

    ``None`` gives ``(1.0, 1.0)`` (one pixel = one unit). Raises :class:`InputError`
    for anything that is not one or two finite numbers within :data:`PIXEL_MM_RANGE` (a
    spacing of 10⁻³⁰⁰ mm is a typing mistake, and its pixel counts overflow downstream).
    """
    if spacing is None:
        return (1.0, 1.0)
    values = np.atleast_1d(np.asarray(spacing, dtype=float)).ravel()
    if values.size == 1:
        values = np.repeat(values, 2)
    if values.size != 2 or not np.all(np.isfinite(values)) or np.any(values <= 0):
        raise InputError(f"expected one or two positive pixel sizes in mm (row, col), got {spacing!r}", what)
    lo, hi = PIXEL_MM_RANGE
    if np.any(values < lo) or np.any(values > hi):
        raise InputError(f"expected pixel sizes of {lo:g} … {hi:g} mm, got {spacing!r}", what)
    return (float(values[0]), float(values[1]))


@dataclass
class ImageSequence:
    """A sequence of grey-level frames with their geometry.

    Attributes
    ----------
    frames
        float32 array ``(T, H, W)``, intensities scaled to [0, 1].
    spacing_mm
        Pixel size ``(row, col)`` in mm.
    frame_interval_s
        Time between consecutive frames in seconds; ``None`` for a spatial sweep
        or a single image.
    slice_positions_mm
        For a spatial sweep: the position of each frame's plane along the sweep
        axis in mm, shape ``(T,)``; ``None`` otherwise.
    spacing_known
        False when the source carried no pixel size and none was given, so
        ``spacing_mm`` is the placeholder ``(1, 1)`` (one pixel = one unit).
    source
        Where the frames came from (a path, or a short description).
    metadata
        What the reader found worth keeping (modality, device, original dtype ...).
    """

    frames: np.ndarray
    spacing_mm: tuple[float, float] = (1.0, 1.0)
    frame_interval_s: float | None = None
    slice_positions_mm: np.ndarray | None = None
    spacing_known: bool = True
    source: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        frames = np.asarray(self.frames)
        if frames.ndim == 2:
            frames = frames[None]
        if frames.ndim != 3 or min(frames.shape) == 0:
            raise InputError(f"expected frames of shape (T, H, W), got {frames.shape}", self.source or None)
        frames = frames.astype(np.float32, copy=False)
        if not np.all(np.isfinite(frames)):
            raise InputError("frames contain NaN or infinite values", self.source or None)
        if frames.min() < 0.0 or frames.max() > 1.0:
            raise InputError(
                f"frames must be scaled to [0, 1], got [{frames.min():.4g}, {frames.max():.4g}]; "
                "use ImageSequence.from_array to scale raw intensities",
                self.source or None,
            )
        self.frames = frames
        self.spacing_mm = as_spacing_mm(self.spacing_mm)
        if self.frame_interval_s is not None:
            dt = float(self.frame_interval_s)
            if not np.isfinite(dt) or dt <= 0:
                raise InputError(f"frame interval must be a positive number of seconds, got {self.frame_interval_s!r}", self.source or None)
            self.frame_interval_s = dt
        if self.slice_positions_mm is not None:
            pos = np.asarray(self.slice_positions_mm, dtype=float).ravel()
            if pos.shape != (frames.shape[0],):
                raise InputError(
                    f"expected {frames.shape[0]} slice positions (one per frame), got {pos.size}", self.source or None
                )
            if not np.all(np.isfinite(pos)):
                raise InputError("slice positions must be finite", self.source or None)
            self.slice_positions_mm = pos

    @classmethod
    def from_array(
        cls,
        array: np.ndarray,
        *,
        spacing_mm: float | tuple[float, float] | None = None,
        frame_interval_s: float | None = None,
        slice_positions_mm: np.ndarray | None = None,
        source: str = "",
        metadata: dict[str, Any] | None = None,
        value_range: tuple[float, float] | None = None,
    ) -> "ImageSequence":
        """Build a sequence from raw intensities of any dtype.

        Intensities are scaled to [0, 1] by :func:`scale_intensities` (the full
        range of an unsigned integer type, else the sequence's own min-max), one
        scale for the whole sequence so frames stay comparable.
        """
        frames = np.asarray(array)
        if frames.ndim == 2:
            frames = frames[None]
        if frames.ndim != 3 or min(frames.shape) == 0:
            raise InputError(f"expected one image or a stack of images, got an array of shape {frames.shape}")
        if not np.issubdtype(frames.dtype, np.number) and frames.dtype != np.bool_:
            raise InputError(f"expected numeric pixel values, got {frames.dtype}")
        if np.issubdtype(frames.dtype, np.floating) or np.issubdtype(frames.dtype, np.complexfloating):
            bad = ~np.isfinite(frames)
            if bad.any():
                raise InputError(f"{int(bad.sum())} pixel(s) are NaN or infinite; expected finite intensities")
        return cls(
            frames=scale_intensities(frames, value_range=value_range),
            spacing_mm=as_spacing_mm(spacing_mm),
            frame_interval_s=frame_interval_s,
            slice_positions_mm=slice_positions_mm,
            spacing_known=spacing_mm is not None,
            source=source,
            metadata=dict(metadata or {}),
        )

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """Frame size ``(H, W)`` in pixels."""
        return (int(self.frames.shape[1]), int(self.frames.shape[2]))

    @property
    def kind(self) -> str:
        """``"image"``, ``"cine"`` (has a frame interval), ``"sweep"`` (has slice positions) or ``"stack"``."""
        if self.n_frames == 1 and self.slice_positions_mm is None:
            return "image"
        if self.slice_positions_mm is not None:
            return "sweep"
        if self.frame_interval_s is not None:
            return "cine"
        return "stack"

    @property
    def times_s(self) -> np.ndarray | None:
        """Acquisition time of each frame in seconds from the first, or ``None`` without a frame interval."""
        if self.frame_interval_s is None:
            return None
        return np.arange(self.n_frames) * self.frame_interval_s

    @property
    def extent_mm(self) -> tuple[float, float]:
        """Field of view ``(height, width)`` in mm."""
        return (self.shape[0] * self.spacing_mm[0], self.shape[1] * self.spacing_mm[1])

    def frame(self, index: int) -> np.ndarray:
        """Frame ``index`` as a float32 ``(H, W)`` array in [0, 1]."""
        return self.frames[index]

    def subset(self, indices) -> "ImageSequence":
        """A new sequence with the frames ``indices`` (a slice or integer array), geometry kept."""
        idx = np.arange(self.n_frames)[indices]
        idx = np.atleast_1d(idx)
        positions = None if self.slice_positions_mm is None else self.slice_positions_mm[idx]
        interval = self.frame_interval_s
        if interval is not None and idx.size > 1:
            steps = np.unique(np.diff(idx))
            interval = interval * float(steps[0]) if steps.size == 1 else None
        return replace(self, frames=self.frames[idx], slice_positions_mm=positions, frame_interval_s=interval)

    def describe(self) -> dict[str, Any]:
        """A JSON-ready summary: what ``hifumotion info`` prints."""
        out: dict[str, Any] = {
            "source": self.source,
            "kind": self.kind,
            "frames": self.n_frames,
            "height_px": self.shape[0],
            "width_px": self.shape[1],
            "spacing_mm": list(self.spacing_mm) if self.spacing_known else None,
            "field_of_view_mm": [round(v, 4) for v in self.extent_mm] if self.spacing_known else None,
            "frame_interval_s": self.frame_interval_s,
            "frame_rate_hz": None if self.frame_interval_s is None else 1.0 / self.frame_interval_s,
        }
        if self.slice_positions_mm is not None:
            pos = self.slice_positions_mm
            out["slice_positions_mm"] = {"first": float(pos[0]), "last": float(pos[-1]), "count": int(pos.size)}
        out["intensity"] = {
            "min": float(self.frames.min()),
            "max": float(self.frames.max()),
            "mean": float(self.frames.mean()),
        }
        out["metadata"] = {k: v for k, v in self.metadata.items() if isinstance(v, (str, int, float, bool)) or v is None}
        return out


def scale_intensities(frames: np.ndarray, value_range: tuple[float, float] | None = None) -> np.ndarray:
    """Scale raw intensities to float32 in [0, 1] with one linear map for all frames.

    ``value_range=(lo, hi)`` maps lo→0 and hi→1 (values outside are clipped).
    Without it: unsigned 8-bit data use 0–255 (so a B-mode grey level keeps its
    meaning); bool uses 0–1; every other dtype its own min–max. A constant
    sequence becomes all zeros.
    """
    frames = np.asarray(frames)
    if value_range is None:
        if frames.dtype == np.bool_:
            value_range = (0.0, 1.0)
        elif frames.dtype == np.uint8:
            value_range = (0.0, 255.0)
        else:
            finite = frames[np.isfinite(frames)] if np.issubdtype(frames.dtype, np.floating) else frames
            if finite.size == 0:
                raise InputError("image has no finite pixel values")
            value_range = (float(finite.min()), float(finite.max()))
    lo, hi = float(value_range[0]), float(value_range[1])
    out = frames.astype(np.float32)
    if hi <= lo:
        return np.zeros_like(out)
    out = (out - np.float32(lo)) / np.float32(hi - lo)
    np.clip(out, 0.0, 1.0, out=out)
    return out
