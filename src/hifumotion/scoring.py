"""Score predicted contours against the truth, frame by frame: the paper's Table 4, extended.

Per frame: DSC (the paper's measure), the 95th-percentile Hausdorff distance and
the centroid error, both in mm — the centroid is where the HIFU focus would be
aimed, so its error is what a clinic feels. Frames are grouped into the
training set (the paper's frames 20, 30, …, 100) and the validation set
(110, 120, …, 190); each set gets its mean, min and max.

Masks are read as the paper's and ``../shared/data``'s layout: ``frames/frame_0110.png``
(0/255), matched by frame number.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hifumotion.errors import InputError
from hifumotion.io.structured import read_structured
from hifumotion.metrics import centroid_distance, dice, hausdorff

#: The paper's protocol (Section 3.2): ground truth every 10th frame from the 20th.
TRAINING_FRAMES = tuple(range(20, 101, 10))
VALIDATION_FRAMES = tuple(range(110, 191, 10))

_FRAME = re.compile(r"frame_(\d+)\.png$")


@dataclass
class ScoreTable:
    """Per-frame scores and their summaries by set."""

    rows: list[dict] = field(default_factory=list)

    def summary(self) -> dict:
        out = {}
        for name in ("training", "validation", "other"):
            rows = [r for r in self.rows if r["set"] == name]
            if not rows:
                continue
            s = {"frames": [r["frame"] for r in rows]}
            for key in ("dsc", "hd95_mm", "centroid_error_mm"):
                v = np.array([r[key] for r in rows], float)
                s[key] = {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())}
            out[name] = s
        return out

    def to_csv(self) -> str:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["frame", "set", "dsc", "hd95_mm", "centroid_error_mm"])
        for r in self.rows:
            w.writerow([r["frame"], r["set"], f"{r['dsc']:.5f}", f"{r['hd95_mm']:.4f}", f"{r['centroid_error_mm']:.4f}"])
        return buf.getvalue()


def score_masks(predicted: dict[int, np.ndarray], truth: dict[int, np.ndarray], spacing_mm,
                training=None, validation=None) -> ScoreTable:
    """Score every frame present in both (masks as bool arrays on the same grid).

    The sets default to the paper's frames (20, 30 … 100 and 110 … 190), scaled to the series'
    length when the truth holds a whole series 0 … n−1 (:func:`~hifumotion.estimation.protocol.default_frames`)."""
    from hifumotion.estimation.protocol import default_frames

    common = sorted(set(predicted) & set(truth))
    if not common:
        raise InputError("no frame number is in both the prediction and the truth")
    if training is None or validation is None:
        # a whole series (frames 0 … n−1) gets the protocol scaled to its length; sampled frames the paper's
        n = max(truth) + 1
        whole = len(truth) == n and n >= 20
        auto_train, auto_valid = default_frames(n) if whole else (TRAINING_FRAMES, VALIDATION_FRAMES)
        training = auto_train if training is None else training
        validation = auto_valid if validation is None else validation
    table = ScoreTable()
    for f in common:
        p, t = np.asarray(predicted[f], bool), np.asarray(truth[f], bool)
        if p.shape != t.shape:
            raise InputError(f"frame {f}: prediction {p.shape} and truth {t.shape} differ in size")
        empty = not p.any() or not t.any()
        table.rows.append({
            "frame": int(f),
            "set": "training" if f in training else "validation" if f in validation else "other",
            "dsc": dice(p, t),
            "hd95_mm": float("inf") if empty else hausdorff(p, t, spacing_mm, percentile=95),
            "centroid_error_mm": float("inf") if empty else centroid_distance(p, t, spacing_mm),
        })
    return table


def overlay_figure(images: dict[int, np.ndarray], truth: dict[int, np.ndarray], predicted: dict[int, np.ndarray],
                   frames, path: str | Path, columns: int = 5) -> Path:
    """The paper's Fig. 4: frames with the true (green) and predicted (red) contours, as a PNG,
    drawn as the frames' files show them (row 0 at the top)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hifumotion.io.files import atomic_path

    frames = [f for f in frames if f in images and f in truth and f in predicted]
    if not frames:
        raise InputError("no frame has an image, a true and a predicted mask", path)
    rows = (len(frames) + columns - 1) // columns
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 3.0 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for ax, f in zip(axes.ravel(), frames):
        ax.imshow(images[f], cmap="gray", origin="upper")
        ax.contour(truth[f], [0.5], colors="lime", linewidths=1.0)
        ax.contour(predicted[f], [0.5], colors="red", linewidths=1.0)
        ax.set_title(f"frame {f}  DSC {dice(predicted[f], truth[f]):.3f}", fontsize=9)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    return Path(path)


def read_frame_masks(folder: str | Path) -> dict[int, np.ndarray]:
    """``frame_NNNN.png`` masks of a folder (or of its ``frames/``), by frame number."""
    from hifumotion.io.writers import read_mask

    root = Path(folder)
    if (root / "frames").is_dir():
        root = root / "frames"
    if not root.is_dir():
        raise InputError("no such folder", folder)
    found = {int(m.group(1)): p for p in root.iterdir() if (m := _FRAME.search(p.name))}
    if not found:
        raise InputError("no frame_NNNN.png masks", root)
    return {k: read_mask(p) for k, p in sorted(found.items())}


def pixel_size_mm(truth_dir: str | Path) -> float:
    """The truth's pixel size (mm) from ``parameters.json`` next to its masks."""
    path = Path(truth_dir) / "parameters.json"
    if not path.is_file():
        raise InputError("no parameters.json to take the pixel size from; give --spacing", truth_dir)
    try:
        return float(read_structured(path, "json", "parameters.json")["config"]["imaging"]["pixel_mm"])
    except (KeyError, TypeError, ValueError):
        raise InputError("expected config.imaging.pixel_mm", path) from None
