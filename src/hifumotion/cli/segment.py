"""``hifumotion segment`` and ``hifumotion compare``."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import numpy as np
import typer

from hifumotion.cli.app import app, parse_spacing, positive, require_frame_size
from hifumotion.console import console, log, track
from hifumotion.errors import InputError


def load_init(path: Path, image_path: Path, name: Optional[str], init_kind: Optional[str], shape: tuple[int, int]) -> Any:
    """The initial contour for ``image_path`` from a JSON (``init.json`` layout or one entry), a mask PNG or a contour CSV."""
    from hifumotion.contour import parse_init_entry
    from hifumotion.io import read_contours_csv, read_init_json, read_mask
    from hifumotion.io.files import require_regular_file
    from hifumotion.io.naming import full_suffix

    suffix = full_suffix(path)
    require_regular_file(path, "initial contour")
    if suffix == ".json":
        data = read_init_json(path)
        if "ellipse" in data or "points" in data:
            return parse_init_entry(data, init_kind, where=str(path))
        key = name or image_path.name
        if name is not None and name not in data:
            keys = ", ".join(sorted(data)[:5]) + (" …" if len(data) > 5 else "")
            raise InputError(f"has no entry '{name}' (from --name); its keys: {keys}", path)
        if key not in data:
            if len(data) == 1:
                key = next(iter(data))
            else:
                raise InputError(f"has no entry for '{key}'; pass --name with one of its keys", path)
        return parse_init_entry(data[key], init_kind, where=f"{path}[{key}]")
    if suffix in (".png", ".bmp", ".tif", ".tiff"):
        mask = read_mask(path, binary=True)
        if mask.shape != shape:
            raise InputError(f"mask shape {mask.shape} differs from the image's {shape}", path)
        return mask
    if suffix == ".csv":
        require_regular_file(path, "contour CSV")
        contours = read_contours_csv(path)
        return next(iter(contours.values()))
    raise InputError("expected an initial contour as .json (init.json layout), a mask .png or a contour .csv", path)


@app.command()
def segment(
    source: Path = typer.Argument(..., help="Image or sequence: PNG/TIFF/DICOM/NIfTI/MHA/NRRD/video or a folder of frames."),
    init: Path = typer.Option(..., "--init", help="Initial contour: init.json-style JSON, a mask PNG, or a contour CSV."),
    method: str = typer.Option("glcv", "--method", "-m", help="gac, cv, lcv, rsf, mslcv or glcv."),
    output: Path = typer.Option(..., "--output", "-o", help="New output folder."),
    init_kind: Optional[str] = typer.Option(None, "--init-kind", help="ellipse or points, when the JSON has both."),
    name: Optional[str] = typer.Option(None, "--name", help="Key of the image in the init JSON (default: the file name)."),
    spacing: Optional[str] = typer.Option(None, "--spacing", help="Pixel size in mm: '0.2' or 'row,col'. Overrides the file."),
    frame_interval: Optional[float] = typer.Option(None, "--frame-interval", callback=positive, help="Seconds between frames. Overrides the file."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Segment the target in an image, or track it through every frame of a sequence."""
    from hifumotion.io import (output_folder, read_sequence, write_contours_csv, write_contours_json, write_json,
                               write_masks_nifti, write_png_stack)
    from hifumotion.run_info import RunRecord
    from hifumotion.segmentation import METHODS, track as track_frames
    from hifumotion.segmentation.levelset import check_init_region

    if method.lower() not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}", "--method")
    if init_kind not in (None, "ellipse", "points"):
        raise InputError("expected 'ellipse' or 'points'", "--init-kind")
    seq = read_sequence(source, parse_spacing(spacing), frame_interval)
    require_frame_size(seq.shape, source)
    start = load_init(init, source, name, init_kind, seq.shape)
    check_init_region(start, seq.shape, str(init))
    record = RunRecord("segment", config={"source": str(source), "init": str(init), "method": method,
                                          "init_kind": init_kind, "spacing_mm": list(seq.spacing_mm),
                                          "frame_interval_s": seq.frame_interval_s})
    with output_folder(output, overwrite, inputs=(source, init)) as out:
        with record.stage("segment"):
            result = track_frames(seq, start, method, progress=True)
        masks = result.masks
        with record.stage("write"):
            write_png_stack(out / "masks", masks)
            write_masks_nifti(out / "masks.nii.gz", masks, seq.spacing_mm, seq.frame_interval_s, seq.slice_positions_mm)
            contours = {t: c for t, c in enumerate(result.contours) if c is not None}
            write_contours_csv(out / "contours.csv", contours)
            write_contours_json(out / "contours.json", contours)
            summary = [{"frame": t, "iterations": r.iterations, "converged": r.converged, "seconds": round(r.seconds, 4),
                        "area_mm2": r.contour.area_mm2 if r.contour else 0.0} for t, r in enumerate(result.results)]
            write_json(out / "segmentation.json", {"method": method, "params": result.results[0].params, "frames": summary})
            _overlay(seq.frames[0], masks[0], start, out / "overlay.png")
        record.extra["frames"] = len(result.results)
        record.write(out)
    log.info("%s: %d frame(s) in %.2f s (%.1f ms per frame)", method, len(result.results), result.seconds,
             1000 * result.seconds / len(result.results))
    console.print(f"results in {output.resolve()}", highlight=False)


def _overlay(image: np.ndarray, mask: np.ndarray, init: Any, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hifumotion.segmentation.levelset import initial_phi

    fig, ax = plt.subplots(figsize=(6, 6 * image.shape[0] / image.shape[1]))
    ax.imshow(image, cmap="gray", vmin=0, vmax=1)
    ax.contour(initial_phi(init, image.shape) > 0, [0.5], colors="yellow", linewidths=1)
    if mask.any():
        ax.contour(mask, [0.5], colors="red", linewidths=1.5)
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@app.command()
def compare(
    dataset: Path = typer.Argument(..., help="Folder with images/, masks/ and init.json (the layout of ../shared/data/*)."),
    methods: str = typer.Option("gac,cv,lcv,rsf,mslcv,glcv", "--methods", help="Comma-separated methods."),
    init_kind: str = typer.Option("ellipse", "--init-kind", help="ellipse, points or both."),
    output: Path = typer.Option(..., "--output", "-o", help="New output folder."),
    limit: Optional[int] = typer.Option(None, "--limit", min=1, help="Only the first N images."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Reproduce the paper's Table 2 and Figures 2–3 on a dataset: every method from the same start."""
    from hifumotion.io import output_folder
    from hifumotion.io.dataset import Dataset, load_dataset
    from hifumotion.run_info import RunRecord
    from hifumotion.segmentation import METHODS
    from hifumotion.segmentation.compare import compare_methods, write_comparison

    chosen = [m.strip().lower() for m in methods.split(",") if m.strip()]
    unknown = [m for m in chosen if m not in METHODS]
    if unknown or not chosen:
        raise InputError(f"unknown method(s) {unknown}; expected from {', '.join(METHODS)}", "--methods")
    kinds = ["ellipse", "points"] if init_kind == "both" else [init_kind]
    if any(k not in ("ellipse", "points") for k in kinds):
        raise InputError("expected ellipse, points or both", "--init-kind")
    data = load_dataset(dataset)
    if limit:
        data = Dataset(data.root, data.items[:limit])
    record = RunRecord("compare", config={"dataset": str(dataset), "methods": chosen, "init_kind": init_kind,
                                          "images": len(data)})
    with output_folder(output, overwrite, inputs=(dataset,)) as out:
        for kind in kinds:
            with record.stage(f"compare ({kind})"):
                cmp = compare_methods(data, chosen, kind, progress=track)
            write_comparison(cmp, out, tag="" if len(kinds) == 1 else f"_{kind}")
            record.extra[f"mean_dsc_{kind}"] = {m: round(cmp.mean(m, "dsc"), 4) for m in chosen}
            for m in chosen:
                log.info("%-6s %-7s mean DSC %.3f  MSSD %.1f  HD %.1f  %.3f s", m, kind, cmp.mean(m, "dsc"),
                         cmp.mean(m, "mssd"), cmp.mean(m, "hausdorff"), cmp.mean(m, "seconds"))
        record.write(out)
    console.print(f"results in {output.resolve()}", highlight=False)
