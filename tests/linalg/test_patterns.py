"""A solve's set-up in compiled code (``linalg._patterns``, ``patterns.c``) against the NumPy builds
it replaces, AMD called directly against CVXOPT's interface, and CHOLMOD's factor of ``B = P H Pᵀ``
made from the variables' analysis (``Cholmod._expand``) against CHOLMOD's analysis of ``B``."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie.linalg import BlockStructure, CholeskySolver, _amd, _cholmod, _patterns, structure
from manopt_lie.linalg._factors import coordinates, same_buffer
from manopt_lie.linalg._triangles import permuted_block_triangle
from manopt_lie.linalg.selected_inverse import _cholmod_factor

from .helpers import assert_same_structure, pose_graph, random_factor_graph, random_values

compiled = pytest.mark.skipif(_patterns._library() is None, reason="no C compiler here")
direct = pytest.mark.skipif(not _cholmod.available(), reason="CHOLMOD cannot be called directly here")


def with_ternary(rng: np.random.Generator, n_vars: int) -> tuple[np.ndarray, list[tuple[np.ndarray, int]]]:
    """:func:`random_factor_graph` and a factor type of arity 3 on the 3-dimensional variables."""
    dims, factors = random_factor_graph(rng, n_vars=n_vars)
    small = np.flatnonzero(dims == 3)
    triples = np.stack([rng.permutation(small)[:3] for _ in range(6)])
    return dims, [*factors, (triples, 5)]


def numpy_structure(monkeypatch: pytest.MonkeyPatch, dims: np.ndarray, factors: list, **kwargs) -> BlockStructure:
    with monkeypatch.context() as m:
        m.setattr(structure, "hessian_pattern", lambda *args: None)
        return BlockStructure(dims, factors, **kwargs)


@compiled
@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_structure_is_numpys(monkeypatch, seed):
    """Pattern, block pattern, diagonal positions and both scatters: the same arrays, the same
    dtypes; hence the same ``H`` and ``g`` bit for bit."""
    rng = np.random.default_rng(seed)
    dims, factors = with_ternary(rng, n_vars=int(rng.integers(9, 60)))
    made, reference = BlockStructure(dims, factors), numpy_structure(monkeypatch, dims, factors)
    assert_same_structure(made, reference)
    blocks, residuals, weights = random_values(rng, dims, factors)
    (H1, g1), (H2, g2) = (s.normal_equations(blocks, residuals, weights) for s in (made, reference))
    np.testing.assert_array_equal(H1.data, H2.data)
    np.testing.assert_array_equal(g1, g2)


@compiled
@pytest.mark.parametrize(
    ("edges", "match"),
    [
        (np.array([[0, 1, 2], [3, 4, 3]]), "factor 1, edge 1: touches variable 3 in two slots"),
        (np.array([[0, 1, 2], [3, 4, 9]]), r"factor 1, edge 1, slot 2: variable id 9 is outside \[0, 6\)"),
        (np.array([[0, 1, 2], [-2, 4, 5]]), "factor 1, edge 1, slot 0: variable id -2"),
    ],
)
@pytest.mark.parametrize("build", ["compiled", "numpy", "dense"])
def test_every_build_names_the_bad_edge(monkeypatch, edges, match, build):
    """The compiled build checks the edges in its own pass and leaves the message to NumPy's checks:
    the same error as where NumPy builds (no compiler) or the structure is dense."""
    if build == "numpy":
        monkeypatch.setattr(_patterns, "_library", lambda: None)
    with pytest.raises(ValueError, match=match):
        BlockStructure(np.full(6, 3), [(np.array([[0, 1]]), 3), (edges, 2)], dense=build == "dense")


@compiled
@pytest.mark.parametrize("repeats", [False, True], ids=["distinct pairs", "repeated pairs"])
def test_h_holds_the_structures_own_index_arrays(rng, repeats):
    """``H`` keeps the structure's ``indptr`` and ``indices`` themselves (SciPy copies a view of a
    larger buffer), so a solver bound to the structure trusts the pattern: it analyses the blocks
    and takes the early analysis, not CHOLMOD's analysis of the pattern as it is."""
    dims, factors = random_factor_graph(rng, n_vars=12)
    if not repeats:  # a chain: no two edges on one pair, H's room exactly filled
        dims = np.full(12, 3)
        factors = [(np.stack([np.arange(11), np.arange(1, 12)], axis=1), 3)]
    S = BlockStructure(dims, factors)
    blocks, residuals, weights = random_values(rng, dims, factors)
    H, g = S.normal_equations(blocks, residuals, weights)
    for mine, held in ((S.indptr, H.indptr), (S.indices, H.indices)):
        assert same_buffer(mine, held) and mine.base is None
    solver = CholeskySolver().bind(S)
    H.data[S.diagonal_positions] += 1.0
    solver(H, -g)
    assert solver._trusted is not None and solver.matches(H)
    assert same_buffer(solver._indptr, S.indptr) and same_buffer(solver._indices, S.indices)


@compiled
@pytest.mark.parametrize("upper", [False, True], ids=["lower", "upper"])
def test_the_compiled_triangle_is_numpys(rng, upper):
    dims, factors = with_ternary(rng, n_vars=40)
    S = BlockStructure(dims, factors)
    for order in (np.arange(dims.size), rng.permutation(dims.size), S.variable_ordering()):
        made = _patterns.permuted_block_triangle(S.indptr, S.dims, *S.block_pattern, order, upper)
        assert made is not None
        triangle, perm = made
        numpys = permuted_block_triangle(S.indptr, S.dims, *S.block_pattern, order, upper)
        for a, b in zip(triangle, numpys, strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(perm, coordinates(S.offsets, S.dims, order))


def test_without_compiled_code_numpy_builds_the_structure(monkeypatch, rng):
    """No compiler: ``hessian_pattern`` and the triangle decline, and the NumPy builds serve."""
    monkeypatch.setattr(_patterns, "_library", lambda: None)
    dims, factors = random_factor_graph(rng)
    assert _patterns.hessian_pattern(np.asarray(dims), int(dims.sum()), int(np.dot(dims, dims)), []) is None
    S = BlockStructure(dims, factors)
    assert _patterns.permuted_block_triangle(S.indptr, S.dims, *S.block_pattern, np.arange(dims.size)) is None
    blocks, residuals, _ = random_values(rng, dims, factors)
    H, _ = S.normal_equations(blocks, residuals)
    assert H.nnz == S.nnz and S._hess_scatter[0].whole is not None


@pytest.mark.skipif(_amd._library() is None, reason="AMD cannot be called directly here")
@pytest.mark.parametrize("seed", range(4))
def test_amd_called_directly_orders_as_cvxopt(seed):
    from cvxopt import amd, matrix, spmatrix

    dims, factors = random_factor_graph(np.random.default_rng(seed), n_vars=150)
    indptr, rows = BlockStructure(dims, factors).block_pattern
    cols = np.repeat(np.arange(dims.size), np.diff(indptr))
    lower = rows >= cols
    pattern = spmatrix(1.0, matrix(rows[lower].astype(np.int64)), matrix(cols[lower].astype(np.int64)),
                       (dims.size, dims.size))  # fmt: skip
    np.testing.assert_array_equal(_amd.amd_order(indptr, rows), np.asarray(amd.order(pattern, "L")).ravel())
    assert _amd.amd_order(indptr.astype(np.int64), rows.astype(np.int64)) is None  # 32-bit indices only
    # 64-bit indices: through CVXOPT's interface, the same order.
    np.testing.assert_array_equal(_amd.variable_order(indptr.astype(np.int64), rows.astype(np.int64)),
                                  _amd.amd_order(indptr, rows))  # fmt: skip


def _factor(S: BlockStructure, supernodal: bool | None) -> _cholmod.Cholmod:
    return _cholmod.Cholmod(S.indptr, S.indices, S.fill_reducing_ordering(), supernodal, (S.dims, *S.block_pattern),
                            variables=S.variable_ordering())  # fmt: skip


def _analysed(monkeypatch: pytest.MonkeyPatch, S: BlockStructure, supernodal: bool | None) -> _cholmod.Cholmod:
    """The factor from CHOLMOD's analysis of ``B`` itself (the expansion declined)."""
    with monkeypatch.context() as m:
        m.setattr(_cholmod.Cholmod, "_expand", lambda *args: False)
        return _factor(S, supernodal)


@direct
@compiled
@pytest.mark.parametrize("supernodal", [True, False, None], ids=["supernodal", "simplicial", "auto"])
@pytest.mark.parametrize(("d", "n_poses"), [(2, 300), (3, 200), (6, 120)])
def test_the_factor_from_the_variables_is_the_analysis_of_b(monkeypatch, rng, supernodal, d, n_poses):
    """Made from the variables' analysis, the factor has the order, kind and cost of CHOLMOD's analysis
    of ``B`` and (supernodal) about its size; its ``L`` is the Cholesky factor of ``P H Pᵀ``; its
    solves are ``H``'s, also after factorizations of other values and for many right-hand sides."""
    S, blocks, residuals = pose_graph(rng, n_poses=n_poses, d=d)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)
    made, analysed = _factor(S, supernodal), _analysed(monkeypatch, S, supernodal)
    assert made.supernodal == analysed.supernodal and (supernodal is None or made.supernodal is supernodal)
    assert made.cost == analysed.cost
    np.testing.assert_array_equal(made.permutation(), analysed.permutation())
    if made.supernodal:  # amalgamated alike: about the same entries stored
        assert made._factor().xsize <= 1.02 * analysed._factor().xsize
    dense = H.toarray()
    perm = made.permutation()
    for scale in (1.0, 3.0):
        made.factorize(scale * H.data)
        np.testing.assert_allclose(made.solve(g), np.linalg.solve(scale * dense, g), rtol=1e-8, atol=1e-12)
    L = _cholmod_factor(made, 3.0 * H).L.toarray()
    expected = np.linalg.cholesky(3.0 * dense[np.ix_(perm, perm)])
    np.testing.assert_allclose(L, expected, rtol=1e-9, atol=1e-9 * abs(expected).max())
    many = rng.standard_normal((S.n, 4))
    np.testing.assert_allclose(made.solve(many), np.linalg.solve(3.0 * dense, many), rtol=1e-8, atol=1e-12)


@direct
@compiled
def test_large_supernodes_factor_right(rng):
    """SE(3)-sized blocks on a graph with fill (a grid with long chords): the expanded supernodes
    and the update workspaces CHOLMOD sizes from them hold a factorization of ``H``."""
    n = 400
    grid = [(i, i + 1) for i in range(n - 1) if (i + 1) % 20] + [(i, i + 20) for i in range(n - 20)]
    chords = [tuple(rng.choice(n, 2, replace=False)) for _ in range(40)]
    edges = np.array(grid + chords)
    S = BlockStructure(np.full(n, 6), [(edges, 6), (np.zeros((1, 1), dtype=int), 6)])
    blocks = [rng.standard_normal((len(edges), 6, 12)), np.eye(6)[None]]
    H, g = S.normal_equations(blocks, [rng.standard_normal((len(edges), 6)), np.zeros((1, 6))])
    S.add_diagonal(H, 1e-3, inplace=True)
    factor = _factor(S, True)
    assert factor.supernodal and factor._factor().nsuper > 1
    factor.factorize(H.data)
    x = factor.solve(g)
    assert np.linalg.norm(H @ x - g) <= 1e-9 * np.linalg.norm(g)
    np.testing.assert_allclose(x, sp.linalg.spsolve(H.tocsc(), g), rtol=1e-6, atol=1e-9)


@direct
def test_mixed_dimensions_and_a_declined_expansion_analyse_b(monkeypatch, rng):
    """Variables of dimensions 3 and 6 are not expanded (the column counts of ``B`` do not follow
    from the variables'); an expansion that cannot be made (an index past 32 bits) frees what it
    allocated and leaves the analysis of ``B``. Both factor right."""
    dims, factors = random_factor_graph(rng, n_vars=45)
    S = BlockStructure(dims, factors)
    calls = []
    monkeypatch.setattr(_cholmod.Cholmod, "_expand", lambda *args: calls.append(args) or False)
    _factor(S, None)
    assert not calls
    monkeypatch.undo()
    graph, blocks, residuals = pose_graph(rng, n_poses=80, d=3)
    H, g = graph.normal_equations(blocks, residuals)
    monkeypatch.setattr(_cholmod.Cholmod, "_expand_supernodes", lambda *args: False)
    for supernodal in (True, False):
        factor = _factor(graph, supernodal)
        assert factor.supernodal is supernodal
        factor.factorize(H.data)
        np.testing.assert_allclose(factor.solve(g), np.linalg.solve(H.toarray(), g), rtol=1e-8, atol=1e-12)


@compiled
def test_blocks_that_do_not_make_the_pattern_are_refused(rng):
    """The triangle is built from the blocks into arrays sized by ``H``'s pattern: blocks of another
    pattern (here more of them) raise instead of writing past those arrays."""
    graph, _, _ = pose_graph(rng, n_poses=30, d=3)
    chain = BlockStructure(np.full(30, 3), [(np.stack([np.arange(29), np.arange(1, 30)], axis=1), 3)])
    with pytest.raises(ValueError, match="do not make H's pattern"):
        _patterns.permuted_block_triangle(chain.indptr, graph.dims, *graph.block_pattern, np.arange(30))


@direct
@compiled
@pytest.mark.parametrize("supernodal", [True, False], ids=["supernodal", "simplicial"])
def test_a_factor_made_from_the_variables_refuses_an_indefinite_h_and_recovers(rng, supernodal):
    """A failed factorization (a negative pivot) raises, leaves the made factor usable for the next
    values (LM's larger damping) and freeable."""
    from manopt_lie.linalg import SingularSystemError

    S, blocks, residuals = pose_graph(rng, n_poses=40, d=3)
    H, g = S.normal_equations(blocks, residuals)
    factor = _factor(S, supernodal)
    bad = H.data.copy()
    bad[S.diagonal_positions[5]] = -100.0
    with pytest.raises(SingularSystemError, match="not positive definite"):
        factor.factorize(bad)
    S.add_diagonal(H, 1.0, inplace=True)
    factor.factorize(H.data)
    np.testing.assert_allclose(factor.solve(g), np.linalg.solve(H.toarray(), g), rtol=1e-8, atol=1e-12)
    del factor


def _is_postorder(parent: np.ndarray) -> bool:
    """Whether the forest ``parent`` (−1 at roots) is numbered in a postorder: the descendants of
    every node ``j`` are the nodes just before it, ``j − s + 1 … j − 1`` for a subtree of ``s``."""
    n = parent.size
    descendants: list[set[int]] = [set() for _ in range(n)]
    for i in range(n):
        j = parent[i]
        while j != -1:
            if j <= i:
                return False
            descendants[j].add(i)
            j = parent[j]
    return all(descendants[j] == set(range(j - len(descendants[j]), j)) for j in range(n))


@compiled
@pytest.mark.parametrize("seed", range(4))
def test_the_variables_symbolic_factorization_is_the_elimination_by_hand(seed):
    """``block_symbolic``: a postorder of the elimination tree of the variables' graph in the given
    order, and the blocks of each column of ``L``, as eliminating a dense boolean matrix finds them."""
    rng = np.random.default_rng(seed)
    dims, factors = random_factor_graph(rng, n_vars=int(rng.integers(20, 80)))
    S = BlockStructure(dims, factors)
    indptr, rows = S.block_pattern
    order = S.variable_ordering()
    found = _patterns.block_symbolic(indptr, rows, order)
    assert found is not None
    variables, counts = found
    assert sorted(variables) == list(range(dims.size))
    nv = dims.size
    a = np.zeros((nv, nv), dtype=bool)
    a[rows, np.repeat(np.arange(nv), np.diff(indptr))] = True
    a = a[np.ix_(variables, variables)]
    parent = np.full(nv, -1)
    for k in range(nv):
        below = k + 1 + np.flatnonzero(a[k + 1 :, k])
        assert counts[k] == below.size + 1
        if below.size:
            parent[k] = below[0]
        a[np.ix_(below, below)] = True
    assert _is_postorder(parent)


@direct
@compiled
def test_a_factor_filling_in_past_the_budget_is_analysed_by_cholmod(monkeypatch, rng):
    """Past ``SIMPLICIAL_FILL`` blocks of ``L`` per block of ``H`` the variables' analysis is
    CHOLMOD's: the same factor."""
    S, blocks, residuals = pose_graph(rng, n_poses=120, d=3)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)
    ours = _factor(S, False)
    monkeypatch.setattr(_patterns, "SIMPLICIAL_FILL", 0)
    assert _patterns.block_symbolic(*S.block_pattern, S.variable_ordering()) is None
    theirs = _factor(S, False)
    assert ours.cost == theirs.cost
    for factor in (ours, theirs):
        factor.factorize(H.data)
        np.testing.assert_allclose(factor.solve(g), np.linalg.solve(H.toarray(), g), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("side", [8, 4], ids=["SE(2) grid, simplicial", "SE(3) cube, supernodal"])
def test_a_solve_without_compiled_set_up_gives_the_same_result(monkeypatch, side):
    """LM on a synthetic pose graph past the compiled loop's sizes, set up in compiled code and
    without it (NumPy's structure, CHOLMOD's analyses): the same iterations, cost and point."""
    from manopt_lie.linalg import clear_caches
    from manopt_lie.optim import LevenbergMarquardt
    from manopt_lie.problems import synthetic

    class PythonLoop(LevenbergMarquardt):  # a subclass runs the Python loop at any size
        pass

    made = synthetic.grid2d(side * 4, side * 4, seed=1) if side == 8 else synthetic.cube(side, seed=1)
    x0 = made.graph.chordal_initialization()
    runs = []
    for library in (_patterns._library, lambda: None):
        monkeypatch.setattr(_patterns, "_library", library)
        clear_caches()
        problem = made.graph.problem("geodesic")
        runs.append(PythonLoop(rel_cost_decrease=1e-5).solve(problem, x0))
    monkeypatch.undo()
    clear_caches()
    (a, b), group = runs, made.graph.group
    assert a.nit == b.nit and a.fun == pytest.approx(b.fun, rel=1e-12)
    np.testing.assert_allclose(group.as_matrix(a.x), group.as_matrix(b.x), atol=1e-9)
