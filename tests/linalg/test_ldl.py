"""The compiled simplicial ``LDLᵀ`` (``linalg._ldl``, the backend ``ldl``): its factor against the
dense ``LDLᵀ`` of ``P H Pᵀ``, its analyses (a structure's early one, the variables', the
coordinates') against each other and CHOLMOD's, its failures, and the automatic choice of it."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie.linalg import (
    BlockStructure,
    CholeskySolver,
    SingularSystemError,
    _cholmod,
    _early,
    _ldl,
    _patterns,
    clear_caches,
)
from manopt_lie.linalg._factors import coordinates, exclusive_cumsum
from manopt_lie.linalg.selected_inverse import cholesky_factor

from .helpers import pose_graph, random_factor_graph, random_values

pytestmark = pytest.mark.skipif(not _ldl.available(), reason="the compiled LDLᵀ needs a C compiler and CVXOPT")


def _random_spd(rng: np.random.Generator, n: int, density: float) -> sp.csc_matrix:
    """A sparse SPD matrix: a random symmetric pattern (every diagonal entry) made diagonally dominant."""
    upper = sp.random(n, n, density=density, random_state=rng, format="csc")
    a = upper + upper.T
    a = a + sp.diags(np.abs(a).sum(axis=1).A.ravel() + 1.0)
    a = sp.csc_matrix(a)
    a.sum_duplicates()
    a.indptr, a.indices = a.indptr.astype(np.int32), a.indices.astype(np.int32)
    return a


def _dense_ldl(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``B = L D Lᵀ`` the textbook way: unit lower ``L`` and the pivots ``D``."""
    c = np.linalg.cholesky(b)
    d = np.diag(c) ** 2
    return c / np.diag(c), d


def _check_factor(factor: _ldl.SimplicialLDL, H: sp.csc_matrix) -> None:
    """The factor of ``P H Pᵀ`` entry for entry against the dense one, and its solves against NumPy's."""
    perm = factor.permutation()
    dense = H.toarray()
    unit, d = _dense_ldl(dense[np.ix_(perm, perm)])
    data, indices, indptr = factor.factor_csc()
    packed = sp.csc_matrix((data, indices, indptr), shape=H.shape).toarray()
    np.testing.assert_allclose(np.diag(packed), d, rtol=1e-12)
    np.testing.assert_allclose(np.tril(packed, -1), np.tril(unit, -1), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(factor.pivots, d, rtol=1e-12)
    b = np.arange(1.0, H.shape[0] + 1.0)
    np.testing.assert_allclose(factor.solve(b), np.linalg.solve(dense, b), rtol=1e-10)
    two = np.stack([b, -2.0 * b + 1.0], axis=1)
    np.testing.assert_allclose(factor.solve(two), np.linalg.solve(dense, two), rtol=1e-10)


@given(n=st.integers(1, 40), density=st.floats(0.0, 0.4), seed=st.integers(0, 2**31))
def test_the_factor_of_any_pattern_is_the_dense_ldlt(n, density, seed):
    """Any SPD pattern, analysed in AMD's order of its coordinates: ``L``, ``D`` and the solves are
    the dense ones of ``P H Pᵀ``, and the column counts those of the filled pattern."""
    H = _random_spd(np.random.default_rng(seed), n, density)
    factor = _ldl.ldl_backend(H.indptr, H.indices)
    factor.factorize(H.data)
    _check_factor(factor, H)
    _, _, indptr = factor.factor_csc()
    counts = np.diff(indptr).astype(float)
    assert factor.cost == (counts.sum(), float(np.dot(counts, counts)))
    assert factor.supernodal is False


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_structures_analyses_make_one_factor(seed):
    """A structure of one dimension: its early analysis, the variables' analysis here and the
    coordinates' make the same factor, as large as CHOLMOD's analysis says; variables of two
    dimensions are analysed coordinate by coordinate."""
    rng = np.random.default_rng(seed)
    S, blocks, residuals = pose_graph(rng, n_poses=60)
    H, _ = S.normal_equations(blocks, residuals)
    early, order = S._early_analysis(), S.variable_ordering()
    assert early is not None and early.simplicial is not None
    form = (S.dims, *S.block_pattern)
    made = [_ldl.ldl_backend(S.indptr, S.indices, form, order, early)]
    made.append(_ldl.ldl_backend(S.indptr, S.indices, form, order))
    for factor in made:
        factor.factorize(H.data)
        _check_factor(factor, H)
    np.testing.assert_array_equal(made[0].permutation(), made[1].permutation())
    assert made[0].cost == made[1].cost
    if _cholmod.available():
        cholmod = _cholmod.Cholmod(S.indptr, S.indices, None, False, form, variables=order)
        assert cholmod.cost == made[0].cost
    dims, factors = random_factor_graph(rng, n_vars=30)
    mixed = BlockStructure(dims, factors)
    H, _ = mixed.normal_equations(*random_values(rng, dims, factors)[:2])
    mixed.add_diagonal(H, 1.0, inplace=True)
    form = (mixed.dims, *mixed.block_pattern)
    factor = _ldl.ldl_backend(mixed.indptr, mixed.indices, form, mixed.variable_ordering())
    factor.factorize(H.data)
    _check_factor(factor, H)


def test_an_indefinite_or_non_finite_matrix_is_refused_and_the_factor_recovers(rng):
    """A pivot ≤ 0 or not finite raises naming it; the next factorization of a definite matrix of
    the pattern is exact again (the workspace left as it wants it)."""
    H = _random_spd(rng, 30, 0.2)
    factor = _ldl.ldl_backend(H.indptr, H.indices)
    diagonal = np.flatnonzero(H.indices == np.repeat(np.arange(30), np.diff(H.indptr)))
    bad = H.copy()
    bad.data[diagonal[7]] = -1e3
    with pytest.raises(SingularSystemError, match=r"not positive definite \(the pivot of H's coordinate 7 is ≤ 0\)"):
        factor.factorize(bad.data)
    with pytest.raises(SingularSystemError, match="no factorization"):
        factor.solve(np.ones(30))
    nan = H.copy()
    nan.data[diagonal[3]] = np.nan
    with pytest.raises(SingularSystemError, match="not finite"):
        factor.factorize(nan.data)
    factor.factorize(H.data)
    _check_factor(factor, H)
    with pytest.raises(ValueError, match="holds 5 values"):
        factor.factorize(np.ones(5))


def test_column_counts_of_another_pattern_are_caught(rng):
    """Counts that do not lay out the triangle's ``L`` (a symbolic analysis of something else) raise,
    whether a column would fill past its room or short of it, and nothing is written out of it."""
    H = _random_spd(rng, 25, 0.3)
    good = _ldl.ldl_backend(H.indptr, H.indices)
    good.factorize(H.data)
    counts = np.diff(good.factor_csc()[2]).astype(np.int32)
    assert counts.max() > 1
    for wrong in (np.maximum(counts - 1, 1), counts + 1):
        factor = _ldl.SimplicialLDL(good._triangle, good.permutation(), wrong.astype(np.int32), H.nnz)
        with pytest.raises(RuntimeError, match="pattern is not the one"):
            factor.factorize(H.data)


def test_the_automatic_choice_takes_the_compiled_ldlt_where_the_structure_found_it(rng):
    """A solver of the automatic choice bound to a 2-D pose graph's structure factors with ``ldl``
    (its early analysis found CHOLMOD's simplicial kind), a 3-D one's with CHOLMOD's supernodes; a
    solver asked for ``cholmod`` keeps CHOLMOD, and the pool lends neither's analysis to the other."""
    clear_caches()
    S, blocks, residuals = pose_graph(rng, n_poses=80)
    H, g = S.normal_equations(blocks, residuals)
    auto = CholeskySolver().bind(S)
    x = auto(H, -g)
    assert auto.backend == "ldl" and isinstance(auto._impl, _ldl.SimplicialLDL)
    np.testing.assert_allclose(H @ x, -g, atol=1e-9 * np.abs(g).max())
    explicit = CholeskySolver("cholmod").bind(S)
    np.testing.assert_allclose(explicit(H, -g), x, rtol=1e-9, atol=1e-12)
    assert explicit.backend == "cholmod" and not isinstance(explicit._impl, _ldl.SimplicialLDL)
    del auto
    again = CholeskySolver().bind(S)
    again(H, -g)
    assert isinstance(again._impl, _ldl.SimplicialLDL) and again.n_analyses == 1
    S3, blocks3, residuals3 = pose_graph(rng, n_poses=40, d=6)
    H3, g3 = S3.normal_equations(blocks3, residuals3)
    solid = CholeskySolver().bind(S3)
    solid(H3, -g3)
    assert solid.backend == "cholmod"
    assert not _cholmod.available() or solid._impl.supernodal  # (CVXOPT's interface does not tell)
    unbound = CholeskySolver()
    unbound(H, -g)
    assert unbound.backend == "cholmod"


def test_the_explicit_backend_and_its_selected_inverse(rng):
    """``CholeskySolver("ldl")`` on any pattern, and the selected inverse of its factor, against the
    dense inverse."""
    H = _random_spd(rng, 40, 0.1)
    b = rng.standard_normal(40)
    solver = CholeskySolver("ldl")
    np.testing.assert_allclose(solver(H, b), np.linalg.solve(H.toarray(), b), rtol=1e-10)
    wide = H.copy()
    wide.indices, wide.indptr = H.indices.astype(np.int64), H.indptr.astype(np.int64)  # SciPy's would be 32-bit
    np.testing.assert_allclose(CholeskySolver("ldl")(wide, b), np.linalg.solve(H.toarray(), b), rtol=1e-10)
    factor = cholesky_factor(H, "ldl")
    assert factor.backend == "ldl"
    L = factor.L.toarray()
    perm = factor.perm
    np.testing.assert_allclose(L @ L.T, H.toarray()[np.ix_(perm, perm)], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("d", [1, 2, 6])
def test_chains_of_every_width_factor_exactly(d):
    """Variables of one dimension ``d``: chains of ``d`` columns (taken two or three at a time, six as
    three and three) in the factorization and the solves, against the dense ``LDLᵀ`` of ``P H Pᵀ``,
    the variables' analysis here and the coordinates' giving the same factor."""
    rng = np.random.default_rng(d)
    S, blocks, residuals = pose_graph(rng, n_poses=30, d=d)
    H, _ = S.normal_equations(blocks, residuals)
    form, order = (S.dims, *S.block_pattern), S.variable_ordering()
    by_blocks = _ldl.ldl_backend(S.indptr, S.indices, form, order)
    by_coordinates = _ldl.ldl_backend(S.indptr, S.indices)
    for factor in (by_blocks, by_coordinates):
        factor.factorize(H.data)
        _check_factor(factor, H)
    assert by_blocks.cost == by_coordinates.cost


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_variables_of_several_dimensions_are_analysed_by_their_blocks(seed):
    """Variables of dimensions 3 and 6: each block of the variables' analysis counts its rows
    (``block_symbolic``'s weights), which gives the coordinates' column counts — the same fill as
    the analysis of the coordinates in that order — and an automatic solver takes the compiled
    ``LDLᵀ`` where CHOLMOD's rule says simplicial, solving as CHOLMOD does."""
    rng = np.random.default_rng(seed)
    dims, factors = random_factor_graph(rng, n_vars=40)
    S = BlockStructure(dims, factors)
    H, g = S.normal_equations(*random_values(rng, dims, factors)[:2])
    S.add_diagonal(H, 1.0, inplace=True)
    order = S.variable_ordering()
    made = _early.analyse_here(S.dims, 0, S.indptr, *S.block_pattern, order, simplicial_always=True)
    assert made.symbolic is None and made.simplicial is not None
    unweighted = _patterns.block_symbolic(*S.block_pattern, order, bounded=False)
    weighted = _patterns.block_symbolic(*S.block_pattern, order, bounded=False, weights=np.full(dims.size, 3))
    np.testing.assert_array_equal(weighted[0], unweighted[0])
    np.testing.assert_array_equal(weighted[1], 3 * unweighted[1])  # uniform weights: the blocks' rows
    by_coordinates = _ldl.ldl_backend(S.indptr, S.indices)  # AMD's order of the coordinates
    in_order = _early.analyse_here(np.ones(S.n, np.intp), 1, S.indptr, S.indptr, S.indices,
                                   coordinates(exclusive_cumsum(S.dims), S.dims, order), simplicial_always=True)
    assert made.simplicial.cost == in_order.simplicial.cost  # the variables' order, coordinate by coordinate
    factor = _ldl.ldl_backend(S.indptr, S.indices, (S.dims, *S.block_pattern), order)
    for f in (factor, by_coordinates):
        f.factorize(H.data)
        _check_factor(f, H)
    clear_caches()
    auto = CholeskySolver().bind(S)
    x = auto(H, g)
    np.testing.assert_allclose(x, np.linalg.solve(H.toarray(), g), rtol=1e-9)
    assert (auto.backend == "ldl") == (S._analysis().simplicial is not None)
