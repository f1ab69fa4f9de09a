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
    with pytest.raises(InputError, match="not valid TOML"):
        load_config(p, ReadOptions)
    with pytest.raises(InputError, match="unsupported configuration format"):
        load_config(tmp_path / "x.ini", ReadOptions) if (tmp_path / "x.ini").write_text("") is not None else None


def test_nan_and_infinity_are_no_setting(tmp_path):
    # TOML spells them nan and inf, JSON NaN and Infinity: each is refused, naming the field
    p = tmp_path / "bad.toml"
    p.write_text('path = "x.png"\nframe_interval_s = inf\n')
    with pytest.raises(InputError, match=r"field 'frame_interval_s'.*finite"):
        load_config(p, ReadOptions)
    p.write_text('path = "x.png"\nspacing_mm = [0.2, nan]\n')
    with pytest.raises(InputError, match=r"field 'spacing_mm"):
        load_config(p, ReadOptions)


def test_a_setup_json_with_nan_or_infinity_is_refused(tmp_path):
    from hifumotion.observed.setup import read_setup

    # the first field that is wrong is named (the rest of the file is left out: one line)
    text = ('{"frame_interval_s": 0.05, "frames": 10, "imaging": {"image_shape": [64, 64], "pixel_mm": 0.2, '
            '"row0_col0_mm": [X, 0.0], "frames_plane_z_mm": 0.0}}')
    for value in ("NaN", "Infinity", "-Infinity"):
        (tmp_path / "setup.json").write_text(text.replace("X", value))
        with pytest.raises(InputError, match=r"setup.json: field 'imaging.row0_col0_mm.0': .*finite"):
            read_setup(tmp_path / "setup.json")


def test_dump_toml_reads_back_with_descriptions():
    model = ReadOptions(path="cine.dcm", spacing_mm=(0.2, 0.25), frame_interval_s=0.1)
    text = dump_toml(model)
    assert "# pixel size in mm" in text
    assert ReadOptions.model_validate(tomllib.loads(text)) == model
