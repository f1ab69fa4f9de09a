"""``hifumotion info``: what a file holds, as the readers see it."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app, parse_spacing, positive


@app.command()
def info(
    path: Path = typer.Argument(..., help="Image file or folder: PNG/JPEG/TIFF, DICOM, NIfTI/MHA/NRRD, video."),
    spacing: Optional[str] = typer.Option(None, "--spacing", help="Pixel size in mm: '0.2' or 'row,col'. Overrides the file."),
    frame_interval: Optional[float] = typer.Option(None, "--frame-interval", callback=positive, help="Seconds between frames. Overrides the file."),
    kind: str = typer.Option("auto", "--kind", help="How to read the third axis of a 3D file: auto, cine or sweep."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
) -> None:
    """Print what was read from FILE: frames, size, spacing, frame interval, source."""
    from rich.console import Console
    from rich.table import Table

    from hifumotion.io import read_sequence

    seq = read_sequence(path, parse_spacing(spacing), frame_interval, kind=kind)  # type: ignore[arg-type]
    summary = seq.describe()
    if as_json:
        from hifumotion.io.writers import json_text

        typer.echo(json_text(summary))
        return
    table = Table(title=str(path), show_header=False)
    for key, value in summary.items():
        if key == "metadata":
            for mk, mv in value.items():
                table.add_row(f"  {mk}", str(mv))
            continue
        if key == "spacing_mm" and value is None:
            value = "unknown (1 px = 1 unit); give --spacing"
        table.add_row(key, str(value))
    Console().print(table)   # the table is the command's output: standard output, like --json
