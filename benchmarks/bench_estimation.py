"""Issue 8's benchmark: calibrate, predict and score on a synthetic twin; baselines side by side.

Prints JSON: calibration wall time, recovered parameters against the truth (the
identifiable combinations F/E and β1/E, and ν, β2), the prediction's Table 4
(training and validation DSC, HD95, centroid error), the baselines' scores on the
validation window (no motion, Kalman, NCC), the online mode's error against the
horizon, and the prediction's speed against real time.

Two ways to get the training contours, both measured:

* ``glcv``  — fully automatic: GLCV tracking from the clinician's click;
* ``expert`` — the paper's protocol: an expert's contours of frame 0 and the training
  frames (here the twin's true sections of those frames; never the validation frames').

Usage::

    python benchmarks/bench_estimation.py --twin DIR            # an existing twin (observed/ + truth/)
    python benchmarks/bench_estimation.py --preset default --seed 0   # generate it first (≈ 5 min)

Run it alone: parallel jobs slow each other's timings.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from pathlib import Path



def _expert_contours(truth: Path, frames: list[int], out: Path) -> Path:
    rows = [r for r in csv.DictReader(open(truth / "frame_contours.csv")) if int(r["frame"]) in frames]
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return out


def run(twin: Path, mode: str, method: str, workers: int | None, horizons: list[int]) -> dict:
    from hifumotion.estimation.calibrate import CalibrationSettings, calibrate, recovered_parameters
    from hifumotion.estimation.prepare import prepare
    from hifumotion.estimation.protocol import default_frames
    from hifumotion.observed import load_observed
    from hifumotion.prediction.evaluate import evaluate, online_schedule
    from hifumotion.prediction.pipeline import predict_calibrated
    from hifumotion.scoring import read_frame_masks

    truth_dir = twin / "truth"
    params = json.loads((truth_dir / "parameters.json").read_text())
    truth = read_frame_masks(truth_dir)
    observed = load_observed(twin / "observed")
    n = len(observed.frames)
    train, valid = default_frames(n)
    tmp = Path(tempfile.mkdtemp(prefix="bench_estimation_"))
    contours = _expert_contours(truth_dir, [0] + train, tmp / "expert.csv") if mode == "expert" else None

    t0 = time.perf_counter()
    obs = prepare(observed, contours)
    prep_s = time.perf_counter() - t0
    cal = calibrate(obs, CalibrationSettings(method=method, workers=workers), log_path=tmp / "log.jsonl")
    cal_s = time.perf_counter() - t0
    k = cal.parameters

    t1 = time.perf_counter()
    now, online_frames = online_schedule(train, valid, horizons, n)
    ref = obs.reference_shape()
    pred = predict_calibrated(cal.spec, k, ref, train + valid, online_frames)
    predict_s = time.perf_counter() - t1
    window_s = (valid[-1] - valid[0]) * observed.frame_interval_s
    ev = evaluate(pred, cal.spec, ref, obs.frame_masks, observed.frames, truth, train, valid,
                  observed.frame_interval_s, horizons, now)
    physics, baselines, online = ev.physics, ev.baselines, ev.online

    recovered = recovered_parameters(cal.report(), k, params)
    return {
        "mode": mode, "method": method, "training_frames": train, "validation_frames": valid,
        "calibration_s": cal_s, "prepare_s": prep_s, "calibration_timings_s": cal.timings_s, "runs": cal.runs,
        "fitted": k.as_dict(), "recovered": recovered, "degeneracy": cal.degeneracy,
        "space_mapping": cal.mapped,
        "physics": physics, "baselines_validation": baselines, "online": online,
        "predict_s": predict_s, "validation_window_s": window_s, "predict_over_realtime": predict_s / window_s,
        "targets": {"validation_dsc_mean>=0.97": physics["validation"]["dsc_mean"] >= 0.97,
                    "validation_dsc_min>=0.95": physics["validation"]["dsc_min"] >= 0.95,
                    "validation_centroid_mean<=0.5mm": physics["validation"]["centroid_mean_mm"] <= 0.5,
                    "calibration<=300s": cal_s <= 300,
                    "physics_beats_no_motion_dsc": physics["validation"]["dsc_mean"] > baselines["no_motion"]["dsc_mean"]},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--twin", type=Path, help="an existing twin folder (observed/ and truth/)")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="expert,glcv")
    ap.add_argument("--method", default="least_squares")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--horizons", default="4,6,8", help="online horizons in frames")
    args = ap.parse_args()
    twin = args.twin
    generated = None
    if twin is None:
        from hifumotion.experiment import generate_twin, twin_config

        twin = Path(tempfile.mkdtemp(prefix="bench_twin_"))
        t = time.perf_counter()
        generate_twin(twin_config(args.preset, seed=args.seed), twin)
        generated = time.perf_counter() - t
    horizons = [int(h) for h in args.horizons.split(",")]
    out = {"twin": str(twin), "generate_s": generated, "runs": {}}
    for mode in args.modes.split(","):
        out["runs"][mode] = run(twin, mode, args.method, args.workers, horizons)
        print(f"{mode}: done", file=sys.stderr)
    print(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
