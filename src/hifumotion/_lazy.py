"""Names a package exports, imported on first use (PEP 562).

The solvers, the image readers and SciPy's interpolation take seconds to import; a command's
``--help`` or a configuration's validation needs none of them. A package lists which module
defines each name it exports and gets its ``__getattr__`` from :func:`lazy_exports`.
"""

from __future__ import annotations

import importlib
from typing import Callable


def lazy_exports(package: str, where: dict[str, str]) -> Callable[[str], object]:
    """``package``'s ``__getattr__``: ``name`` from the module ``where[name]`` (relative to the
    package, or absolute when it starts with ``hifumotion.``), imported when first asked for."""
    def __getattr__(name: str):
        if name in where:
            module = where[name] if where[name].startswith("hifumotion.") else f"{package}.{where[name]}"
            return getattr(importlib.import_module(module), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


__all__ = ["lazy_exports"]
