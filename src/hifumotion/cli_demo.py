"""``hifumotion demo``: the most complete pipeline the package runs so far.

Until the end-to-end system exists (issue "make demo"), the demo reproduces
the paper's segmentation comparison (Table 2, Figures 2–3) on real images with
expert masks, ``../shared/data/ddti`` when present: every method from the
same rough initial contours, scored against the experts, beside the score of
the initial contours themselves (the floor every method must beat).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from hifumotion.cli import app
from hifumotion.console import console, log, track
from hifumotion.errors import InputError


def default_dataset() -> Path | None:
    """``../shared/data/ddti`` beside the source tree or the working directory, if present."""
    here = Path(__file__).resolve()
    for base in [Path.cwd(), *here.parents]:
        candidate = base.parent / "shared" / "data" / "ddti"
        if candidate.is_dir():
            return candidate
    return None


def _initial_scores(data, out: Path) -> dict[str, float]:
    from hifumotion.contour import ClickedPoints
    from hifumotion.io import read_mask, write_text
    from hifumotion.metrics import score

    rows = []
    for item in data:
        truth = read_mask(item.mask_path)
        for kind in ("ellipse", "points"):
            init = item.initial_contour(kind)
            mask = init.to_mask(truth.shape, smooth=False) if isinstance(init, ClickedPoints) else init.to_mask(truth.shape)
            rows.append({"image": item.name, "init": kind, **score(mask, truth)})
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text(out / "initial_contour_scores.csv", buf.getvalue())
    return {kind: float(np.mean([r["dsc"] for r in rows if r["init"] == kind])) for kind in ("ellipse", "points")}


@app.command()
def demo(
    output: Path = typer.Option(Path("demo-output"), "--output", "-o", help="New output folder."),
    dataset: Optional[Path] = typer.Option(None, "--dataset", help="Dataset folder (images/, masks/, init.json); default ../shared/data/ddti."),
    images: int = typer.Option(6, "--images", help="How many images of the dataset to use."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Run the most complete pipeline there is on the built-in data; say where the results are."""
    from hifumotion.io import output_folder
    from hifumotion.io.dataset import Dataset, load_dataset
    from hifumotion.run_info import RunRecord
    from hifumotion.segmentation import METHODS
    from hifumotion.segmentation.compare import compare_methods, write_comparison

    folder = dataset or default_dataset()
    if folder is None:
        raise InputError("no dataset found; pass --dataset DIR (a folder with images/, masks/ and init.json)", "--dataset")
    data = load_dataset(folder)
    data = Dataset(data.root, data.items[: max(images, 1)])
    methods = list(METHODS)
    record = RunRecord("demo", config={"dataset": str(folder), "images": len(data), "methods": methods,
                                       "output": str(output)})
    with output_folder(output, overwrite) as out:
        with record.stage("score initial contours"):
            floor = _initial_scores(data, out)
        for kind in ("ellipse", "points"):
            with record.stage(f"segment ({kind} start)"):
                cmp = compare_methods(data, methods, kind, progress=track)
            write_comparison(cmp, out, tag=f"_{kind}")
            record.extra[f"mean_dsc_{kind}"] = {m: round(cmp.mean(m, "dsc"), 4) for m in methods}
            log.info("%s start: initial contour DSC %.3f; %s", kind, floor[kind],
                     ", ".join(f"{m.upper()} {cmp.mean(m, 'dsc'):.3f}" for m in methods))
        record.extra["initial_contour_mean_dsc"] = floor
        record.write(out)
    console.print(f"results in {output.resolve()}: table2_*.md, figure2_*.png, figure3_*.png, comparison_*.csv",
                  highlight=False)
