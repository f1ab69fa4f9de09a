"""The ``hifumotion`` command line: one program, one subcommand per stage.

Each command is a thin adapter in its own module (``info``, ``segment``, ``imaging``,
``reconstruct``, ``particles``, ``experiment``, ``estimation``, ``score``, ``track``, ``workflow``)
over the same functions the Python API offers; :mod:`.app` holds the Typer application
they register on.

A user's mistake — a missing or unreadable file, a bad format or value, an output folder
that exists — prints one line ``error: …`` on standard error, naming the file or field,
and exits with status 2: never a traceback. SIGTERM and Ctrl-C end a run the way an
error does, so its half-written output folder is removed.
"""

from __future__ import annotations

import errno
import signal
import sys
from typing import Optional


def _register_commands() -> None:
    """Importing the command modules registers their commands on the app."""
    from hifumotion.cli import (estimation, experiment, imaging, info, particles, reconstruct,  # noqa: F401
                                score, segment, track, workflow)


def _terminate(signum, frame) -> None:
    # turned into an exception, so every ``with output_folder(...)`` removes its staging folder
    raise KeyboardInterrupt(f"signal {signum}")


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _os_error(exc: OSError) -> str:
    """An operating-system error on a user's path, as the line a user needs."""
    where = exc.filename if exc.filename is not None else ""
    reason = exc.strerror or type(exc).__name__
    if exc.errno == errno.ENOSPC:
        reason = "no space left on the device"
    return f"{where}: {reason}" if where else reason


def _stdout_broken() -> bool:
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return True
    except (OSError, ValueError):
        return False
    return False


def _quiet_stdout() -> None:
    """Point standard output at /dev/null, so the interpreter's last flush does not fail again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def main(argv: Optional[list[str]] = None) -> None:
    """Console-script entry point: run the app; user errors become one line and exit status 2."""
    from rich.text import Text

    try:   # Typer ≥ 0.24 carries its own copy of Click
        from typer import _click as click
    except ImportError:  # pragma: no cover - older Typer
        import click

    from hifumotion import console
    from hifumotion.cli.app import app
    from hifumotion.errors import HifuError

    def fail(message: str, status: int = 2) -> None:
        console.console.print(Text.assemble(("error: ", "bold red"), _one_line(message)), highlight=False,
                              soft_wrap=True)
        sys.exit(status)

    # Typer's own copy of Click has no Abort (it raises KeyboardInterrupt or exits instead)
    abort = getattr(click.exceptions, "Abort", None) or getattr(click, "Abort", None) or KeyboardInterrupt
    _register_commands()
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        status = app(args=argv, prog_name="hifumotion", standalone_mode=False)
    except click.exceptions.NoArgsIsHelpError as exc:
        exc.show()
        sys.exit(0)
    except click.exceptions.UsageError as exc:
        # Typer's own checks (an unknown option, a value out of its range): one line too
        where = f" (see '{exc.ctx.command_path} --help')" if exc.ctx is not None else ""
        fail(f"{exc.format_message()}{where}")
    except click.exceptions.ClickException as exc:
        fail(exc.format_message())
    except HifuError as exc:
        fail(str(exc))
    except BrokenPipeError:
        _quiet_stdout()   # the reader went away (``hifumotion … | head``): nothing more to say
        sys.exit(0)
    except MemoryError:
        fail("out of memory: the input or the settings ask for more memory than this machine has; "
             "use a coarser resolution or a smaller input")
    except OSError as exc:
        fail(_os_error(exc))
    except RuntimeError as exc:
        linear = sys.modules.get("hifumotion.creep.linear")     # loaded wherever a solve could fail
        if linear is None or not isinstance(exc, linear.FactorError):
            raise
        # the model's settings gave a linear system its sparse solver could not factor or solve
        fail(f"the tissue model's linear system could not be solved ({exc}): its settings give a singular or "
             "badly conditioned system; check the model's settings (the tissue's material, its resolution, "
             "the scene) or try another integrator")
    except SystemExit:
        if _stdout_broken():
            _quiet_stdout()
            sys.exit(0)
        raise
    except (KeyboardInterrupt, abort):
        console.console.print("interrupted; nothing was written", highlight=False)
        sys.exit(130)
    finally:
        signal.signal(signal.SIGTERM, previous)
    if isinstance(status, int) and status:
        sys.exit(status)


__all__ = ["main"]
