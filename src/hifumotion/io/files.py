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


def check_output_folder(path: str | Path, overwrite: bool = False) -> Path:
    """Raise unless ``path`` can take a run's output: new, empty, or ``overwrite`` given."""
    folder = Path(path)
    if folder.exists():
        if not folder.is_dir():
            raise InputError("exists and is not a folder; choose another output folder", folder)
        if not overwrite and any(folder.iterdir()):
            raise OutputExistsError(f"{folder}: output folder exists and is not empty; choose a new one or pass --overwrite")
    return folder


@contextlib.contextmanager
def output_folder(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Prepare a run's output folder; yield a staging folder to write into.

    The run writes into a hidden staging folder beside ``path``. When the block
    ends without an error, the staging folder takes the place of ``path`` (an
    existing one is only replaced with ``overwrite``, and only then). When it
    fails, the staging folder is removed and ``path`` is untouched, so a failed
    run never destroys the results of an earlier one.
    """
    final = check_output_folder(path, overwrite).resolve()
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".partial", dir=final.parent))
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
