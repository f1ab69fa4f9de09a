"""``hifumotion simulate`` and ``hifumotion validate``: the particle framework from the shell."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app
from hifumotion.console import console
from hifumotion.errors import InputError


@app.command()
def simulate(
    scene_file: Optional[Path] = typer.Argument(None, help="Scene file (TOML or YAML); defaults for anything it leaves out."),
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="New output folder."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
    print_scene: bool = typer.Option(False, "--print-scene", help="Print the scene (every field, with its unit) as TOML and exit."),
    settings: Optional[list[str]] = typer.Option(None, "--set", help="Change one setting: KEY=VALUE, KEY a dotted path (bar.force_n=0.3, run.duration_s=2); repeatable."),
    integrator: str = typer.Option("explicit", "--integrator", help="explicit: the paper's particle framework (SPH water, Eq. 8–20); implicit: the fast path (the tissue's creep, contacts as constraints, water as buoyancy). The reduced model runs only around a fit (calibrate, predict)."),
) -> None:
    """Simulate tissue, water and bar: frames/*.vtu + frames.pvd (ParaView), bar_pose.csv, run_info.json.

    With --integrator implicit: creep.pvd (the tissue's voxels, displacement in mm) instead of frames.pvd.
    """
    from hifumotion.config import dump_toml
    from hifumotion.console import progress_fraction
    from hifumotion.io import output_folder, write_json
    from hifumotion.estimation.model import forward_model
    from hifumotion.scene import load_scene
    from hifumotion.run_info import RunRecord

    scene = load_scene(scene_file, settings)
    if print_scene:
        typer.echo(dump_toml(scene))
        return
    if output is None:
        raise InputError("give an output folder", "--output")
    try:
        model = forward_model(integrator)
        if model.scene_run is None:
            model.simulate(scene)           # says why, naming the models that can
    except InputError as exc:
        raise InputError(exc.reason, "--integrator") from None
    record = RunRecord("simulate", config={**json.loads(scene.model_dump_json()), "integrator": integrator})
    with output_folder(output, overwrite, inputs=(scene_file, scene.tissue.particles_csv)) as out:
        with record.stage("simulate"), progress_fraction("simulate") as update:
            result = model.simulate(scene, out, progress=update)
        record.extra["scene"] = result.facts
        record.extra["steps"] = result.steps
        write_json(out / "summary.json", {
            "frames": len(result.times_s), "steps": result.steps, **result.facts,
            "tissue_centroid_mm": result.tissue_mm.mean(axis=1).round(4).tolist(),
            "bar_centre_mm": result.bar_centre_mm.round(4).tolist(),
        })
        record.write(out)
    console.print(f"simulation in {output.resolve()}: open {model.pvd} in ParaView "
                  f"({len(result.times_s)} frames, {result.steps} steps)", highlight=False)


@app.command()
def validate(
    case: str = typer.Argument(..., help="hydrostatic, cantilever, plate, hertz, poisson, rotation, buoyancy, momentum, or all."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Run a validation case of the particle framework against its analytic reference."""
    from hifumotion.particles.validation import CASES, run_case

    names = list(CASES) if case == "all" else [case]
    unknown = [n for n in names if n not in CASES]
    if unknown:
        raise InputError(f"unknown case; choose from {', '.join(CASES)} or all", unknown[0])
    results = [run_case(n).to_dict() for n in names]
    if as_json:
        from hifumotion.io.writers import json_text

        typer.echo(json_text(results[0] if len(results) == 1 else results))
    else:
        for r in results:
            mark = "[green]passed[/green]" if r["passed"] else "[red]FAILED[/red]"
            console.print(f"{r['case']:12s} {mark}  measured {r['measured']:.6g}  reference "
                          f"{r['reference']:.6g}  error {r['rel_error']:.3g} (tolerance {r['tolerance']:g})  "
                          f"{r['seconds']:.1f} s")
    if not all(r["passed"] for r in results):
        raise typer.Exit(1)
