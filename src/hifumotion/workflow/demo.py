"""``hifumotion demo``: the whole system on the built-in synthetic experiment, then the report.

One documented order (each step's folder inside the output):

1. ``experiment/`` — the synthetic experiment: the sweep, the time series, the clicked contour
   (``observed/``) and the truth (``truth/``). The twin that ships with the package
   (:func:`~hifumotion.experiment.stored.bundled_twin`: preset ``slide_reverse``, seed 0) is copied
   there; another preset or seed, or ``regenerate``, makes one afresh
   (:func:`~hifumotion.experiment.generate_twin`: its finite-element truth takes minutes);
2. ``segmentation/`` — the paper's comparison of the six level-set methods (Table 2, Figures
   2–3) on planes of the twin's sweep against their true sections, and on the real images
   with expert masks of ``../shared/data/ddti`` when present;
3. the imaging system's boundary offset, measured on a simulated gel phantom of known shape
   imaged with the experiment's probe settings (:mod:`hifumotion.experiment.boundary_offset`);
4. the pipeline (:func:`~hifumotion.workflow.pipeline.run_pipeline`) on ``experiment/observed``:
   GLCV sweep → 3D reconstruction → particle model → tracking → calibration on the
   training frames → prediction of the validation frames → scores against the truth;
5. ``report/report.html``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from hifumotion.console import log
from hifumotion.experiment.stored import BUNDLED_PRESET
from hifumotion.workflow.pipeline import EstimationConfig, outcome_summary, run_pipeline

Progress = Callable[[str, float], None]

#: The estimation of the reduced presets (demo, small): the model at the twin's model size,
#: searched at that resolution (no second, finer model), a short least-squares search —
#: minutes on two cores. The default preset gets the paper's 4,399 particles and the full search.
REDUCED_ESTIMATION = {"max_evaluations": 3}


def demo_estimation(preset: str, model_particles: int, overrides: dict | None = None) -> EstimationConfig:
    """The estimation settings of a demo on ``preset`` (see :data:`REDUCED_ESTIMATION`), with ``overrides``."""
    base: dict = {}
    if preset != "default":
        base = {**REDUCED_ESTIMATION, "particles": model_particles, "search_particles": model_particles}
    base.update(overrides or {})
    if "particles" in (overrides or {}) and "search_particles" not in (overrides or {}):
        base["search_particles"] = min(base.get("search_particles", 1000), base["particles"])
    return EstimationConfig(**base)


def default_dataset() -> Path | None:
    """``../shared/data/ddti`` beside the source tree or the working directory, if present."""
    here = Path(__file__).resolve()
    for base in [Path.cwd(), *here.parents]:
        candidate = base.parent / "shared" / "data" / "ddti"
        if candidate.is_dir():
            return candidate
    return None


def sweep_dataset(twin, folder: str | Path, planes: int = 4, clicks: int = 8, error_mm: float = 0.6,
                  seed: int = 0) -> Path:
    """A segmentation dataset (``images/``, ``masks/``, ``init.json``) from a twin's sweep.

    ``twin`` is a :class:`~hifumotion.experiment.stored.StoredTwin`. The ``planes`` sweep planes
    nearest the middle of the tissue, their true sections as masks, and a clinician's rough
    clicks on each (``clicks`` points along the true boundary, each off by a normal radial
    error of ``error_mm``) as the common initial contour."""
    from hifumotion.contour import Contour
    from hifumotion.experiment.twin import clinician_contour
    from hifumotion.io import write_json
    from hifumotion.io.writers import write_mask_png, write_png_stack

    folder = Path(folder)
    pixel = twin.pixel_mm
    sections = np.asarray(twin.sweep_masks, bool)          # the end planes are empty
    area = sections.sum(axis=(1, 2))
    tissue = np.flatnonzero(area > 0.25 * area.max())
    middle = tissue[np.argsort(np.abs(tissue - tissue.mean()))[:planes]]
    rng = np.random.default_rng(seed)
    init = {}
    for i in sorted(middle):
        name = f"slice_{i:03d}.png"
        contour = Contour.from_mask(sections[i], pixel)
        points = clinician_contour(contour.points_px * pixel, clicks, error_mm, rng) / pixel
        init[name] = {"points": points.round(2).tolist()}
        write_png_stack(folder / "images", twin.sweep[i:i + 1], prefix="slice_", start=int(i), digits=3)
        write_mask_png(folder / "masks" / name, sections[i])
    write_json(folder / "init.json", init)
    return folder


@dataclass
class DemoSettings:
    """What ``hifumotion demo`` runs (every field has a default)."""

    preset: str = BUNDLED_PRESET             # twin preset: the twin the package ships (a drive that reverses, at the demo's resolution, seed 0); small (tests), default (the paper's size)
    seed: int = 0
    dataset: Path | None = None              # real images with expert masks; default ../shared/data/ddti
    dataset_images: int = 6
    sweep_planes: int = 4
    estimation_overrides: dict | None = None     # EstimationConfig fields on top of demo_estimation()
    regenerate: bool = False                 # make the twin afresh even where the package ships it


def demo_twin(out: Path, settings: DemoSettings, record, tell: Progress):
    """Step 1: the twin in ``out/experiment`` — the package's own, copied, where it ships one for
    the preset and seed and ``regenerate`` is not asked; otherwise generated (minutes)."""
    import shutil

    from hifumotion.experiment import generate_twin, twin_config
    from hifumotion.experiment.stored import BUNDLED_PRESET, BUNDLED_SEED, StoredTwin, bundled_twin, read_twin

    folder = out / "experiment"
    if not settings.regenerate and (settings.preset, settings.seed) == (BUNDLED_PRESET, BUNDLED_SEED):
        with record.stage("experiment: the package's twin"):
            shutil.copytree(bundled_twin(), folder)
            twin = read_twin(folder)
        record.config["twin"] = "the package's twin (experiment/run_info.json: how it was made)"
        return twin
    if not settings.regenerate:
        log.info(f"the package ships the twin of preset {BUNDLED_PRESET}, seed {BUNDLED_SEED} only: generating "
                 f"preset {settings.preset}, seed {settings.seed}")
    cfg = twin_config(settings.preset, seed=settings.seed)
    with record.stage("experiment: generate the synthetic twin"):
        result = generate_twin(cfg, folder, progress=tell)
    record.config["twin"] = "generated"
    return StoredTwin(folder, cfg, result.observed, np.asarray(result.frame_masks, bool),
                      np.asarray(result.sweep_masks, bool), result.parameters, result.motion)


def run_demo(out: Path, settings: DemoSettings, record, progress: Progress | None = None) -> dict:
    """Steps 1–5 of the module docstring into ``out`` (an output folder being written)."""
    from hifumotion.experiment.boundary_offset import measure_boundary_offset
    from hifumotion.io.dataset import Dataset, load_dataset
    from hifumotion.report.build import ReportInputs, SegmentationSection, output_links, write_report
    from hifumotion.segmentation import METHODS
    from hifumotion.segmentation.compare import compare_methods, write_comparison

    tell = progress or (lambda stage, fraction: None)
    result = demo_twin(out, settings, record, tell)
    cfg, twin, truth_params = result.config, result.folder, result.parameters

    segmentation = []
    methods = list(METHODS)
    with record.stage("segmentation: six methods on the twin's sweep"):
        data = load_dataset(sweep_dataset(result, out / "segmentation" / "sweep_dataset", settings.sweep_planes,
                                          seed=settings.seed))
        cmp = compare_methods(data, methods, "points", progress=_items(tell, "segmentation (sweep)"))
        paths = write_comparison(cmp, out / "segmentation", tag="_sweep")
        segmentation.append(SegmentationSection(
            f"The twin's sweep: {len(data)} planes, simulated B-mode against the true sections", cmp,
            paths["figure2"], paths["figure3"], "Initial contour: a clinician's 8 rough clicks on each plane."))
    folder = settings.dataset or default_dataset()
    if folder is None:
        log.warning("../shared/data/ddti not found: the segmentation comparison runs on the twin's sweep only")
    else:
        with record.stage("segmentation: six methods on real images"):
            real = load_dataset(folder)
            real = Dataset(real.root, real.items[: max(settings.dataset_images, 1)])
            cmp = compare_methods(real, methods, "points", progress=_items(tell, "segmentation (real images)"))
            paths = write_comparison(cmp, out / "segmentation", tag=f"_{Path(folder).name}")
            segmentation.append(SegmentationSection(
                f"Real ultrasound images with expert masks ({Path(folder).name}, {len(real)} images)", cmp,
                paths["figure2"], paths["figure3"], "Initial contour: the dataset's clicked points (init.json)."))

    estimation = demo_estimation(settings.preset, cfg.resolution.model_tissue_particles, settings.estimation_overrides)
    if "boundary_offset_mm" not in (settings.estimation_overrides or {}):
        # the lab's calibration of its imaging system: a phantom of known shape (not the sample),
        # imaged with the same probe settings, segmented the same way
        with record.stage("imaging: boundary offset on a phantom"):
            offset = measure_boundary_offset(cfg.imaging, "glcv", seed=settings.seed + 7919)
        estimation.boundary_offset_mm = round(offset.offset_mm, 3)
    record.config["estimation"] = estimation.model_dump(mode="json")
    truth = {f: m for f, m in enumerate(result.frame_masks)}
    outcome = run_pipeline(result.observed, out, estimation, truth_masks=truth, truth_kind="twin's true sections",
                           truth_parameters=truth_params, record=record, progress=tell,
                           observed_dir=twin / "observed")
    motion = result.motion
    with record.stage("report"):
        inputs = ReportInputs(
            title="hifumotion demo: the synthetic experiment end to end",
            segmentation=segmentation, timings_s=dict(record.timings_s),
            experiment_note=(f"A synthetic experiment (preset '{settings.preset}', seed {settings.seed}) stands in for "
                             f"the paper's cow tissue: {cfg.imaging.frames} frames at {cfg.imaging.frame_rate_hz:g} Hz, "
                             f"a {cfg.bar.force_n:g} N push by a rigid bar, tissue E = "
                             f"{cfg.tissue.youngs_modulus_pa:g} Pa, ν = {cfg.tissue.poisson_ratio:g}. The truth "
                             f"has {cfg.resolution.truth_particle_factor:g}× the fitted model's particles."),
            experiment_facts={"segmentation boundary offset, measured on a phantom (mm)": estimation.boundary_offset_mm,
                              "truth tissue particles": truth_params["facts"]["truth_tissue_particles"],
                              "true blob volume (mm³)": truth_params["facts"]["blob_volume_mm3"]},
            true_centroid_mm=np.asarray(motion["centroid_mm"], float),
            true_push_scale=_true_push_scale(cfg, result.observed.setup, outcome.training),
            links=output_links(out, {"experiment/truth/particles/frames.pvd — the twin's particles (ParaView)":
                                     out / "experiment" / "truth" / "particles" / "frames.pvd",
                                     "experiment/truth/finite_elements.pvd — the twin's finite-element truth (ParaView)":
                                     out / "experiment" / "truth" / "finite_elements.pvd"}))
        page = write_report(out / "report", outcome, truth, inputs)
    summary = outcome_summary(outcome)
    summary["report"] = page.relative_to(out).as_posix()
    summary["segmentation_mean_dsc"] = {r.title: {m: round(r.comparison.mean(m, "dsc"), 4) for m in methods}
                                        for r in segmentation}
    return summary


def _true_push_scale(cfg, setup, training: list[int]) -> np.ndarray:
    """The twin's true push over the program ``setup.json`` announced, per frame, as the online
    filter's push scale estimates it (:func:`~hifumotion.report.build.relative_push`)."""
    from hifumotion.report.build import relative_push

    t = np.arange(setup.frames) * setup.frame_interval_s
    bar = cfg.bar
    drive = bar.travel_schedule() if bar.control == "travel" else bar.schedule()
    return relative_push(np.array([drive(x) for x in t]), setup.program_at_frames(), max(training))


def _items(tell: Progress, stage: str):
    """A ``progress(items, description, total)`` iterator wrapper feeding the stage bars."""
    def wrap(items, description=None, total=None):
        items = list(items)
        for i, item in enumerate(items):
            tell(stage, i / max(len(items), 1))
            yield item
        tell(stage, 1.0)
    return wrap


__all__ = ["DemoSettings", "demo_twin", "run_demo", "sweep_dataset", "default_dataset", "demo_estimation"]
