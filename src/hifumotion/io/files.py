"""Safe writing: atomic files, and output folders that never clobber existing results.

Every writer in the package goes through :func:`atomic_path`: the data are
written to a temporary name in the destination folder and moved into place
with :func:`os.replace`, so a reader never sees half a file and a crash never
leaves one. A run's output folder is prepared by :func:`output_folder`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import uuid
from pathlib import Path
from typing import Iterator

from hifumotion.errors import InputError, OutputExistsError


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix); on success move it onto ``path``.

    Use it with writers that take a filename (SimpleITK, imageio, numpy)::

        with atomic_path("out/mask.nii.gz") as tmp:
            sitk.WriteImage(image, str(tmp))
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    suffix = "".join(final.suffixes) or ".tmp"
    fd, tmp_name = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=suffix, dir=final.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


#: The file every hifumotion output folder holds; ``--overwrite`` replaces only folders that have it.
RUN_INFO = "run_info.json"


def require_regular_file(path: str | Path, what: str = "file") -> Path:
    """``path`` if it is a regular file; a missing path, a folder, a FIFO, a device or a socket
    is an :class:`~hifumotion.errors.InputError` (reading a FIFO or a device would hang or never end)."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        raise InputError(f"no such {what}", p) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", p) from None
    import stat

    if stat.S_ISDIR(mode):
        raise InputError(f"is a folder; expected a file ({what})", p)
    if not stat.S_ISREG(mode):
        raise InputError(f"is not a regular file (a FIFO, device or socket); expected a regular {what}", p)
    return p


def _is_within(inner: Path, outer: Path) -> bool:
    return inner == outer or outer in inner.parents


def check_output_folder(path: str | Path, overwrite: bool = False, inputs=()) -> Path:
    """Raise unless ``path`` can take a run's output: new, empty, or — with ``overwrite`` — a
    folder hifumotion wrote (it holds ``run_info.json``) that is not the working folder or an
    ancestor of it and holds none of the run's ``inputs``."""
    folder = Path(path)
    # what is checked is what will be written: the resolved path (``missing/../file`` does not
    # exist as typed, but resolves onto ``file``)
    final = folder.resolve()
    if final.exists() or folder.is_symlink():
        if not final.is_dir():
            raise InputError("exists and is not a folder; choose another output folder", folder)
        if any(final.iterdir()):
            if not overwrite:
                raise OutputExistsError(f"{folder}: output folder exists and is not empty; choose a new one or pass "
                                        "--overwrite")
            cwd = Path.cwd().resolve()
            if _is_within(cwd, final):
                raise InputError("is the working folder or holds it; --overwrite never replaces it — choose a new "
                                 "output folder", folder)
            for item in inputs:
                if item is not None and _is_within(Path(item).resolve(), final):
                    raise InputError(f"holds {item}, an input of this run; --overwrite never replaces it — choose "
                                     "another output folder", folder)
            if not (final / RUN_INFO).is_file():
                raise InputError(f"was not written by hifumotion (it has no {RUN_INFO}); --overwrite only replaces "
                                 "hifumotion's own output folders — choose a new one", folder)
    return folder


def _make_parent(final: Path, shown: Path) -> None:
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError("cannot create the output folder here: a part of its path is a file, not a folder",
                         shown) from None
    except OSError as exc:
        raise InputError(f"cannot create the output folder here ({exc.strerror or exc})", shown) from None
    if not os.access(final.parent, os.W_OK | os.X_OK):
        raise InputError(f"cannot write into {final.parent} (permission denied)", shown)


@contextlib.contextmanager
def output_folder(path: str | Path, overwrite: bool = False, inputs=()) -> Iterator[Path]:
    """Prepare a run's output folder; yield a staging folder to write into.

    The run writes into a hidden staging folder beside ``path``. When the block
    ends without an error, the staging folder takes the place of ``path`` (an
    existing one is only replaced with ``overwrite``, and only then — see
    :func:`check_output_folder` for what ``overwrite`` may replace; ``inputs`` are
    the files and folders the run reads). When it fails or is interrupted, the
    staging folder is removed and ``path`` is untouched, so a failed run never
    destroys the results of an earlier one.
    """
    shown = Path(path)
    final = check_output_folder(path, overwrite, inputs).resolve()
    _make_parent(final, shown)
    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
    except OSError as exc:
        raise InputError(f"cannot create the output folder here ({exc.strerror or exc})", shown) from None
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if final.exists():
        retired = final.with_name(f".{final.name}.old-{uuid.uuid4().hex[:8]}")
        final.rename(retired)
        staging.rename(final)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        staging.rename(final)
