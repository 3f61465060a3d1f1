"""The compiled assembly of H and g (``_assembly``, ``assembly.c``) against NumPy's path and the dense
reference: every factor type, with and without weights, sparse and dense structures, whole scatters
and scatters made per chunk; the NumPy path where the C cannot serve."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from manopt_lie.linalg import BlockStructure, _assembly, _factors, structure

from .helpers import dense_normal_equations, in_threads, random_factor_graph, random_values

pytestmark = pytest.mark.skipif(_assembly._library() is None, reason="no C compiler here")


def _numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_assembly, "_library", lambda: None)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("dense", [False, True])
def test_the_compiled_assembly_is_numpys(monkeypatch, seed, dense):
    """The same H and g as NumPy's path to rounding (sums of a few products in another order), and
    as the dense reference; with weights and without."""
    rng = np.random.default_rng(seed)
    dims, factors = random_factor_graph(rng, n_vars=12)
    blocks, residuals, weights = random_values(rng, dims, factors)
    S = BlockStructure(dims, factors, dense=dense)
    for w in (None, weights):
        compiled = S.normal_equations(blocks, residuals, w)
        with monkeypatch.context() as m:
            _numpy_path(m)
            H, g = S.normal_equations(blocks, residuals, w)
        H_ref, g_ref = dense_normal_equations(dims, factors, blocks, residuals, w)
        for h in (H.toarray(), H_ref):
            np.testing.assert_allclose(compiled[0].toarray(), h, rtol=0, atol=1e-13 * np.abs(h).max())
        for v in (g, g_ref):
            np.testing.assert_allclose(compiled[1], v, rtol=0, atol=1e-13 * np.abs(v).max())
        assert np.array_equal(compiled[0].toarray(), compiled[0].toarray().T)  # (i, j) and (j, i) summed alike


def test_a_scatter_made_per_chunk_is_summed_alike(monkeypatch):
    """Above WHOLE_SCATTER_BYTES the positions are made chunk by chunk: the C sums each chunk as it
    sums the whole scatter, so H is the same bit for bit."""
    rng = np.random.default_rng(7)
    dims, factors = random_factor_graph(rng, n_vars=15)
    blocks, _, weights = random_values(rng, dims, factors)
    whole = BlockStructure(dims, factors)
    monkeypatch.setattr(_factors, "WHOLE_SCATTER_BYTES", 0)
    monkeypatch.setattr(structure, "CHUNK", 64)
    made = BlockStructure(dims, factors)
    assert all(s.whole is None for s in made._hess_scatter)
    for w in (None, weights):
        np.testing.assert_array_equal(made.hessian(blocks, w).data, whole.hessian(blocks, w).data)


def test_where_the_c_cannot_serve_numpy_assembles():
    """A block wider than MAX_WIDTH, 64-bit positions, Jacobians, weights or an output not C-contiguous
    float64: the functions decline, and the structure's NumPy path gives the dense reference."""
    a = np.ones((2, 1, _assembly.MAX_WIDTH + 1))
    positions = np.zeros(2 * a.shape[2] ** 2, dtype=np.int32)
    assert not _assembly.hessian_add(a, None, positions, np.zeros(4))
    assert not _assembly.hessian_add(np.ones((2, 1, 3)), None, positions.astype(np.int64), np.zeros(4))
    assert not _assembly.hessian_add(np.ones((2, 1, 3)), None, positions, np.zeros(4, dtype=np.float32))
    assert not _assembly.hessian_add(np.ones((2, 1, 3)), np.ones(4)[::2], positions, np.zeros(4))  # strided weights
    strided = np.ones((2, 1, 6))[:, :, ::2]
    assert not _assembly.gradient_add(strided, np.ones((2, 1)), None, positions, np.zeros(4))
    dims = np.full(4, 9)  # edges of width 36 > 32
    factors = [(np.array([[0, 1, 2, 3]]), 2), (np.array([[0, 1], [2, 3]]), 3)]
    rng = np.random.default_rng(3)
    blocks, residuals, weights = random_values(rng, dims, factors)
    H, g = BlockStructure(dims, factors).normal_equations(blocks, residuals, weights)
    H_ref, g_ref = dense_normal_equations(dims, factors, blocks, residuals, weights)
    np.testing.assert_allclose(H.toarray(), H_ref, rtol=0, atol=1e-13 * np.abs(H_ref).max())
    np.testing.assert_allclose(g, g_ref, rtol=0, atol=1e-13 * np.abs(g_ref).max())


def test_threads_assemble_one_structure_alike():
    """The C keeps no workspace: four threads assembling one structure at once get one thread's H."""
    rng = np.random.default_rng(4)
    dims, factors = random_factor_graph(rng, n_vars=30)
    blocks, _, weights = random_values(rng, dims, factors)
    S = BlockStructure(dims, factors)
    alone = S.hessian(blocks, weights).data
    results: list[np.ndarray | None] = [None] * 4
    lock = threading.Lock()

    def run(i: int) -> None:
        for _ in range(50):
            data = S.hessian(blocks, weights).data
        with lock:
            results[i] = data

    in_threads(run, 4)
    assert all(np.array_equal(r, alone) for r in results)
