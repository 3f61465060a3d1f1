"""The symbolic groups against the numpy kernels: values, edge cases, derivatives."""

from __future__ import annotations

from functools import cache

import casadi as ca
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import S3, SE2, SE3, SE23, SO2, SO3, Bundle, LieGroup, Rn, ShapeError, Sim2, Sim3
from manopt_lie.casadi import SymbolicGroup, SymSE2, SymSE3, SymSO2, SymSO3, symbolic
from manopt_lie.casadi import lie as casadi_lie
from manopt_lie.lie import _series

TWINS = [SymSO2, SymSO3, SymSE2, SymSE3]
twins = pytest.mark.parametrize("sym", TWINS, ids=lambda s: s.__name__)
ROTATION = {SO2: slice(0, 1), SO3: slice(0, 3), SE2: slice(2, 3), SE3: slice(3, 6)}
REGIMES = ["identity", "tiny", "random", "uniform", "near_pi", "at_pi"]
TOL = 1e-12


def tangent(group: type[LieGroup], regime: str, rng: np.random.Generator) -> np.ndarray:
    """A tangent of a sampling regime: zero, ``1e-8·randn``, ``randn``, or a rotation angle
    within ``1e-9`` of π (``near_pi``) or exactly π (``at_pi``, on a coordinate axis)."""
    tau = rng.standard_normal(group.dim)
    if regime == "identity":
        return np.zeros(group.dim)
    if regime == "tiny":
        return 1e-8 * tau
    if regime in ("random", "uniform"):
        return tau
    part = ROTATION[group]
    if regime == "at_pi":
        axis = np.zeros(part.stop - part.start)
        axis[rng.integers(axis.size)] = 1.0
        tau[part] = np.pi * axis
        return tau
    rot = tau[part]
    tau[part] = rot / np.linalg.norm(rot) * (np.pi - rng.uniform(1e-12, 1e-9))
    return tau


def element(group: type[LieGroup], regime: str, rng: np.random.Generator) -> LieGroup:
    if regime == "uniform":
        return group.random(rng)
    if regime == "at_pi" and group in (SO3, SE3):
        # A rotation by exactly π: diag with two −1 (no rounding in Exp).
        m = group.identity().as_matrix().copy()
        keep = rng.integers(3)
        flip = [i for i in range(3) if i != keep]
        m[flip, flip] = -1.0
        if group is SE3:
            m[:3, 3] = rng.standard_normal(3)
        return group.from_matrix(m)
    return group.exp(tangent(group, regime, rng))


@cache
def functions(sym: type[SymbolicGroup]) -> dict[str, ca.Function]:
    """Every operation of ``sym`` as a ``casadi.Function`` of SX symbols."""
    k, d = sym.size, sym.dim
    mx, my = ca.SX.sym("x", k, k), ca.SX.sym("y", k, k)
    x, y = sym.from_matrix(mx), sym.from_matrix(my)  # SE(n): the last rows are unused inputs
    tau = ca.SX.sym("tau", d)
    p = ca.SX.sym("p", k - 1 if sym in (SymSE2, SymSE3) else k)
    a = ca.SX.sym("a", k, k)
    fs = {
        "exp": ([tau], sym.exp(tau)),
        "log": ([mx], sym.log(x)),
        "compose": ([mx, my], sym.compose(x, y)),
        "inverse": ([mx], sym.inverse(x)),
        "act": ([mx, p], sym.act(x, p)),
        "adjoint": ([mx], sym.adjoint(x)),
        "rplus": ([mx, tau], sym.rplus(x, tau)),
        "rminus": ([my, mx], sym.rminus(y, x)),
        "lplus": ([mx, tau], sym.lplus(x, tau)),
        "lminus": ([my, mx], sym.lminus(y, x)),
        "between": ([mx, my], sym.between(x, y)),
        "hat": ([tau], sym.hat(tau)),
        "vee": ([a], sym.vee(a)),
    }
    return {name: ca.Function(name, ins, [ca.densify(ca.SX(out))]) for name, (ins, out) in fs.items()}


def call(f: ca.Function, *args: np.ndarray) -> np.ndarray:
    out = np.array(f(*args))
    return out.ravel() if out.shape[1] == 1 else out


def assert_close(actual: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(actual, expected, rtol=0, atol=TOL * max(1.0, np.abs(expected).max()))


@twins
@pytest.mark.parametrize("regime", REGIMES)
@given(seed=st.integers(0, 2**32 - 1))
def test_operations_agree_with_numpy(sym, regime, seed):
    rng = np.random.default_rng(seed)
    g = sym.group
    f = functions(sym)
    x, y = element(g, regime, rng), element(g, regime, rng)
    mx, my = x.as_matrix(), y.as_matrix()
    tau = tangent(g, regime, rng)
    p = rng.standard_normal(g.point_dim)
    assert_close(call(f["exp"], tau), g.exp(tau).as_matrix())
    log = call(f["log"], mx)
    if regime == "at_pi" and g in (SO3, SE3):
        # Either axis sign is valid at exactly π: compare through Exp, and the angle.
        assert_close(g.exp(log).as_matrix(), mx)
        assert_close(np.abs(log[ROTATION[g]]), np.abs(x.log()[ROTATION[g]]))
    else:
        assert_close(log, x.log())
    assert_close(call(f["compose"], mx, my), x.compose(y).as_matrix())
    assert_close(call(f["inverse"], mx), x.inverse().as_matrix())
    assert_close(call(f["act"], mx, p), x.act(p))
    assert_close(np.atleast_2d(call(f["adjoint"], mx)), np.atleast_2d(x.adjoint()))
    assert_close(call(f["rplus"], mx, tau), x.rplus(tau).as_matrix())
    assert_close(call(f["lplus"], mx, tau), x.lplus(tau).as_matrix())
    assert_close(call(f["between"], mx, my), x.between(y).as_matrix())
    if regime not in ("near_pi", "at_pi"):  # differences of two elements near π are generic
        assert_close(call(f["rminus"], my, mx), y.rminus(x))
        assert_close(call(f["lminus"], my, mx), y.lminus(x))
    hat = g.hat(tau)
    assert_close(call(f["hat"], tau), hat)
    assert_close(call(f["vee"], hat), tau)


@twins
def test_log_near_pi_to_machine_precision(sym):
    """Angles π − ε for ε down to 0: the symbolic log agrees with numpy to 1e-12."""
    g = sym.group
    f = functions(sym)
    rng = np.random.default_rng(0)
    for gap in (1e-6, 1e-9, 1e-12, 0.0):
        for _ in range(10):
            tau = rng.standard_normal(g.dim)
            rot = tau[ROTATION[g]]
            tau[ROTATION[g]] = rot / np.linalg.norm(rot) * (np.pi - gap)
            x = g.exp(tau)
            log = call(f["log"], x.as_matrix())
            if gap == 0.0 and g in (SO3, SE3):
                assert_close(g.exp(log).as_matrix(), x.as_matrix())
            else:
                assert_close(log, x.log())


@twins
def test_exact_edge_values(sym):
    f = functions(sym)
    eye = sym.identity()
    np.testing.assert_array_equal(call(f["exp"], np.zeros(sym.dim)), np.array(eye))
    np.testing.assert_array_equal(call(f["log"], np.array(eye)), np.zeros(sym.dim))


@twins
def test_derivatives_finite_at_identity(sym):
    """Every small-angle branch has finite derivatives of first and second order at 0."""
    d = sym.dim
    delta = ca.SX.sym("d", d)
    mx = ca.SX.sym("x", sym.size, sym.size)
    x = sym.from_matrix(mx)
    around = sym.log(sym.exp(delta))
    h, _ = ca.hessian(ca.sumsqr(sym.log(sym.rplus(x, delta))) + ca.sumsqr(around), delta)
    fn = ca.Function("f", [delta, mx], [ca.jacobian(around, delta), ca.jacobian(sym.log(x), mx), h])
    j_log_exp, j_log, hess = (np.array(o) for o in fn(np.zeros(d), np.array(sym.identity())))
    np.testing.assert_allclose(j_log_exp, np.eye(d), atol=1e-15)
    assert np.isfinite(j_log).all() and np.isfinite(hess).all()
    np.testing.assert_allclose(hess, 4.0 * np.eye(d), atol=1e-12)  # ‖δ‖² + ‖δ‖² about the identity


@twins
def test_right_jacobians_match_numpy(sym):
    """CasADi's derivatives through the chart X ⊕ δ are the closed-form right Jacobians (CONVENTIONS §4)."""
    g = sym.group
    rng = np.random.default_rng(1)
    k, d = sym.size, sym.dim
    mx = ca.SX.sym("x", k, k)
    x = sym.from_matrix(mx)
    tau = ca.SX.sym("tau", d)
    dx, dt = ca.SX.sym("dx", d), ca.SX.sym("dt", d)
    y0 = sym.rplus(x, tau)
    y = sym.rplus(sym.rplus(x, dx), tau + dt)
    err = sym.rminus(y, y0)  # the right-Jacobian definition: (f(X ⊕ δ) ⊖ f(X)) / δ
    fn = ca.Function("j", [mx, tau, dx, dt], [ca.jacobian(err, dx), ca.jacobian(err, dt)])
    xs, ts = g.random(rng), 0.7 * rng.standard_normal(d)
    j_x, j_t = (np.array(o) for o in fn(xs.as_matrix(), ts, np.zeros(d), np.zeros(d)))
    _, ref_x, ref_t = xs.rplus(ts, jac=True)
    np.testing.assert_allclose(j_x, ref_x, atol=1e-12)
    np.testing.assert_allclose(j_t, ref_t, atol=1e-12)


def test_mx_and_numbers():
    """The same code runs on MX (and on plain numbers, as DM)."""
    tau, mx = ca.MX.sym("tau", 6), ca.MX.sym("X", 4, 4)
    x = SymSE3.from_matrix(mx)
    f = ca.Function("f", [tau, mx], [SymSE3.rminus(SymSE3.rplus(x, tau), x)])
    t = np.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    m = SE3.random(0).as_matrix()
    np.testing.assert_allclose(np.array(f(t, m)).ravel(), t, atol=1e-14)
    assert isinstance(SymSO3.exp([0.1, 0.2, 0.3]), ca.DM)
    np.testing.assert_allclose(np.array(SymSO3.exp([0.1, 0.2, 0.3])), SO3.exp([0.1, 0.2, 0.3]).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(np.array(SymSO2.log(SO2.from_angle(0.5).as_matrix())), [[0.5]], atol=1e-15)


def test_twin_lookup_and_bad_input():
    assert [symbolic(g) for g in (SO2, SO3, SE2, SE3)] == TWINS
    with pytest.raises(TypeError, match="no symbolic twin of R3"):
        symbolic(Rn(3))  # alone, Rⁿ needs no twin; inside a Bundle it has one (lie_extended.sym_rn)

    class Other(LieGroup):
        pass

    with pytest.raises(TypeError, match="no symbolic twin of Other"):
        symbolic(Other)
    with pytest.raises(ShapeError, match="vector of 3 entries"):
        SymSO3.exp(ca.SX.sym("t", 2))
    with pytest.raises(ShapeError, match="4×4"):
        SymSE3.log(ca.SX.sym("x", 3, 3))
    with pytest.raises(ShapeError, match="p: expected a vector of 2"):
        SymSE2.act(SymSE2.identity(), [1.0, 2.0, 3.0])
    with pytest.raises(TypeError, match="CasADi"):
        SymSO3.log("R")


# ---- the coefficient functions: one source (``lie._series``), two backends ------------------

COEFFICIENTS = pytest.mark.parametrize("coef", _series.COEFFICIENTS, ids=lambda c: c.name)


def angle_grid(coef: _series.Coefficient) -> np.ndarray:
    """Both branches: 0, tiny angles (θ² denormal or zero), every threshold ± 1 ulp, π, and
    up to just below 2π (just below the singularity at 2π for jinv_coef and half_cot)."""
    thresholds = np.array([c.threshold for c in _series.COEFFICIENTS])
    top = 2 * np.pi - (1e-6 if coef.name in ("jinv_coef", "half_cot") else 4e-16)
    special = [0.0, 5e-324, 1e-300, 1e-160, 1e-20, 1e-8, np.pi, 2 * np.pi - 1e-3, top]
    edges = np.concatenate([thresholds, np.nextafter(thresholds, 0), np.nextafter(thresholds, 1)])
    return np.unique(np.concatenate([special, edges, np.linspace(0.0, top, 301)]))


def symbolic_values(coef: _series.Coefficient, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exported CasADi function at ``t = θ²``, without and with the angle (mapped SX functions)."""
    f = getattr(casadi_lie, coef.name)
    t, a = ca.SX.sym("t"), ca.SX.sym("a")
    of_t = ca.Function("f", [t], [f(t)]).map(theta.size)
    of_t_theta = ca.Function("g", [t, a], [f(t, a)]).map(theta.size)
    return np.array(of_t(theta * theta)).ravel(), np.array(of_t_theta(theta * theta, theta)).ravel()


@COEFFICIENTS
def test_numpy_and_casadi_coefficients_agree(coef):
    """The numpy kernels' and the CasADi evaluations of the same data agree to 1e-14 relative,
    on both branches and at the switch (both select on θ², so they pick the same branch)."""
    theta = angle_grid(coef)
    numpy = _series.evaluate(coef, theta * theta, theta)
    assert np.isfinite(numpy).all()
    for sym in symbolic_values(coef, theta):
        np.testing.assert_allclose(sym, numpy, rtol=1e-14, atol=1e-300)
    # The signed angle: every closed form is even.
    np.testing.assert_allclose(symbolic_values(coef, -theta)[1], numpy, rtol=1e-14, atol=1e-300)


@COEFFICIENTS
def test_casadi_coefficient_derivatives_are_finite_and_exact_at_zero(coef):
    """``f'(0) = c₁`` and ``f''(0) = 2c₂`` through ``ca.jacobian``/``ca.hessian`` in ``t``, and
    ``d²f(θ², θ)/dθ² = 2c₁`` at ``θ = 0``; finite on both sides of the threshold."""
    f = getattr(casadi_lie, coef.name)
    t, a = ca.SX.sym("t"), ca.SX.sym("a")
    d1 = ca.Function("d", [t], [ca.jacobian(f(t), t), ca.hessian(f(t), t)[0]])
    d_theta = ca.Function("e", [a], [ca.jacobian(f(a * a, a), a), ca.hessian(f(a * a, a), a)[0]])
    j0, h0 = (float(v) for v in d1(0.0))
    assert j0 == pytest.approx(coef.series[1], rel=1e-15)
    assert h0 == pytest.approx(2.0 * coef.series[2], rel=1e-15)
    j0, h0 = (float(v) for v in d_theta(0.0))
    assert j0 == 0.0 and h0 == pytest.approx(2.0 * coef.series[1], rel=1e-15)
    for t0 in (coef.threshold2, np.nextafter(coef.threshold2, 0), 0.25, 4.0):
        assert np.isfinite([float(v) for v in d1(t0)]).all()
    # First derivatives match across the switch (the series is the closed form's Taylor series).
    below, above = (float(d1(x)[0]) for x in (np.nextafter(coef.threshold2, 0), coef.threshold2))
    assert below == pytest.approx(above, rel=1e-6)


def test_numpy_and_casadi_atan2_ratio_agree():
    """``atan2(s, c)/s`` at quaternion-like ``(|v|, w)`` and matrix-like ``(sin θ, cos θ)`` pairs,
    on both sides of the series switch ``s/c = 1e-3``, for ``c`` of either sign and at ``s = 0``."""
    phi = np.concatenate([np.linspace(0.0, np.pi, 181), [1e-12, np.pi / 2, np.pi - 1e-9]])
    ratios = np.array([1e-3, np.nextafter(1e-3, 0), np.nextafter(1e-3, 1), 1e-8])
    s = np.concatenate([np.sin(phi), ratios / np.hypot(1.0, ratios), [0.0, 0.0]])
    c = np.concatenate([np.cos(phi), 1.0 / np.hypot(1.0, ratios), [-1.0, 0.0]])
    numpy = _series.atan2_ratio(s * s, c)
    s2, w = ca.SX.sym("s2"), ca.SX.sym("w")
    sym = np.array(ca.Function("r", [s2, w], [casadi_lie.atan2_ratio(s2, w)]).map(s.size)(s * s, c)).ravel()
    assert np.isfinite(numpy).all()
    np.testing.assert_allclose(sym, numpy, rtol=1e-14, atol=0)
    grad = ca.Function("g", [s2, w], [ca.jacobian(casadi_lie.atan2_ratio(s2, w), ca.vertcat(s2, w))])
    hess = ca.Function("h", [s2, w], [ca.hessian(casadi_lie.atan2_ratio(s2, w), ca.vertcat(s2, w))[0]])
    np.testing.assert_allclose(np.array(grad(0.0, 1.0)).ravel(), [-1.0 / 3.0, -1.0], rtol=1e-15)
    assert np.isfinite(np.array(hess(0.0, 1.0))).all()


# ---- the twins of Sim3, SE23, Rn and bundles (casadi.lie_extended) ----------------------------

NEW = [Sim3, Sim2, SE23, S3, Rn(3), Bundle(SO3, Rn(3)), Bundle(SE2, Sim3), Bundle(S3, SE23)]


def _twin(group: type[LieGroup]) -> type[SymbolicGroup]:
    from manopt_lie.casadi.lie_extended import sym_rn

    return sym_rn(group) if group is Rn(3) else symbolic(group)


def _new_tangent(group: type[LieGroup], regime: str, rng: np.random.Generator) -> np.ndarray:
    tau = rng.standard_normal(group.dim)
    if regime == "identity":
        return np.zeros(group.dim)
    if regime == "tiny":
        return 1e-8 * tau
    if regime == "near_pi" and group in (Sim3, SE23):
        part = slice(3, 6) if group is Sim3 else slice(6, 9)
        tau[part] *= (np.pi - 1e-9) / np.linalg.norm(tau[part])
        if group is Sim3:
            tau[6] = 0.0
    if regime == "large_scale" and group in (Sim3, Sim2):
        tau[-1] = 6.0 * np.sign(tau[-1])
    return tau


@pytest.mark.parametrize("group", NEW, ids=lambda g: g.__name__)
@pytest.mark.parametrize("regime", ["identity", "tiny", "random", "near_pi", "large_scale"])
def test_new_twins_agree_with_numpy(group, regime):
    rng = np.random.default_rng(3)
    sym = _twin(group)
    assert sym.group is group and _twin(group) is sym
    k, d = sym.size, sym.dim
    mx, my = ca.SX.sym("x", k, k), ca.SX.sym("y", k, k)
    tau, p = ca.SX.sym("t", d), ca.SX.sym("p", group.point_dim)
    x, y = sym.from_matrix(mx), sym.from_matrix(my)
    outs = [sym.exp(tau), sym.log(x), sym.compose(x, y), sym.inverse(x), sym.act(x, p), sym.adjoint(x)]
    outs += [
        sym.rplus(x, tau),
        sym.rminus(y, x),
        sym.lplus(x, tau),
        sym.between(x, y),
        sym.hat(tau),
        sym.vee(sym.hat(tau)),
    ]
    f = ca.Function("f", [mx, my, tau, p], [ca.densify(ca.SX(o)) for o in outs])
    for _ in range(5):
        t = _new_tangent(group, regime, rng)
        xs, ys = group.exp(_new_tangent(group, regime, rng)), group.exp(_new_tangent(group, regime, rng))
        pt = rng.standard_normal(group.point_dim)
        refs = [group.exp(t).as_matrix(), xs.log(), (xs @ ys).as_matrix(), xs.inverse().as_matrix(), xs.act(pt)]
        refs += [xs.adjoint(), xs.rplus(t).as_matrix(), ys.rminus(xs), xs.lplus(t).as_matrix()]
        refs += [xs.between(ys).as_matrix(), group.hat(t), t]
        for got, ref in zip(f(xs.as_matrix(), ys.as_matrix(), t, pt), refs, strict=True):
            got = np.array(got).reshape(ref.shape)
            np.testing.assert_allclose(got, ref, rtol=0, atol=TOL * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize("group", NEW, ids=lambda g: g.__name__)
def test_new_twins_right_jacobians_match_numpy(group):
    """CasADi's derivatives through the chart are the numpy right Jacobians of rplus (Sim3: the doubling)."""
    rng = np.random.default_rng(4)
    sym = _twin(group)
    k, d = sym.size, sym.dim
    mx, tau, dx, dt = ca.SX.sym("x", k, k), ca.SX.sym("t", d), ca.SX.sym("dx", d), ca.SX.sym("dt", d)
    x = sym.from_matrix(mx)
    err = sym.rminus(sym.rplus(sym.rplus(x, dx), tau + dt), sym.rplus(x, tau))
    fn = ca.Function("j", [mx, tau, dx, dt], [ca.jacobian(err, dx), ca.jacobian(err, dt)])
    xs, ts = group.random(rng), 0.7 * rng.standard_normal(d)
    j_x, j_t = (np.array(o) for o in fn(xs.as_matrix(), ts, np.zeros(d), np.zeros(d)))
    _, ref_x, ref_t = xs.rplus(ts, jac=True)
    np.testing.assert_allclose(j_x, ref_x, atol=1e-11 * max(1.0, np.abs(ref_x).max()))
    np.testing.assert_allclose(j_t, ref_t, atol=1e-11 * max(1.0, np.abs(ref_t).max()))
