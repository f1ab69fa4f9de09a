"""The ``hifumotion`` Typer application and the options its commands share.

A leaf module: every ``hifumotion.cli.*`` command module imports :data:`app` from here
and registers its commands on it; :func:`hifumotion.cli.main` imports them all.
"""

from __future__ import annotations

from typing import Optional

import typer

from hifumotion import __version__, console
from hifumotion.errors import InputError

def _flags_shown_as_flags() -> None:
    """Typer's rich help prints a type beside every flag (``--overwrite <bool>``), as if it took
    a value; a flag takes none, so none is printed (versions without the hook are left as they are)."""
    from typer.core import TyperOption

    shown = getattr(TyperOption, "display_type_rich", None)
    if shown is None or getattr(shown, "_flag_aware", False):
        return

    def display_type_rich(self, ctx):
        if getattr(self, "is_flag", False) and self.metavar is None:
            return None
        return shown(self, ctx)

    display_type_rich._flag_aware = True
    TyperOption.display_type_rich = display_type_rich


_flags_shown_as_flags()

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
    from hifumotion.sequence import as_spacing_mm

    try:
        values = [float(v) for v in text.replace("x", ",").split(",") if v.strip()]
    except ValueError:
        raise InputError(f"expected a number or 'row,col' in mm, got {text!r}", "--spacing") from None
    return as_spacing_mm(values, "--spacing")


def pixel_size(value: Optional[float]) -> Optional[float]:
    """Typer callback: a pixel size in mm within :data:`~hifumotion.sequence.PIXEL_MM_RANGE`
    (None passes: the option was not given)."""
    from hifumotion.sequence import as_spacing_mm

    return None if value is None else as_spacing_mm(value, "--spacing")[0]


def positive(value: Optional[float]) -> Optional[float]:
    """Typer callback: a finite number > 0 (None passes: the option was not given)."""
    import math

    if value is not None and not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"expected a positive number, got {value:g}")
    return value


#: The smallest frame a level set or a tracker can work on (px, each side).
MIN_FRAME_PX = 8


def require_frame_size(shape: tuple[int, ...], source) -> None:
    """Refuse frames smaller than :data:`MIN_FRAME_PX` on a side, naming ``source``, before
    anything that goes with them (an initial contour, points) is checked against them."""
    h, w = int(shape[-2]), int(shape[-1])
    if min(h, w) < MIN_FRAME_PX:
        raise InputError(f"has frames of {h} × {w} px; segmenting and tracking need at least "
                         f"{MIN_FRAME_PX} × {MIN_FRAME_PX}", source)
