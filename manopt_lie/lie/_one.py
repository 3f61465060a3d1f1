"""One element on Python floats: the fast path of the SO(2), SO(3), SE(2), SE(3) array kernels.

NumPy spends about a microsecond on every call whatever the size of its arrays, so a kernel of
forty array operations costs ~40 µs on a single element, where the same arithmetic on Python
floats takes ~2 µs. Each array kernel with a *twin* here is decorated with :func:`fast`: given
exactly one element (no batch axes, or batch axes of length 1), it runs the twin instead.

A twin repeats its kernel's operations in the kernel's order, with the same roundings (IEEE
arithmetic, ``math.sqrt``, and NumPy's own ufuncs for the transcendental functions, through
``_series.FLOAT``): the results are the kernel's bit for bit, up to the sign of zeros. Matrix
products stay NumPy's ``@`` on the one element, whose rounding the stacked product shares. A twin
returns ``None`` to decline — an angle beyond ``HUGE``, whose scale-safe forms only the array
kernels have — and the array kernel runs. ``tests/lie/test_one.py`` holds twins and kernels to
equality.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import wraps
from typing import Any, TypeVar

import numpy as np

from . import _formulas, _series
from ._series import COS_HALF, COSC, HALF_COT, JINV_COEF, Q_COEF2, Q_COEF3, SINC, SINC3, SINC_HALF, horner, value

K = TypeVar("K", bound=Callable[..., Any])
Floats = list[float]
HUGE2 = _series.HUGE2
_tan = np.tan
_sin, _cos, _atan2 = _series.FLOAT.sin, _series.FLOAT.cos, _series.FLOAT.atan2


def _batch_of_one(args: tuple[np.ndarray, ...], ndims: tuple[int, ...]) -> tuple[int, ...] | None:
    """The batch shape if every ``args[i]`` (with ``ndims[i]`` trailing axes) holds one element, else ``None``."""
    batch: tuple[int, ...] = ()
    for a, k in zip(args, ndims, strict=True):
        n = a.ndim - k
        if n:
            s = a.shape
            if a.size != (1 if k == 0 else s[-1] if k == 1 else s[-1] * s[-2]):
                return None
            if n > len(batch):
                batch = s[:n]
    return batch


SMALL = 8
"""Batches of at most this many elements go element by element through the twins: each costs
a few µs on floats, while the array kernels pay ~1 µs per NumPy call whatever the size."""

SMALL_JACOBIAN = 16
"""The same for the kernels of SE(3) and the Jacobians of SE(2), a few hundred NumPy calls each:
element by element they stay faster up to ~16–20 elements (SE(3) ``Log`` 1.4×, ``Jr⁻¹`` 1.5× at
12 elements), the rotations' and SE(2)'s ``Exp``/``Log`` only up to ~10."""


def _small_batch(args: tuple[np.ndarray, ...], ndims: tuple[int, ...], small: int) -> tuple[int, ...] | None:
    """The batch shape if it has 2 to ``small`` elements and every argument either has it or
    has no batch axes (no other broadcasting), else ``None``."""
    batch: tuple[int, ...] | None = None
    for a, k in zip(args, ndims, strict=True):
        if a.ndim > k:
            s = a.shape[: a.ndim - k]
            if batch is None:
                batch = s
            elif s != batch:
                return None
    if batch is None:
        return None
    return batch if 1 < math.prod(batch) <= small else None


def _rebatch(out: Any, batch: tuple[int, ...]) -> Any:
    if type(out) is tuple:
        return tuple(o.reshape(batch + o.shape) for o in out)
    return out.reshape(batch + out.shape)


def fast(twin: Callable[..., Any], *ndims: int, floats: bool = True, small: int = SMALL) -> Callable[[K], K]:
    """Decorate an array kernel whose argument ``i`` has ``ndims[i]`` trailing axes: one element goes
    to ``twin``, called with each argument's entries as a flat list of floats (``floats=False``: with
    the arrays, batch axes dropped). ``twin`` returns an array (or a tuple of arrays) without batch
    axes, or ``None`` to leave the element to the kernel. Batches of up to ``small`` elements
    (:func:`_small_batch`) go through ``twin`` element by element: worth it for the kernels of
    many NumPy calls (series, Jacobians), not for a product (``small=0``)."""

    def prepare(a: np.ndarray, k: int) -> Any:
        if floats:
            return a.ravel().tolist()
        return a.reshape(a.shape[a.ndim - k :]) if a.ndim > k else a

    def decorate(kernel: K) -> K:
        def general(*args: np.ndarray, **kw: Any) -> Any:
            if kw:  # e.g. ``out=``, from the blocks of a large batch
                return kernel(*args, **kw)
            batch = _batch_of_one(args, ndims)
            if batch is not None:
                out = twin(*[prepare(a, k) for a, k in zip(args, ndims, strict=True)])
                if out is not None:
                    return _rebatch(out, batch) if batch else out
                return kernel(*args)
            batch = _small_batch(args, ndims, small)
            if batch is not None:
                out = _elementwise(args, batch)
                if out is not None:
                    return out
            return kernel(*args)

        def _elementwise(args: tuple[np.ndarray, ...], batch: tuple[int, ...]) -> Any:
            """The twin on each element of a small batch, stacked (``None`` if it declines one)."""
            rows = [a.reshape((-1, *a.shape[a.ndim - k :])) if a.ndim > k else None
                    for a, k in zip(args, ndims, strict=True)]  # fmt: skip
            outs = []
            for i in range(math.prod(batch)):
                out = twin(*[prepare(a if r is None else r[i], k) for a, r, k in zip(args, rows, ndims, strict=True)])
                if out is None:
                    return None
                outs.append(out)
            if type(outs[0]) is tuple:
                return tuple(np.stack(parts).reshape(batch + parts[0].shape) for parts in zip(*outs, strict=True))
            return np.stack(outs).reshape(batch + outs[0].shape)

        if len(ndims) == 1:
            (k1,) = ndims

            def f(*args: np.ndarray, **kw: Any) -> Any:
                if len(args) == 1 and args[0].ndim == k1 and not kw:  # the common case, checked first
                    out = twin(prepare(args[0], k1))
                    return kernel(*args) if out is None else out
                return general(*args, **kw)

        elif len(ndims) == 2:
            k1, k2 = ndims

            def f(*args: np.ndarray, **kw: Any) -> Any:
                if len(args) == 2 and args[0].ndim == k1 and args[1].ndim == k2 and not kw:
                    out = twin(prepare(args[0], k1), prepare(args[1], k2))
                    return kernel(*args) if out is None else out
                return general(*args, **kw)

        else:
            f = general
        return wraps(kernel)(f)  # type: ignore[return-value]

    return decorate


def _array(entries: Floats, *shape: int) -> np.ndarray:
    return np.array(entries).reshape(shape)


def _cross(a: Floats, b: Floats) -> Floats:
    return list(_formulas.cross3(*a, *b))


def _sq(w: Floats) -> float:
    return _formulas.sq3(*w)


# ---- SO(3) --------------------------------------------------------------------------------


def hat3(w: Floats) -> np.ndarray:
    x, y, z = w
    return _array([0.0, -z, y, z, 0.0, -x, -y, x, 0.0], 3, 3)


def _exp3(w: Floats) -> Floats | None:
    x, y, z = w
    t = x * x + y * y + z * z
    if not t < HUGE2:
        return None
    if t < SINC_HALF.threshold2:
        r, c = horner(t, SINC_HALF.series), horner(t, COS_HALF.series)
    else:
        theta = math.sqrt(t)
        tau = float(_tan(theta * 0.25))
        k = 2.0 / (tau * tau + 1.0)
        r = tau / theta * k
        c = k - 1.0
    return _formulas.rodrigues(r, c, x, y, z, t)


def so3_exp(w: Floats) -> np.ndarray | None:
    r = _exp3(w)
    return None if r is None else _array(r, 3, 3)


def _log3(m: Floats) -> Floats:
    """``_so3.log``: Shepperd's (unnormalized) quaternion, then ``2 atan2(|v|, w)/|v| · v``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = m
    diag = [r00 - r11 - r22, r11 - r00 - r22, r22 - r00 - r11, r00 + r11 + r22]
    k = diag.index(max(diag))
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21
    d10, d02, d21 = r10 - r01, r02 - r20, r21 - r12
    big = 1.0 + diag[k]
    qx, qy, qz, qw = (
        (big, s01, s02, d21),
        (s01, big, s12, d02),
        (s02, s12, big, d10),
        (d21, d02, d10, big),
    )[k]
    if qw < 0.0:  # a positive multiple of the quaternion, not normalized (as ``_so3.log``)
        qx, qy, qz, qw = -qx, -qy, -qz, -qw
    ratio = _series.atan2_ratio_float(qx * qx + qy * qy + qz * qz, qw)
    ratio *= 2.0
    return [ratio * qx, ratio * qy, ratio * qz]


def so3_log(m: Floats) -> np.ndarray:
    return np.array(_log3(m))


def _jl_apply(w: Floats, v: Floats, inverse: bool) -> Floats | None:
    t = _sq(w)
    if not t < HUGE2:
        return None
    theta = math.sqrt(t)
    wv = _cross(w, v)
    wwv = _cross(w, wv)
    if inverse:
        j = value(JINV_COEF, t, theta)
        return [v[i] - 0.5 * wv[i] + j * wwv[i] for i in range(3)]
    cc, s3 = value(COSC, t, theta), value(SINC3, t, theta)
    return [v[i] + cc * wv[i] + s3 * wwv[i] for i in range(3)]


def jl_apply(w: Floats, v: Floats) -> np.ndarray | None:
    out = _jl_apply(w, v, False)
    return None if out is None else np.array(out)


def jl_inv_apply(w: Floats, v: Floats) -> np.ndarray | None:
    out = _jl_apply(w, v, True)
    return None if out is None else np.array(out)


def _jr3(w: Floats, inverse: bool) -> Floats | None:
    t = _sq(w)
    if not t < HUGE2:
        return None
    theta = math.sqrt(t)
    x, y, z = w
    if inverse:
        return _formulas.i_plus(0.5, value(JINV_COEF, t, theta), x, y, z, t)
    return _formulas.i_plus(-value(COSC, t, theta), value(SINC3, t, theta), x, y, z, t)


def so3_jr(w: Floats) -> np.ndarray | None:
    j = _jr3(w, False)
    return None if j is None else _array(j, 3, 3)


def so3_jr_inv(w: Floats) -> np.ndarray | None:
    j = _jr3(w, True)
    return None if j is None else _array(j, 3, 3)


# ---- SE(3) --------------------------------------------------------------------------------


def se3_exp(tau: Floats) -> np.ndarray | None:
    rho, theta = tau[:3], tau[3:]
    r = _exp3(theta)
    t = _jl_apply(theta, rho, False)
    if r is None or t is None:
        return None
    return _array([*r[0:3], t[0], *r[3:6], t[1], *r[6:9], t[2], 0.0, 0.0, 0.0, 1.0], 4, 4)


def se3_log(m: Floats) -> np.ndarray | None:
    theta = _log3([m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]])
    rho = _jl_apply(theta, [m[3], m[7], m[11]], True)
    return None if rho is None else np.array([*rho, *theta])


def _q(rho: Floats, v: Floats) -> Floats | None:
    """``_se3.q_matrix(ρ, θ)`` with ``v = θ``."""
    s = _sq(v)
    if not s < HUGE2:
        return None
    d = _formulas.dot3(*v, *rho)
    angle = math.sqrt(s)
    c1, c2, c3 = value(SINC3, s, angle), value(Q_COEF2, s, angle), value(Q_COEF3, s, angle)
    return _formulas.q_entries(tuple(rho), tuple(v), _formulas.q_coefficients(c1, c2, c3, s, d))  # type: ignore[arg-type]


def q_matrix(rho: Floats, theta: Floats) -> np.ndarray | None:
    q = _q(rho, theta)
    return None if q is None else _array(q, 3, 3)


def _neg(v: Floats) -> Floats:
    return [-x for x in v]


def _se3_jacobian(tau: Floats, inverse: bool) -> np.ndarray | None:
    """``_se3._jacobian``: the blocks by ``_formulas.se3_jacobian``, then ``[[D, C], [0, D]]``."""
    rho, theta = tau[:3], tau[3:]
    t = _sq(theta)
    if not t < HUGE2:
        return None
    angle = math.sqrt(t)
    if inverse:
        ab, c1 = (0.5, value(JINV_COEF, t, angle)), value(SINC3, t, angle)
    else:
        ab = (-value(COSC, t, angle), value(SINC3, t, angle))
        c1 = ab[1]
    c = (c1, value(Q_COEF2, t, angle), value(Q_COEF3, t, angle))
    d, q = _formulas.se3_jacobian(tuple(rho), tuple(theta), t, ab, c, inverse)  # type: ignore[arg-type]
    return _array(
        [
            d[0], d[1], d[2], q[0], q[1], q[2],
            d[3], d[4], d[5], q[3], q[4], q[5],
            d[6], d[7], d[8], q[6], q[7], q[8],
            0.0, 0.0, 0.0, d[0], d[1], d[2],
            0.0, 0.0, 0.0, d[3], d[4], d[5],
            0.0, 0.0, 0.0, d[6], d[7], d[8],
        ],
        6, 6,
    )  # fmt: skip


def se3_jr(tau: Floats) -> np.ndarray | None:
    return _se3_jacobian(tau, False)


def se3_jr_inv(tau: Floats) -> np.ndarray | None:
    return _se3_jacobian(tau, True)


# ---- homogeneous matrices and rotations of the plane and space --------------------------------


def _rotate(r: Floats, v: Floats, d: int) -> Floats:
    """``R v`` as ``_matrix.rotate_vectors``, ``r`` a flat ``d×d`` (or the rows of a homogeneous matrix,
    ``d+1`` wide, via the stride)."""
    if d == 3:
        return [r[0] * v[0] + r[1] * v[1] + r[2] * v[2], r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
                r[6] * v[0] + r[7] * v[1] + r[8] * v[2]]  # fmt: skip
    return [r[0] * v[0] + r[1] * v[1], r[2] * v[0] + r[3] * v[1]]


def _split(m: Floats) -> tuple[Floats, Floats, int]:
    """``(R, t, d)`` of a flat homogeneous matrix."""
    if len(m) == 16:
        return [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]], [m[3], m[7], m[11]], 3
    return [m[0], m[1], m[3], m[4]], [m[2], m[5]], 2


def _assemble(r: Floats, t: Floats, d: int) -> np.ndarray:
    if d == 3:
        return _array([*r[0:3], t[0], *r[3:6], t[1], *r[6:9], t[2], 0.0, 0.0, 0.0, 1.0], 4, 4)
    return _array([r[0], r[1], t[0], r[2], r[3], t[1], 0.0, 0.0, 1.0], 3, 3)


def rotate_vectors(r: Floats, v: Floats) -> np.ndarray:
    return np.array(_rotate(r, v, len(v)))


def h_act(m: Floats, p: Floats) -> np.ndarray:
    r, t, d = _split(m)
    q = _rotate(r, p, d)
    return np.array([q[i] + t[i] for i in range(d)])


def h_inverse(m: Floats) -> np.ndarray:
    r, t, d = _split(m)
    rt = [r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8]] if d == 3 else [r[0], r[2], r[1], r[3]]
    return _assemble(rt, _neg(_rotate(rt, t, d)), d)


def h_compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``[[Ra Rb, Ra tb + ta], [0, 1]]``: the rotation block by ``@`` (as the kernel), the rest on floats."""
    d = a.shape[-1] - 1
    rr = (a[:d, :d] @ b[:d, :d]).ravel().tolist()
    ra, ta, _ = _split(a.ravel().tolist())
    tb = b[:d, d].tolist()
    q = _rotate(ra, tb, d)
    return _assemble(rr, [q[i] + ta[i] for i in range(d)], d)


def rotation2(theta: Floats) -> np.ndarray:
    c, s = _cos(theta[0]), _sin(theta[0])
    return _array([c, -s, s, c], 2, 2)


def angle2(m: Floats) -> np.ndarray:
    return np.array(_atan2(m[2], m[0]))


# ---- SE(2) --------------------------------------------------------------------------------


def _v2(theta: float) -> tuple[float, float, float]:
    """``(sin θ/θ, (1 − cos θ)/θ, (1 − cos θ)/θ²)`` as ``_se2._v_coefficients``."""
    ang = abs(theta)
    t = ang * ang
    c = value(COSC, t, ang)
    return value(SINC, t, ang), theta * c, c


def se2_exp(tau: Floats) -> np.ndarray | None:
    x, y, theta = tau
    if not abs(theta) < _series.HUGE:
        return None
    a, b, _ = _v2(theta)
    c, s = _cos(theta), _sin(theta)
    return _array([c, -s, a * x + b * -y, s, c, a * y + b * x, 0.0, 0.0, 1.0], 3, 3)


def se2_log(m: Floats) -> np.ndarray:
    theta = _atan2(m[3], m[0])
    ang = abs(theta)
    a, b = value(HALF_COT, ang * ang, ang), 0.5 * theta
    tx, ty = m[2], m[5]
    return np.array([a * tx - b * -ty, a * ty - b * tx, theta])


def _jr2(tau: Floats) -> Floats | None:
    x, y, theta = tau
    if not abs(theta) < _series.HUGE:
        return None
    a, b, c = _v2(theta)
    ang = abs(theta)
    d = theta * value(SINC3, ang * ang, ang)
    return [a, b, x * d - y * c, -b, a, x * c + y * d, 0.0, 0.0, 1.0]


def se2_jr(tau: Floats) -> np.ndarray | None:
    j = _jr2(tau)
    return None if j is None else _array(j, 3, 3)


def se2_jr_inv(tau: Floats) -> np.ndarray | None:
    j = _jr2(tau)
    if j is None:
        return None
    theta = tau[2]
    ang = abs(theta)
    a, b = value(HALF_COT, ang * ang, ang), 0.5 * theta
    w0, w1 = j[2], j[5]
    return _array([a, -b, -(a * w0 + -b * w1), b, a, -(b * w0 + a * w1), 0.0, 0.0, 1.0], 3, 3)
