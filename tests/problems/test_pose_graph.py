"""Pose graphs on synthetic instances: every optimizer, noise-consistent errors, robust
costs against outliers, and the checks the problem builder makes."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.optim import GaussNewton, LevenbergMarquardt, Status, TrustRegion
from manopt_lie.problems import PoseGraph, costs, evaluation, synthetic

INSTANCES = {
    "grid2d": lambda **kw: synthetic.grid2d(12, 12, loop_closure_probability=0.3, seed=1, **kw),
    "cube": lambda **kw: synthetic.cube(5, loop_closure_probability=0.3, seed=2, **kw),
}
OPTIMIZERS = [("chordal", TrustRegion), ("geodesic", LevenbergMarquardt), ("geodesic", GaussNewton),
              ("geodesic", TrustRegion)]  # fmt: skip


@pytest.mark.parametrize("kind", sorted(INSTANCES))
def test_exact_measurements_are_recovered(kind):
    inst = INSTANCES[kind](translation_noise=0.0, rotation_noise=0.0)
    graph = inst.graph
    start = graph.chordal_initialization().rplus(
        0.05 * np.random.default_rng(0).standard_normal((graph.n, graph.group.dim))
    )
    for cost, optimizer in OPTIMIZERS:
        result = optimizer(grad_rtol=1e-12, rel_cost_decrease=0).solve(graph.problem(cost), start)
        assert result.status is Status.GRADIENT_NORM, (cost, optimizer, result)
        assert result.fun < 1e-18
        errors = evaluation.errors(result.x, inst.truth)
        assert errors.rotation_stats.max < 1e-9 and errors.translation_stats.max < 1e-8


@pytest.mark.parametrize("kind", sorted(INSTANCES))
def test_every_optimizer_reaches_the_same_optimum_from_both_initializations(kind):
    graph = INSTANCES[kind]().graph
    for cost in ("chordal", "geodesic"):
        finals = []
        for x0 in (graph.chordal_initialization(), graph.odometry_initialization()):
            for c, optimizer in OPTIMIZERS:
                if c == cost:
                    result = optimizer(grad_rtol=1e-8, rel_cost_decrease=0).solve(graph.problem(cost), x0)
                    assert result.status is Status.GRADIENT_NORM
                    assert result.fun == pytest.approx(graph.cost(result.x, cost), rel=1e-12)
                    finals.append(result.fun)
        np.testing.assert_allclose(finals, finals[0], rtol=1e-9)


@pytest.mark.parametrize("kind", sorted(INSTANCES))
def test_errors_scale_with_the_injected_noise(kind):
    """Maximum likelihood: the estimate beats the truth on the cost, its chi-square is
    that of ``m − n + 1`` independent cycles, and its error is linear in the noise."""
    rms = []
    for scale in (1.0, 0.1):
        inst = INSTANCES[kind](translation_noise=0.05 * scale, rotation_noise=0.01 * scale)
        graph = inst.graph
        result = GaussNewton().solve(graph.problem("geodesic"), graph.chordal_initialization())
        assert result.fun <= graph.cost(graph.chordal_initialization(), "geodesic")
        assert result.fun <= graph.cost(evaluation.align(inst.truth, result.x), "geodesic")
        chi2 = evaluation.edge_residuals(graph, result.x)["chi2"]
        expected = graph.group.dim * (graph.m - graph.n + 1)
        assert 0.6 * expected < chi2 < 1.4 * expected
        errors = evaluation.errors(result.x, inst.truth)
        rms.append([errors.rotation_stats.rms, errors.translation_stats.rms])
    np.testing.assert_allclose(np.divide(*rms), 10.0, rtol=0.05)


def test_robust_costs_reject_outlier_loop_closures():
    inst = synthetic.grid2d(12, 12, loop_closure_probability=0.4, outlier_rate=0.15, seed=7)
    graph = inst.graph
    assert inst.outliers.sum() > 5
    x0 = graph.odometry_initialization()  # the chordal one is corrupted by the outliers too
    plain = LevenbergMarquardt().solve(graph.problem("geodesic"), x0)
    robust = LevenbergMarquardt(max_iterations=300, rel_cost_decrease=0)
    robust = robust.solve(graph.problem("geodesic", robust="cauchy:1"), x0)
    assert robust.status is Status.GRADIENT_NORM
    clean = synthetic.grid2d(12, 12, loop_closure_probability=0.4, seed=7)
    reference = evaluation.errors(
        GaussNewton().solve(clean.graph.problem("geodesic"), clean.graph.chordal_initialization()).x, clean.truth
    ).translation_stats.rms
    assert evaluation.errors(plain.x, inst.truth).translation_stats.rms > 10 * reference
    assert evaluation.errors(robust.x, inst.truth).translation_stats.rms < 3 * reference
    flagged = evaluation.edge_residuals(graph, robust.x)["norms"] > 10.0
    np.testing.assert_array_equal(flagged, inst.outliers)


def test_indefinite_information_is_refused_by_the_geodesic_cost_unless_repaired(rng):
    inst = synthetic.grid2d(4, 4, seed=0)
    g = inst.graph
    info = g.information.copy()
    info[[2, 5]] = np.diag([1.0, -2.0, 1.0])
    graph = PoseGraph(SE2, g.edges, g.measurements, info, ids=g.ids + 100)
    i, j = graph.ids[graph.edges[2]]
    with pytest.raises(costs.IndefiniteInformationError, match=f"2 edges .*{i}→{j}"):
        graph.problem("geodesic")
    result = GaussNewton().solve(graph.problem("geodesic", repair_information=True), graph.chordal_initialization())
    assert result.success
    # The chordal cost needs only κ, τ > 0 (here τ from the translation block stays positive).
    kappa, tau = graph.se_sync_weights
    assert np.all(kappa > 0) and np.all(tau > 0)
    assert TrustRegion().solve(graph.problem("chordal"), graph.chordal_initialization()).success
    info[3] = np.diag([1.0, 1.0, -1.0])
    negative_kappa = PoseGraph(SE2, g.edges, g.measurements, info, ids=g.ids + 100)
    with pytest.raises(costs.IndefiniteInformationError, match="κ, τ > 0"):
        negative_kappa.problem("chordal")


def test_unknown_cost_and_bad_points_are_rejected():
    graph = synthetic.grid2d(3, 3, seed=0).graph
    with pytest.raises(ValueError, match="cost must be one of"):
        graph.problem("frobenius")
    with pytest.raises(ValueError, match="cost must be one of"):
        graph.cost(graph.chordal_initialization(), "frobenius")
    with pytest.raises(ShapeError):
        graph.cost(SE2.identity((4,)), "geodesic")


def test_pose_graph_validates_its_arrays(rng):
    z = SE3.random(rng, (2,))
    info = np.broadcast_to(np.eye(6), (2, 6, 6))
    edges = np.array([[0, 1], [1, 2]])
    with pytest.raises(TypeError):
        PoseGraph(SO3, edges, z, info)
    with pytest.raises(ShapeError):
        PoseGraph(SE3, edges[:, :1], z, info)
    with pytest.raises(ShapeError):
        PoseGraph(SE3, edges, z, info[:, :3, :3])
    with pytest.raises(ShapeError):
        PoseGraph(SE3, edges, SE2.random(rng, (2,)), info)
    with pytest.raises(ValueError, match="self-loop"):
        PoseGraph(SE3, np.array([[0, 1], [1, 1]]), z, info)
    with pytest.raises(ValueError, match=r"0\.\.1"):
        PoseGraph(SE3, edges, z, info, ids=np.array([5, 6]))
    with pytest.raises(ValueError, match="non-finite"):
        PoseGraph(SE3, edges, z, np.where(np.eye(6) > 0, np.nan, 0.0)[None].repeat(2, 0))
    graph = PoseGraph(SE3, edges, z, info, ids=np.array([7, 3, 9]), fixed=np.array([1]))
    assert (graph.n, graph.m, graph.d, graph.anchor) == (3, 2, 3, 1)
    assert graph.edge_names([1]) == ["3→9"]


def test_levenberg_marquardt_survives_long_robust_runs():
    """Hundreds of successful steps used to drive λ to 0, and the next failure to 0·∞ = nan."""
    graph = synthetic.cube(4, loop_closure_probability=0.5, outlier_rate=0.2, seed=1).graph
    result = LevenbergMarquardt(grad_rtol=1e-10, max_iterations=3000, rel_cost_decrease=0).solve(
        graph.problem("geodesic", robust="huber:3.0"), graph.chordal_initialization()
    )
    assert result.nit > 600 and result.status in (Status.GRADIENT_NORM, Status.STEP_SIZE)
    assert np.all(result.history.extra["damping"][1:] >= 1e-15)
