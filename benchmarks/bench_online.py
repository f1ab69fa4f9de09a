"""Issue 39's benchmark, first part: the reduced forward model against the implicit path, in one run.

On each twin of ``_estimation_twins.CASES`` (or ``--twin DIR``), the observation
``bench_estimation`` fits (GLCV sweep, speckle-tracked frames, the boundary offset
measured on a phantom) gives the paper-resolution model (``--particles``, 4,399). At
the twin's own parameters K (the stand-in for a fit: what is measured is the forward
model, not the fit) and at F/E × 0.5, 0.7, 1.4 and 2:

* the implicit path (``integrator = "implicit"``) runs the whole push (every frame);
* the reduced model is made (``ModelSpec.reduced``: full runs at F/E × 0.5 and × 2, the
  POD of their motion, the Galerkin matrices) — its construction timed — and runs the
  same push at each F/E, on one core;
* the contour points A of both are compared: the RMS over the points of the difference
  of their displacement since frame 0, over the frames, against the implicit path's RMS
  motion (issue 39: within 3 % at K and at F/E × 0.5 and × 2). × 0.5 and × 2 are the
  snapshots' own forces; × 0.7, × 1.4 and K itself are forces the modes never saw.

Prints JSON: per twin and F/E the wall times, speed-ups (implicit / reduced; simulated
time / reduced: the real-time factor), the error ratio and the targets as true/false;
a summary at the end. ``--quick`` runs one twin at 1,000 particles (a few minutes).

Usage (run it alone: parallel jobs slow each other's timings)::

    python benchmarks/bench_online.py --quick
    python benchmarks/bench_online.py                          # the four twins, 4,399 particles
    python benchmarks/bench_online.py --twin DIR
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: issue 39's thresholds
SPEEDUP_OVER_IMPLICIT, REALTIME_FACTOR, POINT_ERROR = 100.0, 20.0, 0.03
SCALES = (1.0, 0.5, 2.0, 0.7, 1.4)
SNAPSHOT_SCALES = (0.5, 2.0)


def point_error(reduced: np.ndarray, implicit: np.ndarray) -> tuple[float, float]:
    """(max over frames of the RMS point difference of the motion since frame 0, max RMS motion), mm."""
    moved = implicit - implicit[:1]
    error = np.sqrt(np.mean(np.sum((reduced - reduced[:1] - moved) ** 2, axis=-1), axis=1))
    motion = np.sqrt(np.mean(np.sum(moved ** 2, axis=-1), axis=1))
    return float(error.max()), float(motion.max())


def run_twin(twin: Path, particles: int) -> dict:
    from bench_estimation import _twin_settings, observe

    from hifumotion.creep.linear import set_threads
    from hifumotion.estimation.model import ModelSettings, Parameters, model_spec, run_model
    from hifumotion.experiment.boundary_offset import measure_boundary_offset
    from hifumotion.experiment.config import ImagingConfig

    imaging = ImagingConfig(**_twin_settings(twin)["imaging"])
    offset_mm = round(measure_boundary_offset(imaging, "glcv", seed=7919).offset_mm, 3)
    observed, obs, *_ = observe(twin, "tracked", "speckle", offset_mm)
    p = json.loads((twin / "truth" / "parameters.json").read_text())
    k = Parameters(p["external_force_n"], p["youngs_modulus_pa"], p["poisson_ratio"], p["beta1_pa_s_pow"], p["beta2"])
    last = len(observed.frames) - 1
    simulated_s = last * observed.frame_interval_s
    set_threads(1)   # one core, as the targets and the calibration's workers
    implicit = model_spec(obs, ModelSettings(tissue_particles=particles))
    reduced = model_spec(obs, ModelSettings(tissue_particles=particles, integrator="reduced",
                                            reduced_span=SNAPSHOT_SCALES))
    reduced._voxels = implicit.voxels()   # the same mesh (made once)
    t0 = time.perf_counter()
    model = reduced.reduced(k, last)
    build_s = time.perf_counter() - t0
    rows = []
    for scale in SCALES:
        ks = k.replaced(force_n=k.force_n * scale)
        full = run_model(implicit, ks, last)
        t1 = time.perf_counter()
        red = run_model(reduced, ks, last)
        red_s = time.perf_counter() - t1
        error, motion = point_error(red.points_mm, full.points_mm)
        rows.append({"force_over_youngs_scale": scale, "in_snapshots": scale in SNAPSHOT_SCALES,
                     "implicit_s": round(full.seconds, 3), "reduced_s": round(red_s, 4),
                     "speedup_over_implicit": round(full.seconds / red_s, 1),
                     "realtime_factor": round(simulated_s / red_s, 1),
                     "points_rms_motion_mm": round(motion, 4), "points_error_mm": round(error, 5),
                     "error_over_motion": round(error / motion, 5) if motion > 0 else None,
                     "reduced_steps": red.steps, "implicit_steps": full.steps})
    at_k = rows[0]
    targets = {
        "speedup_over_implicit_100x": at_k["speedup_over_implicit"] >= SPEEDUP_OVER_IMPLICIT,
        "realtime_20x_one_core": at_k["realtime_factor"] >= REALTIME_FACTOR,
        "points_within_3pct_at_K_and_x0.5_x2": all(r["error_over_motion"] is not None
                                                   and r["error_over_motion"] <= POINT_ERROR
                                                   for r in rows if r["force_over_youngs_scale"] in (1.0, 0.5, 2.0)),
    }
    return {"twin": twin.name, "particles": int(len(implicit.tissue_mm)), "frames": last + 1,
            "simulated_s": round(simulated_s, 3), "modes": model.basis.size,
            "contact_rows": int(len(model.rows)), "construction_s": round(build_s, 2), "runs": rows,
            "targets": targets}


def main() -> None:
    from _estimation_twins import CASES, twin_folder

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one twin at 1,000 particles")
    ap.add_argument("--cases", default=None, help="comma-separated case names (default: all)")
    ap.add_argument("--twin", type=Path, default=None, help="an existing twin folder instead of the cases")
    ap.add_argument("--particles", type=int, default=None, help="tissue particles (default 4,399; --quick 1,000)")
    ap.add_argument("--work", type=Path, default=ROOT / ".bench" / "twins")
    args = ap.parse_args()
    particles = args.particles or (1000 if args.quick else 4399)
    if args.twin is not None:
        twins = [args.twin]
    else:
        names = args.cases.split(",") if args.cases else list(CASES)
        if args.quick and not args.cases:
            names = names[:1]
        twins = [twin_folder(args.work, n) for n in names]
    results = []
    for twin in twins:
        results.append(run_twin(twin, particles))
        print(json.dumps(results[-1]), flush=True)
    summary = {"twins": len(results),
               "all_targets_met": all(all(r["targets"].values()) for r in results),
               "min_speedup_over_implicit": min(r["runs"][0]["speedup_over_implicit"] for r in results),
               "min_realtime_factor": min(r["runs"][0]["realtime_factor"] for r in results),
               "max_error_over_motion": max(x["error_over_motion"] or 0.0 for r in results for x in r["runs"]),
               "max_construction_s": max(r["construction_s"] for r in results)}
    print(json.dumps({"summary": summary}), flush=True)


if __name__ == "__main__":
    main()
