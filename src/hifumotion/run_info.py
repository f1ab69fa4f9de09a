"""``run_info.json``: what a run needs to be reproduced and understood.

Every command that writes an output folder records the resolved
configuration, the seed, the package versions, the git commit of the source
tree (if any), the command line, and the wall time of each stage.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Iterator

from hifumotion.io.writers import write_json

#: Packages whose versions are recorded.
RECORDED_PACKAGES = (
    "hifumotion", "numpy", "scipy", "numba", "scikit-image", "SimpleITK", "pydicom", "imageio", "av",
    "tifffile", "pydantic", "typer", "rich", "matplotlib", "trimesh", "meshio", "dask", "distributed",
    "cma", "filterpy",
)


def package_versions() -> dict[str, str]:
    """Installed versions of the packages that shape a result (absent ones are left out)."""
    out = {"python": platform.python_version()}
    for name in RECORDED_PACKAGES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


def git_commit(path: Path | None = None) -> dict[str, Any] | None:
    """``{"commit": sha, "dirty": bool}`` of the git tree holding ``path`` (default: this package), or None."""
    where = Path(path or Path(__file__).parent)
    try:
        sha = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5)
        if sha.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5)
        return {"commit": sha.stdout.strip(), "dirty": bool(dirty.stdout.strip())}
    except (OSError, subprocess.SubprocessError):
        return None


@dataclass
class RunRecord:
    """Collects a run's configuration, seed and stage timings; :meth:`write` saves ``run_info.json``."""

    command: str
    config: dict[str, Any] = field(default_factory=dict)
    seed: int | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    started: float = field(default_factory=time.time)

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time a stage: ``with record.stage("segment"): ...`` (seconds, wall clock; repeats add up)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings_s[name] = self.timings_s.get(name, 0.0) + time.perf_counter() - t0

    def as_dict(self) -> dict[str, Any]:
        now = time.time()
        return {
            "command": self.command,
            "argv": sys.argv,
            "started": _dt.datetime.fromtimestamp(self.started, _dt.timezone.utc).isoformat(),
            "finished": _dt.datetime.fromtimestamp(now, _dt.timezone.utc).isoformat(),
            "wall_time_s": round(now - self.started, 4),
            "seed": self.seed,
            "config": self.config,
            "timings_s": {k: round(v, 4) for k, v in self.timings_s.items()},
            "versions": package_versions(),
            "git": git_commit(),
            "platform": {"system": platform.system(), "machine": platform.machine(), "processor": platform.processor()},
            **self.extra,
        }

    def write(self, folder: str | Path) -> Path:
        """Write ``folder/run_info.json`` atomically and return its path."""
        return write_json(Path(folder) / "run_info.json", self.as_dict())
