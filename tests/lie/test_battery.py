"""The generic battery: every group × batch shape × sampling regime (hypothesis-driven seeds)."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from manopt_lie import SE3

from .helpers import (
    BATCH_SHAPES,
    FRAMES,
    GROUPS,
    assert_jacobian,
    assert_same,
    cases,
    element,
    group_id,
    numerical_jacobian,
    rotation_angle,
    size,
    tangent,
)

seeds = st.integers(0, 2**32 - 1)
battery = pytest.mark.parametrize("group", GROUPS, ids=group_id)
shapes = pytest.mark.parametrize("batch", BATCH_SHAPES, ids=str)
grouped_regimes = pytest.mark.parametrize("group,regime", cases())


def clear_of_pi(group: type, tau: np.ndarray, gap: float) -> bool:
    """Whether every rotation angle of ``tau`` is farther than ``gap`` from the odd multiples of
    π, where ``Exp`` of a vector crosses the cut locus of ``Log``."""
    u = np.mod(rotation_angle(group, tau) - np.pi, 2 * np.pi)
    return bool(np.all(np.minimum(u, 2 * np.pi - u) > gap))


def fd_step(regime: str) -> float:
    """Central-difference step: 1e-6, or 1e-4 where elements have entries ~1e4 (Sim(3) products with s = e^±12),
    whose round-off (~1e-16·1e4/h) would otherwise exceed the 1e-6 tolerance."""
    return 1e-4 if regime == "large_scale" else 1e-6


@grouped_regimes
@shapes
@given(seed=seeds)
def test_group_axioms(group, batch, regime, seed):
    rng = np.random.default_rng(seed)
    x, y, z = (element(group, regime, batch, rng) for _ in range(3))
    e = group.identity(batch)
    # Round-off grows with the entries' size (Sim(3) with s = e^12): tolerances relative to it.
    k = size(x) * size(y) * size(z) * size(x.inverse())
    assert_same((x @ y) @ z, x @ (y @ z), tol=1e-12 * k)
    assert_same(x @ e, x)
    assert_same(e @ x, x)
    assert_same(x @ x.inverse(), e, tol=1e-12 * k)
    assert_same(x.inverse() @ x, e, tol=1e-12 * k)
    assert_same(x.between(y), x.inverse() @ y)


@grouped_regimes
@shapes
@given(seed=seeds)
def test_exp_log_round_trips(group, batch, regime, seed):
    rng = np.random.default_rng(seed)
    x = element(group, regime, batch, rng)
    assert_same(group.exp(x.log()), x)
    tau = tangent(group, regime, batch, rng)
    back = group.exp(tau).log()
    inside = rotation_angle(group, tau) < np.pi
    scale = np.maximum(1.0, np.abs(tau).max(axis=-1))
    np.testing.assert_array_less(np.where(inside, np.abs(back - tau).max(axis=-1) / scale, 0.0), 1e-10)
    # Outside the injectivity radius Log returns an equivalent tangent.
    assert_same(group.exp(back), group.exp(tau), tol=1e-10)
    assert np.isfinite(back).all()


@grouped_regimes
@shapes
@given(seed=seeds)
def test_adjoint_identities(group, batch, regime, seed):
    rng = np.random.default_rng(seed)
    x, y = element(group, regime, batch, rng), element(group, regime, batch, rng)
    np.testing.assert_allclose((x @ y).adjoint(), x.adjoint() @ y.adjoint(), atol=1e-10)
    # Ad_X τ = (X τ^ X⁻¹)^∨
    tau = rng.standard_normal(batch + (group.dim,))
    conj = x.as_matrix() @ group.hat(tau) @ x.inverse().as_matrix()
    np.testing.assert_allclose(
        np.einsum("...ij,...j->...i", x.adjoint(), tau), group.vee(conj), atol=1e-10 * (1 + np.abs(tau).max())
    )
    np.testing.assert_allclose(x.inverse().adjoint(), np.linalg.inv(x.adjoint()), atol=1e-9)


@grouped_regimes
@shapes
@given(seed=seeds)
def test_jacobian_identities(group, batch, regime, seed):
    rng = np.random.default_rng(seed)
    tau = tangent(group, regime, batch, rng)
    jr, jl = group.jr(tau), group.jl(tau)
    eye = np.eye(group.dim)
    np.testing.assert_allclose(jl, group.jr(-tau), atol=1e-14)
    # Ad_{Exp τ} = Jl(τ) Jr(τ)⁻¹, i.e. Jl = Ad·Jr
    np.testing.assert_allclose(group.exp(tau).adjoint() @ jr, jl, atol=1e-10)
    np.testing.assert_allclose(group.jr_inv(tau) @ jr, np.broadcast_to(eye, jr.shape), atol=1e-9)
    np.testing.assert_allclose(group.jl_inv(tau) @ jl, np.broadcast_to(eye, jl.shape), atol=1e-9)


@grouped_regimes
@shapes
@given(seed=seeds)
def test_jacobians_of_elements_vs_finite_differences(group, batch, regime, seed):
    """exp, compose, inverse, act, rplus, between, lplus: right Jacobians; lplus also left ones."""
    rng = np.random.default_rng(seed)
    fd = partial(numerical_jacobian, h=fd_step(regime))
    x, y = element(group, regime, batch, rng), element(group, regime, batch, rng)
    tau = tangent(group, regime, batch, rng)
    p = rng.standard_normal(batch + (group.point_dim,))

    _, j = group.exp(tau, jac=True)
    assert_jacobian(j, fd(group.exp, [tau], 0))

    _, j_x, j_y = x.compose(y, jac=True)
    assert_jacobian(j_x, fd(lambda a, b: a @ b, [x, y], 0))
    assert_jacobian(j_y, fd(lambda a, b: a @ b, [x, y], 1))

    _, j = x.inverse(jac=True)
    assert_jacobian(j, fd(lambda a: a.inverse(), [x], 0))

    _, j_x, j_p = x.act(p, jac=True)
    assert_jacobian(j_x, fd(lambda a, q: a.act(q), [x, p], 0))
    assert_jacobian(j_p, fd(lambda a, q: a.act(q), [x, p], 1))

    _, j_x, j_t = x.rplus(tau, jac=True)
    assert_jacobian(j_x, fd(lambda a, t: a.rplus(t), [x, tau], 0))
    assert_jacobian(j_t, fd(lambda a, t: a.rplus(t), [x, tau], 1))

    _, j_x, j_y = x.between(y, jac=True)
    assert_jacobian(j_x, fd(lambda a, b: a.between(b), [x, y], 0))
    assert_jacobian(j_y, fd(lambda a, b: a.between(b), [x, y], 1))

    for frame in FRAMES:
        _, j_x, j_t = x.lplus(tau, jac=True, frame=frame)
        assert_jacobian(j_x, fd(lambda a, t: a.lplus(t), [x, tau], 0, frame=frame))
        assert_jacobian(j_t, fd(lambda a, t: a.lplus(t), [x, tau], 1, frame=frame))


@grouped_regimes
@shapes
@given(seed=seeds)
def test_jacobians_of_tangents_vs_finite_differences(group, batch, regime, seed):
    """log, rminus (right), lminus (right and left). Log is discontinuous at angle π,
    so the near-π regime keeps a gap of 1e-4 > the finite-difference step, and a draw of
    another regime whose angle (of ``X`` or of ``τ``, modulo 2π) lies within ten steps of π
    is not compared: central differences across the jump measure the jump, not ``J``
    (Sim(3), large scale, step 1e-4: an angle 7e-5 short of π)."""
    rng = np.random.default_rng(seed)
    h = fd_step(regime)
    fd = partial(numerical_jacobian, h=h)
    x = element(group, regime, batch, rng, pi_gap=1e-4)
    tau = tangent(group, regime, batch, rng, pi_gap=1e-4)
    assume(clear_of_pi(group, x.log(), 10 * h) and clear_of_pi(group, tau, 10 * h))
    _, j = x.log(jac=True)
    assert_jacobian(j, fd(lambda a: a.log(), [x], 0))

    # Y = X ⊕ τ with τ inside the injectivity radius, so Y ⊖ X = τ is smooth.
    y = x.rplus(tau)
    _, j_y, j_x = y.rminus(x, jac=True)
    assert_jacobian(j_y, fd(lambda b, a: b.rminus(a), [y, x], 0))
    assert_jacobian(j_x, fd(lambda b, a: b.rminus(a), [y, x], 1))

    y = x.lplus(tau)
    for frame in FRAMES:
        _, j_y, j_x = y.lminus(x, jac=True, frame=frame)
        assert_jacobian(j_y, fd(lambda b, a: b.lminus(a), [y, x], 0, frame=frame))
        assert_jacobian(j_x, fd(lambda b, a: b.lminus(a), [y, x], 1, frame=frame))


@grouped_regimes
@shapes
@given(seed=seeds)
def test_left_jacobians_are_converted_right_ones(group, batch, regime, seed):
    """``J_left = Ad_{f(X)} · J_right · Ad_X⁻¹`` for lplus and lminus (``Ad = I`` on vectors),
    and the closed forms of both frames (CONVENTIONS §4)."""
    rng = np.random.default_rng(seed)
    x = element(group, regime, batch, rng)
    tau = tangent(group, regime, batch, rng)
    eye = np.broadcast_to(np.eye(group.dim), batch + (group.dim, group.dim))
    ad_x, ad_x_inv = x.adjoint(), x.inverse().adjoint()

    y, r_x, r_t = x.lplus(tau, jac=True)
    _, l_x, l_t = x.lplus(tau, jac=True, frame="left")
    ad_y = y.adjoint()
    np.testing.assert_allclose(l_x, ad_y @ r_x @ ad_x_inv, atol=1e-9 * max(1.0, np.abs(l_x).max()))
    np.testing.assert_allclose(l_t, ad_y @ r_t, atol=1e-9 * max(1.0, np.abs(l_t).max()))
    np.testing.assert_allclose(r_x, eye, atol=0)
    np.testing.assert_allclose(r_t, y.inverse().adjoint() @ group.jl(tau), atol=1e-12)
    np.testing.assert_allclose(l_x, group.exp(tau).adjoint(), atol=1e-12)
    np.testing.assert_allclose(l_t, group.jl(tau), atol=0)

    t, r_y, r_x = y.lminus(x, jac=True)
    _, l_y, l_x = y.lminus(x, jac=True, frame="left")
    np.testing.assert_allclose(l_y, r_y @ y.inverse().adjoint(), atol=1e-9 * max(1.0, np.abs(l_y).max()))
    np.testing.assert_allclose(l_x, r_x @ ad_x_inv, atol=1e-9 * max(1.0, np.abs(l_x).max()))
    np.testing.assert_allclose(r_y, group.jl_inv(t) @ ad_y, atol=1e-12 * max(1.0, np.abs(r_y).max()))
    np.testing.assert_allclose(r_x, -group.jr_inv(t) @ ad_x, atol=1e-12 * max(1.0, np.abs(r_x).max()))
    np.testing.assert_allclose(l_y, group.jl_inv(t), atol=0)
    np.testing.assert_allclose(l_x, -group.jr_inv(t), atol=0)


@pytest.mark.parametrize("method", ["lplus", "lminus"])
def test_frame_must_be_right_or_left(method):
    x = SE3.identity()
    arg = np.zeros(6) if method == "lplus" else x
    with pytest.raises(ValueError, match=r"frame must be 'right' or 'left', got 'global'"):
        getattr(x, method)(arg, jac=True, frame="global")
    with pytest.raises(ValueError, match="frame"):
        getattr(x, method)(arg, frame="Left")


@grouped_regimes
@shapes
@given(seed=seeds)
def test_plus_minus_consistency(group, batch, regime, seed):
    rng = np.random.default_rng(seed)
    x = element(group, regime, batch, rng)
    tau = tangent(group, regime, batch, rng, pi_gap=1e-6)
    tau_in = np.where(rotation_angle(group, tau)[..., None] < np.pi, tau, 0.0)
    np.testing.assert_allclose(x.rplus(tau_in).rminus(x), tau_in, atol=1e-9)
    np.testing.assert_allclose(x.lplus(tau_in).lminus(x), tau_in, atol=1e-9)
    # τ ⊕ X = X ⊕ (Ad_X⁻¹ τ)
    local = np.einsum("...ij,...j->...i", np.linalg.inv(x.adjoint()), tau)
    assert_same(x.lplus(tau), x.rplus(local), tol=1e-9)
    y = element(group, regime, batch, rng)
    np.testing.assert_allclose(x.dist(y), y.dist(x), atol=1e-9)
    assert_same(x.interpolate(y, 0.0), x)
    assert_same(x.interpolate(y, 1.0), y, tol=1e-9)


@battery
@given(seed=seeds)
def test_composition_drift_over_1000_products(group, seed):
    """``Exp(τ)¹⁰⁰⁰ = Exp(1000 τ)`` (a one-parameter subgroup) and stays in the group."""
    rng = np.random.default_rng(seed)
    tau = 0.01 * rng.standard_normal(group.dim)
    step = group.exp(tau)
    x = group.identity()
    for _ in range(1000):
        x = x @ step
    assert_same(x, group.exp(1000 * tau), tol=1e-11)
    x.validate(tol=1e-12)  # still in the group: rotation blocks orthonormal, constant rows exact
