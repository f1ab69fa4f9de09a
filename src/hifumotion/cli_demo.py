"""``hifumotion demo``: the most complete pipeline the package runs so far.

Until the end-to-end system exists (issue "make demo"), the demo scores the
rough initial contours of a dataset laid out like ``../shared/data/*`` against
its expert masks, the floor every segmentation method must beat, and writes
the table, the masks and ``run_info.json``.
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


@app.command()
def demo(
    output: Path = typer.Option(Path("demo-output"), "--output", "-o", help="New output folder."),
    dataset: Optional[Path] = typer.Option(None, "--dataset", help="Dataset folder (images/, masks/, init.json); default ../shared/data/ddti."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Run the most complete pipeline there is on the built-in data; say where the results are."""
    from hifumotion.contour import ClickedPoints
    from hifumotion.io import output_folder, read_mask, read_sequence, write_mask_png, write_text
    from hifumotion.io.dataset import load_dataset
    from hifumotion.metrics import score
    from hifumotion.run_info import RunRecord

    folder = dataset or default_dataset()
    if folder is None:
        raise InputError("no dataset found; pass --dataset DIR (a folder with images/, masks/ and init.json)", "--dataset")
    data = load_dataset(folder)
    record = RunRecord("demo", config={"dataset": str(folder), "output": str(output)})
    rows = []
    with output_folder(output, overwrite) as out:
        with record.stage("score initial contours"):
            for item in track(data, "initial contours", total=len(data)):
                shape = read_sequence(item.image_path).shape
                truth = read_mask(item.mask_path)
                for kind in ("ellipse", "points"):
                    init = item.initial_contour(kind)
                    mask = init.to_mask(shape, smooth=False) if isinstance(init, ClickedPoints) else init.to_mask(shape)
                    rows.append({"image": item.name, "init": kind, **score(mask, truth)})
                    write_mask_png(out / "init_masks" / kind / f"{item.name}.png", mask)
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        write_text(out / "initial_contour_scores.csv", buf.getvalue())
        summary = {kind: float(np.mean([r["dsc"] for r in rows if r["init"] == kind])) for kind in ("ellipse", "points")}
        record.extra["mean_dsc"] = summary
        record.write(out)
    for kind, value in summary.items():
        log.info("initial %s contours: mean DSC %.3f over %d images", kind, value, len(data))
    console.print(f"results in {output.resolve()}", highlight=False)
