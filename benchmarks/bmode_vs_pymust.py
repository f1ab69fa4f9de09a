"""Our B-mode simulator against an independent one: PyMUST (the MUST toolbox), as JSON.

The same medium in both: a 20 x 26 mm region of soft tissue with a
hypoechoic disc (radius 4 mm, backscatter power 0.3, i.e. -5.2 dB) at 25 mm
depth. PyMUST simulates a 128-element linear array (L11-5v, 7.6 MHz) with one
plane-wave transmit (``simus``), demodulates (``rf2iq``) and beamforms by
delay-and-sum (``dasmtx``); ours convolves the scatterers with its Gaussian
pulse-echo PSF at the same centre frequency. Compared: the speckle's
envelope mean/std in the background, each depth row normalised to its RMS (Rayleigh: 1.913), the inclusion's
contrast in dB (expected -5.2 dB), and seconds per frame.

    pip install pymust   # only for this comparison
    python benchmarks/bmode_vs_pymust.py [--scatterers 8000]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from hifumotion.io.writers import json_text

DEPTH0_M, WIDTH_M, DEPTH_M = 0.012, 0.02, 0.026
DISC_Z_M, DISC_R_M, DISC_POWER = 0.025, 0.004, 0.3


def statistics(envelope: np.ndarray, x_m: np.ndarray, z_m: np.ndarray) -> dict:
    """Speckle mean/std in the background and inclusion contrast, after dividing each depth row
    by its background RMS (so beam spreading and diffraction trends do not count as speckle)."""
    r = np.hypot(x_m, z_m - DISC_Z_M)
    inside = r < 0.8 * DISC_R_M
    background = (r > 1.5 * DISC_R_M) & (np.abs(x_m) < 0.8 * WIDTH_M / 2)
    row_rms = np.sqrt(np.nanmean(np.where(background, envelope**2, np.nan), axis=1, keepdims=True))
    envelope = envelope / np.where(np.isfinite(row_rms) & (row_rms > 0), row_rms, 1.0)
    env_bg = envelope[background]
    return {"background_mean_over_std": round(float(env_bg.mean() / env_bg.std()), 3),
            "inclusion_contrast_db": round(float(10 * np.log10(np.mean(envelope[inside] ** 2) / np.mean(env_bg**2))), 2)}


def run_pymust(n: int, seed: int) -> dict:
    import pymust

    param = pymust.getparam("L11-5v")
    rng = np.random.default_rng(seed)
    xs = rng.uniform(-WIDTH_M / 2, WIDTH_M / 2, n)
    zs = rng.uniform(DEPTH0_M - 0.002, DEPTH0_M + DEPTH_M, n)
    rc = rng.standard_normal(n) * np.where(np.hypot(xs, zs - DISC_Z_M) < DISC_R_M, np.sqrt(DISC_POWER), 1.0)
    t0 = time.perf_counter()
    txdel = pymust.txdelay(param, 0)
    rf, _ = pymust.simus(xs, zs, rc, txdel, param)
    iq = pymust.rf2iq(rf, param)
    x = np.linspace(-WIDTH_M / 2, WIDTH_M / 2, 128)
    z = np.linspace(DEPTH0_M, DEPTH0_M + DEPTH_M, 256)
    xx, zz = np.meshgrid(x, z)
    m = pymust.dasmtx(1j * np.array(iq.shape), xx, zz, txdel, param)
    env = np.abs((m @ iq.flatten(order="F")).reshape(xx.shape, order="F"))
    seconds = time.perf_counter() - t0
    return {"seconds_per_frame": round(seconds, 2), "center_frequency_mhz": param.fc / 1e6, **statistics(env, xx, zz)}


def run_ours(seed: int, f0_mhz: float) -> dict:
    from hifumotion.imaging import Scatterers, Transducer, simulate_frame

    spacing = (0.1, 0.1)  # mm
    shape = (int(DEPTH_M * 1e3 / spacing[0]), int(WIDTH_M * 1e3 / spacing[1]))
    tr = Transducer(center_frequency_mhz=f0_mhz, axial_fwhm_mm=0.3, lateral_fwhm_mm=0.6, attenuation_db_cm_mhz=0.0,
                    tgc_error=0.0, tgc_ripple_db=0.0, noise_db=-100.0, focus_depth_mm=13.0, rayleigh_length_mm=1e6)
    scat = Scatterers.uniform((shape[0] * spacing[0], shape[1] * spacing[1]), tr, seed)
    cx_mm, cz_mm = WIDTH_M * 1e3 / 2, (DISC_Z_M - DEPTH0_M) * 1e3

    def echo(p):
        return np.where(np.hypot(p[:, 0] - cx_mm, p[:, 1] - cz_mm) < DISC_R_M * 1e3, DISC_POWER, 1.0)

    simulate_frame(echo, scat, None, shape, spacing, tr)  # compile
    t0 = time.perf_counter()
    frame = simulate_frame(echo, scat, None, shape, spacing, tr)
    seconds = time.perf_counter() - t0
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    x_m = (cols * spacing[1] - cx_mm) / 1e3
    z_m = rows * spacing[0] / 1e3 + DEPTH0_M
    return {"seconds_per_frame": round(seconds, 4), "center_frequency_mhz": f0_mhz, **statistics(frame.envelope, x_m, z_m)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scatterers", type=int, default=8000, help="PyMUST scatterers (its run time grows with them)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="a run of a few minutes: 4,000 scatterers")
    args = ap.parse_args(argv)
    if args.quick:
        args.scatterers = min(args.scatterers, 4000)
    try:
        import pymust  # noqa: F401
    except ImportError:
        print(json_text({"skipped": "pymust is not installed; pip install pymust to run this comparison"}, indent=None))
        return 0
    pm = run_pymust(args.scatterers, args.seed)
    ours = run_ours(args.seed, pm["center_frequency_mhz"])
    out = {"expected": {"background_mean_over_std": 1.913, "inclusion_contrast_db": round(10 * np.log10(DISC_POWER), 2)},
           "pymust": pm, "hifumotion": ours,
           "speedup": round(pm["seconds_per_frame"] / max(ours["seconds_per_frame"], 1e-9), 1)}
    print(json_text(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
