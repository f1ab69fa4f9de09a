"""The tissue's particles as the voxels of a hexahedral mesh.

Every tissue particle of a lattice (spacing Δx) is the centre of a cube of side Δx;
the cubes' corners are the mesh's nodes, shared between neighbouring cubes. The body
the mesh covers is then exactly the particles' union — its volume N Δx³, its floor
face where the lowest particles' cells end (half a spacing under their centres), so a
contact with the floor has no gap that depends on Δx. A particle moves with the mean of
its cube's eight corners (the trilinear interpolant at the centre). Where the true
surface is known, :func:`conform` moves the boundary nodes onto it.
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


#: The smallest corner Jacobian (a fraction of the undistorted cube's, Δx³/8) :func:`conform`
#: lets a boundary voxel reach. The boundary's fidelity, not the voxels' shape, decides a
#: contact: at ⅕ one boundary node in seven of a reconstructed sample
#: (s47, 4,399 particles) stayed more than ¼ Δx outside the surface, and the fast path's
#: pressed push was 11 % of its peak off the P2 reference; at 1/100 one in a hundred, and
#: 4.4 % (docs/decisions.md, "The voxels meet the surface").
MIN_CORNER_JACOBIAN = 0.01


#: How many times :func:`conform` projects the boundary again from where its nodes went.
PROJECTIONS = 3


def conform(mesh: VoxelMesh, surface, floor_mm: float | None = 0.0, rounds: int = 6,
            min_jacobian: float = MIN_CORNER_JACOBIAN, projections: int = PROJECTIONS) -> VoxelMesh:
    """The mesh with its boundary nodes moved onto ``surface`` (a closed ``trimesh.Trimesh``, mm).

    A voxel mesh's boundary is a staircase up to ½√3 Δx from the true surface, and its
    contact with a flat bar or floor is then decided by which layer of steps touches:
    the push converges only to first order in Δx (docs/decisions.md). Each boundary node
    goes to its closest point on the surface (not below ``floor_mm``, the pool's floor);
    a voxel whose Jacobian would fall below ``min_jacobian`` of the cube's at a corner (it
    would fold) has its nodes moved half as far, up to ``rounds`` times. A node so held back is
    projected again from where it went, ``projections`` times in all: its closest point from
    there is often one it reaches without a fold — the fold guard halves all eight nodes of a
    voxel that one or two of them fold, and the closest point from the lattice may lie across a
    thin feature. Interior nodes stay on the lattice.
    """
    from hifumotion.creep.hexahedra import general_blocks

    if not 0.0 < min_jacobian < 1.0:
        raise InputError(f"must be between 0 and 1 (a fraction of the cube's Jacobian), got {min_jacobian}",
                         "min_jacobian")
    boundary = np.unique(mesh.surface_faces())
    touched = np.flatnonzero(np.isin(mesh.elements, boundary).any(axis=1))
    cube = mesh.spacing_mm ** 3 / 8.0
    nodes = mesh.nodes_mm.copy()
    for _ in range(max(1, projections)):
        target = np.asarray(surface.nearest.on_surface(nodes[boundary])[0], float)
        if floor_mm is not None:
            target[:, 1] = np.maximum(target[:, 1], floor_mm)
        shift = np.zeros_like(nodes)
        shift[boundary] = target - nodes[boundary]
        if np.abs(shift).max() <= 1e-9 * mesh.spacing_mm:
            break
        scale = np.ones(len(nodes))
        for _ in range(rounds):
            *_, min_det = general_blocks(nodes + scale[:, None] * shift, mesh.elements, touched)
            bad = touched[min_det < min_jacobian * cube]
            if len(bad) == 0:
                break
            scale[np.unique(mesh.elements[bad])] *= 0.5
        else:
            scale[np.unique(mesh.elements[bad])] = 0.0
        nodes = nodes + scale[:, None] * shift
        if np.all(scale == 1.0):
            break
    return VoxelMesh(mesh.spacing_mm, nodes, mesh.elements, mesh.centres_mm)


__all__ += ["conform", "MIN_CORNER_JACOBIAN", "PROJECTIONS"]
