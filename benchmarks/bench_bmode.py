"""B-mode simulator: speed, a cine loop, and what the phantom presets do to segmentation, as JSON.

* ``speed``: frames per second for a 256 x 256 frame (scatterers at 12 per
  resolution cell), and the wall time of a 200-frame cine loop of a moving
  target (scatterers moving with it).
* ``presets``: on N phantoms per preset, the DSC of a global Chan-Vese model
  (ours and scikit-image's ``chan_vese``) against the localized ones (LCV,
  GLCV), from the phantom's initial ellipse. The hard preset must defeat the
  global model while a localized one still succeeds.
* ``pymust`` (only if the package is installed): the same inclusion simulated
  by PyMUST's ``simus`` + ``das`` and by ours; speckle mean/std and
  inclusion contrast side by side.

    python benchmarks/bench_bmode.py [--phantoms 6]

Target: >= 20 frames/s for 256 x 256 on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from hifumotion.io.writers import json_text


def speed(frames: int = 200) -> dict:
    from hifumotion.imaging import Scatterers, Transducer, simulate_frame

    shape, spacing = (256, 256), (0.15, 0.15)
    tr = Transducer(focus_depth_mm=20.0)
    scat = Scatterers.uniform((shape[0] * spacing[0], shape[1] * spacing[1]), tr, 0)
    rows, cols = np.mgrid[0:256, 0:256]

    def echo_at(p):  # a hypoechoic disc of radius 6 mm around (19, 19) mm in material coordinates
        return np.where(np.hypot(p[:, 0] - 19.0, p[:, 1] - 19.0) < 6.0, 0.3, 1.0)

    simulate_frame(echo_at, scat, None, shape, spacing, tr)  # compile
    t0 = time.perf_counter()
    for _ in range(20):
        simulate_frame(echo_at, scat, None, shape, spacing, tr)
    single = (time.perf_counter() - t0) / 20
    t0 = time.perf_counter()
    for t in range(frames):
        offset = np.array([2.0 * np.sin(2 * np.pi * t / frames), 1.0 * np.sin(4 * np.pi * t / frames)])
        simulate_frame(echo_at, scat, scat.positions_mm + offset, shape, spacing, tr)
    loop = time.perf_counter() - t0
    return {"frame_ms": round(single * 1e3, 2), "frames_per_s": round(1.0 / single, 1), "scatterers": len(scat.amplitudes),
            "cine_frames": frames, "cine_wall_s": round(loop, 2)}


def presets(n: int) -> dict:
    from skimage.segmentation import chan_vese

    from hifumotion.contour import parse_init_entry
    from hifumotion.imaging import make_phantom
    from hifumotion.metrics import dice
    from hifumotion.segmentation import segment
    from hifumotion.segmentation.levelset import initial_phi

    out = {}
    for preset in ("easy", "medium", "hard"):
        scores: dict[str, list[float]] = {"cv": [], "skimage_chan_vese": [], "lcv": [], "glcv": [], "initial": []}
        for seed in range(n):
            ph = make_phantom("irregular" if seed % 2 else "ellipse", preset, seed=100 + seed)
            init = parse_init_entry(ph["init"])
            img = ph["image"].astype(float) / 255.0
            scores["initial"].append(dice(init.to_mask(img.shape), ph["mask"]))
            for m in ("cv", "lcv", "glcv"):
                scores[m].append(dice(segment(img, init, m).mask, ph["mask"]))
            phi0 = initial_phi(init, img.shape).astype(float)
            scores["skimage_chan_vese"].append(dice(np.asarray(chan_vese(img, init_level_set=phi0, max_num_iter=200), bool),
                                                    ph["mask"]))
        out[preset] = {k: round(float(np.mean(v)), 4) for k, v in scores.items()}
    return out


def pymust_comparison() -> dict:
    try:
        import pymust  # noqa: F401
    except ImportError:
        return {"skipped": "pymust is not installed (pip install pymust to compare)"}
    return {"skipped": "pymust is installed but the comparison is not implemented yet"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--phantoms", type=int, default=6)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: 3 phantoms of 50 frames")
    args = ap.parse_args(argv)
    if args.quick:
        args.phantoms, args.frames = 3, 50
    print(json_text({"speed": speed(args.frames), "presets": presets(args.phantoms), "pymust": pymust_comparison()}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
