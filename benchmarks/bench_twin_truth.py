"""How far the fitted model (the voxel fast path) is from the twin's finite-element truth.

Reads a twin folder made with ``truth.solver = "finite_elements"`` (``hifumotion experiment
--preset demo -o twin/``), runs the fast path (:func:`hifumotion.creep.simulate_creep`) on
the same sample, material, bar and schedule — its particles the truth's lattice, its voxels
conformed to the sample's surface — and compares the displacement of every lattice point
frame by frame. Prints JSON: RMS and largest difference over the truth's largest
displacement, the whole sample's turn in each (rotation vectors since frame 0, degrees), the bar's advance in both, and the wall times.

    .venv/bin/python benchmarks/bench_twin_truth.py twin/ [--frames 0,50,100,199]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from hifumotion.io.writers import json_text

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("twin", type=Path)
    args = ap.parse_args()
    from _rigid_split import split_difference

    from hifumotion.creep.scene_run import simulate_creep
    from hifumotion.experiment.blob import Blob
    from hifumotion.experiment.config import TwinConfig, apply_protocol
    from hifumotion.experiment.twin import _seeds, truth_scene

    truth = args.twin / "truth"
    params = json.loads((truth / "parameters.json").read_text())
    cfg = apply_protocol(TwinConfig.model_validate(params["config"]))
    traj = np.load(truth / "tissue_trajectory.npz")
    fe = traj["positions_mm"].astype(float)
    dx = float(traj["spacing_mm"])
    placement = np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2])
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut,
                       int(_seeds(cfg)[0]))
    lattice = blob.particles(dx) + placement
    if len(lattice) != fe.shape[1]:
        lattice = np.loadtxt(truth / "blob_particles.csv", delimiter=",", skiprows=1)[:, :3]
    surface = blob.surface(0.25)
    surface.apply_translation(placement)
    scene = truth_scene(cfg, truth / "blob_particles.csv", dx, float(np.ptp(lattice[:, 1]) + dx),
                        centre_mm=(lattice.min(0) + lattice.max(0)) / 2)
    scene.run.write_vtu = False
    started = time.perf_counter()
    sim = simulate_creep(scene, tissue_particles=(lattice, np.full(len(lattice), dx ** 3)), surface=surface)
    fast_s = time.perf_counter() - started
    n = min(len(sim.times_s), len(fe))
    # both from their own settled frame 0: the push's motion
    u_fe = fe[:n] - fe[:1]
    u_fast = sim.tissue_mm[:n] - sim.tissue_mm[:1]
    diff = np.linalg.norm(u_fast - u_fe, axis=2)
    peak = np.linalg.norm(u_fe, axis=2).max(axis=1)
    last = n - 1
    out = {
        "twin": str(args.twin), "lattice_points": int(len(lattice)), "spacing_mm": dx,
        "truth_solver": params.get("truth_solver"),
        "truth_wall_s": params["facts"].get("fe_wall_s"), "fast_path_wall_s": fast_s,
        "frames": {str(k): {"truth_peak_mm": float(peak[k]),
                            "rms_over_peak": float(np.sqrt((diff[k] ** 2).mean()) / max(peak[k], 1e-12)),
                            "max_over_peak": float(diff[k].max() / max(peak[k], 1e-12)),
                            # the whole sample's turn since frame 0 (rotation vectors, degrees)
                            "truth_turn_vector_deg": np.round(split_difference(
                                lattice, lattice + u_fe[k])["turn_vector_deg"], 3).tolist(),
                            "fast_turn_vector_deg": np.round(split_difference(
                                lattice, lattice + u_fast[k])["turn_vector_deg"], 3).tolist()}
                   for k in sorted({n // 4, n // 2, last})},
        "truth_mean_descent_mm": float(-u_fe[last, :, 1].mean()),
        "fast_mean_descent_mm": float(-u_fast[last, :, 1].mean()),
    }
    print(json_text(out, indent=2))


if __name__ == "__main__":
    main()
