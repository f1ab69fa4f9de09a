"""Speed of the particle framework on the paper-sized scene, as JSON.

The paper's scene had 4,399 tissue, 3,344 water and 120 bar particles (7,863)
and ran at 11.5 frames/s on a GPU. This benchmark builds a scene of the same
counts (within a few %) — an ellipsoidal tissue 30 × 18 × 24 mm on the floor of
a small tank, a shallow pool, a steel bar — settles it briefly, then times
``--steps`` solver steps of the push. Printed: particle counts, steps per
second, simulated seconds per wall second (real-time factor), time per step
and peak memory. Target (issue 6): ≥ 100 steps/s on 2 cores (measured: 115–125
with Numba's default OpenMP layer on an idle machine; 82–84 with the workqueue
layer; see docs/decisions.md for shared cores). For reference
(not run here): SPlisHSPlasH's DFSPH with Becker elasticity ran ≈ 28 steps/s
for 6,270 particles on this kind of machine.

    python benchmarks/bench_particles.py --json
    python benchmarks/bench_particles.py --steps 500 --threads 1
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from hifumotion import paper


def paper_scene(spacing_mm: float = 1.16):
    from hifumotion.particles.scene import Scene

    scene = Scene()
    scene.particles.spacing_mm = spacing_mm
    scene.tissue.size_mm = (30.0, 18.0, 24.0)
    scene.tank.size_mm = (40.0, 30.0, 30.0)
    scene.tank.water_depth_mm = 6.4
    scene.bar.radius_mm = 2.6
    scene.bar.length_mm = 9.0
    scene.bar.force_n = 0.02
    scene.run.settle_s = 0.0
    return scene


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--warmup", type=int, default=30)
    parser.add_argument("--threads", type=int, default=None, help="Numba threads (default: all cores)")
    parser.add_argument("--json", action="store_true", help="print JSON only")
    args = parser.parse_args(argv)
    if args.threads:
        os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    import numba

    from hifumotion.particles.scene import build_scene, solver_settings
    from hifumotion.particles.solver import Solver

    scene = paper_scene()
    system, facts = build_scene(scene)
    solver = Solver(system, solver_settings(scene))
    for _ in range(args.warmup):  # compile and let the neighbour lists settle
        solver.step()
    t0 = time.perf_counter()
    sim0 = system.time_s
    for _ in range(args.steps):
        solver.step()
    wall = time.perf_counter() - t0
    simulated = system.time_s - sim0
    counts = facts["counts"]
    moving = counts["fluid"] + counts["tissue"] + counts["rigid"]
    out = {
        "benchmark": "particles",
        "particles": moving,
        "counts": counts,
        "paper_counts": {"tissue": paper.TISSUE_PARTICLES, "fluid": paper.WATER_PARTICLES, "rigid": paper.BAR_PARTICLES},
        "spacing_mm": scene.particles.spacing_mm,
        "steps": args.steps,
        "steps_per_s": args.steps / wall,
        "ms_per_step": 1000 * wall / args.steps,
        "mean_step_s": simulated / args.steps,
        "real_time_factor": simulated / wall,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "threads": numba.get_num_threads(),
        "threading_layer": numba.threading_layer(),
        "target_steps_per_s": 100,
        "reference": {"paper_gpu_frames_per_s": 11.5, "splishsplash_dfsph_steps_per_s_6270": 28},
    }
    print(json.dumps(out, indent=None if args.json else 2))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
