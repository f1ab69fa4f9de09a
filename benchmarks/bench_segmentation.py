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
    python benchmarks/bench_segmentation.py --methods gac,glcv --peers sitk_gac
    python benchmarks/bench_segmentation.py --methods glcv,glcv+carry=global --no-peers

A method may carry parameters: ``name+key=value+key=value`` (values parsed as
JSON where they can be, else strings).

Rows are cached in ``.bench/cache/segmentation/``, one file per method and
fingerprint: the fingerprint hashes the source the method runs (the
segmentation package and the contour, metric and polygon modules; for a peer,
``peers.py`` and its library's version), so a re-run after a change runs only
the methods whose code changed; an image's row is keyed by the image's and the
mask's bytes. ``--no-cache`` runs everything. The JSON says how many rows came
from the cache: their seconds were measured in the run that made them.

Beside the methods, ``start_enlarged`` (not a method, no look at the image) is
the start scaled about its centre by 1/0.7, the factor by which the shared
sets' starts were shrunk from the expert region: what the start's size alone
knows (``docs/decisions.md``).

Targets: GLCV mean DSC >= the best peer + 0.03 on each set from each
start; <= 0.05 s per 300x300 and <= 0.3 s per 800x540 image on one core.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from hifumotion.io.writers import json_text

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"


CACHE = ROOT / ".bench" / "cache" / "segmentation"
#: The start protocol's shrink factor (``../shared/data/README.md``), for the reference row only.
START_SHRINK = 0.7


def _digest(paths) -> str:
    h = hashlib.sha1()
    for p in paths:
        h.update(Path(p).read_bytes())
    return h.hexdigest()[:16]


def fingerprint(method: str) -> str:
    """A hash of what decides ``method``'s rows: its source and, for a peer, its library's version."""
    src = ROOT / "src" / "hifumotion"
    files = [src / "contour.py", src / "metrics.py", src / "_polygon.py", src / "io" / "dataset.py",
             Path(__file__)]
    from hifumotion.segmentation.peers import PEERS

    if method in PEERS:
        files.append(src / "segmentation" / "peers.py")
        import importlib.metadata as md

        lib = "SimpleITK" if method.startswith("sitk") else "scikit-image"
        extra = f"{method}:{md.version(lib)}"
    else:
        files += sorted((src / "segmentation").glob("*.py"))
        extra = method
    return hashlib.sha1((_digest(files) + extra).encode()).hexdigest()[:16]


def _start_enlarged(image, init):
    from hifumotion.contour import ClickedPoints, Ellipse

    s = 1.0 / START_SHRINK
    if isinstance(init, Ellipse):
        return Ellipse(init.cx, init.cy, init.a * s, init.b * s, init.angle_deg).to_mask(image.shape)
    pts = init.array
    centre = pts.mean(axis=0)
    return ClickedPoints(centre + s * (pts - centre)).to_mask(image.shape, smooth=True)


def method_spec(spec: str) -> tuple[str, dict]:
    """``"glcv+carry=global"`` → ``("glcv", {"carry": "global"})``."""
    name, *pairs = spec.split("+")
    params = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        try:
            params[key] = json.loads(value)
        except ValueError:
            params[key] = value
    return name, params


def _one(args):
    dataset, name, kind, method, key = args
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
    if method == "start_enlarged":
        mask = _start_enlarged(image, init)
    elif method in PEERS:
        init_mask = init.to_mask(image.shape, smooth=True) if isinstance(init, ClickedPoints) else init.to_mask(image.shape)
        t0 = time.perf_counter()
        mask = PEERS[method](image, init_mask)
    else:
        base, params = method_spec(method)
        mask = segment(image, init, base, **params).mask
    seconds = time.perf_counter() - t0
    s = score(mask, truth)
    return {"dataset": dataset, "image": name, "init": kind, "method": method, "dsc": s["dsc"], "hd95": s["hd95"],
            "seconds": seconds, "shape": list(image.shape), "key": key}


class RowCache:
    """Rows of one method under one fingerprint, in ``CACHE/<method>-<fingerprint>.json``."""

    def __init__(self, method: str, enabled: bool):
        self.path = CACHE / f"{method}-{fingerprint(method)}.json"
        self.rows = json.loads(self.path.read_text()) if enabled and self.path.is_file() else {}

    def save(self, rows) -> None:
        self.rows.update({r["key"]: r for r in rows})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.rows))
        tmp.replace(self.path)


def _warm_up(methods):
    """Compile the Numba kernels once (cached on disk) so that timings measure the work."""
    from hifumotion.contour import Ellipse
    from hifumotion.segmentation import METHODS, segment

    rng = np.random.default_rng(0)
    img = rng.random((96, 96))
    for m in methods:
        base, params = method_spec(m)
        if base in METHODS:
            segment(img, Ellipse(48, 48, 20, 18), base, **{"max_iterations": 5, **params})


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
    ap.add_argument("--no-cache", action="store_true", help="run every row, ignoring and replacing the cache")
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: the first 10 images of each dataset")
    args = ap.parse_args(argv)
    if args.quick:
        args.limit = 10 if args.limit is None else min(args.limit, 10)

    datasets = [d for d in args.datasets.split(",") if d]
    missing = [d for d in datasets if not (DATA / d / "init.json").is_file()]
    if missing:
        print(json_text({"skipped": f"datasets not found under {DATA}: {missing}"}, indent=None))
        return 0
    methods = [m for m in args.methods.split(",") if m]
    peers = [] if args.no_peers else (list(PEERS) if args.peers is None else [p for p in args.peers.split(",") if p])
    unknown = [p for p in peers if p not in PEERS] + [m for m in methods if method_spec(m)[0] not in METHODS]
    if unknown:
        print(f"unknown method or peer {unknown}; methods: {', '.join(METHODS)}; peers: {', '.join(PEERS)}", file=sys.stderr)
        return 2
    _warm_up(methods)
    from hifumotion.io.dataset import load_dataset

    everything = methods + peers + ["start_enlarged"]
    caches = {m: RowCache(m, not args.no_cache) for m in everything}
    jobs, rows = [], []
    for d in datasets:
        items = list(load_dataset(DATA / d))[: args.limit]
        digests = {item.name: _digest([item.image_path, item.mask_path]) for item in items}  # read once
        for kind in args.inits.split(","):
            for m in everything:
                for item in items:
                    key = f"{d}/{item.name}/{kind}/{digests[item.name]}"
                    cached = caches[m].rows.get(key)
                    if cached is not None:
                        rows.append(cached)
                    else:
                        jobs.append((d, item.name, kind, m, key))
    from_cache = len(rows)
    t0 = time.perf_counter()
    if jobs:
        fresh = []
        with ProcessPoolExecutor(args.workers, initializer=_warm_up, initargs=(methods,)) as pool:
            for k, row in enumerate(pool.map(_one, jobs, chunksize=4), 1):
                fresh.append(row)
                if k % 40 == 0 or k == len(jobs):  # a stopped run keeps what it measured
                    for m in {r["method"] for r in fresh[-40:]}:
                        caches[m].save([r for r in fresh[-40:] if r["method"] == m])
                    print(f"{k}/{len(jobs)} rows, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
        rows += fresh
    wall = time.perf_counter() - t0

    summary: dict = {"wall_s": round(wall, 1), "workers": args.workers, "cpu_count": os.cpu_count(),
                     "rows_run": len(jobs), "rows_from_cache": from_cache, "results": {}}
    for d in datasets:
        for kind in args.inits.split(","):
            block = {}
            for m in everything:
                sel = [r for r in rows if r["dataset"] == d and r["init"] == kind and r["method"] == m]
                dsc = np.array([r["dsc"] for r in sel])
                block[m] = {"images": len(sel), "dsc_mean": round(float(dsc.mean()), 4), "dsc_min": round(float(dsc.min()), 4),
                            "hd95_mean_px": round(float(np.mean([r["hd95"] for r in sel])), 2),
                            "seconds_mean": round(float(np.mean([r["seconds"] for r in sel])), 4)}
            if "glcv" in block:
                g = block["glcv"]
                block["glcv_vs"] = {m: {"dsc_gain": round(g["dsc_mean"] - v["dsc_mean"], 4),
                                        "speedup": round(v["seconds_mean"] / max(g["seconds_mean"], 1e-9), 2)}
                                    for m, v in block.items() if m not in ("glcv", "start_enlarged")}
                if peers:
                    best = max(peers, key=lambda m: block[m]["dsc_mean"])
                    margin = g["dsc_mean"] - block[best]["dsc_mean"]
                    block["target"] = {"best_peer": best, "glcv_margin": round(margin, 4), "met": bool(margin >= 0.03)}
            summary["results"][f"{d}/{kind}"] = block
    if args.rows:
        args.rows.write_text(json.dumps(rows, indent=1))
    print(json_text(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
