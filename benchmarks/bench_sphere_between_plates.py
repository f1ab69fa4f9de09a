"""An elastic sphere squeezed between the floor and the bar on the fast path, against Hertz.

Hertz (1882): a sphere of radius R pressed onto a rigid flat with force F approaches it by
δ = (9 F² / (16 R E*²))^(1/3), E* = E / (1 − ν²) — a half-space result, for a ≪ R. Squeezed
between two flats the sphere's approach is read as 2δ. The fast path runs the sphere
(conforming voxels, frictionless floor and bar, no gravity) with F chosen so that δ = 4 % of R;
printed (JSON): the bar's advance over 2δ at each R/Δx.

    python benchmarks/bench_sphere_between_plates.py --spacings 1.0,0.5
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from hifumotion.io.writers import json_text


def main() -> None:
    import trimesh

    from hifumotion.creep import CreepMaterial, CreepSolver, ContactPlane, Punch, Surroundings, voxel_mesh
    from hifumotion.creep.conform import conform

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--radius-mm", type=float, default=6.0)
    ap.add_argument("--spacings", default="1.0,0.5", help="Δx in mm")
    ap.add_argument("--youngs-modulus-pa", type=float, default=1e5)
    ap.add_argument("--poisson-ratio", type=float, default=0.3)
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: the 1 mm spacing only")
    args = ap.parse_args()
    if args.quick:
        args.spacings = "1.0"
    r_mm, e, nu = args.radius_mm, args.youngs_modulus_pa, args.poisson_ratio
    delta = 0.04 * r_mm * 1e-3
    force = 4 / 3 * e / (1 - nu ** 2) * math.sqrt(r_mm * 1e-3) * delta ** 1.5
    centre = np.array([20.0, r_mm, 20.0])
    rows = []
    for dx in (float(s) for s in args.spacings.split(",")):
        n = int(np.ceil(r_mm / dx))
        axis = dx * (np.arange(-n, n) + 0.5)
        pts = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
        pts = pts[np.linalg.norm(pts, axis=1) <= r_mm] + centre
        sphere = trimesh.creation.icosphere(subdivisions=5)
        sphere.apply_scale(r_mm)
        sphere.apply_translation(centre)
        mesh = conform(voxel_mesh(pts, dx), sphere)
        top = float(mesh.nodes_mm[:, 1].max())
        punch = Punch((0.02, top * 1e-3, 0.02), (0.0, -1.0, 0.0), r_mm * 1e-3,
                      lambda t: force if t > 0 else 0.0, friction=0.0)
        solver = CreepSolver(mesh, CreepMaterial(e, nu, beta1=0.0, density_kg_m3=1e-3), Surroundings((0, 0, 0)),
                             [ContactPlane((0, 0, 0), (0, 1, 0), 0.0)], punch)
        t0 = time.perf_counter()
        result = solver.run(np.array([0.0, 0.5]))
        rows.append({"spacing_mm": dx, "radius_over_spacing": r_mm / dx, "voxels": len(pts),
                     "advance_mm": float(result.advance_mm[-1]), "hertz_two_delta_mm": 2 * delta * 1e3,
                     "ratio": float(result.advance_mm[-1] / (2 * delta * 1e3)), "seconds": time.perf_counter() - t0})
        print(json_text(rows[-1], indent=None), flush=True)
    print(json_text({"force_n": force, "runs": rows}, indent=1))


if __name__ == "__main__":
    main()
