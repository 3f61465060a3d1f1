"""BlockStructure: J, H = JᵀWJ and g = JᵀWr against a dense reference; fixed patterns; bad input."""

from __future__ import annotations

import re

import numpy as np
import pytest

from manopt_lie import ShapeError
from manopt_lie.linalg import BlockStructure

from .helpers import dense_jacobian, dense_normal_equations, random_factor_graph, random_values

SEEDS = [0, 1, 2]


@pytest.fixture(params=[(seed, dense) for dense in (False, True) for seed in SEEDS], ids=str)
def graph(request):
    """A random factor graph's structure, sparse or dense (every entry stored): everything
    below holds for both but the pattern itself."""
    seed, dense = request.param
    rng = np.random.default_rng(seed)
    dims, factors = random_factor_graph(rng)
    return rng, dims, factors, BlockStructure(dims, factors, dense=dense)


def test_sizes(graph):
    _, dims, factors, S = graph
    assert S.n == dims.sum()
    assert S.n_rows == sum(len(ids) * r for ids, r in factors)
    assert S.nnz == S.indices.size == S.indptr[-1]


def test_jacobian_matches_dense(graph):
    rng, dims, factors, S = graph
    blocks, _, _ = random_values(rng, dims, factors)
    J = S.jacobian(blocks)
    assert J.format == "csr" and J.shape == (S.n_rows, S.n) and J.has_canonical_format
    np.testing.assert_array_equal(J.toarray(), dense_jacobian(dims, factors, blocks))


@pytest.mark.parametrize("weighted", [False, True])
def test_normal_equations_match_dense(graph, weighted):
    rng, dims, factors, S = graph
    blocks, residuals, weights = random_values(rng, dims, factors)
    w = weights if weighted else None
    H, g = S.normal_equations(blocks, residuals, w)
    H_ref, g_ref = dense_normal_equations(dims, factors, blocks, residuals, w)
    assert H.format == "csc" and H.shape == (S.n, S.n) and H.has_canonical_format
    np.testing.assert_allclose(H.toarray(), H_ref, rtol=0, atol=1e-12 * np.abs(H_ref).max())
    np.testing.assert_allclose(g, g_ref, rtol=0, atol=1e-12 * np.abs(g_ref).max())
    # Each half alone (a linearization's deferred H, a gradient-only solver) is the same.
    np.testing.assert_array_equal(S.hessian(blocks, w).toarray(), H.toarray())
    np.testing.assert_allclose(S.gradient(blocks, residuals, w), g, rtol=0, atol=1e-13 * np.abs(g).max())
    # Written over an earlier H of the structure (its values all overwritten): the same matrix.
    old = S.hessian(*random_values(rng, dims, factors)[::2])
    old.data[:] = np.nan
    data = old.data
    assert S.hessian(blocks, w, out=old) is old and old.data is data
    np.testing.assert_array_equal(old.toarray(), H.toarray())


@pytest.mark.parametrize("dense", [False, True])
def test_a_scatter_made_per_chunk_gives_the_same_h(monkeypatch, dense):
    """Above WHOLE_SCATTER_BYTES a factor's positions in H are made chunk by chunk from its row
    starts and slot offsets: the same positions in the same order, so the same H bit for bit. (A
    dense structure, small by construction, keeps its positions whole and sums them by chunks.)"""
    from manopt_lie.linalg import _factors, structure

    rng = np.random.default_rng(5)
    dims, factors = random_factor_graph(rng)
    blocks, residuals, weights = random_values(rng, dims, factors)
    whole = BlockStructure(dims, factors, dense=dense)
    monkeypatch.setattr(_factors, "WHOLE_SCATTER_BYTES", 0)
    monkeypatch.setattr(structure, "CHUNK", 64)  # several chunks per factor, the last one short
    made = BlockStructure(dims, factors, dense=dense)
    assert all(s.whole is not None for s in whole._hess_scatter)
    assert all((s.whole is not None) is dense for s in made._hess_scatter)
    assert any(f.m > max(1, 64 // f.width**2) for f in made._factors)
    for w in (None, weights):
        (h_made, g_made), (h_whole, g_whole) = (s.normal_equations(blocks, residuals, w) for s in (made, whole))
        np.testing.assert_array_equal(h_made.data, h_whole.data)
        np.testing.assert_array_equal(g_made, g_whole)


def test_hessian_out_must_be_of_the_structure(graph):
    rng, dims, factors, S = graph
    blocks = random_values(rng, dims, factors)[0]
    H = S.hessian(blocks)
    foreign = H.copy()  # the same pattern, but not the structure's index arrays
    for bad in (foreign, S.hessian(blocks).astype(np.float32), H.tocsr()):
        with pytest.raises(ValueError, match="out must be an H of this structure"):
            S.hessian(blocks, out=bad)


def test_pattern_is_the_touched_blocks_plus_the_diagonal(graph):
    rng, dims, factors, S = graph
    # With all-ones blocks every touched block pair is structurally nonzero in JᵀJ.
    ones = [np.ones_like(b) for b in random_values(rng, dims, factors)[0]]
    J = dense_jacobian(dims, factors, ones)
    var_of = np.repeat(np.arange(dims.size), dims)
    expected = (J.T @ J != 0) | (var_of[:, None] == var_of[None, :]) | S.dense
    stored = np.zeros((S.n, S.n), dtype=bool)
    stored[S.indices, np.repeat(np.arange(S.n), np.diff(S.indptr))] = True
    np.testing.assert_array_equal(stored, expected)


def test_pattern_is_fixed_across_calls(graph):
    rng, dims, factors, S = graph
    H1, _ = S.normal_equations(*random_values(rng, dims, factors))
    H2, _ = S.normal_equations(*random_values(rng, dims, factors))
    for H in (H1, H2):
        assert np.shares_memory(H.indptr, S.indptr) and np.shares_memory(H.indices, S.indices)
        np.testing.assert_array_equal(H.indptr, S.indptr)
        np.testing.assert_array_equal(H.indices, S.indices)
    assert not np.array_equal(H1.data, H2.data)
    J1, J2 = (S.jacobian(random_values(rng, dims, factors)[0]) for _ in range(2))
    assert np.shares_memory(J1.indices, J2.indices) and np.shares_memory(J1.indptr, J2.indptr)


def test_add_diagonal_keeps_the_pattern(graph):
    rng, dims, factors, S = graph
    H, _ = S.normal_equations(*random_values(rng, dims, factors))
    before = H.toarray()
    lam = rng.uniform(0.5, 1.5, S.n)
    H_damped = S.add_diagonal(H, lam * H.diagonal())
    np.testing.assert_allclose(H_damped.toarray(), before + np.diag(lam * H.diagonal()), rtol=1e-15)
    np.testing.assert_array_equal(H.toarray(), before)
    assert np.shares_memory(H_damped.indices, S.indices) and np.shares_memory(H_damped.indptr, S.indptr)
    np.testing.assert_allclose(S.add_diagonal(H, 2.0).toarray(), before + 2.0 * np.eye(S.n))
    with pytest.raises(ValueError, match="pattern"):
        S.add_diagonal(H[:-1, :-1], 1.0)


def test_diagonal_positions_point_at_the_diagonal(graph):
    rng, dims, factors, S = graph
    H, _ = S.normal_equations(*random_values(rng, dims, factors))
    positions = S.diagonal_positions
    np.testing.assert_array_equal(H.data[positions], H.diagonal())
    assert positions is S.diagonal_positions and not positions.flags.writeable
    H.data[positions[[0, S.n - 1]]] += 1.0  # as LeastSquaresProblem marks its fixed variables
    np.testing.assert_array_equal(H.diagonal()[[0, S.n - 1]], H.data[positions[[0, S.n - 1]]])


@pytest.mark.parametrize("seed", SEEDS)
def test_a_dense_structure_stores_the_dense_matrix_column_by_column(seed):
    rng = np.random.default_rng(seed)
    dims, factors = random_factor_graph(rng)
    S = BlockStructure(dims, factors, dense=True)
    H, _ = S.normal_equations(*random_values(rng, dims, factors))
    np.testing.assert_array_equal(H.data.reshape(S.n, S.n).T, H.toarray())
    indptr, rows = S.block_pattern  # every variable next to every other
    assert np.array_equal(np.diff(indptr), np.full(dims.size, dims.size))
    np.testing.assert_array_equal(rows, np.tile(np.arange(dims.size), dims.size))


def test_single_factor_without_diagonal_only_variables():
    # A variable no edge touches still gets its (zero) diagonal block, ready for damping.
    S = BlockStructure([2, 2, 2], [(np.array([[0, 1]]), 2)])
    H, g = S.normal_equations([np.ones((1, 2, 4))], [np.ones((1, 2))])
    assert H.shape == (6, 6) and np.all(H.toarray()[4:, 4:] == 0) and g.shape == (6,)
    assert np.all(S.add_diagonal(H, 1.0).diagonal()[4:] == 1.0)


# -- bad input ---------------------------------------------------------------


def test_out_of_range_ids_name_factor_and_edge():
    with pytest.raises(ValueError, match=r"factor 1, edge 2, slot 1: variable id 7 is outside \[0, 4\)"):
        BlockStructure([3, 3, 3, 3], [(np.array([[0]]), 3), (np.array([[0, 1], [1, 2], [2, 7]]), 3)])
    with pytest.raises(ValueError, match="factor 0, edge 0, slot 0: variable id -1"):
        BlockStructure([3, 3], [(np.array([[-1, 1]]), 3)])


def test_mixed_slot_dimensions_are_rejected():
    with pytest.raises(ValueError, match=r"factor 0, slot 1: .*dimension 6 \(edge 0\) and 3 \(edge 1, variable 1\)"):
        BlockStructure([3, 3, 6], [(np.array([[0, 2], [0, 1]]), 3)])


@pytest.mark.parametrize(
    ("dims", "factors", "match"),
    [
        ([3, 3], [(np.array([[1, 1]]), 3)], "edge 0: touches variable 1 in two slots"),
        ([3, 3], [(np.zeros((0, 2), dtype=int), 3)], "factor 0: has no edges"),
        ([3, 3], [(np.array([0, 1]), 3)], r"integer array \(m, arity\)"),
        ([3, 3], [(np.array([[0.0, 1.0]]), 3)], r"integer array \(m, arity\)"),
        ([3, 3], [(np.array([[0, 1]]), 0)], "residual_dim must be a positive integer"),
        ([3, 0], [(np.array([[0, 1]]), 3)], "dims must be"),
        ([[3, 3]], [(np.array([[0, 1]]), 3)], "dims must be"),
        ([3, 3], [], "at least one factor type"),
    ],
)
def test_malformed_structures(dims, factors, match):
    with pytest.raises(ValueError, match=match):
        BlockStructure(dims, factors)


def test_wrong_shapes_are_rejected(graph):
    rng, dims, factors, S = graph
    blocks, residuals, weights = random_values(rng, dims, factors)
    m, r, D = blocks[2].shape
    bad = [*blocks[:2], blocks[2][:, :, :-1], *blocks[3:]]
    expected = re.escape(f"blocks[2]: expected shape (m, residual_dim, Σ slot dims) = {(m, r, D)}, got {(m, r, D - 1)}")
    with pytest.raises(ShapeError, match=expected):
        S.normal_equations(bad, residuals)
    with pytest.raises(ShapeError, match=r"blocks\[2\]"):
        S.jacobian(bad)
    with pytest.raises(ValueError, match=f"expected {len(factors)} Jacobian block arrays"):
        S.jacobian(blocks[:-1])
    with pytest.raises(ShapeError, match=r"residuals\[1\]"):
        S.normal_equations(blocks, [residuals[0], residuals[1][:, :-1], *residuals[2:]])
    with pytest.raises(ShapeError, match=r"weights\[0\]"):
        S.normal_equations(blocks, residuals, [weights[0][:-1], *weights[1:]])
    with pytest.raises(ValueError, match="residual arrays"):
        S.normal_equations(blocks, residuals[:-1])
    with pytest.raises(ValueError, match="weight arrays"):
        S.normal_equations(blocks, residuals, weights[:-1])
