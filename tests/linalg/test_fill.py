"""The cost of a Cholesky factorization its analysis predicts (against a symbolic elimination
done by hand) and the linear solver it chooses: the factorization for pose graphs, PCG where the
factor would be dense, and the fall back to the factorization when PCG does not finish in its cap."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie.linalg import AutoSolver, BlockStructure, CholeskySolver, _cholmod, fill

from .helpers import pose_graph, random_factor_graph, random_values

direct = pytest.mark.skipif(not _cholmod.available(), reason="CHOLMOD cannot be called directly here")


def column_counts(structure: BlockStructure) -> np.ndarray:
    """The column counts of ``L`` for ``H``'s pattern in the structure's fill-reducing order, by
    eliminating a dense boolean matrix: column ``k``'s rows below the diagonal become a clique."""
    order = structure.fill_reducing_ordering()
    n = structure.n
    pattern = np.zeros((n, n), dtype=bool)
    cols = np.repeat(np.arange(n), np.diff(structure.indptr))
    pattern[structure.indices, cols] = True
    a = pattern[np.ix_(order, order)]
    counts = np.empty(n, dtype=int)
    for k in range(n):
        below = k + 1 + np.flatnonzero(a[k + 1 :, k])
        counts[k] = below.size + 1
        a[np.ix_(below, below)] = True
    return counts


def analysed(structure: BlockStructure) -> CholeskySolver:
    """A solver bound to ``structure`` and analysed (values of the pattern's own)."""
    rng = np.random.default_rng(0)
    solver = CholeskySolver().bind(structure)
    solver.analyze(sp.csc_matrix((rng.random(structure.nnz), structure.indices, structure.indptr)))
    return solver


@direct
@pytest.mark.parametrize("d", [3, 6])
def test_the_predicted_cost_is_the_symbolic_factorizations(d):
    """``Σ c_j`` and ``Σ c_j²`` of the analysis are those of the elimination by hand."""
    structure, _, _ = pose_graph(np.random.default_rng(d), n_poses=240 // d, d=d)  # above DENSE_MAX
    counts = column_counts(structure)
    cost = analysed(structure).factor_cost
    assert cost is not None
    assert cost.nnz == counts.sum() and cost.flops == float(np.dot(counts, counts))


@direct
def test_mixed_dimensions_are_predicted_exactly_too():
    dims, factors = random_factor_graph(np.random.default_rng(4), n_vars=45)
    structure = BlockStructure(dims, factors)
    counts = column_counts(structure)
    assert analysed(structure).factor_cost == fill.FactorCost(float(counts.sum()), float(np.dot(counts, counts)))


def test_no_cost_before_the_analysis_nor_from_the_other_backends():
    structure, _, _ = pose_graph(np.random.default_rng(1), n_poses=20, d=3)
    assert CholeskySolver().bind(structure).factor_cost is None
    solver = CholeskySolver("superlu")
    solver.analyze(sp.csc_matrix((np.ones(structure.nnz), structure.indices, structure.indptr)))
    assert solver.factor_cost is None


@direct
def test_pose_graphs_are_factored():
    """A ring with chords: the factorization, its solution, nothing to report."""
    structure, blocks, residuals = pose_graph(np.random.default_rng(0), n_poses=60, d=3)
    H, g = structure.normal_equations(blocks, residuals)
    solver = AutoSolver().bind(structure)
    np.testing.assert_array_equal(solver(H, -g), CholeskySolver().bind(structure)(H, -g))
    assert not solver.iterative and not solver.stats
    assert not fill.prefers_iterative(analysed(structure).factor_cost, structure.nnz)


def test_a_dense_structure_is_factored():
    dims, factors = random_factor_graph(np.random.default_rng(1), n_vars=6)
    assert isinstance(AutoSolver().bind(BlockStructure(dims, factors, dense=True)), CholeskySolver)


@direct
def test_pcg_that_does_not_finish_in_its_cap_falls_back_to_the_factorization(monkeypatch):
    """Every structure sent to PCG, capped at 50 iterations: a long ring with few chords is too
    ill-conditioned for that, so the first solve is the factorization's (to round-off), its
    stats count the 50 iterations tried, and the rest of the run factors without trying."""
    monkeypatch.setattr(fill, "ITERATIVE_FLOPS_PER_ENTRY", 0.0)
    monkeypatch.setattr(fill, "FLOPS_PER_PRODUCT", 1e12)
    rng = np.random.default_rng(2)
    structure, blocks, residuals = pose_graph(rng, n_poses=400, d=3)
    H, g = structure.normal_equations(blocks, residuals)
    solver = AutoSolver().bind(structure)
    assert isinstance(solver, AutoSolver) and not solver.iterative  # chosen at the first solve
    x = solver(H, -g)
    assert not solver.iterative
    assert solver.stats["linear_iterations"] == 50.0 and solver.stats["linear_converged"] == 1.0
    assert solver.stats["linear_residual"] < 1e-10
    np.testing.assert_allclose(x, CholeskySolver().bind(structure)(H, -g), rtol=1e-9, atol=1e-12)
    solver(H, g)
    assert solver.stats["linear_iterations"] == 0.0  # no PCG tried any more


@direct
def test_pcg_that_converges_is_kept(monkeypatch):
    """Sent to PCG with room enough (a cap of ``n``): its solution, to its tolerance, and its stats."""
    monkeypatch.setattr(fill, "ITERATIVE_FLOPS_PER_ENTRY", 0.0)
    monkeypatch.setattr(fill, "FLOPS_PER_PRODUCT", 1e-12)
    rng = np.random.default_rng(3)
    structure, blocks, residuals = pose_graph(rng, n_poses=60, d=3)
    H, g = structure.normal_equations(blocks, residuals)
    solver = AutoSolver(tol=1e-8).bind(structure)
    x = solver(H, -g)
    assert solver.iterative and solver.stats["linear_converged"] == 1.0
    assert 1 <= solver.stats["linear_iterations"] <= structure.n
    assert np.linalg.norm(H @ x + g) <= 1e-8 * np.linalg.norm(g)


def test_an_unbound_auto_solver_refuses_to_solve():
    dims, factors = random_factor_graph(np.random.default_rng(5))
    structure = BlockStructure(dims, factors)
    blocks, residuals, _ = random_values(np.random.default_rng(5), dims, factors)
    H, g = structure.normal_equations(blocks, residuals)
    with pytest.raises(RuntimeError, match="bind"):
        AutoSolver()(H, g)


@pytest.mark.parametrize("tol", [0.0, 1.5])
def test_a_bad_tolerance_is_refused_at_construction(tol):
    with pytest.raises(ValueError, match="tol"):
        AutoSolver(tol=tol)
