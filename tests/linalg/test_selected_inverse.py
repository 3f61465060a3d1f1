"""Selected inversion: ``H⁻¹`` on the pattern of the Cholesky factor, for every backend,
against the dense inverse; the supernodes, restricted recursions and completed patterns."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie.linalg import BlockStructure, SelectedInverse, SingularSystemError, Supernodes, _ldl, cholesky_factor
from manopt_lie.linalg.selected_inverse import CholeskyFactor

from .helpers import random_factor_graph, random_values

# ldl is compiled here: skipped without a C compiler (MANOPT_LIE_NATIVE=0)
BACKENDS = ["cholmod", pytest.param("ldl", marks=pytest.mark.skipif(not _ldl.available(), reason="no compiled ldl")),
            "qdldl", "superlu"]  # fmt: skip


def random_spd(rng: np.random.Generator, n_vars: int = 30) -> sp.csc_matrix:
    """``JᵀWJ + I`` of a random factor graph (variables of dimension 3 and 6)."""
    dims, factors = random_factor_graph(rng, n_vars)
    small, large = np.flatnonzero(dims == 3), np.flatnonzero(dims == 6)
    factors += [  # chains of each dimension and links between them: connected, with fill-in
        (np.c_[small[:-1], small[1:]], 3),
        (np.c_[large[:-1], large[1:]], 6),
        (np.c_[small[: large.size], large], 4),
    ]
    structure = BlockStructure(dims, factors)
    blocks, residuals, weights = random_values(rng, dims, factors)
    H, _ = structure.normal_equations(blocks, residuals, weights)
    return structure.add_diagonal(H, np.ones(H.shape[0]))


@pytest.mark.parametrize("backend", BACKENDS)
def test_factor_and_solve(rng, backend):
    H = random_spd(rng)
    f = cholesky_factor(H, backend)
    assert isinstance(f, CholeskyFactor) and f.backend == backend
    dense = H.toarray()
    np.testing.assert_allclose((f.L @ f.L.T).toarray(), dense[np.ix_(f.perm, f.perm)], atol=1e-10)
    B = rng.standard_normal((H.shape[0], 4))
    np.testing.assert_allclose(f.solve(B), np.linalg.solve(dense, B), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("interface", ["direct", "cvxopt"])
def test_cholmod_factor_read_then_solved_through_either_interface(rng, monkeypatch, interface):
    """Reading L leaves the factor as it was for the solves after it: the direct binding reads a
    copy; CVXOPT's ``getfactor`` makes it symbolic, and the backend factors its values again."""
    pytest.importorskip("cvxopt")
    if interface == "cvxopt":
        monkeypatch.setenv("MANOPT_LIE_CHOLMOD", "cvxopt")
    H = random_spd(rng)
    f = cholesky_factor(H, "cholmod")
    dense, B = H.toarray(), rng.standard_normal((H.shape[0], 3))
    for _ in range(2):  # L, then solves, then L again
        np.testing.assert_allclose((f.L @ f.L.T).toarray(), dense[np.ix_(f.perm, f.perm)], atol=1e-10)
        np.testing.assert_allclose(f.solve(B), np.linalg.solve(dense, B), rtol=1e-10, atol=1e-12)
        f._L = None  # read L anew


@pytest.mark.parametrize("backend", BACKENDS)
def test_selected_inverse_on_the_pattern(rng, backend):
    H = random_spd(rng)
    Z = np.linalg.inv(H.toarray())
    inverse = SelectedInverse(cholesky_factor(H, backend))
    rows, cols = H.nonzero()
    values, found = inverse.entries(rows, cols)
    assert found.all()  # the pattern of H lies inside that of L + Lᵀ
    assert np.abs(values - Z[rows, cols]).max() < 1e-12 * np.abs(Z).max()
    # Every entry of the filled pattern is right, read from either triangle.
    L = inverse.factor.L.tocoo()
    r, c = inverse.factor.perm[L.row], inverse.factor.perm[L.col]
    for a, b in ((r, c), (c, r)):
        values, found = inverse.entries(a, b)
        assert found.all() and np.abs(values - Z[a, b]).max() < 1e-12 * np.abs(Z).max()


@pytest.mark.parametrize("backend", ["cholmod", "qdldl"])
def test_exact_patterns_need_no_entrywise_check(rng, backend):
    """CHOLMOD's and QDLDL's factors keep their structural zeros (here from the identity
    blocks of fixed-like variables and the random factors' cancellations): the supernodes
    found without comparing rows are those found with it."""
    H = random_spd(rng)
    f = cholesky_factor(H, backend)
    assert f.exact
    fast, checked = Supernodes(f.L, exact=True), Supernodes(f.L)
    assert np.array_equal(fast.start, checked.start) and not checked.completed
    assert np.array_equal(fast.panels(f.L.data), checked.panels(f.L.data))


@pytest.mark.parametrize("backend", BACKENDS)
def test_restricted_to_a_few_columns(rng, backend):
    H = random_spd(rng)
    Z = np.linalg.inv(H.toarray())
    factor = cholesky_factor(H, backend)
    columns = np.array([4, 5, 17])
    inverse = SelectedInverse(factor, columns)
    nodes = inverse.nodes
    assert inverse.computed.sum() < nodes.start.size  # not the whole tree
    mine = nodes.owner[np.argsort(factor.perm)[columns]]
    assert inverse.computed[mine].all() and inverse.computed[nodes.parent[mine][nodes.parent[mine] >= 0]].all()
    values, found = inverse.entries(columns[:, None], columns[None, :])
    assert found[[0, 1, 0], [0, 1, 1]].all()  # diagonal, and one variable's coordinates 4 and 5
    np.testing.assert_allclose(values[found], Z[np.ix_(columns, columns)][found], rtol=1e-12)


def test_supernodes_of_a_factor():
    # A 3-column clique joined through row 3 to a 2-column clique: supernodes {0, 1, 2}, {3, 4}.
    pattern = np.tril(np.ones((5, 5)))
    pattern[4, :3] = 0
    L = sp.csc_matrix(pattern * (1 + np.eye(5)))
    nodes = Supernodes(L)
    assert nodes.start.tolist() == [0, 3] and nodes.width.tolist() == [3, 2] and nodes.nrows.tolist() == [4, 2]
    assert nodes.parent.tolist() == [1, -1] and not nodes.completed
    index, found = nodes.locate([3, 4, 0], [3, 3, 4])  # either triangle
    assert found.tolist() == [True, True, False]
    panels = nodes.panels(L.data)
    assert panels[index[:2]].tolist() == [2.0, 1.0]
    assert nodes.ancestors([0]).tolist() == [True, True] and nodes.ancestors([1]).tolist() == [False, True]


def test_a_pattern_without_its_zeros_is_completed(rng):
    """A factor whose structural zeros were dropped (as SciPy's copy of SuperLU's ``L`` does)
    is completed by the symbolic factorization, and the recursion stays exact."""
    H = random_spd(rng, 45)
    f = cholesky_factor(H, "cholmod")
    L = f.L.copy()
    small = np.abs(L.data) < 0.3 * np.abs(L.data).max()
    off = L.indices != np.repeat(np.arange(L.shape[0]), np.diff(L.indptr))
    L.data[small & off & (rng.random(L.nnz) < 0.5)] = 0.0
    L.eliminate_zeros()
    damaged = CholeskyFactor(f.perm, "test", lambda: L)
    inverse = SelectedInverse(damaged)
    assert inverse.nodes.completed
    Hd = (L @ L.T).toarray()[np.ix_(np.argsort(f.perm), np.argsort(f.perm))]  # the damaged factor's matrix
    rows, cols = np.nonzero(Hd)
    values, found = inverse.entries(rows, cols)
    Z = np.linalg.inv(Hd)
    assert found.all() and np.abs(values - Z[rows, cols]).max() < 1e-11 * np.abs(Z).max()


@pytest.mark.parametrize("backend", BACKENDS)
def test_singular_and_bad_input(backend):
    chain = sp.diags([np.full(5, 2.0), -np.ones(4), -np.ones(4)], [0, 1, -1]).tolil()
    chain[0, 0] = chain[4, 4] = 1.0  # a path Laplacian: singular
    with pytest.raises(SingularSystemError):
        cholesky_factor(chain.tocsc(), backend)
    with pytest.raises(ValueError, match="unknown backend"):
        cholesky_factor(sp.eye(3, format="csc"), "mumps")
    with pytest.raises(ValueError, match="diagonal first"):
        Supernodes(sp.csc_matrix(np.array([[0.0, 0], [1, 1]])))


def test_a_factor_needs_a_sparse_backend(rng):
    with pytest.raises(ValueError, match="unknown backend 'dense'"):
        cholesky_factor(random_spd(rng), "dense")
