"""The forward model: the versatile particle framework run with a parameter set K.

:func:`model_spec` turns a prepared observation (:mod:`.prepare`) into a
:class:`ModelSpec` — plain, picklable data, so a Dask worker can run it:

* the reconstructed tissue filled with particles at the paper's resolution
  (``tissue_particles``, 4,399 by default: the spacing shrinks until there are that many);
* the pool, the bar and the push's ramp from ``setup.json`` (size, water depth; bar radius,
  length, direction, tip);
* the contour points A: points spread evenly along the frame-0 contour, in the
  imaging plane (tank mm).

:func:`run_model` simulates the scene with a :class:`Parameters` set K — settling
under gravity, then the push; by default on the fast path (:mod:`hifumotion.creep`:
the reconstructed tissue as conforming voxels, contacts as constraints, backward
Euler), ``ModelSettings.integrator = "explicit"`` for the paper's Eq. 8–20 — and returns where the points A have moved at every
frame (their displacement since frame 0, interpolated from the tissue particles around
them at frame 0, :func:`~hifumotion.particles.section.material_displacement`), and, if asked, the tissue
particles of chosen frames.

Frame 0 of the model is its settled state. Motion is measured from there, so the
model's predicted contour of frame t is the *observed* frame-0 shape carried by
the model's displacement since frame 0 — the resting shape the model settles from
need not be the unloaded one.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from typing import Callable

import numpy as np

from hifumotion.errors import InputError
from hifumotion.estimation.settings import INTEGRATORS, ModelSettings
from hifumotion.particles.quasi_static import settling
from hifumotion.scene import (BYTES_PER_PARTICLE, BarConfig, ParticleConfig, PhysicsConfig, RunConfig, Scene, TankConfig, TissueConfig)
from hifumotion.scene.geometry import spacing_for_count, touching_tip
from hifumotion.resources import check_memory
from hifumotion import paper


@dataclass(frozen=True)
class Parameters:
    """The parameter set K of the paper's Table 3 (SI units)."""

    force_n: float = paper.FORCE_N                      # external force held by the bar (N)
    youngs_modulus_pa: float = paper.YOUNGS_MODULUS_PA  # E (Pa)
    poisson_ratio: float = paper.POISSON_RATIO          # ν
    beta1: float = paper.BETA1                          # β1 of Eq. 16 (Pa·s^(1+β2))
    beta2: float = paper.BETA2                          # β2 of Eq. 16
    friction: float | None = None                       # μ_f of the floor and the bar (None: the model's setting)

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items() if v is not None}

    def replaced(self, **changes: float) -> "Parameters":
        return replace(self, **changes)


@dataclass(frozen=True)
class KeptReduced:
    """The reduced model a :class:`ModelSpec` keeps: the model, the parameters whose full runs
    it was made around and the last frame those runs reached."""

    model: object                   # hifumotion.reduced.model.ReducedCreep
    made_at: "Parameters"
    last_frame: int


@dataclass(frozen=True)
class ReducedSnapshots:
    """The full runs a reduced model is made from (:meth:`ModelSpec.snapshot_scenes`, each a
    :class:`~hifumotion.creep.integrate.CreepResult`), the parameters they were run around and the
    last frame they reach: what a calibration saves so that the online loop need not run them."""

    made_at: "Parameters"
    last_frame: int
    runs: tuple


@dataclass
class ModelSpec:
    """Everything a forward run needs, as plain data (mm, s)."""

    scene: Scene
    tissue_mm: np.ndarray           # (N, 3) tissue particles in the tank frame
    tissue_volume_mm3: np.ndarray   # (N,)
    points_mm: np.ndarray           # (M, 3) the contour points A on the frame-0 contour
    frame_interval_s: float
    settings: ModelSettings = field(default_factory=ModelSettings)
    surface_vertices_mm: np.ndarray | None = None   # the reconstructed surface, moved as the particles were
    surface_faces: np.ndarray | None = None
    _voxels: object = field(default=None, repr=False, compare=False)  # the fast path's mesh, made once
    _reduced: KeptReduced | None = field(default=None, repr=False, compare=False)   # made on first use, then kept
    _offered: ReducedSnapshots | None = field(default=None, repr=False, compare=False)  # runs made elsewhere (saved)

    def voxels(self):
        """The fast path's conforming voxel mesh of the tissue (made on first use, then kept)."""
        if self._voxels is None:
            import trimesh

            from hifumotion.creep.conform import conform

            from hifumotion.creep.voxels import voxel_mesh

            mesh = voxel_mesh(self.tissue_mm, self.spacing_mm)
            if self.surface_vertices_mm is not None:
                mesh = conform(mesh, trimesh.Trimesh(self.surface_vertices_mm, self.surface_faces, process=False))
            self._voxels = mesh
        return self._voxels

    @property
    def spacing_mm(self) -> float:
        return self.scene.particles.spacing_mm

    def reduced(self, k: "Parameters", last_frame: int, progress=None):
        """The reduced model (:mod:`hifumotion.reduced.model`) of this spec around ``k``: its modes
        from full runs at F/E × ``settings.reduced_span`` to ``last_frame`` (made on first use
        or when asked for other parameters or a longer run, then kept)."""
        kept = self._reduced
        if kept is not None and kept.made_at == k and kept.last_frame >= last_frame:
            return kept.model
        offered = self._offered
        if (offered is not None and offered.last_frame >= last_frame and _same_parameters(offered.made_at, k)
                and offered.runs[0].nodes_mm.shape[1] == len(self.voxels().nodes_mm)):
            # its runs were made already (a calibration saved them): the model from them, as made then
            return self.adopt_reduced(k, offered.last_frame, list(offered.runs))
        from hifumotion.reduced.build import reduced_creep

        model = reduced_creep(self.snapshot_scenes(k, last_frame), self.voxels(), self.tissue_volume_mm3,
                              self.settings.reduced, progress=progress, creep=self.settings.creep)
        self._reduced = KeptReduced(model, k, last_frame)
        return model

    @property
    def reduced_made_at(self) -> "Parameters | None":
        """The parameters the kept reduced model was made around (``None``: none made yet)."""
        return None if self._reduced is None else self._reduced.made_at

    def snapshot_scenes(self, k: "Parameters", last_frame: int) -> list:
        """The scenes whose full runs make the reduced model around ``k`` (F/E × ``reduced_span``;
        a driven bar's travel × ``reduced_span``, so that the modes see shallower and deeper pushes)."""
        if self.scene.bar.control == "travel":
            scenes = []
            for f in self.settings.reduced_span:
                scene = scene_for(self, k, last_frame)
                bar = scene.bar
                scene.bar = bar.model_copy(update={"travel_mm": bar.travel_mm * f, "schedule_travel_mm": None if
                                                   bar.schedule_travel_mm is None else
                                                   [x * f for x in bar.schedule_travel_mm]})
                scenes.append(scene)
            return scenes
        return [scene_for(self, k.replaced(force_n=k.force_n * f), last_frame) for f in self.settings.reduced_span]

    def offer_reduced(self, snapshots: ReducedSnapshots) -> None:
        """Keep full runs made elsewhere (a saved calibration's): :meth:`reduced` makes its model
        from them, not from runs of its own, when asked around the parameters they were made at
        for no later frame than theirs."""
        self._offered = snapshots

    def adopt_reduced(self, k: "Parameters", last_frame: int, runs: list) -> object:
        """Make and keep the reduced model around ``k`` from its snapshot runs made elsewhere
        (:func:`~hifumotion.creep.scene_run.snapshot_run` of each of :meth:`snapshot_scenes`, e.g. on a
        cluster's cores)."""
        from hifumotion.reduced.build import reduced_from_runs

        scenes = self.snapshot_scenes(k, last_frame)
        model = reduced_from_runs(scenes[0], self.voxels(), runs, self.settings.reduced, self.settings.creep)
        self._reduced = KeptReduced(model, k, last_frame)
        return model


def _same_parameters(a: "Parameters", b: "Parameters", rtol: float = 1e-9) -> bool:
    """Whether two parameter sets are one (each value within ``rtol``: a set read back from
    ``parameters.json`` is the one written, to the last digit JSON keeps)."""
    da, db = a.as_dict(), b.as_dict()
    return da.keys() == db.keys() and all(abs(da[n] - db[n]) <= rtol * max(abs(da[n]), abs(db[n])) for n in da)


@dataclass
class ModelRun:
    """A forward run: where the points A went, frame by frame."""

    parameters: Parameters
    frames: np.ndarray              # (F,) frame numbers 0 … last
    points_mm: np.ndarray           # (F, M, 3) positions of the points A
    rest_mm: np.ndarray             # (N, 3) the tissue particles at frame 0 (settled)
    kept: dict                      # frame -> (N, 3) tissue particles of the frames asked for
    bar_centre_mm: np.ndarray       # (F, 3)
    steps: int
    seconds: float


def model_spec(observation, settings: ModelSettings | None = None) -> ModelSpec:
    """The forward model of an :class:`~hifumotion.estimation.prepare.Observation`."""
    from hifumotion.contour import Contour, resample_closed

    s = settings or ModelSettings()
    # the tissue and its water (about as many again) before any array is made
    check_memory(2.5 * s.tissue_particles * BYTES_PER_PARTICLE, f"a model of {s.tissue_particles} tissue particles",
                 "particles")
    setup = observation.observed.setup
    rec = observation.reconstruction
    def fill(dx):
        # the tissue rests on the pool's floor (y = 0): a segmentation that took in some of the
        # bright membrane puts particles below it, which the floor's walls would eject
        filled = rec.particles(dx)
        tissue = filled.positions_mm + observation.offset_mm
        above = tissue[:, 1] >= 0.5 * dx
        return tissue[above], filled.volume_mm3[above]

    # the paper's particle count: the lattice misses a little of the surface, so shrink until it is reached
    dx, (tissue, volume) = spacing_for_count(fill, (rec.volume_mm3 / s.tissue_particles) ** (1 / 3),
                                             s.tissue_particles)
    # on the floor: the lowest layer half a spacing up (a gap would make the tissue fall into the push)
    lift = tissue[:, 1].min() - 0.5 * dx
    tissue[:, 1] -= lift
    surface = np.asarray(rec.mesh.vertices, float) + observation.offset_mm - np.array([0.0, lift, 0.0])
    b = setup.bar
    axis = np.asarray(b.direction, float)
    # the reconstructed surface is not exactly where the real one was: the tip touches the model's
    tip = touching_tip(tissue, np.asarray(b.tip_at_rest_mm, float), axis, b.radius_mm, dx)
    tank = TankConfig(size_mm=setup.tank.size_mm, water_depth_mm=setup.tank.water_depth_mm)
    bar = BarConfig(enabled=b.enabled, radius_mm=b.radius_mm, length_mm=b.length_mm, direction=b.direction,
                    tip_mm=tuple(float(c) for c in (b.tip_at_rest_mm if tip is None else tip)),
                    weight_supported=b.weight_supported, edge_radius_mm=b.edge_radius_mm,
                    **push_fields(setup.push, Parameters().force_n, s.force_ramp_s))
    tissue_cfg = TissueConfig(density_kg_m3=s.tissue_density_kg_m3, rate_floor_per_s=s.rate_floor_per_s,
                              shape="particles", particles_csv="tissue_particles.csv",
                              centre_mm=tuple(float(c) for c in (tissue.min(0) + tissue.max(0)) / 2))
    scene = Scene(tank=tank, tissue=tissue_cfg, bar=bar,
                  particles=ParticleConfig(spacing_mm=dx, support_factor=s.support_factor),
                  physics=PhysicsConfig(friction=s.friction),
                  run=RunConfig(duration_s=1.0, output_interval_s=observation.observed.frame_interval_s,
                                mass_scaling=s.mass_scaling, cfl=s.cfl, max_step_s=s.max_step_s, write_vtu=False))
    contour = Contour.from_mask(observation.frame_masks[0], observation.pixel_mm)
    px = resample_closed(contour.points_px, count=s.contour_points)
    points = _plane_points(observation.frame_plane, px)
    return ModelSpec(scene, tissue, volume, points, observation.observed.frame_interval_s, s,
                     surface, np.asarray(rec.mesh.faces, np.int64))


def push_fields(push, peak_force_n: float, ramp_override_s: float | None) -> dict:
    """The bar's schedule fields for ``setup.json``'s push shape at ``peak_force_n``."""
    if push.shape == "ramp_hold":
        return push.model_copy(update={"ramp_s": float(ramp_override_s if ramp_override_s is not None
                                                       else push.ramp_s)}).schedule(peak_force_n)
    return push.schedule(peak_force_n)


def _plane_points(plane, xy_px: np.ndarray) -> np.ndarray:
    """Tank positions (mm) of in-plane pixel coordinates ``(x = col, y = row)``."""
    o = np.asarray(plane.origin_mm, float)
    return (o + xy_px[:, :1] * plane.pixel_mm * np.asarray(plane.u, float)
            + xy_px[:, 1:2] * plane.pixel_mm * np.asarray(plane.v, float))


def scene_for(spec: ModelSpec, k: Parameters, last_frame: int) -> Scene:
    """The spec's scene with the parameter set ``k``, run to frame ``last_frame``."""
    s = spec.settings
    height_mm = float(np.ptp(spec.tissue_mm[:, 1]) + spec.spacing_mm)
    settle_s, damping = settling(k.youngs_modulus_pa, s.tissue_density_kg_m3, height_mm, s.mass_scaling,
                                 s.settle_periods)
    scene = spec.scene.model_copy(deep=True)
    scene.tissue.youngs_modulus_pa = k.youngs_modulus_pa
    scene.tissue.poisson_ratio = k.poisson_ratio
    scene.tissue.beta1 = k.beta1
    scene.tissue.beta2 = k.beta2
    if k.friction is not None:
        scene.physics.friction = k.friction
    if scene.bar.control == "force" and scene.bar.schedule_force_n is not None:
        # a known shape, an unknown magnitude: the schedule scales with the fitted peak (a driven
        # bar's travel is known: its force is a result, F is no parameter of its runs)
        peak = max(scene.bar.schedule_force_n)
        scene.bar.schedule_force_n = [f * k.force_n / peak for f in scene.bar.schedule_force_n]
    scene.bar.force_n = k.force_n
    scene.run.duration_s = max(last_frame, 1) * spec.frame_interval_s
    scene.run.settle_s = settle_s
    scene.run.settle_damping_per_s = damping
    return scene


@dataclass(frozen=True)
class ForwardModel:
    """One integrator of the model: called ``(spec, scene, k, last_frame) → SimulationResult``,
    the scene (:func:`scene_for`) run from its settled state to ``last_frame``, its tissue
    particles at every frame. :data:`FORWARD_MODELS` names them; ``ModelSettings.integrator``
    picks one (:func:`forward_model`). Callers ask it what it is, never test its name.

    ``reduces``: the full integrator whose runs make this one's modes (``None``: a full model) —
    a reduced model needs full runs before it runs, and is checked against that full model.
    ``scene_run``: how it runs a user's scene file as it stands (``hifumotion simulate``:
    ``(scene, folder, progress) → SimulationResult``, its frames written into ``folder`` as
    ``pvd`` names them); ``None`` where it cannot (a reduced model has no modes before its full
    runs)."""

    name: str
    run: Callable
    reduces: str | None = None
    scene_run: Callable | None = None
    pvd: str = ""

    def __call__(self, spec: ModelSpec, scene: Scene, k: Parameters, last_frame: int):
        return self.run(spec, scene, k, last_frame)

    def simulate(self, scene: Scene, folder=None, progress=None):
        """Run ``scene`` as it stands, writing its frames into ``folder`` (:attr:`scene_run`)."""
        if self.scene_run is None:
            runnable = ", ".join(n for n, m in FORWARD_MODELS.items() if m.scene_run is not None)
            raise InputError(f"the {self.name} model is made from full runs around a fit and cannot run a scene "
                             f"alone; expected {runnable}", "integrator")
        return self.scene_run(scene, folder, progress=progress)

    @property
    def is_reduced(self) -> bool:
        """Whether its modes come from another integrator's full runs."""
        return self.reduces is not None

    @property
    def full(self) -> "ForwardModel":
        """The full model it reduces (itself when it is one)."""
        return FORWARD_MODELS[self.reduces] if self.reduces is not None else self


def _implicit(spec: ModelSpec, scene: Scene, k: Parameters, last_frame: int):
    """The fast path (:mod:`hifumotion.creep`) with ``settings.creep``."""
    return _implicit_with_nodes(spec, scene)[0]


def _implicit_with_nodes(spec: ModelSpec, scene: Scene):
    """The fast path's run and its :class:`~hifumotion.creep.integrate.CreepResult` (nodes and all)."""
    from hifumotion.creep.scene_run import run_creep

    return run_creep(scene, spec.voxels(), spec.tissue_volume_mm3, spec.settings.creep)


def _explicit(spec: ModelSpec, scene: Scene, k: Parameters, last_frame: int):
    """The paper's particle framework, Eq. 8–20 (:mod:`hifumotion.particles`)."""
    from hifumotion.particles.simulate import simulate

    return simulate(scene, tissue_particles=(spec.tissue_mm, spec.tissue_volume_mm3))


def _reduced(spec: ModelSpec, scene: Scene, k: Parameters, last_frame: int):
    """The reduced model (:mod:`hifumotion.reduced.model`), its modes made once around the first
    parameters asked for (:meth:`ModelSpec.reduced`)."""
    from hifumotion.reduced.build import simulate_reduced

    made = spec.reduced_made_at or k
    return simulate_reduced(scene, spec.reduced(made, last_frame), spec.tissue_volume_mm3)


def _implicit_scene(scene: Scene, folder=None, progress=None):
    from hifumotion.creep.scene_run import simulate_creep

    return simulate_creep(scene, folder, progress=progress)


def _explicit_scene(scene: Scene, folder=None, progress=None):
    from hifumotion.particles.simulate import simulate

    return simulate(scene, folder, progress=progress)


#: The integrators behind :func:`run_model` and ``hifumotion simulate``, by ``ModelSettings.integrator``.
FORWARD_MODELS: dict[str, ForwardModel] = {m.name: m for m in (
    ForwardModel("implicit", _implicit, scene_run=_implicit_scene, pvd="creep.pvd"),
    ForwardModel("explicit", _explicit, scene_run=_explicit_scene, pvd="frames.pvd"),
    ForwardModel("reduced", _reduced, reduces="implicit"))}
assert tuple(FORWARD_MODELS) == INTEGRATORS, "every integrator the settings accept has a forward model"


def forward_model(spec_or_integrator) -> ForwardModel:
    """The forward model of a :class:`ModelSpec` (its ``settings.integrator``), of
    :class:`ModelSettings`, or of an integrator's name."""
    name = spec_or_integrator
    if isinstance(name, ModelSpec):
        name = name.settings.integrator
    elif isinstance(name, ModelSettings):
        name = name.integrator
    if name not in FORWARD_MODELS:
        raise InputError(f"unknown integrator {name!r}; expected {', '.join(FORWARD_MODELS)}", "integrator")
    return FORWARD_MODELS[name]


def run_model(spec: ModelSpec, k: Parameters, last_frame: int, keep_frames=(), full: bool = False) -> ModelRun:
    """Simulate frames 0 … ``last_frame`` with ``k``; the points A at every frame.

    ``keep_frames``: frames whose tissue particles are returned as well (for masks).
    ``full``: run the full model the spec's integrator reduces (:attr:`ForwardModel.full`; the
    spec's own when it is a full one).
    Raises :class:`~hifumotion.errors.InputError` for parameters outside the model's
    validity (ν ≥ 0.5, E ≤ 0 …).
    """
    _check_range(k)
    t0 = time.perf_counter()
    model = forward_model(spec)
    sim = (model.full if full else model)(spec, scene_for(spec, k, last_frame), k, last_frame)
    return _model_run(spec, k, sim, keep_frames, t0)


def run_snapshot(spec: ModelSpec, k: Parameters, last_frame: int):
    """A run of the fast path (the full model a reduced one is made from) at ``k`` to
    ``last_frame``: ``(its ModelRun, its CreepResult)`` — the second a reduced model's snapshot
    (:func:`~hifumotion.reduced.build.reduced_from_runs`)."""
    _check_range(k)
    t0 = time.perf_counter()
    sim, nodes = _implicit_with_nodes(spec, scene_for(spec, k, last_frame))
    return _model_run(spec, k, sim, (), t0), nodes


def _check_range(k: Parameters) -> None:
    if not (k.youngs_modulus_pa > 0 and -1 < k.poisson_ratio < 0.5 and k.beta1 >= 0):
        raise InputError(f"parameters outside the model's range: {k}", "parameters")


def _model_run(spec: ModelSpec, k: Parameters, sim, keep_frames, started: float) -> ModelRun:
    """A run's :class:`ModelRun`: the points A followed as material points (with the particles
    near them at frame 0), the kept frames' particles."""
    from hifumotion.particles.section import material_displacement

    rest = sim.tissue_mm[0]
    frames = np.arange(len(sim.times_s))
    u, _ = material_displacement(spec.points_mm, sim.tissue_mm, rest, spec.spacing_mm)
    kept = {int(f): sim.tissue_mm[f].copy() for f in keep_frames if 0 <= f < len(frames)}
    return ModelRun(k, frames, spec.points_mm + u, rest, kept, sim.bar_centre_mm, sim.steps,
                    time.perf_counter() - started)


__all__ = ["Parameters", "ModelSettings", "ModelSpec", "KeptReduced", "ReducedSnapshots", "ModelRun", "ForwardModel", "FORWARD_MODELS", "forward_model",
           "model_spec",
           "scene_for", "run_model", "run_snapshot"]
