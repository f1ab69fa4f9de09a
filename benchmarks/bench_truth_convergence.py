"""Is a twin's finite-strain truth converged on its own protocol? Its run again with one numerical setting changed.

A twin made with ``truth.solver = "finite_strain"`` keeps its truth's motion in
``truth/tissue_trajectory.npz`` (the lattice of ``blob_particles.csv``, frame by frame). This
benchmark reruns that truth from the twin's own configuration with one setting changed at a
time and compares the lattice's motion with the stored one:

* ``mesh``: the sample's surface one icosphere subdivision finer and the largest tetrahedron
  half the volume (slide_stop_s49: 22,342 P2 nodes against 5,156 — hours on one core, where
  the others take 15–18 minutes);
* ``penalty``: both contacts' penalty (the floor's and the bar's face) ``--penalty`` times
  stiffer;
* ``slip``: the sticking contacts' elastic slip ``--slip`` times smaller;
* ``step``: the largest time step halved.

Printed (JSON), per variant and every ``--every`` frames: the RMS difference of the lattice's
positions (µm) and its split into the common shift, the rest without it, the rest without the
best rigid motion (the shape's own difference) and the turn between the two (degrees, and its
rotation vector); each one's own turn since frame 0; the truth's RMS motion; the variant's mesh
size, steps and wall time. Each variant's line also goes to stderr as it ends. A converged
truth moves the same under each variant, within a small fraction of its motion. The twins' earlier sweeps were
made on a push (docs/decisions.md, "A finite-strain truth on FElupe"); a slide's convergence is the question here::

    python benchmarks/bench_truth_convergence.py .bench/twins/slide_stop_s49-*/ --variants mesh,penalty
    python benchmarks/bench_truth_convergence.py TWIN --quick        # the first 2 s, penalty and slip

One process per variant, ``--workers`` at a time (each solve single-threaded then).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from hifumotion.io.writers import json_text

sys.path.insert(0, str(Path(__file__).resolve().parent))

VARIANTS = ("mesh", "penalty", "slip", "step")


def rerun(twin: Path, variant: str, until_s: float | None, penalty: float, slip: float) -> dict:
    """The twin's truth again with ``variant`` changed; the lattice's positions (mm) at its frames."""
    from hifumotion.experiment.blob import Blob
    from hifumotion.experiment.config import TwinConfig, apply_protocol
    from hifumotion.experiment.fe_truth import fe_problem
    from hifumotion.experiment.twin import _seeds
    from hifumotion.reference.finite_strain_push import FiniteStrainSettings, finite_strain_reference

    truth = twin / "truth"
    params = json.loads((truth / "parameters.json").read_text())
    cfg = apply_protocol(TwinConfig.model_validate(params["config"]))
    if cfg.truth.solver != "finite_strain":
        raise SystemExit(f"{truth / 'parameters.json'}: truth.solver is {cfg.truth.solver!r}, expected 'finite_strain'")
    settings = FiniteStrainSettings(step_s=cfg.truth.step_s)
    if variant == "mesh":
        cfg.truth.surface_subdivisions += 1
        cfg.truth.max_volume_mm3 /= 2.0
    elif variant == "penalty":
        settings.contact_multiplier *= penalty
        settings.face_contact_multiplier *= penalty
    elif variant == "slip":
        if settings.elastic_slip_mm is None:
            raise SystemExit("--variants slip: the truth's contacts have no elastic slip to make smaller")
        settings.elastic_slip_mm /= slip
    elif variant == "step":
        settings.step_s /= 2.0
    blob = Blob.random(cfg.blob.size_mm, cfg.blob.irregularity, cfg.blob.lobes, cfg.blob.bottom_cut,
                       int(_seeds(cfg)[0]))
    placement = np.array([cfg.tank.size_mm[0] / 2, 0.0, cfg.tank.size_mm[2] / 2])
    lattice = np.loadtxt(truth / "blob_particles.csv", delimiter=",", skiprows=1)[:, :3]
    times = np.arange(cfg.imaging.frames) / cfg.imaging.frame_rate_hz
    if until_s is not None:
        times = times[times <= until_s + 1e-9]
    problem, lift = fe_problem(cfg, blob, placement)
    started = time.perf_counter()
    told = [-1]

    def progress(fraction: float) -> None:
        # a line on stderr every tenth of the run (the JSON goes to stdout)
        tenth = int(10 * fraction)
        if tenth > told[0]:
            told[0] = tenth
            print(f"{variant}: {10 * tenth} % after {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)

    solution = finite_strain_reference(problem, times, settings, progress)
    seconds = time.perf_counter() - started
    positions = lattice[None] + lift + solution.displacement_at(lattice + lift)
    return {"variant": variant, "positions_mm": positions, "seconds": seconds,
            "nodes": int(len(solution.p2.points_m)), "steps": int(solution.stats["steps"]),
            "halvings": int(solution.stats.get("halvings", 0)),
            "physicality": {k: solution.stats[k] for k in ("smallest_jacobian", "largest_strain",
                                                          "floor_penetration_mm", "face_penetration_mm")
                            if k in solution.stats}}


def main() -> None:
    from _rigid_split import split_difference

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("twin", type=Path, help="a twin folder whose truth is finite_strain")
    ap.add_argument("--variants", default="mesh,penalty", help=f"comma-separated, of {', '.join(VARIANTS)}")
    ap.add_argument("--until", type=float, default=None, help="run only to this time (s)")
    ap.add_argument("--every", type=int, default=10, help="report every n-th frame")
    ap.add_argument("--penalty", type=float, default=4.0, help="the penalty variant's factor on both contacts")
    ap.add_argument("--slip", type=float, default=4.0, help="the slip variant's divisor of the elastic slip")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="the first 2 s, variants penalty and slip")
    args = ap.parse_args()
    if args.quick:
        args.until = 2.0 if args.until is None else args.until
        args.variants = "penalty,slip"
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    bad = sorted(set(variants) - set(VARIANTS))
    if bad:
        raise SystemExit(f"--variants: unknown {bad}; expected some of {', '.join(VARIANTS)}")
    if not (args.twin / "truth" / "tissue_trajectory.npz").is_file():
        raise SystemExit(f"{args.twin}: no truth/tissue_trajectory.npz (not a twin folder)")
    stored = np.load(args.twin / "truth" / "tissue_trajectory.npz")["positions_mm"].astype(float)
    if args.workers > 1:
        # one solve per core
        for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
            os.environ[name] = "1"
    out = {"twin": str(args.twin), "until_s": args.until, "penalty_factor": args.penalty, "slip_divisor": args.slip,
           "variants": {}}
    with ProcessPoolExecutor(max_workers=max(1, args.workers)) as pool:
        futures = [pool.submit(rerun, args.twin, v, args.until, args.penalty, args.slip) for v in variants]
        for done in as_completed(futures):
            run = done.result()
            positions, variant = run.pop("positions_mm"), run.pop("variant")
            n = min(len(positions), len(stored))
            frames = list(range(0, n, args.every)) + ([n - 1] if (n - 1) % args.every else [])
            # each from its own settled frame 0: the protocol's motion (the settle is not the question)
            splits = [split_difference(stored[0] + positions[f] - positions[0], stored[f]) for f in frames]
            motion = [float(np.sqrt(((stored[f] - stored[0]) ** 2).sum(1).mean()) * 1000) for f in frames]
            # the whole sample's own turn (rotation vector since frame 0, degrees): the variant's, the stored truth's
            turns = {"variant_turn_vector_deg": [np.round(split_difference(positions[0], positions[f])["turn_vector_deg"],
                                                          3).tolist() for f in frames],
                     "truth_turn_vector_deg": [np.round(split_difference(stored[0], stored[f])["turn_vector_deg"],
                                                        3).tolist() for f in frames]}
            out["variants"][variant] = {
                **{k: (round(v, 2) if isinstance(v, float) else v) for k, v in run.items()},
                "frames": frames, "truth_rms_motion_um": np.round(motion, 1).tolist(),
                **{k: (np.round([s[k] for s in splits], 2 if k == "turn_deg" else 1).tolist() if k != "turn_vector_deg"
                       else [np.round(s[k], 3).tolist() for s in splits]) for k in splits[0]},
                **turns,
                "settled_frame0_rms_um": round(float(np.sqrt(((positions[0] - stored[0]) ** 2).sum(1).mean()) * 1000), 1),
                "rms_over_motion_at_last": round(splits[-1]["rms_um"] / max(motion[-1], 1e-9), 4)}
            # each variant as it ends (a long run's first results are not lost to its last)
            print(json_text({"variant": variant, **out["variants"][variant]}, indent=None), file=sys.stderr, flush=True)
    print(json_text(out, indent=1))


if __name__ == "__main__":
    main()
