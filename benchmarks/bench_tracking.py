"""Tracking speed and accuracy on a synthetic 256 x 256 cine loop, as JSON.

A target (a lobed blob) translates and deforms over the frames under
speckle-like correlated noise on an uneven background; ``track`` follows it
from an ellipse on the first frame. Printed: milliseconds per frame, first frame
excluded since it starts from the rough ellipse: ``ms_per_frame_wall``, the wall time of
``track`` per frame with the motion estimate and the result included, and the median
and mean of the segmentation's own time; mean/min DSC against the known masks, and, for comparison in the same run,
scikit-image's ``morphological_chan_vese`` started from the previous mask
with the same per-frame iteration budget.

    python benchmarks/bench_tracking.py --frames 60

Target: <= 5 ms per 256 x 256 frame (``ms_per_frame_wall``).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from scipy import ndimage

from hifumotion.io.writers import json_text


def cine(frames: int, seed: int = 0, size: int = 256):
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:size, 0:size]
    base_noise = ndimage.gaussian_filter(rng.standard_normal((size + 64, size + 64)), 1.5)
    base_noise /= base_noise.std()
    images, masks = [], []
    for t in range(frames):
        phase = 2 * np.pi * t / frames
        cx, cy = 120 + 18 * np.sin(phase), 128 + 8 * np.sin(2 * phase)
        radius = 52 * (1 + 0.06 * np.sin(phase))
        theta = np.arctan2(rows - cy, cols - cx)
        r = radius * (1 + 0.1 * np.cos(3 * theta + 0.4 * np.sin(phase)))
        mask = np.hypot(cols - cx, rows - cy) < r
        # speckle attached to the tissue: the noise field moves with the target's centre
        dx, dy = int(round(cx - 120)), int(round(cy - 128))
        noise = base_noise[32 - dy : 32 - dy + size, 32 - dx : 32 - dx + size]
        background = 0.35 + 0.15 * rows / size
        img = np.clip(np.where(mask, background + 0.2, background) + 0.07 * noise, 0, 1)
        images.append(img)
        masks.append(mask)
    return np.stack(images), np.stack(masks)


def main(argv=None) -> int:
    from skimage.segmentation import morphological_chan_vese

    from hifumotion.contour import Ellipse
    from hifumotion.metrics import dice
    from hifumotion.segmentation import segment, track

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--method", default="glcv")
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: the first 60 frames")
    args = ap.parse_args(argv)
    if args.quick:
        args.frames = min(args.frames, 60)

    images, masks = cine(args.frames)
    init = Ellipse(120, 128, 38, 36, 0)
    segment(images[0], init, args.method, max_iterations=5)  # compile the kernels (cached on disk)
    t0 = time.perf_counter()
    result = track(images, init, args.method)
    wall_ms = (time.perf_counter() - t0 - result.results[0].seconds) * 1000 / (args.frames - 1)
    per_frame_ms = np.array([r.seconds * 1000 for r in result.results[1:]])
    dsc = np.array([dice(m, t) for m, t in zip(result.masks, masks)])

    # peer: morphological Chan-Vese from the previous mask, a fixed small iteration budget per frame
    prev = result.masks[0]
    peer_ms, peer_dsc = [], []
    for t in range(1, args.frames):
        t0 = time.perf_counter()
        prev = morphological_chan_vese(images[t], 10, init_level_set=prev, smoothing=1).astype(bool)
        peer_ms.append((time.perf_counter() - t0) * 1000)
        peer_dsc.append(dice(prev, masks[t]))
    out = {
        "frames": args.frames,
        "size": list(images.shape[1:]),
        "method": args.method,
        "ms_per_frame_wall": round(float(wall_ms), 2),
        "ms_per_frame_median": round(float(np.median(per_frame_ms)), 2),
        "ms_per_frame_mean": round(float(per_frame_ms.mean()), 2),
        "iterations_per_frame_mean": round(float(np.mean([r.iterations for r in result.results[1:]])), 1),
        "first_frame_ms": round(result.results[0].seconds * 1000, 1),
        "dsc_mean": round(float(dsc.mean()), 4),
        "dsc_min": round(float(dsc.min()), 4),
        "peer_skimage_morph_cv": {"ms_per_frame_median": round(float(np.median(peer_ms)), 2),
                                  "dsc_mean": round(float(np.mean(peer_dsc)), 4)},
    }
    out["speed_ratio_vs_peer"] = round(out["peer_skimage_morph_cv"]["ms_per_frame_median"] / out["ms_per_frame_wall"], 2)
    print(json_text(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
