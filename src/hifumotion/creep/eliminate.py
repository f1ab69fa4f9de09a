"""The constrained system's matrix ``Tᵀ A T``, node block by node block (a Numba kernel).

The creep's unknowns are eliminated per node (:meth:`~.integrate.CreepSolver._reduction`):
node i's displacement is ``u_i = P_i q_i + n_i s`` with ``P_i`` a 3 × 3 matrix whose columns
are its free directions (the axes for a free node; a contact's two tangents, a zero column
for its prescribed normal; all zero for a bonded contact) and ``n_i`` the bar's axis for a
node on the bar (s the bar's advance). ``T`` is then block diagonal but for the s column,
and ``Tᵀ A T`` has A's node-pair blocks ``P_iᵀ A_ij P_j`` plus a bar row and column
``P_iᵀ Σ_j A_ij n_j``. Computing them in place on A's pattern replaces two sparse products,
a conversion and a search of every entry's place (a third of a 1,000-particle run's time).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def _eliminated_blocks(indptr, indices, data, columns, bar_normal, with_s, out, bar_diagonal):
    n = columns.shape[0]
    last = indptr[3 * n] + 3 * n   # where the bar's row starts in the eliminated pattern
    for i in prange(n):
        r0 = 3 * i
        start = indptr[r0]
        blocks = (indptr[r0 + 1] - start) // 3
        pi = columns[i]
        sv = np.zeros(3)
        blk = np.empty((3, 3))
        tmp = np.empty((3, 3))
        for b in range(blocks):
            j = indices[start + 3 * b] // 3
            pj = columns[j]
            for a in range(3):
                base = indptr[r0 + a] + 3 * b
                for c in range(3):
                    blk[a, c] = data[base + c]
            for a in range(3):
                for c in range(3):
                    tmp[a, c] = blk[a, 0] * pj[0, c] + blk[a, 1] * pj[1, c] + blk[a, 2] * pj[2, c]
            for a in range(3):
                # each earlier row of the eliminated pattern has one more entry (its bar column)
                base = indptr[r0 + a] + 3 * b + ((r0 + a) if with_s else 0)
                for c in range(3):
                    out[base + c] = pi[0, a] * tmp[0, c] + pi[1, a] * tmp[1, c] + pi[2, a] * tmp[2, c]
            if with_s:
                nj = bar_normal[j]
                for a in range(3):
                    sv[a] += blk[a, 0] * nj[0] + blk[a, 1] * nj[1] + blk[a, 2] * nj[2]
        if with_s:
            for a in range(3):
                col = pi[0, a] * sv[0] + pi[1, a] * sv[1] + pi[2, a] * sv[2]
                out[indptr[r0 + a + 1] + r0 + a] = col   # the row's last entry: the bar column
                out[last + r0 + a] = col                 # and its mirror in the bar's row
            ni = bar_normal[i]
            bar_diagonal[i] = ni[0] * sv[0] + ni[1] * sv[1] + ni[2] * sv[2]


def eliminated_matrix_data(a_indptr: np.ndarray, a_indices: np.ndarray, a_data: np.ndarray, columns: np.ndarray,
                        bar_normal: np.ndarray, with_bar: bool) -> np.ndarray:
    """The data of ``Tᵀ A T`` on the eliminated pattern (module docstring).

    ``A`` is a CSR matrix of 3 × 3 node-pair blocks with sorted columns (the mesh's
    :class:`~.hexahedra.Assembly`); ``columns`` ``(n, 3, 3)`` the nodes' ``P_i``,
    ``bar_normal`` ``(n, 3)`` their ``n_i`` (0 off the bar). The eliminated pattern is A's with,
    when ``with_bar``, one more column (the bar's advance, last in every row) and a last
    row over every column; its data come back in that order.
    """
    n = columns.shape[0]
    size = len(a_data) + (2 * 3 * n + 1 if with_bar else 0)
    out = np.zeros(size)
    bar_diagonal = np.zeros(n)
    _eliminated_blocks(a_indptr.astype(np.int64), a_indices.astype(np.int64), a_data,
                    np.ascontiguousarray(columns, np.float64), np.ascontiguousarray(bar_normal, np.float64),
                    bool(with_bar), out, bar_diagonal)
    if with_bar:
        out[-1] = bar_diagonal.sum()
    return out


__all__ = ["eliminated_matrix_data"]
