"""Generate the synthetic experiment: one documented order from settings to files.

1. **Sample.** A seeded irregular blob (:mod:`.blob`); its volume fixes the fitted
   model's particle spacing (``resolution.model_tissue_particles``, the paper's
   4,399) and the truth's, ``truth_particle_factor`` times as many particles.
2. **Physics.** By default quadratic finite elements
   (:mod:`hifumotion.experiment.fe_truth`, :mod:`hifumotion.reference.creep_fe`) — a
   solver that shares the fitted model's physics and none of its discretisation —
   settle the sample under gravity, then push it by the protocol's schedule for
   ``frames / frame_rate`` seconds; the displacement is sampled at the truth's lattice
   at every frame time. ``truth.solver = "particles"`` uses the particle framework's
   explicit path (:mod:`hifumotion.particles`) instead.
3. **Truth.** Cross-sections of the particles (:func:`~hifumotion.particles.section.section`)
   in the imaging plane at every frame, and in every sweep plane at rest.
4. **Observation.** B-mode images of the same planes (:mod:`.imaging`) with the
   speckle carried by the tissue; a clinician's rough click-contour on frame 0.
5. **Files.** ``observed/`` holds only what a device's user has; ``truth/`` what only
   the scoring may read (see :func:`generate_twin`).
"""

from __future__ import annotations

import csv
import io
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.contour import Contour, resample_closed
from hifumotion.errors import InputError
from hifumotion.experiment.blob import Blob
from hifumotion.experiment.config import TwinConfig
from hifumotion.experiment import imaging as im
from hifumotion.io import write_json
from hifumotion.io.files import write_text
from hifumotion.io.writers import write_contours_csv, write_masks_nifti, write_png_stack
from hifumotion.observed import BarSetup, ImagingGeometry, Observed, PushSchedule, Setup, TankSetup, write_observed
from hifumotion.scene import ParticleConfig, RunConfig, Scene, TissueConfig
from hifumotion.scene.geometry import spacing_for_count
from hifumotion.particles.quasi_static import settling as quasi_static_settling
from hifumotion.particles.section import mapped_section
from hifumotion.scene import SimulationResult
from hifumotion.particles.simulate import simulate

Progress = Callable[[str, float], None]


@dataclass
class TwinResult:
    """What :func:`generate_twin` made (arrays in memory; files under ``folder``)."""

    config: TwinConfig
    times_s: np.ndarray
    frames: np.ndarray            # uint8 (T, H, W) observed B-mode frames
    frame_masks: np.ndarray       # bool (T, H, W) true masks
    sweep: np.ndarray             # uint8 (S, H, W)
    sweep_masks: np.ndarray       # bool (S, H, W)
    probe: im.Probe
    simulation: SimulationResult
    observed: Observed            # observed/: what the device's user has
    parameters: dict              # truth/parameters.json
    facts: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)
    motion: dict = field(default_factory=dict)   # motion.json: centroid path, area, checks


def resolution(cfg: TwinConfig, blob: Blob) -> dict:
    """Spacings (mm) of the fitted model and of the truth, from the sample's volume."""
    volume = blob.volume_mm3(seed=cfg.seed)
    model = (volume / cfg.resolution.model_tissue_particles) ** (1 / 3)
    truth = model / cfg.resolution.truth_particle_factor ** (1 / 3)
    return {"blob_volume_mm3": volume, "model_spacing_mm": model, "truth_spacing_mm": truth}


def settling(cfg: TwinConfig, height_mm: float) -> tuple[float, float]:
    """Settling time (s) and damping (1/s): the configured ones, or from the slowest mode
    (:func:`~hifumotion.particles.quasi_static.settling`). A settling that is too short
    (0.3 s at s = 2×10⁴) left the tissue sagging into the first second of the push, where
    it showed as the largest difference between mass scalings."""
    t = cfg.tissue
    duration, damping = quasi_static_settling(t.youngs_modulus_pa, t.density_kg_m3, height_mm, cfg.run.mass_scaling)
    return (cfg.run.settle_s if cfg.run.settle_s is not None else duration,
            cfg.run.settle_damping_per_s if cfg.run.settle_damping_per_s is not None else damping)


def truth_scene(cfg: TwinConfig, particles_csv: Path, spacing_mm: float, height_mm: float,
                centre_mm=None) -> Scene:
    """The particle scene of the truth (re-runnable: ``hifumotion simulate truth/scene.toml``).

    ``centre_mm``, the centre of the particles' bounding box, keeps them where they are."""
    im_cfg = cfg.imaging
    settle_s, settle_damping = settling(cfg, height_mm)
    tissue = TissueConfig(**cfg.tissue.model_dump(), shape="particles", particles_csv=particles_csv,
                          centre_mm=None if centre_mm is None else tuple(float(c) for c in centre_mm))
    return Scene(
        tank=cfg.tank, tissue=tissue, bar=cfg.bar, physics=cfg.physics,
        particles=ParticleConfig(spacing_mm=spacing_mm, support_factor=cfg.resolution.support_factor),
        run=RunConfig(duration_s=(im_cfg.frames - 1) / im_cfg.frame_rate_hz, output_interval_s=1.0 / im_cfg.frame_rate_hz,
                      settle_s=settle_s, settle_damping_per_s=settle_damping,
                      mass_scaling=cfg.run.mass_scaling, cfl=cfg.run.cfl, max_step_s=cfg.run.max_step_s,
                      write_vtu=True, vtu_every=cfg.run.particle_frames_every))


def push_shape(bar, protocol=None) -> PushSchedule:
    """The shape of the bar's schedule, for ``setup.json`` (its magnitude is not the operator's to know;
    nor, under ``push_change``, the change: only the ramp and hold announced)."""
    if bar.control == "travel":
        # a driven bar: its stage's program is the operator's to know, the force it takes is not
        times = list(bar.schedule_times_s) if bar.schedule_times_s is not None else [0.0, max(bar.ramp_s, 1e-9)]
        travel = bar.travel_schedule()
        return PushSchedule(control="travel", shape="piecewise_linear", times_s=times,
                            travel_mm=[float(travel(t)) for t in times])
    if bar.schedule_times_s is None or (protocol is not None and protocol.name == "push_change"):
        return PushSchedule(shape="ramp_hold", ramp_s=bar.ramp_s)
    peak = max(bar.schedule_force_n)
    return PushSchedule(shape="piecewise_linear", times_s=list(bar.schedule_times_s),
                        relative_force=[f / peak for f in bar.schedule_force_n])


def clinician_contour(contour_mm: np.ndarray, cfg_points: int, error_mm: float,
                      rng: np.random.Generator) -> np.ndarray:
    """A rough contour as clicked: ``cfg_points`` points spread along the true boundary
    (in-plane mm), each off by a random radial error, as an (N, 2) polygon in mm."""
    c = np.asarray(contour_mm, float)
    length = float(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1).sum())
    pts = resample_closed(c, count=cfg_points, start=rng.uniform(0, length))
    centre = c.mean(0)
    radial = pts - centre
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-9)
    return pts + radial * rng.normal(0.0, error_mm, (cfg_points, 1))


def motion_summary(masks: np.ndarray, pixel_mm: float, times_s: np.ndarray, tissue_mm: np.ndarray,
                   spacing_mm: float, tank_mm) -> dict:
    """Centroid path and area of the true sections, and the physical sanity checks."""
    rows, cols = np.indices(masks.shape[1:])
    area = masks.sum((1, 2)).astype(float)
    safe = np.maximum(area, 1)
    cx = (masks * cols).sum((1, 2)) / safe * pixel_mm
    cy = (masks * rows).sum((1, 2)) / safe * pixel_mm
    path = np.column_stack([cx, cy])
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    lo = tissue_mm.min(axis=(0, 1))
    hi = tissue_mm.max(axis=(0, 1))
    spread = np.linalg.norm(tissue_mm - tissue_mm.mean(1, keepdims=True), axis=2).max(1)
    return {
        "frames": len(times_s),
        "centroid_mm": path.round(4).tolist(),
        "area_mm2": (area * pixel_mm ** 2).round(3).tolist(),
        "centroid_displacement_mm": float(np.linalg.norm(path[-1] - path[0])),
        "centroid_path_length_mm": float(step.sum()),
        "largest_centroid_shift_mm": float(np.linalg.norm(path - path[0], axis=1).max()),
        "area_change_mm2": float((area[-1] - area[0]) * pixel_mm ** 2),
        "area_change_fraction": float((area[-1] - area[0]) / max(area[0], 1)),
        "checks": {
            "lowest_particle_y_mm": float(lo[1]),
            "sinks_through_floor": bool(lo[1] < -0.5 * spacing_mm),
            "leaves_tank": bool(np.any(lo < -0.5 * spacing_mm) or np.any(hi > np.asarray(tank_mm) + 0.5 * spacing_mm)),
            "largest_radius_growth": float(spread.max() / max(spread[0], 1e-9) - 1.0),
            "explodes": bool(spread.max() > 1.5 * spread[0]),
            "section_empty_frames": int((area == 0).sum()),
        },
    }


def _write_csv(path: Path, header: list[str], rows) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    write_text(path, buf.getvalue())


def _contours(masks_sections, pixel_mm, labels) -> dict:
    out = {}
    for label, sec in zip(labels, masks_sections):
        if len(sec.contour_px) >= 3:
            out[label] = Contour(sec.contour_px, (pixel_mm, pixel_mm))
    return out


def _seeds(cfg: TwinConfig) -> np.ndarray:
    """One seed per random use (shape, texture, speckle …), all drawn from ``cfg.seed``."""
    return np.random.default_rng(cfg.seed).integers(0, 2**31 - 1, 8)


@dataclass
class TruthRun:
    """The physics of the experiment: sample, resolutions, scene and simulation."""

    blob: Blob
    resolution: dict
    scene: Scene
    simulation: SimulationResult
    spacing_mm: float
    particles_mm: np.ndarray      # rest positions in the tank (mm)
    placement_mm: np.ndarray      # tank position of the resting frame's origin (mm)
    sample_s: float
    simulate_s: float


def simulate_truth(cfg: TwinConfig, folder: str | Path, progress: Callable[[float], None] | None = None,
                   particle_factor: float | None = None) -> TruthRun:
    """Steps 1–2: the seeded sample and its simulation; writes ``blob_particles.csv``,
    ``scene.toml`` and ``particles/`` (VTU + PVD) into ``folder``.

    ``particle_factor`` overrides ``resolution.truth_particle_factor`` (1.0 simulates at the
    fitted model's resolution: the floor any fitted model can reach).
    """
    folder = Path(folder)
    (folder / "particles").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut,
                       int(_seeds(cfg)[0]))
    res = resolution(cfg, blob)
    factor = cfg.resolution.truth_particle_factor if particle_factor is None else particle_factor
    dx = res["model_spacing_mm"] / factor ** (1 / 3)
    wanted = factor * cfg.resolution.model_tissue_particles
    if factor > 1.0:   # the lattice misses a little of the lumps
        dx, pts = spacing_for_count(blob.particles, dx, wanted, shrink=0.995, tolerance=0.995)
    else:
        pts = blob.particles(dx)
    res["truth_spacing_mm"] = dx
    # the resting frame's origin goes to the middle of the tank floor
    placement = np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2])
    pts = pts + placement
    particles_csv = folder / "blob_particles.csv"
    _write_csv(particles_csv, ["x_mm", "y_mm", "z_mm", "volume_mm3"],
               ([f"{p[0]:.6f}", f"{p[1]:.6f}", f"{p[2]:.6f}", f"{dx ** 3:.6f}"] for p in pts))
    scene = truth_scene(cfg, particles_csv, dx, float(np.ptp(pts[:, 1]) + dx),
                        centre_mm=(pts.min(0) + pts.max(0)) / 2)
    from hifumotion.config import dump_toml

    scene_for_file = scene.model_copy(deep=True)
    scene_for_file.tissue.particles_csv = Path("blob_particles.csv")
    write_text(folder / "scene.toml", dump_toml(scene_for_file))
    t1 = time.perf_counter()
    if cfg.truth.solver in ("finite_elements", "finite_strain"):
        from hifumotion.experiment.fe_truth import simulate_fe_truth

        sim, _ = simulate_fe_truth(cfg, blob, pts, dx, placement, folder, progress)
    else:
        sim = simulate(scene, folder / "particles", progress=progress)
    return TruthRun(blob, res, scene, sim, dx, pts, placement, t1 - t0, time.perf_counter() - t1)


def truth_sections(truth: TruthRun, probe: im.Probe, progress: Callable[[float], None] | None = None):
    """Step 3: the true sections of every frame (imaging plane) and sweep plane (at rest).

    The sample's exact rest shape is mapped through the particles' displacement
    (:func:`~hifumotion.particles.section.mapped_section`), so the truth has the blob's
    smooth boundary, not the particles' staircase.
    """
    tell = progress or (lambda f: None)
    sim = truth.simulation
    n = len(sim.times_s) + len(probe.sweep_z_mm)
    rest = truth.particles_mm   # the lattice at rest, before settling (the truth's reference shape)
    # the blob's own frame: undo the placement in the tank and the resting frame's offset
    shift = truth.placement_mm + truth.blob.offset_mm()

    def inside(points_mm):
        return truth.blob.inside(points_mm - shift)

    frame_plane = probe.plane(probe.z_frames_mm)
    frames = []
    for k in range(len(sim.times_s)):
        frames.append(mapped_section(sim.tissue_mm[k], rest, sim.spacing_mm, frame_plane, inside))
        tell((k + 1) / n)
    sweep = []
    for k, z in enumerate(probe.sweep_z_mm):
        sweep.append(mapped_section(sim.tissue_mm[0], rest, sim.spacing_mm, probe.plane(z), inside))
        tell((len(sim.times_s) + k + 1) / n)
    return frames, sweep


def operator_setup(cfg: TwinConfig, probe: im.Probe, tip_mm: np.ndarray, axis: np.ndarray, frames: int) -> Setup:
    """``setup.json``: what the operator knows (image geometry and timing, the pool, the bar's
    shape and resting place, the shape of its push but not its magnitude)."""
    return Setup(
        description="What the operator of the HIFU device knows: image geometry and timing, the pool, the bar's "
                    "shape, where it starts and the shape of its push (not how hard it is). Pool frame in mm, y up; "
                    "image rows run upwards from the probe (depth), columns along x.",
        frame_interval_s=1.0 / cfg.imaging.frame_rate_hz, frames=int(frames), initial_contour_frame=0,
        imaging=ImagingGeometry(**probe.as_dict()),
        tank=TankSetup(size_mm=tuple(cfg.tank.size_mm), water_depth_mm=cfg.tank.water_depth_mm),
        bar=BarSetup(enabled=cfg.bar.enabled, radius_mm=cfg.bar.radius_mm, length_mm=cfg.bar.length_mm,
                     direction=tuple(np.asarray(axis).tolist()), tip_at_rest_mm=tuple(np.asarray(tip_mm).tolist())
                     if cfg.bar.enabled else tuple(0.5 * np.asarray(cfg.tank.size_mm)),
                     weight_supported=cfg.bar.weight_supported, edge_radius_mm=cfg.bar.edge_radius_mm),
        push=push_shape(cfg.bar, cfg.protocol))


def echo_maps(cfg: TwinConfig, probe: im.Probe, tip_mm: np.ndarray, axis: np.ndarray,
              seeds: np.ndarray) -> Callable[[float, np.ndarray], im.EchoMap]:
    """``echo_map(z_mm, tissue_mask)``: the backscatter of the plane at ``z_mm`` (tissue with its
    seeded texture, water, the floor and the bar at rest)."""
    size = np.asarray(cfg.tank.size_mm)
    texture = im.Texture(-np.full(3, 2.0), size + 2.0, cfg.imaging.echo_texture, np.random.default_rng(seeds[1]))

    def echo_map(z: float, tissue_mask: np.ndarray) -> im.EchoMap:
        bar = (im.bar_mask(probe, z, tip_mm, axis, cfg.bar.radius_mm, cfg.bar.length_mm) if cfg.bar.enabled
               else np.zeros(probe.shape, bool))
        return im.EchoMap(cfg.imaging, probe, z, tissue_mask, bar, cfg.tank.water_depth_mm, texture)

    return echo_map


def sweep_images(probe: im.Probe, sweep_masks: np.ndarray, echo_map, trans, seeds: np.ndarray,
                 progress: Callable[[float], None] | None = None) -> np.ndarray:
    """The B-mode images (uint8 ``(S, H, W)``) of the sweep's planes, each with its own scatterers."""
    extent = (probe.shape[0] * probe.pixel_mm, probe.shape[1] * probe.pixel_mm)
    images = []
    for k, z in enumerate(probe.sweep_z_mm):
        scat = im.Scatterers.uniform(extent, trans, int(seeds[2]) + k)
        images.append(im.render(echo_map(z, sweep_masks[k]), scat, None, probe, trans, int(seeds[3]),
                                sweep_masks[k]).image)
        if progress is not None:
            progress((k + 1) / len(sweep_masks))
    return np.stack(images)


def check_image_memory(cfg: TwinConfig) -> None:
    """Refuse, before the physics runs, imaging settings whose images this machine cannot hold:
    every frame and sweep plane (at most the pool's depth over the sweep's gap) as grey levels,
    masks and the truth's sections (6 bytes a pixel), and the B-mode simulation's working
    arrays (about 20 float64 images)."""
    from hifumotion.resources import check_memory

    im_cfg = cfg.imaging
    rows, cols = im_cfg.depth_mm / im_cfg.pixel_mm, im_cfg.width_mm / im_cfg.pixel_mm
    planes = im_cfg.frames + cfg.tank.size_mm[2] / im_cfg.sweep_gap_mm + 1
    need = rows * cols * (6.0 * planes + 20 * 8.0)
    def count(x: float) -> str:
        return f"{x:,.0f}" if x < 1e9 else f"{x:.3g}"

    check_memory(need, f"images of {count(rows)} × {count(cols)} px ({im_cfg.depth_mm:g} × {im_cfg.width_mm:g} mm at "
                 f"{im_cfg.pixel_mm:g} mm), {count(planes)} of them,",
                 "imaging (pixel_mm, width_mm, depth_mm, frames, sweep_gap_mm)")


def generate_twin(cfg: TwinConfig, folder: str | Path, progress: Progress | None = None) -> TwinResult:
    """Run the experiment (module docstring) and write ``folder/observed`` and ``folder/truth``.

    ``observed/``: ``sweep/slice_000.png …`` + ``sweep.nii.gz`` + ``sweep_positions.csv``,
    ``frames/frame_0000.png …`` + ``frames.nii.gz``, ``initial_contour.csv`` and
    ``setup.json`` (image geometry, frame interval, tank, bar — what the operator knows).
    ``truth/``: ``parameters.json``, ``frames/frame_0000.png …`` and ``sweep/slice_000.png …``
    (0/255 masks on the same grids), ``frame_contours.csv``, ``sweep_contours.csv``,
    ``particles/`` (VTU + PVD for ParaView), ``tissue_trajectory.npz``, ``bar_pose.csv``,
    ``motion.json``, ``scene.toml`` + ``blob_particles.csv`` (re-runnable).
    """
    check_image_memory(cfg)
    folder = Path(folder)
    obs, tru = folder / "observed", folder / "truth"
    for d in (obs / "sweep", obs / "frames", tru / "sweep", tru / "frames", tru / "particles"):
        d.mkdir(parents=True, exist_ok=True)
    tell = progress or (lambda stage, fraction: None)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    seeds = _seeds(cfg)

    # 1–2. the sample, the resolutions and the physics
    truth = simulate_truth(cfg, tru, lambda f: tell("simulate", f))
    res, scene, sim, dx = truth.resolution, truth.scene, truth.simulation, truth.spacing_mm
    timings["sample_s"] = truth.sample_s
    timings["simulate_s"] = truth.simulate_s
    times = sim.times_s
    rest = sim.tissue_mm[0]
    vol = sim.tissue_volume_mm3
    pts = truth.particles_mm

    # 3. truth sections
    t2 = time.perf_counter()
    probe = im.make_probe(cfg.imaging, rest)
    frame_secs, sweep_secs = truth_sections(truth, probe, lambda f: tell("sections", f))
    frame_masks = np.stack([s.mask for s in frame_secs])
    sweep_masks = np.stack([s.mask for s in sweep_secs])
    timings["sections_s"] = time.perf_counter() - t2

    # 4. observation
    t3 = time.perf_counter()
    facts = sim.facts
    axis = np.asarray(facts["bar_axis"]) if cfg.bar.enabled else np.array([0.0, -1.0, 0.0])
    tip0 = np.asarray(facts["bar_tip_mm"]) if cfg.bar.enabled else np.full(3, 1e9)
    bar_shift = sim.bar_centre_mm - sim.bar_centre_mm[0] if cfg.bar.enabled else np.zeros((len(times), 3))
    echo_map = echo_maps(cfg, probe, tip0, axis, seeds)
    trans = im.transducer(cfg.imaging, probe, rest)
    extent = (probe.shape[0] * probe.pixel_mm, probe.shape[1] * probe.pixel_mm)
    n_images = len(probe.sweep_z_mm) + len(times)
    sweep = sweep_images(probe, sweep_masks, echo_map, trans, seeds,
                         lambda f: tell("images", f * len(sweep_masks) / n_images))
    z0 = probe.z_frames_mm
    echo0 = echo_map(z0, frame_masks[0])
    speckle = im.MovingSpeckle(echo0, im.Scatterers.uniform(extent, trans, int(seeds[4])), rest, dx)
    frames = []
    for k in range(len(times)):
        pos = speckle.positions(sim.tissue_mm[k], bar_shift[k])
        frames.append(im.render(echo0, speckle.scatterers, pos, probe, trans, int(seeds[5]), frame_masks[k]).image)
        tell("images", (len(probe.sweep_z_mm) + k + 1) / n_images)
    frames = np.stack(frames)
    clicked = clinician_contour(frame_secs[0].contour_mm, cfg.clinician.points, cfg.clinician.error_mm,
                                np.random.default_rng(seeds[6]))
    timings["images_s"] = time.perf_counter() - t3

    # 5. files
    t4 = time.perf_counter()
    px = probe.pixel_mm
    interval = 1.0 / cfg.imaging.frame_rate_hz
    setup = operator_setup(cfg, probe, tip0, axis, len(times))
    observed = Observed(sweep, np.asarray(probe.sweep_z_mm, float), frames, Contour.from_mm(clicked, px), setup)
    write_observed(obs, setup, sweep, observed.sweep_z_mm, frames, observed.initial_contour)
    write_png_stack(tru / "frames", frame_masks, prefix="frame_", digits=4)
    write_png_stack(tru / "sweep", sweep_masks, prefix="slice_", digits=3)
    write_masks_nifti(tru / "frames.nii.gz", frame_masks, (px, px), frame_interval_s=interval)
    write_masks_nifti(tru / "sweep.nii.gz", sweep_masks, (px, px), slice_positions_mm=probe.sweep_z_mm)
    write_contours_csv(tru / "frame_contours.csv", _contours(frame_secs, px, range(len(times))))
    write_contours_csv(tru / "sweep_contours.csv", _contours(sweep_secs, px, range(len(probe.sweep_z_mm))))
    np.savez_compressed(tru / "tissue_trajectory.npz", times_s=times, positions_mm=sim.tissue_mm.astype(np.float32),
                        volumes_mm3=vol, spacing_mm=dx)
    # the force on the bar: its schedule, or (a driven bar) what the truth's contacts took
    forces = (np.asarray(sim.facts["bar_force_n"], float) if scene.bar.control == "travel"
              else np.array([scene.bar.schedule()(t) for t in times]))
    _write_csv(tru / "bar_pose.csv", ["frame", "time_s", "centre_x_mm", "centre_y_mm", "centre_z_mm", "force_n"],
               ([k, f"{t:.6g}", *(f"{c:.6f}" for c in sim.bar_centre_mm[k]), f"{forces[k]:.6g}"]
                for k, t in enumerate(times)))
    system = sim.system
    motion = motion_summary(frame_masks, px, times, sim.tissue_mm, dx, cfg.tank.size_mm)
    lo, hi = sim.tissue_mm.min(axis=(0, 1)), sim.tissue_mm.max(axis=(0, 1))
    walls = np.asarray(cfg.tank.size_mm, float)
    # the finite-element truths have no side walls (reference.creep_fe): a sample whose surface
    # (half a spacing beyond its particles) reaches them would be stopped there, and is not the scene's
    if cfg.truth.solver in ("finite_elements", "finite_strain") and (
            np.any(lo[[0, 2]] < 0.5 * dx) or np.any(hi[[0, 2]] > walls[[0, 2]] - 0.5 * dx)):
        raise InputError(f"the truth's sample spans {np.round(lo, 1).tolist()} to {np.round(hi, 1).tolist()} mm, "
                         f"within half a spacing of the tank's side walls (0 to {list(cfg.tank.size_mm)} mm), which "
                         "the finite-element truth does not model: enlarge the tank or shorten the push", "tank.size_mm")
    write_json(tru / "motion.json", motion)
    facts = {**facts, **res, "truth_tissue_particles": int(len(pts)),
             "model_tissue_particles": cfg.resolution.model_tissue_particles}
    parameters = {
        "description": "The true parameters of the synthetic experiment (SI unless the name says otherwise).",
        "bar_control": cfg.bar.control,
        # a driven bar's force is a result (bar_pose.csv), not a parameter
        "external_force_n": cfg.bar.force_n if cfg.bar.control == "force" else None, "force_ramp_s": cfg.bar.ramp_s,
        **({"bar_travel_mm": cfg.bar.travel_mm, "bar_schedule_travel_mm": cfg.bar.schedule_travel_mm,
            "bar_schedule_times_s": cfg.bar.schedule_times_s} if cfg.bar.control == "travel" else {}),
        "force_direction": axis.tolist(),
        "youngs_modulus_pa": cfg.tissue.youngs_modulus_pa, "poisson_ratio": cfg.tissue.poisson_ratio,
        "beta1_pa_s_pow": cfg.tissue.beta1, "beta2": cfg.tissue.beta2,
        "tissue_density_kg_m3": cfg.tissue.density_kg_m3,
        "water_density_kg_m3": cfg.physics.water_density_kg_m3,
        "water_viscosity_pa_s": cfg.physics.water_viscosity_pa_s,
        **({"water_stiffness_m2_s2": system.fluid_stiffness_m2_s2,
            "contact_coefficient_n_m4_kg2": system.contact_coefficient,
            "wall_coefficient_n_m4_kg2": system.wall_coefficient} if system is not None else {}),
        "truth_solver": cfg.truth.solver,
        "friction": cfg.physics.friction,
        "gravity_m_s2": cfg.physics.gravity_m_s2,
        "mass_scaling": cfg.run.mass_scaling,
        "seed": cfg.seed,
        "facts": facts,
        "config": json.loads(cfg.model_dump_json()),
    }
    write_json(tru / "parameters.json", parameters)
    timings["write_s"] = time.perf_counter() - t4
    timings["total_s"] = time.perf_counter() - t0
    facts["steps"] = sim.steps
    return TwinResult(cfg, times, frames, frame_masks, sweep, sweep_masks, probe, sim, observed, parameters, facts, timings,
                      motion)


def summary_line(result: TwinResult) -> str:
    m = result.motion
    return (f"{len(result.times_s)} frames over {result.times_s[-1]:.1f} s; centroid moved "
            f"{m['centroid_displacement_mm']:.2f} mm, area changed {m['area_change_mm2']:+.1f} mm² "
            f"({100 * m['area_change_fraction']:+.1f} %)")


__all__ = ["TwinResult", "generate_twin", "resolution", "truth_scene", "clinician_contour", "motion_summary",
           "summary_line"]
