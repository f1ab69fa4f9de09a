"""The paper's Table 2 and Figures 2–3 on any dataset laid out like ``../shared/data/*``.

:func:`compare_methods` segments every image with every method from the same
initial contour and scores each result against the expert mask;
:func:`write_comparison` writes the CSV, a markdown table with the best value
per row in bold, a figure grid (image, initial contour, each method's contour
over the expert's) and a plot of the metrics.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from hifumotion.contour import ClickedPoints
from hifumotion.io.dataset import Dataset
from hifumotion.metrics import score

#: Metric columns, and whether larger is better.
METRICS = {"dsc": True, "mssd": False, "hausdorff": False, "hd95": False, "seconds": False}


@dataclass
class ComparisonRow:
    image: str
    method: str
    init_kind: str
    dsc: float
    mssd: float
    hausdorff: float
    hd95: float
    centroid_distance: float
    seconds: float
    iterations: int
    converged: bool


@dataclass
class Comparison:
    """Rows of scores plus what the figures need (images, masks, initial masks)."""

    rows: list[ComparisonRow]
    images: dict[str, np.ndarray]
    truths: dict[str, np.ndarray]
    inits: dict[str, np.ndarray]
    masks: dict[tuple[str, str], np.ndarray]
    methods: list[str]

    def mean(self, method: str, metric: str) -> float:
        values = [getattr(r, metric) for r in self.rows if r.method == method]
        return float(np.mean(values)) if values else float("nan")


def compare_methods(dataset: Dataset, methods: Sequence[str], init_kind: str = "ellipse",
                    progress: Callable | None = None) -> Comparison:
    """Segment every image of ``dataset`` with every method from the same initial contour and score it."""
    from hifumotion.io import read_mask, read_sequence
    from hifumotion.segmentation import segment

    rows, images, truths, inits, masks = [], {}, {}, {}, {}
    items = list(dataset)
    iterator = progress(items, f"segmenting ({init_kind} start)", total=len(items)) if progress else items
    for item in iterator:
        image = read_sequence(item.image_path).frames[0]
        truth = read_mask(item.mask_path)
        init = item.initial_contour(init_kind)
        images[item.name], truths[item.name] = image, truth
        inits[item.name] = init.to_mask(image.shape, smooth=True) if isinstance(init, ClickedPoints) else init.to_mask(image.shape)
        for method in methods:
            result = segment(image, init, method)
            s = score(result.mask, truth)
            masks[(item.name, method)] = result.mask
            rows.append(ComparisonRow(item.name, method, init_kind, s["dsc"], s["mssd"], s["hausdorff"], s["hd95"],
                                      s["centroid_distance"], result.seconds, result.iterations, result.converged))
    return Comparison(rows, images, truths, inits, masks, list(methods))


def _fmt(v: float) -> str:
    if not np.isfinite(v):
        return "inf"
    return f"{v:.3f}" if abs(v) < 10 else f"{v:.2f}"


def markdown_table(cmp: Comparison) -> str:
    """Table 2's layout: one row per image × metric, one column per method, best value in bold."""
    lines = ["| image | metric | " + " | ".join(m.upper() for m in cmp.methods) + " |",
             "| --- | --- | " + " | ".join("---:" for _ in cmp.methods) + " |"]
    by_key = {(r.image, r.method): r for r in cmp.rows}
    for image in cmp.images:
        for metric, larger in METRICS.items():
            if metric == "seconds":
                continue
            values = [getattr(by_key[(image, m)], metric) for m in cmp.methods]
            best = max(values) if larger else min(values)
            cells = [f"**{_fmt(v)}**" if v == best else _fmt(v) for v in values]
            lines.append(f"| {image} | {metric.upper()} | " + " | ".join(cells) + " |")
    for metric, larger in METRICS.items():
        means = [cmp.mean(m, metric) for m in cmp.methods]
        best = max(means) if larger else min(means)
        cells = [f"**{_fmt(v)}**" if v == best else _fmt(v) for v in means]
        lines.append(f"| mean | {metric.upper()} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def rows_csv(rows: Sequence[ComparisonRow]) -> str:
    buf = io.StringIO()
    fields = list(ComparisonRow.__dataclass_fields__)
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(fields)
    for r in rows:
        writer.writerow([getattr(r, f) if not isinstance(getattr(r, f), float) else f"{getattr(r, f):.6g}" for f in fields])
    return buf.getvalue()


def figure_grid(cmp: Comparison, path: Path, max_images: int = 6) -> Path:
    """Figure 2's layout: per image, the image with the initial contour, then each method's
    contour (red) over the expert's (green)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(cmp.images)[:max_images]
    cols = 1 + len(cmp.methods)
    fig, axes = plt.subplots(len(names), cols, figsize=(2.2 * cols, 2.2 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        img = cmp.images[name]
        for j in range(cols):
            ax = axes[i, j]
            ax.imshow(img, cmap="gray", vmin=0, vmax=1)
            ax.set_xticks([])
            ax.set_yticks([])
            if j == 0:
                ax.contour(cmp.inits[name], [0.5], colors="yellow", linewidths=1)
                ax.set_ylabel(name, fontsize=7)
                if i == 0:
                    ax.set_title("image + initial", fontsize=8)
                continue
            method = cmp.methods[j - 1]
            ax.contour(cmp.truths[name], [0.5], colors="lime", linewidths=1)
            mask = cmp.masks[(name, method)]
            if mask.any():
                ax.contour(mask, [0.5], colors="red", linewidths=1)
            if i == 0:
                ax.set_title(method.upper(), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def metrics_plot(cmp: Comparison, path: Path) -> Path:
    """Figure 3's layout: DSC, MSSD and Hausdorff per image, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(cmp.images)
    by_key = {(r.image, r.method): r for r in cmp.rows}
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    for ax, metric in zip(axes, ("dsc", "mssd", "hausdorff")):
        for method in cmp.methods:
            values = [getattr(by_key[(n, method)], metric) for n in names]
            style = dict(color="red", linewidth=2.2) if method == "glcv" else dict(linewidth=1)
            ax.plot(range(len(names)), values, marker="o", markersize=3, label=method.upper(), **style)
        ax.set_title(metric.upper())
        ax.set_xlabel("image")
        if metric == "mssd":
            ax.set_yscale("log")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_comparison(cmp: Comparison, folder: Path, tag: str = "") -> dict[str, Path]:
    """Write ``comparison{tag}.csv``, ``table2{tag}.md``, ``figure2{tag}.png``, ``figure3{tag}.png``."""
    from hifumotion.io import write_text

    folder = Path(folder)
    out = {
        "csv": write_text(folder / f"comparison{tag}.csv", rows_csv(cmp.rows)),
        "table": write_text(folder / f"table2{tag}.md", markdown_table(cmp)),
    }
    out["figure2"] = figure_grid(cmp, folder / f"figure2{tag}.png")
    out["figure3"] = metrics_plot(cmp, folder / f"figure3{tag}.png")
    return out
