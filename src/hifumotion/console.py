"""Terminal output: logging levels, messages and progress bars (rich), silenced by ``-q``."""

from __future__ import annotations

import logging
from typing import Iterable, Iterator, TypeVar

from rich.console import Console
from rich.logging import RichHandler
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

T = TypeVar("T")

#: Messages and progress go to standard error, so standard output stays clean for ``--json``.
console = Console(stderr=True)
log = logging.getLogger("hifumotion")
_quiet = False


def setup(verbosity: int = 0, quiet: bool = False) -> None:
    """Configure logging: ``-q`` errors only and no progress bars, default info, ``-v`` debug."""
    global _quiet
    _quiet = quiet
    level = logging.ERROR if quiet else (logging.DEBUG if verbosity > 0 else logging.INFO)
    log.handlers.clear()
    handler = RichHandler(console=console, show_time=False, show_path=verbosity > 0, markup=False)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False


class ProgressLines:
    """Progress as plain lines, for standard error that is not a terminal (a log file, CI, ``make``),
    where a bar cannot redraw: one line at most every :attr:`INTERVAL_S` seconds, so a long stage
    is not silent for minutes, and none for work that ends sooner (a refusal stays one line)."""

    INTERVAL_S = 10.0

    def __init__(self, description: str):
        import time

        self.description = description
        self.start = self.last = time.monotonic()
        self.printed = False

    def __call__(self, fraction: float, done: int | None = None, total: int | None = None) -> None:
        import time

        now = time.monotonic()
        if _quiet or now - self.last < self.INTERVAL_S:
            return
        self.last, self.printed = now, True
        count = f" ({done}/{total})" if done is not None and total else ""
        console.print(f"{self.description}: {100 * min(max(fraction, 0.0), 1.0):.0f} %{count}, "
                      f"{now - self.start:.0f} s", highlight=False, markup=False, soft_wrap=True)

    def finish(self) -> None:
        import time

        if self.printed and not _quiet:
            console.print(f"{self.description}: 100 %, done in {time.monotonic() - self.start:.0f} s", highlight=False,
                          markup=False, soft_wrap=True)


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """Iterate with a progress bar on standard error (none with ``-q``; plain lines,
    :class:`ProgressLines`, when standard error is not a terminal)."""
    if _quiet:
        yield from items
        return
    if not console.is_terminal:
        n = total if total is not None else (len(items) if hasattr(items, "__len__") else None)
        lines = ProgressLines(description)
        for i, item in enumerate(items):
            yield item
            lines((i + 1) / n if n else 0.0, i + 1, n)
        lines.finish()
        return
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task(description, total=total if total is not None else (len(items) if hasattr(items, "__len__") else None))
        for item in items:
            yield item
            progress.advance(task)


class _Fraction:
    """A progress bar driven by a fraction in [0, 1] (for simulated time, not item counts)."""

    def __init__(self, description: str):
        self.description = description
        self.progress: Progress | None = None
        self.task = None
        self.lines: ProgressLines | None = None

    def __enter__(self):
        if not _quiet and not console.is_terminal:
            self.lines = ProgressLines(self.description)
        if not _quiet and console.is_terminal:
            self.progress = Progress(TextColumn("{task.description}"), BarColumn(),
                                     TextColumn("{task.percentage:>3.0f}%"), TimeElapsedColumn(),
                                     TimeRemainingColumn(), console=console)
            self.progress.__enter__()
            self.task = self.progress.add_task(self.description, total=1.0)
        return self

    def __call__(self, fraction: float) -> None:
        if self.progress is not None:
            self.progress.update(self.task, completed=min(max(fraction, 0.0), 1.0))
        if self.lines is not None:
            self.lines(fraction)

    def __exit__(self, *exc):
        if self.progress is not None:
            self.progress.__exit__(*exc)
        if self.lines is not None and exc[0] is None:
            self.lines.finish()
        return False


def progress_fraction(description: str) -> _Fraction:
    """``with progress_fraction("simulate") as update: update(0.5)`` — a bar on standard error."""
    return _Fraction(description)


class StageBars:
    """``progress(stage, fraction)`` for a run of stages: one bar per stage, opened as it starts.

    Use as a context manager; the open bar is closed on exit (also after an error)."""

    def __init__(self):
        self.bars: dict[str, _Fraction] = {}

    def __call__(self, stage: str, fraction: float) -> None:
        if stage not in self.bars:
            self.close()
            self.bars[stage] = progress_fraction(stage).__enter__()
        self.bars[stage](fraction)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.__exit__(None, None, None)
        self.bars.clear()

    def __enter__(self) -> "StageBars":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False
