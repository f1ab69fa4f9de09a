"""A calibration folder: what ``hifumotion calibrate`` writes and ``hifumotion predict`` reads.

::

    parameters.json           values, uncertainties, identifiability, fit summary, settings
    search_log.jsonl          every forward run of the search (resumable)
    model/scene.toml          the fitted model at the paper's resolution (``hifumotion simulate`` runs it)
    model/tissue_particles.csv
    model/contour_points.csv  the contour points A (tank mm)
    model/tissue_surface.npz  the reconstructed surface the model's voxels conform to (tank mm, float64)
    model/reduced_snapshots.npz  the full runs the online loop's reduced model is made from (when
                              the calibration made them: ``online_model``): each run's times (s),
                              voxel nodes and bar advance (mm), its counts; the parameters and last frame
    observation/reference.npz the frame-0 shape: in-plane mask and the reconstruction's distance grid
    observation/frames/       the tracked (or given) masks of every frame, 0/255 PNG
    observation/sweep/        the sweep's masks
    observation/tissue.stl|ply|vtp, tissue_volume.nii.gz   the reconstruction (ParaView, 3D Slicer)
    run_info.json
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from hifumotion.errors import InputError
from hifumotion.estimation.model import ModelSettings, ModelSpec, Parameters, ReducedSnapshots
from hifumotion.io.files import atomic_path, require_regular_file, write_text
from hifumotion.io.structured import read_structured
from hifumotion.scene import Plane
from hifumotion.estimation.reference import ReferenceShape


def _csv(path: Path, header: str, rows: np.ndarray) -> None:
    body = "\n".join(",".join(f"{v:.6f}" for v in r) for r in rows)
    write_text(path, header + "\n" + body + "\n")


def _provenance(observed_dir: str | Path | None, folder: Path) -> str | None:
    """Where the observation came from: relative to the calibration when both are in one
    output folder (which is written under a temporary name and then renamed), else absolute."""
    import os

    if observed_dir is None:
        return None
    obs, root = Path(observed_dir).resolve(), folder.resolve()
    return Path(os.path.relpath(obs, root)).as_posix() if obs.is_relative_to(root.parent) else str(obs)


def save_calibration(cal, folder: str | Path, observed_dir: str | Path | None = None, extra: dict | None = None) -> dict:
    """Write a :class:`~hifumotion.estimation.calibrate.Calibration` into ``folder``: the fitted
    model (``model/``), what it was fitted to (``observation/``) and ``parameters.json``."""
    from hifumotion.io import write_json

    folder = Path(folder)
    for d in ("model", "observation/frames", "observation/sweep"):
        (folder / d).mkdir(parents=True, exist_ok=True)
    _write_model(cal, folder / "model")
    _write_observation(cal.observation, folder / "observation")
    summary = {**_summary(cal, folder, observed_dir), **(extra or {})}
    write_json(folder / "parameters.json", summary)
    return summary


def _write_model(cal, folder: Path) -> None:
    """The fitted scene, its particles, the points A and the surface its voxels conform to."""
    from hifumotion.config import dump_toml

    spec = cal.spec
    scene = spec.scene.model_copy(deep=True)
    k = cal.parameters
    scene.tissue.youngs_modulus_pa, scene.tissue.poisson_ratio = k.youngs_modulus_pa, k.poisson_ratio
    scene.tissue.beta1, scene.tissue.beta2, scene.bar.force_n = k.beta1, k.beta2, k.force_n
    scene.tissue.particles_csv = Path("tissue_particles.csv")
    write_text(folder / "scene.toml", dump_toml(scene))
    _csv(folder / "tissue_particles.csv", "x_mm,y_mm,z_mm,volume_mm3",
         np.column_stack([spec.tissue_mm, spec.tissue_volume_mm3]))
    _csv(folder / "contour_points.csv", "x_mm,y_mm,z_mm", spec.points_mm)
    if cal.online_snapshots is not None:
        write_reduced_snapshots(folder / "reduced_snapshots.npz", cal.online_snapshots)
    if spec.surface_vertices_mm is not None:
        # the model's voxels conform to this surface (ModelSpec.voxels): without it a loaded
        # calibration would run another mesh than the one that was fitted
        with atomic_path(folder / "tissue_surface.npz") as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, vertices_mm=np.asarray(spec.surface_vertices_mm, float),
                                    faces=np.asarray(spec.surface_faces, np.int64))


def _write_observation(obs, folder: Path) -> None:
    """Frame 0's reference shape, the tracked frames' masks (and material points), the sweep's
    masks and the reconstruction."""
    from hifumotion.io.writers import write_png_stack

    rec = obs.reconstruction
    ref = obs.reference_shape()
    plane = ref.plane
    with atomic_path(folder / "reference.npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, frame0_mask=ref.frame0_mask, rec_distance_mm=ref.rec_distance_mm.astype(np.float32),
                                rec_voxel_mm=ref.rec_voxel_mm, rec_origin_mm=np.asarray(ref.rec_origin_mm),
                                plane_origin_mm=np.asarray(plane.origin_mm), plane_u=np.asarray(plane.u),
                                plane_v=np.asarray(plane.v), plane_shape=np.asarray(plane.shape),
                                pixel_mm=plane.pixel_mm)
    write_png_stack(folder / "frames", obs.frame_masks, prefix="frame_", digits=4)
    if obs.motion is not None:   # the speckle-tracked material points beside the masks
        from hifumotion.speckle.output import material_points, write_material_points

        write_material_points(folder, material_points(obs.motion), obs.motion.displacement.spacing_mm)
    write_png_stack(folder / "sweep", obs.sweep.masks, prefix="slice_", digits=3)
    rec.write(folder)


def _summary(cal, folder: Path, observed_dir) -> dict:
    """``parameters.json``: the fit, its uncertainty, the models and the observation."""
    obs, spec, rec = cal.observation, cal.spec, cal.observation.reconstruction
    return {
        "description": "Parameters fitted by hifumotion calibrate (SI). 'determined' says whether the training "
                       "frames fix the value; E and β1 are at the nominal force (only F/E and β1/E are seen).",
        "observed": _provenance(observed_dir, folder),
        "observed_frame0_sha256": frame0_fingerprint(obs.observed.frames),
        "parameters": cal.report(),
        "training_frames": cal.training_frames,
        "frame_interval_s": spec.frame_interval_s,
        "frames": int(len(obs.frame_masks)),
        "model_settings": asdict(spec.settings),
        "model": {"tissue_particles": int(len(spec.tissue_mm)), "spacing_mm": spec.spacing_mm,
                  "search_tissue_particles": int(len(cal.search_spec.tissue_mm)),
                  "search_spacing_mm": cal.search_spec.spacing_mm,
                  "search_integrator": cal.search_spec.settings.integrator},
        # the online loop's reduced model's runs, saved (CalibrationSettings.online_model); null: not made
        "online_model": None if cal.online_snapshots is None else {
            "file": "model/reduced_snapshots.npz", "runs": len(cal.online_snapshots.runs),
            "last_frame": cal.online_snapshots.last_frame, "made_at": cal.online_snapshots.made_at.as_dict()},
        "fit": {
            "method": cal.search.method if cal.search is not None else "table1",
            "objective": cal.objective,
            "cost_mm": cal.search.cost_mm if cal.search is not None else float(cal.table1.frame_sums_mm.sum()),
            "S_t_mm": (np.abs(cal.search.residuals_mm).sum(1).round(3).tolist() if cal.search is not None
                       else cal.table1.frame_sums_mm.round(3).tolist()),
            "iterations": cal.search.iterations if cal.search is not None else None,
            "message": cal.search.message if cal.search is not None else None,
            "table1": None if cal.table1 is None else {
                "accepted": cal.table1.accepted, "threshold_mm": cal.table1.threshold_mm,
                "runs": cal.table1.runs, "events": cal.table1.events},
            "strategy": cal.record.as_dict(),
            "degeneracy": cal.degeneracy,
            "resolution_check": cal.resolution,
            # the fit's coordinates (estimation.space), their standard errors (null: no data bound
            # it) and correlations: the covariance the prediction's band is made from — the larger,
            # coordinate by coordinate, of the independent-point one and the frames' jackknife
            # (estimation.fit.uncertainty), both beside it
            "correlation": {"coordinates": list(cal.std),
                            "std": _finite_or_none(cal.std.values()),
                            "matrix": cal.correlation,
                            **({} if cal.assessment is None else {
                                "std_independent_points": _finite_or_none(cal.assessment.uncertainty.std_independent),
                                "std_frames_jackknife": _finite_or_none(cal.assessment.uncertainty.std_frames)})},
            "runs": cal.runs,
            "failed_runs": cal.failed_runs,
            "converged": cal.search.converged if cal.search is not None else None,
            "caveats": cal.caveats(),
        },
        "observation": {"contours": obs.contour_source, "sweep_planes_with_tissue": int(obs.sweep.present.sum()),
                        "bloom_continuation": obs.bloom_continuation,
                        "bloom_continued_by": obs.bloom_continued_by,
                        "reconstructed_volume_mm3": rec.volume_mm3, "notes": obs.sweep.notes + rec.notes},
        "timings_s": {**obs.timings_s, **cal.timings_s},
    }


def frame0_fingerprint(frames: np.ndarray) -> str:
    """SHA-256 of the time series' frame 0 (its pixels and shape): which experiment a calibration
    belongs to, whatever the folder is called or how many frames followed."""
    import hashlib

    first = np.ascontiguousarray(frames[0])
    return hashlib.sha256(repr((first.shape, str(first.dtype))).encode() + first.tobytes()).hexdigest()


def load_calibration(folder: str | Path) -> tuple[ModelSpec, Parameters, ReferenceShape, dict]:
    """The fitted model, its parameters, the frame-0 reference shape and ``parameters.json``.

    The model is the one that was fitted: its particles, its contour points and the surface
    its voxels conform to (``model/tissue_surface.npz``; a folder written before that file
    existed runs an unconformed mesh, as it did then)."""
    from hifumotion.scene import load_scene, read_particles_csv

    folder = Path(folder)
    pj = folder / "parameters.json"
    if not pj.is_file():
        raise InputError("not a calibration folder (no parameters.json; run hifumotion calibrate)", folder)
    try:
        meta = read_structured(pj, "json", "parameters.json")
        p = meta["parameters"]
        k = Parameters(force_n=p["external_force_n"]["value"], youngs_modulus_pa=p["youngs_modulus_pa"]["value"],
                       poisson_ratio=p["poisson_ratio"]["value"], beta1=p["beta1_pa_s_pow"]["value"],
                       beta2=p["beta2"]["value"],
                       friction=p["friction"]["value"] if "friction" in p else None)
        settings = ModelSettings(**meta["model_settings"])
        interval = float(meta["frame_interval_s"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"malformed calibration ({' '.join(str(exc).split())[:200]})", pj) from None
    _check_series(meta, interval, pj)
    scene = load_scene(folder / "model" / "scene.toml")
    tissue, volume = read_particles_csv(folder / "model" / "tissue_particles.csv")
    points, _ = read_particles_csv(folder / "model" / "contour_points.csv")
    vertices, faces = _surface(folder / "model" / "tissue_surface.npz")
    spec = ModelSpec(scene, tissue, volume if volume is not None else np.full(len(tissue), scene.particles.spacing_mm ** 3),
                     points, interval, settings, vertices, faces)
    snapshots = folder / "model" / "reduced_snapshots.npz"
    if snapshots.exists():
        spec.offer_reduced(read_reduced_snapshots(snapshots))
    ref_path = folder / "observation" / "reference.npz"
    if not ref_path.is_file():
        raise InputError("no such file", ref_path)
    try:
        with np.load(ref_path) as z:
            plane = Plane(tuple(z["plane_origin_mm"].tolist()), tuple(z["plane_u"].tolist()),
                          tuple(z["plane_v"].tolist()), tuple(int(v) for v in z["plane_shape"]), float(z["pixel_mm"]))
            ref = ReferenceShape(z["frame0_mask"].astype(bool), plane, z["rec_distance_mm"].astype(float),
                                 float(z["rec_voxel_mm"]), tuple(z["rec_origin_mm"].tolist()))
    except (OSError, EOFError, KeyError, TypeError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"unreadable frame-0 reference ({' '.join(str(exc).split())[:160]}); expected the npz "
                         "hifumotion calibrate writes (plane_*, pixel_mm, frame0_mask, rec_*)", ref_path) from None
    return spec, k, ref, meta


#: what each saved run keeps: all the reduced model is made from (:func:`~hifumotion.reduced.model.pod_basis`)
_RUN_ARRAYS = ("times_s", "nodes_mm", "advance_mm", "bar_force_n")


def write_reduced_snapshots(path: Path, snapshots: ReducedSnapshots) -> None:
    """``snapshots`` (:class:`~hifumotion.estimation.model.ReducedSnapshots`) as one npz, written atomically."""
    from hifumotion.io.writers import json_text

    arrays = {"made_at": np.array(json.dumps(snapshots.made_at.as_dict())), "last_frame": np.array(snapshots.last_frame),
              "runs": np.array(len(snapshots.runs))}
    for i, run in enumerate(snapshots.runs):
        arrays.update({f"run{i}_{name}": np.asarray(getattr(run, name), float) for name in _RUN_ARRAYS})
        arrays[f"run{i}_stats"] = np.array(json_text(run.stats))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


def read_reduced_snapshots(path: Path) -> ReducedSnapshots:
    """The runs :func:`write_reduced_snapshots` wrote, checked: one node count, finite motion, one
    time per frame; an :class:`~hifumotion.errors.InputError` naming ``path`` otherwise."""
    from hifumotion.creep.integrate import CreepResult

    require_regular_file(path, "npz of the reduced model's runs")     # a FIFO would hang np.load
    expected = ("expected the npz hifumotion calibrate writes (made_at, last_frame, runs and each run's "
                + ", ".join(_RUN_ARRAYS) + ", stats)")
    try:
        with np.load(path, allow_pickle=False) as z:
            made_at = Parameters(**json.loads(str(z["made_at"])))
            last, count = int(z["last_frame"]), int(z["runs"])
            runs = [_saved_run(z, i, CreepResult) for i in range(count)]
    except (OSError, EOFError, KeyError, TypeError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"unreadable reduced model's runs ({' '.join(str(exc).split())[:160]}); {expected}",
                         path) from None
    if not runs or len({r.nodes_mm.shape[1] for r in runs}) != 1 or last < 1:
        raise InputError(f"malformed reduced model's runs: expected runs of one node count to a frame ≥ 1, got "
                         f"{count} runs to frame {last}; {expected}", path)
    return ReducedSnapshots(made_at, last, tuple(runs))


def _saved_run(z, i: int, result_type):
    """Run ``i`` of an open ``reduced_snapshots.npz`` as a ``result_type`` (CreepResult); a
    ValueError unless it is one finite motion per frame, its times increasing."""
    a = {name: np.asarray(z[f"run{i}_{name}"], float) for name in _RUN_ARRAYS}
    frames, nodes = len(a["times_s"]), a["nodes_mm"]
    whole = (frames >= 2 and nodes.ndim == 3 and nodes.shape[0] == frames and nodes.shape[2] == 3
             and a["advance_mm"].shape == a["bar_force_n"].shape == (frames,)
             and all(np.isfinite(v).all() for v in a.values()) and np.all(np.diff(a["times_s"]) > 0))
    if not whole:
        raise ValueError(f"run {i}'s arrays are not one finite motion per frame")
    return result_type(a["times_s"], nodes, np.zeros((frames, 0, 3)), a["advance_mm"], a["bar_force_n"],
                       json.loads(str(z[f"run{i}_stats"])))


def _finite_or_none(values) -> list:
    """Standard errors as JSON: ``null`` where no data bound one (infinite)."""
    return [float(v) if np.isfinite(v) else None for v in values]


def _check_series(meta: dict, interval_s: float, path: Path) -> None:
    """``parameters.json``'s series: a whole number of frames (2 … ``resources.MAX_FRAMES``),
    training frames among them, a finite frame interval > 0 — each named where it is not."""
    from hifumotion.resources import MAX_FRAMES

    frames = meta.get("frames")
    if isinstance(frames, bool) or not isinstance(frames, int) or not 2 <= frames <= MAX_FRAMES:
        raise InputError(f"frames must be a whole number of frames, 2 … {MAX_FRAMES:,}, got {frames!r}", path)
    training = meta.get("training_frames")
    if (not isinstance(training, list) or not training
            or any(isinstance(f, bool) or not isinstance(f, int) or not 0 <= f < frames for f in training)):
        raise InputError(f"training_frames must be a list of frame numbers in 0 … {frames - 1}, got "
                         f"{str(training)[:60]}", path)
    if not (np.isfinite(interval_s) and 0 < interval_s <= 3600):
        raise InputError(f"frame_interval_s must be a finite time > 0 s (at most an hour), got {interval_s!r}", path)


def _surface(path: Path) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The model's surface (vertices mm, faces) from ``path``; (None, None) when there is none."""
    if not path.exists() and not path.is_symlink():
        return None, None
    require_regular_file(path, "npz of the model's surface")          # a FIFO would hang np.load
    try:
        with np.load(path) as z:
            vertices, faces = np.asarray(z["vertices_mm"], float), np.asarray(z["faces"], np.int64)
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"unreadable model surface ({exc}); expected vertices_mm and faces", path) from None
    if (vertices.ndim != 2 or vertices.shape[1:] != (3,) or faces.ndim != 2 or faces.shape[1:] != (3,)
            or not np.isfinite(vertices).all() or faces.min(initial=0) < 0 or faces.max(initial=0) >= len(vertices)):
        raise InputError("malformed model surface: expected finite (V, 3) vertices_mm and (F, 3) faces indexing them",
                         path)
    return vertices, faces


__all__ = ["save_calibration", "load_calibration", "frame0_fingerprint", "read_reduced_snapshots", "write_reduced_snapshots"]
