"""CHOLMOD called directly (``linalg._cholmod``): the permuted triangle it factors, the factor
against the dense Cholesky factor of ``P H Pᵀ``, its checks, and the fallback to CVXOPT's
interface."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie.linalg import BlockStructure, CholeskySolver, SingularSystemError, _backends, _cholmod
from manopt_lie.linalg._analyses import ANALYSES
from manopt_lie.linalg._triangles import permuted_block_triangle
from manopt_lie.linalg.selected_inverse import _cholmod_factor

from .helpers import pose_graph, random_factor_graph, random_values

HAS_CVXOPT = "cholmod" in CholeskySolver.available_backends()
direct = pytest.mark.skipif(not _cholmod.available(), reason="CHOLMOD cannot be called directly here")


def test_cholmod_is_called_directly_where_cvxopt_ships_it():
    """On Linux CVXOPT's wheels ship CHOLMOD 3.0, which the binding finds and checks: there the
    direct tests below run (they are skipped only where the binding cannot work)."""
    if sys.platform.startswith("linux") and HAS_CVXOPT:
        assert _cholmod.available()


def _mixed_system(rng: np.random.Generator) -> tuple[BlockStructure, sp.csc_matrix, np.ndarray]:
    """Variables of dimension 3 and 6, unary and binary factors; H definite everywhere."""
    dims, factors = random_factor_graph(rng, n_vars=30)
    S = BlockStructure(dims, factors)
    blocks, residuals, _ = random_values(rng, dims, factors)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)
    return S, H, g


@pytest.mark.parametrize("upper", [False, True], ids=["lower", "upper"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_permuted_block_triangle_is_the_triangle_of_p_h_pt(upper, seed):
    """Built from the blocks, the triangle of ``P H Pᵀ`` (``P`` putting variable ``order[k]``
    k-th) equals SciPy's, entry by entry, and its gather reads ``H``'s values into it."""
    rng = np.random.default_rng(seed)
    S, H, _ = _mixed_system(rng)
    for order in (np.arange(S.dims.size), rng.permutation(S.dims.size)):
        perm = np.concatenate([np.arange(S.offsets[v], S.offsets[v + 1]) for v in order])
        expected = (sp.triu if upper else sp.tril)(H[perm][:, perm], format="csc")
        expected.sort_indices()
        indptr, indices, gather = permuted_block_triangle(S.indptr, S.dims, *S.block_pattern, order, upper)
        assert indptr.dtype == indices.dtype == np.int32
        np.testing.assert_array_equal(indptr, expected.indptr)
        np.testing.assert_array_equal(indices, expected.indices)
        np.testing.assert_array_equal(H.data[gather], expected.data)


def _keeps_variables_together(perm: np.ndarray, dims: np.ndarray) -> bool:
    """Whether ``perm`` lists each variable's coordinates together and in order."""
    offsets = np.concatenate([[0], np.cumsum(dims)])
    variable = np.repeat(np.arange(dims.size), dims)[perm]
    order = variable[perm == offsets[:-1][variable]]
    expanded = [np.arange(offsets[v], offsets[v + 1]) for v in order]
    return order.size == dims.size and np.array_equal(perm, np.concatenate(expanded))


def _dense_factor(impl: _cholmod.Cholmod | _backends._CHOLMOD, H: sp.csc_matrix) -> np.ndarray:
    """``L`` of a factorized backend, dense (``LDLᵀ``: ``L₁ D^½``)."""
    return _cholmod_factor(impl, H).L.toarray()


@direct
@pytest.mark.parametrize("supernodal", [True, False, None])
def test_direct_factor_is_the_cholesky_factor_of_p_h_pt(rng, supernodal):
    """Bound to a structure, the solver factors ``H`` directly in the structure's ordering
    (postordered, each variable's coordinates kept together): ``L`` is the Cholesky factor of
    ``P H Pᵀ`` (``LDLᵀ``: ``L₁ D^½``), solves of one and many right-hand sides are ``H``'s, and
    the factor stays usable after ``L`` is read."""
    S, H, g = _mixed_system(rng)
    ANALYSES.clear()
    solver = CholeskySolver("cholmod", supernodal=supernodal).bind(S)
    x = solver(H, g)
    impl = solver._impl
    assert isinstance(impl, _cholmod.Cholmod)
    if supernodal is not None:
        assert impl.supernodal is supernodal and (impl.pivots is None) == supernodal
    perm = impl.permutation()
    assert _keeps_variables_together(perm, S.dims)
    dense = H.toarray()
    np.testing.assert_allclose(x, np.linalg.solve(dense, g), rtol=1e-9, atol=1e-12)
    L = _dense_factor(impl, H)
    np.testing.assert_allclose(L, np.linalg.cholesky(dense[np.ix_(perm, perm)]), rtol=1e-9, atol=1e-9 * abs(L).max())
    many = rng.standard_normal((S.n, 3))
    np.testing.assert_allclose(impl.solve(many), np.linalg.solve(dense, many), rtol=1e-9, atol=1e-12)
    ANALYSES.clear()


@direct
@pytest.mark.skipif(not HAS_CVXOPT, reason="CVXOPT is not installed")
@pytest.mark.parametrize("d", [3, 6])
def test_direct_and_cvxopt_factor_the_same_matrix_alike(rng, monkeypatch, d):
    """The same pattern and ordering through either interface: the same elimination order, the
    same factor to rounding, the same solutions."""
    S, blocks, residuals = pose_graph(rng, n_poses=60, d=d)
    H, g = S.normal_equations(blocks, residuals)
    S.add_diagonal(H, 1.0, inplace=True)
    results = []
    for switch in ("", "cvxopt"):
        monkeypatch.setenv("MANOPT_LIE_CHOLMOD", switch)
        ANALYSES.clear()
        solver = CholeskySolver("cholmod").bind(S)
        x = solver(H, g)
        assert isinstance(solver._impl, _cholmod.Cholmod) == (switch == "")
        results.append((x, solver._impl.permutation(), _dense_factor(solver._impl, H)))
        del solver  # its backend goes back to the pool, which the next solve must not borrow from
        ANALYSES.clear()
    (x0, p0, l0), (x1, p1, l1) = results
    np.testing.assert_array_equal(p0, p1)
    np.testing.assert_allclose(l0, l1, rtol=1e-10, atol=1e-12 * abs(l0).max())
    np.testing.assert_allclose(x0, x1, rtol=1e-9, atol=1e-12)
    ANALYSES.clear()


@direct
def test_direct_factorization_refuses_an_indefinite_matrix():
    """Supernodal ``LLᵀ`` stops at the first non-positive pivot; simplicial ``LDLᵀ`` does not stop,
    so its pivots are read: both raise."""
    n = 200
    off = np.full(n - 1, 0.5)
    values = np.full(n, 2.0)
    values[n // 2] = -1.0
    H = sp.diags([off, values, off], [-1, 0, 1], format="csc")
    H.indptr, H.indices = H.indptr.astype(np.int32), H.indices.astype(np.int32)
    for supernodal, message in ((True, "not positive definite"), (False, "pivots of LDLᵀ ≤ 0")):
        impl = _cholmod.Cholmod(H.indptr, H.indices, None, supernodal)
        with pytest.raises(SingularSystemError, match=message):
            impl.factorize(H.data)
        impl.factorize(H.data + 3.0 * (H.indices == np.repeat(np.arange(n), np.diff(H.indptr))))  # recovers


@direct
def test_a_pattern_without_a_structure_is_factored_in_cholmods_own_order(rng):
    """No structure, no ordering: CHOLMOD orders the coordinates itself (its AMD) and the triangle
    is permuted through SciPy; the solution is ``H``'s."""
    _, H, g = _mixed_system(rng)
    plain = sp.csc_matrix(H.toarray())
    plain.indptr, plain.indices = plain.indptr.astype(np.int32), plain.indices.astype(np.int32)
    impl = _cholmod.cholmod_backend(plain.indptr, plain.indices)
    assert isinstance(impl, _cholmod.Cholmod)
    impl.factorize(plain.data)
    np.testing.assert_allclose(impl.solve(g), np.linalg.solve(plain.toarray(), g), rtol=1e-9, atol=1e-12)
    assert sorted(impl.permutation().tolist()) == list(range(H.shape[0]))


@pytest.mark.skipif(not HAS_CVXOPT, reason="CVXOPT is not installed")
def test_cvxopts_interface_serves_where_the_direct_call_does_not(rng, monkeypatch):
    """``MANOPT_LIE_CHOLMOD=cvxopt`` and 64-bit indices take CVXOPT's interface."""
    _, H, _ = _mixed_system(rng)
    wide = (H.indptr.astype(np.int64), H.indices.astype(np.int64))
    assert isinstance(_cholmod.cholmod_backend(*wide), _backends._CHOLMOD)
    monkeypatch.setenv("MANOPT_LIE_CHOLMOD", "cvxopt")
    assert not _cholmod.available()
    assert isinstance(_cholmod.cholmod_backend(H.indptr, H.indices), _backends._CHOLMOD)


class _OtherCholmod:
    """A stand-in library: another version, or one whose Common is laid out otherwise."""

    def __init__(self, version: list[int]) -> None:
        self.version = version

    def cholmod_version(self, out):
        out[:] = self.version
        return 0

    def cholmod_start(self, buffer):
        return 1  # writes no defaults where the binding looks for them

    def cholmod_finish(self, buffer):
        return 1


def test_the_binding_checks_the_library_it_calls():
    """Another major version, or a Common without CHOLMOD 3.0's defaults at the binding's
    offsets, is refused (the solver then goes through CVXOPT)."""
    assert not _cholmod._works(_OtherCholmod([5, 0, 0]))
    assert not _cholmod._works(_OtherCholmod([3, 0, 6]))
