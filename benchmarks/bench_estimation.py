"""The estimation benchmark: calibrate, predict and aim on twins nobody tuned to; every peer beside it.

On each twin of ``_estimation_twins.CASES`` (one per therapy protocol — paper,
slow_push, push_release, oblique — each with its own seed, shape, bar, material and
push; finite-element truth, B-mode images), in one run:

1. **Observe** as ``hifumotion run`` does: the sweep segmented by GLCV and
   reconstructed, the frames tracked by speckle (``--tracking glcv`` for the paper's
   way), the boundary offset measured on a simulated phantom with the twin's imaging
   settings (as ``hifumotion demo`` does). ``--training expert`` uses the true sections
   of frame 0 and the training frames instead (the paper's protocol; never the
   validation frames').
2. **Calibrate** on the training frames (the paper's 20…100) with each ``--methods``:
   least squares (the default), the paper's Table 1 algorithm, CMA-ES; the final model
   at the paper's 4,399 particles.
3. **Predict** the validation frames (110…190) and the online mode (from frame t to
   t + k, k = 4, 6, 8 frames: 200–400 ms), and score against the truth beside the
   baselines that see the same tracked frames: holding the last training contour, the
   Kalman filter, the drive surrogates (the tracked centroid regressed on the push's
   program from ``setup.json``, static and with a first-order lag; online, the same
   updated every frame by recursive least squares), and the NCC template tracker (which
   also sees the validation images: a tracker, the ceiling of what observation alone gives).
   ``surrogate_targets``: the physics' centroid ≤ ½ of the best peer's that knows the
   same inputs and its DSC above all of them; online ≤ ½ of the online surrogate's.

Prints JSON: per twin and method the recovered F/E, β1/E, ν, β2 against the truth, the
Table 4 scores, the timings, and the targets each as true/false, with a summary
over all twins at the end.

Usage (run it alone: parallel jobs slow each other's timings)::

    python benchmarks/bench_estimation.py                      # every case, every method
    python benchmarks/bench_estimation.py --cases slow_push_s42 --methods least_squares
    python benchmarks/bench_estimation.py --twin DIR           # one existing twin (observed/ + truth/)
    python benchmarks/bench_estimation.py --quick              # slow_push_s42, least squares
    python benchmarks/bench_estimation.py --methods least_squares --compare-search   # reduced vs implicit search
    python benchmarks/bench_estimation.py --large-motion --model-at-truth   # the model at the true K beside the fit

``--compare-search`` calibrates each twin a second time with the other search model
(``CalibrationSettings.search_integrator``: the search model's reduced model or its full
runs; ``--peer-set`` gives the peer's settings whole) and reports the reduced search's calibration
targets: ≤ 30 s, and a validation DSC within 0.001 and a centroid within 0.01 mm of the
implicit search's fit. The comparison is against the default calibration::

    python benchmarks/bench_estimation.py --methods least_squares --compare-search \
        --set search_integrator=reduced,particles=1000 --peer-set search_integrator=implicit

Twins are generated once into ``--work`` (default ``.bench/twins``; 4–8 min each) and
re-used.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from pathlib import Path

from hifumotion.io.writers import json_text


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

#: the estimation's thresholds
DSC_MEAN, DSC_MIN, CENTROID_MM = 0.97, 0.95, 0.3
PARAMETER_REL, POISSON_ABS = 0.10, 0.03
CALIBRATION_S, PREDICT_SPEEDUP = 120.0, 10.0
#: the reduced search's: calibration on the reduced search model, its fit as good as the implicit search's
REDUCED_CALIBRATION_S, FIT_DSC, FIT_CENTROID_MM = 30.0, 0.001, 0.01
#: the driven protocols', and how far their twins' section centroid moves in the validation window
DRIVEN, WINDOW_MOTION_MM = ("slide", "drive_release"), 2.0


def _expert_contours(truth: Path, frames: list[int], out: Path) -> Path:
    rows = [r for r in csv.DictReader(open(truth / "frame_contours.csv")) if int(r["frame"]) in frames]
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return out


def _twin_settings(twin: Path) -> dict:
    """The settings the twin was generated with (``truth/parameters.json``'s ``config``)."""
    return json.loads((twin / "truth" / "parameters.json").read_text()).get("config", {})


def observe(twin: Path, training: str, tracking: str, offset_mm: float, fill_bar_cap: bool = True,
            bloom_continuation: str = "reconstruction"):
    """The observation of ``twin`` (timed) and the frames of the paper's protocol."""
    from hifumotion.estimation.prepare import prepare
    from hifumotion.estimation.protocol import default_frames
    from hifumotion.observed import load_observed

    observed = load_observed(twin / "observed")
    train, valid = default_frames(len(observed.frames))
    tmp = Path(tempfile.mkdtemp(prefix="bench_estimation_"))
    contours = _expert_contours(twin / "truth", [0] + train, tmp / "expert.csv") if training == "expert" else None
    t0 = time.perf_counter()
    obs = prepare(observed, contours, boundary_offset_mm=0.0 if contours else offset_mm, tracking=tracking,
                  fill_bar_cap=fill_bar_cap, bloom_continuation=bloom_continuation)
    return observed, obs, train, valid, time.perf_counter() - t0, tmp


def calibrate_and_predict(observed, obs, train, valid, truth, params, method, workers, horizons, tmp,
                          settings: dict | None = None, at_truth: bool = False, choose: bool = False) -> dict:
    """One method on one observation: calibration, prediction, Table 4, online mode; with
    ``at_truth`` the fitted model at the twin's true parameters too (:func:`model_at_truth`); with
    ``choose`` the product's choice of predictor on a temporal hold-out of the training frames
    (:mod:`hifumotion.prediction.choice`: one more calibration, on the earlier frames)."""
    from hifumotion.estimation.calibrate import CalibrationSettings, calibrate, recovered_parameters
    from hifumotion.prediction.evaluate import evaluate, online_schedule
    from hifumotion.prediction.pipeline import online_predictions, predict_calibrated

    t0 = time.perf_counter()
    # no online session runs here (the online mode is scored by online_predictions): no online model
    # unless --set asks for one, so calibration_s is the fit's alone
    cal = calibrate(obs, CalibrationSettings(method=method, training_frames=train, workers=workers,
                                             **{"online_model": False, **(settings or {})}),
                    log_path=tmp / f"log_{method}.jsonl")
    cal_s = time.perf_counter() - t0
    k = cal.parameters
    n = len(observed.frames)

    t1 = time.perf_counter()
    now, online_frames = online_schedule(train, valid, horizons, n)
    ref = obs.reference_shape()
    pred = predict_calibrated(cal.spec, k, ref, train + valid, online_frames)
    predict_s = time.perf_counter() - t1
    # the online mode's cost per frame at one horizon: the model's masks of t and t + k and the
    # shift (an upper bound: running frame by frame, mask t was made k frames earlier)
    t2 = time.perf_counter()
    online_predictions(pred, cal.spec, ref, obs.frame_masks, horizons[:1], now)
    online_ms = 1000.0 * (time.perf_counter() - t2) / max(1, len(now))
    program = observed.setup.program_at_frames(n)
    choice, choice_s = None, None
    if choose:
        from hifumotion.prediction.choice import holdout_physics, rank_on_holdout

        t3 = time.perf_counter()
        held, earlier = holdout_physics(obs, CalibrationSettings(method=method, training_frames=train, workers=workers,
                                                                 **(settings or {})), train,
                                        log_path=tmp / f"holdout_{method}.jsonl")
        cal.compare_with_earlier(earlier)
        tracked = {f: obs.frame_masks[f] for f in range(n)}
        choice = rank_on_holdout(tracked, train, program, observed.frame_interval_s, float(observed.pixel_mm), held)
        choice_s = time.perf_counter() - t3
    ev = evaluate(pred, cal.spec, ref, obs.frame_masks, observed.frames, truth, train, valid,
                  observed.frame_interval_s, horizons, now, program=program, choice=choice)
    window_s = (valid[-1] - valid[0]) * observed.frame_interval_s
    extra = {"model_at_truth": model_at_truth(cal.spec, k, params, ref, obs, observed, truth, train, valid)
             } if at_truth else {}
    return {
        **extra,
        "calibration_s": cal_s, "calibration_timings_s": cal.timings_s, "runs": cal.runs, "objective": cal.objective,
        "calibration_settings": {"search_integrator": cal.search_spec.settings.integrator},
        "fitted": k.as_dict(), "recovered": recovered_parameters(cal.report(), k, params),
        "degeneracy": cal.degeneracy, "strategy": cal.record.as_dict(), "resolution_check": cal.resolution,
        "holdout_shift": None if cal.holdout_shift is None else cal.holdout_shift.as_dict(),
        "physics": ev.physics, "baselines_validation": ev.baselines, "online": ev.online,
        "verdict": ev.physics["verdict"], "choice": ev.physics.get("choice"), "choice_s": choice_s,
        "predict_s": predict_s, "validation_window_s": window_s,
        "predict_speedup_over_realtime": window_s / predict_s,
        "online_ms_per_frame": online_ms, "frame_interval_ms": 1000.0 * observed.frame_interval_s,
    }


def true_parameters(params: dict, fitted):
    """The twin's true K (``truth/parameters.json``) in the fitted model's terms: a driven bar pushed
    no force, so its F is the fit's (the model does not read it); μ_f the truth's, fitted or not."""
    from dataclasses import replace

    force = params.get("external_force_n")
    return replace(fitted, force_n=fitted.force_n if force is None else float(force),
                   youngs_modulus_pa=params["youngs_modulus_pa"], poisson_ratio=params["poisson_ratio"],
                   beta1=params["beta1_pa_s_pow"], beta2=params["beta2"], friction=params.get("friction"))


def model_at_truth(spec, fitted, params, ref, obs, observed, truth, train, valid) -> dict:
    """The fitted model (its resolution and settings) run at the twin's true parameters and scored as
    the fit is: the model's own error, apart from the estimation's. A fit that validates as well as
    this has left nothing to the search; one that validates better has compensated for the model."""
    from hifumotion.prediction.evaluate import evaluate
    from hifumotion.prediction.pipeline import predict_calibrated

    k = true_parameters(params, fitted)
    t0 = time.perf_counter()
    pred = predict_calibrated(spec, k, ref, train + valid)
    ev = evaluate(pred, spec, ref, obs.frame_masks, observed.frames, truth, train, valid, observed.frame_interval_s)
    return {"parameters": k.as_dict(), "run_s": time.perf_counter() - t0, "training": ev.physics["training"],
            "validation": ev.physics["validation"]}


def ncc_validation(observed, obs, truth, valid) -> dict:
    """The NCC template tracker from the tracked frame 0, scored on the validation frames."""
    from hifumotion.prediction.baselines import ncc_track
    from hifumotion.prediction.evaluate import summary

    ncc = ncc_track(observed.frames, obs.frame_masks[0])
    return summary({f: ncc[f] for f in valid if f in ncc}, truth, float(observed.pixel_mm), valid)


def targets(protocol: str, r: dict) -> dict:
    """The estimation targets on one twin and method, each true or false."""
    v, b = r["physics"]["validation"], r["baselines_validation"]
    hold, kal = b["no_motion"], b["kalman"]
    rec = r["recovered"]
    t = {
        f"validation_dsc_mean>={DSC_MEAN}": v["dsc_mean"] >= DSC_MEAN,
        f"validation_dsc_min>={DSC_MIN}": v["dsc_min"] >= DSC_MIN,
        f"validation_centroid_mean<={CENTROID_MM}mm": v["centroid_mean_mm"] <= CENTROID_MM,
        "beats_hold": v["dsc_mean"] > hold["dsc_mean"] and v["centroid_mean_mm"] < hold["centroid_mean_mm"],
        "beats_kalman": v["dsc_mean"] > kal["dsc_mean"] and v["centroid_mean_mm"] < kal["centroid_mean_mm"],
        f"calibration<={CALIBRATION_S:.0f}s": r["calibration_s"] <= CALIBRATION_S,
        f"prediction>={PREDICT_SPEEDUP:.0f}x_realtime": r["predict_speedup_over_realtime"] >= PREDICT_SPEEDUP,
        "online_at_frame_rate": r["online_ms_per_frame"] <= r["frame_interval_ms"],
    }
    t.update(surrogate_targets(r))
    t[f"no_determined_fit_beyond_{CONFIDENT_SIGMAS:.0f}_sigma"] = not confidently_wrong(rec)
    if protocol in ("slow_push", "push_release"):
        best = min(hold["centroid_mean_mm"], kal["centroid_mean_mm"])
        t["centroid<=half_of_hold_and_kalman"] = v["centroid_mean_mm"] <= 0.5 * best
    if protocol in ("paper", "slow_push"):
        for name in ("force_over_youngs_m2", "beta1_over_youngs_s_pow"):
            t[f"{name}_within_{PARAMETER_REL:.0%}"] = abs(rec[name]["rel_error"]) <= PARAMETER_REL
        t[f"poisson_within_{POISSON_ABS}"] = abs(rec["poisson_ratio"]["fit"] - rec["poisson_ratio"]["truth"]) <= POISSON_ABS
    if protocol in DRIVEN:
        # a driven bar's: a third of holding still and of the Kalman filter; the material (a driven bar
        # pushes no force: β1/E and ν are what the data fix); the twin itself moves millimetres
        best = min(hold["centroid_mean_mm"], kal["centroid_mean_mm"])
        t["centroid<=third_of_hold_and_kalman"] = v["centroid_mean_mm"] <= best / 3
        t[f"beta1_over_youngs_s_pow_within_{PARAMETER_REL:.0%}"] = \
            abs(rec["beta1_over_youngs_s_pow"]["rel_error"]) <= PARAMETER_REL
        t[f"poisson_within_{POISSON_ABS}"] = abs(rec["poisson_ratio"]["fit"] - rec["poisson_ratio"]["truth"]) <= POISSON_ABS
        t[f"twin_moves>={WINDOW_MOTION_MM}mm_in_validation"] = r["validation_window_motion_mm"] >= WINDOW_MOTION_MM
    return t


#: a fit reported as determined may lie this many of its own standard errors from the truth
CONFIDENT_SIGMAS = 3.0


def confidently_wrong(recovered: dict) -> list[str]:
    """The recovered parameters (:func:`~hifumotion.estimation.calibrate.recovered_parameters`)
    reported as determined that lie more than :data:`CONFIDENT_SIGMAS` of their own standard
    errors from the truth, each as ``name: z σ``."""
    out = []
    for name, v in recovered.items():
        if v["determined"] and v["std"]:
            z = (v["fit"] - v["truth"]) / v["std"]
            if abs(z) > CONFIDENT_SIGMAS:
                out.append(f"{name}: {z:+.1f}σ")
    return out


#: how far ahead the online physics is measured against the online surrogate (ms)
ONLINE_MS = 300.0
#: the names of the peers that know the same inputs as the physics (evaluate's baselines)
SURROGATES = ("drive_static", "drive_lagged", "kalman", "no_motion")


def surrogate_targets(r: dict) -> dict:
    """The physics against every predictor that knows the same inputs (the drive regressions,
    static and lagged, the constant-velocity Kalman filter, holding still): validation centroid
    ≤ ½ of the best one's, DSC above all; online, 300 ms ahead, ≤ ½ of the online surrogate's."""
    v, b = r["physics"]["validation"], r["baselines_validation"]
    peers = {name: b[name] for name in SURROGATES if name in b}
    best = min(p["centroid_mean_mm"] for p in peers.values())
    t = {"centroid<=half_of_best_surrogate": v["centroid_mean_mm"] <= 0.5 * best,
         "dsc_above_every_surrogate": all(v["dsc_mean"] > p["dsc_mean"] for p in peers.values())}
    online = [e for e in r.get("online", {}).values() if "surrogate" in e and e["surrogate"].get("frames")]
    if online:
        # 300 ms ahead (the horizon nearest it), the online horizon
        e = min(online, key=lambda e: abs(e["horizon_ms"] - ONLINE_MS))
        # the aims (where each puts the centroid), not their masks: a mask realises an aim only to
        # the pixel grid's quantisation (prediction.pipeline.OnlinePredictions)
        aims = e.get("aim", {})
        ours, theirs = (aims["physics"], aims["surrogate"]) if "surrogate" in aims else (e["physics"], e["surrogate"])
        t["online_300ms_centroid<=half_of_online_surrogate"] = \
            ours["centroid_mean_mm"] <= 0.5 * theirs["centroid_mean_mm"]
    choice = r.get("choice")
    if choice and "excess_over_best_mm" in choice:
        # the product's choice no worse than the validation's best predictor by more than the spread
        t["choice_within_spread_of_the_best"] = choice["excess_over_best_mm"] <= choice["excess_spread_mm"]
    return t


def _settings(text: str) -> dict:
    """``'a=true,model.creep.tolerance=0.01'`` → the nested dict of :class:`CalibrationSettings`
    fields it sets (``hifumotion --set``'s reading), checked against the model."""
    from hifumotion.config import apply_settings, validate_config
    from hifumotion.errors import InputError
    from hifumotion.estimation.calibrate import CalibrationSettings

    try:
        out = apply_settings({}, [part.strip() for part in text.split(",") if part.strip()])
        validate_config(CalibrationSettings, out)
    except InputError as exc:
        raise ValueError(f"--set {text!r}: {exc}") from None
    return out


def run_twin(twin: Path, args, offset_mm: float) -> dict:
    from hifumotion.scoring import read_frame_masks

    params = json.loads((twin / "truth" / "parameters.json").read_text())
    truth = read_frame_masks(twin / "truth")
    motion = json.loads((twin / "truth" / "motion.json").read_text())
    protocol = _twin_settings(twin).get("protocol", {}).get("name", "custom")
    observed, obs, train, valid, prep_s, tmp = observe(twin, args.training, args.tracking, offset_mm,
                                                       fill_bar_cap=not args.no_bar_cap,
                                                       bloom_continuation=args.bloom_continuation)
    out = {"twin": str(twin), "protocol": protocol, "motion": motion, "boundary_offset_mm": offset_mm,
           "prepare_s": prep_s, "training_frames": train, "validation_frames": valid,
           "ncc_validation": ncc_validation(observed, obs, truth, valid), "methods": {}}
    horizons = [int(h) for h in args.horizons.split(",")]
    for method in args.methods.split(","):
        r = calibrate_and_predict(observed, obs, train, valid, truth, params, method, args.workers,
                                  horizons, tmp, _settings(args.set), args.model_at_truth, args.choose)
        r["validation_window_motion_mm"] = window_motion_mm(motion, valid)
        r["targets"] = targets(protocol, r)
        out["methods"][method] = r
        _tell(twin.name, method, r)
        if args.compare_search:
            # the same calibration with the other search model, in the same run: the reduced search's
            # calibration target (≤ 30 s, the fit as good as the implicit search's)
            ours = r["calibration_settings"]["search_integrator"]
            other = "implicit" if ours == "reduced" else "reduced"
            # the peer: --peer-set's settings, or ours with the other search model
            peer_settings = (_settings(args.peer_set) if args.peer_set is not None
                             else {**_settings(args.set), "search_integrator": other})
            peer = calibrate_and_predict(observed, obs, train, valid, truth, params, method, args.workers, horizons,
                                         tmp, peer_settings)
            other = peer["calibration_settings"]["search_integrator"]
            if other == ours:
                raise SystemExit(f"--compare-search: the peer's search model is ours ({ours}); "
                                 "--peer-set must name the other one")
            _tell(twin.name, f"{method} ({other} search)", peer)
            r["search_comparison_settings"] = {"ours": _settings(args.set), "peer": peer_settings}
            runs = {ours: r, other: peer}
            out["methods"][method]["search_comparison"] = search_comparison(runs["reduced"], runs["implicit"])
    return out


def window_motion_mm(motion: dict, frames: list[int]) -> float:
    """How far the true section centroid travels from the first validation frame, at most (mm)."""
    import numpy as np

    c = np.asarray(motion["centroid_mm"], float)[list(frames)]
    return float(np.linalg.norm(c - c[0], axis=1).max())


def _tell(name: str, label: str, r: dict) -> None:
    v = r["physics"]["validation"]
    fe = r["recovered"].get("force_over_youngs_m2")    # none for a driven bar: it pushed no force
    fe_text = "" if fe is None else f"F/E {fe['rel_error']:+.0%}, "
    at = r.get("model_at_truth")
    at_text = "" if at is None else f", at the truth {at['validation']['centroid_mean_mm']:.3f} mm"
    rc = r.get("resolution_check")
    if rc is not None:
        over = rc.get("overruled")
        first = "" if over is None else f" ({over['particles']:,} particles: {over['largest_mm']:.3f} mm, overruled)"
        at_text += (f", {rc['particles'][1]:,} particles move the points {rc['largest_mm']:.3f} mm from where "
                    f"{rc['particles'][0]:,} put them{first}")
    print(f"{name} {label}: DSC {v['dsc_mean']:.4f}/{v['dsc_min']:.4f} centroid {v['centroid_mean_mm']:.3f} mm"
          f"{at_text}, {fe_text}{r['calibration_s']:.0f} s", file=sys.stderr, flush=True)
    peers = ", ".join(f"{m} {s['dsc_mean']:.4f}/{s['centroid_mean_mm']:.3f}"
                      for m, s in r["baselines_validation"].items() if s.get("frames"))
    print(f"    peers (DSC/centroid mm): {peers}; {r['verdict']}", file=sys.stderr, flush=True)
    fits = ", ".join(f"{n} {v['fit']:.4g} (truth {v['truth']:.4g}, {'' if v['determined'] else 'un'}determined"
                     + (f", {(v['fit'] - v['truth']) / v['std']:+.1f}σ)" if v["std"] else ")")
                     for n, v in r["recovered"].items())
    print(f"    fit: {fits}", file=sys.stderr, flush=True)
    online = [e for e in r.get("online", {}).values() if e.get("aim")]
    if online:
        aims = "; ".join(f"{e['horizon_ms']:.0f} ms " + ", ".join(
            f"{m} {a['centroid_mean_mm']:.3f}" for m, a in e["aim"].items() if a.get("frames"))
            for e in online)
        print(f"    online aims vs truth (mm): {aims}", file=sys.stderr, flush=True)
    c = r.get("choice")
    if c and "chosen" in c:
        print(f"    choice: {c['sentence']}; on validation {c['chosen']} {c['validation'].get('centroid_mean_mm', float('nan')):.3f} mm, "
              f"best {c['validation_best']} (excess {c.get('excess_over_best_mm', float('nan')):+.3f} ± "
              f"{c.get('excess_spread_mm', float('nan')):.3f} mm)", file=sys.stderr, flush=True)


def search_comparison(reduced: dict, implicit: dict) -> dict:
    """The reduced search model's calibration against the implicit one's (the reduced search's targets)."""
    vr, vi = reduced["physics"]["validation"], implicit["physics"]["validation"]
    d_dsc = vr["dsc_mean"] - vi["dsc_mean"]
    d_centroid = vr["centroid_mean_mm"] - vi["centroid_mean_mm"]
    return {
        "calibration_s": {"reduced": reduced["calibration_s"], "implicit": implicit["calibration_s"],
                          "speedup": implicit["calibration_s"] / reduced["calibration_s"]},
        "timings_s": {"reduced": reduced["calibration_timings_s"], "implicit": implicit["calibration_timings_s"]},
        "validation": {"reduced": {k: vr[k] for k in ("dsc_mean", "dsc_min", "centroid_mean_mm")},
                       "implicit": {k: vi[k] for k in ("dsc_mean", "dsc_min", "centroid_mean_mm")}},
        "dsc_mean_difference": d_dsc, "centroid_difference_mm": d_centroid,
        "fitted": {"reduced": reduced["fitted"], "implicit": implicit["fitted"]},
        # the training objective of each fit on the full final model (what both searches minimise)
        "final_model_cost_mm": {"reduced": reduced["strategy"].get("full_model_check", {}).get("cost_full_model_mm"),
                                "implicit": implicit["strategy"].get("cost_final_model_mm")},
        "targets": {f"calibration<={REDUCED_CALIBRATION_S:.0f}s": reduced["calibration_s"] <= REDUCED_CALIBRATION_S,
                    # "as good as": no worse than the implicit search's fit by more than the margins
                    f"dsc_within_{FIT_DSC}": d_dsc >= -FIT_DSC,
                    f"centroid_within_{FIT_CENTROID_MM}mm": d_centroid <= FIT_CENTROID_MM},
    }


def main() -> None:
    from _estimation_twins import ALL_CASES, CASES, LARGE_MOTION_CASES, REVERSAL_CASES, twin_folder

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--twin", type=Path, help="one existing twin folder (observed/ and truth/) instead of the cases")
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated cases of _estimation_twins.CASES "
                    "(or LARGE_MOTION_CASES, REVERSAL_CASES)")
    ap.add_argument("--reversals", action="store_true",
                    help="the drives that reverse (REVERSAL_CASES: finite-strain truth, ~17 min each to make), where "
                    "the physics is measured against every predictor that knows the same inputs")
    ap.add_argument("--large-motion", action="store_true",
                    help="the driven twins (LARGE_MOTION_CASES: finite-strain truth, ~25 min each to make)")
    ap.add_argument("--work", type=Path, default=ROOT / ".bench" / "twins", help="where the twins are generated")
    ap.add_argument("--methods", default="least_squares,table1,cmaes")
    ap.add_argument("--training", choices=["tracked", "expert"], default="tracked")
    ap.add_argument("--tracking", choices=["speckle", "glcv"], default="speckle")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--horizons", default="4,6,8", help="online horizons in frames")
    ap.add_argument("--set", default="", help="CalibrationSettings fields to change, e.g. "
                    "'quality_weights=true,bar_motion=false' (to measure an option against the defaults)")
    ap.add_argument("--model-at-truth", action="store_true",
                    help="also run the fitted model at the twin's true parameters (its own error, apart from the "
                    "estimation's: model_at_truth)")
    ap.add_argument("--choose", action="store_true",
                    help="also rank the physics and the surrogates on the last quarter of the training frames (the "
                    "physics calibrated again on the earlier ones) and score the winner: the product's choice")
    ap.add_argument("--no-bar-cap", action="store_true", help="do not continue the sweep's top under the bar")
    ap.add_argument("--bloom-continuation", choices=("reconstruction", "image", "off"), default="reconstruction",
                    help="what gives frame 0's tracked target the strip the bar's bloom hides "
                         "(EstimationConfig.bloom_continuation; default: the product's)")
    ap.add_argument("--compare-search", action="store_true",
                    help="also calibrate with the other search model (reduced/implicit) and compare")
    ap.add_argument("--peer-set", default=None,
                    help="--compare-search's peer settings in --set's form (default: --set's with the other search "
                    "model), e.g. 'search_integrator=implicit' for the default calibration against "
                    "--set 'search_integrator=reduced,particles=1000'")
    ap.add_argument("--quick", action="store_true",
                    help="one twin (slow_push_s42), least squares only: a few minutes once the twin exists")
    args = ap.parse_args()
    if args.quick:
        args.cases, args.methods = "slow_push_s42", "least_squares"
    if args.large_motion:
        args.cases = ",".join(LARGE_MOTION_CASES)
    if args.reversals:
        args.cases = ",".join(REVERSAL_CASES)
    try:
        _settings(args.set)
        if args.peer_set is not None:
            _settings(args.peer_set)
    except ValueError as exc:
        ap.error(str(exc))

    from hifumotion.experiment.boundary_offset import measure_boundary_offset
    from hifumotion.experiment.config import ImagingConfig

    out: dict = {"training": args.training, "tracking": args.tracking, "settings": _settings(args.set),
                 "bar_cap": not args.no_bar_cap, "bloom_continuation": args.bloom_continuation, "twins": {}}
    if args.twin is not None:
        folders = {args.twin.name: args.twin}
    else:
        folders = {}
        for name in args.cases.split(","):
            if name not in ALL_CASES:
                ap.error(f"unknown case {name!r}; expected one of {', '.join(ALL_CASES)}")
            t = time.perf_counter()
            folders[name] = twin_folder(args.work, name)
            out.setdefault("generate_s", {})[name] = time.perf_counter() - t
    offsets: dict = {}   # the phantom's offset, once per imaging setting (a lab measures it once per device)
    for name, folder in folders.items():
        imaging = ImagingConfig(**_twin_settings(folder)["imaging"])
        key = imaging.model_dump_json()
        if key not in offsets:
            offsets[key] = round(measure_boundary_offset(imaging, "glcv", seed=7919).offset_mm, 3)
        out["twins"][name] = run_twin(folder, args, offsets[key])
    everything = [(n, m, r) for n, tw in out["twins"].items() for m, r in tw["methods"].items()]
    out["summary"] = {
        "targets_met": {f"{n}/{m}": all(r["targets"].values()) for n, m, r in everything},
        "targets_missed": {f"{n}/{m}": [k for k, ok in r["targets"].items() if not ok] for n, m, r in everything},
    }
    driven = {n: tw for n, tw in out["twins"].items() if tw["protocol"] in DRIVEN}
    if driven:
        # the driven targets are measured on at least three twins that each move ≥ 2 mm in the window
        moving = sorted(n for n, tw in driven.items()
                        if any(r["validation_window_motion_mm"] >= WINDOW_MOTION_MM for r in tw["methods"].values()))
        out["summary"][f"driven_twins_moving>={WINDOW_MOTION_MM}mm_in_validation"] = moving
        out["summary"]["at_least_three_such_twins"] = len(moving) >= 3
    moving = {f"{n}/{m}": r for n, tw in out["twins"].items() for m, r in tw["methods"].items()
              if r.get("validation_window_motion_mm", 0.0) >= WINDOW_MOTION_MM}
    if moving:
        # the physics against every predictor that knows the same inputs, on twins that move ≥ 2 mm
        # in the validation window (each target on each twin; met on at least three?)
        keys = [f"validation_dsc_mean>={DSC_MEAN}", f"validation_centroid_mean<={CENTROID_MM}mm"]
        table = {k: {t: v for t, v in r["targets"].items() if t in keys or t in surrogate_targets(r)}
                 for k, r in moving.items()}
        out["summary"]["physics_against_the_surrogates"] = table
        for target in sorted({t for row in table.values() for t in row}):
            out["summary"][f"{target}_on_three_moving_twins"] = sum(row.get(target, False) for row in table.values()) >= 3
    print(json_text(out, indent=1))


if __name__ == "__main__":
    main()
