"""The synthetic experiment: generation time, the resolution floor, the mass-scaling tolerance (JSON).

Three measurements (the twin's checks):

* ``generate`` — wall time of the whole twin (``hifumotion experiment``'s work) for the
  preset, with its stage timings and particle counts. Target: ≤ 5 min on 2 cores
  for ``default``.
* ``resolution`` — the truth simulated again at the fitted model's resolution
  (``truth_particle_factor = 1``), sectioned on the *same* image grid; per-frame DSC
  and centroid distance against the truth. This is the floor any fitted model can
  reach: it has the right parameters and only the coarser particles.
* ``mass_scaling`` — the truth again with the inertia multiplier divided by
  ``--scaling-divisor`` (4): per-frame DSC and centroid distance. The stated
  tolerance of the speed-up.

The comparisons use the truth's own particles, not images: they measure the
physics, not segmentation.

    python benchmarks/bench_twin.py --preset default              # ≈ 4 min + 2 × the comparisons
    python benchmarks/bench_twin.py --preset small --skip generate
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hifumotion.io.writers import json_text


def _centroids(masks: np.ndarray, pixel_mm: float) -> np.ndarray:
    rows, cols = np.indices(masks.shape[1:])
    area = np.maximum(masks.sum((1, 2)), 1)
    return np.column_stack([(masks * cols).sum((1, 2)) / area, (masks * rows).sum((1, 2)) / area]) * pixel_mm


def compare(reference, other, probe) -> dict:
    """Per-frame DSC and centroid distance (mm) of two truths' sections on one grid."""
    from hifumotion.experiment.twin import truth_sections
    from hifumotion.metrics import dice

    a = np.stack([s.mask for s in truth_sections(reference, probe)[0]])
    b = np.stack([s.mask for s in truth_sections(other, probe)[0]])
    dsc = np.array([dice(x, y) for x, y in zip(a, b)])
    dist = np.linalg.norm(_centroids(a, probe.pixel_mm) - _centroids(b, probe.pixel_mm), axis=1)
    return {"dsc_min": float(dsc.min()), "dsc_mean": float(dsc.mean()), "dsc_per_frame": dsc.round(4).tolist(),
            "centroid_distance_max_mm": float(dist.max()), "centroid_distance_mean_mm": float(dist.mean())}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="default", choices=["default", "small"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--skip", nargs="*", default=[], choices=["generate", "resolution", "mass_scaling"])
    parser.add_argument("--scaling-divisor", type=float, default=4.0)
    parser.add_argument("--json", action="store_true", help="print JSON only")
    parser.add_argument("--quick", action="store_true", help="a run of a few minutes: the small preset")
    args = parser.parse_args(argv)
    if args.quick:
        args.preset = "small"

    from hifumotion.experiment import generate_twin, twin_config
    from hifumotion.experiment import imaging as im
    from hifumotion.experiment.twin import simulate_truth

    cfg = twin_config(args.preset, seed=args.seed)
    out: dict = {"benchmark": "twin", "preset": args.preset, "seed": args.seed,
                 "mass_scaling": cfg.run.mass_scaling}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if "generate" not in args.skip:
            t0 = time.perf_counter()
            result = generate_twin(cfg, tmp / "twin")
            out["generate"] = {"wall_s": time.perf_counter() - t0, "timings_s": result.timings_s,
                               "counts": result.facts["counts"], "steps": result.facts["steps"],
                               "truth_spacing_mm": result.facts["truth_spacing_mm"],
                               "model_spacing_mm": result.facts["model_spacing_mm"]}
        reference = simulate_truth(cfg, tmp / "reference")
        probe = im.make_probe(cfg.imaging, reference.simulation.tissue_mm[0])
        if "resolution" not in args.skip:
            coarse = simulate_truth(cfg, tmp / "coarse", particle_factor=1.0)
            out["resolution"] = {"truth_particles": int(len(reference.particles_mm)),
                                 "model_particles": int(len(coarse.particles_mm)),
                                 **compare(reference, coarse, probe)}
        if "mass_scaling" not in args.skip:
            slower = cfg.model_copy(deep=True)
            slower.run.mass_scaling = cfg.run.mass_scaling / args.scaling_divisor
            t0 = time.perf_counter()
            other = simulate_truth(slower, tmp / "slower")
            out["mass_scaling"] = {"reference": cfg.run.mass_scaling, "compared_with": slower.run.mass_scaling,
                                   "wall_s_compared": time.perf_counter() - t0,
                                   **compare(reference, other, probe)}
    if args.json:
        print(json_text(out, indent=None))
    else:
        brief = {k: ({kk: vv for kk, vv in v.items() if kk != "dsc_per_frame"} if isinstance(v, dict) else v)
                 for k, v in out.items()}
        print(json_text(brief, indent=2))
    return out


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
