"""SO(3) kernels on arrays: rotation matrices ``(..., 3, 3)``, rotation vectors ``(..., 3)``.

Formulas: Solà, Deray, Atchuthan, "A micro Lie theory" (arXiv:1812.01537),
Appendix B; Barfoot, "State Estimation for Robotics", §7.1.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import wraps
from typing import Any

import numpy as np

from . import _formulas, _one, _series
from ._checks import FloatArray

# Angles beyond HUGE are routed to the scale-safe forms below (see ``_series.HUGE``).
HUGE = _series.HUGE


def sq(w: FloatArray) -> FloatArray:
    """``|w|²`` summed by components (as the single-element twins do; ``einsum`` is slow on 3-vectors)."""
    return _formulas.sq3(w[..., 0], w[..., 1], w[..., 2])


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a × b`` by components (``np.cross`` costs ~50 µs on small arrays), broadcasting batch axes."""
    return _formulas.stack(list(_formulas.cross3(a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2])), 3)


@_one.fast(_one.hat3, 1, small=0)
def hat(w: FloatArray) -> FloatArray:
    """``[w]×``."""
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def vee(m: FloatArray) -> FloatArray:
    """Inverse of :func:`hat` on the skew part ``(M − Mᵀ)/2``."""
    return 0.5 * np.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
        axis=-1,
    )


def _norm(w: FloatArray) -> FloatArray:
    return np.sqrt(sq(w))


# ---- huge angles: every kernel below stays finite for any finite tangent -------------------


def polar(w: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``(u, h, sin h, cos h)`` with ``w = 2h·u``, ``|u| = 1``, computed without overflow.

    ``w`` is scaled by its largest component first, and ``h = θ/2`` (not ``θ``) is formed,
    which stays below the largest float for every finite ``w``. ``sin``/``cos`` reduce ``h``
    modulo the exact ``π`` (NumPy's argument reduction), so the rotation of a huge angle is
    the one its floating-point value denotes — though an angle whose ulp exceeds 2π
    (``θ ≳ 1e16``) carries no physical meaning.
    """
    m = np.abs(w).max(axis=-1)
    v = w / m[..., None]
    n = _norm(v)
    h = 0.5 * m * n
    return v / n[..., None], h, np.sin(h), np.cos(h)


def scale_safe(huge: Callable[..., FloatArray], angle: int = 0, part: slice = slice(None)) -> Callable[[Any], Any]:
    """Decorate a kernel of rotation vectors so that rows with ``|θ| ≥ HUGE`` go to ``huge``.

    ``args[angle][..., part]`` is the rotation vector; all arguments are vectors ``(..., k)``. The
    common path (no huge row) is the kernel itself, unchanged; otherwise the huge rows are
    zeroed for the kernel (no overflow, no warning) and recomputed by ``huge`` on their own.
    """

    def decorate(kernel: Callable[..., FloatArray]) -> Callable[..., FloatArray]:
        @wraps(kernel)
        def f(*args: FloatArray) -> FloatArray:
            with np.errstate(over="ignore"):
                big = ~(sq(args[angle][..., part]) < _series.HUGE2)  # inf (overflow) included
            if not big.any():
                return kernel(*args)
            batch = np.broadcast_shapes(*(a.shape[:-1] for a in args))
            full = [np.broadcast_to(a, batch + a.shape[-1:]) for a in args]
            big = np.broadcast_to(big, batch)
            safe = list(full)
            safe[angle] = np.where(big[..., None], 0.0, full[angle])
            out = np.array(kernel(*safe))
            out[big] = huge(*(a[big] for a in full))
            return out

        return f

    return decorate


def _exp_huge(w: FloatArray) -> FloatArray:
    """``Exp`` through the quaternion ``(sin(θ/2) u, cos(θ/2))``."""
    u, _, s, c = polar(w)
    return from_quaternion(np.concatenate([s[..., None] * u, c[..., None]], axis=-1))


def _jl_apply_huge(w: FloatArray, v: FloatArray) -> FloatArray:
    """``v + (1 − cos θ)/θ u×v + (1 − sin θ/θ) u×(u×v)``, with ``h = θ/2``: ``sin²h/h``, ``1 − sin h cos h/h``."""
    u, h, s, c = polar(w)
    uv, uuv = _cross_terms(u, v)
    return v + (s * s / h)[..., None] * uv + (1.0 - s * c / h)[..., None] * uuv


def _jl_inv_apply_huge(w: FloatArray, v: FloatArray) -> FloatArray:
    """``v − (θ/2) u×v + (1 − (θ/2)cot(θ/2)) u×(u×v)``."""
    u, h, s, c = polar(w)
    uv, uuv = _cross_terms(u, v)
    return v - h[..., None] * uv + (1.0 - h * c / s)[..., None] * uuv


def _jr_huge(w: FloatArray) -> FloatArray:
    """``I − (1 − cos θ)/θ [u]× + (1 − sin θ/θ) [u]×²``."""
    u, h, s, c = polar(w)
    return i_plus(-s * s / h, 1.0 - s * c / h, u, sq(u))


def _jr_inv_huge(w: FloatArray) -> FloatArray:
    """``I + (θ/2)[u]× + (1 − (θ/2)cot(θ/2)) [u]×²``."""
    u, h, s, c = polar(w)
    return i_plus(h, 1.0 - h * c / s, u, sq(u))


def _rodrigues_into(r: FloatArray, c: FloatArray, w: FloatArray, t: FloatArray, out: FloatArray) -> None:
    """:func:`_formulas.rodrigues` into ``out`` ``(n, 9)``, the same operations in the same order,
    with fewer temporaries (``r``, ``c``, ``t`` are overwritten) and the entries written in place."""
    x, y, z = w[:, 0], w[:, 1], w[:, 2]
    r2 = r + r
    a = np.multiply(r2, c, out=c)
    b = np.multiply(r2, r, out=r)
    cd = np.multiply(b, t, out=t)
    np.subtract(1.0, cd, out=cd)
    bx, by, bz = np.multiply(b, x, out=r2), b * y, b * z
    ax, ay, az = a * x, a * y, np.multiply(a, z, out=a)
    for k, (p, q) in enumerate(((bx, x), (by, y), (bz, z))):  # strided writes into ``out`` only
        np.add(np.multiply(p, q, out=b), cd, out=out[:, 4 * k])
    bxy = np.multiply(bx, y, out=cd)
    np.subtract(bxy, az, out=out[:, 1])
    np.add(bxy, az, out=out[:, 3])
    bxz = np.multiply(bx, z, out=bx)
    np.add(bxz, ay, out=out[:, 2])
    np.subtract(bxz, ay, out=out[:, 6])
    byz = np.multiply(by, z, out=by)
    np.subtract(byz, ax, out=out[:, 5])
    np.add(byz, ax, out=out[:, 7])


def _sq_rows(w: FloatArray) -> FloatArray:
    """:func:`sq` of rows ``(n, 3)``, squaring in contiguous temporaries."""
    t = np.square(w[:, 0])
    tmp = np.square(w[:, 1])
    t += tmp
    t += np.square(w[:, 2], out=tmp)
    return t


def _exp_rows(w: FloatArray, t: FloatArray, out: FloatArray) -> None:
    """``Exp`` of rotation vectors ``w`` ``(n, 3)`` with ``t = |w|² < HUGE²`` (overwritten) into ``out`` ``(n, 9)``."""
    theta = np.sqrt(t)
    small = t < _series.SINC_HALF.threshold2
    few = small.any()
    if few:
        theta[small] = 1.0  # placeholders: the series below replace these rows
    tau = np.multiply(theta, 0.25)
    np.tan(tau, out=tau)
    r = np.divide(tau, theta, out=theta)
    k = np.multiply(tau, tau, out=tau)
    k += 1.0
    np.divide(2.0, k, out=k)
    r *= k
    c = np.subtract(k, 1.0, out=k)
    if few:
        ts = t[small]
        r[small] = _series.horner(ts, _series.SINC_HALF.series)
        c[small] = _series.horner(ts, _series.COS_HALF.series)
    _rodrigues_into(r, c, w, t, out)


@_one.fast(_one.so3_exp, 1)
def exp(w: FloatArray, out: FloatArray | None = None) -> FloatArray:
    """Rodrigues: ``Exp(θu) = cos θ I + (1 − cos θ) u uᵀ + sin θ [u]×`` (:func:`_formulas.rodrigues`).

    Both coefficients come from one ``tan`` of ``θ/4`` (vectorized in NumPy, unlike ``sin``/``cos``),
    without cancellation: with ``τ = tan(θ/4)`` and ``k = 2/(1 + τ²) = 1 + cos(θ/2)``,
    ``r = sin(θ/2)/θ = (τ/θ)·k`` and ``cos(θ/2) = k − 1``. Below ``θ = 1e-4`` the series
    :data:`_series.SINC_HALF` and :data:`_series.COS_HALF` replace them (only on those rows, if
    any). Angles beyond :data:`HUGE` go through the quaternion of :func:`polar`, the other rows
    unchanged (as :func:`scale_safe` does). ``out``: a C-contiguous ``(..., 3, 3)`` array to fill
    (``_blocks.blockwise`` passes its output's blocks).
    """
    flat = w.reshape(-1, 3)
    with np.errstate(over="ignore"):
        t = _sq_rows(flat)
    o = np.empty((flat.shape[0], 9)) if out is None else out.reshape(-1, 9)
    if (t < _series.HUGE2).all():
        _exp_rows(flat, t, o)
    else:  # inf (overflow) included
        big = ~(t < _series.HUGE2)
        t[big] = 0.0
        _exp_rows(np.where(big[:, None], 0.0, flat), t, o)
        o[big] = _exp_huge(flat[big]).reshape(-1, 9)
    return o.reshape(w.shape[:-1] + (3, 3)) if out is None else out


exp.into = True  # type: ignore[attr-defined]


def _shepperd(r: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """A positive multiple ``(x, y, z, w)`` of the unit quaternion of ``R`` with ``w ≥ 0``, by
    components (Shepperd's method, not normalized).

    Of the four proportional candidate columns of the symmetric matrix built from ``R``, the one
    with the largest diagonal entry is taken (its length is ``4|q_k|``, at least 2), so the
    quaternion is accurate to machine precision for every rotation, including angle π.
    """
    r00, r01, r02 = r[..., 0, 0], r[..., 0, 1], r[..., 0, 2]
    r10, r11, r12 = r[..., 1, 0], r[..., 1, 1], r[..., 1, 2]
    r20, r21, r22 = r[..., 2, 0], r[..., 2, 1], r[..., 2, 2]
    d0, d1, d2, trace = r00 - r11 - r22, r11 - r00 - r22, r22 - r00 - r11, r00 + r11 + r22
    d10, d02, d21 = r10 - r01, r02 - r20, r21 - r12
    w = 1.0 + trace
    w_largest = (trace > d0) & (trace > d1) & (trace > d2)
    if w_largest.all():
        # Every angle below ~2π/3 (residuals, steps): column w is the largest (strictly, as
        # argmax would pick it), no selection, and its w = 1 + tr R = 4w² > 0.
        return d21, d02, d10, w
    if r.ndim == 2:  # one element (a 0-d selection below would not be writable)
        return _shepperd_select(r, (d0, d1, d2, trace), (d21, d02, d10))
    # The few elements with a larger x, y or z column alone go through the selection.
    x, y, z, rest = d21, d02, d10, ~w_largest  # new arrays, written in place
    diagonal, skew = (d0[rest], d1[rest], d2[rest], trace[rest]), (x[rest], y[rest], z[rest])
    x[rest], y[rest], z[rest], w[rest] = _shepperd_select(r[rest], diagonal, skew)
    return x, y, z, w


def _shepperd_select(
    r: FloatArray, diagonal: tuple[FloatArray, ...], skew: tuple[FloatArray, ...]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`_shepperd`'s column with the largest diagonal entry, for any rotations, given the
    diagonal entries ``(d0, d1, d2, tr R)`` and the skew parts ``(d21, d02, d10)``."""
    r01, r02, r10, r12, r20, r21 = r[..., 0, 1], r[..., 0, 2], r[..., 1, 0], r[..., 1, 2], r[..., 2, 0], r[..., 2, 1]
    d21, d02, d10 = skew
    diag = np.stack(diagonal, -1)
    k = np.argmax(diag, axis=-1)
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21
    big = 1.0 + np.take_along_axis(diag, k[..., None], -1)[..., 0]
    # Candidate column k, as (x, y, z, w), each proportional to the quaternion.
    q = [np.choose(k, [big, s01, s02, d21]), np.choose(k, [s01, big, s12, d02]),
         np.choose(k, [s02, s12, big, d10]), np.choose(k, [d21, d02, d10, big])]  # fmt: skip
    sign = np.where(q[3] < 0.0, -1.0, 1.0)
    return q[0] * sign, q[1] * sign, q[2] * sign, q[3] * sign


def to_quaternion(r: FloatArray) -> FloatArray:
    """Unit quaternion ``(x, y, z, w)`` with ``w ≥ 0`` (Shepperd's method, :func:`_shepperd`),
    accurate to machine precision for every rotation, including angle π."""
    q = np.stack(_shepperd(r), axis=-1)
    n = q[..., 0] * q[..., 0]
    for i in (1, 2, 3):
        n += q[..., i] * q[..., i]
    q /= np.sqrt(n)[..., None]
    return q


def from_quaternion(q: FloatArray) -> FloatArray:
    """Rotation matrix of a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1.0 - 2.0 * (yy + zz)
    out[..., 0, 1] = 2.0 * (xy - wz)
    out[..., 0, 2] = 2.0 * (xz + wy)
    out[..., 1, 0] = 2.0 * (xy + wz)
    out[..., 1, 1] = 1.0 - 2.0 * (xx + zz)
    out[..., 1, 2] = 2.0 * (yz - wx)
    out[..., 2, 0] = 2.0 * (xz - wy)
    out[..., 2, 1] = 2.0 * (yz + wx)
    out[..., 2, 2] = 1.0 - 2.0 * (xx + yy)
    return out


def quaternion_log(q: FloatArray) -> FloatArray:
    """``θu`` of a unit quaternion with ``w ≥ 0``: ``θu = 2 atan2(|v|, w)/|v| · v``, ``θ ∈ [0, π]``.

    The ratio is :func:`_series.atan2_ratio`, a series in ``|v|²/w²`` near the identity.
    """
    return _rotation_vector(q[..., 0], q[..., 1], q[..., 2], q[..., 3])


def _rotation_vector(x: FloatArray, y: FloatArray, z: FloatArray, w: FloatArray) -> FloatArray:
    """``2 atan2(|v|, w)/|v| · v`` from the components of ``(v, w)``, any positive multiple of a
    quaternion with ``w ≥ 0`` (the ratio is scale-free)."""
    ratio = _series.atan2_ratio(_formulas.sq3(x, y, z), w)
    ratio *= 2.0
    return _formulas.stack([ratio * x, ratio * y, ratio * z], 3)


@_one.fast(_one.so3_log, 2)
def log(r: FloatArray) -> FloatArray:
    """``Log(R) = θu`` with ``θ ∈ [0, π]``, through the quaternion ``(v, w)``:
    ``2 atan2(|v|, w)/|v| · v`` (:func:`quaternion_log`), which any positive multiple of the
    quaternion gives alike, so Shepperd's column is used as it is, without normalizing."""
    return _rotation_vector(*_shepperd(r))


def _cross_terms(w: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``(w × v, w × (w × v))``, i.e. ``[w]× v`` and ``[w]×² v``."""
    wv = cross(w, v)
    return wv, cross(w, wv)


@_one.fast(_one.jl_apply, 1, 1)
@scale_safe(_jl_apply_huge)
def jl_apply(w: FloatArray, v: FloatArray) -> FloatArray:
    """``Jl(w) v = v + (1 − cos θ)/θ² w×v + (θ − sin θ)/θ³ w×(w×v)`` (eq. 145)."""
    t = sq(w)
    theta = np.sqrt(t)
    wv, wwv = _cross_terms(w, v)
    return v + _series.cosc(theta, t)[..., None] * wv + _series.sinc3(theta, t)[..., None] * wwv


@_one.fast(_one.jl_inv_apply, 1, 1)
@scale_safe(_jl_inv_apply_huge)
def jl_inv_apply(w: FloatArray, v: FloatArray) -> FloatArray:
    """``Jl(w)⁻¹ v = v − ½ w×v + (1/θ² − (1+cos θ)/(2θ sin θ)) w×(w×v)`` (eq. 146)."""
    t = sq(w)
    wv, wwv = _cross_terms(w, v)
    return v - 0.5 * wv + _series.jinv_coef(np.sqrt(t), t)[..., None] * wwv


def i_plus(a: FloatArray | float, b: FloatArray, w: FloatArray, t: FloatArray) -> FloatArray:
    """``I + a [w]× + b [w]×²`` with ``[w]×² = w wᵀ − t I``, ``t = |w|²``, entry by entry."""
    return _formulas.stack(_formulas.i_plus(a, b, w[..., 0], w[..., 1], w[..., 2], t), 3, 3)


def jr_coefficients(t: FloatArray, inverse: bool) -> tuple[FloatArray | float, FloatArray]:
    """``(a, b)`` of :func:`i_plus` for ``Jr(θ)`` (``−(1 − cos θ)/θ²``, ``(θ − sin θ)/θ³``) or for
    ``Jr(θ)⁻¹`` (``½``, :func:`_series.jinv_coef`), from ``t = |θ|²``."""
    theta = np.sqrt(t)
    if inverse:
        return 0.5, _series.jinv_coef(theta, t)
    return -_series.cosc(theta, t), _series.sinc3(theta, t)


@_one.fast(_one.so3_jr, 1)
@scale_safe(_jr_huge)
def jr(w: FloatArray) -> FloatArray:
    """``Jr(θ) = I − (1 − cos θ)/θ² [θ]× + (θ − sin θ)/θ³ [θ]×²`` (eq. 143)."""
    t = sq(w)
    return i_plus(*jr_coefficients(t, False), w, t)


@_one.fast(_one.so3_jr_inv, 1)
@scale_safe(_jr_inv_huge)
def jr_inv(w: FloatArray) -> FloatArray:
    """``Jr(θ)⁻¹ = I + ½[θ]× + (1/θ² − (1 + cos θ)/(2θ sin θ)) [θ]×²`` (eq. 144)."""
    t = sq(w)
    return i_plus(*jr_coefficients(t, True), w, t)


def act_jac_rotation(r: FloatArray, p: FloatArray) -> FloatArray:
    """``D(R·p)/DR = −R [p]×``."""
    return -r @ hat(p)
