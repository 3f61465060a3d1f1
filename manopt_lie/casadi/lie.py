"""Symbolic twins of SO(2), SO(3), SE(2), SE(3) on CasADi matrices (Sim3, Sim2, SE23, S3,
bundles: ``.lie_extended``; ``symbolic(G)``: ``.twins``).

Elements are CasADi matrices in the numpy groups' matrix form (CONVENTIONS §2), constant
entries built from constants; tangents are ``dim×1`` columns, translation first. Every
operation accepts ``SX``, ``MX`` or ``DM`` (numbers become ``DM``) and returns the same kind,
ready for ``casadi.jacobian``/``casadi.hessian`` or a ``casadi.Function``.

The formulas are the numpy kernels'; every small-angle coefficient comes from their data,
``lie._series`` (one source of thresholds, series and closed forms), on the :data:`CASADI`
backend. The coefficients (``sinc`` … ``atan2_ratio``) are public functions of the *squared*
angle ``t = θ²``; the closed form sees a safe argument (``1``) where the series is selected,
so values *and derivatives of every order* are finite at 0.
"""

from __future__ import annotations

from typing import Any, ClassVar, TypeAlias

import casadi as ca
import numpy as np

from ..errors import ShapeError
from ..lie import SE2, SE3, SO2, SO3, LieGroup, _series
from ..lie._series import Backend

__all__ = ["SymbolicGroup", "SymSO2", "SymSO3", "SymSE2", "SymSE3", "Matrix", "CASADI", "horner"]
# The coefficient functions of ``lie._series``, on CasADi matrices.
__all__ += ["sinc", "cosc", "sinc3", "jinv_coef", "q_coef2", "q_coef3", "half_cot", "sinc_half", "cos_half"]
__all__ += ["atan_ratio", "atan2_ratio", "emoment0", "emoment1", "emoment2"]

# A CasADi SX, MX or DM matrix. Typed ``Any``: casadi's stubs do not type arithmetic across the three.
Matrix: TypeAlias = Any
_CASADI = (ca.SX, ca.MX, ca.DM)
CASADI = Backend(ca.sin, ca.cos, ca.sqrt, ca.atan, ca.atan2, ca.fmax, ca.if_else, ca.sinh, ca.cosh, ca.exp)
"""The CasADi backend of ``lie._series``: the same closed forms and series as the numeric
kernels, evaluated on CasADi matrices (``where`` is ``if_else``)."""


def _matrix(a: Any, name: str) -> Matrix:
    """``a`` as a CasADi matrix (numbers become ``DM``)."""
    if isinstance(a, _CASADI):
        return a
    try:
        return ca.DM(np.asarray(a, dtype=np.float64))
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name}: expected a CasADi SX/MX/DM matrix or numbers, got {type(a).__name__}") from err


def _column(tau: Any, n: int, name: str) -> Matrix:
    """A tangent (or point) as an ``n×1`` column; a row or a flat array of ``n`` numbers is accepted."""
    t = _matrix(tau, name)
    if t.numel() != n or min(t.shape) != 1:
        raise ShapeError(f"{name}: expected a vector of {n} entries, got a {t.shape[0]}×{t.shape[1]} matrix")
    return t if t.shape == (n, 1) else ca.reshape(t, n, 1)


def _square(m: Any, k: int, name: str) -> Matrix:
    a = _matrix(m, name)
    if a.shape != (k, k):
        raise ShapeError(f"{name}: expected a {k}×{k} matrix, got {a.shape[0]}×{a.shape[1]}")
    return a


# ---- coefficient functions of the angle (``lie._series``), stable at 0 --------------------

horner = _series.horner
sinc = _series.bind(_series.SINC, CASADI)
cosc = _series.bind(_series.COSC, CASADI)
sinc3 = _series.bind(_series.SINC3, CASADI)
jinv_coef = _series.bind(_series.JINV_COEF, CASADI)
q_coef2 = _series.bind(_series.Q_COEF2, CASADI)
q_coef3 = _series.bind(_series.Q_COEF3, CASADI)
half_cot = _series.bind(_series.HALF_COT, CASADI)
sinc_half = _series.bind(_series.SINC_HALF, CASADI)
cos_half = _series.bind(_series.COS_HALF, CASADI)
atan_ratio = _series.bind(_series.ATAN_RATIO, CASADI)
emoment0 = _series.bind(_series.EMOMENT0, CASADI)
emoment1 = _series.bind(_series.EMOMENT1, CASADI)
emoment2 = _series.bind(_series.EMOMENT2, CASADI)


def atan2_ratio(s2: Matrix, c: Matrix) -> Matrix:
    """``atan2(s, c) / s``, ``s = √s2 ≥ 0``, any sign of ``c``: ``atan_ratio(s/c)/c`` (series) where ``c > 0``
    and ``s/c < 1e-3``, else ``atan2(s, c)/s`` with ``s ≥ 1e-150`` (``lie._series.atan2_ratio``). Of a unit
    quaternion ``(v, w)``, ``2·atan2_ratio(|v|², w)·v`` is the rotation vector."""
    return _series.atan2_ratio(s2, c, CASADI)


# ---- the groups -----------------------------------------------------------------------------


class SymbolicGroup:
    """A matrix Lie group acting on CasADi matrices: classmethods only, no instances.

    Subclasses supply ``exp``, ``log``, ``hat``, ``vee``, ``compose``,
    ``inverse``, ``act``, ``adjoint`` and ``from_matrix``; the deduced
    operations (``rplus``, ``rminus``, ``lplus``, ``lminus``, ``between``)
    are written once here (CONVENTIONS §3).

    Class attributes
    ----------------
    group : type[LieGroup]
        The numpy twin (``SO3`` for ``SymSO3``).
    dim : int
        Tangent dimension.
    size : int
        Side of the element matrix (``d`` or ``d + 1``).
    """

    group: ClassVar[type[LieGroup]]
    dim: ClassVar[int]
    size: ClassVar[int]

    @classmethod
    def _element(cls, x: Any, name: str = "X") -> Matrix:
        return _square(x, cls.size, name)

    @classmethod
    def _tangent(cls, tau: Any, name: str = "tau") -> Matrix:
        return _column(tau, cls.dim, name)

    @classmethod
    def identity(cls) -> ca.DM:
        """The identity matrix of the group's size."""
        return ca.DM.eye(cls.size)

    @classmethod
    def from_matrix(cls, m: Any) -> Matrix:
        """The element whose matrix is ``m``, rebuilt structurally (no validation): ``m`` itself
        for rotations; for SE(n), ``[[R, t], [0, 1]]`` from the blocks of ``m``, so that the
        last row is constant even when ``m`` is a matrix of free symbols."""
        return cls._element(m)

    # ---- deduced API ------------------------------------------------------------------------

    @classmethod
    def rplus(cls, x: Any, tau: Any) -> Matrix:
        """``X ⊕ τ = X·Exp(τ)``."""
        return cls.compose(x, cls.exp(tau))

    @classmethod
    def rminus(cls, y: Any, x: Any) -> Matrix:
        """``Y ⊖ X = Log(X⁻¹·Y)``."""
        return cls.log(cls.compose(cls.inverse(x), y))

    @classmethod
    def lplus(cls, x: Any, tau: Any) -> Matrix:
        """``τ ⊕ X = Exp(τ)·X``."""
        return cls.compose(cls.exp(tau), x)

    @classmethod
    def lminus(cls, y: Any, x: Any) -> Matrix:
        """``Y ⊖ₗ X = Log(Y·X⁻¹)``."""
        return cls.log(cls.compose(y, cls.inverse(x)))

    @classmethod
    def between(cls, x: Any, y: Any) -> Matrix:
        """``X⁻¹·Y``."""
        return cls.compose(cls.inverse(x), y)

    # ---- minimal API ------------------------------------------------------------------------

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``Exp(τ) = exp(τ^)``."""
        raise NotImplementedError

    @classmethod
    def log(cls, x: Any) -> Matrix:
        """``Log(X)``, a ``dim×1`` column."""
        raise NotImplementedError

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        """``τ^``."""
        raise NotImplementedError

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        """``M^∨``."""
        raise NotImplementedError

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        """``X·Y``."""
        raise NotImplementedError

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        """``X⁻¹``."""
        raise NotImplementedError

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        """``X·p`` for a point column ``p``."""
        raise NotImplementedError

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``Ad_X``, with ``Ad_X τ = (X τ^ X⁻¹)^∨``."""
        raise NotImplementedError


class _SymRotation(SymbolicGroup):
    """SO(n): ``R`` itself."""

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        return ca.mtimes(cls._element(x, "X"), cls._element(y, "Y"))

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        return cls._element(x).T

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        return ca.mtimes(cls._element(x), _column(p, cls.size, "p"))


class SymSO2(_SymRotation):
    """SO(2): ``2×2`` rotations, tangent ``θ`` as ``1×1``."""

    group = SO2
    dim = 1
    size = 2

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``[[cos θ, −sin θ], [sin θ, cos θ]]``."""
        theta = cls._tangent(tau)
        c, s = ca.cos(theta), ca.sin(theta)
        return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        """``θ = atan2(R₁₀, R₀₀) ∈ (−π, π]``."""
        r = cls._element(x)
        return ca.atan2(r[1, 0], r[0, 0])

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        theta = cls._tangent(tau)
        return ca.vertcat(ca.horzcat(0, -theta), ca.horzcat(theta, 0))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 2, "M")
        return 0.5 * (a[1, 0] - a[0, 1])

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        cls._element(x)
        return ca.DM.ones(1, 1)


def _so3_exp(w: Matrix) -> Matrix:
    """Rodrigues with the half-angle coefficients of ``lie._so3.exp``:
    ``Exp(w) = (1 − b t) I + b w wᵀ + a [w]×``, ``r = sin(θ/2)/θ``, ``a = 2r cos(θ/2)``, ``b = 2r²``."""
    t = ca.sumsqr(w)
    r = sinc_half(t)
    a, b = 2.0 * r * cos_half(t), 2.0 * r * r
    return (1.0 - b * t) * ca.DM.eye(3) + b * ca.mtimes(w, w.T) + a * ca.skew(w)


def _so3_quaternion(r: Matrix) -> Matrix:
    """Unit quaternion ``(x, y, z, w)``, ``w ≥ 0``, by Shepperd's method (``lie._so3.to_quaternion``):
    the candidate column with the largest diagonal entry, chosen with ``if_else`` (ties: the first)."""
    r00, r01, r02 = r[0, 0], r[0, 1], r[0, 2]
    r10, r11, r12 = r[1, 0], r[1, 1], r[1, 2]
    r20, r21, r22 = r[2, 0], r[2, 1], r[2, 2]
    d = [r00 - r11 - r22, r11 - r00 - r22, r22 - r00 - r11, r00 + r11 + r22]
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21
    d10, d02, d21 = r10 - r01, r02 - r20, r21 - r12
    candidates = [
        ca.vertcat(1.0 + d[0], s01, s02, d21),
        ca.vertcat(s01, 1.0 + d[1], s12, d02),
        ca.vertcat(s02, s12, 1.0 + d[2], d10),
        ca.vertcat(d21, d02, d10, 1.0 + d[3]),
    ]
    q = candidates[3]
    for k in (2, 1, 0):  # innermost test last: candidate k wins if it is ≥ every later one
        wins = d[k] >= d[k + 1]
        for j in range(k + 2, 4):
            wins = ca.logic_and(wins, d[k] >= d[j])
        q = ca.if_else(wins, candidates[k], q)
    q = q / ca.norm_2(q)
    return ca.if_else(q[3] < 0.0, -q, q)


def _so3_log(r: Matrix) -> Matrix:
    """``θu = 2 atan2(|v|, w)/|v| · v``, ``θ ∈ [0, π]``, of the quaternion ``(v, w)``, ``w ≥ 0``, of ``R``."""
    q = _so3_quaternion(r)
    return 2.0 * atan2_ratio(ca.sumsqr(q[:3]), q[3]) * q[:3]


class SymSO3(_SymRotation):
    """SO(3): ``3×3`` rotations, tangent ``θu`` as ``3×1``.

    ``log`` goes through the quaternion (Shepperd's method), accurate to machine
    precision at every angle, including ``π``, where it returns the axis whose
    quaternion has ``w = +0`` (either sign is valid, CONVENTIONS §3).
    """

    group: ClassVar[type[LieGroup]] = SO3  # not narrowed to type[SO3]: SymS3 inherits all but the group
    dim = 3
    size = 3

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """Rodrigues: ``Exp(θu) = cos θ I + (1 − cos θ) u uᵀ + sin θ [u]×``."""
        return _so3_exp(cls._tangent(tau))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        return _so3_log(cls._element(x))

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        """``[w]× = [[0, −w₃, w₂], [w₃, 0, −w₁], [−w₂, w₁, 0]]``."""
        return ca.skew(cls._tangent(tau))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        return ca.inv_skew(_square(m, 3, "M"))

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``Ad_R = R``."""
        return cls._element(x)


class _SymHomogeneous(SymbolicGroup):
    """Homogeneous matrices ``[[M, t], [0, 1]]`` handled by blocks, the last row always
    constant: SE(n) (``M = R``) and Sim(n) (``M = sR``, in :mod:`.lie_extended`)."""

    point_dim: ClassVar[int]

    @classmethod
    def _assemble(cls, m: Matrix, t: Matrix) -> Matrix:
        last = ca.horzcat(ca.DM.zeros(1, cls.point_dim), ca.DM.ones(1, 1))
        return ca.vertcat(ca.horzcat(m, t), last)

    @classmethod
    def _split(cls, x: Any, name: str = "X") -> tuple[Matrix, Matrix]:
        a, d = cls._element(x, name), cls.point_dim
        return a[:d, :d], a[:d, d]

    @classmethod
    def from_matrix(cls, m: Any) -> Matrix:
        """``[[M, t], [0, 1]]`` from the blocks of ``m`` (its last row is replaced by constants)."""
        return cls._assemble(*cls._split(m, "m"))

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        """``[[Ma Mb, Ma tb + ta], [0, 1]]``."""
        ma, ta = cls._split(x, "X")
        mb, tb = cls._split(y, "Y")
        return cls._assemble(ca.mtimes(ma, mb), ca.mtimes(ma, tb) + ta)

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        """``M p + t``."""
        m, t = cls._split(x)
        return ca.mtimes(m, _column(p, cls.point_dim, "p")) + t


class _SymTransform(_SymHomogeneous):
    """SE(n): ``[[R, t], [0, 1]]``."""

    rotation: ClassVar[type[SymbolicGroup]]

    @classmethod
    def from_rotation_translation(cls, r: Any, t: Any) -> Matrix:
        """``[[R, t], [0, 1]]``."""
        return cls._assemble(cls.rotation._element(r, "R"), _column(t, cls.point_dim, "t"))

    @classmethod
    def rotation_part(cls, x: Any) -> Matrix:
        """``R``."""
        return cls._split(x)[0]

    @classmethod
    def translation(cls, x: Any) -> Matrix:
        """``t`` (a column)."""
        return cls._split(x)[1]

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        """``[[Rᵀ, −Rᵀt], [0, 1]]``."""
        r, t = cls._split(x)
        return cls._assemble(r.T, -ca.mtimes(r.T, t))


class SymSE2(_SymTransform):
    """SE(2): ``3×3`` homogeneous matrices, tangent ``(ρx, ρy, θ)``."""

    group = SE2
    rotation = SymSO2
    dim = 3
    size = 3
    point_dim = 2

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``[[R(θ), V(θ) ρ], [0, 1]]``, ``V(θ) = [[a, −b], [b, a]]``, ``a = sin θ/θ``, ``b = (1 − cos θ)/θ``."""
        tau = cls._tangent(tau)
        rho, theta = tau[:2], tau[2]
        t = theta * theta
        a, b = sinc(t, theta), theta * cosc(t, theta)
        trans = ca.vertcat(a * rho[0] - b * rho[1], a * rho[1] + b * rho[0])
        return cls._assemble(SymSO2.exp(theta), trans)

    @classmethod
    def log(cls, x: Any) -> Matrix:
        """``(V(θ)⁻¹ t, θ)``, ``V⁻¹ = [[a, b], [−b, a]]``, ``a = (θ/2) cot(θ/2)``, ``b = θ/2``."""
        r, t = cls._split(x)
        theta = SymSO2.log(r)
        a = half_cot(theta * theta, theta)
        b = 0.5 * theta
        return ca.vertcat(a * t[0] + b * t[1], a * t[1] - b * t[0], theta)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        """``[[0, −θ, ρx], [θ, 0, ρy], [0, 0, 0]]``."""
        tau = cls._tangent(tau)
        return ca.vertcat(ca.horzcat(SymSO2.hat(tau[2]), tau[:2]), ca.DM.zeros(1, 3))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 3, "M")
        return ca.vertcat(a[0, 2], a[1, 2], 0.5 * (a[1, 0] - a[0, 1]))

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``[[R, (t_y, −t_x)ᵀ], [0, 1]]``."""
        r, t = cls._split(x)
        return cls._assemble(r, ca.vertcat(t[1], -t[0]))


class SymSE3(_SymTransform):
    """SE(3): ``4×4`` homogeneous matrices, tangent ``(ρ, θ)`` as ``6×1``."""

    group = SE3
    rotation = SymSO3
    dim = 6
    size = 4
    point_dim = 3

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``[[Exp(θ), Jl(θ) ρ], [0, 1]]``, ``Jl(θ)ρ = ρ + (1 − cos θ)/θ² θ×ρ + (θ − sin θ)/θ³ θ×(θ×ρ)``."""
        tau = cls._tangent(tau)
        rho, theta = tau[:3], tau[3:]
        t = ca.sumsqr(theta)
        wv = ca.cross(theta, rho)
        trans = rho + cosc(t) * wv + sinc3(t) * ca.cross(theta, wv)
        return cls._assemble(_so3_exp(theta), trans)

    @classmethod
    def log(cls, x: Any) -> Matrix:
        """``(Jl(θ)⁻¹ t, θ)``, ``Jl(θ)⁻¹ t = t − ½ θ×t + (1/θ² − cot(θ/2)/(2θ)) θ×(θ×t)``, ``θ = Log(R)``."""
        r, t = cls._split(x)
        theta = _so3_log(r)
        wt = ca.cross(theta, t)
        rho = t - 0.5 * wt + jinv_coef(ca.sumsqr(theta)) * ca.cross(theta, wt)
        return ca.vertcat(rho, theta)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        """``[[θ^, ρ], [0, 0]]``."""
        tau = cls._tangent(tau)
        return ca.vertcat(ca.horzcat(ca.skew(tau[3:]), tau[:3]), ca.DM.zeros(1, 4))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 4, "M")
        return ca.vertcat(a[:3, 3], ca.inv_skew(a[:3, :3]))

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``[[R, [t]× R], [0, R]]``."""
        r, t = cls._split(x)
        top = ca.horzcat(r, ca.mtimes(ca.skew(t), r))
        return ca.vertcat(top, ca.horzcat(ca.DM.zeros(3, 3), r))
