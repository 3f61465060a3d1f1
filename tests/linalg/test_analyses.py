"""The pools of symbolic work: analyses keyed by pattern (or by a structure's blocks), lent, bounded;
block structures keyed by a graph, shared among its problems, bounded."""

from __future__ import annotations

import gc
import threading
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from manopt_lie.linalg import BlockStructure, CholeskySolver, clear_caches
from manopt_lie.linalg._analyses import ANALYSES, STRUCTURES, AnalysisPool, StructureInputs, StructurePool, pattern_key
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt
from manopt_lie.problems import synthetic

from .helpers import pose_graph

BACKENDS = CholeskySolver.available_backends()


@pytest.fixture(autouse=True)
def empty_pool():
    clear_caches()
    yield
    clear_caches()


def _solve(structure: BlockStructure, blocks, residuals, backend: str) -> tuple[CholeskySolver, np.ndarray]:
    H, g = structure.normal_equations(blocks, residuals)
    solver = CholeskySolver(backend).bind(structure)
    x = solver(H, -g)
    np.testing.assert_allclose(H @ x, -g, rtol=0, atol=1e-10 * np.abs(g).max())
    return solver, x


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_structure_of_the_same_pattern_takes_the_pooled_analysis(backend, rng):
    """Two structures of one graph, built apart, have one key; the second solve borrows the
    first's analysis once it is returned, and solves alike."""
    s1, blocks, residuals = pose_graph(np.random.default_rng(0), n_poses=30, d=6)
    s2, _, _ = pose_graph(np.random.default_rng(0), n_poses=30, d=6)
    assert s1 is not s2 and s1._inputs == s2._inputs and s1.pattern_digest() == s2.pattern_digest()
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


def test_a_structure_is_keyed_by_its_own_copy_of_the_inputs():
    """A structure's key is its inputs, held in its own read-only copies: equal (and of one hash)
    for equal inputs, unchanged when the caller's arrays change after. The same pattern listed in
    another edge order is another key with the same pattern digest."""
    chain = np.array([[0, 1], [1, 2]])
    a, b = (BlockStructure([3, 3, 3], [(chain, 3)]) for _ in range(2))
    assert a._inputs == b._inputs and hash(a._inputs) == hash(b._inputs)
    assert a._inputs == StructureInputs(np.array([3, 3, 3]), [(chain, 3)], False)
    chain[1] = [0, 2]  # the caller's array, changed
    assert a._inputs == b._inputs != StructureInputs(np.array([3, 3, 3]), [(chain, 3)], False)
    assert not a.dims.flags.writeable and not a._factors[0].var_ids.flags.writeable
    reordered = BlockStructure([3, 3, 3], [(np.array([[1, 2], [0, 1]]), 3)])
    assert reordered._inputs != a._inputs and reordered.pattern_digest() == a.pattern_digest()


def test_shared_structures_come_from_the_pool():
    """``BlockStructure.shared``: one structure for equal inputs (lists or arrays alike), another for
    other inputs or the dense flag, a new one after ``clear_caches``; keyed by its own copy of the
    inputs, not by the caller's arrays."""
    chain = np.array([[0, 1], [1, 2]])
    first = BlockStructure.shared(np.array([3, 3, 3]), [(chain, 3)])
    assert BlockStructure.shared([3, 3, 3], [(chain.tolist(), 3)]) is first and STRUCTURES.hits == 1
    chain[0, 0] = 2  # the array the pool was given, changed: the pooled key (the structure's copy) is not
    assert BlockStructure.shared([3, 3, 3], [([[0, 1], [1, 2]], 3)]) is first and STRUCTURES.hits == 2
    others = [BlockStructure.shared([3, 3, 3], [(chain, 3)]), BlockStructure.shared([3, 3, 3], [(chain[:1], 3)]),
              BlockStructure.shared([3, 3, 3], [(chain, 3)], dense=True)]  # fmt: skip
    assert all(o is not first for o in others) and len(STRUCTURES) == 4
    clear_caches()
    assert BlockStructure.shared([3, 3, 3], [(chain, 3)]) is not first
    with pytest.raises(ValueError, match="edge 1, slot 1: variable id 3"):  # the constructor's check
        BlockStructure.shared([3, 3, 3], [(chain + np.array([[0, 0], [0, 1]]), 3)])
    assert len(STRUCTURES) == 1  # nothing kept for it


def test_keys_of_a_copied_pattern_hash_its_coordinates(rng):
    """A matrix that is not the structure's own (copied arrays) is keyed by its coordinates, so
    equal patterns share a key whoever built them, and the block digest never collides with one."""
    s, blocks, residuals = pose_graph(rng, n_poses=12, d=3)
    H, g = s.normal_equations(blocks, residuals)
    copy = sp.csc_matrix((H.data.copy(), H.indices.copy(), H.indptr.copy()), shape=H.shape)
    k1 = pattern_key("qdldl", copy.indptr, copy.indices)
    k2 = pattern_key("qdldl", H.indptr, H.indices)
    k3 = pattern_key("qdldl", H.indptr, H.indices, s._inputs)
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


PYTHON_LOOP = LevenbergMarquardt(damping="diagonal")
"""An optimizer that runs its Python loop, which builds the problem's structure, also on a small pose
graph (whose iterations the default ones run compiled, without one)."""


def _grid(seed: int, rows: int = 6):
    return synthetic.grid2d(rows, 6, loop_closure_probability=1.0, seed=seed).graph  # every closure: one edge set


def _anchored(graph, anchor: int) -> LeastSquaresProblem:
    """The graph's geodesic problem with another variable fixed."""
    return LeastSquaresProblem(graph.manifold, list(graph.problem("geodesic").factors), fixed=[anchor])


@pytest.mark.parametrize("rows", [3, 12])  # 54 unknowns (dense H) and 216 (sparse)
def test_problems_of_one_graph_share_its_structure_and_solve_alike(rows):
    """A second problem of the same edges — here with other measurements and another anchor —
    takes the first one's structure from the pool, and its solve equals a cold one's."""
    graph, other = _grid(0, rows), _grid(1, rows)
    assert np.array_equal(graph.edges, other.edges)
    assert not np.allclose(graph.measurements.as_matrix(), other.measurements.as_matrix())
    first = graph.problem("geodesic")
    x0 = graph.chordal_initialization()
    PYTHON_LOOP.solve(first, x0)
    assert (STRUCTURES.misses, STRUCTURES.hits) == (1, 0)
    second = _anchored(other, 3)
    y0 = other.chordal_initialization()
    warm = PYTHON_LOOP.solve(second, y0)
    assert second.structure is first.structure and STRUCTURES.hits == 1
    clear_caches()
    cold_problem = _anchored(other, 3)
    cold = PYTHON_LOOP.solve(cold_problem, y0)
    assert cold_problem.structure is not first.structure
    assert warm.nit == cold.nit and warm.fun == cold.fun  # the same arithmetic, bit for bit


def test_problems_in_threads_share_one_structure():
    """Problems of one graph solved in threads at once: one structure (built once), every solve
    as the one alone."""
    graph = _grid(2, 8)
    x0 = graph.chordal_initialization()
    alone = PYTHON_LOOP.solve(graph.problem("geodesic"), x0)
    problems = [graph.problem("geodesic") for _ in range(4)]
    results: list = [None] * 4

    def run(i: int) -> None:
        results[i] = PYTHON_LOOP.solve(problems[i], x0)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(p.structure is problems[0].structure for p in problems) and STRUCTURES.misses == 1
    assert all(r.fun == alone.fun and r.nit == alone.nit for r in results)


def test_structure_keys_tell_graphs_apart():
    """The key of the structure's inputs changes with the dimensions, the edges (also edges of the
    same bytes in another shape), a residual length and the dense flag; equal values in another
    integer dtype are the same key."""
    dims = np.array([3, 3, 3, 3])
    chain = np.array([[0, 1], [1, 2], [2, 3]])
    flat = chain.reshape(-1, 1)  # the same bytes as unary edges
    keys = {
        StructureInputs(dims, [(chain, 3)], False),
        StructureInputs(np.array([2, 2, 2, 2]), [(chain, 3)], False),
        StructureInputs(dims, [(chain[::-1].copy(), 3)], False),
        StructureInputs(dims, [(flat, 3)], False),
        StructureInputs(dims, [(chain, 2)], False),
        StructureInputs(dims, [(chain, 3)], True),
        StructureInputs(dims, [(chain, 3), (chain, 3)], False),
        StructureInputs(np.array([3, 2, 3, 3]), [(chain, 3)], False),
        StructureInputs(np.array([3, 3, 2, 3]), [(chain, 3)], False),
        StructureInputs(dims, [(chain + np.array([0, 2**32]), 3)], False),  # not hashed as its 32-bit wrap
    }
    assert len(keys) == 10
    assert StructureInputs(dims, [(chain, 3)], False) == StructureInputs(dims.copy(), [(chain.copy(), 3)], False)
    narrow = StructureInputs(dims.astype(np.int32), [(chain.astype(np.int32), 3)], False)
    assert StructureInputs(dims, [(chain, 3)], False) == narrow


def test_the_structure_pool_keeps_at_most_its_bounds():
    pool = StructurePool(max_kept=2, max_kept_nnz=100)
    keys = [StructureInputs(np.array([i + 1]), [(np.zeros((1, 1), int), 1)], False) for i in range(5)]
    made = [SimpleNamespace(nnz=10 * (i + 1), _inputs=keys[i]) for i in range(4)]
    for i in range(3):
        assert pool.get(keys[i], lambda i=i: made[i]) is made[i]  # type: ignore[arg-type,return-value]
    assert len(pool) == 2 and pool.misses == 3  # the least recently used dropped
    assert pool.get(keys[2], lambda: None) is made[2] and pool.hits == 1  # type: ignore[arg-type,return-value]
    big = SimpleNamespace(nnz=101, _inputs=keys[4])
    assert pool.get(keys[4], lambda: big) is big and keys[4] not in pool  # type: ignore[arg-type,return-value]
    pool.get(keys[3], lambda: made[3])  # type: ignore[arg-type,return-value]  # 30 + 40 ≤ 100: kept beside the most recent
    assert set(pool._kept) == {keys[2], keys[3]}
    pool.clear()
    assert len(pool) == 0 and pool.hits == pool.misses == 0


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5)), min_size=1, max_size=6),
    st.lists(st.tuples(st.integers(0, 5), st.integers(0, 5)), min_size=1, max_size=6),
    st.integers(1, 3),
    st.integers(1, 3),
)
def test_structure_keys_agree_exactly_when_the_inputs_do(edges_a, edges_b, r_a, r_b):
    dims = np.full(6, 3)
    a, b = np.array(edges_a), np.array(edges_b)
    same = a.shape == b.shape and np.array_equal(a, b) and r_a == r_b
    assert (StructureInputs(dims, [(a, r_a)], False) == StructureInputs(dims, [(b, r_b)], False)) == same
