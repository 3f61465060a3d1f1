"""Symbolic twins of Sim(3), Sim(2), SE₂(3), S³, Rⁿ and bundles, on CasADi matrices (see :mod:`.lie`).

Elements are matrices in the numpy groups' matrix form: ``[[s·R, t], [0, 1]]`` (Sim3),
``[[R, p, v], [0, 1, 0], [0, 0, 1]]`` (SE23), ``[[I, v], [0, 1]]`` (Rn), the block-diagonal
matrix of the parts (Bundle); constant entries are rebuilt structurally by ``from_matrix``.
Sim(3)'s coefficients come from ``lie._series.sim3_coefficients`` on the CasADi backend,
the same source as numpy.
"""

from __future__ import annotations

from functools import cache
from typing import Any, ClassVar

import casadi as ca

from ..lie import S3, SE23, BundleGroup, LieGroup, RnGroup, Sim2, Sim3, _series
from .lie import (
    CASADI,
    Matrix,
    SymbolicGroup,
    SymSO3,
    _column,
    _so3_exp,
    _so3_log,
    _square,
    _SymHomogeneous,
    cosc,
    jinv_coef,
    sinc3,
)

__all__ = ["SymSim3", "SymSim2", "SymSE23", "SymS3", "sym_rn", "sym_bundle"]


def _jl_apply(theta: Matrix, v: Matrix) -> Matrix:
    t = ca.sumsqr(theta)
    wv = ca.cross(theta, v)
    return v + cosc(t) * wv + sinc3(t) * ca.cross(theta, wv)


def _jl_inv_apply(theta: Matrix, v: Matrix) -> Matrix:
    wv = ca.cross(theta, v)
    return v - 0.5 * wv + jinv_coef(ca.sumsqr(theta)) * ca.cross(theta, wv)


class _SymSimilarity(_SymHomogeneous):
    """Sim(3) and Sim(2): ``[[sR, t], [0, 1]]`` (the blocks, product and action of
    :class:`~.lie._SymHomogeneous`); ``(sR)⁻¹ = (sR)ᵀ/s²``."""

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        """``[[(sR)ᵀ/s², −(sR)ᵀt/s²], [0, 1]]``."""
        m, t = cls._split(x)
        mi = m.T / ca.sumsqr(m[:, 0])
        return cls._assemble(mi, -ca.mtimes(mi, t))


class SymSim3(_SymSimilarity):
    """Sim(3): ``4×4`` ``[[s·R, t], [0, 1]]``, tangent ``(ρ, θ, σ)`` as ``7×1``."""

    group = Sim3
    dim = 7
    size = 4
    point_dim = 3

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``[[e^σ Exp(θ), a ρ + b θ×ρ + c θ×(θ×ρ)], [0, 1]]``."""
        tau = cls._tangent(tau)
        rho, theta, sigma = tau[:3], tau[3:6], tau[6]
        a, b, c = _series.sim3_coefficients(sigma, ca.sumsqr(theta), CASADI)
        wv = ca.cross(theta, rho)
        return cls._assemble(ca.exp(sigma) * _so3_exp(theta), a * rho + b * wv + c * ca.cross(theta, wv))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        """``(W(σ, θ)⁻¹ t, θ, σ)``, ``s = |first column of sR|``."""
        m, t = cls._split(x)
        s = ca.norm_2(m[:, 0])
        theta, sigma = _so3_log(m / s), ca.log(s)
        tt = ca.sumsqr(theta)
        al, be, ga = _series.sim3_inverse_coefficients(*_series.sim3_coefficients(sigma, tt, CASADI), tt)
        wt = ca.cross(theta, t)
        return ca.vertcat(al * t + be * wt + ga * ca.cross(theta, wt), theta, sigma)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        tau = cls._tangent(tau)
        return ca.vertcat(ca.horzcat(ca.skew(tau[3:6]) + tau[6] * ca.DM.eye(3), tau[:3]), ca.DM.zeros(1, 4))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 4, "M")
        return ca.vertcat(a[:3, 3], ca.inv_skew(a[:3, :3]), ca.trace(a[:3, :3]) / 3.0)

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``[[sR, [t]× R, −t], [0, R, 0], [0, 0, 1]]``."""
        m, t = cls._split(x)
        r = m / ca.norm_2(m[:, 0])
        top = ca.horzcat(m, ca.mtimes(ca.skew(t), r), -t)
        mid = ca.horzcat(ca.DM.zeros(3, 3), r, ca.DM.zeros(3, 1))
        return ca.vertcat(top, mid, ca.horzcat(ca.DM.zeros(1, 6), ca.DM.ones(1, 1)))


class SymSim2(_SymSimilarity):
    """Sim(2): ``3×3`` ``[[s·R, t], [0, 1]]``, tangent ``(ρx, ρy, θ, σ)`` as ``4×1``."""

    group = Sim2
    dim = 4
    size = 3
    point_dim = 2

    @staticmethod
    def _w(sigma: Matrix, theta: Matrix) -> tuple[Matrix, Matrix]:
        t = theta * theta
        a, b, c = _series.sim3_coefficients(sigma, t, CASADI)
        return a - c * t, b * theta

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        """``[[e^σ R(θ), (A I + B J) ρ], [0, 1]]``."""
        tau = cls._tangent(tau)
        rho, theta, sigma = tau[:2], tau[2], tau[3]
        a, b = cls._w(sigma, theta)
        c, s = ca.cos(theta), ca.sin(theta)
        r = ca.exp(sigma) * ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))
        return cls._assemble(r, ca.vertcat(a * rho[0] - b * rho[1], a * rho[1] + b * rho[0]))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        m, t = cls._split(x)
        theta = ca.atan2(m[1, 0], m[0, 0])
        sigma = ca.log(ca.norm_2(m[:, 0]))
        a, b = cls._w(sigma, theta)
        d = a * a + b * b
        return ca.vertcat((a * t[0] + b * t[1]) / d, (a * t[1] - b * t[0]) / d, theta, sigma)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        tau = cls._tangent(tau)
        top = ca.horzcat(ca.vertcat(ca.horzcat(tau[3], -tau[2]), ca.horzcat(tau[2], tau[3])), tau[:2])
        return ca.vertcat(top, ca.DM.zeros(1, 3))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 3, "M")
        return ca.vertcat(a[0, 2], a[1, 2], 0.5 * (a[1, 0] - a[0, 1]), 0.5 * (a[0, 0] + a[1, 1]))

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``[[sR, (t_y, −t_x)ᵀ, −t], [0, 1, 0], [0, 0, 1]]``."""
        m, t = cls._split(x)
        top = ca.horzcat(m, ca.vertcat(t[1], -t[0]), -t)
        return ca.vertcat(top, ca.horzcat(ca.DM.zeros(2, 2), ca.DM.eye(2)))


class SymSE23(SymbolicGroup):
    """SE₂(3): ``5×5`` ``[[R, p, v], [0, 1, 0], [0, 0, 1]]``, tangent ``(ρ, ν, θ)`` as ``9×1``."""

    group = SE23
    dim = 9
    size = 5

    @classmethod
    def _split(cls, x: Any, name: str = "X") -> tuple[Matrix, Matrix, Matrix]:
        a = cls._element(x, name)
        return a[:3, :3], a[:3, 3], a[:3, 4]

    @classmethod
    def _assemble(cls, r: Matrix, p: Matrix, v: Matrix) -> Matrix:
        return ca.vertcat(ca.horzcat(r, p, v), ca.horzcat(ca.DM.zeros(2, 3), ca.DM.eye(2)))

    @classmethod
    def from_matrix(cls, m: Any) -> Matrix:
        return cls._assemble(*cls._split(m, "m"))

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        tau = cls._tangent(tau)
        theta = tau[6:]
        return cls._assemble(_so3_exp(theta), _jl_apply(theta, tau[:3]), _jl_apply(theta, tau[3:6]))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        r, p, v = cls._split(x)
        theta = _so3_log(r)
        return ca.vertcat(_jl_inv_apply(theta, p), _jl_inv_apply(theta, v), theta)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        tau = cls._tangent(tau)
        return ca.vertcat(ca.horzcat(ca.skew(tau[6:]), tau[:3], tau[3:6]), ca.DM.zeros(2, 5))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        a = _square(m, 5, "M")
        return ca.vertcat(a[:3, 3], a[:3, 4], ca.inv_skew(a[:3, :3]))

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        ra, pa, va = cls._split(x, "X")
        rb, pb, vb = cls._split(y, "Y")
        return cls._assemble(ca.mtimes(ra, rb), ca.mtimes(ra, pb) + pa, ca.mtimes(ra, vb) + va)

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        r, p, v = cls._split(x)
        return cls._assemble(r.T, -ca.mtimes(r.T, p), -ca.mtimes(r.T, v))

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        r, pos, _ = cls._split(x)
        return ca.mtimes(r, _column(p, 3, "p")) + pos

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        """``[[R, 0, [p]× R], [0, R, [v]× R], [0, 0, R]]``."""
        r, p, v = cls._split(x)
        z = ca.DM.zeros(3, 3)
        return ca.vertcat(
            ca.horzcat(r, z, ca.mtimes(ca.skew(p), r)),
            ca.horzcat(z, r, ca.mtimes(ca.skew(v), r)),
            ca.horzcat(z, z, r),
        )


class SymS3(SymSO3):
    """S³ in its matrix form, the rotation matrix ``R(q)``: SO(3)'s twin (the tangent and every
    operation on matrix forms are SO(3)'s; ``q`` and ``−q`` have one matrix)."""

    group = S3


class _SymRn(SymbolicGroup):
    """Rⁿ: ``[[I, v], [0, 1]]``."""

    @classmethod
    def _vector(cls, x: Any, name: str = "X") -> Matrix:
        return cls._element(x, name)[: cls.dim, cls.dim]

    @classmethod
    def _assemble(cls, v: Matrix) -> Matrix:
        n = cls.dim
        return ca.vertcat(ca.horzcat(ca.DM.eye(n), v), ca.horzcat(ca.DM.zeros(1, n), ca.DM.ones(1, 1)))

    @classmethod
    def from_matrix(cls, m: Any) -> Matrix:
        return cls._assemble(cls._vector(m, "m"))

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        return cls._assemble(cls._tangent(tau))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        return cls._vector(x)

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        n = cls.dim
        return ca.vertcat(ca.horzcat(ca.DM.zeros(n, n), cls._tangent(tau)), ca.DM.zeros(1, n + 1))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        return _square(m, cls.size, "M")[: cls.dim, cls.dim]

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        return cls._assemble(cls._vector(x, "X") + cls._vector(y, "Y"))

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        return cls._assemble(-cls._vector(x))

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        return cls._vector(x) + _column(p, cls.dim, "p")

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        cls._element(x)
        return ca.DM.eye(cls.dim)


@cache
def sym_rn(group: type[RnGroup]) -> type[SymbolicGroup]:
    """The twin of ``Rn(n)`` (one class per ``n``)."""
    return type(f"Sym{group.__name__}", (_SymRn,), {"group": group, "dim": group.dim, "size": group.dim + 1})


class _SymBundle(SymbolicGroup):
    """A bundle: block-diagonal matrices of the parts' twins, tangents concatenated."""

    parts: ClassVar[tuple[type[SymbolicGroup], ...]]

    @classmethod
    def _blocks(cls, x: Any, name: str = "X") -> list[Matrix]:
        a, out, i = cls._element(x, name), [], 0
        for p in cls.parts:
            out.append(a[i : i + p.size, i : i + p.size])
            i += p.size
        return out

    @classmethod
    def _pieces(cls, v: Matrix) -> list[Matrix]:
        out, i = [], 0
        for p in cls.parts:
            out.append(v[i : i + p.dim])
            i += p.dim
        return out

    @classmethod
    def _per_part(cls, op: str, *elements: Any) -> Matrix:
        blocks = zip(*(cls._blocks(e) for e in elements), strict=True)
        return ca.diagcat(*(getattr(p, op)(*b) for p, b in zip(cls.parts, blocks, strict=True)))

    @classmethod
    def from_matrix(cls, m: Any) -> Matrix:
        return cls._per_part("from_matrix", m)

    @classmethod
    def exp(cls, tau: Any) -> Matrix:
        return ca.diagcat(*(p.exp(t) for p, t in zip(cls.parts, cls._pieces(cls._tangent(tau)), strict=True)))

    @classmethod
    def log(cls, x: Any) -> Matrix:
        return ca.vertcat(*(p.log(b) for p, b in zip(cls.parts, cls._blocks(x), strict=True)))

    @classmethod
    def hat(cls, tau: Any) -> Matrix:
        return ca.diagcat(*(p.hat(t) for p, t in zip(cls.parts, cls._pieces(cls._tangent(tau)), strict=True)))

    @classmethod
    def vee(cls, m: Any) -> Matrix:
        return ca.vertcat(*(p.vee(b) for p, b in zip(cls.parts, cls._blocks(m, "M"), strict=True)))

    @classmethod
    def compose(cls, x: Any, y: Any) -> Matrix:
        return cls._per_part("compose", x, y)

    @classmethod
    def inverse(cls, x: Any) -> Matrix:
        return cls._per_part("inverse", x)

    @classmethod
    def act(cls, x: Any, p: Any) -> Matrix:
        pts = _column(p, cls.group.point_dim, "p")
        out, i = [], 0
        for part, b in zip(cls.parts, cls._blocks(x), strict=True):
            k = part.group.point_dim
            out.append(part.act(b, pts[i : i + k]))
            i += k
        return ca.vertcat(*out)

    @classmethod
    def adjoint(cls, x: Any) -> Matrix:
        return cls._per_part("adjoint", x)


@cache
def sym_bundle(group: type[BundleGroup], parts: tuple[type[SymbolicGroup], ...]) -> type[SymbolicGroup]:
    """The twin of a ``Bundle(...)`` class from its parts' twins."""
    attrs = {"group": group, "parts": parts, "dim": group.dim, "size": sum(p.size for p in parts)}
    return type(f"Sym{group.__name__}", (_SymBundle,), attrs)


TWINS: dict[type[LieGroup], type[SymbolicGroup]] = {Sim3: SymSim3, Sim2: SymSim2, SE23: SymSE23, S3: SymS3}
