"""Configuration files: TOML and YAML into pydantic models, one-line errors naming the field."""

from __future__ import annotations

import tomllib
from pathlib import Path

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


def test_a_setting_is_changed_by_its_dotted_path_and_validated_as_any_configuration():
    from hifumotion.config import apply_settings, validate_config
    from hifumotion.workflow.pipeline import EstimationConfig

    data = apply_settings({"model": {"tissue_particles": 2000}},
                          ["model.creep.tolerance=0.01", "model.reduced.friction=false", "search_integrator=reduced",
                           "horizons_frames=[2, 4]"])
    s = validate_config(EstimationConfig, data)
    assert s.model.tissue_particles == 2000 and s.model.creep.tolerance == 0.01 and s.model.reduced.friction is False
    assert s.search_integrator == "reduced" and s.horizons_frames == [2, 4]
    assert type(s.model.creep).__name__ == "CreepSettings"          # the solver's own type, not a copy
    for items, word in ((["model.creep.tolerence=0.01"], "tolerence"), (["model.creep.tolerance=-1"], "greater than 0"),
                        (["model.creep.precision=quad"], "precision"), (["model.integrator=magic"], "integrator"),
                        (["model.tissue_particles=2.5"], "tissue_particles")):
        with pytest.raises(InputError, match=word):
            validate_config(EstimationConfig, apply_settings({}, items))
    for bad in ("noequals", "=3", "a..b=1"):
        with pytest.raises(InputError, match="KEY=VALUE"):
            apply_settings({}, [bad])
    with pytest.raises(InputError, match="not a table"):
        apply_settings({"model": {"integrator": "implicit"}}, ["model.integrator.x=1"])


def test_particles_is_the_models_tissue_particles_given_once():
    from hifumotion.config import validate_config
    from hifumotion.workflow.pipeline import EstimationConfig

    assert EstimationConfig(particles=600).model.tissue_particles == 600
    assert EstimationConfig().model.tissue_particles == 4399
    with pytest.raises(InputError, match="give it once"):
        validate_config(EstimationConfig, {"particles": 600, "model": {"tissue_particles": 700}})


def test_reading_a_setting_does_not_load_the_solvers():
    """A configuration is validated (and ``--help`` answers) without Numba, SciPy's solvers or
    the image readers: each package imports them on first use."""
    import subprocess
    import sys

    code = ("import sys; import hifumotion.workflow.pipeline, hifumotion.cli; "
            "heavy = [m for m in ('numba', 'scipy.sparse', 'SimpleITK', 'pydicom', 'hifumotion.creep.integrate') "
            "if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_a_bar_is_driven_by_a_force_or_by_its_travel_and_the_other_schedule_is_refused(tmp_path):
    from hifumotion.scene import BarConfig, Scene
    from hifumotion.particles.scene_system import build_scene

    bar = BarConfig(control="travel", schedule_times_s=[0.0, 2.0, 4.0], schedule_travel_mm=[0.0, 3.0, 1.0])
    travel = bar.travel_schedule()
    assert travel(1.0) == pytest.approx(1.5) and travel(3.0) == pytest.approx(2.0) and bar.breakpoints_s() == (0.0, 2.0, 4.0)
    assert BarConfig(control="travel", travel_mm=2.0, ramp_s=0.5).travel_schedule()(0.25) == pytest.approx(1.0)
    p = tmp_path / "scene.toml"
    for body, message in (
            ('control = "travel"\nschedule_times_s = [0.0, 1.0]\nschedule_force_n = [0.0, 0.2]\n', "schedule_force_n does not drive"),
            ('schedule_times_s = [0.0, 1.0]\nschedule_travel_mm = [0.0, 2.0]\n', "schedule_travel_mm does not drive"),
            ('control = "travel"\nschedule_times_s = [0.0, 1.0]\nschedule_travel_mm = [0.0, -2.0]\n', "must be ≥ 0"),
            ('control = "push"\n', "control")):
        p.write_text("[bar]\n" + body)
        with pytest.raises(InputError, match=message):
            load_config(p, Scene)
    # the particle path's bar is pushed by a force: a driven one is refused by name, not run wrong
    with pytest.raises(InputError, match="bar.control"):
        build_scene(Scene(bar=bar))


def test_setup_json_carries_a_driven_bars_travel_and_the_model_is_driven_by_it():
    """A driven bar's stage program is the operator's to know: ``setup.json``'s push holds its
    travel (not a force shape), and the bar the model is built with is driven by it."""
    from hifumotion.observed.setup import PushSchedule
    from hifumotion.scene import BarConfig

    push = PushSchedule(control="travel", shape="piecewise_linear", times_s=[0.0, 2.0, 6.0], travel_mm=[0.0, 1.0, 4.0])
    bar = BarConfig(**push.schedule(0.3))
    assert bar.control == "travel" and bar.travel_schedule()(4.0) == pytest.approx(2.5)
    with pytest.raises(ValueError, match="must be a bar's stage|travel control needs"):
        PushSchedule(control="travel", shape="ramp_hold", ramp_s=1.0)
    with pytest.raises(ValueError, match="travel_mm is the schedule of a bar in travel control"):
        PushSchedule(shape="piecewise_linear", times_s=[0.0, 1.0], relative_force=[0.0, 1.0], travel_mm=[0.0, 1.0])
    with pytest.raises(ValueError, match="≥ 0 mm"):
        PushSchedule(control="travel", shape="piecewise_linear", times_s=[0.0, 1.0], travel_mm=[0.0, -1.0])


def test_driven_protocols_drive_the_bar_and_force_protocols_refuse_a_driven_one():
    from hifumotion.experiment.config import twin_config

    slide = twin_config("slide", {"protocol": {"peak_travel_mm": 4.0, "angle_deg": 30.0}})
    end = (slide.imaging.frames - 1) / slide.imaging.frame_rate_hz
    assert slide.bar.control == "travel" and slide.truth.solver == "finite_strain"
    assert slide.bar.travel_schedule()(end / 2) == pytest.approx(2.0)
    assert slide.bar.direction[0] == pytest.approx(0.5) and slide.bar.direction[1] == pytest.approx(-(3 ** 0.5) / 2)
    stops = twin_config("slide", {"protocol": {"peak_travel_mm": 4.0, "ramp_s": 6.0}})
    assert [stops.bar.travel_schedule()(t) for t in (3.0, 6.0, 9.0)] == pytest.approx([2.0, 4.0, 4.0])
    assert 6.0 in stops.bar.breakpoints_s()
    with pytest.raises(InputError, match="protocol.ramp_s"):
        twin_config("slide", {"protocol": {"ramp_s": 30.0}})
    back = twin_config("drive_release", {"protocol": {"peak_travel_mm": 2.0, "ramp_s": 1.0, "hold_s": 3.0}})
    travel = back.bar.travel_schedule()
    assert [travel(t) for t in (0.5, 2.0, 4.5, 6.0)] == pytest.approx([1.0, 2.0, 1.0, 0.0])
    with pytest.raises(InputError, match="bar.control"):
        twin_config("paper", {"bar": {"control": "travel", "travel_mm": 2.0}})
    with pytest.raises(InputError, match="protocol.hold_s"):
        twin_config("drive_release", {"protocol": {"hold_s": 20.0}})
    # in to 4 mm over 4 s, back by 1.5 mm over 1.5 s, on to 7 mm by 90 % of the run, held
    rev = twin_config("slide_reverse")
    end = (rev.imaging.frames - 1) / rev.imaging.frame_rate_hz
    travel = rev.bar.travel_schedule()
    assert rev.bar.control == "travel" and rev.truth.solver == "finite_strain" and rev.physics.friction == 0.15
    assert [travel(t) for t in (2.0, 4.0, 4.75, 5.5, 0.9 * end, end)] == pytest.approx([2.0, 4.0, 3.25, 2.5, 7.0, 7.0])
    with pytest.raises(InputError, match="protocol.reverse_at_mm"):
        twin_config("slide_reverse", {"protocol": {"reverse_at_mm": 1.0}})   # not beyond what is drawn back
    with pytest.raises(InputError, match="protocol.ramp_s"):
        twin_config("slide_reverse", {"protocol": {"ramp_s": 8.0}})          # the drawing back past 90 %


def test_every_section_the_code_and_readme_cite_in_the_decisions_exists():
    """Each pointer into the decision record (its file name, a comma, a heading in quotes) in the
    package, the benchmarks, the tests or the README names one of its headings (or a prefix of
    one, as the sources shorten them)."""
    import re

    root = Path(__file__).resolve().parents[1]
    headings = [line[3:].strip() for line in (root / "docs" / "decisions.md").read_text().splitlines()
                if line.startswith("## ")]
    sources = [root / "README.md", *(root / "src").rglob("*.py"), *(root / "benchmarks").glob("*.py"),
               *(root / "tests").glob("*.py")]
    cited = {(p.name, m) for p in sources
             for m in re.findall(r'decisions\.md,\s*"([^"]+)"', " ".join(p.read_text().split()))}
    assert cited, "no citation found: the pattern no longer matches how the sources cite"
    missing = sorted((name, m) for name, m in cited if not any(h.startswith(m) for h in headings))
    assert not missing, missing



def test_every_section_of_the_decisions_is_listed_under_a_topic():
    """The record's "Topics" index lists each section once, by its heading, with a link whose
    anchor is the heading's (GitHub's rule: lower case, punctuation dropped, spaces to hyphens)."""
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "decisions.md").read_text()
    headings = [h for h in re.findall(r"^## (.+)$", text, flags=re.M) if h != "Topics"]
    index = text.split("## Topics", 1)[1].split("\n## ", 1)[0]
    links = re.findall(r"\[([^\]]+)\]\(#([^)]+)\)", index)
    assert sorted(name for name, _ in links) == sorted(headings)
    for name, anchor in links:
        assert anchor == re.sub(r"[^\w\- ]", "", name.lower()).replace(" ", "-")

def _settings_defaults() -> dict:
    """``(field, default) -> [(module:Class, literal?)]`` over every settings class in the package
    (pydantic models and dataclasses named *Settings/*Config/*Setup/…), read from the source."""
    import ast
    import collections

    import hifumotion

    root = Path(hifumotion.__file__).parent
    found = collections.defaultdict(list)
    for path in root.rglob("*.py"):
        if "cli" in path.parts:
            continue
        for cls in (n for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.ClassDef)):
            bases = [ast.unparse(b) for b in cls.bases]
            decorated = any(ast.unparse(d).startswith("dataclass") for d in cls.decorator_list)
            if not (any(b in ("ConfigModel", "BaseModel") or b.endswith("Model") for b in bases)
                    or decorated and cls.name.endswith(("Settings", "Config", "Setup", "Geometry", "Schedule"))):
                continue
            for statement in cls.body:
                if not (isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)
                        and statement.value is not None):
                    continue
                value = statement.value
                if isinstance(value, ast.Call) and ast.unparse(value.func) in ("Field", "field"):
                    keywords = {k.arg: k.value for k in value.keywords}
                    value = value.args[0] if value.args else keywords.get("default")
                    if value is None:
                        continue
                try:
                    default, literal = repr(ast.literal_eval(value)), True
                except ValueError:
                    default, literal = ast.unparse(value), False
                found[(statement.target.id, default)].append((f"{path.relative_to(root)}:{cls.name}", literal))
    return found


def test_each_setting_default_is_written_once():
    """A setting that two classes share (a scene's and a setup's bar radius, the twin's and the
    fitted model's mass scaling, the fast path's and its reduced model's tolerance) takes its
    default from one home — a named constant or the other class — so the two cannot drift apart.
    A repeated literal default of a field with the same name fails here. Seeds are each stage's
    own random stream, not one setting."""
    own_meaning = {"seed"}
    repeats = {key: where for key, where in _settings_defaults().items()
               if key[0] not in own_meaning and key[1] not in ("None", "True", "False")
               and sum(literal for _, literal in where) > 1}
    assert repeats == {}


def test_the_settings_walk_sees_the_settings_it_checks():
    """The walk above finds the classes it is meant to check (so an empty answer means no repeat,
    not no classes): the scene's bar, the setup's bar, the fast path's and the fitted model's."""
    seen = {where for group in _settings_defaults().values() for where, _ in group}
    for cls in ("scene/config.py:BarConfig", "observed/setup.py:BarSetup", "creep/settings.py:CreepSettings",
                "creep/settings.py:ReducedSettings", "estimation/settings.py:ModelSettings",
                "estimation/settings.py:CalibrationSettings", "experiment/config.py:TruthConfig"):
        assert cls in seen


def test_the_bloom_rule_defaults_to_the_reconstructions_and_reads_yes_and_no_as_before():
    """``bloom_continuation`` names its rule; a yes/no written before the rules had names keeps its
    meaning (yes: the strip continued, by the image's edge where no reconstruction decides it)."""
    from hifumotion.workflow.pipeline import EstimationConfig

    assert EstimationConfig().bloom_continuation == "reconstruction"
    assert EstimationConfig(bloom_continuation=True).bloom_continuation == "image"
    assert EstimationConfig(bloom_continuation=False).bloom_continuation == "off"
    with pytest.raises(ValueError):
        EstimationConfig(bloom_continuation="sometimes")
