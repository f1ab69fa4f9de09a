"""Shared fixtures. Tests that use ``../shared/data`` skip cleanly when it is absent."""

from __future__ import annotations

import os
from pathlib import Path

# pytest-xdist runs one process per core: one Numba thread each (see hifumotion.particles._numba)
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture
def shared_data() -> Path:
    if not (SHARED_DATA / "ddti" / "init.json").is_file():
        pytest.skip("../shared/data is not present")
    return SHARED_DATA


@pytest.fixture
def shared_data_or_none() -> Path | None:
    """``../shared/data`` when present, else ``None`` (for tests that run either way)."""
    return SHARED_DATA if (SHARED_DATA / "ddti" / "init.json").is_file() else None


def disc(shape: tuple[int, int], cx: float, cy: float, r: float) -> np.ndarray:
    """Pixels whose centre is within ``r`` of ``(cx, cy)`` (x = column, y = row)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    return (cols - cx) ** 2 + (rows - cy) ** 2 <= r**2


@pytest.fixture(scope="session")
def small_twin(tmp_path_factory):
    """The small synthetic experiment (seed 1), generated once per test process: ``(folder, TwinResult)``."""
    from hifumotion.experiment import generate_twin, twin_config

    folder = tmp_path_factory.mktemp("small_twin")
    return folder, generate_twin(twin_config("small", seed=1), folder)
