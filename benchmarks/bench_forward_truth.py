"""The fitted model against a twin's truth at the truth's own parameters.

Runs the paper-resolution model (the fast path, ``integrator = "implicit"``) of a twin's
observation with the parameters the twin was made with, and compares the displacement
of the model's points A (frame 0's contour, in the image plane) with the truth's — the
finite-element trajectory in ``truth/tissue_trajectory.npz``, interpolated at the same
points. What it measures is the model's own error (discretisation, reconstructed shape,
contact law), the floor under any fit: a calibration cannot do better than this on the
frames it fits without absorbing the error into wrong parameters.

Prints JSON: the run's time and solver counts, and every ``--every`` frames the RMS
displacement error (and its split: the points' common shift, the RMS left without it, and the
RMS left without the best rigid motion of the model's points onto the truth's: the shape's own
error), the rotation vector of that motion and each one's own since frame 0 (degrees), and the truth's and the model's RMS displacements (µm). Run it alone (2 cores)::

    python benchmarks/bench_forward_truth.py .bench/twins/push_release_s43-*/ --last 190
    python benchmarks/bench_forward_truth.py TWIN --set '{"stick_mm": 0.01}'   # CreepSettings fields
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
    from _rigid_split import split_difference
    from bench_estimation import observe

    from hifumotion.creep import integrate
    from hifumotion.creep.linear import set_threads
    from hifumotion.estimation.model import ModelSettings, Parameters, model_spec, run_model
    from hifumotion.particles.section import material_weights

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("twin", type=Path, help="a twin folder (observed/ and truth/)")
    ap.add_argument("--last", type=int, default=190, help="last frame to run")
    ap.add_argument("--particles", type=int, default=4399)
    ap.add_argument("--every", type=int, default=10, help="report every n-th frame")
    ap.add_argument("--set", default="{}", help="CreepSettings fields as JSON, e.g. '{\"friction_rtol\": 0.01}'")
    args = ap.parse_args()
    changes = json.loads(args.set)
    unknown = set(changes) - set(integrate.CreepSettings.__dataclass_fields__)
    if unknown:
        sys.exit(f"--set: not CreepSettings fields: {sorted(unknown)}")
    set_threads(1)   # as the calibration's workers run

    # the settings reach the solver through the scene; patch the defaults for this process only
    defaults = integrate.CreepSettings.__init__
    stats: dict = {}

    def settings_init(self, *a, **k):
        defaults(self, *a, **k)
        for name, value in changes.items():
            setattr(self, name, value)

    run = integrate.CreepSolver.run

    def counted_run(self, *a, **k):
        result = run(self, *a, **k)
        stats.update(result.stats)
        return result

    integrate.CreepSettings.__init__ = settings_init
    integrate.CreepSolver.run = counted_run

    # the observation bench_estimation fits: the sweep segmented by GLCV, its boundary moved in
    # by the offset measured on a phantom of the twin's imaging (the expert contours would
    # leave the offset out: a reconstruction 10 % too large on paper_s41)
    from bench_estimation import _twin_settings

    from hifumotion.experiment.boundary_offset import measure_boundary_offset
    from hifumotion.experiment.config import ImagingConfig

    imaging = ImagingConfig(**_twin_settings(args.twin)["imaging"])
    offset_mm = round(measure_boundary_offset(imaging, "glcv", seed=7919).offset_mm, 3)
    observed, obs, *_ = observe(args.twin, "tracked", "speckle", offset_mm)
    p = json.loads((args.twin / "truth" / "parameters.json").read_text())
    # a driven bar pushes no set force (its travel is in the scene); the floor's friction is the twin's
    force = p["external_force_n"] if p.get("external_force_n") is not None else Parameters().force_n
    k = Parameters(force, p["youngs_modulus_pa"], p["poisson_ratio"], p["beta1_pa_s_pow"], p["beta2"],
                   p.get("friction"))
    spec = model_spec(obs, ModelSettings(tissue_particles=args.particles))
    t0 = time.perf_counter()
    model = run_model(spec, k, args.last, keep_frames=range(0, args.last + 1, args.every))
    seconds = time.perf_counter() - t0

    truth = np.load(args.twin / "truth" / "tissue_trajectory.npz")
    positions, dx = truth["positions_mm"].astype(float), float(truth["spacing_mm"])
    a0 = model.points_mm[0]
    frames = list(range(0, min(len(model.points_mm), len(positions)), args.every))
    error, size, size_model, shift, shape, rigid, angle = [], [], [], [], [], [], []
    own_turn_model, own_turn_truth, axes, body_turn = [], [], [], []
    follow, _ = material_weights(a0, positions[0], dx)   # the truth's material points A
    for f in frames:
        u_true = follow @ (positions[f] - positions[0])
        u_model = model.points_mm[f] - a0
        split = split_difference(a0 + u_model, a0 + u_true)
        error.append(split["rms_um"])
        shift.append(split["shift_um"])
        shape.append(split["without_shift_um"])
        rigid.append(split["without_rigid_motion_um"])
        angle.append(split["turn_deg"])
        axes.append(np.round(split["turn_vector_deg"], 2).tolist())
        # each one's own turn since frame 0 (its rotation vector: which way each turns)
        own_turn_model.append(np.round(split_difference(a0, a0 + u_model)["turn_vector_deg"], 2).tolist())
        body_turn.append(np.round(split_difference(model.rest_mm, model.kept[f])["turn_vector_deg"],
                                  2).tolist() if f in model.kept else None)
        own_turn_truth.append(np.round(split_difference(a0, a0 + u_true)["turn_vector_deg"], 2).tolist())
        size.append(float(np.sqrt((u_true ** 2).sum(1).mean()) * 1000))
        size_model.append(float(np.sqrt((u_model ** 2).sum(1).mean()) * 1000))
    print(json_text({"twin": str(args.twin), "settings": changes, "seconds": round(seconds, 2),
                      "boundary_offset_mm": offset_mm, "tissue_volume_mm3": round(obs.reconstruction.volume_mm3, 1),
                      "stats": {n: (round(v, 4) if isinstance(v, float) else v) for n, v in stats.items()},
                      "frames": frames, "rms_error_um": np.round(error, 1).tolist(),
                      "mean_shift_error_um": np.round(shift, 1).tolist(),
                      "rms_error_without_shift_um": np.round(shape, 1).tolist(),
                      "rms_error_without_rigid_motion_um": np.round(rigid, 1).tolist(),
                      "rigid_turn_between_model_and_truth_deg": np.round(angle, 2).tolist(),
                      "rigid_turn_vector_deg": axes,
                      "model_turn_vector_deg": own_turn_model,
                      "truth_turn_vector_deg": own_turn_truth,
                      "model_whole_sample_turn_vector_deg": body_turn,
                      "truth_rms_displacement_um": np.round(size, 1).tolist(),
                      "model_rms_displacement_um": np.round(size_model, 1).tolist()}, indent=None))


if __name__ == "__main__":
    main()
