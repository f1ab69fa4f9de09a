"""The twins the estimation and online benchmarks score on: one per therapy protocol, none the defaults.

Each is a protocol preset (the demo's resolution: 0.3 mm pixels, 200 frames at 20 Hz,
finite-element truth) with its own seed, shape, bar, material and push. They were
written down before any was scored and are not a default of anything; other twins,
with parameters nobody here sees, measure the same code.

A twin is generated once into ``<work>/<name>-<key>``, where ``key`` is a hash of its
full settings, so a changed case (or a changed default) makes a new one and a re-run
reads the old one.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

#: name -> (protocol preset, overrides of that preset)
CASES: dict[str, tuple[str, dict]] = {
    "paper_s41": ("paper", {
        "seed": 41,
        "blob": {"size_mm": [28.0, 17.0, 22.0], "lobes": 5, "irregularity": 0.15},
        "tissue": {"youngs_modulus_pa": 10000.0, "poisson_ratio": 0.46, "beta1": 5.0e5},
        "bar": {"radius_mm": 5.0, "force_n": 0.35},
    }),
    "slow_push_s42": ("slow_push", {
        "seed": 42,
        "blob": {"size_mm": [32.0, 19.0, 25.0], "lobes": 7, "irregularity": 0.10},
        "tissue": {"youngs_modulus_pa": 15000.0, "poisson_ratio": 0.48, "beta1": 9.0e5, "beta2": 0.45},
        "bar": {"radius_mm": 5.5},
        "protocol": {"peak_force_n": 1.4},
    }),
    "push_release_s43": ("push_release", {
        "seed": 43,
        "blob": {"size_mm": [26.0, 16.0, 24.0], "lobes": 4, "irregularity": 0.18},
        "tissue": {"youngs_modulus_pa": 12000.0, "poisson_ratio": 0.45, "beta1": 6.0e5},
        "bar": {"radius_mm": 6.5},
        "protocol": {"peak_force_n": 0.8, "ramp_s": 1.2, "hold_s": 2.5},
    }),
    "oblique_s44": ("oblique", {
        "seed": 44,
        "blob": {"size_mm": [30.0, 18.0, 22.0], "lobes": 6},
        "tissue": {"youngs_modulus_pa": 8000.0, "beta2": 0.55},
        "bar": {"radius_mm": 5.5},
        "protocol": {"peak_force_n": 0.6, "angle_deg": 20.0},
    }),
    # the push changes after the training frames, unannounced
    "push_change_s45": ("push_change", {
        "seed": 45,
        "blob": {"size_mm": [27.0, 17.0, 23.0], "lobes": 5, "irregularity": 0.12},
        "tissue": {"youngs_modulus_pa": 11000.0, "poisson_ratio": 0.47, "beta1": 6.5e5},
        "bar": {"radius_mm": 5.0},
        "protocol": {"peak_force_n": 0.45, "change_at_s": 6.3, "change_factor": 1.8},
    }),
    "push_change_s46": ("push_change", {
        "seed": 46,
        "blob": {"size_mm": [31.0, 18.0, 21.0], "lobes": 6, "irregularity": 0.16},
        "tissue": {"youngs_modulus_pa": 9000.0, "poisson_ratio": 0.45, "beta1": 4.5e5, "beta2": 0.45},
        "bar": {"radius_mm": 6.0},
        "protocol": {"peak_force_n": 0.55, "change_at_s": 5.7, "change_factor": 0.3, "change_ramp_s": 0.4},
    }),
}


#: twins whose bar is driven (travel control, finite-strain truth) so that they move
#: millimetres in the validation window, and whose motion changes after the training frames —
#: the drive stops within the window, unannounced to a filter that only sees the frames (a
#: slide at a steady rate to the end is the constant-velocity Kalman filter's own case,
#: docs/decisions.md); not in the default run (each twin takes ~15–50 min to make). The targets ask
#: for three twins that move ≥ 2 mm in the validation window: s47 moves 1.92 mm (at full
#: resolution; its coarse probe gave 2.42), so s50 — another seed, shape, material and bar — is the
#: third (2.62 mm), and s47 stays as a witness
LARGE_MOTION_CASES: dict[str, tuple[str, dict]] = {
    "slide_stop_s47": ("slide", {
        "seed": 47,
        "blob": {"size_mm": [29.0, 17.0, 23.0], "lobes": 5, "irregularity": 0.14},
        "tissue": {"youngs_modulus_pa": 9000.0, "poisson_ratio": 0.47, "beta1": 1.5e5},
        "bar": {"radius_mm": 6.0},
        "physics": {"friction": 0.15},
        "protocol": {"peak_travel_mm": 5.0, "angle_deg": 35.0, "ramp_s": 7.5},
    }),
    "slide_stop_s48": ("slide", {
        "seed": 48,
        "blob": {"size_mm": [33.0, 19.0, 24.0], "lobes": 7, "irregularity": 0.10},
        "tissue": {"youngs_modulus_pa": 14000.0, "poisson_ratio": 0.46, "beta1": 3.0e5, "beta2": 0.45},
        "bar": {"radius_mm": 5.5, "edge_radius_mm": 0.8},
        "physics": {"friction": 0.1},
        "protocol": {"peak_travel_mm": 4.5, "angle_deg": 30.0, "ramp_s": 8.0},
    }),
    "slide_stop_s49": ("slide", {
        "seed": 49,
        "blob": {"size_mm": [27.0, 18.0, 22.0], "lobes": 4, "irregularity": 0.16},
        "tissue": {"youngs_modulus_pa": 11000.0, "poisson_ratio": 0.45, "beta1": 2.0e5, "beta2": 0.55},
        "bar": {"radius_mm": 6.5, "edge_radius_mm": 0.3},
        "physics": {"friction": 0.2},
        "protocol": {"peak_travel_mm": 7.0, "angle_deg": 40.0, "ramp_s": 7.25},
    }),
    "slide_stop_s50": ("slide", {
        "seed": 50,
        "blob": {"size_mm": [30.0, 16.0, 21.0], "lobes": 6, "irregularity": 0.12},
        "tissue": {"youngs_modulus_pa": 12000.0, "poisson_ratio": 0.48, "beta1": 1.0e5, "beta2": 0.5},
        "bar": {"radius_mm": 6.0, "edge_radius_mm": 0.5},
        "physics": {"friction": 0.12},
        "protocol": {"peak_travel_mm": 6.0, "angle_deg": 38.0, "ramp_s": 7.75},
    }),
}

#: a drive that reverses (travel control, finite-strain truth): in, drawn back, then on again.
#: Friction holds the sample where the bar left it, and the bar must come back to it before it
#: moves again — a motion that is not a linear image of the travel, where a model of contact and
#: friction can earn its cost over a regression on the drive (each set before any score; ~17 min
#: each to make; docs/decisions.md, "A drive that reverses")
REVERSAL_CASES: dict[str, tuple[str, dict]] = {
    # in 4 mm over 4 s, drawn back to 2.5 mm by 5.5 s, then on to 7 mm by 9 s
    "slide_reverse_s51": ("slide", {
        "seed": 51,
        "blob": {"size_mm": [28.0, 17.0, 23.0], "lobes": 5, "irregularity": 0.13},
        "tissue": {"youngs_modulus_pa": 10000.0, "poisson_ratio": 0.47, "beta1": 2.0e5, "beta2": 0.5},
        "bar": {"radius_mm": 6.0, "edge_radius_mm": 0.5, "control": "travel", "travel_mm": 7.0,
                "schedule_times_s": [0.0, 4.0, 5.5, 9.0, 9.95], "schedule_travel_mm": [0.0, 4.0, 2.5, 7.0, 7.0],
                "direction": [0.573576436351046, -0.8191520442889918, 0.0]},     # 35° from the vertical
        "physics": {"friction": 0.15},
        "protocol": {"name": "custom"},
    }),
    # two more reversals: other seeds, shapes, materials, bars, frictions, angles and schedules
    "slide_reverse_s52": ("slide", {
        "seed": 52,
        "blob": {"size_mm": [31.0, 18.0, 22.0], "lobes": 6, "irregularity": 0.11},
        "tissue": {"youngs_modulus_pa": 13000.0, "poisson_ratio": 0.46, "beta1": 3.0e5, "beta2": 0.45},
        "bar": {"radius_mm": 5.5, "edge_radius_mm": 0.8, "control": "travel", "travel_mm": 6.5,
                "schedule_times_s": [0.0, 3.5, 5.0, 8.5, 9.95], "schedule_travel_mm": [0.0, 3.5, 2.0, 6.5, 6.5],
                "direction": [0.5, -0.8660254037844386, 0.0]},                 # 30°
        "physics": {"friction": 0.12},
        "protocol": {"name": "custom"},
    }),
    "slide_reverse_s53": ("slide", {
        "seed": 53,
        "blob": {"size_mm": [27.0, 17.0, 24.0], "lobes": 4, "irregularity": 0.16},
        "tissue": {"youngs_modulus_pa": 9000.0, "poisson_ratio": 0.48, "beta1": 1.5e5, "beta2": 0.55},
        "bar": {"radius_mm": 6.5, "edge_radius_mm": 0.3, "control": "travel", "travel_mm": 7.0,
                "schedule_times_s": [0.0, 4.5, 5.5, 9.0, 9.95], "schedule_travel_mm": [0.0, 4.5, 3.0, 7.0, 7.0],
                "direction": [0.6427876096865393, -0.766044443118978, 0.0]},   # 40°
        "physics": {"friction": 0.18},
        "protocol": {"name": "custom"},
    }),
}

#: every case by name
ALL_CASES = {**CASES, **LARGE_MOTION_CASES, **REVERSAL_CASES}


def case_config(name: str):
    """The :class:`~hifumotion.experiment.config.TwinConfig` of case ``name`` (any table)."""
    from hifumotion.experiment.config import twin_config

    preset, overrides = ALL_CASES[name]
    return twin_config(preset, overrides)


def twin_folder(work: Path, name: str) -> Path:
    """The twin of case ``name`` under ``work``, generated there first if it is not."""
    from hifumotion.experiment import generate_twin
    from hifumotion.io import output_folder

    cfg = case_config(name)
    today = json.loads(cfg.model_dump_json())
    key = hashlib.sha256(json.dumps(today, sort_keys=True).encode()).hexdigest()[:10]
    folder = Path(work) / f"{name}-{key}"
    if (folder / "truth" / "motion.json").is_file():
        return folder
    # a twin made before a setting was added (its default what the twin was made without) is
    # the same twin: its settings read by today's code are today's
    for made in sorted(Path(work).glob(f"{name}-*")):
        if _made_with(made) == today:
            return made
    with output_folder(folder, overwrite=False) as out:
        generate_twin(cfg, out)
    return folder


def _made_with(folder: Path) -> dict | None:
    """A generated twin's settings (``truth/parameters.json``'s ``config``) as today's code reads
    them; None where the folder is not a complete twin or its settings are no longer valid."""
    from hifumotion.experiment import TwinConfig

    try:
        if not (folder / "truth" / "motion.json").is_file():
            return None
        config = json.loads((folder / "truth" / "parameters.json").read_text())["config"]
        return json.loads(TwinConfig(**config).model_dump_json())
    except (OSError, ValueError, KeyError, TypeError):
        return None


if __name__ == "__main__":
    import sys

    work = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / ".bench" / "twins"
    for case in (sys.argv[2].split(",") if len(sys.argv) > 2 else CASES):
        print(case, twin_folder(work, case), flush=True)
