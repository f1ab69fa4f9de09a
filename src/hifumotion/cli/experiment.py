"""``hifumotion experiment``: generate the synthetic HIFU experiment (observed/ and truth/)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from hifumotion.cli.app import app
from hifumotion.console import console
from hifumotion.errors import InputError


@app.command()
def experiment(
    output: Optional[Path] = typer.Option(None, "--output", "-o", help="New output folder (observed/ and truth/ go inside)."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="twin.toml (or .yaml) overriding any setting of the preset."),
    preset: str = typer.Option("default", "--preset", help="default (the paper-sized twin), demo (coarse), small (a reduced twin for tests, particle truth), or a therapy protocol on the demo's resolution: paper, slow_push, push_release, oblique, push_change (the push changed unannounced after the training frames); or a driven bar on the finite-strain truth: slide (tilted, driven at a steady rate: the sample slides), slide_reverse (tilted, driven in, drawn back, driven on: friction holds the sample until the bar returns), drive_release (driven in, held, drawn back)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of every random draw (overrides the config's)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output folder."),
    print_config: bool = typer.Option(False, "--print-config", help="Print every setting (with its unit) as TOML and exit."),
    settings: Optional[list[str]] = typer.Option(None, "--set", help="Change one setting: KEY=VALUE, KEY a dotted path (imaging.frames=100, protocol.name=oblique); repeatable."),
) -> None:
    """Generate the digital twin of the paper's experiment: a sweep, 200 frames, a clicked contour, and the truth."""
    from hifumotion.config import dump_toml
    from hifumotion.console import StageBars
    from hifumotion.experiment import generate_twin, summary_line, twin_config
    from hifumotion.io import output_folder
    from hifumotion.run_info import RunRecord

    from hifumotion.config import apply_settings

    cfg = twin_config(preset, overrides=apply_settings({}, settings), config_file=config, seed=seed)
    if print_config:
        typer.echo(dump_toml(cfg))
        return
    if output is None:
        raise InputError("give an output folder", "--output")
    record = RunRecord("experiment", config=json.loads(cfg.model_dump_json()), seed=cfg.seed)
    record.extra["preset"] = preset
    with output_folder(output, overwrite, inputs=(config,)) as out:
        with StageBars() as progress, record.stage("experiment"):
            result = generate_twin(cfg, out, progress)
        record.extra["timings_s"] = result.timings_s
        record.extra["facts"] = result.facts
        record.write(out)
    console.print(f"experiment in {output.resolve()}: {summary_line(result)}; "
                  f"{result.timings_s['total_s']:.0f} s", highlight=False)
