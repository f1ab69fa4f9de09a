"""Following points in real ultrasound cine against human keypoints, as JSON.

The development set (``shared/data/tongue``: real midsagittal tongue B-mode, swallow and speech,
human DeepLabCut keypoints on sparse keyframes; :mod:`_tongue`) is tracked from each clip's
first keyframe: every keypoint labelled there is started at its label and carried to the end
of the clip by each tracker, all in the same run:

* ``hold`` — holding still (the label of the first keyframe);
* ``lk`` — OpenCV's pyramidal Lucas–Kanade, frame to frame (21 px window, 3 levels);
* ``farneback`` — OpenCV's dense Farnebäck flow, frame to frame, the points moved by it;
* ``hifumotion`` — :func:`hifumotion.speckle.track_points`, what ``hifumotion track --points``
  and the Python API run;
* ``dense_field`` — :class:`hifumotion.speckle.SpeckleTracker` with
  :func:`~hifumotion.speckle.follow.carry_points`, the region tracker's field sampled at the points.

Measured at every later keyframe where the point is labelled (pixels; the spacing is unknown):
the landmarks' error (hyoid, mandible, short tendon, thyroid), the tongue surface points'
error and their distance to the labelled tongue line (the polyline through that keyframe's
surface labels), the drift (mean error over the last third of keyframes ÷ the first third),
and milliseconds per frame (one process; the host's speed drifts, compare ratios).

    python benchmarks/bench_real_tracking.py --quick          # six clips, a minute or two
    python benchmarks/bench_real_tracking.py                  # all 22 clips

Also printed: ``label_noise``, how far one point's human labels differ between keyframes at most
two frames apart — the floor under any tracker's error here.

Targets (on the development set and on kept-back recordings alike): landmarks ≤ ½ of holding
still's mean error and below LK's on every clip; tongue points' line distance ≤ ½ of holding
still's, their point error below holding still's and LK's; drift ≤ 1.3; ≤ 10 ms a frame.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _tongue import DEFAULT_ROOT, LANDMARKS, TONGUE, Clip, clip_names, load_clips, point_to_polyline_px  # noqa: E402

from hifumotion.io.writers import json_text

#: The clips of ``--quick``: speech and swallow, scanner and screen-capture, 32–121 frames/s.
QUICK = ("tongue_speech_AA11", "tongue_speech_coalstone", "tongue_swallow_P10", "tongue_swallow_P14",
         "tongue_swallow_standard63fps2", "tongue_swallow_M09thin")


def track_hold(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.repeat(points[None], len(frames), axis=0)


def track_lk(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    import cv2

    out = [points.astype(np.float32)]
    p = points.astype(np.float32).reshape(-1, 1, 2)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    for t in range(1, len(frames)):
        q, status, _ = cv2.calcOpticalFlowPyrLK(frames[t - 1], frames[t], p, None, winSize=(21, 21), maxLevel=3,
                                                criteria=criteria)
        lost = status.ravel() == 0
        q[lost] = p[lost]
        p = q
        out.append(p.reshape(-1, 2).copy())
    return np.stack(out)


def track_farneback(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    import cv2

    out = [points.astype(np.float32)]
    p = points.astype(np.float32)
    for t in range(1, len(frames)):
        flow = cv2.calcOpticalFlowFarneback(frames[t - 1], frames[t], None, 0.5, 3, 15, 3, 5, 1.2, 0)
        mx, my = p[:, 0].reshape(1, -1), p[:, 1].reshape(1, -1)
        d = cv2.remap(flow, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1, 2)
        p = p + d
        out.append(p.copy())
    return np.stack(out)


def track_dense_field(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    from hifumotion.speckle import SpeckleTracker
    from hifumotion.speckle.follow import carry_points

    tracker = SpeckleTracker(frames[0], 1.0)
    out = [points.astype(np.float64)]
    for t in range(1, len(frames)):
        disp, q = tracker.update(frames[t])
        moved, _ = carry_points(points, disp, q, (1.0, 1.0))
        out.append(moved)
    return np.stack(out)


def track_hifumotion(frames: np.ndarray, points: np.ndarray) -> np.ndarray:
    from hifumotion.speckle import track_points

    return track_points(frames, points).positions_px


TRACKERS = {"hold": track_hold, "lk": track_lk, "farneback": track_farneback, "hifumotion": track_hifumotion,
            "dense_field": track_dense_field}


def score_clip(clip: Clip, tracker) -> dict:
    """One tracker on one clip: its errors at the keyframes after the first."""
    k0 = clip.keyframes[0]
    names = [k for k in (*TONGUE, *LANDMARKS) if k in clip.labels[k0]]
    start = np.array([clip.labels[k0][k] for k in names], float)
    t0 = time.perf_counter()
    path = np.asarray(tracker(clip.frames[k0:], start), float)
    seconds = time.perf_counter() - t0
    per_key = []          # (keyframe, mean error of every labelled point)
    landmark, tongue, line = [], [], []
    for k in clip.keyframes[1:]:
        lab = clip.labels[k]
        pos = path[k - k0]
        errs = []
        surface = clip.tongue_line(k)
        for i, name in enumerate(names):
            if name not in lab:
                continue
            e = float(np.hypot(*(pos[i] - lab[name])))
            errs.append(e)
            if name in LANDMARKS:
                landmark.append(e)
            else:
                tongue.append(e)
                if len(surface) >= 2:
                    line.append(float(point_to_polyline_px(pos[i:i + 1], surface)[0]))
        if errs:
            per_key.append(float(np.mean(errs)))
    third = max(len(per_key) // 3, 1)
    first, last = np.mean(per_key[:third]), np.mean(per_key[-third:])

    def stats(x):
        return {"mean": float(np.mean(x)), "p90": float(np.percentile(x, 90)), "n": len(x)} if x else None

    return {"landmarks_px": stats(landmark), "tongue_points_px": stats(tongue), "tongue_line_px": stats(line),
            "all_px": float(np.mean(landmark + tongue)), "drift": float(last / max(first, 1e-9)),
            "ms_per_frame": 1e3 * seconds / max(len(path) - 1, 1)}


def label_noise(clips: list[Clip], within_frames: int = 2) -> dict:
    """How far the human labels of one point differ between keyframes at most ``within_frames``
    apart (≤ 25–60 ms here, where the tissue barely moves): the scatter of the labels themselves.
    A tracker started on one label and scored on another cannot do better than about this."""
    landmark, tongue = [], []
    for clip in clips:
        keys = clip.keyframes
        for a, b in zip(keys[:-1], keys[1:]):
            if b - a > within_frames:
                continue
            for name in set(clip.labels[a]) & set(clip.labels[b]):
                d = float(np.hypot(*np.subtract(clip.labels[a][name], clip.labels[b][name])))
                (landmark if name in LANDMARKS else tongue).append(d)
    return {"within_frames": within_frames,
            "landmarks_px": float(np.mean(landmark)) if landmark else None, "landmark_pairs": len(landmark),
            "tongue_points_px": float(np.mean(tongue)) if tongue else None, "tongue_pairs": len(tongue)}


def summarise(per_clip: dict, trackers: list[str]) -> dict:
    """Means over clips, and the issue's targets checked clip by clip for ``hifumotion``."""
    def mean_of(tr, key, field="mean"):
        v = [c[tr][key][field] if isinstance(c[tr][key], dict) else c[tr][key]
             for c in per_clip.values() if c[tr][key] is not None]
        return float(np.mean(v)) if v else None

    out = {tr: {k: mean_of(tr, k) for k in ("landmarks_px", "tongue_points_px", "tongue_line_px", "all_px",
                                             "drift", "ms_per_frame")} for tr in trackers}
    if "hifumotion" in trackers and "hold" in trackers and "lk" in trackers:
        checks = {"landmarks_half_of_hold": [], "landmarks_below_lk": [], "line_half_of_hold": [],
                  "points_below_hold_and_lk": [], "drift_le_1.3": [], "ms_le_10": []}
        for name, c in per_clip.items():
            h, k, m = c["hold"], c["lk"], c["hifumotion"]
            if m["landmarks_px"]:
                checks["landmarks_half_of_hold"].append(m["landmarks_px"]["mean"] <= 0.5 * h["landmarks_px"]["mean"])
                checks["landmarks_below_lk"].append(m["landmarks_px"]["mean"] < k["landmarks_px"]["mean"])
            if m["tongue_line_px"]:
                checks["line_half_of_hold"].append(m["tongue_line_px"]["mean"] <= 0.5 * h["tongue_line_px"]["mean"])
            if m["tongue_points_px"]:
                checks["points_below_hold_and_lk"].append(
                    m["tongue_points_px"]["mean"] < min(h["tongue_points_px"]["mean"], k["tongue_points_px"]["mean"]))
            checks["drift_le_1.3"].append(m["drift"] <= 1.3)
            checks["ms_le_10"].append(m["ms_per_frame"] <= 10.0)
        out["targets_met"] = {k: f"{sum(v)}/{len(v)}" for k, v in checks.items()}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=DEFAULT_ROOT, help="the tongue set's folder")
    ap.add_argument("--quick", action="store_true", help=f"only {len(QUICK)} clips")
    ap.add_argument("--clips", nargs="*", help="clip names (default: all, or the quick ones)")
    ap.add_argument("--trackers", default=",".join(TRACKERS), help="comma-separated, of " + ",".join(TRACKERS))
    args = ap.parse_args(argv)
    if not args.root.is_dir():
        print(f"error: {args.root}: no tongue set there (give --root)", file=sys.stderr)
        return 2
    import cv2

    cv2.setNumThreads(1)   # the target is one core
    names = args.clips or (list(QUICK) if args.quick else clip_names(args.root))
    trackers = [t for t in args.trackers.split(",") if t]
    unknown = [t for t in trackers if t not in TRACKERS]
    if unknown:
        print(f"error: --trackers: unknown {unknown}; expected of {list(TRACKERS)}", file=sys.stderr)
        return 2
    per_clip = {}
    clips = load_clips(args.root, names)
    for clip in clips:
        per_clip[clip.name] = {tr: score_clip(clip, TRACKERS[tr]) for tr in trackers}
        row = {tr: round(per_clip[clip.name][tr]["all_px"], 2) for tr in trackers}
        print(f"{clip.name}: {row}", file=sys.stderr, flush=True)
    print(json_text({"clips": per_clip, "summary": summarise(per_clip, trackers), "label_noise": label_noise(clips)}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
