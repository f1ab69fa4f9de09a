"""The twin's finite-element truth (:mod:`hifumotion.reference.creep_fe`) against closed forms."""

import math

import numpy as np
import pytest

pytest.importorskip("skfem")
pytest.importorskip("tetgen")

import trimesh  # noqa: E402

from hifumotion.reference.creep_fe import CreepFESettings, CreepingTissue, creep_reference  # noqa: E402


def _box(side_mm=10.0):
    box = trimesh.creation.box(extents=(side_mm,) * 3)
    box.apply_translation((20.0, side_mm / 2, 20.0))
    return box


def test_uniaxial_kelvin_voigt_creep_follows_the_closed_form():
    """ν = 0, β2 = 0 (μ = β1): a frictionless block under a held force creeps as
    ε(t) = σ/E (1 − exp(−E t / 2μ)) — the bar's advance is ε L."""
    box, e, mu, force = _box(), 1e4, 500.0, 0.01
    problem = CreepingTissue(box.vertices, box.faces, e, 0.0, mu, 0.0, 1e-3, (20.0, 12.0, 20.0), (0.0, -1.0, 0.0),
                             20.0, lambda t: force, (), gravity_m_s2=0.0, floor_friction=0.0, bar_friction=0.0,
                             max_volume_mm3=50.0)
    times = np.linspace(0.0, 0.5, 11)
    sol = creep_reference(problem, times, CreepFESettings(tolerance_mm=1e-5))
    exact = force / 1e-4 / e * 10.0 * (1 - np.exp(-times * e / (2 * mu)))
    assert np.allclose(sol.advance_mm[1:], exact[1:], rtol=2e-3)
    assert np.allclose(sol.force_n[1:], force)


def test_nonlinear_creep_ends_in_the_elastic_solution():
    """ν = 0.3 with Eq. 16's power-law μ: long after the push the frictionless block is the
    elastic one — shortened by F L / (E A), its sides out by ν ε w / 2."""
    box, e, nu, force = _box(), 1e4, 0.3, 0.01
    problem = CreepingTissue(box.vertices, box.faces, e, nu, 200.0, 0.5, 1e-2, (20.0, 12.0, 20.0), (0.0, -1.0, 0.0),
                             20.0, lambda t: force * min(t / 0.2, 1.0), (0.2,), gravity_m_s2=0.0, floor_friction=0.0,
                             bar_friction=0.0, max_volume_mm3=50.0)
    sol = creep_reference(problem, np.array([0.0, 5.0, 30.0]), CreepFESettings(tolerance_mm=1e-4, max_step_s=5.0))
    strain = force / 1e-4 / e
    assert sol.advance_mm[-1] == pytest.approx(strain * 10.0, rel=1e-3)
    side = sol.displacement_at(np.array([[25.0, 5.0, 20.0], [15.0, 5.0, 20.0]]))[-1]
    assert side[0, 0] - side[1, 0] == pytest.approx(nu * strain * 10.0, rel=1e-2)


def test_a_pushed_and_released_sphere_on_a_rough_floor():
    """A sphere pushed down, held and let go on a floor with friction: the bar takes its
    schedule's force, nothing sinks into the floor or the bar, and the Kelvin–Voigt solid
    creeps back towards where it rested once the force is gone."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    sphere.apply_scale(6.0)
    sphere.apply_translation((20.0, 6.0, 20.0))
    sphere.vertices[:, 1] = np.maximum(sphere.vertices[:, 1], 1.0)   # a flat face to rest on
    sphere.vertices[:, 1] -= 1.0

    def force(t):
        return float(np.interp(t, [0.0, 0.5, 1.0, 1.5], [0.0, 0.05, 0.05, 0.0]))

    problem = CreepingTissue(sphere.vertices, sphere.faces, 1.3e4, 0.45, 2e3, 0.5, 0.02, (20.0, 20.0, 20.0),
                             (0.0, -1.0, 0.0), 3.0, force, (0.5, 1.0, 1.5), water_line_mm=4.0,
                             floor_friction=0.5, bar_friction=0.5, max_volume_mm3=20.0)
    times = np.array([0.0, 0.5, 1.0, 1.5, 4.0])
    sol = creep_reference(problem, times, CreepFESettings(tolerance_mm=5e-3))
    assert np.allclose(sol.force_n, [force(t) for t in times], atol=1e-9)
    assert sol.stats["max_penetration_mm"] <= 1e-3
    rest = sol.displacement_m[0]
    pushed = np.abs(sol.displacement_m[2] - rest).max()
    after = np.abs(sol.displacement_m[-1] - rest).max()
    assert pushed > 0.05e-3 and after < 0.5 * pushed


def test_protocols_set_the_schedule_and_the_bar():
    from hifumotion.experiment.config import twin_config
    from hifumotion.experiment.twin import push_shape

    slow = twin_config("slow_push")
    assert slow.bar.schedule_times_s == [0.0, (slow.imaging.frames - 1) / slow.imaging.frame_rate_hz]
    assert slow.bar.schedule_force_n[-1] == pytest.approx(slow.protocol.peak_force_n)
    release = twin_config("push_release")
    assert release.bar.schedule_force_n[0] == release.bar.schedule_force_n[-1] == 0.0
    shape = push_shape(release.bar)
    assert shape.shape == "piecewise_linear" and max(shape.relative_force) == 1.0
    oblique = twin_config("oblique")
    tilt = math.degrees(math.acos(-oblique.bar.direction[1]))
    assert tilt == pytest.approx(oblique.protocol.angle_deg)
    assert twin_config("paper").bar.schedule_times_s is None


def test_push_change_changes_the_push_after_the_training_frames_and_setup_does_not_say_so():
    from hifumotion.errors import InputError
    from hifumotion.experiment.config import twin_config
    from hifumotion.experiment.twin import push_shape

    for factor in (0.0, 0.5, 1.8):   # lifted, lowered, raised
        cfg = twin_config("push_change", {"protocol": {"change_factor": factor, "change_at_s": 6.0}})
        force = cfg.bar.schedule()
        assert force(5.9) == pytest.approx(cfg.protocol.peak_force_n)
        assert force(9.0) == pytest.approx(factor * cfg.protocol.peak_force_n)
        # the operator's setup.json knows the ramp and the hold, not the change
        shape = push_shape(cfg.bar, cfg.protocol)
        assert shape.shape == "ramp_hold" and shape.ramp_s == cfg.bar.ramp_s
    with pytest.raises(InputError, match="change_at_s"):
        twin_config("push_change", {"protocol": {"change_at_s": 0.1}})


def test_a_piecewise_push_must_make_sense():
    from pydantic import ValidationError

    from hifumotion.observed.setup import PushSchedule

    with pytest.raises(ValidationError, match="same length"):
        PushSchedule(shape="piecewise_linear", times_s=[0.0, 1.0], relative_force=[0.0])
    with pytest.raises(ValidationError, match="increase"):
        PushSchedule(shape="piecewise_linear", times_s=[0.0, 0.0], relative_force=[0.0, 1.0])
    with pytest.raises(ValidationError, match="0 … 1"):
        PushSchedule(shape="piecewise_linear", times_s=[0.0, 1.0], relative_force=[0.0, 2.0])
