"""3D reconstruction against shapes known on paper: an ellipsoid and a star-shaped blob,
sliced every 1 and 2 mm."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from hifumotion.errors import InputError
from hifumotion.reconstruction import reconstruct

SPACING = 0.2  # mm, in-plane
H, W = 130, 150
ROWS, COLS = np.mgrid[0:H, 0:W]
X, Y = COLS * SPACING - 15.0, ROWS * SPACING - 13.0  # mm, centred


def ellipsoid(a=12.0, b=9.0, c=7.0):
    inside = lambda x, y, z: (x / a) ** 2 + (y / b) ** 2 + (z / c) ** 2 <= 1.0  # noqa: E731
    volume = 4.0 / 3.0 * np.pi * a * b * c
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 400), np.linspace(0, np.pi, 200))
    surface = np.column_stack([(a * np.cos(u) * np.sin(v)).ravel(), (b * np.sin(u) * np.sin(v)).ravel(),
                               (c * np.cos(v)).ravel()])
    return inside, volume, surface, c


def blob(seed=7, radius=8.0):
    """A star-shaped body r(θ, φ) = R (1 + Σ a_k cos(m θ + p) sin(n φ)); volume ∫∫ r³/3 dΩ by quadrature."""
    rng = np.random.default_rng(seed)
    terms = [(rng.uniform(0.04, 0.1), m, n, rng.uniform(0, 2 * np.pi)) for m, n in ((2, 1), (3, 2), (1, 3))]

    def r_of(theta, phi):
        return radius * (1 + sum(a * np.cos(m * theta + p) * np.sin(n * phi) for a, m, n, p in terms))

    def inside(x, y, z):
        rr = np.sqrt(x * x + y * y + z * z)
        theta = np.arctan2(y, x)
        phi = np.arccos(np.clip(z / np.maximum(rr, 1e-12), -1, 1))
        return rr <= r_of(theta, phi)

    th, ph = np.meshgrid(np.linspace(0, 2 * np.pi, 1601)[:-1], np.linspace(0, np.pi, 801))
    rr = r_of(th, ph)
    trapezoid = getattr(np, "trapezoid", None) or np.trapz
    volume = float(trapezoid((rr**3 / 3.0 * np.sin(ph)).sum(axis=1) * (2 * np.pi / 1600), ph[:, 0]))
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 400), np.linspace(0, np.pi, 200))
    rs = r_of(u, v)
    surface = np.column_stack([(rs * np.cos(u) * np.sin(v)).ravel(), (rs * np.sin(u) * np.sin(v)).ravel(),
                               (rs * np.cos(v)).ravel()])
    return inside, volume, surface, radius * 1.3


def slices(inside, half_height, gap, offset=0.37):
    zs = np.arange(-half_height - gap + offset, half_height + gap, gap)
    masks = np.stack([inside(X, Y, z) for z in zs])
    keep = masks.reshape(len(zs), -1).any(axis=1)
    return masks[keep], zs[keep]


def symmetric_hausdorff(vertices, surface):
    d1 = cKDTree(surface).query(vertices)[0].max()
    d2 = cKDTree(vertices).query(surface)[0].max()
    return max(d1, d2)


@pytest.mark.parametrize("shape", ["ellipsoid", "blob"])
@pytest.mark.parametrize("gap", [1.0, 2.0])
def test_volume_and_surface_match_the_analytic_shape(shape, gap):
    inside, volume, surface, half = ellipsoid() if shape == "ellipsoid" else blob()
    masks, zs = slices(inside, half, gap)
    rec = reconstruct(masks, SPACING, zs)
    assert rec.volume_mm3 == pytest.approx(volume, rel=0.02)
    # the mesh sits in the frame of the pixel grid: shift the analytic surface into it
    surface = surface + np.array([15.0, 13.0, 0.0])
    assert symmetric_hausdorff(rec.mesh.vertices, surface) <= gap
    assert rec.mesh.is_watertight and rec.mesh.is_winding_consistent and rec.mesh.volume > 0


def test_particles_fill_the_volume():
    inside, volume, _, half = ellipsoid()
    masks, zs = slices(inside, half, 1.0)
    rec = reconstruct(masks, SPACING, zs)
    dx = 0.8
    p = rec.particles(dx)
    assert len(p) == pytest.approx(rec.volume_mm3 / dx**3, rel=0.02)
    assert p.volume_mm3.sum() == pytest.approx(rec.volume_mm3, rel=0.01)
    assert p.volume_mm3.sum() == pytest.approx(volume, rel=0.02)
    assert 0 < p.surface.sum() < len(p)
    # surface particles lie near the surface, interior ones deeper
    depth = rec.inside(p.positions_mm)
    assert depth[p.surface].mean() < depth[~p.surface].mean()


def test_non_uniform_slice_positions():
    inside, volume, _, half = ellipsoid()
    zs = np.sort(np.concatenate([np.arange(-6.8, 0, 0.8), np.arange(0.3, 7, 1.6)]))
    masks = np.stack([inside(X, Y, z) for z in zs])
    rec = reconstruct(masks, SPACING, zs[::-1][::-1])
    assert rec.volume_mm3 == pytest.approx(volume, rel=0.02)


def test_empty_end_slices_and_a_spurious_component():
    inside, volume, _, half = ellipsoid()
    masks, zs = slices(inside, half, 1.0)
    masks = np.concatenate([np.zeros_like(masks[:2]), masks, np.zeros_like(masks[:1])])
    zs = np.concatenate([zs[0] - np.array([2.0, 1.0]), zs, [zs[-1] + 1.0]])
    k = len(zs) // 2
    masks[k, 5:12, 5:12] = True  # a speck far from the tissue in one slice
    rec = reconstruct(masks, SPACING, zs)
    assert any("components" in n for n in rec.notes) and any("end slices" in n for n in rec.notes)
    assert rec.volume_mm3 == pytest.approx(volume, rel=0.02)


@pytest.mark.parametrize("offset_mm", [0.5, 0.07])
def test_boundary_offset_moves_every_slice_inwards_in_plane(offset_mm):
    """Slices of a sphere of radius R, each boundary moved inwards in its plane by δ: the body
    whose slice at z has radius sqrt(R² − z²) − δ, volume ∫ π (sqrt(R² − z²) − δ)² dz (quadrature).
    0.07 mm is a third of a pixel, which eroding the masks cannot express."""
    radius = 8.0
    inside = lambda x, y, z: x * x + y * y + z * z <= radius**2  # noqa: E731
    masks, zs = slices(inside, radius, 1.0)
    z = np.linspace(-radius, radius, 200001)
    r = np.clip(np.sqrt(radius**2 - z**2) - offset_mm, 0, None)
    trapezoid = getattr(np, "trapezoid", None) or np.trapz
    expected = float(trapezoid(np.pi * r**2, z))
    plain = reconstruct(masks, SPACING, zs).volume_mm3
    moved = reconstruct(masks, SPACING, zs, boundary_offset_mm=offset_mm).volume_mm3
    assert moved == pytest.approx(expected, rel=0.02)
    assert plain - moved == pytest.approx(4 / 3 * np.pi * radius**3 - expected, rel=0.15)


def test_bad_sweeps_are_clear_errors():
    inside, _, _, half = ellipsoid()
    masks, zs = slices(inside, half, 1.0)
    with pytest.raises(InputError, match="only one slice"):
        reconstruct(masks[3:4], SPACING, zs[3:4])
    with pytest.raises(InputError, match="every slice is empty"):
        reconstruct(np.zeros_like(masks), SPACING, zs)
    with pytest.raises(InputError, match="share one position"):
        reconstruct(masks[:3], SPACING, [0.0, 1.0, 1.0])
    with pytest.raises(InputError, match="slice positions"):
        reconstruct(masks, SPACING, zs[:-1])
    with pytest.raises(InputError, match="boundary offset"):
        reconstruct(masks, SPACING, zs, boundary_offset_mm=50.0)
