"""The fast path (hifumotion.creep) against the finite-element reference, and both against resolution.

Scene: the default scene's ellipsoid tissue (30 × 18 × 24 mm) on the floor, the bar's flat
end pressing it with the scene's force — run on the fast path in its relaxed limit (β1 = 0:
the creep's end state), on a floor rough enough not to slip (the reference's floor is
stuck). Reference: :func:`hifumotion.reference.punch_reference`, P2 tetrahedra on a TetGen
mesh of the same ellipsoid, at two mesh sizes (its own convergence). Printed (JSON):

* per particle count: the RMS over the particles of the difference between the two
  displacement fields from rest, relative to the reference's peak displacement
  (target ≤ 5 % at the paper's 4,399); the bar's advance and the mean descent of both;
* the reference's change between its two meshes (how converged the yardstick is);
* wall seconds of each.

Usage::

    python benchmarks/bench_fe_reference.py                       # 1,100 / 2,200 / 4,399 particles
    python benchmarks/bench_fe_reference.py --particles 4399 --fine 1.0
    python benchmarks/bench_fe_reference.py --quick --edge-spacings 0    # the sharp-edged bar
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hifumotion.io.writers import json_text


def ellipsoid_surface(scene, subdivisions: int):
    import trimesh

    surface = trimesh.creation.icosphere(subdivisions=subdivisions)
    surface.apply_scale(np.asarray(scene.tissue.size_mm) / 2)
    surface.apply_translation([scene.tank.size_mm[0] / 2, scene.tissue.size_mm[1] / 2, scene.tank.size_mm[2] / 2])
    return surface


def main() -> None:
    from hifumotion.creep.scene_run import scene_punch, simulate_creep, tissue_mesh
    from hifumotion.scene import Scene
    from hifumotion.scene.geometry import spacing_for_count, tissue_particles_mm
    from hifumotion.reference import PunchedTissue, punch_reference

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--particles", default="1100,2200,4399")
    ap.add_argument("--coarse", type=float, default=4.0, help="reference's largest tetrahedron (mm³), coarse mesh")
    ap.add_argument("--fine", type=float, default=1.0, help="… and fine mesh")
    ap.add_argument("--quick", action="store_true", help="1,100 particles, references of 8 and 4 mm³: minutes")
    ap.add_argument("--edge-spacings", type=float, default=None,
                    help="the fast path's bar rim rounding in spacings (CreepSettings.bar_edge_spacings; "
                         "0: the reference's sharp edge)")
    args = ap.parse_args()
    if args.quick:
        args.particles, args.coarse, args.fine = "1100", 8.0, 4.0
    creep_settings = None
    if args.edge_spacings is not None:
        from hifumotion.creep.settings import CreepSettings

        creep_settings = CreepSettings(bar_edge_spacings=args.edge_spacings)
    scene = Scene()
    scene.tissue = scene.tissue.model_copy(update={"beta1": 0.0})
    if args.edge_spacings == 0:
        # the reference's sharp edge: the bar's own rounding would otherwise round it (0.5 mm)
        scene.bar = scene.bar.model_copy(update={"edge_radius_mm": 1e-9})
    scene.physics.friction = 3.0   # rough: the stuck reference's limit (tests/test_creep.py says why not 100)
    scene.run.duration_s, scene.run.output_interval_s = 1.0, 0.5
    counts = [int(c) for c in args.particles.split(",")]
    volume = np.pi / 6 * np.prod(scene.tissue.size_mm)
    refs = {}
    out = {"scene": {"tissue_mm": list(scene.tissue.size_mm), "youngs_modulus_pa": scene.tissue.youngs_modulus_pa,
                     "poisson_ratio": scene.tissue.poisson_ratio, "force_n": scene.bar.force_n,
                     "bar_radius_mm": scene.bar.radius_mm}, "runs": []}
    for n in counts:
        dx, _ = spacing_for_count(lambda d: tissue_particles_mm(scene.tissue, scene.tank, d), (volume / n) ** (1 / 3), n)
        scene.particles.spacing_mm = dx
        mesh, _ = tissue_mesh(scene)
        t0 = time.perf_counter()
        sim = simulate_creep(scene, mesh=mesh, settings=creep_settings)
        fast_s = time.perf_counter() - t0
        u_fast = sim.tissue_mm[-1] - mesh.centres_mm
        punch, axis = scene_punch(scene, mesh.centres_mm, dx)
        row = {"particles": len(mesh.centres_mm), "spacing_mm": dx, "fast_seconds": fast_s,
               "fast_mean_descent_mm": float(-u_fast[:, 1].mean()),
               "fast_max_penetration_mm": sim.facts["creep_max_penetration_mm"]}
        for name, max_volume, subdiv in (("coarse", args.coarse, 3), ("fine", args.fine, 4)):
            key = (name, tuple(np.round(punch.tip_m, 9)))
            if key not in refs:
                surface = ellipsoid_surface(scene, subdiv)
                problem = PunchedTissue(surface.vertices, surface.faces, scene.tissue.youngs_modulus_pa,
                                        scene.tissue.poisson_ratio, tuple(np.asarray(punch.tip_m) * 1e3), tuple(axis),
                                        scene.bar.radius_mm, scene.bar.force_n, max_volume_mm3=max_volume)
                t0 = time.perf_counter()
                refs[key] = (punch_reference(problem), time.perf_counter() - t0)
            ref, ref_s = refs[key]
            u_ref = ref.at(mesh.centres_mm)
            peak = float(np.linalg.norm(u_ref, axis=1).max())
            rms = float(np.sqrt(((u_fast - u_ref) ** 2).sum(1).mean()))
            row[f"reference_{name}"] = {"dofs": ref.dofs, "tetrahedra": ref.tetrahedra, "seconds": ref_s,
                                        "bar_advance_mm": ref.advance_mm, "peak_mm": peak,
                                        "mean_descent_mm": float(-u_ref[:, 1].mean()),
                                        "rms_difference_mm": rms, "rms_over_peak": rms / peak}
        c, f = row["reference_coarse"], row["reference_fine"]
        row["reference_change_coarse_to_fine"] = abs(c["mean_descent_mm"] - f["mean_descent_mm"]) / f["mean_descent_mm"]
        out["runs"].append(row)
        print(json_text(row, indent=None), flush=True)
    print(json_text(out, indent=1))


if __name__ == "__main__":
    main()
