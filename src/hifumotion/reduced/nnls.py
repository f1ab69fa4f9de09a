"""Non-negative least squares started from a guessed active set, compiled.

The reduced model's contact solve (:meth:`~hifumotion.reduced.model.ReducedCreep._solve`) is a
least-distance problem that Lawson & Hanson reduce to NNLS (Solving Least Squares Problems,
1974, ch. 23): ``min |E w − f|`` over ``w ≥ 0``, one column of E per contact row. Steps a
frame apart press nearly the same rows, but SciPy's NNLS starts every call from an empty
passive set and spends most of a step there (docs/decisions.md, "The filter's step: NNLS started
warm": 28 of the online filter's 53 ms a frame at 4,441 particles, 4.7 ms a call). Here Lawson & Hanson's algorithm
starts from the rows the last solve pressed (the warm start of Bro & De Jong, J.
Chemometrics 1997): the guessed set is first pruned to a feasible one, then the usual outer
loop adds the column of largest gradient and the inner loop keeps the iterate
non-negative. The answer is the same problem's; only the path to it is shorter.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _passive_solution(e, f, passive):
    """The least-squares solution on the passive columns, zero elsewhere, and whether those
    columns are independent (else the solution is not unique and nothing is returned)."""
    index = np.flatnonzero(passive)
    z = np.zeros(e.shape[1])
    k = len(index)
    if k == 0:
        return z, True
    if k > e.shape[0]:
        return z, False
    q, r = np.linalg.qr(np.ascontiguousarray(e[:, index]))
    biggest = 0.0
    for i in range(k):
        biggest = max(biggest, abs(r[i, i]))
    rhs = np.ascontiguousarray(q.T) @ f
    for i in range(k - 1, -1, -1):      # back substitution on R
        if abs(r[i, i]) <= 1e-12 * biggest:
            return np.zeros(e.shape[1]), False
        s = rhs[i]
        for j in range(i + 1, k):
            s -= r[i, j] * z[index[j]]
        z[index[i]] = s / r[i, i]
    return z, True


@njit(cache=True)
def nnls_from(e: np.ndarray, f: np.ndarray, start: np.ndarray, max_iter: int) -> tuple[np.ndarray, bool]:
    """``(w, converged)``: ``argmin |e w − f|`` over ``w ≥ 0``, Lawson & Hanson's active-set
    iteration from the passive set ``start`` (column indices; any, feasible or not).
    ``converged`` is False when ``max_iter`` outer iterations did not reach the optimality
    conditions (the caller then solves cold)."""
    m, n = e.shape
    x = np.zeros(n)
    passive = np.zeros(n, np.bool_)
    for j in start:
        passive[j] = True
    scale = 0.0
    for j in range(n):
        s = 0.0
        for i in range(m):
            s += abs(e[i, j])
        scale = max(scale, s)
    tol = 10.0 * np.finfo(np.float64).eps * scale * max(m, n)
    # prune the guess to a passive set whose solution is positive (x = 0 is feasible); a guess
    # of dependent columns is dropped (the iteration then starts cold)
    while passive.any():
        z, independent = _passive_solution(e, f, passive)
        if not independent:
            passive[:] = False
            break
        bad = passive & (z <= tol)
        if not bad.any():
            x = z
            break
        passive &= ~bad
    banned = -1
    for _ in range(max_iter):
        w = e.T @ (f - e @ x)
        best, j = tol, -1
        for c in range(n):
            if not passive[c] and c != banned and w[c] > best:
                best, j = w[c], c
        if j < 0:
            # optimal, unless the one column skipped still wants in
            return x, not (banned >= 0 and w[banned] > tol)
        passive[j] = True
        z, independent = _passive_solution(e, f, passive)
        if not independent:          # j depends on the passive columns: leave it for one round
            passive[j] = False
            banned = j
            continue
        while True:
            bad = passive & (z <= tol)
            if not bad.any():
                break
            alpha = 1.0
            for c in np.flatnonzero(bad):
                alpha = min(alpha, x[c] / (x[c] - z[c]))
            x = x + alpha * (z - x)
            drop = passive & (x <= tol)
            passive &= ~drop
            x[drop] = 0.0
            z, independent = _passive_solution(e, f, passive)
            if not independent:
                return x, False
        # a column that left at once would be picked again: skip it for one round
        banned = j if not passive[j] else -1
        x = z
    return x, False


def load_compiled() -> None:
    """Load (or compile) :func:`nnls_from`'s machine code now: its first call reads Numba's
    cache (0.5 s; seconds when it compiles), which should not land in a model's first step."""
    nnls_from(np.eye(2), np.ones(2), np.zeros(0, np.int64), 4)


__all__ = ["load_compiled", "nnls_from"]
