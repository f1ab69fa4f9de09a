"""Settings of the synthetic experiment (``twin.toml``), with the presets ``default`` and ``small``.

Every quantity carries its unit in its name or description; ``hifumotion
experiment --print-config`` prints them all. A ``twin.toml`` overrides any of
them on top of the chosen preset, e.g.::

    seed = 3

    [tissue]
    youngs_modulus_pa = 9000.0

    [bar]
    force_n = 0.2
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hifumotion.config import ConfigModel, read_config_file, validate_config
from hifumotion.errors import InputError
from hifumotion.resources import MAX_FRAMES
from hifumotion.scene import BarConfig, PhysicsConfig, TankConfig, TissueMaterial
from hifumotion.numerics import (CFL, QUASI_STATIC_MASS_SCALING, QUASI_STATIC_MAX_STEP_S, SUPPORT_FACTOR,
                                  TRUTH_STEP_S, TRUTH_TOLERANCE_MM)
from hifumotion import paper


class BlobConfig(ConfigModel):
    size_mm: tuple[float, float, float] = Field((30.0, 18.0, 24.0), description="approximate extent of the tissue sample (x, height y, z) in mm")
    irregularity: float = Field(0.12, ge=0, le=0.4, description="relative height of the sample's lumps (0: an ellipsoid)")
    lobes: int = Field(6, ge=1, le=30, description="number of random waves making the lumps")
    bottom_cut: float = Field(0.2, ge=0, lt=0.5, description="fraction of the ellipsoid's height cut off flat: the face the sample rests on")

    @field_validator("size_mm")
    @classmethod
    def _a_sample(cls, v):
        # a sample is seen by a probe of ~1 mm resolution and sits in a tank of ~10 cm: below 1 mm it
        # has no image and its particle spacing makes the tank's water unbounded work; above 1 m no tank holds it
        if not all(np.isfinite(s) and 1.0 <= s <= 1000.0 for s in v):
            raise ValueError(f"each extent of the sample must be 1 … 1000 mm, got {list(v)}")
        return v


class ResolutionConfig(ConfigModel):
    model_tissue_particles: int = Field(paper.TISSUE_PARTICLES, ge=100, description="tissue particles of the model that will be fitted (the paper: 4,399)")
    truth_particle_factor: float = Field(2.0, ge=1.0, description="the truth has this many times the fitted model's particles (≥ 2 for an honest test)")
    support_factor: float = Field(SUPPORT_FACTOR, ge=1.5, le=3.0, description="kernel support radius h in particle spacings")


#: Longest cine a twin simulates (s).
MAX_CINE_S = 600.0


class ImagingConfig(ConfigModel):
    frames: int = Field(200, ge=2, le=MAX_FRAMES, description="number of B-mode frames of the imaging plane while the bar pushes")
    frame_rate_hz: float = Field(20.0, ge=1e-3, le=1e4, description="imaging frame rate in Hz (frame interval = 1/rate s; 0.001 … 10,000 Hz)")
    pixel_mm: float = Field(0.2, gt=0, description="pixel size of every image in mm (square pixels)")
    width_mm: float = Field(44.0, gt=0, description="lateral extent of the images in mm")
    depth_mm: float = Field(40.0, gt=0, description="depth extent of the images in mm, from the probe's face")
    probe_standoff_mm: float = Field(8.0, ge=0, description="water path from the probe face (below the tank's membrane floor, looking up) to the floor in mm")
    sweep_gap_mm: float = Field(1.0, gt=0, description="distance between the parallel planes of the spatial sweep in mm")
    sweep_margin_mm: float = Field(2.0, ge=0, description="the sweep starts and ends this far beyond the tissue in mm")
    center_frequency_mhz: float = Field(3.5, gt=0, le=100, description="centre frequency of the imaging probe in MHz (at most 100)")
    axial_fwhm_mm: float = Field(0.45, gt=0, description="axial resolution (FWHM of the pulse-echo envelope) in mm")
    lateral_fwhm_mm: float = Field(1.1, gt=0, description="lateral resolution at the focus (FWHM) in mm")
    dynamic_range_db: float = Field(50.0, gt=0, le=200, description="log-compression dynamic range in dB (at most 200)")
    tissue_echogenicity: float = Field(1.0, gt=0, description="backscatter power of the tissue (relative)")
    echo_texture: float = Field(0.35, ge=0, lt=1, description="relative variation of the tissue's backscatter (smooth, 1.5 mm scale)")
    water_echogenicity: float = Field(1e-4, ge=0, description="backscatter power of the water (relative; degassed water is nearly anechoic, −40 dB)")
    floor_echogenicity: float = Field(5.0, ge=0, description="backscatter power of the tank's membrane floor (relative)")
    bar_echogenicity: float = Field(30.0, ge=0, description="backscatter power of the metal bar (relative)")

    @model_validator(mode="after")
    def _a_cine_of_minutes(self):
        # the twin simulates the whole cine; a quasi-static push over more than ten minutes is not
        # this tool's experiment, and its physics would run for hours before anyone saw a frame
        span = (self.frames - 1) / self.frame_rate_hz
        if span > MAX_CINE_S:
            raise ValueError(f"frames / frame_rate_hz make a cine of {span:.3g} s; at most {MAX_CINE_S:g} s")
        return self


class ClinicianConfig(ConfigModel):
    points: int = Field(16, ge=4, description="points a clinician clicks around the tissue on the first frame")
    error_mm: float = Field(0.6, ge=0, le=10, description="standard deviation of each click's distance from the true boundary in mm (at most 10)")


class TwinRunConfig(ConfigModel):
    mass_scaling: float = Field(QUASI_STATIC_MASS_SCALING, ge=1.0, description="inertia multiplier of the quasi-static push (weights unchanged; see docs/decisions.md for the tolerance)")
    settle_s: float | None = Field(None, ge=0, description="damped settling under gravity before t = 0 in s; default: 6 periods' worth (6/ω) of the tissue's slowest elastic mode under the mass scaling")
    settle_damping_per_s: float | None = Field(None, ge=0, description="velocity damping while settling in 1/s; default: 2ω, critical damping of that mode")
    cfl: float = Field(CFL, gt=0, le=1.0, description="safety factor on the time step")
    max_step_s: float = Field(QUASI_STATIC_MAX_STEP_S, gt=0, description="largest time step in s")
    particle_frames_every: int = Field(5, ge=1, description="write every n-th frame's particles as VTU (all frames go to tissue_trajectory.npz)")


class TruthConfig(ConfigModel):
    solver: Literal["finite_elements", "finite_strain", "particles"] = Field("finite_elements", description="what computes the truth: finite_elements (small strain: P2 tetrahedra, BDF2, Coulomb contacts; independent of the fitted voxel model), finite_strain (the same tetrahedra at finite strain on FElupe: neo-Hookean, Eq. 16's viscosity, frictional contacts; for pushes that strain the tissue beyond ~10 %) or particles (the explicit SPH path of Eq. 8–20)")
    max_volume_mm3: float = Field(8.0, gt=0, description="finite elements: largest tetrahedron in mm³")
    surface_subdivisions: int = Field(3, ge=2, le=5, description="finite elements: icosphere subdivisions of the sample's surface (3: 1,280 triangles)")
    tolerance_mm: float = Field(TRUTH_TOLERANCE_MM, gt=0, description="finite elements: local error of a time step in mm")
    step_s: float = Field(TRUTH_STEP_S, gt=0, le=1.0, description="finite strain: the largest backward-Euler step in s")


class ProtocolConfig(ConfigModel):
    """How the bar pushes; sets the bar's schedule and direction (the preset names a therapy's protocol)."""

    name: Literal["paper", "slow_push", "push_release", "oblique", "push_change", "slide", "slide_reverse", "drive_release", "custom"] = Field("paper", description="paper: ramp then held; slow_push: the force rises all along; push_release: up, hold, down; oblique: ramp then held with the bar tilted; push_change: ramp then held, then the operator raises, lowers or lifts the push unannounced (setup.json tells only the ramp and hold); slide: the bar, tilted by angle_deg, driven along its axis at a steady rate over ramp_s (default: the whole run), then held (travel control: the sample slides on the floor, and stops); slide_reverse: the tilted bar driven in to reverse_at_mm over ramp_s, drawn back by reverse_by_mm over reverse_s, then driven on to peak_travel_mm by 90 % of the run and held (travel control: friction holds the sample where the bar left it until the bar comes back to it); drive_release: the bar driven in over ramp_s, held hold_s, drawn back over ramp_s (travel control: the tissue recovers); custom: the [bar] section as given")
    peak_force_n: float | None = Field(None, gt=0, description="the largest force in N (default: bar.force_n)")
    peak_travel_mm: float | None = Field(None, gt=0, description="slide, slide_reverse, drive_release: the bar's largest travel along its axis in mm (default: bar.travel_mm)")
    ramp_s: float | None = Field(None, ge=0, description="paper/oblique/push_release/drive_release: duration of the rise in s (default: bar.ramp_s; push_release, drive_release: 1.5 s); slide: how long the bar is driven before it stops (default: the whole run); slide_reverse: how long the first drive in lasts (default: 40 % of the run)")
    reverse_at_mm: float | None = Field(None, gt=0, description="slide_reverse: the travel in mm at which the bar turns back (default: 4/7 of peak_travel_mm)")
    reverse_by_mm: float = Field(1.5, gt=0, description="slide_reverse: how far the bar is drawn back, in mm")
    reverse_s: float = Field(1.5, gt=0, description="slide_reverse: how long the drawing back takes, in s")
    hold_s: float = Field(3.0, ge=0, description="push_release: time held at the peak in s")
    angle_deg: float = Field(25.0, ge=0, lt=60, description="oblique, slide: tilt of the bar from the vertical in degrees (in the x–y plane, pushing towards +x)")
    change_at_s: float | None = Field(None, gt=0, description="push_change: when the push starts to change, in s (default: 60 % of the run, after the paper's training frames)")
    change_factor: float = Field(1.6, ge=0, le=5, description="push_change: the force after the change over the force before (0: the bar lifted; below 1: lowered; above 1: raised)")
    change_ramp_s: float = Field(0.3, ge=0, description="push_change: how long the change takes, in s")


def apply_protocol(cfg: "TwinConfig") -> "TwinConfig":
    """The bar's schedule and direction as the protocol says (``custom`` leaves the bar as it is)."""
    import math

    p = cfg.protocol
    if p.name == "custom":
        return cfg
    end = (cfg.imaging.frames - 1) / cfg.imaging.frame_rate_hz
    if p.name in DRIVEN_PROTOCOLS:
        return cfg.model_copy(update={"bar": _driven_bar(cfg, p, end)})
    if cfg.bar.control == "travel":
        raise InputError(f"protocol {p.name!r} pushes its bar by a force; a bar in travel control takes its "
                         f"schedule from [bar] (protocol.name = custom) or a driven protocol "
                         f"({', '.join(DRIVEN_PROTOCOLS)})", "bar.control")
    bar = cfg.bar.model_dump()
    peak = p.peak_force_n if p.peak_force_n is not None else cfg.bar.force_n
    bar.update(force_n=peak, schedule_times_s=None, schedule_force_n=None, direction=(0.0, -1.0, 0.0))
    if p.name in ("paper", "oblique"):
        bar["ramp_s"] = p.ramp_s if p.ramp_s is not None else cfg.bar.ramp_s
    elif p.name == "push_change":
        ramp = p.ramp_s if p.ramp_s is not None else cfg.bar.ramp_s
        at = p.change_at_s if p.change_at_s is not None else 0.6 * end
        if not ramp < at < end:
            raise InputError(f"must lie between the ramp's end ({ramp:g} s) and the run's "
                             f"({end:g} s), got {at:g}", "protocol.change_at_s")
        done = min(at + p.change_ramp_s, end) if p.change_ramp_s > 0 else at + 1e-6
        # the announced part (a ramp, then held) is bar.ramp_s and force_n: setup.json's push
        bar.update(ramp_s=ramp, schedule_times_s=[0.0, ramp, at, done],
                   schedule_force_n=[0.0, peak, peak, peak * p.change_factor])
    elif p.name == "slow_push":
        bar.update(schedule_times_s=[0.0, end], schedule_force_n=[0.0, peak])
    elif p.name == "push_release":
        ramp = p.ramp_s if p.ramp_s is not None else 1.5
        up, down = ramp, ramp + p.hold_s
        bar.update(schedule_times_s=[0.0, up, down, down + ramp], schedule_force_n=[0.0, peak, peak, 0.0])
    if p.name == "oblique":
        a = math.radians(p.angle_deg)
        bar["direction"] = (math.sin(a), -math.cos(a), 0.0)
    bar = BarConfig(**bar)
    return cfg.model_copy(update={"bar": bar})


#: protocols whose bar is driven (travel control): its travel given, its force a result
DRIVEN_PROTOCOLS = ("slide", "slide_reverse", "drive_release")


def _driven_bar(cfg: "TwinConfig", p: ProtocolConfig, end_s: float) -> BarConfig:
    """The bar of a driven protocol: its travel schedule and direction."""
    import math

    peak = p.peak_travel_mm if p.peak_travel_mm is not None else cfg.bar.travel_mm
    if not peak > 0:
        raise InputError("a driven protocol needs the bar's travel: set protocol.peak_travel_mm or bar.travel_mm (mm)",
                         "protocol.peak_travel_mm")
    bar = cfg.bar.model_dump()
    bar.update(control="travel", travel_mm=peak, schedule_force_n=None, direction=(0.0, -1.0, 0.0))
    if p.name == "slide":
        a = math.radians(p.angle_deg)
        stop = end_s if p.ramp_s is None else p.ramp_s
        if not 0.0 < stop <= end_s:
            raise InputError(f"a slide's drive must last more than 0 s and end within the run ({end_s:g} s), got {stop:g} s",
                             "protocol.ramp_s")
        times, travel = ([0.0, stop], [0.0, peak]) if stop == end_s else ([0.0, stop, end_s], [0.0, peak, peak])
        bar.update(schedule_times_s=times, schedule_travel_mm=travel, direction=(math.sin(a), -math.cos(a), 0.0))
    elif p.name == "slide_reverse":
        a = math.radians(p.angle_deg)
        turn = p.ramp_s if p.ramp_s is not None else 0.4 * end_s
        back = turn + p.reverse_s
        on = 0.9 * end_s
        if not 0.0 < turn < back < on:
            raise InputError(f"slide_reverse's drive in ({turn:g} s) and drawing back ({p.reverse_s:g} s) must end "
                             f"before 90 % of the run ({on:g} s)", "protocol.ramp_s")
        at = p.reverse_at_mm if p.reverse_at_mm is not None else 4.0 / 7.0 * peak
        if not (p.reverse_by_mm < at < peak):
            raise InputError(f"slide_reverse turns back at {at:g} mm: it must lie between the distance drawn back "
                             f"({p.reverse_by_mm:g} mm) and the peak travel ({peak:g} mm)", "protocol.reverse_at_mm")
        bar.update(schedule_times_s=[0.0, turn, back, on, end_s],
                   schedule_travel_mm=[0.0, at, at - p.reverse_by_mm, peak, peak],
                   direction=(math.sin(a), -math.cos(a), 0.0))
    else:   # drive_release
        ramp = p.ramp_s if p.ramp_s is not None else 1.5
        up, down = ramp, ramp + p.hold_s
        if not down + ramp <= end_s:
            raise InputError(f"drive_release's rise, hold and return ({down + ramp:g} s) must fit in the run "
                             f"({end_s:g} s)", "protocol.hold_s")
        bar.update(schedule_times_s=[0.0, up, down, down + ramp], schedule_travel_mm=[0.0, peak, peak, 0.0])
    return BarConfig(**bar)


class TwinConfig(ConfigModel):
    """The synthetic experiment: sample, material, bar, tank, resolution, imaging."""

    seed: int = Field(0, ge=0, lt=2 ** 63, description="seed of every random draw (shape, speckle, clicks); a whole number ≥ 0")
    blob: BlobConfig = BlobConfig()
    tissue: TissueMaterial = TissueMaterial(beta1=7e5)
    bar: BarConfig = BarConfig(ramp_s=0.5, density_kg_m3=2700.0)
    tank: TankConfig = TankConfig(size_mm=(44.0, 40.0, 36.0), water_depth_mm=6.0)
    physics: PhysicsConfig = PhysicsConfig()
    resolution: ResolutionConfig = ResolutionConfig()
    imaging: ImagingConfig = ImagingConfig()
    clinician: ClinicianConfig = ClinicianConfig()
    run: TwinRunConfig = TwinRunConfig()
    truth: TruthConfig = TruthConfig()
    protocol: ProtocolConfig = ProtocolConfig(name="custom")


#: Overrides of each preset on top of the defaults.
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    # a reduced twin for tests: a coarse model, 40 frames over the same 10 s, coarse images
    "small": {
        "resolution": {"model_tissue_particles": 500},
        "imaging": {"frames": 40, "frame_rate_hz": 4.0, "pixel_mm": 0.4, "sweep_gap_mm": 2.0},
        "run": {"particle_frames_every": 10},
        # the plumbing's twin: the particle truth takes seconds, the finite elements minutes
        "truth": {"solver": "particles"},
    },
    # the paper's protocol (200 frames at 20 Hz) on a coarse model: `hifumotion demo` in minutes
    "demo": {
        "resolution": {"model_tissue_particles": 600},
        "imaging": {"pixel_mm": 0.3, "sweep_gap_mm": 1.5},
        "run": {"particle_frames_every": 10},
    },
}
# the therapy protocols, each on the demo's resolution
for _name, _extra in (("paper", {}), ("slow_push", {"peak_force_n": 1.0}), ("push_release", {"peak_force_n": 0.6}),
                      ("oblique", {"peak_force_n": 0.5}), ("push_change", {"peak_force_n": 0.5})):
    PRESETS[_name] = {**PRESETS["demo"], "protocol": {"name": _name, **_extra}}

# the driven protocols: millimetres of motion, so the finite-strain truth
for _name, _extra in (("slide", {"peak_travel_mm": 5.0, "angle_deg": 35.0}),
                      ("slide_reverse", {"peak_travel_mm": 7.0, "angle_deg": 35.0, "ramp_s": 4.0}),
                      ("drive_release", {"peak_travel_mm": 3.0, "ramp_s": 2.0, "hold_s": 2.0})):
    PRESETS[_name] = {**PRESETS["demo"], "protocol": {"name": _name, **_extra}, "truth": {"solver": "finite_strain"}}
# a slide carries the sample ~travel / sin(angle) along x (8.7 mm at 5 mm and 35°): room for it,
# since the finite-element truth has no side walls (the twin refuses a truth that reaches them)
PRESETS["slide"]["tank"] = {"size_mm": [64.0, 40.0, 36.0]}
# a reversal needs the sample to slide while driven and to stay where the bar leaves it: a
# floor as slippery as wet tissue on plastic (μ_f 0.15), not the default's 0.5, which holds it
PRESETS["slide_reverse"]["tank"] = {"size_mm": [64.0, 40.0, 36.0]}
PRESETS["slide_reverse"]["physics"] = {"friction": 0.15}

Preset = Literal["default", "small", "demo", "paper", "slow_push", "push_release", "oblique", "push_change", "slide",
                 "slide_reverse", "drive_release"]


def _merge(base: dict, extra: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in extra.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def twin_config(preset: str = "default", overrides: dict[str, Any] | None = None,
                config_file: str | Path | None = None, seed: int | None = None) -> TwinConfig:
    """The settings: ``preset`` ← ``config_file`` ← ``overrides`` ← ``seed`` (later wins)."""
    if preset not in PRESETS:
        raise InputError(f"unknown preset; choose from {', '.join(PRESETS)}", preset)
    data = _merge(TwinConfig().model_dump(mode="json"), PRESETS[preset])
    source: str | Path = f"preset {preset}"
    if config_file is not None:
        data = _merge(data, read_config_file(config_file))
        source = config_file
    if overrides:
        data = _merge(data, overrides)
    if seed is not None:
        data["seed"] = int(seed)
    return apply_protocol(validate_config(TwinConfig, data, source))
