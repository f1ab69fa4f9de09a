"""Reading JSON, TOML and YAML text a user gave: one place where each is parsed and checked.

Python's parsers recurse once per nesting level, so a file nested a few thousand levels
deep (``[[[[…]]]]``) ends in a ``RecursionError`` inside the parser, and one nested a few
hundred levels passes it and breaks whatever walks the result later. No setting of
hifumotion nests deeper than a handful of levels, so both become one
:class:`~hifumotion.errors.InputError` naming the file: the parser's recursion is caught,
and the parsed value is walked (without recursion) to :data:`MAX_DEPTH`. YAML aliases share
nodes, so a few lines can stand for billions of values ("billion laughs") or for a node inside
itself: the walk visits each node once, and a value that expands past :data:`MAX_VALUES` or
contains itself is refused the same way.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from hifumotion.errors import InputError

#: Deepest nesting of lists and tables accepted (hifumotion's own files nest ≤ 5 levels).
MAX_DEPTH = 32
#: Most values a settings file may hold once its YAML aliases are expanded (hifumotion's own
#: files hold thousands at most; a "billion laughs" expands nine aliases nine deep to 9⁹)
MAX_VALUES = 1_000_000

_FORMATS = {"json": "JSON", "toml": "TOML", "yaml": "YAML"}


def nesting_depth(value: Any, limit: int = MAX_DEPTH) -> int:
    """How deep ``value``'s lists and mappings nest (a scalar is 0), counted up to ``limit`` + 1
    (see :func:`value_shape`)."""
    return value_shape(value, limit)[0]


def value_shape(value: Any, depth_limit: int = MAX_DEPTH, size_limit: int = MAX_VALUES) -> tuple[float, float]:
    """``(depth, values)``: how deep ``value``'s lists and mappings nest and how many values it
    holds once every shared node is counted where it is used (YAML aliases share nodes), each
    counted until its limit is passed. A node that contains itself (a YAML alias to its own
    anchor) is infinitely deep.

    Each node is walked once (memoised by identity, without recursion: the value may be deeper
    than Python's recursion limit), so ``a: &a [...]`` nested nine aliases deep costs nine
    nodes, not 9⁹."""
    memo: dict[int, tuple[float, float]] = {}
    open_nodes: set[int] = set()

    def children(item):
        return list(item.values()) if isinstance(item, dict) else list(item)

    def container(item) -> bool:
        return isinstance(item, (dict, list, tuple))

    if not container(value):
        return 0, 1
    stack: list[tuple[Any, bool]] = [(value, False)]
    while stack:
        item, finished = stack.pop()
        key = id(item)
        if finished:
            kids = [memo[id(c)] for c in children(item) if container(c)]
            plain = sum(1 for c in children(item) if not container(c))
            depth = 1 + max((d for d, _ in kids), default=0)
            size = 1 + plain + sum(n for _, n in kids)
            memo[key] = (depth, size)
            open_nodes.discard(key)
            if depth > depth_limit or size > size_limit:
                return depth, size
            continue
        if key in memo:
            continue
        if key in open_nodes:         # met again inside itself: it contains itself
            return float("inf"), float("inf")
        open_nodes.add(key)
        stack.append((item, True))
        stack.extend((c, False) for c in children(item) if container(c) and id(c) not in memo)
    return memo[id(value)]


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
    depth, size = value_shape(data)
    if depth > MAX_DEPTH:
        what = "refers to itself (a YAML alias inside its own anchor)" if depth == float("inf") else \
            f"nested more than {MAX_DEPTH} levels deep"
        raise InputError(f"{what}; expected {name} settings", source)
    if size > MAX_VALUES:
        raise InputError(f"holds more than {MAX_VALUES:,} values once its aliases are expanded; expected {name} "
                         "settings", source)
    return data


def read_structured(path: str | Path, kind: str, what: str) -> Any:
    """The parsed content of the regular file ``path`` (``what`` names it in errors)."""
    from hifumotion.io.files import require_regular_file

    p = require_regular_file(path, what)
    try:
        text = p.read_text(encoding="utf-8-sig")     # a byte-order mark (Windows editors) is no content
    except UnicodeDecodeError:
        raise InputError(f"not UTF-8 text; expected a {_FORMATS[kind]} file ({what})", p) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", p) from None
    return parse_text(text, kind, p)


__all__ = ["MAX_DEPTH", "MAX_VALUES", "nesting_depth", "parse_text", "read_structured", "value_shape"]
