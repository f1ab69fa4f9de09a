"""Reader of the real tongue cine development set (``shared/data/tongue``), for the benchmarks only.

Each clip folder holds ``frames/frame_NNNN.png`` (8-bit grey, consecutive), ``stats.json``
(``fps``, ``labeled_frames``) and ``annotations_points.csv`` (``frame, source_frame, keypoint, x,
y``; pixels, origin top-left, integer = pixel centre). Pixel spacing is unknown: everything here
is in pixels. The reader lives beside the benchmarks, not in the package: the package reads a
user's cine through :mod:`hifumotion.sequence`; this set's label format is its own.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The tongue surface, root → tip (an open curve).
TONGUE = ("vallecula", "tongueRoot1", "tongueRoot2", "tongueBody1", "tongueBody2", "tongueDorsum1",
          "tongueDorsum2", "tongueBlade1", "tongueBlade2", "tongueTip1", "tongueTip2")
#: Anatomical landmarks (the thyroid only in swallow clips).
LANDMARKS = ("hyoid", "mandible", "shortTendon", "thyroid1")

#: Where the set lies relative to this checkout.
DEFAULT_ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "tongue"


@dataclass
class Clip:
    """One cine loop with its human keypoints.

    ``frames``: uint8 ``(T, H, W)``; ``fps``: frames per second; ``labels``: keyframe →
    keypoint name → ``(x, y)`` px.
    """

    name: str
    frames: np.ndarray
    fps: float
    labels: dict[int, dict[str, tuple[float, float]]]

    @property
    def keyframes(self) -> list[int]:
        return sorted(self.labels)

    def tongue_line(self, frame: int) -> np.ndarray:
        """The labelled tongue surface at ``frame``: ``(M, 2)`` px, root → tip, the points present."""
        lab = self.labels[frame]
        return np.array([lab[k] for k in TONGUE if k in lab], float).reshape(-1, 2)


def clip_names(root: Path = DEFAULT_ROOT) -> list[str]:
    return sorted(p.name for p in Path(root).iterdir() if (p / "annotations_points.csv").is_file())


def load_clip(folder: Path) -> Clip:
    import cv2

    folder = Path(folder)
    stats = json.loads((folder / "stats.json").read_text())
    paths = sorted((folder / "frames").glob("frame_*.png"))
    frames = np.stack([cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in paths])
    labels: dict[int, dict[str, tuple[float, float]]] = {}
    with open(folder / "annotations_points.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            labels.setdefault(int(row["frame"]), {})[row["keypoint"]] = (float(row["x"]), float(row["y"]))
    return Clip(folder.name, frames, float(stats["fps"]), labels)


def load_clips(root: Path = DEFAULT_ROOT, names: list[str] | None = None) -> list[Clip]:
    root = Path(root)
    return [load_clip(root / n) for n in (names or clip_names(root))]


def point_to_polyline_px(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance (px) from each of ``points`` ``(N, 2)`` to the open polyline ``line`` ``(M ≥ 2, 2)``."""
    p = np.asarray(points, float)[:, None, :]
    a, b = line[:-1][None], line[1:][None]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    nearest = a + t[..., None] * ab
    return np.sqrt(((p - nearest) ** 2).sum(-1)).min(axis=1)
