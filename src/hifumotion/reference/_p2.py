"""The quadratic-tetrahedron discretisation both finite-element references share (SI inside).

TetGen meshes the closed surface (quality bound radius–edge ≤ 1.5, volumes ≤
``max_volume_mm3``); scikit-fem's ten-node tetrahedra carry the displacement. A *point*
is a P2 node (a vertex or an edge's midpoint) and owns three dofs (x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MM = 1e-3


@dataclass
class P2Mesh:
    """The mesh, its vector P2 basis and the points' dofs.

    ``dof_xyz`` is ``(points, 3)``: the x, y, z dof of each point; ``points_m`` the points'
    rest positions (m); ``on_surface`` whether a point lies on the boundary.
    """

    mesh: object
    basis: object
    dof_xyz: np.ndarray
    points_m: np.ndarray
    on_surface: np.ndarray

    @property
    def dofs(self) -> int:
        return int(self.basis.N)

    def tetra10_cells(self) -> np.ndarray:
        """``(elements, 10)`` point indices in VTK's (and FElupe's, meshio's) tetra10 order: the
        four vertices, then the midpoints of the edges 01, 12, 20, 03, 13, 23 — scikit-fem's
        local order of its P2 element's nodes."""
        point_of_dof = np.empty(self.dofs, np.int64)
        point_of_dof[self.dof_xyz[:, 0]] = np.arange(len(self.dof_xyz))
        # the vector P2 element's dofs: x, y, z of each of its ten nodes in turn
        return point_of_dof[self.basis.element_dofs[0::3]].T

    def probes(self, points_mm: np.ndarray):
        """``(3·n, dofs)`` sparse interpolation to ``points_mm`` — rows x of all points, then y,
        then z — and a mask of the points outside the mesh (those take their nearest P2 point)."""
        import scipy.sparse as sp
        from scipy.spatial import cKDTree

        q = np.asarray(points_mm, float).reshape(-1, 3)
        try:
            cells = self.mesh.element_finder()(*(q * MM).T)
            inside = cells >= 0
        except ValueError:
            inside = np.zeros(len(q), bool)
        matrix = sp.csr_matrix((3 * len(q), self.dofs))
        if inside.any():
            p = self.basis.probes((q[inside] * MM).T).tocsr()   # rows: x of those points, then y, z
            k = int(inside.sum())
            index = np.flatnonzero(inside)
            order = np.concatenate([index, len(q) + index, 2 * len(q) + index])
            matrix = matrix + sp.csr_matrix((np.ones(3 * k), (order, np.arange(3 * k))),
                                            shape=(3 * len(q), 3 * k)) @ p
        outside = np.flatnonzero(~inside)
        if len(outside):
            _, near = cKDTree(self.points_m).query(q[outside] * MM)
            r = np.concatenate([outside, len(q) + outside, 2 * len(q) + outside])
            c = np.concatenate([self.dof_xyz[near, 0], self.dof_xyz[near, 1], self.dof_xyz[near, 2]])
            matrix = matrix + sp.csr_matrix((np.ones(len(r)), (r, c)), shape=(3 * len(q), self.dofs))
        return matrix.tocsr(), ~inside


def p2_mesh(vertices_mm: np.ndarray, faces: np.ndarray, max_volume_mm3: float, intorder: int = 4) -> P2Mesh:
    """Tetrahedralise the closed surface (mm) and build the vector P2 basis on it."""
    import skfem
    import tetgen

    tg = tetgen.TetGen(np.asarray(vertices_mm, float), np.asarray(faces, np.int32))
    nodes, tets = tg.tetrahedralize(order=1, minratio=1.5, maxvolume=max_volume_mm3, fixedvolume=True, quality=True)[:2]
    mesh = skfem.MeshTet(np.ascontiguousarray((nodes * MM).T), np.ascontiguousarray(np.asarray(tets, np.int64).T))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()), intorder=intorder)
    # the P2 points (vertices, then edge midpoints) and their three dofs
    dof_xyz = np.concatenate([basis.nodal_dofs.T, basis.edge_dofs.T])
    points = np.stack([basis.doflocs[c, dof_xyz[:, c]] for c in range(3)], 1)
    on_surface = np.zeros(len(points), bool)
    surf_dofs = basis.get_dofs(mesh.boundary_facets()).flatten()
    on_surface[np.isin(dof_xyz[:, 0], surf_dofs)] = True
    return P2Mesh(mesh, basis, dof_xyz, points, on_surface)


def spsolve(matrix, rhs: np.ndarray) -> np.ndarray:
    """A direct sparse solve: MKL PARDISO where installed (40× faster here), else SuperLU."""
    try:
        import pypardiso
    except ImportError:  # pragma: no cover
        import scipy.sparse.linalg as spla

        lu = spla.splu(matrix.tocsc(), permc_spec="MMD_AT_PLUS_A")
        return lu.solve(np.asarray(rhs, float))
    return np.asarray(pypardiso.spsolve(matrix.tocsr(), np.asfortranarray(rhs, dtype=float))).reshape(rhs.shape)
