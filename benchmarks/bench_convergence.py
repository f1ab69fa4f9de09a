"""Resolution convergence of the twin's physics: how far the tissue moves at 1×, 2×, 4× the particles.

The same sample, material and push simulated at several resolutions (the ``demo`` preset's
model size times each factor) for the training window (5 s of push). A converged particle
model moves its tissue the same at every resolution; printed per run (JSON):

* ``mean_descent_mm`` — the tissue particles' mean downward displacement since frame 0;
* ``bottom_sink_mm`` — that of the bottom 10 % (the layer on the floor): its sinking into the
  floor's contact, which no elastic deformation explains;
* ``top_descent_mm`` — that of the top 10 %; ``bar_travel_mm`` — the bar's, at 1, 2.5 and 5 s.

With ``--integrator implicit`` (the default: the fast path the fit and the prediction use,
:mod:`hifumotion.creep`) the sample is meshed as conforming voxels (boundary nodes on the
sample's surface) and also reported: ``section_centroid_mm`` — the displacement of the
centroid of the rest section in the imaging plane (z through the sample's centre),
followed as material points — at 1, 2.5 and 5 s; ``max_penetration_mm`` of the floor and
the bar (target ≤ 1 % of Δx); and, over the factors, the Richardson extrapolate of each
figure (observed order from the three finest) with each run's deviation from it
(target ±5 %).

Usage::

    python benchmarks/bench_convergence.py                       # fast path, factors 1,2,4
    python benchmarks/bench_convergence.py --integrator explicit --contact-factor 16

Runs one process per factor (two at a time on two cores; ``--workers 1`` to time them).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from hifumotion.io.writers import json_text


def one_implicit(factor: float, preset: str, seed: int) -> dict:
    import numpy as np

    from hifumotion.creep.scene_run import simulate_creep
    from hifumotion.creep.conform import conform
    from hifumotion.creep.voxels import voxel_mesh
    from hifumotion.experiment import twin_config
    from hifumotion.experiment.blob import Blob
    from hifumotion.experiment.twin import _seeds, resolution, truth_scene
    from hifumotion.scene.geometry import spacing_for_count
    from hifumotion.particles.section import displacement_at

    cfg = twin_config(preset, seed=seed, overrides={"imaging": {"frames": 101}})
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut,
                       int(_seeds(cfg)[0]))
    res = resolution(cfg, blob)
    wanted = factor * cfg.resolution.model_tissue_particles
    dx, pts = spacing_for_count(blob.particles, res["model_spacing_mm"] / factor ** (1 / 3), wanted,
                                shrink=0.995, tolerance=0.995)
    placement = np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2])
    pts = pts + placement
    t0 = time.perf_counter()
    surface = blob.surface(min(0.25, dx / 4))
    surface.apply_translation(placement)
    mesh = conform(voxel_mesh(pts, dx), surface)
    scene = truth_scene(cfg, "unused.csv", dx, float(np.ptp(pts[:, 1]) + dx), centre_mm=(pts.min(0) + pts.max(0)) / 2)
    sim = simulate_creep(scene, tissue_particles=(pts, np.full(len(pts), dx ** 3)), mesh=mesh)
    seconds = time.perf_counter() - t0
    # the rest section in the plane through the sample's centre, as material points on a fine grid
    zc = placement[2]
    g = np.arange(-20.0, 20.0, 0.25)
    gx, gy = np.meshgrid(g + placement[0], np.arange(0.125, 25.0, 0.25), indexing="ij")
    plane = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, zc)], 1)
    plane = plane[blob.inside(plane - placement - blob.offset_mm())]
    rest = sim.tissue_mm[0]
    frame = {t: min(int(round(t / sim.times_s[1])), len(sim.times_s) - 1) for t in (1.0, 2.5, 5.0)}
    centroid = {str(t): displacement_at(plane, sim.tissue_mm[f], rest, dx)[0].mean(0).tolist()
                for t, f in frame.items()}
    dy = sim.tissue_mm[-1][:, 1] - rest[:, 1]
    bar = sim.bar_centre_mm[:, 1] - sim.bar_centre_mm[0, 1]
    return {"factor": factor, "tissue_particles": int(len(pts)), "spacing_mm": dx, "integrator": "implicit",
            "mean_descent_mm": float(-dy.mean()), "section_centroid_mm": centroid,
            "bar_travel_mm": {str(t): float(-bar[f]) for t, f in frame.items()},
            "max_penetration_mm": sim.facts["creep_max_penetration_mm"],
            "penetration_over_spacing": sim.facts["creep_max_penetration_mm"] / dx,
            "steps": sim.facts["creep_steps"], "factorisations": sim.facts["creep_factorisations"],
            "seconds": seconds}


def richardson(values, factors) -> dict:
    """Extrapolate ``values`` at particle factors (spacing ∝ factor^(−1/3)) to zero spacing."""
    import numpy as np

    v = np.asarray(values, float)
    h = np.asarray(factors, float) ** (-1 / 3)
    if len(v) < 3:
        return {"extrapolate": None, "order": None, "deviation": None}
    f1, f2, f3 = v[-3:]
    r = h[-2] / h[-1]
    ratio = (f1 - f2) / (f2 - f3) if f2 != f3 else np.inf
    if not np.isfinite(ratio) or ratio <= 0:  # not monotone: no order, the finest is the estimate
        order, limit = None, float(f3)
    else:
        order = float(np.log(ratio) / np.log(r))
        limit = float(f3 + (f3 - f2) / (r ** order - 1)) if order > 0 else float(f3)
    return {"extrapolate": limit, "order": order,
            "deviation": [float((x - limit) / limit) if limit else None for x in v]}


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
    ap.add_argument("--integrator", choices=("implicit", "explicit"), default="implicit")
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: the small preset")
    args = ap.parse_args()
    if args.quick:
        args.preset = "small"
    factors = [float(f) for f in args.factors.split(",")]
    with ProcessPoolExecutor(args.workers) as pool:
        if args.integrator == "implicit":
            runs = list(pool.map(one_implicit, factors, [args.preset] * len(factors), [args.seed] * len(factors)))
        else:
            runs = list(pool.map(one, factors, [args.contact_factor] * len(factors), [args.preset] * len(factors),
                                 [args.seed] * len(factors)))
    finest = runs[-1]["mean_descent_mm"]
    out = {"preset": args.preset, "seed": args.seed, "integrator": args.integrator, "runs": runs,
           "mean_descent_over_finest": [r["mean_descent_mm"] / finest for r in runs],
           "richardson": {"mean_descent_mm": richardson([r["mean_descent_mm"] for r in runs], factors)}}
    if args.integrator == "implicit":
        for t in ("1.0", "2.5", "5.0"):
            out["richardson"][f"section_centroid_y_mm_{t}s"] = richardson(
                [r["section_centroid_mm"][t][1] for r in runs], factors)
            out["richardson"][f"bar_travel_mm_{t}s"] = richardson([r["bar_travel_mm"][t] for r in runs], factors)
    print(json_text(out, indent=1))


if __name__ == "__main__":
    main()
