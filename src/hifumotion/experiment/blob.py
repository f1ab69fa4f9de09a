"""A seeded irregular tissue sample: a lumpy ellipsoid with a flat underside.

A cut piece of tissue (the paper's cow tissue) is roughly ellipsoidal, lumpy,
and rests on a flat cut face. The body is star-shaped about its centre: a
point ``p`` is inside when

    |q| ≤ 1 + ε f(q/|q|),   q = (p − c) / a,

``a`` the semi-axes (mm), ``ε`` the irregularity and ``f`` a smooth random
field on the unit sphere — a sum of ``lobes`` plane waves ``cos(k n·d + φ)``
with random directions ``n``, wavenumbers ``k`` ∈ [1.5, 3] and phases,
scaled to ``max |f| = 1`` — and above the cut plane ``y ≥ y_cut``, so that
the sample lies on its cut face instead of rocking on a point. Lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Blob:
    """The sample's shape (mm): semi-axes, lumps and the flat cut (see the module docstring).

    Attributes
    ----------
    semi_axes_mm
        Semi-axes ``a`` (x, y up, z) of the underlying ellipsoid (mm).
    directions, wavenumbers, phases, amplitudes
        The plane waves of ``f`` (unit vectors, rad per unit radius, rad, weights).
    irregularity
        ε: the relative height of the lumps.
    cut_y
        The cut plane's height in units of the y semi-axis (−1 … 1; −1: no cut).
    """

    semi_axes_mm: tuple[float, float, float]
    directions: np.ndarray
    wavenumbers: np.ndarray
    phases: np.ndarray
    amplitudes: np.ndarray
    irregularity: float
    cut_y: float

    @classmethod
    def random(cls, size_mm: tuple[float, float, float], irregularity: float, lobes: int,
               bottom_cut: float, seed: int) -> "Blob":
        """A blob whose bounding box is about ``size_mm`` (x, height, z) after the cut.

        ``bottom_cut`` is the fraction of the ellipsoid's height cut off flat.
        """
        rng = np.random.default_rng(seed)
        n = rng.standard_normal((max(lobes, 1), 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        k = rng.uniform(1.5, 3.0, len(n))
        phi = rng.uniform(0.0, 2 * np.pi, len(n))
        w = rng.uniform(0.5, 1.0, len(n))
        # the height left after cutting a fraction of it must be size_mm[1]
        sx, sy, sz = (float(v) for v in size_mm)
        ay = sy / (2.0 * (1.0 - bottom_cut))
        blob = cls((sx / 2, ay, sz / 2), n, k, phi, np.ones(len(n)), float(irregularity),
                   -1.0 + 2.0 * bottom_cut)
        # normalise the field so that its largest value on the sphere is 1
        d = _fibonacci_sphere(4000)
        peak = np.abs(blob._field(d, w)).max()
        return cls(blob.semi_axes_mm, n, k, phi, w / max(peak, 1e-12), float(irregularity), blob.cut_y)

    def _field(self, unit: np.ndarray, amplitudes: np.ndarray | None = None) -> np.ndarray:
        a = self.amplitudes if amplitudes is None else amplitudes
        return (a * np.cos(self.wavenumbers * (unit @ self.directions.T) + self.phases)).sum(-1)

    def inside(self, points_mm: np.ndarray) -> np.ndarray:
        """Whether points (mm, relative to the ellipsoid's centre) are inside the sample."""
        q = np.asarray(points_mm, float) / np.asarray(self.semi_axes_mm)
        r = np.linalg.norm(q, axis=-1)
        unit = q / np.maximum(r, 1e-12)[..., None]
        return (r <= 1.0 + self.irregularity * self._field(unit)) & (q[..., 1] >= self.cut_y)

    def offset_mm(self) -> np.ndarray:
        """The shift from the blob's own frame (ellipsoid centre at 0) to the resting frame
        (cut face at y = 0, x = z = 0 through the ellipsoid's centre), mm."""
        return np.array([0.0, -self.cut_y * self.semi_axes_mm[1], 0.0])

    def particles(self, spacing_mm: float) -> np.ndarray:
        """Lattice points (mm, resting frame: see :meth:`offset_mm`) inside the sample.

        The lattice is fixed to the sample, not to its sampled points: columns at
        x, z = (k + ½) Δx about the centre, layers from half a spacing above the cut face.
        So every resolution puts the same body in the same place."""
        a = np.asarray(self.semi_axes_mm) * (1.0 + self.irregularity)
        half = spacing_mm / 2
        xs = np.arange(-np.ceil(a[0] / spacing_mm), np.ceil(a[0] / spacing_mm)) * spacing_mm + half
        zs = np.arange(-np.ceil(a[2] / spacing_mm), np.ceil(a[2] / spacing_mm)) * spacing_mm + half
        y0 = self.cut_y * self.semi_axes_mm[1]
        ys = y0 + half + np.arange(int(np.ceil((a[1] - y0) / spacing_mm)) + 1) * spacing_mm
        grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)
        return grid[self.inside(grid)] + self.offset_mm()

    def surface(self, resolution_mm: float = 0.25):
        """The sample's closed surface (``trimesh.Trimesh``, mm, resting frame like
        :meth:`particles`): marching cubes of :meth:`inside` on a grid of ``resolution_mm``."""
        import trimesh
        from skimage.measure import marching_cubes

        a = np.asarray(self.semi_axes_mm, float) * (1.0 + self.irregularity) + 2 * resolution_mm
        axes = [np.arange(-h, h + resolution_mm, resolution_mm) for h in a]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        inside = self.inside(grid.reshape(-1, 3)).reshape(grid.shape[:3]).astype(float)
        verts, faces, *_ = marching_cubes(np.pad(inside, 1), 0.5, spacing=(resolution_mm,) * 3)
        verts = verts - resolution_mm + np.array([ax[0] for ax in axes])
        return trimesh.Trimesh(verts + self.offset_mm(), faces[:, ::-1], process=True)

    def star_surface(self, subdivisions: int = 4):
        """The sample's closed surface (``trimesh.Trimesh``, mm, resting frame) as the star
        body's radial graph over an icosphere: vertex d at a ⊙ d (1 + ε f(d)); the points
        below the cut are lowered onto it along y (the body shrinks towards its base, so
        they land inside the cut's section). Smooth and coarse, for a finite-element mesh
        (:meth:`surface` is the fine marching-cubes one)."""
        import trimesh

        sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
        d = np.asarray(sphere.vertices, float)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        q = d * (1.0 + self.irregularity * self._field(d))[:, None]
        q[:, 1] = np.maximum(q[:, 1], self.cut_y)
        verts = q * np.asarray(self.semi_axes_mm)
        return trimesh.Trimesh(verts + self.offset_mm(), np.asarray(sphere.faces), process=True)

    def volume_mm3(self, samples: int = 400_000, seed: int = 0) -> float:
        """Volume (mm³) by Monte Carlo over the bounding box (±0.3 % at the default samples)."""
        rng = np.random.default_rng(seed)
        a = np.asarray(self.semi_axes_mm) * (1.0 + self.irregularity)
        p = rng.uniform(-a, a, (samples, 3))
        return float(self.inside(p).mean() * np.prod(2 * a))


def _fibonacci_sphere(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5 ** 0.5) * k
    return np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
