"""A segmentation dataset laid out like ``../shared/data/*``: ``images/``, ``masks/``, ``init.json``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

from hifumotion.contour import InitialContour, parse_init_entry
from hifumotion.errors import InputError
from hifumotion.io.init_json import read_init_json
from hifumotion.io.naming import RASTER_SUFFIXES, full_suffix, natural_key


@dataclass(frozen=True)
class DatasetItem:
    """One image of a dataset: its path, the expert mask's path (if any) and its init.json entry."""

    name: str
    image_path: Path
    mask_path: Path | None
    init: dict[str, Any]

    def initial_contour(self, kind: str | None = None) -> InitialContour:
        return parse_init_entry(self.init, kind, where=f"init.json[{self.name}]")


@dataclass(frozen=True)
class Dataset:
    """A folder of images with expert masks and rough initial contours."""

    root: Path
    items: tuple[DatasetItem, ...]

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self) -> Iterator[DatasetItem]:
        return iter(self.items)


def load_dataset(folder: str | Path, require_masks: bool = True) -> Dataset:
    """Index ``folder/images/*``, ``folder/masks/*`` (same names) and ``folder/init.json``.

    Images without an init.json entry are an error: every method must start
    from the same given contour.
    """
    root = Path(folder)
    images_dir, masks_dir, init_path = root / "images", root / "masks", root / "init.json"
    if not images_dir.is_dir():
        raise InputError("expected a dataset folder with images/, masks/ and init.json (no images/ folder)", root)
    init = read_init_json(init_path)
    images = sorted((p for p in images_dir.iterdir() if full_suffix(p) in RASTER_SUFFIXES), key=natural_key)
    if not images:
        raise InputError("no images", images_dir)
    items = []
    for img in images:
        mask = masks_dir / img.name
        if not mask.is_file():
            if require_masks:
                raise InputError(f"no expert mask for image {img.name}", masks_dir)
            mask = None
        if img.name not in init:
            raise InputError(f"no initial contour for image {img.name}", init_path)
        items.append(DatasetItem(img.stem, img, mask, init[img.name]))
    return Dataset(root, tuple(items))
