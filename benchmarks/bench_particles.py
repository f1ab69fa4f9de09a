"""Speed of the particle framework on the paper-sized scene, as JSON.

The paper's scene had 4,399 tissue, 3,344 water and 120 bar particles (7,863)
and ran at 11.5 frames/s on a GPU. This benchmark builds a scene of the same
counts (within a few %) — an ellipsoidal tissue 30 × 18 × 24 mm on the floor of
a small tank, a shallow pool, a steel bar — settles it briefly, then times
``--steps`` solver steps of the push. Printed: particle counts, steps per
second, simulated seconds per wall second (real-time factor), time per step
and peak memory. Target: ≥ 100 steps/s on 2 cores (measured: 115–125
with Numba's default OpenMP layer on an idle machine; 82–84 with the workqueue
layer; see docs/decisions.md for shared cores). For reference
(not run here): SPlisHSPlasH's DFSPH with Becker elasticity ran ≈ 28 steps/s
for 6,270 particles on this kind of machine.

It then runs 10 s of the synthetic twin's push (its material, bar and frame rate) on the
fast path (:mod:`hifumotion.creep`) at ``--fast`` tissue particle counts and reports wall
time, real-time factor (target ≥ 10 at 4,399 and ≥ 50 at 1,000), steps,
factorisations, the worst penetration, and the speed-up over the explicit path above.

    python benchmarks/bench_particles.py --json
    python benchmarks/bench_particles.py --steps 500 --threads 1 --fast ""
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from hifumotion import paper
from hifumotion.io.writers import json_text


def paper_scene(spacing_mm: float = 1.16):
    from hifumotion.scene import Scene

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


def fast_path(particles: int, push_s: float = 10.0) -> dict:
    """10 s of the synthetic twin's push (its material and bar) on the fast path (hifumotion.creep)."""
    import numpy as np

    from hifumotion.creep.scene_run import simulate_creep, tissue_mesh
    from hifumotion.experiment.config import TwinConfig
    from hifumotion.scene import Scene
    from hifumotion.scene.geometry import spacing_for_count, tissue_particles_mm

    twin = TwinConfig()
    scene = Scene()
    material = twin.tissue.model_dump()
    scene.tissue = scene.tissue.model_copy(update=material)
    scene.bar.force_n, scene.bar.ramp_s = twin.bar.force_n, twin.bar.ramp_s
    volume = np.pi / 6 * np.prod(scene.tissue.size_mm)
    dx, _ = spacing_for_count(lambda d: tissue_particles_mm(scene.tissue, scene.tank, d),
                              (volume / particles) ** (1 / 3), particles)
    scene.particles.spacing_mm = dx
    scene.run.duration_s = push_s
    scene.run.output_interval_s = 1.0 / twin.imaging.frame_rate_hz
    t0 = time.perf_counter()
    mesh, _ = tissue_mesh(scene)
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    sim = simulate_creep(scene, mesh=mesh)
    wall = time.perf_counter() - t0
    f = sim.facts
    return {"tissue_particles": len(mesh.centres_mm), "nodes": mesh.n_nodes, "spacing_mm": dx, "push_s": push_s,
            "frames": len(sim.times_s), "mesh_seconds": setup, "wall_s": wall, "real_time_factor": push_s / wall,
            "steps": f["creep_steps"], "rejected_steps": f["creep_rejected"],
            "factorisations": f["creep_factorisations"], "solves": f["creep_solves"],
            "cg_iterations": f["creep_cg_iterations"], "max_penetration_mm": f["creep_max_penetration_mm"],
            "bar_travel_mm": float(sim.bar_centre_mm[0, 1] - sim.bar_centre_mm[-1, 1])}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--warmup", type=int, default=30)
    parser.add_argument("--threads", type=int, default=None, help="Numba threads (default: all cores)")
    parser.add_argument("--json", action="store_true", help="print JSON only")
    parser.add_argument("--fast", default="1000,4399", help="tissue particles of the fast-path runs ('' for none)")
    parser.add_argument("--quick", action="store_true", help="a run of a few minutes: 150 steps")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps = 150
    if args.threads:
        os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    import numba

    from hifumotion.particles.scene_system import build_scene, solver_settings
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
    runs = [fast_path(int(n)) for n in args.fast.split(",") if n]
    for run in runs:  # the same run's explicit figure: how much faster the fast path is
        run["speedup_over_explicit"] = run["real_time_factor"] / out["real_time_factor"]
    out["fast_path"] = runs
    out["fast_path_targets"] = {"real_time_factor_at_4399": 10, "real_time_factor_at_1000": 50}
    print(json_text(out, indent=None if args.json else 2))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
