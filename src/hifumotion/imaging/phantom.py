"""Segmentation phantoms: a target of known shape in simulated B-mode, laid out like ``../shared/data``.

A phantom is a target (an ellipse, or an irregular blob from low-order
harmonic perturbations of an ellipse) in a background tissue with
low-frequency echogenicity variation and a few bright and dark structures,
imaged by :mod:`hifumotion.imaging.bmode`. Presets go from easy (bright
contrast, little unevenness) to hard (low contrast, strong unevenness and
distracting structures, where a global Chan-Vese model fails and a
localized model can still succeed).

The initial contours follow ``../shared/data/README.md``: the expert
region's moment ellipse shrunk to 70 % of its axes, shifted and turned a
little; and 6 points in boundary order 15–30 % of the way to the centre,
with 2 px of jitter.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from hifumotion.errors import InputError
from hifumotion.imaging.bmode import BModeOptions, Scatterers, Transducer, echogenicity_sampler, simulate_frame


@dataclass(frozen=True)
class Preset:
    """How hard a phantom is.

    Attributes
    ----------
    target_db
        Echogenicity of the target relative to the background mean (dB; negative = hypoechoic).
    background_variation_db
        Amplitude of the smooth random echogenicity variation of the background (dB).
    structures
        Number of bright/dark distracting structures (layers, vessels) in the background.
    noise_db, tgc_error, tgc_ripple_db
        Passed to the :class:`~hifumotion.imaging.bmode.Transducer`.
    shadow_db_per_mm, specular_gain
        Passed to :class:`~hifumotion.imaging.bmode.BModeOptions`.
    """

    target_db: float
    background_variation_db: float
    structures: int
    noise_db: float
    tgc_error: float
    tgc_ripple_db: float
    shadow_db_per_mm: float
    specular_gain: float


PRESETS: dict[str, Preset] = {
    "easy": Preset(-12.0, 1.0, 0, -50.0, 0.05, 0.5, 0.0, 0.0),
    "medium": Preset(-7.0, 2.5, 2, -40.0, 0.15, 2.0, 0.1, 2.0),
    "hard": Preset(-4.0, 4.0, 4, -30.0, 0.35, 5.0, 0.25, 3.0),
}


def target_mask(shape: tuple[int, int], kind: str, rng: np.random.Generator, size_fraction: float = 0.28) -> np.ndarray:
    """A target mask: ``"ellipse"`` or ``"irregular"`` (an ellipse with random 2nd–5th harmonics).

    The target's mean radius is ``size_fraction`` of the image's smaller side,
    centred near the middle, randomly elongated and turned.
    """
    if kind not in ("ellipse", "irregular"):
        raise InputError(f"shape must be 'ellipse' or 'irregular', got {kind!r}", "shape")
    h, w = shape
    r = size_fraction * min(h, w)
    cy, cx = h * rng.uniform(0.45, 0.55), w * rng.uniform(0.45, 0.55)
    ratio = rng.uniform(0.7, 0.95)
    a, b = r / np.sqrt(ratio), r * np.sqrt(ratio)
    angle = rng.uniform(0, np.pi)
    rows, cols = np.mgrid[0:h, 0:w]
    u = (cols - cx) * np.cos(angle) + (rows - cy) * np.sin(angle)
    v = -(cols - cx) * np.sin(angle) + (rows - cy) * np.cos(angle)
    theta = np.arctan2(v / b, u / a)
    rho = np.hypot(u / a, v / b)
    boundary = np.ones_like(theta)
    if kind == "irregular":
        for k in range(2, 6):
            boundary += rng.uniform(0.03, 0.12) / (k - 1) ** 0.5 * np.cos(k * theta + rng.uniform(0, 2 * np.pi))
    return rho < boundary


def initial_contours(mask: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """The rough starts of ``../shared/data/README.md`` for an expert mask (pixel coordinates)."""
    rows, cols = np.nonzero(mask)
    cy, cx = rows.mean(), cols.mean()
    cov = np.cov(np.vstack([cols - cx, rows - cy]))
    evals, evecs = np.linalg.eigh(cov)
    a, b = 2.0 * np.sqrt(evals[1]), 2.0 * np.sqrt(evals[0])
    angle = np.degrees(np.arctan2(evecs[1, 1], evecs[0, 1]))
    ellipse = {"cx": float(cx + rng.uniform(-0.05, 0.05) * a), "cy": float(cy + rng.uniform(-0.05, 0.05) * b),
               "a": float(0.7 * a), "b": float(0.7 * b), "angle_deg": float(angle + rng.uniform(-10, 10))}
    from hifumotion.contour import Contour

    boundary = Contour.from_mask(mask).points_px
    picks = (np.arange(6) * len(boundary) / 6 + rng.uniform(0, len(boundary) / 6)).astype(int) % len(boundary)
    pts = []
    for p in boundary[np.sort(picks)]:
        f = rng.uniform(0.15, 0.30)
        q = p + f * (np.array([cx, cy]) - p) + rng.normal(0, 2.0, 2)
        pts.append([float(q[0]), float(q[1])])
    return {"ellipse": ellipse, "points": pts}


def background_echogenicity(shape: tuple[int, int], preset: Preset, rng: np.random.Generator) -> np.ndarray:
    """Background tissue: smooth random variation plus bright layers and dark round structures."""
    h, w = shape
    field = ndimage.gaussian_filter(rng.standard_normal(shape), min(h, w) / 8.0)
    field = field / (np.abs(field).max() + 1e-12) * preset.background_variation_db
    rows, cols = np.mgrid[0:h, 0:w]
    for k in range(preset.structures):
        if k % 2 == 0:  # a bright layer (fascia), slightly tilted, near the top or bottom
            z0 = h * (rng.uniform(0.06, 0.18) if k % 4 == 0 else rng.uniform(0.82, 0.94))
            slope = rng.uniform(-0.15, 0.15)
            field += 8.0 * np.exp(-0.5 * ((rows - z0 - slope * (cols - w / 2)) / (0.012 * h)) ** 2)
        else:  # a dark round structure (vessel) near a side
            cz, cx = h * rng.uniform(0.2, 0.8), w * (rng.uniform(0.05, 0.15) if k % 4 == 1 else rng.uniform(0.85, 0.95))
            rad = 0.07 * min(h, w)
            field -= 15.0 * (np.hypot(rows - cz, cols - cx) < rad)
    return 10 ** (field / 10.0)


def make_phantom(shape_kind: str = "ellipse", preset: str = "medium", seed: int = 0,
                 size_px: tuple[int, int] = (256, 256), spacing_mm: float = 0.15) -> dict[str, Any]:
    """Simulate one phantom: ``{"image": uint8, "mask": bool, "init": {...}, "spacing_mm": ...}``."""
    if preset not in PRESETS:
        raise InputError(f"preset must be one of {', '.join(PRESETS)}, got {preset!r}", "preset")
    p = PRESETS[preset]
    rng = np.random.default_rng(seed)
    mask = target_mask(size_px, shape_kind, rng)
    echo = background_echogenicity(size_px, p, rng)
    echo = np.where(mask, echo.mean() * 10 ** (p.target_db / 10.0) * (echo / echo.mean()) ** 0.3, echo)
    transducer = Transducer(noise_db=p.noise_db, tgc_error=p.tgc_error, tgc_ripple_db=p.tgc_ripple_db,
                            focus_depth_mm=0.55 * size_px[0] * spacing_mm)
    extent = (size_px[0] * spacing_mm, size_px[1] * spacing_mm)
    scat = Scatterers.uniform(extent, transducer, rng)
    lookup = echogenicity_sampler(echo, (spacing_mm, spacing_mm))
    frame = simulate_frame(lookup, scat, None, size_px, (spacing_mm, spacing_mm), transducer,
                           BModeOptions(p.shadow_db_per_mm, p.specular_gain, int(rng.integers(2**31))), mask)
    return {"image": frame.image, "mask": mask, "init": initial_contours(mask, rng), "spacing_mm": spacing_mm,
            "preset": asdict(p), "transducer": asdict(transducer)}


def write_phantom(folder: str | Path, phantom: dict[str, Any], name: str = "phantom.png") -> Path:
    """Write ``folder/images/NAME``, ``folder/masks/NAME`` (0/255) and ``folder/init.json``."""
    import imageio.v3 as iio

    from hifumotion.io import atomic_path, write_json, write_mask_png

    folder = Path(folder)
    with atomic_path(folder / "images" / name) as tmp:
        iio.imwrite(tmp, phantom["image"], extension=".png")
    write_mask_png(folder / "masks" / name, phantom["mask"])
    init_path = folder / "init.json"
    entries = json.loads(init_path.read_text()) if init_path.is_file() else {}
    entries[name] = phantom["init"]
    write_json(init_path, entries)
    return folder
