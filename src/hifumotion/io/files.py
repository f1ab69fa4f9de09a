"""Safe writing: atomic files, and output folders that never clobber existing results.

Every writer in the package goes through :func:`atomic_path`: the data are
written to a temporary name in the destination folder and moved into place
with :func:`os.replace`, so a reader never sees half a file and a crash never
leaves one. A run's output folder is prepared by :func:`output_folder`: its
``run_info.json`` lists every file and folder the run wrote, and ``--overwrite``
replaces a folder only when nothing else is in it (one whose ``run_info.json`` lists
nothing, an older version's, is moved aside to ``NAME.replaced-*``, never deleted, and the
move is said on standard error). Files and folders are made with
the permissions the umask gives (not the temporary files' private 0600/0700).
"""

from __future__ import annotations

import contextlib
import json
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
        follow_umask(tmp)
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
#: ``run_info.json``'s list of what the run wrote (paths relative to the folder, POSIX)
OUTPUTS_KEY = "outputs"


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def follow_umask(path: str | Path, folder: bool = False) -> None:
    """Give ``path`` the permissions a plain ``open``/``mkdir`` would have under the umask
    (temporary files and folders are made private)."""
    try:
        os.chmod(path, (0o777 if folder else 0o666) & ~_umask())
    except OSError:
        pass


def _contents(folder: Path) -> list[str]:
    """Every file, link and folder under ``folder`` (relative POSIX paths, sorted; links not followed)."""
    found = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        found += [(rel / name).as_posix() for name in dirs + files]
    return sorted(found)


def _record_outputs(staging: Path) -> None:
    """List what the run wrote in its ``run_info.json`` (what a later ``--overwrite`` may replace)."""
    info = staging / RUN_INFO
    if not info.is_file():
        return
    try:
        data = json.loads(info.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    if isinstance(data, dict):
        data[OUTPUTS_KEY] = _contents(staging)
        write_text(info, json.dumps(data, indent=2, default=str))


def foreign_contents(folder: Path) -> list[str] | None:
    """What is in ``folder`` that its ``run_info.json`` does not list as written by hifumotion
    (None: it lists nothing — an older version's folder, or the file is unreadable)."""
    try:
        data = json.loads((folder / RUN_INFO).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    listed = data.get(OUTPUTS_KEY) if isinstance(data, dict) else None
    if not isinstance(listed, list):
        return None
    ours = set(map(str, listed)) | {RUN_INFO}
    return [p for p in _contents(folder) if p not in ours]


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
    final = _resolved(folder)
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
            _refuse_foreign(foreign_contents(final), folder)
    return folder


def _resolved(path: Path) -> Path:
    """``path`` resolved; a symbolic link that points back into itself is an :class:`InputError`."""
    try:
        return path.resolve()
    except (RuntimeError, OSError):     # Python < 3.13 raises RuntimeError on a loop, later OSError
        raise InputError("is a symbolic link loop; expected a folder or a new path", path) from None


def _refuse_foreign(foreign: list[str] | None, shown: Path) -> None:
    """Raise when a folder holds ``foreign`` files (:func:`foreign_contents`): ``--overwrite``
    would delete them. None (an older version's folder, which lists nothing) passes: it is
    kept aside, not deleted (:func:`output_folder`)."""
    if foreign:
        named = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise InputError(f"holds files hifumotion did not write ({named}); --overwrite never deletes them — move them "
                         "out or choose a new folder", shown)


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


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True                  # another user's process, or no such number: not ours to judge
    return True


def remove_stale_staging(final: Path) -> list[Path]:
    """Remove the staging folders of runs into ``final`` that were killed before they could
    clean up (``.NAME.PID.*.partial`` whose process is gone); the removed folders are returned.
    Only folders of that form, which hifumotion made, are touched; a staging folder without a
    process number (an older version's) or of a live process stays."""
    removed = []
    try:
        candidates = list(final.parent.glob(f".{final.name}.*.partial"))
    except OSError:
        return removed
    for folder in candidates:
        middle = folder.name[len(final.name) + 2: -len(".partial")]
        pid_text = middle.split(".", 1)[0]
        if not pid_text.isdigit() or "." not in middle or not folder.is_dir() or folder.is_symlink():
            continue
        if not _process_alive(int(pid_text)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


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
    remove_stale_staging(final)
    try:
        # the staging folder's name carries its process: a later run can tell one whose run was
        # killed (SIGKILL, power loss) from one still being written
        staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.{os.getpid()}.", suffix=".partial", dir=final.parent))
    except OSError as exc:
        raise InputError(f"cannot create the output folder here ({exc.strerror or exc})", shown) from None
    follow_umask(staging, folder=True)
    try:
        yield staging
        _record_outputs(staging)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if final.exists() and not any(final.iterdir()):
        final.rmdir()                     # an empty folder the user made for the run
    if final.exists():
        foreign = foreign_contents(final)
        try:
            # a file put there while the run was going is not the run's to delete
            _refuse_foreign(foreign, shown)
        except InputError as exc:
            kept = final.with_name(f"{final.name}.new-{uuid.uuid4().hex[:8]}")
            staging.rename(kept)
            raise InputError(f"{exc.reason}; this run's output is in {kept}", shown) from None
        # a folder that does not list what hifumotion wrote may hold the user's files too: it is
        # kept aside, visible, rather than deleted
        unlisted = foreign is None
        retired = final.with_name(f"{final.name}.replaced-{uuid.uuid4().hex[:8]}" if unlisted
                                  else f".{final.name}.old-{uuid.uuid4().hex[:8]}")
        final.rename(retired)
        staging.rename(final)
        if not unlisted:
            shutil.rmtree(retired, ignore_errors=True)
        else:
            from hifumotion.console import console

            # said, not silent: the user's files may be among what was moved
            console.print(f"{shown}: its earlier contents (not listed as hifumotion's own, so perhaps yours) were "
                          f"moved to {retired}", highlight=False, soft_wrap=True)
    else:
        staging.rename(final)
