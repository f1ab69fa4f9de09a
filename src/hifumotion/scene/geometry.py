"""The scene's solids as points (mm): the tissue's particles on a lattice or from a CSV, the bar's,
the spacing that gives a count of them, and where the bar first touches the tissue. Every path
(the particle framework, the fast path's voxels, the fitted model) places its solids with these."""

from __future__ import annotations

import math

import numpy as np

from hifumotion.errors import InputError
from hifumotion.scene.config import BarConfig, TankConfig, TissueConfig, read_particles_csv


def lattice(lo_m, hi_m, spacing_m: float) -> np.ndarray:
    """Points of a cubic lattice filling the box ``[lo, hi)`` (m), first point at lo + Δx/2."""
    lo = np.asarray(lo_m, float)
    hi = np.asarray(hi_m, float)
    axes = [lo[a] + spacing_m * (0.5 + np.arange(max(int(round((hi[a] - lo[a]) / spacing_m)), 0)))
            for a in range(3)]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=1)


def tissue_particles_mm(cfg: TissueConfig, tank: TankConfig, spacing_mm: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Tissue particle positions (mm, tank frame) and volumes (mm³)."""
    if cfg.shape == "particles":
        pts, vol = read_particles_csv(cfg.particles_csv)
        if vol is None:
            vol = np.full(len(pts), spacing_mm ** 3)
        lo = pts.min(0)
        hi = pts.max(0)
        if cfg.centre_mm is None:
            shift = np.array([tank.size_mm[0] / 2, 0.0, tank.size_mm[2] / 2]) - \
                np.array([(lo[0] + hi[0]) / 2, lo[1] - spacing_mm / 2, (lo[2] + hi[2]) / 2])
        else:
            shift = np.asarray(cfg.centre_mm) - (lo + hi) / 2
        return pts + shift, vol
    size = np.asarray(cfg.size_mm, float)
    centre = (np.array([tank.size_mm[0] / 2, size[1] / 2, tank.size_mm[2] / 2])
              if cfg.centre_mm is None else np.asarray(cfg.centre_mm, float))
    pts = lattice(centre - size / 2, centre + size / 2, spacing_mm)
    if cfg.shape == "ellipsoid":
        pts = pts[(((pts - centre) / (size / 2)) ** 2).sum(1) <= 1.0]
        volume = math.pi / 6 * float(np.prod(size))
    else:
        volume = float(np.prod(size))
    if len(pts) == 0:
        raise InputError(f"no particle fits in the tissue at spacing {spacing_mm} mm", "tissue.size_mm")
    return pts, np.full(len(pts), volume / len(pts))


def touching_tip(tissue_mm: np.ndarray, through_mm: np.ndarray, axis: np.ndarray, radius_mm: float,
                 spacing_mm: float) -> np.ndarray | None:
    """The bar's tip on the line through ``through_mm`` along the unit ``axis``, touching the
    tissue: one spacing (where the contact force of Eq. 18 begins) before the first tissue
    particle under the bar's end face; ``None`` when no particle is under it.

    A gap would let the force accelerate the bar freely and strike the tissue (its work
    F × gap turned into an impact), which a slow push does not do; a tip inside the tissue
    would start the push with a spurious compression."""
    rel = np.asarray(tissue_mm, float) - through_mm
    along = rel @ axis
    across = np.linalg.norm(rel - along[:, None] * axis, axis=1)
    under = across <= radius_mm
    if not under.any():
        return None
    return np.asarray(through_mm, float) + (along[under].min() - spacing_mm) * axis


def spacing_for_count(fill, spacing_mm: float, count: int, shrink: float = 0.99, tolerance: float = 1.0):
    """Shrink ``spacing_mm`` until ``fill(spacing)`` holds at least ``tolerance × count`` particles.

    A lattice misses a little of a curved surface, so the spacing that a volume and a count
    imply gives too few; ``fill`` returns the particles (any sized sequence, or a tuple
    whose first item is). Returns ``(spacing, fill(spacing))``."""
    def size(result):
        return len(result[0] if isinstance(result, tuple) else result)

    result = fill(spacing_mm)
    for _ in range(2000):
        if size(result) >= tolerance * count:
            return spacing_mm, result
        spacing_mm *= shrink
        result = fill(spacing_mm)
    raise InputError(f"no spacing gives {count} particles", "particles")


def bar_particles_mm(cfg: BarConfig, tissue_mm: np.ndarray, spacing_mm: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bar particles (mm), its unit axis and its tip (mm)."""
    axis = np.asarray(cfg.direction, float)
    axis /= np.linalg.norm(axis)
    if cfg.tip_mm is None:
        # touching the tissue, on the axis through its centre
        centre = tissue_mm.mean(0)
        tip = touching_tip(tissue_mm, centre, axis, cfg.radius_mm, spacing_mm)
        if tip is None:
            tip = centre + (((tissue_mm - centre) @ axis).min() - spacing_mm) * axis
    else:
        tip = np.asarray(cfg.tip_mm, float)
    r, length = cfg.radius_mm, cfg.length_mm
    span = max(r, length) + spacing_mm
    local = lattice([-span] * 3, [span] * 3, spacing_mm)
    helper = np.array([0.0, 1.0, 0.0]) if abs(axis[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    t = local @ np.stack([axis, e1, e2], axis=1)  # coordinates along (axis, e1, e2)
    keep = (t[:, 0] <= 0) & (t[:, 0] > -length) & (np.hypot(t[:, 1], t[:, 2]) <= r)
    t = t[keep]
    pts = tip + t[:, :1] * axis + t[:, 1:2] * e1 + t[:, 2:3] * e2
    return pts, axis, tip


__all__ = ["bar_particles_mm", "lattice", "spacing_for_count", "tissue_particles_mm", "touching_tip"]
