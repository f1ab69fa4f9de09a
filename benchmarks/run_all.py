"""Run every benchmark, one after the other (never two at once: 2 cores), and print one JSON.

    python benchmarks/run_all.py                 # the quick settings of each (about 20–30 min)
    python benchmarks/run_all.py --full          # each benchmark's own defaults (hours)
    python benchmarks/run_all.py --only bench_tracking bench_bmode

Each benchmark runs in its own process; its JSON (the last JSON object it prints) goes
under its name, with its wall time and exit status; one that fails does not stop the rest.
``make bench`` calls this.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from hifumotion.io.writers import json_text

HERE = Path(__file__).resolve().parent

#: Benchmark → the arguments of a quick run (the full run uses each script's defaults).
QUICK = {
    "bench_tracking": ["--frames", "60"],
    "bench_real_tracking": ["--quick"],
    "bench_observation": ["--quick"],
    "bench_bmode": ["--phantoms", "3", "--frames", "50"],
    "bench_particles": ["--steps", "150", "--json"],
    "bench_segmentation": ["--limit", "10"],
    "bench_sweep": ["--methods", "glcv,gac"],
    "bench_twin": ["--preset", "small", "--json"],
    "bench_convergence": ["--preset", "small"],
    "bench_estimation": ["--preset", "small", "--modes", "glcv"],
    "bmode_vs_pymust": [],
}


def last_json(text: str):
    """The last top-level JSON object in ``text`` (benchmarks may log before it)."""
    decoder = json.JSONDecoder()
    found = None
    i = 0
    while (i := text.find("{", i)) != -1:
        try:
            found, end = decoder.raw_decode(text, i)
            i = end
        except ValueError:
            i += 1
    return found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="each benchmark's own (long) defaults")
    ap.add_argument("--only", nargs="*", default=None, help="names of the benchmarks to run")
    args = ap.parse_args()
    names = args.only or list(QUICK)
    unknown = [n for n in names if n not in QUICK]
    if unknown:
        sys.exit(f"error: unknown benchmark(s) {unknown}; choose from {', '.join(QUICK)}")
    results = {}
    for name in names:
        cmd = [sys.executable, str(HERE / f"{name}.py"), *([] if args.full else QUICK[name])]
        print(f"running {name} …", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        results[name] = {"exit_status": proc.returncode, "wall_s": round(time.perf_counter() - t0, 1),
                         "result": last_json(proc.stdout)}
        if proc.returncode != 0:
            results[name]["error"] = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
    print(json_text(results, indent=2))


if __name__ == "__main__":
    main()
