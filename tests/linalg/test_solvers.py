"""CholeskySolver (every available backend) and PCG: accuracy, reuse of the analysis, singular systems."""

from __future__ import annotations

import platform

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie import ShapeError
from manopt_lie.linalg import (
    BlockStructure,
    CholeskySolver,
    SingularSystemError,
    _backends,
    _cholmod,
    _memory,
    _triangles,
    block_jacobi,
    pcg_solve,
)
from manopt_lie.linalg._analyses import ANALYSES

from .helpers import pose_graph, random_factor_graph, random_values

BACKENDS = CholeskySolver.available_backends()


def cholesky_factor_of(impl) -> sp.csc_matrix:
    """CHOLMOD's numeric factor ``L`` (as CVXOPT packs it) of a factorized backend."""
    colptr, rowind, values = impl._cholmod.getfactor(impl._factor).CCS
    n = len(colptr) - 1
    return sp.csc_matrix((np.asarray(values).ravel(), np.asarray(rowind).ravel(), np.asarray(colptr).ravel()), (n, n))


@pytest.fixture(params=BACKENDS)
def solver(request):
    return CholeskySolver(request.param)


@pytest.fixture
def system(rng):
    S, blocks, residuals = pose_graph(rng, n_poses=60, d=6)
    H, g = S.normal_equations(blocks, residuals)
    return S, blocks, residuals, H, g


def test_auto_prefers_the_fastest_available_backend():
    assert CholeskySolver().backend == BACKENDS[0]
    assert BACKENDS[-2:] == ("superlu", "dense")


@pytest.mark.parametrize("n_poses", [4, 60])
def test_auto_binds_small_structures_to_the_dense_backend(rng, n_poses):
    """A bound solver of an automatic backend factors systems of order ≤ DENSE_MAX dense,
    with the same solution; a backend asked for by name, or supernodes, stay sparse."""
    S, blocks, residuals = pose_graph(rng, n_poses=n_poses, d=3)
    H, g = S.normal_equations(blocks, residuals)
    small = S.n <= _backends.DENSE_MAX
    assert small == (n_poses == 4)
    bound = CholeskySolver().bind(S)
    assert bound.backend == ("dense" if small else BACKENDS[0])
    x_ref = np.linalg.solve(H.toarray(), g)
    assert np.linalg.norm(bound(H, g) - x_ref) <= 1e-10 * np.linalg.norm(x_ref)
    for template in (CholeskySolver(BACKENDS[0]), CholeskySolver(supernodal=True)):
        assert template.bind(S).backend == BACKENDS[0]


def test_solves_spd_systems(solver, system):
    _, _, _, H, g = system
    x = solver(H, g)
    x_ref = np.linalg.solve(H.toarray(), g)
    assert np.linalg.norm(x - x_ref) <= 1e-10 * np.linalg.norm(x_ref)


def test_mixed_dimension_graph(solver, rng):
    dims, factors = random_factor_graph(rng)
    S = BlockStructure(dims, factors)
    blocks, residuals, weights = random_values(rng, dims, factors)
    H, g = S.normal_equations(blocks, residuals, weights)
    H = S.add_diagonal(H, 1.0)  # random small graphs may leave variables unconstrained
    x_ref = np.linalg.solve(H.toarray(), g)
    assert np.linalg.norm(solver(H, g) - x_ref) <= 1e-10 * np.linalg.norm(x_ref)


def test_analysis_is_reused_while_the_pattern_is_fixed(solver, system, rng):
    S, blocks, residuals, H, g = system
    solver(H, g)
    for lam in (1e-3, 1e-1, 10.0):
        H_damped = S.add_diagonal(H, lam * H.diagonal())
        x = solver(H_damped, g)
        assert np.linalg.norm(H_damped @ x - g) <= 1e-10 * np.linalg.norm(g)
    H2, g2 = S.normal_equations([b * rng.uniform(0.5, 2.0) for b in blocks], residuals)
    solver(H2, g2)
    assert solver.n_analyses == 1
    # A copy with equal arrays (not the same objects) is recognised too.
    solver(sp.csc_matrix((H.data, H.indices.copy(), H.indptr.copy()), shape=H.shape), g)
    assert solver.n_analyses == 1
    other, other_blocks, other_res = pose_graph(rng, n_poses=30, d=3)
    solver(*other.normal_equations(other_blocks, other_res))
    assert solver.n_analyses == 2


def test_phases_can_be_called_separately(solver, system):
    S, _, _, H, g = system
    with pytest.raises(RuntimeError, match="factorize"):
        solver.solve(g)
    solver.analyze(H)
    solver.factorize(S.add_diagonal(H, 1.0))
    x1 = solver.solve(g)
    x2 = solver.solve(2 * g)
    np.testing.assert_allclose(x2, 2 * x1, rtol=1e-12)
    with pytest.raises(ValueError, match="analysed sparsity pattern"):
        solver.factorize(sp.identity(S.n, format="csc"))
    with pytest.raises(ShapeError, match=r"b: expected shape \(360,\)"):
        solver.solve(g[:-1])


def test_a_call_leaves_the_factorization_for_more_solves(solver, system):
    """``solver(H, b)`` (the dense backend: factorization, probe and ``b`` in one pass) keeps its
    factorization: ``solve`` applies it to other right-hand sides."""
    _, _, _, H, g = system
    x = solver(H, g)
    np.testing.assert_allclose(H @ x, g, rtol=0, atol=1e-8 * np.linalg.norm(g))
    np.testing.assert_allclose(solver.solve(-3 * g), -3 * x, rtol=0, atol=1e-12 * np.abs(x).max())


@pytest.mark.parametrize("d", [3, 6])
def test_unanchored_pose_graph_is_singular(solver, rng, d):
    S, blocks, residuals = pose_graph(rng, n_poses=40, d=d, anchor=False)
    H, g = S.normal_equations(blocks, residuals)
    with pytest.raises(SingularSystemError, match="fix the gauge") as err:
        solver(H, g)
    assert "never return a garbage step" in str(err.value)
    assert isinstance(err.value, ValueError)


@pytest.mark.parametrize(
    ("dense", "b"),
    [
        (np.array([[1.0, 1.0], [1.0, 1.0]]), np.ones(2)),  # exactly singular, consistent right-hand side
        (np.diag([2.0, -1.0, 3.0]), np.ones(3)),  # indefinite: bᵀH⁻¹b < 0
        (np.array([[1.0, 2.0], [2.0, 1.0]]), np.array([1.0, -1.0])),  # indefinite, nonzero pivots
    ],
)
def test_singular_or_indefinite_matrices_raise(solver, dense, b):
    with pytest.raises(SingularSystemError, match="singular or indefinite"):
        solver(sp.csc_matrix(dense), b)


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="needs cvxopt (CHOLMOD)")
@pytest.mark.parametrize("n", [30, 3000], ids=["simplicial", "larger"])
def test_cholmod_reads_the_pivot_signs_of_its_ldlt(n):
    """CHOLMOD factors sparse matrices as LDLᵀ, which an indefinite matrix does not make fail:
    one negative pivot among many, with a right-hand side and probe of positive curvature, is
    still refused (from the signs of D), and an SPD matrix of the same pattern is solved."""
    off = np.full(n - 1, 0.5)
    values = np.full(n, 2.0)
    values[n // 2] = -1.0
    indefinite = sp.diags([off, values, off], [-1, 0, 1], format="csc")
    b = np.ones(n)
    with pytest.raises(SingularSystemError, match="pivots of LDLᵀ"):
        CholeskySolver("cholmod")(indefinite, b)
    values[n // 2] = 2.0
    spd = sp.diags([off, values, off], [-1, 0, 1], format="csc")
    x = CholeskySolver("cholmod")(spd, b)
    assert np.linalg.norm(spd @ x - b) <= 1e-12 * n


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="needs cvxopt (CHOLMOD)")
def test_cholmod_kind_can_be_chosen(rng):
    """``supernodal=True`` forces CHOLMOD's LLᵀ (no pivots D), ``False`` its LDLᵀ, on a pattern
    its own choice would factor simplicially; both solve alike, and their analyses are pooled apart."""
    S, blocks, residuals = pose_graph(rng, n_poses=60, d=3)
    H, g = S.normal_equations(blocks, residuals)
    x = {}
    for kind in (True, False, None):
        solver = CholeskySolver("cholmod", supernodal=kind).bind(S)
        x[kind] = solver(H, g)
        assert solver.supernodal is kind and (solver._impl.pivots is None) == (kind is True)
    for kind in (False, None):
        assert np.linalg.norm(x[kind] - x[True]) <= 1e-8 * np.linalg.norm(x[True])


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
def test_cholmod_factors_six_dimensional_variables_by_supernodes(rng):
    """Left to choose, a solver bound to a structure of 3-D poses (d = 6) asks CHOLMOD for
    supernodes (no pivots D: LLᵀ); d = 3 stays CHOLMOD's choice (here LDLᵀ); an explicit kind wins."""
    for d, expected in ((6, True), (3, None)):
        S, blocks, residuals = pose_graph(rng, n_poses=60, d=d)
        H, g = S.normal_equations(blocks, residuals)
        solver = CholeskySolver("cholmod").bind(S)
        solver(H, g)
        assert solver.supernodal is expected
        assert (solver._impl.pivots is None) == (d == 6)
    explicit = CholeskySolver("cholmod", supernodal=False).bind(S)
    assert explicit.supernodal is False


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
@pytest.mark.parametrize("chunk", [7, 100, 1 << 16])
def test_cholmod_builds_its_lower_triangle_in_pieces(rng, monkeypatch, chunk):
    """CVXOPT's copy of the lower triangle, joined from pieces of ``chunk`` entries (one column
    may hold more than a piece), is the triangle of ``H`` in CSC order; the factor solves."""
    S, blocks, residuals = pose_graph(rng, n_poses=40, d=6)
    H, g = S.normal_equations(blocks, residuals)
    monkeypatch.setattr(_triangles, "CHUNK", chunk)
    impl = _backends._CHOLMOD(H.indptr, H.indices)
    lower = sp.tril(H).tocsc()
    np.testing.assert_array_equal(np.asarray(impl._A.I).ravel(), lower.indices)
    np.testing.assert_array_equal(np.asarray(impl._A.CCS[0]).ravel(), lower.indptr)
    np.testing.assert_array_equal(H.data[impl._gather], lower.data)
    impl.factorize(H.data)
    x = impl.solve(g)
    assert np.linalg.norm(H @ x - g) <= 1e-9 * np.linalg.norm(g)


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
def test_the_values_of_cholmods_triangle_are_written_in_place(rng, monkeypatch):
    """A factorization writes ``H``'s values into CVXOPT's own copy of the triangle through a view
    (no CVXOPT matrix per factorization): what CVXOPT reads back is the gathered triangle, on
    every factorization. Where the layout check fails (here, pretended), the values go through
    CVXOPT's ``V`` and the solutions agree."""
    import cvxopt

    S, blocks, residuals = pose_graph(rng, n_poses=30, d=6)
    H, g = S.normal_equations(blocks, residuals)
    solutions = []
    for layout_ok in (True, False):
        monkeypatch.setattr(_triangles, "_layout_checked", lambda cvxopt, ok=layout_ok: ok)
        impl = _backends._CHOLMOD(H.indptr, H.indices)
        assert (impl._values is not None) is layout_ok
        for scale in (1.0, 2.0):
            impl.factorize(scale * H.data)
            np.testing.assert_array_equal(np.asarray(impl._A.V).ravel(), scale * H.data[impl._gather])
        solutions.append(impl.solve(g))
    np.testing.assert_array_equal(solutions[0], solutions[1])
    monkeypatch.undo()
    _triangles._layout_checked.cache_clear()
    assert _triangles._layout_checked(cvxopt)  # this CVXOPT is laid out as the view reads it
    complex_matrix = cvxopt.spmatrix([1j], [0], [0])
    assert _triangles.values_view(cvxopt, complex_matrix, 1) is None


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
def test_cholmods_forced_supernodes_refuse_an_indefinite_matrix():
    """Supernodal LLᵀ has no pivots to read: an indefinite matrix makes the factorization itself fail."""
    n = 200
    off = np.full(n - 1, 0.5)
    values = np.full(n, 2.0)
    values[n // 2] = -1.0
    solver = CholeskySolver("cholmod", supernodal=True)
    with pytest.raises(SingularSystemError, match="not positive definite"):
        solver(sp.diags([off, values, off], [-1, 0, 1], format="csc"), np.ones(n))
    assert solver._impl.pivots is None


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
@pytest.mark.parametrize("graph", ["mixed", "poses", "scalars"])
def test_cholmod_of_a_structure_factors_h_in_coordinate_major_order(rng, monkeypatch, graph):
    """A solver bound to a structure hands CHOLMOD ``H`` reordered coordinate-major (coordinate
    0 of every variable, then 1, …), joined from copies of the block pattern: its lower
    triangle is exactly that of ``H[coords][:, coords]``, gathered from ``H.data``; the factor is
    that of ``H`` in the structure's fill-reducing order, and solves, single and many
    right-hand sides, come back in ``H``'s coordinates."""
    if graph == "mixed":  # variables of dimension 3 and 6, unary and binary factors, repeated pairs
        dims, factors = random_factor_graph(rng, n_vars=30)
    elif graph == "scalars":  # dimensions 1, 2 and 3: three classes of coordinates
        dims = np.array([1, 2, 3] * 6)
        of = [np.flatnonzero(dims == k) for k in (1, 2, 3)]
        factors = [(np.stack([v, np.roll(v, 1)], axis=1), k) for k, v in zip((1, 2, 3), of, strict=True)]
        factors += [(np.stack([of[0], of[2]], axis=1), 2), (of[0][:, None], 1)]
    if graph == "poses":
        S, blocks, residuals = pose_graph(rng, n_poses=40, d=6)
    else:
        S = BlockStructure(dims, factors)
        blocks, residuals, _ = random_values(rng, dims, factors)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)  # every variable definite, even one no factor touches
    monkeypatch.setattr(_backends, "GRID_ENTRIES", 1)
    monkeypatch.setenv("MANOPT_LIE_CHOLMOD", "cvxopt")  # CHOLMOD through CVXOPT's interface
    ANALYSES.clear()
    solver = CholeskySolver("cholmod").bind(S)
    x = solver(H, g)
    impl = solver._impl
    coords = impl._coords
    np.testing.assert_array_equal(np.sort(coords), np.arange(S.n))
    var = np.repeat(np.arange(S.dims.size), S.dims)
    local = np.arange(S.n) - S.offsets[var]
    assert np.all(np.diff(local[coords]) >= 0)  # coordinate-major, variables in order within
    # 3-D poses force supernodes, which CHOLMOD factors from the upper triangle.
    assert impl.uplo == ("U" if graph == "poses" else "L")
    triangle = (sp.triu if impl.uplo == "U" else sp.tril)(H[coords][:, coords]).tocsc()
    triangle.sort_indices()
    np.testing.assert_array_equal(np.asarray(impl._A.I).ravel(), triangle.indices)
    np.testing.assert_array_equal(np.asarray(impl._A.CCS[0]).ravel(), triangle.indptr)
    np.testing.assert_array_equal(H.data[impl._gather], triangle.data)
    dense = H.toarray()
    np.testing.assert_allclose(x, np.linalg.solve(dense, g), rtol=1e-9, atol=1e-12)
    many = rng.standard_normal((S.n, 3))
    np.testing.assert_allclose(impl.solve(many), np.linalg.solve(dense, many), rtol=1e-9, atol=1e-12)
    # The factor is that of H's own triangle in the same ordering: same order, same numbers.
    plain = _backends._CHOLMOD(H.indptr, H.indices, S.fill_reducing_ordering(), solver.supernodal)
    plain.factorize(H.data)
    np.testing.assert_array_equal(impl.permutation(), plain.permutation())
    factors = [sp.csc_matrix(cholesky_factor_of(b)) for b in (impl, plain)]
    np.testing.assert_array_equal(factors[0].indices, factors[1].indices)
    np.testing.assert_allclose(factors[0].data, factors[1].data, rtol=1e-12, atol=1e-14)
    ANALYSES.clear()


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
@pytest.mark.parametrize("supernodal", [True, False, None])
@pytest.mark.parametrize("grid", [False, True], ids=["own-order", "coordinate-major"])
def test_cholmod_reads_the_triangle_its_kind_permutes_fastest(rng, monkeypatch, supernodal, grid):
    """Supernodes read the upper triangle, the simplicial ``LDLᵀ`` and CHOLMOD's own choice the
    lower, in ``H``'s order or coordinate-major (variables of dimension 3 and 6); either way
    the factor is the Cholesky factor of ``P H Pᵀ`` in the given ordering."""
    dims, factors = random_factor_graph(rng, n_vars=30)
    S = BlockStructure(dims, factors)
    blocks, residuals, _ = random_values(rng, dims, factors)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)
    order = S.fill_reducing_ordering()
    monkeypatch.setattr(_backends, "GRID_ENTRIES", 1 if grid else _backends.TRIM_ENTRIES)
    impl = _backends._CHOLMOD(H.indptr, H.indices, order, supernodal, (S.dims, *S.block_pattern))
    assert impl.uplo == ("U" if supernodal else "L")
    coords = impl._coords if grid else np.arange(S.n)
    assert (impl._coords is not None) == grid
    triangle = (sp.triu if supernodal else sp.tril)(H[coords][:, coords]).tocsc()
    triangle.sort_indices()
    np.testing.assert_array_equal(np.asarray(impl._A.I).ravel(), triangle.indices)
    np.testing.assert_array_equal(H.data[impl._gather], triangle.data)
    impl.factorize(H.data)
    x = impl.solve(g)
    assert np.linalg.norm(H @ x - g) <= 1e-9 * np.linalg.norm(g)
    perm = impl.permutation()
    L = cholesky_factor_of(impl).toarray()  # leaves the factor symbolic: last
    if impl.pivots is not None:  # LDLᵀ, packed: D on the diagonal, unit L below
        d = np.diag(L).copy()
        np.fill_diagonal(L, 1.0)
        L = L * np.sqrt(d)
    dense = H.toarray()[np.ix_(perm, perm)]
    np.testing.assert_allclose(L, np.linalg.cholesky(dense), rtol=1e-9, atol=1e-9 * np.abs(L).max())


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
def test_cholmod_of_a_small_structure_keeps_the_order_of_h(rng, monkeypatch):
    """Below ``GRID_ENTRIES`` a bound solver builds ``H``'s own triangle from triplets (faster
    there) and solves in it; from there on, the coordinate-major grid (through CVXOPT)."""
    monkeypatch.setenv("MANOPT_LIE_CHOLMOD", "cvxopt")
    S, blocks, residuals = pose_graph(rng, n_poses=8, d=3)
    H, g = S.normal_equations(blocks, residuals)
    assert (H.nnz + S.n) // 2 < _backends.GRID_ENTRIES
    ANALYSES.clear()
    solver = CholeskySolver("cholmod").bind(S)
    x = solver(H, g)
    assert solver._impl._coords is None
    np.testing.assert_allclose(x, np.linalg.solve(H.toarray(), g), rtol=1e-9, atol=1e-12)
    big, blocks, residuals = pose_graph(rng, n_poses=150, d=6)
    H, g = big.normal_equations(blocks, residuals)
    assert (H.nnz + big.n) // 2 >= _backends.GRID_ENTRIES
    solver = CholeskySolver("cholmod").bind(big)
    solver(H, g)
    assert solver._impl._coords is not None
    ANALYSES.clear()


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
def test_cholmod_refuses_a_pattern_that_is_not_canonical(monkeypatch):
    """Unsorted row indices in a column (which CVXOPT would reorder silently) are refused."""
    H = sp.csc_matrix(np.array([[4.0, 1.0, 1.0], [1.0, 4.0, 1.0], [1.0, 1.0, 4.0]]))
    indices = H.indices.copy()
    indices[[1, 2]] = indices[[2, 1]]  # column 0: rows 0, 2, 1
    monkeypatch.setattr(_triangles, "CHUNK", 2)
    with pytest.raises(ValueError, match="canonical"):
        _backends._CHOLMOD(H.indptr, indices)


def test_rejects_bad_matrices(solver):
    with pytest.raises(ValueError, match="not symmetric"):
        solver(sp.csc_matrix(np.array([[2.0, 1.0], [0.0, 2.0]])), np.ones(2))
    with pytest.raises(ValueError, match="no diagonal entry in column 1"):
        solver(sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 2.0]])), np.ones(3))
    with pytest.raises(ValueError, match="square"):
        solver(sp.csc_matrix(np.ones((2, 3))), np.ones(2))
    with pytest.raises(ValueError, match="square"):
        solver(np.eye(2), np.ones(2))


def test_unknown_backend():
    with pytest.raises(ValueError, match="unknown backend 'pardiso'"):
        CholeskySolver("pardiso")


# -- PCG -------------------------------------------------------------------


@pytest.mark.parametrize("preconditioner", ["block-jacobi", "jacobi", None])
def test_pcg_agrees_with_the_direct_solver(system, preconditioner):
    S, _, _, H, g = system
    result = pcg_solve(H, g, tol=1e-12, preconditioner=preconditioner, dims=S.dims, maxiter=10 * S.n)
    assert result.converged and result.residual <= 1e-12 and result.nit > 0
    x = CholeskySolver()(H, g)
    assert np.linalg.norm(result.x - x) <= 1e-8 * np.linalg.norm(x)


def test_pcg_reports_a_truncated_run(system):
    S, _, _, H, g = system
    result = pcg_solve(H, g, tol=1e-14, maxiter=3, dims=S.dims)
    assert not result.converged and result.nit == 3 and result.residual > 1e-14
    assert pcg_solve(H, np.zeros(S.n), dims=S.dims).nit == 0


def test_block_jacobi_inverts_the_diagonal_blocks(rng):
    dims, factors = random_factor_graph(rng)
    S = BlockStructure(dims, factors)
    H, _ = S.normal_equations(*random_values(rng, dims, factors))
    H = S.add_diagonal(H, 1.0)
    M = block_jacobi(H, dims).toarray()
    Hd = H.toarray()
    for v in range(dims.size):
        block = slice(S.offsets[v], S.offsets[v + 1])
        np.testing.assert_allclose(M[block, block] @ Hd[block, block], np.eye(dims[v]), atol=1e-10)
    var_of = np.repeat(np.arange(dims.size), dims)
    assert np.all(M[var_of[:, None] != var_of[None, :]] == 0)


def test_pcg_errors(system):
    S, _, _, H, g = system
    with pytest.raises(ValueError, match="needs dims"):
        pcg_solve(H, g)
    with pytest.raises(ValueError, match="unknown preconditioner"):
        pcg_solve(H, g, preconditioner="ilu")
    with pytest.raises(ValueError, match="summing to n"):
        pcg_solve(H, g, dims=S.dims[:-1])
    with pytest.raises(ShapeError, match="b: expected shape"):
        pcg_solve(H, g[:-1], dims=S.dims)
    indefinite = sp.csc_matrix(np.diag([1.0, 2.0, -1.0]))
    with pytest.raises(SingularSystemError, match="variable 2 is not positive definite"):
        pcg_solve(indefinite, np.ones(3), dims=[1, 1, 1])
    with pytest.raises(SingularSystemError, match="diagonal entry 2"):
        pcg_solve(indefinite, np.ones(3), preconditioner="jacobi")
    with pytest.raises(SingularSystemError, match="non-positive curvature"):
        pcg_solve(indefinite, np.ones(3), preconditioner=None)


@pytest.mark.skipif("cholmod" not in BACKENDS, reason="CHOLMOD (cvxopt) is not installed")
@pytest.mark.parametrize("direct", [True, False], ids=["direct", "cvxopt"])
def test_cholmod_hands_a_large_analysis_transients_back(rng, monkeypatch, direct):
    """An analysis of at least ``TRIM_ENTRIES`` lower-triangle entries returns the heap's free
    pages to the system once (glibc's ``malloc_trim``), a smaller one does not; both solve alike."""
    module = _cholmod if direct else _backends
    if not direct:
        monkeypatch.setenv("MANOPT_LIE_CHOLMOD", "cvxopt")
    calls: list[int] = []
    monkeypatch.setattr(module, "release_freed_memory", lambda: calls.append(1) or True)
    S, blocks, residuals = pose_graph(rng, n_poses=30, d=3)
    H, g = S.normal_equations(blocks, residuals)
    lower = sp.tril(H).nnz
    x = {}
    for threshold, expected in ((lower + 1, 0), (lower, 1)):
        monkeypatch.setattr(module, "TRIM_ENTRIES", threshold)
        ANALYSES.clear()
        calls.clear()
        x[threshold] = CholeskySolver("cholmod")(H, g)
        assert len(calls) == expected
    np.testing.assert_allclose(x[lower], x[lower + 1], rtol=1e-12, atol=0)


def test_release_freed_memory_is_glibc_malloc_trim_or_nothing(monkeypatch):
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert _memory._TRIM is not None
    assert isinstance(_memory.release_freed_memory(), bool)
    monkeypatch.setattr(_memory, "_TRIM", None)
    assert _memory.release_freed_memory() is False
