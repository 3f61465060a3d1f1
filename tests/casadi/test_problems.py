"""Problems from symbolic costs and residuals: derivatives, batching, solvers, bad input."""

from __future__ import annotations

import shutil

import casadi as ca
import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3, NonFiniteError, ShapeError
from manopt_lie.casadi import SymSE2, SymSE3, SymSO3
from manopt_lie.casadi.problems import (
    SymbolicFactor,
    SymbolicTerm,
    least_squares_from_casadi,
    problem_from_casadi,
)
from manopt_lie.check import check_gradient, check_hessian
from manopt_lie.manifolds import Blocks, Euclidean, LieGroupManifold, Power, Product, Sphere
from manopt_lie.optim import Factor, LeastSquaresProblem, LevenbergMarquardt, Status, TrustRegion


def quadratic_form(a: np.ndarray, x: np.ndarray):
    """``f(R) = xᵀRᵀARx``: minimum ``λ_min(A)|x|²`` where ``Rx`` is along the bottom eigenvector."""
    col = x.reshape(3, 1)
    return lambda r: ca.mtimes([col.T, r.T, a, r, col])


@pytest.fixture
def spd(rng):
    b = rng.standard_normal((3, 3))
    return b @ b.T + 0.5 * np.eye(3), rng.standard_normal(3)


# ---- smooth costs ------------------------------------------------------------------------------


@pytest.mark.parametrize("power", [False, True], ids=["element", "power1"])
def test_quadratic_form_on_so3(spd, rng, power):
    a, x = spd
    manifold = Power(LieGroupManifold(SO3), 1) if power else LieGroupManifold(SO3)
    problem = problem_from_casadi(manifold, quadratic_form(a, x))
    for seed in range(3):
        assert check_gradient(problem, rng=seed).passed
        assert check_hessian(problem, rng=seed).passed
    x0 = manifold.random_point(rng)
    res = TrustRegion(grad_rtol=1e-10).solve(problem, x0)
    assert res.success, res
    lam, vec = np.linalg.eigh(a)
    assert res.fun == pytest.approx(lam[0] * x @ x, rel=1e-12)
    rx = res.x.as_matrix().reshape(3, 3) @ x
    assert abs(rx @ vec[:, 0]) == pytest.approx(np.linalg.norm(x), rel=1e-10)


def test_gradient_and_hessian_are_the_manifolds(spd, rng):
    """The chart derivatives equal egrad2rgrad / ehess2rhess of the Euclidean ones (CONVENTIONS §6)."""
    a, x = spd
    m = LieGroupManifold(SO3)
    problem = problem_from_casadi(m, quadratic_form(a, x))
    r = SO3.random(rng)
    egrad = 2.0 * a @ r.as_matrix() @ np.outer(x, x)
    v = rng.standard_normal(3)
    ehess = 2.0 * a @ m.to_ambient(r, v) @ np.outer(x, x)
    np.testing.assert_allclose(problem.grad(r), m.egrad2rgrad(r, egrad), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(problem.hess(r, v), m.ehess2rhess(r, egrad, ehess, v), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(problem.grad(r), 2.0 * np.cross(x, r.as_matrix().T @ a @ r.as_matrix() @ x), atol=1e-12)


def test_power_map_matches_numpy(rng):
    """n rotations, each with its own A_i and x_i (data rows): cost, gradient and Hessian
    of the mapped functions against the numpy formulas."""
    n = 200
    b = rng.standard_normal((n, 3, 3))
    a = b @ np.swapaxes(b, 1, 2)
    x = rng.standard_normal((n, 3))
    m = Power(LieGroupManifold(SO3), n)
    problem = problem_from_casadi(m, lambda r, ai, xi: ca.mtimes([xi.T, r.T, ai, r, xi]), data=(a, x))
    rot = SO3.random(rng, (n,))
    rx = np.einsum("nij,nj->ni", rot.as_matrix(), x)
    assert problem.cost(rot) == pytest.approx(np.einsum("ni,nij,nj->", rx, a, rx), rel=1e-13)
    egrad = 2.0 * np.einsum("nij,nj,nk->nik", a, rx, x)
    v = rng.standard_normal((n, 3))
    ehess = 2.0 * np.einsum("nij,njk,nk,nl->nil", a, m.to_ambient(rot, v), x, x)
    np.testing.assert_allclose(problem.grad(rot), m.egrad2rgrad(rot, egrad), rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(problem.hess(rot, v), m.ehess2rhess(rot, egrad, ehess, v), rtol=1e-11, atol=1e-11)
    assert problem.grad(rot).shape == (n, 3)


@pytest.mark.parametrize("geometry", ["group", "product"])
def test_se3_point_alignment(rng, geometry):
    """``Σᵢ ‖Tᵢ pᵢ − qᵢ‖²`` per pose, in both SE(3) geometries: derivatives pass the checks,
    and the gradient is the numpy one ``2 J_Tᵀ r`` (group geometry)."""
    n = 5
    p, q = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    m = Power(LieGroupManifold(SE3, geometry), n)
    problem = problem_from_casadi(m, lambda t, pi, qi: ca.sumsqr(SymSE3.act(t, pi) - qi), data=(p, q))
    assert check_gradient(problem, rng=1).passed
    assert check_hessian(problem, rng=1).passed
    if geometry == "group":
        x = SE3.random(rng, (n,))
        y, j_x, _ = x.act(p, jac=True)
        np.testing.assert_allclose(problem.grad(x), 2.0 * np.einsum("nki,nk->ni", j_x, y - q), atol=1e-12)


def geodesic_rotation_averaging(rng, n=6):
    """A cycle plus chords of noisy relative rotations, and the numpy cost ``½ Σ ‖Log(R̃ᵢⱼ⁻¹ Rᵢᵀ Rⱼ)‖²``."""
    truth = SO3.random(rng, (n,))
    edges = np.array([(i, (i + 1) % n) for i in range(n)] + [(0, 3), (1, 4), (2, 5)])
    meas = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(0.05 * rng.standard_normal((len(edges), 3)))

    def cost(x):
        r = x[edges[:, 0]].between(x[edges[:, 1]]).rminus(meas)
        return 0.5 * float(np.sum(r * r))

    return edges, meas, cost


def test_edge_terms_and_a_function_of_all_elements(rng):
    """A cost over edges (pairs) and the same cost as one function of all n elements agree,
    with each other and with numpy; several term types add up."""
    n = 6
    edges, meas, numpy_cost = geodesic_rotation_averaging(rng, n)
    z = meas.as_matrix()
    term = lambda ri, rj, zij: 0.5 * ca.sumsqr(SymSO3.rminus(SymSO3.between(ri, rj), zij))
    prior = SymbolicTerm([0], lambda r: 10.0 * ca.sumsqr(SymSO3.log(r)), name="prior")
    m = Power(LieGroupManifold(SO3), n)
    by_edges = problem_from_casadi(m, [SymbolicTerm(edges, term, (z,), "between"), prior])

    def all_at_once(*rs):
        return sum(term(rs[i], rs[j], zij) for (i, j), zij in zip(edges, z, strict=True)) + prior.cost(rs[0])

    whole = problem_from_casadi(m, all_at_once, variables=[range(n)])
    x = SO3.random(rng, (n,))
    v = rng.standard_normal((n, 3))
    expected = numpy_cost(x) + 10.0 * float(np.sum(x[0].log() ** 2))
    assert by_edges.cost(x) == pytest.approx(expected, rel=1e-12)
    assert whole.cost(x) == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(by_edges.grad(x), whole.grad(x), atol=1e-11)
    np.testing.assert_allclose(by_edges.hess(x, v), whole.hess(x, v), atol=1e-11)
    assert check_hessian(by_edges, x, rng=0).passed
    res = TrustRegion(grad_rtol=0.0, grad_atol=1e-10).solve(by_edges, x)
    assert res.success and res.grad_norm <= 1e-10


# ---- least squares ---------------------------------------------------------------------------


def range_bearing(rng, k=6):
    """One SE(2) pose, landmarks with known positions, exact range and bearing measurements."""
    truth = SE2.exp([1.0, -0.5, 0.7])
    landmarks = rng.uniform(-5.0, 5.0, (k, 2))
    local = truth.inverse().act(landmarks)
    z = np.stack([np.linalg.norm(local, axis=1), np.arctan2(local[:, 1], local[:, 0])], axis=1)

    def residual(x, landmark, zi):
        p = SymSE2.act(SymSE2.inverse(x), landmark)
        bearing = ca.atan2(p[1], p[0]) - zi[1]
        return ca.vertcat(ca.norm_2(p) - zi[0], ca.atan2(ca.sin(bearing), ca.cos(bearing)))

    return truth, landmarks, z, residual


@pytest.mark.parametrize(
    ("make", "exact"),
    [(LevenbergMarquardt, False), (TrustRegion, False), (TrustRegion, True)],
    ids=["lm", "tr-gauss-newton", "tr-exact-hessian"],
)
def test_range_bearing_localization(rng, make, exact):
    truth, landmarks, z, residual = range_bearing(rng)
    m = Power(LieGroupManifold(SE2), 1)
    problem = least_squares_from_casadi(
        m, np.zeros((len(z), 1), dtype=int), residual, data=(landmarks, z), exact_hessian=exact
    )
    assert isinstance(problem, LeastSquaresProblem)
    x0 = SE2.identity((1,))
    assert check_gradient(problem, x0, rng=0).passed
    if exact:
        assert check_hessian(problem, x0, rng=0).passed
    res = make(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)  # converge past the 1e-5 rule
    assert res.success, res
    assert res.fun < 1e-18
    assert truth.dist(res.x[0]) < 1e-9


def test_pose_graph_factors_match_numpy_jacobians(rng):
    """Two factor types (relative poses and a prior): the linearization equals that of the
    hand-written numpy factor with closed-form right Jacobians; LM recovers the truth."""
    n = 8
    steps = 0.4 * rng.standard_normal((n - 1, 3))
    poses = [SE2.identity()]
    for s in steps:
        poses.append(poses[-1].rplus(s))
    truth = SE2.stack(poses)
    edges = np.array([(i, i + 1) for i in range(n - 1)] + [(0, 4), (2, 7)])
    meas = truth[edges[:, 0]].between(truth[edges[:, 1]])
    sym = [
        SymbolicFactor(edges, lambda xi, xj, zij: SymSE2.rminus(SymSE2.between(xi, xj), zij), (meas.as_matrix(),)),
        SymbolicFactor([0], lambda x: SymSE2.log(x), name="prior"),
    ]
    m = Power(LieGroupManifold(SE2), n)
    problem = least_squares_from_casadi(m, sym)

    def between(xi, xj, jac):
        if not jac:
            return xi.between(xj).rminus(meas)
        e, j_i, j_j = xi.between(xj, jac=True)
        r, j_e, _ = e.rminus(meas, jac=True)
        return r, [j_e @ j_i, j_e @ j_j]

    def prior(x, jac):
        return x.log(jac=True) if jac else x.log()

    reference = LeastSquaresProblem(m, [Factor(edges, between), Factor([0], prior)])
    x = truth.rplus(0.2 * rng.standard_normal((n, 3)))
    ours, ref = problem.linearize(x), reference.linearize(x)
    assert ours.cost == pytest.approx(ref.cost, rel=1e-12)
    np.testing.assert_allclose(ours.grad, ref.grad, atol=1e-11)
    np.testing.assert_allclose(ours.hessian.toarray(), ref.hessian.toarray(), atol=1e-11)
    res = LevenbergMarquardt(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x)  # past the 1e-5 rule
    assert res.success and truth.dist(res.x).max() < 1e-9


def test_robust_loss_and_fixed_variables(rng):
    truth, landmarks, z, residual = range_bearing(rng)
    z[0, 0] += 5.0  # an outlier
    m = Power(LieGroupManifold(SE2), 2)  # a second, unconstrained and fixed pose
    variables = np.zeros((len(z), 1), dtype=int)
    problem = least_squares_from_casadi(m, variables, residual, data=(landmarks, z), loss="cauchy:0.1", fixed=[1])
    x0 = SE2.identity((2,))
    res = LevenbergMarquardt().solve(problem, x0)
    assert truth.dist(res.x[0]) < 1e-3
    np.testing.assert_array_equal(res.x[1].as_matrix(), np.eye(3))


@pytest.mark.skipif(shutil.which("gcc") is None, reason="jit=True compiles with gcc")
def test_jit_compiled_functions_agree(rng):
    _, landmarks, z, residual = range_bearing(rng, k=4)
    m = Power(LieGroupManifold(SE2), 1)
    args = (m, np.zeros((4, 1), dtype=int), residual)
    plain = least_squares_from_casadi(*args, data=(landmarks, z))
    jitted = least_squares_from_casadi(*args, data=(landmarks, z), jit=True)
    x = SE2.random(rng, (1,))
    np.testing.assert_allclose(jitted.linearize(x).grad, plain.linearize(x).grad, atol=1e-13)


# ---- bad input ---------------------------------------------------------------------------------


def test_bad_manifolds():
    f = lambda r: ca.trace(r)
    with pytest.raises(TypeError, match="two"):
        problem_from_casadi(Euclidean(2, 3, 4), f)
    with pytest.raises(TypeError, match="integer n"):
        problem_from_casadi(Power(LieGroupManifold(SO3), (2, 3)), f)
    with pytest.raises(TypeError, match="Power of a Product"):
        problem_from_casadi(Power(Product(Sphere(3), Euclidean(2)), 2), f)
    with pytest.raises(TypeError, match="single manifolds"):
        problem_from_casadi(Product(Power(Sphere(3), 2), Euclidean(2)), f)
    with pytest.raises(TypeError, match="Blocks"):
        problem_from_casadi(Blocks({"a": Power(Euclidean(2), 2)}), f)
    with pytest.raises(TypeError, match="n = 1 for a single element"):
        least_squares_from_casadi(LieGroupManifold(SO3), [0], lambda r: SymSO3.log(r))
    with pytest.raises(TypeError, match="tangent coordinates"):
        least_squares_from_casadi(Power(Sphere(3), 2), [0], lambda x: x)


def test_bad_costs_and_residuals():
    m = Power(LieGroupManifold(SO3), 2)
    with pytest.raises(ValueError, match="scalar"):
        problem_from_casadi(m, lambda r: SymSO3.log(r))
    with pytest.raises(ValueError, match="vector"):
        least_squares_from_casadi(m, [0, 1], lambda r: r)
    with pytest.raises(TypeError, match="callable"):
        problem_from_casadi(m, [SymbolicTerm([0], "trace")])
    with pytest.raises(TypeError, match="must be callable or a list of SymbolicTerms"):
        problem_from_casadi(m, 3.0)
    with pytest.raises(TypeError, match="numpy array of CasADi objects"):
        problem_from_casadi(m, lambda r: np.array([r[0, 0], r[1, 1]]))
    free = ca.SX.sym("a")
    with pytest.raises(ValueError, match="free variables"):
        problem_from_casadi(m, lambda r: free * ca.trace(r))
    with pytest.raises(ValueError, match=r"outside 0\.\.1"):
        problem_from_casadi(m, lambda r: ca.trace(r), variables=[0, 2])
    with pytest.raises(ShapeError, match=r"data\[0\] must have shape \(2, ...\)"):
        problem_from_casadi(m, lambda r, a: ca.trace(a @ r), data=(np.eye(3),))
    with pytest.raises(NonFiniteError, match="non-finite"):
        problem_from_casadi(m, lambda r, s: s * ca.trace(r), data=([1.0, np.nan],))
    with pytest.raises(ValueError, match="robust loss"):
        least_squares_from_casadi(m, [0], lambda r: SymSO3.log(r), loss="huber:1", exact_hessian=True)


def test_bad_points():
    problem = problem_from_casadi(Power(LieGroupManifold(SO3), 2), lambda r: ca.trace(r))
    with pytest.raises(ShapeError, match=r"batch shape \(2,\)"):
        problem.cost(SO3.identity((3,)))
    with pytest.raises(TypeError, match="expected a SO3 element"):
        problem.cost(SE3.identity((2,)))
    with pytest.raises(ShapeError, match="tangent vector"):
        problem.hess(SO3.identity((2,)), np.zeros(3))


def test_constant_and_status(rng):
    """A cost that ignores its argument is a constant with zero derivatives: solvers stop at once."""
    problem = problem_from_casadi(LieGroupManifold(SO3), lambda r: 2.0)
    x = SO3.random(rng)
    assert problem.cost(x) == 2.0
    np.testing.assert_array_equal(problem.grad(x), np.zeros(3))
    assert TrustRegion().solve(problem, x).status is Status.GRADIENT_NORM


def test_public_spellings(spd, rng):
    """``manopt_lie.casadi.problem_from_casadi`` / ``least_squares_from_casadi`` are the public
    spellings; the optim classes have no CasADi constructors (optim never imports casadi)."""
    import manopt_lie.casadi
    from manopt_lie.optim import Problem

    assert manopt_lie.casadi.problem_from_casadi is problem_from_casadi
    assert manopt_lie.casadi.least_squares_from_casadi is least_squares_from_casadi
    assert not hasattr(Problem, "from_casadi") and not hasattr(LeastSquaresProblem, "from_casadi")
    a, x = spd
    problem = manopt_lie.casadi.problem_from_casadi(LieGroupManifold(SO3), quadratic_form(a, x))
    assert TrustRegion(grad_rtol=1e-10).solve(problem, SO3.identity()).fun == pytest.approx(
        np.linalg.eigvalsh(a)[0] * x @ x, rel=1e-10
    )
    truth, landmarks, z, residual = range_bearing(rng)
    lsq = manopt_lie.casadi.least_squares_from_casadi(
        Power(LieGroupManifold(SE2), 1), np.zeros((len(z), 1), dtype=int), residual, data=(landmarks, z)
    )
    assert isinstance(lsq, LeastSquaresProblem)
    assert truth.dist(LevenbergMarquardt(grad_rtol=1e-12).solve(lsq, SE2.identity((1,))).x[0]) < 1e-9
