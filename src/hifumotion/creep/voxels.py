"""The tissue's particles as the voxels of a hexahedral mesh.

Every tissue particle of a lattice (spacing Δx) is the centre of a cube of side Δx;
the cubes' corners are the mesh's nodes, shared between neighbouring cubes. The body
the mesh covers is then exactly the particles' union — its volume N Δx³, its floor
face where the lowest particles' cells end (half a spacing under their centres), so a
contact with the floor has no gap that depends on Δx. A particle moves with the mean of
its cube's eight corners (the trilinear interpolant at the centre). Where the true
surface is known, :func:`~.conform.conform` moves the boundary nodes onto it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.errors import InputError

#: The eight corners of a voxel in the order of :mod:`.hexahedra` (lexicographic on
#: the faces: −z face counter-clockwise, then +z face), in units of Δx from the lower corner.
CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                    [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.int64)


@dataclass(frozen=True)
class VoxelMesh:
    """Hexahedral mesh of a particle lattice (mm).

    Attributes
    ----------
    spacing_mm
        Δx, the side of every voxel (mm).
    nodes_mm
        ``(nodes, 3)`` rest positions of the voxels' corners (mm).
    elements
        ``(voxels, 8)`` node indices of each voxel, in :data:`CORNERS` order;
        voxel k is the k-th particle given.
    centres_mm
        ``(voxels, 3)`` the particles (the voxels' centres, mm).
    """

    spacing_mm: float
    nodes_mm: np.ndarray
    elements: np.ndarray
    centres_mm: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.nodes_mm)

    def particles(self, nodes_mm: np.ndarray) -> np.ndarray:
        """Particle positions (mm) for the node positions ``nodes_mm``: each particle moves by
        the mean displacement of its voxel's corners (the trilinear interpolant at the centre)."""
        return self.centres_mm + (np.asarray(nodes_mm) - self.nodes_mm)[self.elements].mean(axis=1)

    def surface_faces(self) -> np.ndarray:
        """``(F, 4)`` node quads of the voxel faces no other voxel shares (for output)."""
        faces = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [1, 2, 6, 5], [0, 4, 7, 3]])
        quads = self.elements[:, faces].reshape(-1, 4)
        key = np.sort(quads, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return quads[counts[inverse.ravel()] == 1]


def voxel_mesh(particles_mm: np.ndarray, spacing_mm: float) -> VoxelMesh:
    """The :class:`VoxelMesh` of particles on a cubic lattice of spacing ``spacing_mm``.

    Raises :class:`~hifumotion.errors.InputError` when the particles are not on one
    lattice (the fast path needs the voxels to tile the body) or two coincide.
    """
    x = np.asarray(particles_mm, float)
    dx = float(spacing_mm)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) == 0:
        raise InputError(f"expected (N, 3) particle positions, got shape {x.shape}", "tissue particles")
    if not dx > 0:
        raise InputError(f"particle spacing must be positive, got {dx}", "particles.spacing_mm")
    index_f = (x - x[0]) / dx
    index = np.round(index_f).astype(np.int64)
    if np.abs(index_f - index).max() > 1e-3:
        raise InputError(f"the tissue particles are not on one cubic lattice of spacing {dx:g} mm "
                         "(the implicit path meshes them as voxels; use the explicit path for scattered particles)",
                         "tissue particles")
    index -= index.min(axis=0)
    if len(np.unique(index, axis=0)) != len(index):
        raise InputError("two tissue particles share a lattice site", "tissue particles")
    corners = (index[:, None, :] + CORNERS[None]).reshape(-1, 3)
    unique, inverse = np.unique(corners, axis=0, return_inverse=True)
    base = (x - (index + 0.5) * dx).mean(axis=0)  # the lattice's lower corner (the same from every particle)
    nodes = base + unique * dx
    return VoxelMesh(dx, nodes, inverse.reshape(-1, 8).astype(np.int64), x.copy())


__all__ = ["VoxelMesh", "voxel_mesh", "CORNERS"]
