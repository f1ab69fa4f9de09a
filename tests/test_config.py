"""Configuration files: TOML and YAML into pydantic models, one-line errors naming the field."""

from __future__ import annotations

import tomllib

import pytest

from hifumotion.config import ReadOptions, dump_toml, load_config
from hifumotion.errors import InputError


def test_toml_and_yaml_give_the_same_model(tmp_path):
    (tmp_path / "a.toml").write_text('path = "cine.dcm"\nspacing_mm = [0.2, 0.25]\nframe_interval_s = 0.1\n')
    (tmp_path / "a.yaml").write_text("path: cine.dcm\nspacing_mm: [0.2, 0.25]\nframe_interval_s: 0.1\n")
    a, b = load_config(tmp_path / "a.toml", ReadOptions), load_config(tmp_path / "a.yaml", ReadOptions)
    assert a == b and a.spacing_mm == (0.2, 0.25)


def test_errors_name_the_file_and_field(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('path = "x.png"\nspacing_mm = -1\n')
    with pytest.raises(InputError, match=r"bad.toml: field 'spacing_mm'"):
        load_config(p, ReadOptions)
    p.write_text('path = "x.png"\nspacing = 1\n')
    with pytest.raises(InputError, match=r"field 'spacing'.*[Ee]xtra"):
        load_config(p, ReadOptions)
    p.write_text("path = [unclosed\n")
    with pytest.raises(InputError, match="cannot parse"):
        load_config(p, ReadOptions)
    with pytest.raises(InputError, match="unsupported configuration format"):
        load_config(tmp_path / "x.ini", ReadOptions) if (tmp_path / "x.ini").write_text("") is not None else None


def test_dump_toml_reads_back_with_descriptions():
    model = ReadOptions(path="cine.dcm", spacing_mm=(0.2, 0.25), frame_interval_s=0.1)
    text = dump_toml(model)
    assert "# pixel size in mm" in text
    assert ReadOptions.model_validate(tomllib.loads(text)) == model
