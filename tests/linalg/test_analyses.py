"""The pool of symbolic analyses: keys by pattern (or by a structure's blocks), lending, bounds."""

from __future__ import annotations

import gc

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie.linalg import BlockStructure, CholeskySolver
from manopt_lie.linalg._analyses import ANALYSES, AnalysisPool, pattern_key

from .helpers import pose_graph

BACKENDS = CholeskySolver.available_backends()


@pytest.fixture(autouse=True)
def empty_pool():
    ANALYSES.clear()
    yield
    ANALYSES.clear()


def _solve(structure: BlockStructure, blocks, residuals, backend: str) -> tuple[CholeskySolver, np.ndarray]:
    H, g = structure.normal_equations(blocks, residuals)
    solver = CholeskySolver(backend).bind(structure)
    x = solver(H, -g)
    np.testing.assert_allclose(H @ x, -g, rtol=0, atol=1e-10 * np.abs(g).max())
    return solver, x


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_structure_of_the_same_pattern_takes_the_pooled_analysis(backend, rng):
    """Two structures of one graph, built apart, have one digest; the second solve borrows the
    first's analysis once it is returned, and solves alike."""
    s1, blocks, residuals = pose_graph(np.random.default_rng(0), n_poses=30, d=6)
    s2, _, _ = pose_graph(np.random.default_rng(0), n_poses=30, d=6)
    assert s1 is not s2 and s1.pattern_digest() == s2.pattern_digest()
    first, x1 = _solve(s1, blocks, residuals, backend)
    assert ANALYSES.misses == 1 and ANALYSES.hits == 0
    del first
    gc.collect()  # the solver returns its backend when collected
    _, x2 = _solve(s2, blocks, residuals, backend)
    assert ANALYSES.hits == 1 and ANALYSES.misses == 1
    np.testing.assert_allclose(x2, x1, rtol=0, atol=1e-12 * np.abs(x1).max())


def test_a_dense_structure_is_solved_without_the_pool():
    """A small system stored dense has nothing to analyse: its solver neither borrows nor lends,
    keeps its factorization for later solves, and solves as the sparse pattern does."""
    sparse, blocks, residuals = pose_graph(np.random.default_rng(2), n_poses=12, d=3)
    dense = BlockStructure(sparse.dims, [(f.var_ids, f.residual_dim) for f in sparse._factors], dense=True)
    solver = CholeskySolver().bind(dense)
    assert solver.backend == "dense"
    H, g = dense.normal_equations(blocks, residuals)
    x = solver(H, -g)
    assert ANALYSES.misses == 0 and ANALYSES.hits == 0 and len(ANALYSES) == 0
    np.testing.assert_allclose(x, solver.solve(-g), rtol=0, atol=0)
    _, x_sparse = _solve(sparse, blocks, residuals, "dense")
    np.testing.assert_allclose(x, x_sparse, rtol=0, atol=1e-12 * np.abs(x).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_solvers_alive_at_once_each_get_their_own_analysis(backend):
    s, blocks, residuals = pose_graph(np.random.default_rng(1), n_poses=20, d=3)
    a, xa = _solve(s, blocks, residuals, backend)
    b, xb = _solve(s, blocks, residuals, backend)  # a still holds its backend: analysed anew
    assert ANALYSES.misses == 2 and a._impl is not b._impl
    np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-12 * np.abs(xa).max())


def test_digests_tell_patterns_apart():
    chain, star = np.array([[0, 1], [1, 2]]), np.array([[0, 1], [0, 2]])
    base = BlockStructure([3, 3, 3], [(chain, 3)])
    other_dims = BlockStructure([2, 2, 2], [(chain, 3)])
    other_blocks = BlockStructure([3, 3, 3], [(star, 3)])
    digests = {s.pattern_digest() for s in (base, other_dims, other_blocks)}
    assert len(digests) == 3
    assert base.pattern_digest() is base.pattern_digest()  # computed once


def test_keys_of_a_copied_pattern_hash_its_coordinates(rng):
    """A matrix that is not the structure's own (copied arrays) is keyed by its coordinates, so
    equal patterns share a key whoever built them, and the block digest never collides with one."""
    s, blocks, residuals = pose_graph(rng, n_poses=12, d=3)
    H, g = s.normal_equations(blocks, residuals)
    copy = sp.csc_matrix((H.data.copy(), H.indices.copy(), H.indptr.copy()), shape=H.shape)
    k1 = pattern_key("qdldl", copy.indptr, copy.indices)
    k2 = pattern_key("qdldl", H.indptr, H.indices)
    k3 = pattern_key("qdldl", H.indptr, H.indices, s.pattern_digest())
    assert k1 == k2 != k3
    x = CholeskySolver().bind(s)(copy, -g)  # not the bound pattern's arrays: checked and keyed by them
    np.testing.assert_allclose(H @ x, -g, rtol=0, atol=1e-10 * np.abs(g).max())


def test_the_pool_keeps_at_most_its_bounds():
    pool = AnalysisPool(max_idle=2, max_idle_nnz=100)
    keys = [("b", 3, 10 * (i + 1), "", bytes([i])) for i in range(4)]
    for i, key in enumerate(keys[:3]):
        pool.release(key, f"backend {i}")
    assert len(pool) == 2  # the oldest dropped
    assert pool.acquire(keys[0]) is None and pool.acquire(keys[2]) == "backend 2"
    pool.release(("b", 3, 101, "", b"big"), "too big")  # beyond max_idle_nnz alone: not kept
    assert pool.acquire(("b", 3, 101, "", b"big")) is None
    pool.release(keys[3], "backend 3")  # 20 + 40 = 60 ≤ 100 entries
    assert len(pool) == 2 and (pool.hits, pool.misses) == (1, 2)
    pool.clear()
    assert len(pool) == 0 and pool.hits == pool.misses == 0
