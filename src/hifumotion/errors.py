"""Exceptions that carry a message meant for the user.

A :class:`HifuError` is a problem with what the user gave (a file, a field, a
value), not a bug. The command line prints its message on one line and exits
with status 2, without a traceback. Messages name the file or field and say
what was expected.
"""

from __future__ import annotations

from pathlib import Path


class HifuError(Exception):
    """Base class of the errors the command line reports in one line (exit code 2)."""


class InputError(HifuError, ValueError):
    """Bad input: missing or unreadable file, unsupported format, invalid value.

    Parameters
    ----------
    message
        What was wrong and what was expected.
    source
        The file or field the message is about; it prefixes the message.
    """

    def __init__(self, message: str, source: str | Path | None = None):
        self.source = None if source is None else str(source)
        self.reason = " ".join(str(message).split())  # always one line
        super().__init__(f"{self.source}: {message}" if self.source else message)


def brief(exc: BaseException, limit: int = 160) -> str:
    """A library exception as a short one-line reason: its type and last meaningful line."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    text = lines[-1] if lines else ""
    text = text.removeprefix("sitk::ERROR:").strip()
    if len(text) > limit:
        text = text[: limit - 1] + "…"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


class CalibrationFailed(HifuError, RuntimeError):
    """Most forward runs of a calibration failed: the fit cannot go on (the message says why)."""


class OutputExistsError(HifuError, FileExistsError):
    """The output folder exists and ``overwrite`` was not given."""
