"""The ``hifumotion`` command line.

One program, one subcommand per stage. A user's mistake (missing file, bad
format, bad value, existing output folder) prints one line ``error: …`` on
standard error and exits with status 2; no traceback.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from hifumotion import __version__, console
from hifumotion.errors import HifuError

app = typer.Typer(
    name="hifumotion",
    help="Model and predict the movement and deformation of a HIFU target tissue.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"hifumotion {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    verbose: int = typer.Option(0, "--verbose", "-v", count=True, help="More detail (debug messages)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Errors only; no progress bars."),
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
) -> None:
    """hifumotion: segment, reconstruct, simulate, calibrate, predict."""
    console.setup(verbose, quiet)


def parse_spacing(text: Optional[str]) -> Optional[tuple[float, float]]:
    """``"0.2"`` or ``"0.2,0.25"`` (row, col mm) → a spacing tuple; None stays None."""
    if text is None:
        return None
    from hifumotion.errors import InputError
    from hifumotion.sequence import as_spacing_mm

    try:
        values = [float(v) for v in text.replace("x", ",").split(",") if v.strip()]
    except ValueError:
        raise InputError(f"expected a number or 'row,col' in mm, got {text!r}", "--spacing") from None
    return as_spacing_mm(values, "--spacing")


@app.command()
def info(
    path: Path = typer.Argument(..., help="Image file or folder: PNG/JPEG/TIFF, DICOM, NIfTI/MHA/NRRD, video."),
    spacing: Optional[str] = typer.Option(None, "--spacing", help="Pixel size in mm: '0.2' or 'row,col'. Overrides the file."),
    frame_interval: Optional[float] = typer.Option(None, "--frame-interval", help="Seconds between frames. Overrides the file."),
    kind: str = typer.Option("auto", "--kind", help="How to read the third axis of a 3D file: auto, cine or sweep."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
) -> None:
    """Print what was read from FILE: frames, size, spacing, frame interval, source."""
    from rich.table import Table

    from hifumotion.io import read_sequence

    seq = read_sequence(path, parse_spacing(spacing), frame_interval, kind=kind)  # type: ignore[arg-type]
    summary = seq.describe()
    if as_json:
        typer.echo(json.dumps(summary, indent=2))
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
    console.console.print(table)


def _register_subcommands() -> None:
    """Stage commands live beside their stage; importing them registers them on ``app``."""
    from hifumotion import (cli_demo, cli_estimation, cli_experiment, cli_imaging, cli_particles,  # noqa: F401
                            cli_reconstruct, cli_score, cli_segment)


def main(argv: Optional[list[str]] = None) -> None:
    """Console-script entry point: run the app; turn user errors into one line and exit code 2."""
    _register_subcommands()
    try:
        app(args=argv, prog_name="hifumotion", standalone_mode=True)
    except HifuError as exc:
        from rich.text import Text

        console.console.print(Text.assemble(("error: ", "bold red"), str(exc)), highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        console.console.print("interrupted", highlight=False)
        sys.exit(130)


if __name__ == "__main__":
    main()
