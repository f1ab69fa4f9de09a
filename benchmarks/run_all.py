"""Run every benchmark, one after the other (never two at once: 2 cores), and print one JSON.

    python benchmarks/run_all.py                 # each with --quick (a few minutes each)
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

#: The benchmarks a run makes, in order; each takes ``--quick`` (a run of a few minutes). Those that
#: need a twin folder of their own (bench_forward_truth, bench_twin_truth, bench_truth_convergence)
#: are run by hand.
BENCHMARKS = ["bench_tracking", "bench_real_tracking", "bench_observation", "bench_bmode", "bench_particles",
              "bench_segmentation", "bench_sweep", "bench_twin", "bench_convergence", "bench_estimation",
              "bench_online", "bench_fe_reference", "bench_sphere_between_plates", "bmode_vs_pymust"]


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
    names = args.only or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        sys.exit(f"error: unknown benchmark(s) {unknown}; choose from {', '.join(BENCHMARKS)}")
    results = {}
    for name in names:
        cmd = [sys.executable, str(HERE / f"{name}.py"), *([] if args.full else ["--quick"])]
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
