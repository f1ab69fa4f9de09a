"""A voxel mesh's boundary nodes moved onto the true surface.

A voxel mesh (:mod:`.voxels`) has a staircase for a boundary; :func:`conform` moves its boundary
nodes onto the reconstructed surface without folding a voxel (the corner Jacobians of
:func:`~.hexahedra.general_blocks`).
"""

from __future__ import annotations

import numpy as np

from hifumotion.creep.hexahedra import general_blocks
from hifumotion.creep.voxels import VoxelMesh
from hifumotion.errors import InputError


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


__all__ = ["conform", "MIN_CORNER_JACOBIAN", "PROJECTIONS"]
