"""Resolution convergence of the twin's physics: how far the tissue moves at 1×, 2×, 4× the particles.

The same sample, material and push simulated at several resolutions (the ``demo`` preset's
model size times each factor) for the training window (5 s of push). A converged particle
model moves its tissue the same at every resolution; printed per run (JSON):

* ``mean_descent_mm`` — the tissue particles' mean downward displacement since frame 0;
* ``bottom_sink_mm`` — that of the bottom 10 % (the layer on the floor): its sinking into the
  floor's contact, which no elastic deformation explains;
* ``top_descent_mm`` — that of the top 10 %; ``bar_travel_mm`` — the bar's, at 1, 2.5 and 5 s.

Usage::

    python benchmarks/bench_convergence.py                       # factors 1,2,4; contact factor 4
    python benchmarks/bench_convergence.py --contact-factor 16    # a 4× stiffer Eq. 18 contact

Runs one process per factor (two at a time on two cores).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor


def one(factor: float, contact_factor: float, preset: str, seed: int) -> dict:
    import numba
    import numpy as np

    from hifumotion.experiment import twin_config
    from hifumotion.experiment.twin import simulate_truth

    numba.set_num_threads(1)
    cfg = twin_config(preset, seed=seed, overrides={"imaging": {"frames": 101},
                                                     "physics": {"contact_pressure_factor": contact_factor}})
    t0 = time.perf_counter()
    run = simulate_truth(cfg, tempfile.mkdtemp(prefix="bench_convergence_"), particle_factor=factor)
    sim = run.simulation
    x0, x = sim.tissue_mm[0], sim.tissue_mm[-1]
    dy = x[:, 1] - x0[:, 1]
    bottom = x0[:, 1] < np.percentile(x0[:, 1], 10)
    top = x0[:, 1] > np.percentile(x0[:, 1], 90)
    bar = sim.bar_centre_mm[:, 1] - sim.bar_centre_mm[0, 1]
    frame = {t: int(round(t / sim.times_s[1])) for t in (1.0, 2.5, 5.0)}
    return {"factor": factor, "tissue_particles": int(len(x0)), "spacing_mm": run.spacing_mm,
            "contact_pressure_factor": contact_factor,
            "mean_descent_mm": float(-dy.mean()), "bottom_sink_mm": float(-dy[bottom].mean()),
            "top_descent_mm": float(-dy[top].mean()),
            "bar_travel_mm": {str(t): float(-bar[min(f, len(bar) - 1)]) for t, f in frame.items()},
            "seconds": time.perf_counter() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--factors", default="1,2,4")
    ap.add_argument("--contact-factor", type=float, default=4.0)
    ap.add_argument("--preset", default="demo")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    factors = [float(f) for f in args.factors.split(",")]
    with ProcessPoolExecutor(args.workers) as pool:
        runs = list(pool.map(one, factors, [args.contact_factor] * len(factors), [args.preset] * len(factors),
                             [args.seed] * len(factors)))
    finest = runs[-1]["mean_descent_mm"]
    out = {"preset": args.preset, "seed": args.seed, "runs": runs,
           "mean_descent_over_finest": [r["mean_descent_mm"] / finest for r in runs]}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
