"""Make the twin that ships with the package (``src/hifumotion/data/demo_twin``) again.

It is the output of ``hifumotion experiment --preset slide_reverse --seed 0``, less the truth's
bulky records that no run reads (the finite elements' VTU files, the trajectory, the contour
tables): ``observed/`` whole; ``truth/`` with the true sections of every frame and sweep plane
(PNG and NIfTI), ``parameters.json``, ``motion.json``, ``bar_pose.csv`` and the re-runnable scene;
the experiment's ``run_info.json`` (its command, version and seed).

    python scripts/bundle_demo_twin.py                 # run the experiment (minutes), then bundle it
    python scripts/bundle_demo_twin.py --from DIR      # bundle an existing output of that command

Run it when the twin's generator or the preset changes (``tests/test_bundled_twin.py`` fails then).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = ROOT / "src" / "hifumotion" / "data" / "demo_twin"
TRUTH_FILES = ("parameters.json", "motion.json", "bar_pose.csv", "scene.toml", "blob_particles.csv",
               "frames.nii.gz", "sweep.nii.gz")
TRUTH_FOLDERS = ("frames", "sweep")


def main() -> None:
    sys.path.insert(0, str(ROOT / "src"))
    from hifumotion.experiment.stored import BUNDLED_PRESET, BUNDLED_SEED

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--from", dest="source", type=Path, help="an existing output of the experiment command")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="demo_twin_") as tmp:
        source = args.source
        if source is None:
            source = Path(tmp) / "twin"
            subprocess.run([sys.executable, "-m", "hifumotion", "experiment", "--preset", BUNDLED_PRESET,
                            "--seed", str(BUNDLED_SEED), "-o", str(source)], check=True)
        info = json.loads((source / "run_info.json").read_text())
        made = (info.get("command"), info.get("preset"), info.get("seed"))
        if made != ("experiment", BUNDLED_PRESET, BUNDLED_SEED):
            raise SystemExit(f"{source}: made by {made}; expected experiment, preset {BUNDLED_PRESET}, "
                             f"seed {BUNDLED_SEED}")
        staging = TARGET.with_name(TARGET.name + ".new")
        shutil.rmtree(staging, ignore_errors=True)
        shutil.copytree(source / "observed", staging / "observed")
        for name in TRUTH_FILES:
            (staging / "truth").mkdir(parents=True, exist_ok=True)
            shutil.copy2(source / "truth" / name, staging / "truth" / name)
        for name in TRUTH_FOLDERS:
            shutil.copytree(source / "truth" / name, staging / "truth" / name)
        shutil.copy2(source / "run_info.json", staging / "run_info.json")
        shutil.rmtree(TARGET, ignore_errors=True)
        staging.rename(TARGET)
    size = sum(p.stat().st_size for p in TARGET.rglob("*") if p.is_file())
    print(f"{TARGET}: {size / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
