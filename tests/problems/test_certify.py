"""Certification (manopt_lie.problems.certify) on synthetic instances: the data, the
certificate's verdicts and bounds, the relaxation's derivatives, rounding, the staircase
from good, random and adversarial starts, 2-D and 3-D, poses and rotations."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.check import check_gradient, check_hessian
from manopt_lie.errors import NonFiniteError, NotInGroupError, ShapeError
from manopt_lie.optim import TrustRegion
from manopt_lie.problems import PoseGraph, RotationAveraging, synthetic
from manopt_lie.problems.certify import (
    Certificate,
    StaircaseStatus,
    certify,
    certify_relaxation,
    lift,
    relaxation,
    relaxation_problem,
    round_solution,
    staircase,
)
from manopt_lie.problems.certify.data import stacked
from manopt_lie.problems.costs import chordal_quadratic_form


def _pose_graph_2d(noise: float = 0.01, seed: int = 0) -> PoseGraph:
    return synthetic.grid2d(5, 6, translation_noise=noise, rotation_noise=noise, seed=seed).graph


def _pose_graph_3d(noise: float = 0.01, seed: int = 0) -> PoseGraph:
    return synthetic.cube(3, translation_noise=noise, rotation_noise=noise, seed=seed).graph


def _rotations(d: int, noise: float = 0.05, seed: int = 0) -> RotationAveraging:
    return synthetic.rotation_averaging(40, d=d, noise=noise, seed=seed).graph


GRAPHS = {
    "SE2": _pose_graph_2d,
    "SE3": _pose_graph_3d,
    "SO2": lambda **kw: _rotations(2, **kw),
    "SO3": lambda **kw: _rotations(3, **kw),
}


def _dense_q(rel) -> np.ndarray:
    return rel.q(np.eye(rel.n * rel.d))


def _cycle(group, n: int = 12) -> tuple[RotationAveraging, object]:
    """A cycle of noise-free relative rotations (the optimum: all equal, f* = 0) and the
    "winding" configuration that turns once around it, a spurious critical point."""
    edges = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    graph = RotationAveraging(group, edges, group.identity((n,)))
    tau = np.zeros((n, group.dim))
    tau[:, -1] = 2 * np.pi * np.arange(n) / n
    return graph, group.exp(tau)


# ---- the reduced data ---------------------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_reduced_quadratic_form_is_the_schur_complement(kind):
    graph = GRAPHS[kind]()
    rel = relaxation(graph)
    n, d = graph.n, graph.d
    full = chordal_quadratic_form(n, graph.edges, graph.measurements, graph.chordal_weights()).toarray()
    c = full.shape[0] // n
    rot = (np.arange(n)[:, None] * c + np.arange(d)).ravel()
    if graph.has_translations:
        trans = np.delete(np.arange(n) * c + d, graph.anchor)
        a, b = full[np.ix_(trans, trans)], full[np.ix_(trans, rot)]
        expected = full[np.ix_(rot, rot)] - b.T @ np.linalg.solve(a, b)
    else:
        expected = full[np.ix_(rot, rot)]
    np.testing.assert_allclose(_dense_q(rel), expected, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_reduced_cost_and_poses_are_the_graphs_chordal_cost(kind):
    graph = GRAPHS[kind](noise=0.1)
    rel = relaxation(graph)
    d = graph.d
    rotations = np.asarray(graph.group.random(np.random.default_rng(1), (graph.n,)).as_matrix())[:, :d, :d]
    x = rel.poses(rotations)
    f = rel.cost(rotations)
    assert f == pytest.approx(graph.cost(x, "chordal"), rel=1e-12)
    yt = stacked(rotations)
    assert f == pytest.approx(float(np.vdot(yt, rel.q(yt))), rel=1e-9)
    if graph.has_translations:  # the recovered translations are optimal: the chordal TR cannot improve them
        assert np.allclose(x.as_matrix()[graph.anchor], np.eye(graph.d + 1))


# ---- the relaxation's derivatives and rounding -------------------------------------------


@pytest.mark.parametrize("kind", ["SE2", "SO3"])
@pytest.mark.parametrize("p", [None, 5])
def test_relaxation_gradient_and_hessian(kind, p):
    graph = GRAPHS[kind]()
    rank = graph.d if p is None else p
    problem = relaxation_problem(relaxation(graph), rank, retraction="polar")  # second order
    x = problem.manifold.random_point(np.random.default_rng(2))
    assert check_gradient(problem, x, rng=3).passed
    assert check_hessian(problem, x, rng=4).passed


@pytest.mark.parametrize("d", [2, 3])
def test_rounding_recovers_lifted_rotations_up_to_the_gauge(d, rng):
    group = SO2 if d == 2 else SO3
    r = np.asarray(group.random(rng, (30,)).as_matrix())
    u = np.linalg.qr(rng.standard_normal((5, 5)))[0]  # any O(5) rotation of the lifted point
    y = u @ lift(r, 5)
    rounded = round_solution(y)
    assert np.all(np.linalg.det(rounded) > 0)
    g = rounded[0] @ r[0].T  # the same rotations but for one global rotation
    np.testing.assert_allclose(rounded, g @ r, atol=1e-12)
    np.testing.assert_allclose(round_solution(np.asarray(r)), r, atol=1e-14)


# ---- the certificate ---------------------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_noise_free_truth_is_certified(kind):
    inst = {
        "SE2": lambda: synthetic.grid2d(5, 6, translation_noise=0.0, rotation_noise=0.0),
        "SE3": lambda: synthetic.cube(3, translation_noise=0.0, rotation_noise=0.0),
        "SO2": lambda: synthetic.rotation_averaging(40, d=2, noise=0.0),
        "SO3": lambda: synthetic.rotation_averaging(40, d=3, noise=0.0),
    }[kind]()
    cert = certify(inst.graph, inst.truth)
    assert isinstance(cert, Certificate)
    assert cert.optimal, cert
    assert cert.fun < 1e-20 and 0 <= cert.gap <= cert.atol
    assert cert.lambda_lower >= -cert.eta and abs(cert.lambda_min) < 1e-9


@pytest.mark.parametrize("kind", sorted(GRAPHS))
def test_local_solver_optimum_is_certified_and_bounds_hold(kind):
    graph = GRAPHS[kind]()
    result = TrustRegion(grad_rtol=0, grad_atol=1e-10).solve(graph.problem("chordal"), graph.chordal_initialization())
    cert = certify(graph, result.x)
    assert cert.optimal, cert
    assert cert.fun == pytest.approx(result.fun, rel=1e-12)
    assert cert.dual_bound <= cert.fun <= cert.dual_bound + cert.tol * cert.fun + cert.atol
    # every other solution costs at least the dual bound
    other = graph.odometry_initialization()
    assert graph.cost(other, "chordal") >= cert.dual_bound


@pytest.mark.parametrize("group", [SO2, SO3])
def test_winding_critical_point_is_refused_with_the_exact_eigenpair(group):
    graph, winding = _cycle(group)
    result = TrustRegion().solve(graph.problem("chordal"), winding)
    assert result.fun > 6.0  # a critical point: the trust region does not leave it
    cert = certify(graph, result.x)
    assert not cert.optimal and cert.gap >= cert.fun  # f* = 0 ≥ the dual bound
    rel = relaxation(graph)
    rotations = np.asarray(result.x.as_matrix())
    lam = rel.lambda_blocks(rotations)
    s = _dense_q(rel) - sp.block_diag(list(lam)).toarray()
    exact = np.linalg.eigvalsh(s)[0]
    assert cert.lambda_lower <= exact <= cert.lambda_min + 1e-9 * abs(exact)
    assert cert.lambda_min == pytest.approx(exact, rel=1e-6)
    v = cert.eigenvector.ravel()
    assert np.linalg.norm(s @ v - cert.lambda_min * v) < 1e-5


def test_suboptimal_points_are_refused_within_the_stated_tolerance():
    graph = _pose_graph_3d(noise=0.05)
    opt = staircase(graph)
    assert opt.optimal
    f_star = opt.fun
    rng = np.random.default_rng(5)
    for scale in (1e-2, 1e-3):
        x = opt.x.rplus(scale * rng.standard_normal((graph.n, 6)))
        cert = certify(graph, x, tol=1e-6)
        assert cert.dual_bound <= f_star * (1 + 1e-9)
        assert not cert.optimal  # it costs more than (1 + tol) f*: refused
        assert cert.gap >= graph.cost(x, "chordal") - f_star * (1 + 1e-9)
    loose = certify(graph, opt.x.rplus(1e-4 * rng.standard_normal((graph.n, 6))), tol=1e-2)
    assert loose.optimal and loose.fun <= f_star * (1 + 1e-2)


def test_bad_translations_are_refused_and_optimal_ones_recovered():
    graph = _pose_graph_2d(noise=0.05)
    x = staircase(graph).x
    matrices = np.array(x.as_matrix())
    matrices[:, :2, 2] += 0.1
    matrices[graph.anchor, :2, 2] -= 0.1
    cert = certify(graph, SE2.from_matrix(matrices))
    assert not cert.optimal and "translations" in cert.message
    rotations_only = certify(graph, matrices[:, :2, :2])  # rotations: translations optimal
    assert rotations_only.optimal


def test_solutions_as_plain_arrays():
    graph = _pose_graph_3d()
    x = staircase(graph).x
    m = np.asarray(x.as_matrix())
    reference = certify(graph, x)
    for form in (m, m[:, :3, :], (m[:, :3, :3], m[:, :3, 3]), SO3.from_matrix(m[:, :3, :3])):
        cert = certify(graph, form)
        assert cert.optimal and cert.fun == pytest.approx(reference.fun, rel=1e-9)
    with pytest.raises(ShapeError):
        certify(graph, m[:-1])
    with pytest.raises(NonFiniteError):
        certify(graph, np.where(np.arange(graph.n)[:, None, None] == 3, np.nan, m))
    with pytest.raises(NotInGroupError):
        certify(graph, 1.1 * m[:, :3, :3])
    with pytest.raises(ValueError):
        certify(graph, x, tol=-1.0)


def test_factorization_backends_agree():
    graph, winding = _cycle(SO3)
    for backend in ("cholmod", "superlu"):
        rel = relaxation(graph, backend=backend)
        refused = certify(graph, winding, data=rel)
        accepted = certify(graph, SO3.identity((graph.n,)), data=rel)
        assert not refused.optimal and accepted.optimal, backend
        assert refused.lambda_min == pytest.approx(-0.2679491924311228, rel=1e-6)


def test_relaxation_point_certificate():
    graph = _rotations(3)
    opt = staircase(graph)
    u = np.linalg.qr(np.random.default_rng(6).standard_normal((5, 5)))[0]
    y = u @ lift(np.asarray(opt.x.as_matrix()), 5)
    cert = certify_relaxation(relaxation(graph), y)
    assert cert.optimal and cert.rank == 5
    assert cert.fun == pytest.approx(opt.fun, rel=1e-9)


# ---- the staircase -----------------------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(GRAPHS))
@pytest.mark.parametrize("x0", [None, "random"])
def test_staircase_certifies_from_chordal_and_random_starts(kind, x0):
    graph = GRAPHS[kind](noise=0.05)
    result = staircase(graph, x0, seed=7)
    assert result.optimal and result.status is StaircaseStatus.OPTIMAL, result
    assert result.certificate.optimal
    assert type(result.x) is graph.group and result.x.batch_shape == (graph.n,)
    assert result.fun == pytest.approx(graph.cost(result.x, "chordal"), rel=1e-12)
    assert result.lower_bound <= result.fun and result.suboptimality <= result.certificate.gap + 1e-12
    local = TrustRegion(grad_rtol=0, grad_atol=1e-10).solve(graph.problem("chordal"), graph.chordal_initialization())
    assert result.fun <= local.fun * (1 + 1e-6) + result.certificate.atol
    assert result.levels and result.time >= result.time_certificates > 0


@pytest.mark.parametrize("group", [SO2, SO3])
def test_staircase_escapes_the_winding_saddle(group):
    graph, winding = _cycle(group)
    result = staircase(graph, winding)
    assert result.optimal and result.fun < 1e-12
    first = result.levels[0]
    assert not first.certificate.optimal and first.certificate.lambda_min < -0.2
    assert np.isfinite(first.escape_step) and result.rank > graph.d


def test_staircase_escapes_a_local_minimum_of_the_pose_graph():
    """The chordal trust region on SE(2) from a start wound once around a circle, its steps kept
    short (``Δ̄`` of one typical distance), ends at a spurious critical point (50× the optimum);
    refused, and left by the staircase. (With its default radius it happens to jump to the optimum.)"""
    inst = synthetic.circle2d(2, 20, rotation_noise=0.05, translation_noise=0.1, seed=0)
    graph = inst.graph
    rel = relaxation(graph)
    rotations = inst.truth.as_matrix()[:, :2, :2]
    wind = SO2.exp(2 * np.pi * np.arange(graph.n)[:, None] / graph.n).as_matrix()
    problem = graph.problem("chordal")
    local = TrustRegion(max_radius=problem.manifold.typical_dist).solve(problem, rel.poses(wind @ rotations))
    refused = certify(graph, local.x, data=rel)
    assert not refused.optimal and refused.lambda_min < -1.0
    result = staircase(graph, local.x, data=rel)
    assert result.optimal and result.rank > 2
    assert result.fun < local.fun / 10
    assert refused.dual_bound <= result.fun


def test_staircase_options_and_limits():
    graph, winding = _cycle(SO3)
    capped = staircase(graph, winding, max_rank=3)
    assert not capped.optimal and capped.status is StaircaseStatus.MAX_RANK
    timed_out = staircase(graph, winding, max_time=0.0)
    assert not timed_out.optimal and timed_out.status is StaircaseStatus.MAX_TIME
    assert capped.suboptimality >= capped.fun - 0.0  # f* = 0
    unpreconditioned = staircase(_rotations(2), precondition=False, rank=3)
    assert unpreconditioned.optimal and unpreconditioned.rank == 3
    stiefel = np.random.default_rng(8)
    y0 = relaxation_problem(relaxation(graph), 4).manifold.random_point(stiefel)
    assert staircase(graph, y0).optimal
    with pytest.raises(ValueError):
        staircase(graph, rank=2)
    with pytest.raises(ValueError):
        staircase(graph, "odometry-ish")


def test_staircase_on_a_3d_pose_graph_with_translations_gauge():
    graph = synthetic.cube(3, translation_noise=0.05, rotation_noise=0.05, seed=2).graph
    result = staircase(graph, "random", seed=3, rank=5)
    assert result.optimal
    np.testing.assert_allclose(result.x.as_matrix()[graph.anchor], np.eye(4), atol=1e-12)
    assert isinstance(result.x, SE3)


def test_staircase_escapes_a_local_minimum_of_a_3d_pose_graph():
    """The chordal trust region on SE(3) from random poses, its steps kept short (``Δ̄`` of one
    typical distance), converges (gradient test) to a spurious critical point 50× above the
    optimum; refused, and left at rank 4."""
    graph = synthetic.cube(4, rotation_noise=0.1, translation_noise=0.1, seed=1).graph
    rel = relaxation(graph)
    problem = graph.problem("chordal")
    short = TrustRegion(max_iterations=200, max_radius=problem.manifold.typical_dist)
    local = short.solve(problem, SE3.random(np.random.default_rng(1), (64,)))
    refused = certify(graph, local.x, data=rel)
    assert not refused.optimal and refused.lambda_min < -1.0
    result = staircase(graph, local.x, data=rel)
    assert result.optimal and result.rank > 3
    assert result.fun < local.fun / 10 and refused.dual_bound <= result.fun
    assert result.levels[0].certificate.lambda_min < -1.0 and np.isfinite(result.levels[0].escape_step)


def test_graphs_the_certificate_cannot_use_are_refused_by_name():
    from manopt_lie.problems.costs import IndefiniteInformationError
    from manopt_lie.problems.initialization import DisconnectedGraphError

    graph = _pose_graph_2d()
    info = np.array(graph.information)
    info[3] = 0.0  # singular: no SE-Sync weights
    bad = PoseGraph(graph.group, graph.edges, graph.measurements, info)
    with pytest.raises(IndefiniteInformationError, match="1 edges"):
        relaxation(bad)
    edges = np.array([[0, 1], [2, 3]])
    apart = RotationAveraging(SO3, edges, SO3.identity((2,)), n=4)
    with pytest.raises(DisconnectedGraphError):
        certify(apart, SO3.identity((4,)))
