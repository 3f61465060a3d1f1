"""The single-element path (``lie._one``): the same numbers as the batched kernels, bit for bit.

Each decorated kernel, given one element, runs its twin on Python floats; ``kernel.__wrapped__``
is the array kernel itself. Equality is exact (``array_equal``: only the sign of a zero may differ).
"""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO2, SO3, LieGroup, NonFiniteError, ShapeError
from manopt_lie.lie import _matrix, _one, _se2, _se3, _series, _so3

# Across every series threshold (1e-4, 0.3, 0.5, 0.7), at π, and beyond.
ANGLES = [0.0, 1e-12, 1e-8, 0.9e-4, 1.1e-4, 1e-3, 0.29, 0.31, 0.49, 0.51, 0.69, 0.71, 1.0, 2.5, np.pi - 1e-9, np.pi]
ANGLES += [4.0, 6.0, 40.0]


def _axis(rng: np.random.Generator) -> np.ndarray:
    u = rng.standard_normal(3)
    return u / np.linalg.norm(u)


def rotation_vectors(rng: np.random.Generator) -> list[np.ndarray]:
    out = [a * _axis(rng) for a in ANGLES]
    out += [rng.standard_normal(3) for _ in range(20)]
    out += [np.array([0.0, 0.0, 1e-3]), np.array([np.pi, 0.0, 0.0]), np.array([0.0, -2.0, 0.0])]
    return out


def same(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape, (a.shape, b.shape)
    np.testing.assert_array_equal(a, b)


def check(kernel, *args: np.ndarray) -> None:
    """``kernel`` on one element (the twin) equals the array kernel on it, and on it inside a batch."""
    one = kernel(*args)
    plain = kernel.__wrapped__(*args)
    batch = kernel(*(np.stack([a, a, a]) for a in args))
    for a, b in ((one, plain), (one, batch[1]) if not isinstance(batch, tuple) else (one[0], batch[0][1])):
        if isinstance(a, tuple):
            for x, y in zip(a, b, strict=True):
                same(np.asarray(x), np.asarray(y))
        else:
            same(np.asarray(a), np.asarray(b))


def test_so3_kernels(rng):
    ws = rotation_vectors(rng)
    for w in ws:
        v = rng.standard_normal(3)
        for kernel in (_so3.exp, _so3.jr, _so3.jr_inv, _so3.hat):
            check(kernel, w)
        check(_so3.jl_apply, w, v)
        check(_so3.jl_inv_apply, w, v)
        check(_so3.log, _so3.exp(w))
        check(_matrix.rotate_vectors, _so3.exp(w), v)


def test_so3_log_of_every_branch(rng):
    """Shepperd's four candidate columns, rotations by π, the identity, and near-identity rotations."""
    mats = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    mats += [_so3.exp(np.pi * _axis(rng)) for _ in range(5)]
    mats += [_so3.exp(1e-7 * rng.standard_normal(3)) for _ in range(5)]
    for m in mats:
        check(_so3.log, m)


def test_se3_kernels(rng):
    for w in rotation_vectors(rng):
        rho = rng.standard_normal(3)
        tau = np.r_[rho, w]
        for kernel in (_se3.exp, _se3.jr, _se3.jr_inv):
            check(kernel, tau)
        check(_se3.q_matrix, rho, w)
        m = _se3.exp(tau)
        check(_se3.log, m)
        n = _se3.exp(rng.standard_normal(6))
        check(_matrix.h_compose, m, n)
        check(_matrix.h_inverse, m)
        check(_matrix.h_act, m, rho)


def test_se2_and_so2_kernels(rng):
    for a in ANGLES + [-a for a in ANGLES] + list(rng.uniform(-7, 7, 10)):
        tau = np.r_[rng.standard_normal(2), a]
        for kernel in (_se2.exp, _se2.jr, _se2.jr_inv):
            check(kernel, tau)
        m = _se2.exp(tau)
        check(_se2.log, m)
        check(_matrix.h_compose, m, _se2.exp(rng.standard_normal(3)))
        check(_matrix.h_inverse, m)
        check(_matrix.h_act, m, tau[:2])
        check(_matrix.rotation2, np.array(a))
        check(_matrix.angle2, _matrix.rotation2(np.array(a)))
        check(_matrix.rotate_vectors, _matrix.rotation2(np.array(a)), tau[:2])


def test_huge_angles_are_declined_to_the_scale_safe_forms():
    for theta in (1e20, 1e30, 1e300):
        w = theta * np.array([2.0, -1.0, 2.0]) / 3.0
        one, batch = _so3.exp(w), _so3.exp(w[None])[0]
        same(one, batch)
        same(_se3.jr(np.r_[1.0, 2.0, 3.0, w]), _se3.jr(np.r_[1.0, 2.0, 3.0, w][None])[0])
        same(_se2.exp(np.array([1.0, 2.0, theta])), _se2.exp(np.array([[1.0, 2.0, theta]]))[0])


def test_series_value_matches_the_array_evaluators():
    theta = np.array(ANGLES)
    for coef in _series.COEFFICIENTS:
        t = theta * theta
        arr = _series.patched(coef, t, theta)
        ref = _series.evaluate(coef, t, theta)
        same(arr, ref)
        same(np.array([_series.value(coef, float(a), float(b)) for a, b in zip(t, theta, strict=True)]), ref)


GROUPS = [SO2, SO3, SE2, SE3]


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_public_operations_single_equal_batched(group, rng):
    """Every operation on one element equals the same operation on a batch holding it."""
    n = 4
    tau = rng.standard_normal((n, group.dim))
    tau[0] *= 1e-9
    x, y = group.exp(rng.standard_normal((n, group.dim))), group.exp(rng.standard_normal((n, group.dim)))
    p = rng.standard_normal((n, group.point_dim))
    ops = {
        "exp": lambda x, y, t, p: group.exp(t).data,
        "exp_jac": lambda x, y, t, p: group.exp(t, jac=True)[1],
        "log_jac": lambda x, y, t, p: x.log(jac=True),
        "compose_jac": lambda x, y, t, p: (lambda z, a, b: (z.data, a, b))(*x.compose(y, jac=True)),
        "inverse_jac": lambda x, y, t, p: (lambda z, a: (z.data, a))(*x.inverse(jac=True)),
        "act_jac": lambda x, y, t, p: x.act(p, jac=True),
        "adjoint": lambda x, y, t, p: x.adjoint(),
        "rplus_jac": lambda x, y, t, p: (lambda z, a, b: (z.data, a, b))(*x.rplus(t, jac=True)),
        "lplus_jac": lambda x, y, t, p: (lambda z, a, b: (z.data, a, b))(*x.lplus(t, jac=True)),
        "rminus_jac": lambda x, y, t, p: y.rminus(x, jac=True),
        "lminus_jac": lambda x, y, t, p: y.lminus(x, jac=True),
        "between_jac": lambda x, y, t, p: (lambda z, a, b: (z.data, a, b))(*x.between(y, jac=True)),
        "jacobians": lambda x, y, t, p: (group.jr(t), group.jl(t), group.jr_inv(t), group.jl_inv(t)),
        "interpolate": lambda x, y, t, p: x.interpolate(y, 0.3).data,
        "dist": lambda x, y, t, p: x.dist(y),
    }
    for name, op in ops.items():
        batched = op(x, y, tau, p)
        for i in range(n):
            single = op(x[i], y[i], tau[i], p[i])
            pairs = zip(single, batched, strict=True) if isinstance(single, tuple) else [(single, batched)]
            for a, b in pairs:
                np.testing.assert_allclose(a, b[i], rtol=0, atol=1e-15 * max(1.0, np.abs(b[i]).max()), err_msg=name)


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_small_batches_element_by_element_equal_the_array_kernels(group, rng):
    """Batches of 2 to ``_one.SMALL`` (``_one.SMALL_JACOBIAN``) elements go through the twins one
    by one: bit for bit what the array kernels give on a large batch holding them, shapes included."""
    n = 4 * _one.SMALL_JACOBIAN
    tau = rng.standard_normal((n, group.dim))
    tau[::7] *= 1e-9  # small angles: the series branch too
    x, y = group.exp(rng.standard_normal((n, group.dim))), group.exp(rng.standard_normal((n, group.dim)))
    ops = {
        "exp_jac": lambda x, y, t: group.exp(t, jac=True),
        "log_jac": lambda x, y, t: x.log(jac=True),
        "rminus_jac": lambda x, y, t: y.rminus(x, jac=True),
        "rplus_jac": lambda x, y, t: x.rplus(t, jac=True),
        "jacobians": lambda x, y, t: (group.jr(t), group.jl(t), group.jr_inv(t), group.jl_inv(t)),
    }
    for name, op in ops.items():
        large = op(x, y, tau)
        sizes = (2, _one.SMALL, _one.SMALL + 1, _one.SMALL_JACOBIAN, _one.SMALL_JACOBIAN + 1)
        for size, shape in [(k, (k,)) for k in sizes] + [(6, (2, 3))]:
            parts = op(x[:size].reshape(shape), y[:size].reshape(shape), tau[:size].reshape(shape + (group.dim,)))
            for a, b in zip(parts, large, strict=True):
                a, b = (v.data if isinstance(v, LieGroup) else v for v in (a, b))
                assert a.shape == shape + b.shape[1:], name
                same(a.reshape(b[:size].shape), b[:size])


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
@pytest.mark.parametrize("batch", [(), (1,), (1, 1)], ids=str)
def test_batches_of_one_keep_their_shape(group, batch, rng):
    tau = rng.standard_normal(batch + (group.dim,))
    x = group.exp(tau)
    assert x.batch_shape == batch
    log, j = x.log(jac=True)
    assert log.shape == batch + (group.dim,) and j.shape == batch + (group.dim, group.dim)
    z, j_x, j_y = x.compose(group.exp(rng.standard_normal(group.dim)), jac=True)
    assert z.batch_shape == batch and j_x.shape == j_y.shape == batch + (group.dim, group.dim)
    assert x.act(rng.standard_normal(group.point_dim)).shape == batch + (group.point_dim,)
    np.testing.assert_allclose(log, tau if group is not SO2 else log, atol=1e-14)
    with pytest.raises(ValueError):
        x.data[...] = 0.0  # results are read-only, as every element's array


@pytest.mark.parametrize("group", GROUPS, ids=lambda g: g.__name__)
def test_single_inputs_are_still_validated(group):
    bad = np.zeros(group.dim)
    bad[-1] = np.nan
    with pytest.raises(NonFiniteError):
        group.exp(bad)
    with pytest.raises(NonFiniteError):
        group.identity().rplus(np.full(group.dim, np.inf), jac=True)
    with pytest.raises(ShapeError):
        group.exp(np.zeros(group.dim + 1))
    with pytest.raises(NonFiniteError):
        group.identity().act(np.full(group.point_dim, np.nan))
    # Lists, integers and huge-but-finite sums are fine.
    assert group.exp([0] * group.dim).batch_shape == ()
    assert np.isfinite(group.exp(np.full(group.dim, 1e307)).data).all()
