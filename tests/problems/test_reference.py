"""The CasADi/IPOPT reference solver: its objective is our cost, its derivatives are finite
and correct, and it reaches the optima our optimizers reach."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.optim import LevenbergMarquardt, TrustRegion
from manopt_lie.problems import PoseGraph, evaluation, g2o, synthetic
from manopt_lie.problems.costs import IndefiniteInformationError
from manopt_lie.problems.reference import build_nlp, reference_solve

RTOL_COST = 1e-6
ATOL_POSES = 1e-5


def _instance(kind: str, **noise: float) -> synthetic.Instance:
    """Small instances of each group (``noise`` overrides the generator's noise levels)."""
    if kind == "SE2":
        return synthetic.grid2d(4, 5, loop_closure_probability=0.5, seed=1, **noise)
    if kind == "SE3":
        return synthetic.cube(3, loop_closure_probability=0.3, seed=1, **noise)
    d = 2 if kind == "SO2" else 3
    return synthetic.rotation_averaging(15, d=d, degree=4, seed=1, **noise)


def _noise_free(kind: str) -> synthetic.Instance:
    if kind.startswith("SE"):
        return _instance(kind, translation_noise=0.0, rotation_noise=0.0)
    return _instance(kind, noise=0.0)


KINDS = ["SE2", "SE3", "SO2", "SO3"]
PARAMETRIZATIONS = ["quaternion", "matrix"]
COSTS = ["chordal", "geodesic"]


def _ours(graph, x0, cost, robust=None):
    """TrustRegion on the chordal cost, Levenberg-Marquardt on the geodesic one, run to a tight gradient."""
    tight = {"grad_rtol": 1e-10, "rel_cost_decrease": 0.0}  # no early stop on the cost decrease
    optimizer = TrustRegion(**tight) if cost == "chordal" else LevenbergMarquardt(**tight)
    return optimizer.solve(graph.problem(cost, robust=robust), x0)


def _assert_same_optimum(reference, ours, x0, anchor):
    assert reference.success, reference
    assert reference.fun == pytest.approx(ours.fun, rel=RTOL_COST)
    aligned = evaluation.align(reference.x, ours.x)
    np.testing.assert_allclose(aligned.as_matrix(), ours.x.as_matrix(), atol=ATOL_POSES)
    # Both fixed the gauge at x0's anchor, so they agree without alignment too.
    np.testing.assert_allclose(reference.x.as_matrix(), ours.x.as_matrix(), atol=ATOL_POSES)
    np.testing.assert_array_equal(reference.x[anchor].as_matrix(), x0[anchor].as_matrix())
    # IPOPT's own objective (at its unprojected solution) is our cost at the projected one.
    assert reference.objective == pytest.approx(reference.fun, rel=1e-10, abs=1e-12)


# ---- the objective is our cost ---------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("robust", [None, "huber:1.0", "cauchy:0.5", "l1:0.3", "geman-mcclure:2.0"])
def test_objective_equals_our_cost(kind, parametrization, cost, robust, rng):
    inst = _instance(kind)
    graph = inst.graph
    x = inst.truth.rplus(0.3 * rng.standard_normal((graph.n, graph.group.dim)))
    nlp = build_nlp(graph, x, cost=cost, robust=robust, parametrization=parametrization)
    value = float(nlp.objective(nlp.pack(x)))
    expected = graph.cost(x, cost) if robust is None else graph.problem(cost, robust=robust).cost(x)
    assert value == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(np.asarray(nlp.constraints(nlp.pack(x))), 0.0, atol=1e-14)
    back, reflections = nlp.unpack(nlp.pack(x))
    assert reflections == 0
    np.testing.assert_allclose(back.as_matrix(), x.as_matrix(), atol=1e-14)


@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
def test_geodesic_rotation_averaging_at_large_angles(parametrization, rng):
    """Haar-random rotations: residual angles anywhere in [0, π)."""
    graph = _instance("SO3").graph
    x = SO3.random(rng, (graph.n,))
    nlp = build_nlp(graph, x, cost="geodesic", parametrization=parametrization)
    assert float(nlp.objective(nlp.pack(x))) == pytest.approx(graph.cost(x, "geodesic"), rel=1e-10)


# ---- derivatives -------------------------------------------------------------------------------


def _derivatives(nlp, v, lam_g):
    f, grad = (np.asarray(a, dtype=np.float64) for a in nlp.options["grad_f"](v, []))
    hess = nlp.options["hess_lag"](v, [], 1.0, lam_g).full()
    return float(f.item()), grad.reshape(-1), hess


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("robust", [None, "huber:1.0"])
def test_derivatives_are_finite_at_zero_residual(kind, parametrization, cost, robust):
    """Noise-free measurements at the truth: every residual is exactly zero, where the
    geodesic Log, V(θ)⁻¹, Jl(θ)⁻¹ and √s of Huber must still have finite derivatives."""
    inst = _noise_free(kind)
    nlp = build_nlp(inst.graph, inst.truth, cost=cost, robust=robust, parametrization=parametrization)
    lam_g = np.ones(nlp.nlp["g"].numel())
    f, grad, hess = _derivatives(nlp, nlp.pack(inst.truth), lam_g)
    assert f == pytest.approx(0.0, abs=1e-20)
    assert np.all(np.isfinite(hess))
    np.testing.assert_allclose(grad, 0.0, atol=1e-9)
    # IPOPT started at the optimum stays there.
    result = reference_solve(inst.graph, inst.truth, cost=cost, robust=robust, parametrization=parametrization)
    assert result.success and result.fun < 1e-20, result


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
@pytest.mark.parametrize("cost", COSTS)
def test_assembled_derivatives_match_casadi(kind, parametrization, cost, rng):
    """The per-edge derivatives summed by the scatter matrices equal CasADi's AD of the whole graph."""
    inst = _instance(kind)
    graph = inst.graph
    x = inst.truth.rplus(0.2 * rng.standard_normal((graph.n, graph.group.dim)))
    nlp = build_nlp(graph, x, cost=cost, robust="cauchy:2.0", parametrization=parametrization)
    v, g = nlp.nlp["x"], nlp.nlp["g"]
    lam_g = ca.MX.sym("lam_g", g.numel())
    lagrangian = nlp.nlp["f"] + ca.dot(lam_g, g)
    auto = ca.Function(
        "auto", [v, lam_g], [ca.gradient(nlp.nlp["f"], v), ca.hessian(lagrangian, v)[0], ca.jacobian(g, v)]
    )
    values, lam = nlp.pack(x) + 1e-3 * rng.standard_normal(v.numel()), rng.standard_normal(g.numel())
    grad_auto, hess_auto, jac_auto = (a.full() for a in auto(values, lam))
    _, grad, hess = _derivatives(nlp, values, lam)
    jac = nlp.options["jac_g"](values, [])[1].full()
    np.testing.assert_allclose(grad, grad_auto.reshape(-1), rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(hess, np.triu(hess_auto), rtol=1e-10, atol=1e-7)
    np.testing.assert_allclose(jac, jac_auto, rtol=1e-12, atol=1e-12)


# ---- same optimum as our optimizers ------------------------------------------------------------


SYNTHETIC = {
    "grid2d": lambda: synthetic.grid2d(5, 5, seed=1),
    "cube": lambda: synthetic.cube(3, loop_closure_probability=0.3, seed=1),
    "so3": lambda: synthetic.rotation_averaging(30, seed=1),
    "so2": lambda: synthetic.rotation_averaging(30, d=2, seed=1),
}


@pytest.mark.parametrize("name", list(SYNTHETIC))
@pytest.mark.parametrize("cost", COSTS)
@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
def test_synthetic_optimum_matches_our_optimizers(name, cost, parametrization):
    graph = SYNTHETIC[name]().graph
    x0 = graph.chordal_initialization()
    ours = _ours(graph, x0, cost)
    reference = reference_solve(graph, x0, cost=cost, parametrization=parametrization)
    assert reference.parametrization == parametrization
    _assert_same_optimum(reference, ours, x0, getattr(graph, "anchor", 0))


@pytest.mark.parametrize("dataset_name", ["tinyGrid3D", "smallGrid3D"])
@pytest.mark.parametrize("cost", COSTS)
def test_dataset_optimum_matches_our_optimizers(dataset, dataset_name, cost):
    graph = g2o.read(dataset(dataset_name))
    x0 = graph.chordal_initialization()
    ours = _ours(graph, x0, cost)
    reference = reference_solve(graph, x0, cost=cost)
    _assert_same_optimum(reference, ours, x0, graph.anchor)


@pytest.mark.parametrize(
    ("make", "robust"),
    [
        (lambda: synthetic.grid2d(6, 6, loop_closure_probability=0.5, outlier_rate=0.2, seed=3), "cauchy:3.0"),
        (lambda: synthetic.cube(3, loop_closure_probability=0.5, outlier_rate=0.2, seed=3), "huber:3.0"),
        (lambda: synthetic.rotation_averaging(40, outlier_rate=0.2, seed=3), "huber:1.0"),
    ],
    ids=["grid2d-cauchy", "cube-huber", "so3-huber"],
)
@pytest.mark.parametrize("cost", COSTS)
def test_robust_optimum_matches_our_optimizers(make, robust, cost):
    """Robust costs are not convex: these instances are ones where both solvers reach the same
    local minimum from the chordal initialization (on others IPOPT may find a lower one)."""
    inst = make()
    assert inst.outliers.any()
    graph = inst.graph
    x0 = graph.chordal_initialization()
    ours = _ours(graph, x0, cost, robust)
    reference = reference_solve(graph, x0, cost=cost, robust=robust)
    assert reference.parametrization == ("matrix" if isinstance(graph, PoseGraph) else "quaternion")  # "auto"
    _assert_same_optimum(reference, ours, x0, getattr(graph, "anchor", 0))
    # The reference is a critical point of our robust problem.
    problem = graph.problem(cost, robust=robust)
    grad = problem.manifold.norm(reference.x, problem.grad(reference.x))
    assert grad <= 1e-6 * problem.manifold.norm(x0, problem.grad(x0))


@pytest.mark.parametrize("parametrization", PARAMETRIZATIONS)
def test_anchor_other_than_vertex_zero(parametrization):
    """A g2o ``FIX`` on vertex 7: the variables skip it and it keeps its pose from x0."""
    graph = dataclasses.replace(synthetic.cube(3, loop_closure_probability=0.3, seed=2).graph, fixed=np.array([7]))
    assert graph.anchor == 7
    x0 = graph.chordal_initialization().rplus(0.05 * np.random.default_rng(1).standard_normal((graph.n, 6)))
    for cost in COSTS:
        reference = reference_solve(graph, x0, cost=cost, parametrization=parametrization)
        _assert_same_optimum(reference, _ours(graph, x0, cost), x0, 7)


# ---- results, options and errors -------------------------------------------------------------


def test_result_fields_and_options():
    graph = synthetic.grid2d(5, 5, seed=1).graph
    x0 = graph.chordal_initialization()
    result = reference_solve(graph, x0, cost="geodesic")
    assert isinstance(result.x, SE2) and result.x.batch_shape == (graph.n,)
    assert result.status == "Solve_Succeeded" and result.success and result.message == ""
    assert result.iterations > 0 and result.time > 0 and result.build_time > 0
    assert result.constraint_violation < 1e-10
    assert result.fun == pytest.approx(graph.cost(result.x, "geodesic"), rel=1e-14)
    stopped = reference_solve(graph, x0, cost="geodesic", options={"max_iter": 1})
    assert stopped.status == "Maximum_Iterations_Exceeded" and not stopped.success
    assert stopped.iterations == 1


def test_reflections_are_reported():
    graph = synthetic.cube(3, seed=1).graph
    x0 = graph.chordal_initialization()
    nlp = build_nlp(graph, x0, parametrization="matrix")
    values = nlp.pack(x0).reshape(graph.n - 1, -1)
    values[3, :9] *= -1.0  # R ↦ −R, a reflection in 3-D
    x, reflections = nlp.unpack(values.reshape(-1))
    assert reflections == 1 and isinstance(x, SE3)


def test_bad_input_is_rejected():
    graph = synthetic.cube(3, seed=1).graph
    x0 = graph.chordal_initialization()
    with pytest.raises(ValueError, match="cost must be one of"):
        reference_solve(graph, x0, cost="manhattan")
    with pytest.raises(ValueError, match="parametrization must be one of"):
        reference_solve(graph, x0, parametrization="euler")
    with pytest.raises(ValueError, match="x0 must be a SE3 element"):
        reference_solve(graph, SE2.identity((graph.n,)))
    with pytest.raises(ValueError, match="x0 must be a SE3 element"):
        reference_solve(graph, x0.as_matrix())
    with pytest.raises(ShapeError, match=rf"batch shape \({graph.n},\)"):
        reference_solve(graph, x0[:-1])
    with pytest.raises(ValueError, match="unknown robust loss"):
        reference_solve(graph, x0, robust="tukey:1.0")
    with pytest.raises(TypeError, match="must be a MeasurementGraph"):
        reference_solve(graph.measurements, x0)


def test_unusable_weights_are_rejected():
    graph = synthetic.cube(3, seed=1).graph
    information = graph.information.copy()
    information[4, 3:, 3:] *= -1.0  # κ < 0 on edge 4, and Ω indefinite
    bad = dataclasses.replace(graph, information=information)
    x0 = graph.chordal_initialization()
    with pytest.raises(IndefiniteInformationError, match="κ, τ > 0"):
        reference_solve(bad, x0, cost="chordal")
    with pytest.raises(IndefiniteInformationError, match="positive definite"):
        reference_solve(bad, x0, cost="geodesic", robust="huber:1.0")
    # Without a loss the geodesic cost ½ Σ rᵀΩr is defined for any Ω, as in spec.cost.
    nlp = build_nlp(bad, x0, cost="geodesic")
    assert float(nlp.objective(nlp.pack(x0))) == pytest.approx(bad.cost(x0, "geodesic"), rel=1e-12)
