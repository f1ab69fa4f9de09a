"""The sparse SPD solves: mixed precision refined to a direct double-precision solve's answer."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from hifumotion.creep import linear
from hifumotion.creep.linear import Factor, refined_solve

needs_mkl = pytest.mark.skipif(linear._pardiso is None, reason="MKL PARDISO is not installed")


def _laplacian_3d(n: int, shift: float) -> sp.csr_matrix:
    """The 7-point Laplacian on an n³ grid (Neumann) plus ``shift`` × I: SPD, condition ~ 12 / shift."""
    d = sp.diags([-np.ones(n - 1), np.r_[1.0, 2.0 * np.ones(n - 2), 1.0], -np.ones(n - 1)], [-1, 0, 1])
    eye = sp.identity(n)
    lap = sp.kron(sp.kron(d, eye), eye) + sp.kron(sp.kron(eye, d), eye) + sp.kron(sp.kron(eye, eye), d)
    return (lap + shift * sp.identity(n ** 3)).tocsr()


@needs_mkl
@pytest.mark.parametrize("precision", ["double", "mixed"])
def test_factor_solves_to_the_direct_answer(precision):
    a = _laplacian_3d(14, 1e-2)
    b = np.random.default_rng(3).standard_normal((a.shape[0], 2))
    exact = np.column_stack([spsolve(a.tocsc(), b[:, k]) for k in range(2)])
    f = Factor(a, "pardiso", precision)
    raw = f.solve(b)   # two right-hand sides at once
    rel = np.linalg.norm(raw - exact) / np.linalg.norm(exact)
    assert rel < (1e-10 if precision == "double" else 1e-3)
    if precision == "mixed":
        assert rel > 1e-12   # a single-precision factor is not a double one
    x, its = refined_solve(a, f, b[:, 0], 1e-12)
    assert np.linalg.norm(a @ x - b[:, 0]) <= 1e-12 * np.linalg.norm(b[:, 0])
    assert np.allclose(x, exact[:, 0], rtol=0, atol=1e-8 * np.abs(exact).max())
    assert (its == 0) == (precision == "double")
    f.release()


@needs_mkl
def test_refactor_on_the_same_pattern_solves_the_new_matrix():
    a = _laplacian_3d(10, 1e-2)
    b = np.random.default_rng(4).standard_normal(a.shape[0])
    f = Factor(a, "pardiso", "mixed")
    pattern = f._handle.pattern
    a2 = a.copy()
    a2.setdiag(a2.diagonal() * 3.0 + 1.0)   # new values, the same pattern
    f.refactor(a2)
    assert f._handle.pattern is pattern    # the analysis was kept
    x, _ = refined_solve(a2, f, b, 1e-11)
    assert np.allclose(x, spsolve(a2.tocsc(), b), rtol=0, atol=1e-8)
    a3 = (a2 + sp.diags([0.5 * np.ones(a.shape[0] - 7)], [7]) + sp.diags([0.5 * np.ones(a.shape[0] - 7)], [-7])).tocsr()
    f.refactor(a3)                         # a new pattern: analysed afresh
    assert f._handle.pattern is not pattern
    x, _ = refined_solve(a3, f, b, 1e-11)
    assert np.allclose(x, spsolve(a3.tocsc(), b), rtol=0, atol=1e-8)
    f.release()


@needs_mkl
def test_a_matrix_singular_in_single_precision_is_factorised_in_double():
    # [[1, 1 − 10⁻⁹], [1 − 10⁻⁹, 1]] is SPD (eigenvalue 10⁻⁹) but rounds to a singular
    # matrix in single precision: the mixed factorisation must not return garbage
    c = 1.0 - 1e-9
    a = sp.block_diag([np.array([[1.0, c], [c, 1.0]])] * 50, format="csr")
    b = np.random.default_rng(5).standard_normal(100)
    f = Factor(a, "pardiso", "mixed")
    assert f.precision == "double"
    x, _ = refined_solve(a, f, b, 1e-9)
    b2 = b.reshape(-1, 2)
    exact = np.column_stack([b2[:, 0] - c * b2[:, 1], b2[:, 1] - c * b2[:, 0]]) / (1 - c * c)  # the 2 × 2 inverse
    assert np.allclose(x.reshape(-1, 2), exact, rtol=1e-5, atol=0)
    f.release()
