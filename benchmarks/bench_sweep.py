"""The sweep's reconstruction: the tissue's volume from segmented sweep planes against the truth, as JSON.

Twins with other seeds, shapes, resolutions and bars than the defaults are imaged at
rest (:func:`hifumotion.experiment.rest_sweep.rest_sweep`: the twin's sweep without its
physics, in seconds). Each sweep is segmented from the clinician's contour on the
imaging plane with each method (:func:`hifumotion.segmentation.sweep.segment_sweep`, the
pool's floor and the resting bar excluded as ``hifumotion run`` does) and reconstructed
(:func:`hifumotion.reconstruction.reconstruct`). Per twin and method:

* ``volume_error``: reconstructed volume / the sample's true volume − 1 (quadrature of
  its shape), from the masks as segmented;
* ``volume_error_offset``: the same with the boundary offset measured on a simulated
  gel phantom with the twin's imaging settings and the same method
  (:func:`hifumotion.experiment.boundary_offset.measure_boundary_offset`, what the demo
  applies) taken off the surface (``reconstruct(boundary_offset_mm=…)``);
* ``truth_volume_error``: the reconstruction from the *true* masks (the floor any
  segmentation can reach with this plane gap);
* ``mean_dsc`` over the planes holding tissue, the area ratio of each plane
  (segmented / true), the planes found and missed, and seconds.

    python benchmarks/bench_sweep.py [--methods glcv,lcv,cv,gac,glcv+plane_start=neighbour] [--twins a,b]

Target: GLCV's reconstructed volume within 5 % of the truth on every twin.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from bench_segmentation import method_spec as parse_method  # "glcv+plane_start=neighbour"

from hifumotion.io.writers import json_text

#: The twins: (preset, overrides). Seeds, shapes, pixel sizes, plane gaps and bars differ.
TWINS: dict[str, tuple[str, dict]] = {
    "lobed": ("demo", {"seed": 11, "blob": {"size_mm": [26.0, 16.0, 22.0], "lobes": 5}}),
    "irregular": ("demo", {"seed": 12, "blob": {"size_mm": [32.0, 19.0, 26.0], "irregularity": 0.22, "lobes": 9}}),
    "long_flat": ("demo", {"seed": 13, "blob": {"size_mm": [22.0, 12.0, 30.0], "bottom_cut": 0.3}}),
    "fine_pixels": ("default", {"seed": 14, "blob": {"size_mm": [28.0, 17.0, 20.0]}}),
    "coarse_planes": ("small", {"seed": 15}),
    "oblique_bar": ("oblique", {"seed": 16, "blob": {"size_mm": [24.0, 15.0, 22.0], "lobes": 4},
                                "bar": {"radius_mm": 5.0}}),
}
DEFAULT_METHODS = "glcv,lcv,cv,gac"


def _config(name: str):
    from hifumotion.experiment.config import twin_config

    preset, overrides = TWINS[name]
    return twin_config(preset, overrides)


@functools.lru_cache(maxsize=None)
def _offset(imaging_json: str, spec: str) -> float:
    """The phantom's boundary offset (mm) for these imaging settings and method spec: twins that
    share their imaging share it, so each is measured once per worker."""
    from hifumotion.experiment.boundary_offset import measure_boundary_offset
    from hifumotion.experiment.config import ImagingConfig

    method, params = parse_method(spec)
    return float(measure_boundary_offset(ImagingConfig.model_validate_json(imaging_json), method, **params).offset_mm)


def run_twin(name: str, methods: list[str]) -> dict:
    """Image twin ``name``'s sweep and segment it with every method (one worker's job)."""
    from hifumotion.errors import InputError
    from hifumotion.estimation.prepare import known_solid_mask
    from hifumotion.experiment.rest_sweep import rest_sweep
    from hifumotion.metrics import dice
    from hifumotion.reconstruction import reconstruct
    from hifumotion.segmentation.sweep import segment_sweep

    cfg = _config(name)
    t0 = time.perf_counter()
    rs = rest_sweep(cfg)
    present = rs.masks.reshape(len(rs.masks), -1).any(axis=1)
    row: dict = {"twin": name, "planes": len(rs.z_mm), "planes_with_tissue": int(present.sum()),
                 "pixel_mm": rs.pixel_mm, "gap_mm": float(np.diff(rs.z_mm).mean()), "start_plane": rs.start,
                 "true_volume_mm3": rs.volume_mm3, "image_s": time.perf_counter() - t0,
                 "truth_volume_error": reconstruct(rs.masks, rs.pixel_mm, rs.z_mm).volume_mm3 / rs.volume_mm3 - 1,
                 "methods": {}}
    exclude = np.stack([known_solid_mask(rs.setup, z) for z in rs.z_mm])
    true_area = rs.masks.sum((1, 2))

    def volume_error(masks, offset_mm=0.0):
        if masks.reshape(len(masks), -1).any(axis=1).sum() < 2:
            return None
        try:
            rec = reconstruct(masks, rs.pixel_mm, rs.z_mm, boundary_offset_mm=offset_mm)
        except InputError:  # nothing left
            return -1.0
        return rec.volume_mm3 / rs.volume_mm3 - 1

    for spec in methods:
        method, params = parse_method(spec)
        t = time.perf_counter()
        seg = segment_sweep(rs.images, rs.initial_contour, rs.start, method, spacing=rs.pixel_mm, exclude=exclude,
                            **params)
        seconds = time.perf_counter() - t
        offset = _offset(cfg.imaging.model_dump_json(), spec)
        found = seg.present
        row["methods"][spec] = {
            "volume_error": volume_error(seg.masks),
            "volume_error_offset": volume_error(seg.masks, offset),
            "boundary_offset_mm": offset,
            "mean_dsc": float(np.mean([dice(m, tr) for m, tr in zip(seg.masks[present], rs.masks[present])])),
            "area_ratio": [round(float(a / t_), 3) if t_ else (None if a == 0 else float("inf"))
                           for a, t_ in zip(seg.masks.sum((1, 2)), true_area)],
            "planes_missed": int((present & ~found).sum()),
            "planes_beyond_tissue": int((found & ~present).sum()),
            "seconds": seconds,
        }
    return row


def summary(rows: list[dict], methods: list[str], tolerance: float = 0.05) -> dict:
    out = {}
    for method in methods:
        per = [r["methods"][method] for r in rows]
        for key in ("volume_error", "volume_error_offset"):
            errs = [p[key] for p in per]
            worst = None if any(e is None for e in errs) else max(abs(e) for e in errs)
            out.setdefault(method, {})[f"worst_abs_{key}"] = worst
            out[method][f"mean_{key}"] = None if worst is None else float(np.mean(errs))
        out[method]["mean_dsc"] = float(np.mean([p["mean_dsc"] for p in per]))
        out[method]["seconds"] = float(sum(p["seconds"] for p in per))
        worst = out[method]["worst_abs_volume_error_offset"]
        out[method]["within_5_percent_on_every_twin"] = worst is not None and worst <= tolerance
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--methods", default=DEFAULT_METHODS)
    ap.add_argument("--twins", default=",".join(TWINS))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: GLCV and GAC only")
    args = ap.parse_args(argv)
    if args.quick:
        args.methods = "glcv,gac"
    from hifumotion.segmentation import METHODS

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    twins = [t.strip() for t in args.twins.split(",") if t.strip()]
    bad = [m for m in methods if any("=" not in p for p in m.split("+")[1:]) or parse_method(m)[0] not in METHODS]
    bad += [t for t in twins if t not in TWINS]
    if bad:
        print(f"bench_sweep: unknown {', '.join(bad)}; methods: {', '.join(METHODS)}; twins: {', '.join(TWINS)}",
              file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    from hifumotion.errors import InputError

    try:
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            rows = list(pool.map(run_twin, twins, [methods] * len(twins)))
    except InputError as err:
        print(f"bench_sweep: {err}", file=sys.stderr)
        return 2
    print(json_text({"benchmark": "sweep", "methods": methods, "twins": rows, "summary": summary(rows, methods),
                      "seconds": time.perf_counter() - t0}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
