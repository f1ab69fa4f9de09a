"""Configuration files: pydantic models loaded from TOML or YAML.

Each stage's settings are a :class:`ConfigModel`; every field documents its
unit. :func:`load_config` reads a file into a model and turns validation
failures into one :class:`~hifumotion.errors.InputError` naming the file and
the field.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from hifumotion.errors import InputError
from hifumotion.io.structured import parse_text

M = TypeVar("M", bound=BaseModel)


class ConfigModel(BaseModel):
    """Base of every configuration model: unknown keys are errors, numbers finite, values validated on assignment."""

    # NaN and ±inf are refused in every number (a JSON "NaN" or a TOML "inf" is no setting)
    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


class ReadOptions(ConfigModel):
    """How to read a user's image file."""

    path: Path = Field(description="image file or folder (PNG/JPEG/TIFF, DICOM, NIfTI/MHA/NRRD, video)")
    spacing_mm: float | tuple[float, float] | None = Field(
        default=None, description="pixel size in mm, scalar or (row, col); overrides the file (needed for PNG, video)"
    )
    frame_interval_s: float | None = Field(default=None, gt=0, description="time between frames in seconds; overrides the file")
    kind: Literal["auto", "cine", "sweep"] = Field(default="auto", description="how to read the third axis of a 3D volume file")

    @field_validator("spacing_mm")
    @classmethod
    def _positive_spacing(cls, v):
        if v is None:
            return v
        values = (v, v) if isinstance(v, (int, float)) else v
        if any(x <= 0 for x in values):
            raise ValueError("pixel sizes must be positive (mm)")
        return v


def read_config_file(path: str | Path) -> dict[str, Any]:
    """The raw mapping in a ``.toml``, ``.yaml`` or ``.yml`` file."""
    from hifumotion.io.structured import read_structured

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".toml":
        data = read_structured(p, "toml", "configuration file")
    elif suffix in (".yaml", ".yml"):
        data = read_structured(p, "yaml", "configuration file") or {}
    else:
        from hifumotion.io.files import require_regular_file

        require_regular_file(p, "configuration file")
        raise InputError(f"unsupported configuration format '{suffix}'; expected .toml, .yaml or .yml", p)
    if not isinstance(data, dict):
        raise InputError("expected a table of settings at the top level", p)
    return data


def validate_config(model: type[M], data: dict[str, Any], source: str | Path = "config") -> M:
    """``model`` built from ``data``; a validation error becomes one line naming the field."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        more = f" (and {exc.error_count() - 1} more problem(s))" if exc.error_count() > 1 else ""
        raise InputError(f"field '{where}': {err['msg']}{more}", source) from None


def apply_settings(data: dict[str, Any], items: list[str] | None, option: str = "--set") -> dict[str, Any]:
    """``data`` with each ``KEY=VALUE`` of ``items`` set: ``KEY`` a dotted path into the nested
    tables (``model.creep.tolerance``), ``VALUE`` read as a TOML value (``0.01``, ``true``,
    ``[1, 2]``, ``"text"``; a bare word is text). The result is validated by the caller's
    model like any configuration, so a mistyped key or value is named there."""
    out = _copy_tables(data)
    for item in items or []:
        key, sep, text = item.partition("=")
        path = [part.strip() for part in key.split(".")]
        if not sep or not all(path):
            raise InputError(f"expected KEY=VALUE such as model.creep.tolerance=0.01, got {item[:60]!r}", option)
        try:
            value = parse_text(f"v = {text.strip()}", "toml", option)["v"]
        except InputError:
            value = text.strip()                # a bare word: text, as in model.integrator=reduced
        table = out
        for i, part in enumerate(path[:-1]):
            nxt = table.setdefault(part, {})
            if not isinstance(nxt, dict):
                raise InputError(f"{'.'.join(path[:i + 1])} is a value, not a table of settings ({item[:60]!r})",
                                 option)
            table = nxt
        table[path[-1]] = value
    return out


def _copy_tables(data: dict) -> dict:
    return {k: _copy_tables(v) if isinstance(v, dict) else v for k, v in data.items()}


def load_config(path: str | Path, model: type[M]) -> M:
    """Read a TOML/YAML file into ``model``; relative paths in it stay relative to the caller."""
    return validate_config(model, read_config_file(path), path)


def dump_toml(model: BaseModel) -> str:
    """A model as TOML text, each field preceded by its description as a comment."""
    lines: list[str] = []
    _dump_table(model, [], lines)
    return "\n".join(lines).strip() + "\n"


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _fields(model) -> list[tuple[str, str | None]]:
    """``(name, description)`` of a pydantic model's or a dataclass's fields (a dataclass's
    settings are documented in its docstring, not per field)."""
    if isinstance(model, BaseModel):
        return [(name, info.description) for name, info in type(model).model_fields.items()]
    return [(f.name, None) for f in dataclasses.fields(model)]


def _is_table(value) -> bool:
    return isinstance(value, BaseModel) or (dataclasses.is_dataclass(value) and not isinstance(value, type))


def _dump_table(model, prefix: list[str], lines: list[str]) -> None:
    nested = []
    for name, description in _fields(model):
        value = getattr(model, name)
        if _is_table(value):
            nested.append((name, value))
            continue
        if description:
            lines.append(f"# {description}")
        if value is None:
            lines.append(f"# {name} = (not set)")
        else:
            lines.append(f"{name} = {_toml_value(value.value if hasattr(value, 'value') else value)}")
    for name, value in nested:
        lines.append("")
        lines.append(f"[{'.'.join(prefix + [name])}]")
        if not isinstance(value, BaseModel) and type(value).__doc__:
            # a dataclass's settings: its docstring's first line, and where each is described
            lines.append(f"# {type(value).__doc__.strip().splitlines()[0]} "
                         f"(each setting: {type(value).__module__}.{type(value).__name__})")
        _dump_table(value, prefix + [name], lines)
