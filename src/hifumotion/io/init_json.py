"""``init.json``: the rough initial contours of a dataset (see ``../shared/data/README.md``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hifumotion.contour import InitialContour, parse_init_entry
from hifumotion.errors import InputError


def read_init_json(path: str | Path) -> dict[str, dict[str, Any]]:
    """The raw mapping ``image name → {"ellipse": {...}, "points": [...]}`` of an ``init.json``."""
    from hifumotion.io.structured import read_structured

    p = Path(path)
    data = read_structured(p, "json", "init.json")
    if not isinstance(data, dict):
        raise InputError("expected an object mapping image names to initial contours", p)
    return data


def load_initial_contours(path: str | Path, kind: str | None = None) -> dict[str, InitialContour]:
    """Every entry of an ``init.json`` as an :class:`~hifumotion.contour.Ellipse` or
    :class:`~hifumotion.contour.ClickedPoints` (``kind`` = ``"ellipse"``, ``"points"`` or
    ``None`` for the ellipse when both are given)."""
    p = Path(path)
    return {name: parse_init_entry(entry, kind, where=f"{p}[{name}]") for name, entry in read_init_json(p).items()}
