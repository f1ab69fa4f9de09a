"""Cross-sections of the simulated tissue in a plane: what an ultrasound frame sees.

The tissue's indicator is the SPH colour field (Eq. 9 with A ≡ 1),
``c(q) = Σ_i v_i W(|q − x_i|, h_s)``, which is ≈ 1 inside the particle cloud
and falls to 0 across its surface; the section is ``c ≥ ½`` on a grid in the
plane, and its contour is the ½ level line (sub-pixel, marching squares).
``h_s`` is twice the particle spacing, so the surface sits half a spacing out
from the outer particles, where the lattice cells of the reconstruction end.

When the body's rest shape is known exactly (a synthetic sample),
:func:`mapped_section` gives its section without the particles' staircase:
a pixel q is inside when its material point ``X(q) = q − u(q)`` is inside the
rest shape, ``u`` the particles' displacement interpolated at q.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from hifumotion.particles.kernels import cubic_w
from hifumotion.scene.plane import Plane


@njit(cache=True, parallel=True)
def _splat(pix_u, pix_v, normal_d, values, h, rows, cols, pixel, out):
    """``out[r, c, k] += Σ_i W(|q_rc − x_i|, h) values[i, k]`` over the particles near the plane."""
    n = pix_u.shape[0]
    m = values.shape[1]
    # rows are independent: parallel over rows, each scanning the particles near it
    for r in prange(rows):
        y = r * pixel
        for i in range(n):
            dz = normal_d[i]
            dy = pix_v[i] - y
            rr = dz * dz + dy * dy
            if rr >= h * h:
                continue
            reach = math.sqrt(h * h - rr)
            c0 = max(int(math.ceil((pix_u[i] - reach) / pixel)), 0)
            c1 = min(int(math.floor((pix_u[i] + reach) / pixel)), cols - 1)
            for c in range(c0, c1 + 1):
                dx = pix_u[i] - c * pixel
                w = cubic_w(math.sqrt(rr + dx * dx), h)
                for k in range(m):
                    out[r, c, k] += w * values[i, k]


def _plane_splat(positions_mm: np.ndarray, values: np.ndarray, h: float, plane: Plane) -> np.ndarray:
    """:func:`_splat` of ``values`` ``(N, m)`` at the particles ``positions_mm`` onto ``plane``: ``(rows, cols, m)``."""
    d = np.asarray(positions_mm, float) - np.asarray(plane.origin_mm, float)
    u, v = np.asarray(plane.u, float), np.asarray(plane.v, float)
    normal = np.cross(u, v)
    near = np.abs(d @ normal) < h
    out = np.zeros((*plane.shape, values.shape[1]))
    if near.any():
        _splat(np.ascontiguousarray(d[near] @ u), np.ascontiguousarray(d[near] @ v),
               np.ascontiguousarray(d[near] @ normal), np.ascontiguousarray(values[near], dtype=np.float64), h,
               plane.shape[0], plane.shape[1], float(plane.pixel_mm), out)
    return out


def plane_displacement(positions_mm: np.ndarray, rest_mm: np.ndarray, spacing_mm: float, plane: Plane,
                       smoothing_factor: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`displacement_at` at every pixel centre of ``plane``: ``u`` ``(rows, cols, 3)`` (mm) and
    ``covered`` ``(rows, cols)``.

    The same Shepard interpolation (cubic-kernel weights of support ``smoothing_factor ×
    spacing_mm``), every particle within the support counted, summed by splatting each
    particle near the plane onto the pixels it reaches instead of searching a tree per
    pixel: the image's empty pixels cost nothing.
    """
    x = np.asarray(positions_mm, float)
    disp = x - np.asarray(rest_mm, float)
    h = smoothing_factor * float(spacing_mm)
    sums = _plane_splat(x, np.concatenate([np.ones((len(x), 1)), disp], axis=1), h, plane)
    weight, moved = sums[..., 0], sums[..., 1:]
    covered = weight > 0
    moved[covered] /= weight[covered][:, None]
    return moved, covered


@dataclass
class Section:
    """A cross-section: ``mask`` (rows, cols) bool, ``colour`` field, contours in px and mm."""

    mask: np.ndarray
    colour: np.ndarray
    contour_px: np.ndarray
    contour_mm: np.ndarray
    plane: Plane

    @property
    def area_mm2(self) -> float:
        return float(self.mask.sum()) * self.plane.pixel_mm ** 2


def section(positions_mm: np.ndarray, volumes_mm3: np.ndarray, spacing_mm: float, plane: Plane,
            smoothing_factor: float = 2.0) -> Section:
    """The tissue's cross-section in ``plane`` from its particles (positions in mm).

    The contour is the longest ½ level line of the colour field, as ``(N, 2)``
    ``(x, y)`` pixel coordinates and as in-plane mm; an empty section gives
    empty contours.
    """
    from skimage import measure

    x = np.asarray(positions_mm, float)
    vol = np.asarray(volumes_mm3, float)
    h = smoothing_factor * float(spacing_mm)
    colour = _plane_splat(x, vol[:, None], h, plane)[..., 0]
    mask = colour >= 0.5
    contours = measure.find_contours(colour, 0.5) if mask.any() else []
    if contours:
        best = max(contours, key=len)
        contour_px = best[:, ::-1].copy()  # (row, col) → (x, y)
    else:
        contour_px = np.zeros((0, 2))
    return Section(mask, colour, contour_px, contour_px * plane.pixel_mm, plane)


def displacement_at(points_mm: np.ndarray, positions_mm: np.ndarray, rest_mm: np.ndarray, spacing_mm: float,
                    smoothing_factor: float = 2.0, neighbours: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """The particles' displacement ``u = x − X`` (mm) at points fixed in space, and where it is known.

    Shepard interpolation over the particles *now* within ``smoothing_factor × spacing_mm``
    of each point (cubic-kernel weights): the displacement of the material that is at the
    point now — the inverse map :func:`mapped_section` and a predicted mask need. Exact for
    translations, for an affine motion to the weights' centring error. For where given
    material points went, :func:`material_displacement`. Returns
    ``u`` ``(P, 3)`` and ``covered`` ``(P,)`` (a particle lies within the support; ``u``
    is 0 elsewhere).
    """
    from scipy.spatial import cKDTree

    from hifumotion.particles.kernels import kernel

    x = np.asarray(positions_mm, float)
    q = np.asarray(points_mm, float).reshape(-1, 3)
    disp = x - np.asarray(rest_mm, float)
    h = smoothing_factor * float(spacing_mm)
    u = np.zeros((len(q), 3))
    lo, hi = q.min(0) - h, q.max(0) + h
    near = np.all((x >= lo) & (x <= hi), axis=1)  # only particles that can reach a point
    if not near.any():
        return u, np.zeros(len(q), bool)
    tree = cKDTree(x[near])
    dist, idx = tree.query(q, k=min(neighbours, int(near.sum())), distance_upper_bound=h)
    dist = dist.reshape(len(q), -1)
    idx = idx.reshape(len(q), -1)
    found = np.isfinite(dist)
    w = np.where(found, kernel(np.where(found, dist, h), h), 0.0)
    total = w.sum(1)
    covered = total > 0
    d_near = disp[near]
    safe = np.where(found, idx, 0)
    u[covered] = (w[covered, :, None] * d_near[safe[covered]]).sum(1) / total[covered, None]
    return u, covered


def material_weights(points_mm: np.ndarray, rest_mm: np.ndarray, spacing_mm: float,
                     smoothing_factor: float = 2.0, neighbours: int = 32):
    """The displacement of *material* points as a linear map of the particles' displacements.

    ``points_mm`` ``(P, 3)`` are material points given where they are in the configuration
    ``rest_mm`` (a frame-0 contour on the frame-0 particles, say). Returns ``(Φ, covered)``:
    ``Φ`` a sparse ``(P, N)`` matrix with ``u(X_p) = Σ_j Φ_pj (x_j − X_j)`` for any later
    positions ``x``, and ``covered`` ``(P,)`` (a particle lies within the support;
    Φ's row is 0 elsewhere).

    Where :func:`displacement_at` interpolates at a point fixed in space — the inverse map a
    mask needs — this follows the material: its neighbours and weights are taken in the rest
    configuration, so they stay the same particles however far the tissue moves. (At a point
    fixed in space, a surface the bar pushes 2 mm down leaves the support, and the particles
    beside the bar, which rise, take over: the points A under the bar went up by 0.9 mm
    while the bar advanced.) The weights are moving least squares with a linear basis
    (cubic-kernel weights of support ``smoothing_factor × spacing_mm``): exact for any affine
    motion, at a surface as inside — where Shepard's weights, centred on the neighbours'
    mean, are not. A point with too few neighbours to fit a plane takes Shepard's weights.
    """
    import scipy.sparse as sp
    from scipy.spatial import cKDTree

    from hifumotion.particles.kernels import kernel

    rest = np.asarray(rest_mm, float)
    q = np.asarray(points_mm, float).reshape(-1, 3)
    h = smoothing_factor * float(spacing_mm)
    k = min(neighbours, len(rest))
    dist, idx = cKDTree(rest).query(q, k=k, distance_upper_bound=h)
    dist, idx = dist.reshape(len(q), -1), idx.reshape(len(q), -1)
    found = np.isfinite(dist)
    safe = np.where(found, idx, 0)
    w = np.where(found, kernel(np.where(found, dist, h), h), 0.0)
    w = w / np.maximum(w.sum(1, keepdims=True), 1e-300)     # scale-free moments
    covered = w.sum(1) > 0
    # linear basis p = [1, (X_j − X)/h]: Φ_j = w_j p(0)ᵀ M⁻¹ p_j with M = Σ w p pᵀ
    basis = np.concatenate([np.ones((*safe.shape, 1)), (rest[safe] - q[:, None]) / h], axis=2)
    moments = np.einsum("pk,pka,pkb->pab", w, basis, basis)
    eig = np.linalg.eigvalsh(moments)
    linear = covered & (found.sum(1) >= 4) & (eig[:, 0] > 1e-6 * eig[:, -1])
    phi = w.copy()                                          # Shepard's where a plane cannot be fitted
    if linear.any():
        c = np.linalg.solve(moments[linear], np.eye(4)[0][None, :, None].repeat(linear.sum(), 0))[..., 0]
        phi[linear] = w[linear] * np.einsum("pa,pka->pk", c, basis[linear])
    rows = np.repeat(np.arange(len(q)), safe.shape[1])
    matrix = sp.csr_matrix((np.where(found, phi, 0.0).ravel(), (rows, safe.ravel())), shape=(len(q), len(rest)))
    matrix.eliminate_zeros()
    return matrix, covered


def material_displacement(points_mm: np.ndarray, positions_mm: np.ndarray, rest_mm: np.ndarray,
                          spacing_mm: float, smoothing_factor: float = 2.0,
                          neighbours: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """The displacement (mm) of the material points ``points_mm`` (given in the configuration
    ``rest_mm``) when the particles are at ``positions_mm`` ``(N, 3)`` or ``(F, N, 3)``:
    ``(P, 3)`` or ``(F, P, 3)``, and ``covered`` ``(P,)`` (:func:`material_weights`)."""
    phi, covered = material_weights(points_mm, rest_mm, spacing_mm, smoothing_factor, neighbours)
    disp = np.asarray(positions_mm, float) - np.asarray(rest_mm, float)
    if disp.ndim == 2:
        return phi @ disp, covered
    return np.stack([phi @ d for d in disp]), covered


def mapped_section(positions_mm: np.ndarray, rest_mm: np.ndarray, spacing_mm: float, plane: Plane,
                   inside_rest, smoothing_factor: float = 2.0, neighbours: int = 32) -> Section:
    """The section of a body whose rest shape is known: ``inside_rest(points_mm) -> bool``.

    The displacement ``u = x − X`` of the particles (current ``positions_mm``, rest
    ``rest_mm``) is interpolated at each pixel centre q (:func:`displacement_at`);
    q is inside when ``inside_rest(q − u(q))`` and at least one particle is within the
    support. Exact for any displacement the interpolation reproduces (rigid motions,
    affine strains), and free of the particles' sampling of the surface, so two
    resolutions of the same body differ only by their physics. Contours as in
    :func:`section` (of the 0/1 mask).
    """
    from skimage import measure

    x = np.asarray(positions_mm, float)
    h = smoothing_factor * float(spacing_mm)
    pts = plane.points_mm().reshape(-1, 3)
    mask = np.zeros(len(pts), bool)
    o = np.asarray(plane.origin_mm, float)
    normal = np.cross(np.asarray(plane.u, float), np.asarray(plane.v, float))
    near_plane = np.abs((x - o) @ normal) < h
    if near_plane.any():
        u, covered = displacement_at(pts, x[near_plane], np.asarray(rest_mm, float)[near_plane], spacing_mm,
                                     smoothing_factor, neighbours)
        mask[covered] = np.asarray(inside_rest(pts[covered] - u[covered]), bool)
    mask = mask.reshape(plane.shape)
    contours = measure.find_contours(mask.astype(float), 0.5) if mask.any() else []
    contour_px = max(contours, key=len)[:, ::-1].copy() if contours else np.zeros((0, 2))
    return Section(mask, mask.astype(float), contour_px, contour_px * plane.pixel_mm, plane)
