"""Read an ``observed/`` folder: what a HIFU device's user has, and nothing of the truth.

The layout :func:`~hifumotion.experiment.generate_twin` writes (and a user can
assemble from a real device): ``setup.json`` (image geometry in the tank frame,
frame interval, pool, bar), ``sweep/slice_NNN.png`` with ``sweep_positions.csv``,
``frames/frame_NNNN.png`` and ``initial_contour.csv``. Lengths in mm, times in s.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hifumotion.contour import Contour
from hifumotion.errors import InputError


@dataclass
class Observed:
    """An observed experiment.

    Attributes
    ----------
    sweep
        ``(S, H, W)`` uint8 B-mode images of parallel planes through the resting tissue.
    sweep_z_mm
        ``(S,)`` plane positions (mm, along the tank's z).
    frames
        ``(T, H, W)`` uint8 B-mode frames of the imaging plane during the push.
    frame_interval_s
        Time between frames (s).
    pixel_mm
        Square pixel size (mm).
    initial_contour
        The clinician's contour on frame ``initial_frame``.
    setup
        The rest of ``setup.json`` (plane placement, pool, bar).
    """

    sweep: np.ndarray
    sweep_z_mm: np.ndarray
    frames: np.ndarray
    frame_interval_s: float
    pixel_mm: float
    initial_contour: Contour
    initial_frame: int
    setup: dict

    @property
    def times_s(self) -> np.ndarray:
        return np.arange(len(self.frames)) * self.frame_interval_s


def _stack(folder: Path, pattern: str) -> np.ndarray:
    from hifumotion.io.raster import read_raster_array

    files = sorted(folder.glob(pattern))
    if not files:
        raise InputError(f"no {pattern} images", folder)
    return np.stack([read_raster_array(p)[0] for p in files])


def load_observed(folder: str | Path) -> Observed:
    """Read ``folder`` (see the module docstring); a missing or malformed part is one clear error."""
    from hifumotion.io.writers import read_contours_csv

    root = Path(folder)
    setup_path = root / "setup.json"
    if not setup_path.is_file():
        raise InputError("not an observed experiment folder (no setup.json)", root)
    try:
        setup = json.loads(setup_path.read_text())
        pixel = float(setup["imaging"]["pixel_mm"])
        interval = float(setup["frame_interval_s"])
    except (KeyError, TypeError, ValueError, json.JSONDecodeError):
        raise InputError("expected imaging.pixel_mm and frame_interval_s", setup_path) from None
    sweep = _stack(root / "sweep", "slice_*.png")
    frames = _stack(root / "frames", "frame_*.png")
    pos_path = root / "sweep_positions.csv"
    if not pos_path.is_file():
        raise InputError("no such file", pos_path)
    with open(pos_path, newline="", encoding="utf-8") as fh:
        try:
            z = np.array([float(r["z_mm"]) for r in csv.DictReader(fh)])
        except (KeyError, ValueError):
            raise InputError("expected a z_mm column of numbers", pos_path) from None
    if len(z) != len(sweep):
        raise InputError(f"{len(z)} positions for {len(sweep)} sweep images", pos_path)
    contours = read_contours_csv(root / "initial_contour.csv", spacing_mm=pixel)
    label, contour = next(iter(contours.items()))
    return Observed(sweep, z, frames, interval, pixel, contour, int(float(label)), setup)
