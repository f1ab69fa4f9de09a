"""``hifumotion phantom``: a simulated B-mode image of a known target, in the dataset layout."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from hifumotion.cli.app import app
from hifumotion.console import console
from hifumotion.errors import InputError
from hifumotion.resources import check_memory


@app.command()
def phantom(
    shape: str = typer.Option("ellipse", "--shape", help="ellipse or irregular."),
    preset: str = typer.Option("medium", "--preset", help="easy, medium or hard."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the shape, the scatterers and the noise."),
    size: int = typer.Option(256, "--size", min=32, help="Image size in px (square, ≥ 32)."),
    spacing: float = typer.Option(0.15, "--spacing", help="Pixel size in mm."),
    output: Path = typer.Option(..., "--output", "-o", help="New output folder."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Write DIR/images/phantom.png, DIR/masks/phantom.png and DIR/init.json (the ../shared/data layout)."""
    from hifumotion.imaging import PRESETS, make_phantom, write_phantom
    from hifumotion.io import output_folder
    from hifumotion.run_info import RunRecord

    if shape not in ("ellipse", "irregular"):
        raise InputError("expected ellipse or irregular", "--shape")
    if preset not in PRESETS:
        raise InputError(f"expected one of {', '.join(PRESETS)}", "--preset")
    if not (math.isfinite(spacing) and 0 < spacing <= 10):
        raise InputError(f"expected a pixel size in mm, 0 < spacing ≤ 10, got {spacing}", "--spacing")
    # the simulator holds a few dozen float arrays of the image's size
    check_memory(60.0 * 8 * size * size, f"a {size} × {size} px phantom", "--size")
    record = RunRecord("phantom", config={"shape": shape, "preset": preset, "size_px": size, "spacing_mm": spacing},
                       seed=seed)
    with output_folder(output, overwrite) as out:
        with record.stage("simulate"):
            ph = make_phantom(shape, preset, seed, (size, size), spacing)
        write_phantom(out, ph)
        record.extra["preset"] = ph["preset"]
        record.extra["transducer"] = ph["transducer"]
        record.write(out)
    console.print(f"phantom in {output.resolve()} (pixel size {spacing} mm)", highlight=False)
