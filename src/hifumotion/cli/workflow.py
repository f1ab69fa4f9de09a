"""``hifumotion demo`` and ``hifumotion run``: the whole system end to end.

``demo`` runs it on the built-in synthetic experiment (:mod:`hifumotion.workflow.demo`),
``run CONFIG.toml`` on a user's files (:mod:`hifumotion.workflow.user_run`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app
from hifumotion.console import console
from hifumotion.errors import InputError


@app.command()
def demo(
    output: Path = typer.Option(Path("demo-output"), "--output", "-o", help="New output folder."),
    preset: Optional[str] = typer.Option(None, "--preset", help="Synthetic experiment (default: the twin the package ships, slide_reverse at seed 0: a tilted bar driven in, drawn back and driven on, which friction and contact make no linear image of the drive). Any other preset or seed is generated (minutes): push_change (the push raised unannounced after the training frames), slow_push (the force rising all along), demo (the paper's ramp-and-hold push), paper, push_release, oblique, slide, drive_release, small (seconds), default (the paper's resolution; long)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the synthetic experiment."),
    dataset: Optional[Path] = typer.Option(None, "--dataset", help="Real images with expert masks (images/, masks/, init.json); default ../shared/data/ddti."),
    images: int = typer.Option(6, "--images", min=1, help="How many images of the dataset to segment."),
    particles: Optional[int] = typer.Option(None, "--particles", min=100, max=1_000_000, help="Tissue particles of the fitted model (default: the preset's model size)."),
    max_evaluations: Optional[int] = typer.Option(None, "--max-evaluations", min=1, help="Least-squares evaluations of the calibration (default 3 on the reduced presets, 8 on default)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, max=256, help="Dask worker processes (default: the cores)."),
    regenerate: bool = typer.Option(False, "--regenerate", help="Make the twin afresh (its finite-element truth: minutes) instead of copying the one the package ships."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Run the whole system on the synthetic experiment: twin → segment → reconstruct → calibrate → predict → report."""
    from hifumotion.console import StageBars
    from hifumotion.experiment.config import PRESETS
    from hifumotion.io import output_folder
    from hifumotion.run_info import RunRecord
    from hifumotion.workflow.demo import DemoSettings, run_demo

    preset = DemoSettings.preset if preset is None else preset
    if preset not in PRESETS:
        raise InputError(f"unknown preset; choose from {', '.join(PRESETS)}", "--preset")
    if dataset is not None:
        from hifumotion.io.dataset import load_dataset

        if not dataset.is_dir():
            raise InputError("no such dataset folder", dataset)
        load_dataset(dataset)      # read before the minutes of the twin: a wrong folder is said at once
    overrides: dict = {"workers": workers}
    if max_evaluations is not None:
        overrides["max_evaluations"] = max_evaluations
    if particles is not None:
        overrides.update(particles=particles, search_particles=particles)
    settings = DemoSettings(preset=preset, seed=seed, dataset=dataset, dataset_images=images,
                            estimation_overrides=overrides, regenerate=regenerate)
    record = RunRecord("demo", config={"preset": preset, "seed": seed, "dataset": None if dataset is None else str(dataset),
                                       "images": images, "regenerate": regenerate}, seed=seed)
    with output_folder(output, overwrite, inputs=(dataset,)) as out:
        with StageBars() as progress:
            summary = run_demo(out, settings, record, progress)
        record.extra["summary"] = summary
        record.write(out)
    root = output.resolve()
    v = summary
    console.print(f"validation DSC {v['validation_dsc_mean']:.4f} (min {v['validation_dsc_min']:.4f}), centroid error "
                  f"{v['validation_centroid_mean_mm']:.2f} mm; no motion {v['no_motion_validation_dsc_mean']:.4f}, "
                  f"Kalman {v['kalman_validation_dsc_mean']:.4f}; the physics is {_verdict(v)}", highlight=False)
    if v.get("verdict"):
        console.print(f"of every predictor: {v['verdict']}", highlight=False)
    if v.get("aim_band_largest_mm") is not None:
        console.print(f"the aim, the fit one standard error either way along its least determined direction: up to "
                      f"{v['aim_band_largest_mm']:.2f} mm from the fit's (prediction/aim.csv band_mm)", highlight=False)
    if v.get("choice"):
        console.print(f"the training frames' choice: {v['choice']}", highlight=False)
    console.print(f"open {root / 'report' / 'report.html'} — the report; prediction/tissue.pvd in ParaView; "
                  f"calibration/observation/tissue_volume.nii.gz in 3D Slicer; all in {root}", highlight=False)


@app.command()
def run(
    config: Optional[Path] = typer.Argument(None, help="A run configuration (TOML or YAML); see --example."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="New output folder (default: the config's output)."),
    example: bool = typer.Option(False, "--example", help="Print a complete example configuration and exit."),
    settings: Optional[list[str]] = typer.Option(None, "--set", help="Change one setting: KEY=VALUE, KEY a dotted path (estimation.model.creep.tolerance=0.01, estimation.search_integrator=reduced); repeatable."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
) -> None:
    """Run the whole pipeline on your own files: sweep + time series → calibrate → predict → score → report."""
    from hifumotion.console import StageBars
    from hifumotion.io import output_folder
    from hifumotion.run_info import RunRecord
    from hifumotion.workflow.user_run import example_text, load_run_config, run_inputs, run_user

    if example:
        typer.echo(example_text(), nl=False)        # plain stdout, unwrapped: meant for "> run.toml"
        return
    if config is None:
        raise InputError("give a run configuration file (hifumotion run --example prints one)", "CONFIG")
    cfg, base = load_run_config(config, settings)
    target = output or (None if cfg.output is None else (cfg.output if cfg.output.is_absolute() else base / cfg.output))
    if target is None:
        raise InputError("no output folder: give -o or set output in the configuration", config)
    record = RunRecord("run", config=cfg.model_dump(mode="json"))
    with output_folder(target, overwrite, inputs=(config, *run_inputs(cfg, base))) as out:
        with StageBars() as progress:
            summary = run_user(cfg, base, out, record, progress)
        record.extra["summary"] = summary
        record.write(out)
    v = summary
    console.print(f"validation DSC {v['validation_dsc_mean']:.4f} (min {v['validation_dsc_min']:.4f}) against the "
                  f"{v['truth']}; no motion {v['no_motion_validation_dsc_mean']:.4f}; the physics is {_verdict(v)}",
                  highlight=False)
    if v.get("verdict"):
        console.print(f"of every predictor: {v['verdict']}", highlight=False)
    if v.get("choice"):
        console.print(f"the training frames' choice: {v['choice']}", highlight=False)
    console.print(f"open {target.resolve() / 'report' / 'report.html'}; all results in {target.resolve()}",
                  highlight=False)


def _verdict(summary: dict) -> str:
    """The physics against holding still, with the margin's spread over the validation frames and
    the metric that decided: a margin beyond its spread (``evaluate.margin_over``)."""
    verdict = summary.get("physics_vs_no_motion")
    if verdict is None:
        return "not compared with holding still (too few validation frames)"
    words = {"better": "better than", "worse": "worse than", "no better": "no better than"}[verdict]
    margins = {"DSC": (summary["dsc_margin_over_no_motion"], summary["dsc_margin_spread"])}
    if summary.get("centroid_margin_over_no_motion_mm") is not None:
        margins["centroid"] = (summary["centroid_margin_over_no_motion_mm"], summary["centroid_margin_spread_mm"])
    beyond = [name for name, (mean, spread) in margins.items() if abs(mean) > spread]
    within = [name for name in margins if name not in beyond]
    decided = f" by the {' and the '.join(beyond)}" if verdict != "no better" and beyond else ""
    # both margins: the verdict may rest on either, and the line says which
    centroid = ""
    if "centroid" in margins:
        centroid = f", centroid {margins['centroid'][0]:+.3f} ± {margins['centroid'][1]:.3f} mm"
    note = ""
    if decided and within:
        note = f"; the {' and '.join(within)} margin is within its spread"
    return (f"{words} holding still{decided} (DSC {margins['DSC'][0]:+.4f} ± {margins['DSC'][1]:.4f}{centroid} "
            f"a frame{note})")