"""A twin read back from the folder :func:`~hifumotion.experiment.generate_twin` wrote, and the
twin that ships with the package.

:func:`read_twin` gives what a run on a twin needs — the observation a device's user has
(``observed/``) and the truth only scoring may read (``truth/``: the true sections of every frame
and sweep plane, ``parameters.json``, ``motion.json``) — without the minutes of its physics.
:func:`bundled_twin` is the folder of the twin made by ``hifumotion experiment --preset
push_change --seed 0`` that ``hifumotion demo`` runs on (its ``run_info.json`` names the command
and the version that made it; ``scripts/bundle_demo_twin.py`` makes it again).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hifumotion.errors import InputError
from hifumotion.experiment.config import TwinConfig
from hifumotion.observed import Observed

#: the preset and seed of the twin that ships with the package
BUNDLED_PRESET, BUNDLED_SEED = "slide_reverse", 0


@dataclass
class StoredTwin:
    """A twin's files in memory: what a run on it and its scoring read (arrays as in
    :class:`~hifumotion.experiment.TwinResult`)."""

    folder: Path                  # holds observed/ and truth/
    config: TwinConfig            # the settings it was made with (truth/parameters.json "config")
    observed: Observed            # observed/: what the device's user has
    frame_masks: np.ndarray       # bool (T, H, W): the true section of every frame
    sweep_masks: np.ndarray       # bool (S, H, W): the true section of every sweep plane
    parameters: dict              # truth/parameters.json
    motion: dict = field(default_factory=dict)    # truth/motion.json: centroid path (mm), area, checks

    @property
    def sweep(self) -> np.ndarray:
        """uint8 (S, H, W): the sweep's B-mode images."""
        return self.observed.sweep

    @property
    def pixel_mm(self) -> float:
        """The images' pixel size (mm)."""
        return float(self.observed.pixel_mm)


def _stack(folder: Path, prefix: str, count: int, shape: tuple[int, int]) -> np.ndarray:
    """The 0/255 PNG masks ``prefix*.png`` of ``folder`` (a sweep's end planes hold no tissue)."""
    import imageio.v3 as iio

    from hifumotion.io.writers import check_binary

    paths = sorted(folder.glob(f"{prefix}*.png"))
    if len(paths) != count:
        raise InputError(f"{len(paths)} {prefix}NNNN.png masks; the observation has {count}", folder)
    images = []
    for p in paths:
        try:
            image = iio.imread(p)
        except Exception as exc:
            raise InputError(f"cannot read as an image ({type(exc).__name__})", p) from None
        check_binary(image, p)
        images.append(image)
    masks = np.stack(images) > 0
    if masks.shape[1:] != shape:
        raise InputError(f"masks of {masks.shape[1]} × {masks.shape[2]} px; the images are {shape[0]} × {shape[1]}",
                         folder)
    return masks


def read_twin(folder: str | Path) -> StoredTwin:
    """The twin in ``folder`` (``observed/`` and ``truth/``, as ``hifumotion experiment`` writes them)."""
    from hifumotion.config import validate_config
    from hifumotion.io.structured import read_structured
    from hifumotion.observed import load_observed

    folder = Path(folder)
    truth = folder / "truth"
    if not (folder / "observed").is_dir() or not truth.is_dir():
        raise InputError("expected a twin folder holding observed/ and truth/ (hifumotion experiment's output)", folder)
    observed = load_observed(folder / "observed")
    parameters = read_structured(truth / "parameters.json", "json", "parameters.json")
    if not isinstance(parameters, dict) or not isinstance(parameters.get("config"), dict):
        raise InputError("expected the twin's settings under \"config\"", truth / "parameters.json")
    config = validate_config(TwinConfig, parameters["config"], truth / "parameters.json")
    shape = observed.frames.shape[1:]
    frames = _stack(truth / "frames", "frame_", len(observed.frames), shape)
    sweep = _stack(truth / "sweep", "slice_", len(observed.sweep), shape)
    motion_path = truth / "motion.json"
    motion = read_structured(motion_path, "json", "motion.json") if motion_path.is_file() else {}
    if not isinstance(motion, dict):
        raise InputError("expected a JSON object", motion_path)
    return StoredTwin(folder, config, observed, frames, sweep, parameters, motion)


def bundled_twin() -> Path:
    """The folder of the twin that ships with the package (preset :data:`BUNDLED_PRESET`, seed
    :data:`BUNDLED_SEED`)."""
    from importlib.resources import files

    folder = Path(str(files("hifumotion") / "data" / "demo_twin"))
    if not (folder / "observed" / "setup.json").is_file():
        raise InputError("the package's demo twin is missing (a broken install?); run hifumotion demo --regenerate",
                         folder)
    return folder


__all__ = ["BUNDLED_PRESET", "BUNDLED_SEED", "StoredTwin", "bundled_twin", "read_twin"]
