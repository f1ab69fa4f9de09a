"""B-mode images of the synthetic experiment: the probe, the planes, what echoes where.

Geometry (tank frame, mm, y up). As in an ultrasound-guided HIFU device the
imaging probe sits in the water *below* the pool's acoustically transparent
membrane floor and looks up, ``probe_standoff_mm`` beneath it; the bar
presses from above. Image rows are depth (upwards from the probe, y =
−standoff + row × pixel), columns lateral (x). The time series is one plane
z = z₀ through the tissue's centre and the bar's line of action; the sweep
is parallel planes z = z₀ + k × gap through the resting tissue.

Echoes (relative backscatter power) live on the scatterers in *material*
coordinates: tissue (with a smooth 3D texture, so neighbouring slices look
alike), the membrane floor, the steel bar, water; air above the water line
is silent. In the time series each tissue scatterer moves with the tissue's
in-plane displacement interpolated from the particles near the plane, the
bar's scatterers with the bar, so the speckle stays attached to the tissue
as it deforms (out-of-plane motion, which would decorrelate it, is not
modelled).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from hifumotion.experiment.config import ImagingConfig
from hifumotion.imaging.bmode import BModeImage, BModeOptions, Scatterers, Transducer, simulate_frame
from hifumotion.particles.kernels import kernel
from hifumotion.scene import Plane


@dataclass(frozen=True)
class Probe:
    """The imaging geometry: image grid and the planes' placement (mm)."""

    shape: tuple[int, int]
    pixel_mm: float
    x0_mm: float          # tank x of column 0
    y0_mm: float          # tank y of row 0 (the probe's face)
    z_frames_mm: float    # the time series' plane
    sweep_z_mm: np.ndarray

    def plane(self, z_mm: float) -> Plane:
        return Plane((self.x0_mm, self.y0_mm, float(z_mm)), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                     self.shape, self.pixel_mm)

    def to_tank(self, xz_image_mm: np.ndarray, z_mm: float) -> np.ndarray:
        """Tank positions (mm) of image points ``(lateral, depth)`` (mm) in plane z."""
        p = np.asarray(xz_image_mm, float)
        return np.column_stack([self.x0_mm + p[:, 0], self.y0_mm + p[:, 1], np.full(len(p), z_mm)])

    def as_dict(self) -> dict:
        return {"image_shape": list(self.shape), "pixel_mm": self.pixel_mm,
                "column_axis": [1.0, 0.0, 0.0], "row_axis": [0.0, 1.0, 0.0],
                "row0_col0_mm": [self.x0_mm, self.y0_mm],
                "frames_plane_z_mm": self.z_frames_mm, "sweep_z_mm": [float(z) for z in self.sweep_z_mm]}


def make_probe(cfg: ImagingConfig, tissue_mm: np.ndarray) -> Probe:
    """Centre the field of view on the resting tissue; sweep planes span it plus a margin."""
    lo, hi = tissue_mm.min(0), tissue_mm.max(0)
    centre = (lo + hi) / 2
    cols = int(round(cfg.width_mm / cfg.pixel_mm))
    rows = int(round(cfg.depth_mm / cfg.pixel_mm))
    z0 = float(tissue_mm[:, 2].mean())
    k_lo = int(np.floor((lo[2] - cfg.sweep_margin_mm - z0) / cfg.sweep_gap_mm))
    k_hi = int(np.ceil((hi[2] + cfg.sweep_margin_mm - z0) / cfg.sweep_gap_mm))
    sweep = z0 + cfg.sweep_gap_mm * np.arange(k_lo, k_hi + 1)
    return Probe((rows, cols), cfg.pixel_mm, float(centre[0] - cfg.width_mm / 2), -cfg.probe_standoff_mm,
                 z0, sweep)


def transducer(cfg: ImagingConfig, probe: Probe, tissue_mm: np.ndarray) -> Transducer:
    """The probe, focused at the tissue's centre depth."""
    focus = float(tissue_mm[:, 1].mean() - probe.y0_mm)
    return Transducer(center_frequency_mhz=cfg.center_frequency_mhz, axial_fwhm_mm=cfg.axial_fwhm_mm,
                      lateral_fwhm_mm=cfg.lateral_fwhm_mm, focus_depth_mm=focus,
                      dynamic_range_db=cfg.dynamic_range_db)


class Texture:
    """A smooth random field (mean 1, relative std ``amount``) over the tank, in 3D (mm)."""

    def __init__(self, lo_mm, hi_mm, amount: float, rng: np.random.Generator, cell_mm: float = 0.5,
                 scale_mm: float = 1.5):
        self.lo = np.asarray(lo_mm, float)
        self.cell = cell_mm
        shape = np.maximum(np.ceil((np.asarray(hi_mm, float) - self.lo) / cell_mm).astype(int) + 1, 2)
        noise = ndimage.gaussian_filter(rng.standard_normal(shape), scale_mm / cell_mm, mode="wrap")
        noise /= max(noise.std(), 1e-12)
        self.field = np.clip(1.0 + amount * noise, 0.05, None)

    def __call__(self, points_mm: np.ndarray) -> np.ndarray:
        idx = ((np.asarray(points_mm, float) - self.lo) / self.cell).T
        return ndimage.map_coordinates(self.field, idx, order=1, mode="nearest")


def bar_mask(probe: Probe, z_mm: float, tip_mm: np.ndarray, axis: np.ndarray, radius_mm: float,
             length_mm: float) -> np.ndarray:
    """Pixels of plane z inside the bar (a cylinder from its tip back along −axis)."""
    pts = probe.plane(z_mm).points_mm().reshape(-1, 3)
    d = pts - tip_mm
    along = d @ axis
    radial = np.linalg.norm(d - along[:, None] * axis, axis=1)
    inside = (along <= 0) & (along >= -length_mm) & (radial <= radius_mm)
    return inside.reshape(probe.shape)


class EchoMap:
    """Relative backscatter at material points of one plane (see the module docstring)."""

    def __init__(self, cfg: ImagingConfig, probe: Probe, z_mm: float, tissue: np.ndarray, bar: np.ndarray,
                 water_depth_mm: float, texture: Texture):
        self.cfg, self.probe, self.z = cfg, probe, z_mm
        self.tissue, self.bar, self.water_depth = tissue, bar, water_depth_mm
        self.texture = texture

    def labels(self, xz_mm: np.ndarray) -> np.ndarray:
        """0 water/air, 1 tissue, 2 bar, 3 floor, for material points ``(lateral, depth)`` mm."""
        p = self.probe
        col = np.clip(np.rint(xz_mm[:, 0] / p.pixel_mm).astype(int), 0, p.shape[1] - 1)
        row = np.clip(np.rint(xz_mm[:, 1] / p.pixel_mm).astype(int), 0, p.shape[0] - 1)
        lab = np.zeros(len(xz_mm), np.int8)
        y = p.y0_mm + xz_mm[:, 1]
        lab[np.abs(y) < 0.5 * max(self.cfg.axial_fwhm_mm, p.pixel_mm)] = 3
        lab[self.tissue[row, col]] = 1
        lab[self.bar[row, col]] = 2
        return lab

    def __call__(self, xz_mm: np.ndarray) -> np.ndarray:
        c = self.cfg
        lab = self.labels(xz_mm)
        y = self.probe.y0_mm + xz_mm[:, 1]
        echo = np.where(y <= self.water_depth, c.water_echogenicity, 0.0)
        echo[lab == 3] = c.floor_echogenicity
        t = lab == 1
        echo[t] = c.tissue_echogenicity * self.texture(self.probe.to_tank(xz_mm[t], self.z))
        echo[lab == 2] = c.bar_echogenicity
        return echo


class PlaneInterpolant:
    """The particles' in-plane displacement at fixed material points of one plane.

    Shepard interpolation from the particles within 2Δx of the plane, weighted by the SPH
    kernel of support 2Δx; a point beyond every support takes its nearest particle. The
    same map moves the speckle (:class:`MovingSpeckle`) and gives the true displacement
    a speckle tracker is scored against.
    """

    def __init__(self, rest_tissue_mm: np.ndarray, spacing_mm: float, points_tank_mm: np.ndarray, z_mm: float):
        h = 2.0 * spacing_mm
        self.near = np.flatnonzero(np.abs(rest_tissue_mm[:, 2] - z_mm) < h)
        self.rest_near = rest_tissue_mm[self.near]
        points = np.asarray(points_tank_mm, float).reshape(-1, 3)
        self.count = len(points)
        if len(self.near) and self.count:
            k = int(min(16, len(self.near)))
            dist, idx = cKDTree(self.rest_near).query(points, k=k)
            dist = np.atleast_2d(dist.reshape(len(points), -1))
            idx = np.atleast_2d(idx.reshape(len(points), -1))
            w = kernel(dist, h)
            w[w.sum(1) == 0, 0] = 1.0
            self.weights = w / w.sum(1, keepdims=True)
            self.neighbours = idx

    def __call__(self, tissue_mm: np.ndarray) -> np.ndarray:
        """In-plane displacement ``(N, 2)`` (mm; x, y of the tank) with the tissue at ``tissue_mm``."""
        if not (len(self.near) and self.count):
            return np.zeros((self.count, 2))
        disp = tissue_mm[self.near] - self.rest_near
        return (self.weights[:, :, None] * disp[self.neighbours]).sum(1)[:, :2]


class MovingSpeckle:
    """The time series' scatterers, displaced with the tissue and the bar frame by frame."""

    def __init__(self, echo: EchoMap, scatterers: Scatterers, rest_tissue_mm: np.ndarray, spacing_mm: float):
        self.echo = echo
        self.scatterers = scatterers
        lab = echo.labels(scatterers.positions_mm)
        self.tissue_idx = np.flatnonzero(lab == 1)
        self.bar_idx = np.flatnonzero(lab == 2)
        points = echo.probe.to_tank(scatterers.positions_mm[self.tissue_idx], echo.z)
        self.interpolant = PlaneInterpolant(rest_tissue_mm, spacing_mm, points, echo.z)

    def positions(self, tissue_mm: np.ndarray, bar_shift_mm: np.ndarray) -> np.ndarray:
        """Scatterer positions (lateral, depth mm) with the tissue at ``tissue_mm`` (all particles)."""
        pos = self.scatterers.positions_mm.copy()
        if len(self.tissue_idx):
            pos[self.tissue_idx] += self.interpolant(tissue_mm)   # plane axes: column = x, row = y
        pos[self.bar_idx] += np.asarray(bar_shift_mm, float)[:2]
        return pos


def render(echo: EchoMap, scatterers: Scatterers, positions: np.ndarray | None, probe: Probe,
           trans: Transducer, seed: int, target: np.ndarray) -> BModeImage:
    """One B-mode image of a plane; a soft specular echo on the tissue's probe-facing side."""
    return simulate_frame(echo, scatterers, positions, probe.shape, (probe.pixel_mm, probe.pixel_mm), trans,
                          BModeOptions(specular_gain=1.5, seed=seed), target)
