"""Reading JSON, TOML and YAML text a user gave: one place where each is parsed and checked.

Python's parsers recurse once per nesting level, so a file nested a few thousand levels
deep (``[[[[…]]]]``) ends in a ``RecursionError`` inside the parser, and one nested a few
hundred levels passes it and breaks whatever walks the result later. No setting of
hifumotion nests deeper than a handful of levels, so both become one
:class:`~hifumotion.errors.InputError` naming the file: the parser's recursion is caught,
and the parsed value is walked (without recursion) to :data:`MAX_DEPTH`.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from hifumotion.errors import InputError

#: Deepest nesting of lists and tables accepted (hifumotion's own files nest ≤ 5 levels).
MAX_DEPTH = 32

_FORMATS = {"json": "JSON", "toml": "TOML", "yaml": "YAML"}


def nesting_depth(value: Any, limit: int = MAX_DEPTH) -> int:
    """How deep ``value``'s lists and mappings nest (a scalar is 0), counted up to ``limit`` + 1
    (a stack, not recursion: the value may be deeper than Python's recursion limit)."""
    deepest = 0
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, (list, tuple)):
            children = item
        else:
            continue
        deepest = max(deepest, depth)
        if deepest > limit:
            return deepest
        stack.extend((child, depth + 1) for child in children)
    return deepest


def parse_text(text: str, kind: str, source: str | Path) -> Any:
    """``text`` parsed as ``kind`` (``"json"``, ``"toml"`` or ``"yaml"``); malformed or too
    deeply nested text is an :class:`InputError` naming ``source``."""
    import yaml

    name = _FORMATS[kind]
    try:
        if kind == "json":
            data = json.loads(text)
        elif kind == "toml":
            data = tomllib.loads(text)
        else:
            data = yaml.safe_load(text)
    except RecursionError:
        raise InputError(f"nested too deeply to be {name} settings (expected at most {MAX_DEPTH} levels)",
                         source) from None
    except (ValueError, yaml.YAMLError) as exc:      # JSONDecodeError and TOMLDecodeError are ValueErrors
        raise InputError(f"not valid {name} ({' '.join(str(exc).split())[:160]})", source) from None
    if nesting_depth(data) > MAX_DEPTH:
        raise InputError(f"nested more than {MAX_DEPTH} levels deep; expected {name} settings", source)
    return data


def read_structured(path: str | Path, kind: str, what: str) -> Any:
    """The parsed content of the regular file ``path`` (``what`` names it in errors)."""
    from hifumotion.io.files import require_regular_file

    p = require_regular_file(path, what)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"not UTF-8 text; expected a {_FORMATS[kind]} file ({what})", p) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", p) from None
    return parse_text(text, kind, p)


__all__ = ["MAX_DEPTH", "nesting_depth", "parse_text", "read_structured"]
