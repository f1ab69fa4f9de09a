"""``hifumotion demo``: the most complete pipeline the package runs so far.

Until the end-to-end system exists (issue "make demo"), the demo runs:

1. the paper's segmentation comparison (Table 2, Figures 2–3) on real images
   with expert masks, ``../shared/data/ddti`` when present: every method from
   the same rough initial contours, scored against the experts, beside the
   score of the initial contours themselves (the floor every method must beat);
2. a simulated spatial sweep through a tissue of known shape: B-mode planes
   every 1 mm, segmented with GLCV plane after plane, reconstructed into a 3D
   model whose volume is compared with the truth (:mod:`hifumotion.sweep_demo`).
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
    if dataset is not None and not Path(dataset).is_dir():
        raise InputError("no such dataset folder", dataset)
    data = None
    if folder is not None:
        data = load_dataset(folder)
        data = Dataset(data.root, data.items[: max(images, 1)])
    else:
        log.warning("../shared/data not found: skipping the comparison on real images")
    methods = list(METHODS)
    record = RunRecord("demo", config={"dataset": str(folder) if folder else None, "images": len(data) if data else 0,
                                       "methods": methods, "output": str(output)}, seed=0)
    with output_folder(output, overwrite) as out:
        if data is not None:
            with record.stage("score initial contours"):
                floor = _initial_scores(data, out / "segmentation")
            for kind in ("ellipse", "points"):
                with record.stage(f"segment ({kind} start)"):
                    cmp = compare_methods(data, methods, kind, progress=track)
                write_comparison(cmp, out / "segmentation", tag=f"_{kind}")
                record.extra[f"mean_dsc_{kind}"] = {m: round(cmp.mean(m, "dsc"), 4) for m in methods}
                log.info("%s start: initial contour DSC %.3f; %s", kind, floor[kind],
                         ", ".join(f"{m.upper()} {cmp.mean(m, 'dsc'):.3f}" for m in methods))
            record.extra["initial_contour_mean_dsc"] = floor
        record.extra["sweep"] = _sweep(out / "sweep", record)
        record.write(out)
    console.print(f"results in {output.resolve()}: segmentation/ (table2_*.md, figure2_*.png, figure3_*.png), "
                  "sweep/ (tissue.vtp for ParaView, tissue_volume.nii.gz for 3D Slicer)", highlight=False)


def _sweep(folder: Path, record) -> dict:
    """Simulate, segment and reconstruct a sweep through a known tissue; write it and its scores."""
    from hifumotion.io import write_json, write_masks_nifti, write_nifti, write_png_stack
    from hifumotion.reconstruction import reconstruct as rebuild
    from hifumotion.sweep_demo import simulate_sweep

    with record.stage("sweep: simulate and segment"):
        sweep = simulate_sweep(seed=0)
    with record.stage("sweep: reconstruct"):
        rec = rebuild(sweep.masks, sweep.spacing_mm, sweep.positions_mm)
    write_png_stack(folder / "images", sweep.images, prefix="slice_", digits=3)
    write_nifti(folder / "sweep.nii.gz", sweep.images, sweep.spacing_mm, slice_positions_mm=sweep.positions_mm)
    write_masks_nifti(folder / "segmented_masks.nii.gz", sweep.masks, sweep.spacing_mm,
                      slice_positions_mm=sweep.positions_mm)
    rec.write(folder)
    summary = {"slices": len(sweep.positions_mm), "slice_gap_mm": float(np.diff(sweep.positions_mm)[0]),
               "slice_dsc_mean": round(float(sweep.dsc.mean()), 4), "slice_dsc_min": round(float(sweep.dsc.min()), 4),
               "true_volume_mm3": round(sweep.true_volume_mm3, 1), "reconstructed_volume_mm3": round(rec.volume_mm3, 1),
               "volume_error_percent": round(100 * (rec.volume_mm3 / sweep.true_volume_mm3 - 1), 2),
               "watertight": bool(rec.mesh.is_watertight), "notes": rec.notes}
    write_json(folder / "sweep.json", summary)
    log.info("sweep: %d planes, slice DSC %.3f, volume %.0f mm³ (truth %.0f mm³, %+.1f %%)", summary["slices"],
             summary["slice_dsc_mean"], rec.volume_mm3, sweep.true_volume_mm3, summary["volume_error_percent"])
    return summary
