"""Segmentation accuracy and speed on real images with expert masks, against peers, as JSON.

For each dataset folder laid out like ``../shared/data/*`` (images/, masks/,
init.json) and each start (ellipse, points), every method of
``hifumotion.segmentation`` and every peer (scikit-image, SimpleITK) runs from
the same initial contour with its default parameters. Printed: per method and
dataset, mean/min DSC, mean HD95, mean seconds per image, and the ratios of
GLCV to each peer (DSC difference, speed ratio).

    python benchmarks/bench_segmentation.py                  # everything (tens of minutes)
    python benchmarks/bench_segmentation.py --limit 10 --no-peers
    python benchmarks/bench_segmentation.py --methods glcv --datasets ddti

Targets (issue 4): GLCV mean DSC >= 0.85 on DDTI and >= 0.94 on HC18 from both
starts, >= 0.03 above every peer; <= 0.1 s per 300x300 and <= 0.3 s per
800x540 image.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"


def _one(args):
    dataset, name, kind, method = args
    from hifumotion.contour import ClickedPoints
    from hifumotion.io import read_mask, read_sequence
    from hifumotion.io.dataset import load_dataset
    from hifumotion.metrics import score
    from hifumotion.segmentation import segment
    from hifumotion.segmentation.peers import PEERS

    item = next(i for i in load_dataset(DATA / dataset) if i.name == name)
    image = read_sequence(item.image_path).frames[0].astype(np.float64)
    truth = read_mask(item.mask_path)
    init = item.initial_contour(kind)
    t0 = time.perf_counter()
    if method in PEERS:
        init_mask = init.to_mask(image.shape, smooth=True) if isinstance(init, ClickedPoints) else init.to_mask(image.shape)
        t0 = time.perf_counter()
        mask = PEERS[method](image, init_mask)
    else:
        mask = segment(image, init, method).mask
    seconds = time.perf_counter() - t0
    s = score(mask, truth)
    return {"dataset": dataset, "image": name, "init": kind, "method": method, "dsc": s["dsc"], "hd95": s["hd95"],
            "seconds": seconds, "shape": list(image.shape)}


def _warm_up(methods):
    """Compile the Numba kernels once (cached on disk) so that timings measure the work."""
    from hifumotion.contour import Ellipse
    from hifumotion.segmentation import METHODS, segment

    rng = np.random.default_rng(0)
    img = rng.random((96, 96))
    for m in methods:
        if m in METHODS:
            segment(img, Ellipse(48, 48, 20, 18), m, max_iterations=5)


def main(argv=None) -> int:
    from hifumotion.segmentation import METHODS
    from hifumotion.segmentation.peers import PEERS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--datasets", default="ddti,hc18")
    ap.add_argument("--inits", default="ellipse,points")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--peers", default=None, help="comma-separated subset of the peers (default: all)")
    ap.add_argument("--limit", type=int, default=None, help="first N images of each dataset")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows", type=Path, default=None, help="also write every per-image row to this JSON file")
    args = ap.parse_args(argv)

    datasets = [d for d in args.datasets.split(",") if d]
    missing = [d for d in datasets if not (DATA / d / "init.json").is_file()]
    if missing:
        print(json.dumps({"skipped": f"datasets not found under {DATA}: {missing}"}))
        return 0
    methods = [m for m in args.methods.split(",") if m]
    peers = [] if args.no_peers else (list(PEERS) if args.peers is None else [p for p in args.peers.split(",") if p])
    unknown = [p for p in peers if p not in PEERS] + [m for m in methods if m not in METHODS]
    if unknown:
        print(f"unknown method or peer {unknown}; methods: {', '.join(METHODS)}; peers: {', '.join(PEERS)}", file=sys.stderr)
        return 2
    _warm_up(methods)
    from hifumotion.io.dataset import load_dataset

    jobs = []
    for d in datasets:
        names = [i.name for i in load_dataset(DATA / d)][: args.limit]
        for kind in args.inits.split(","):
            for m in methods + peers:
                jobs += [(d, n, kind, m) for n in names]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers, initializer=_warm_up, initargs=(methods,)) as pool:
        rows = list(pool.map(_one, jobs, chunksize=4))
    wall = time.perf_counter() - t0

    summary: dict = {"wall_s": round(wall, 1), "workers": args.workers, "cpu_count": os.cpu_count(), "results": {}}
    for d in datasets:
        for kind in args.inits.split(","):
            block = {}
            for m in methods + peers:
                sel = [r for r in rows if r["dataset"] == d and r["init"] == kind and r["method"] == m]
                dsc = np.array([r["dsc"] for r in sel])
                block[m] = {"images": len(sel), "dsc_mean": round(float(dsc.mean()), 4), "dsc_min": round(float(dsc.min()), 4),
                            "hd95_mean_px": round(float(np.mean([r["hd95"] for r in sel])), 2),
                            "seconds_mean": round(float(np.mean([r["seconds"] for r in sel])), 4)}
            if "glcv" in block:
                g = block["glcv"]
                block["glcv_vs"] = {m: {"dsc_gain": round(g["dsc_mean"] - v["dsc_mean"], 4),
                                        "speedup": round(v["seconds_mean"] / max(g["seconds_mean"], 1e-9), 2)}
                                    for m, v in block.items() if m != "glcv"}
            summary["results"][f"{d}/{kind}"] = block
    if args.rows:
        args.rows.write_text(json.dumps(rows, indent=1))
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
