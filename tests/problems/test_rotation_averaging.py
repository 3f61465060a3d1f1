"""Rotation averaging: costs, solvers, robustness to outliers, from_pose_graph."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE3, SO2, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.optim import GaussNewton, LevenbergMarquardt, Status, TrustRegion
from manopt_lie.problems import PoseGraph, RotationAveraging, evaluation, rotation_averaging, synthetic


@pytest.mark.parametrize("d", [2, 3])
def test_exact_measurements_are_recovered_by_every_solver(d):
    inst = synthetic.rotation_averaging(60, d=d, noise=0.0, seed=4)
    ra = inst.graph
    x0 = ra.odometry_initialization()
    assert evaluation.errors(x0, inst.truth).rotation_stats.max < 1e-9
    start = x0.rplus(0.3 * np.random.default_rng(0).standard_normal((ra.n, ra.group.dim)))
    for cost in ("chordal", "geodesic"):
        for optimizer in (
            TrustRegion(grad_rtol=1e-12, rel_cost_decrease=0),
            LevenbergMarquardt(grad_rtol=1e-12, rel_cost_decrease=0),
            GaussNewton(grad_rtol=1e-12, rel_cost_decrease=0),
        ):
            result = optimizer.solve(ra.problem(cost), start)
            assert result.status is Status.GRADIENT_NORM, (cost, optimizer, result)
            assert result.fun < 1e-18
            assert evaluation.errors(result.x, inst.truth).rotation_stats.max < 1e-9


def test_error_is_consistent_with_the_noise():
    noise = 0.02
    inst = synthetic.rotation_averaging(300, noise=noise, degree=10, seed=5)
    ra = inst.graph
    x0 = ra.chordal_initialization()
    chordal = TrustRegion().solve(ra.problem("chordal"), x0)
    geodesic = LevenbergMarquardt().solve(ra.problem("geodesic"), x0)
    assert chordal.success and geodesic.success
    for x in (chordal.x, geodesic.x):
        rms = evaluation.errors(x, inst.truth).rotation_stats.rms
        # Each rotation is averaged over ~10 edges: error ≈ noise·√(3/10) per rotation, far below the noise.
        assert 0.1 * noise < rms < noise
    assert ra.cost(chordal.x, "chordal") == pytest.approx(chordal.fun, rel=1e-12)
    assert ra.cost(geodesic.x, "geodesic") == pytest.approx(geodesic.fun, rel=1e-12)
    # Whitened residuals at the optimum: chi-square with ~3 degrees of freedom per edge.
    stats = evaluation.edge_residuals(ra, geodesic.x)
    assert 0.5 * 3 * ra.m < stats["chi2"] < 1.5 * 3 * ra.m


@pytest.mark.parametrize("robust", ["huber:2", "l1:1"])
def test_robust_costs_recover_the_inliers(robust):
    inst = synthetic.rotation_averaging(200, noise=0.02, outlier_rate=0.2, seed=3)
    ra = inst.graph
    x0 = ra.chordal_initialization()
    clean = synthetic.rotation_averaging(200, noise=0.02, outlier_rate=0.0, seed=3)
    reference = evaluation.errors(
        LevenbergMarquardt().solve(clean.graph.problem("geodesic"), clean.graph.chordal_initialization()).x,
        clean.truth,
    ).rotation_stats.rms
    plain = LevenbergMarquardt(max_iterations=300).solve(ra.problem("geodesic"), x0)
    robust_result = LevenbergMarquardt(max_iterations=300, rel_cost_decrease=0)
    robust_result = robust_result.solve(ra.problem("geodesic", robust=robust), x0)
    assert robust_result.status is Status.GRADIENT_NORM
    assert evaluation.errors(plain.x, inst.truth).rotation_stats.rms > 10 * reference
    assert evaluation.errors(robust_result.x, inst.truth).rotation_stats.rms < 2 * reference
    # The residuals at the robust estimate single out the outliers.
    flagged = evaluation.edge_residuals(ra, robust_result.x)["norms"] > 10.0
    assert np.mean(flagged == inst.outliers) > 0.99


def test_from_pose_graph_takes_rotations_and_kappa(rng):
    truth = SE3.random(rng, (5,))
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 0]])
    info = np.broadcast_to(np.diag([1.0, 1, 1, 10, 20, 40]), (5, 6, 6))
    graph = PoseGraph(SE3, edges, truth[edges[:, 0]].between(truth[edges[:, 1]]), info, name="g")
    ra = rotation_averaging.from_pose_graph(graph)
    assert ra.group is SO3 and ra.n == 5 and ra.m == 5
    np.testing.assert_allclose(ra.kappa, 3 / (2 * (1 / 10 + 1 / 20 + 1 / 40)))
    x = ra.chordal_initialization()
    np.testing.assert_allclose(x.as_matrix(), (truth[0].inverse() @ truth).rotation().as_matrix(), atol=1e-9)


def test_bad_input_is_rejected(rng):
    edges = np.array([[0, 1], [1, 2]])
    z = SO2.random(rng, (2,))
    with pytest.raises(TypeError):
        RotationAveraging(SE3, edges, z)
    with pytest.raises(ShapeError):
        RotationAveraging(SO2, edges, SO2.random(rng, (3,)))
    with pytest.raises(ValueError, match="positive"):
        RotationAveraging(SO2, edges, z, kappa=np.array([1.0, -1.0]))
    with pytest.raises(ValueError, match="self-loop"):
        RotationAveraging(SO2, np.array([[0, 1], [1, 1]]), z)
    ra = RotationAveraging(SO2, edges, z)
    with pytest.raises(ValueError, match="cost must be"):
        ra.problem("frobenius")
