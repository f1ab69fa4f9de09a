"""The twin's true motion in the imaging plane, for scoring a speckle tracker.

The truth of a tracked displacement is the particles' displacement carried to the
frame-0 pixels by the same interpolant that moved the speckle
(:class:`~hifumotion.experiment.imaging.PlaneInterpolant`): what the image's scatterers
really did. Only the scoring reads it (it needs ``truth/``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hifumotion.experiment.imaging import PlaneInterpolant
from hifumotion.observed import Setup


@dataclass
class TrueMotion:
    """The twin's true in-plane motion.

    Attributes
    ----------
    displacement_mm
        float32 ``(T, H, W, 2)``: (x, y) = (column, row) displacement in mm of each frame-0
        pixel inside the true frame-0 section; NaN elsewhere.
    masks
        bool ``(T, H, W)``: the true section of every frame.
    pixel_mm
        Pixel size in mm.
    """

    displacement_mm: np.ndarray
    masks: np.ndarray
    pixel_mm: float


def true_motion(positions_mm: np.ndarray, spacing_mm: float, setup: Setup, masks: np.ndarray) -> TrueMotion:
    """The true displacement of frame 0's tissue pixels at every frame.

    ``positions_mm``: ``(T, N, 3)`` tissue particles in the pool frame (the twin's
    ``tissue_trajectory.npz``), frame 0 being the rest; ``spacing_mm``: their spacing;
    ``masks``: ``(T, H, W)`` true sections.
    """
    masks = np.asarray(masks, bool)
    t_count, h, w = masks.shape
    im = setup.imaging
    px = im.pixel_mm
    rows, cols = np.nonzero(masks[0])
    x0, y0 = im.row0_col0_mm
    points = np.column_stack([x0 + cols * px, y0 + rows * px, np.full(rows.size, im.frames_plane_z_mm)])
    interp = PlaneInterpolant(np.asarray(positions_mm[0], float), spacing_mm, points, im.frames_plane_z_mm)
    out = np.full((t_count, h, w, 2), np.nan, np.float32)
    for t in range(t_count):
        out[t, rows, cols] = interp(np.asarray(positions_mm[t], float))
    return TrueMotion(out, masks, px)


def read_true_motion(twin_folder: str | Path) -> TrueMotion:
    """:func:`true_motion` of a twin folder (``observed/setup.json``, ``truth/tissue_trajectory.npz``,
    ``truth/frames/frame_NNNN.png``)."""
    from hifumotion.observed.setup import read_setup
    from hifumotion.scoring import read_frame_masks

    folder = Path(twin_folder)
    setup = read_setup(folder / "observed" / "setup.json")
    traj = np.load(folder / "truth" / "tissue_trajectory.npz")
    by_frame = read_frame_masks(folder / "truth")
    masks = np.stack([by_frame[k] for k in sorted(by_frame)])
    return true_motion(traj["positions_mm"], float(traj["spacing_mm"]), setup, masks)


__all__ = ["TrueMotion", "true_motion", "read_true_motion"]
