"""Small batches on CasADi's virtual machine: the between kernel of SE(2)/SE(3) factors and
the group retraction ``X·Exp(τ)``, each one compiled function of one element mapped over the batch.

NumPy spends about a microsecond on every call whatever the size of its arrays; SE(3)'s
``Log``, ``Exp`` and ``Jr⁻¹`` are a few hundred calls, so on a few elements the array kernels cost
hundreds of µs where the work is a few thousand flops. CasADi's virtual machine runs the same
formulas (:mod:`manopt_lie.casadi.lie`, :mod:`manopt_lie.lie._formulas`, with the small-angle
series of :mod:`manopt_lie.lie._series`) at ~2 ns an instruction. The between kernel of SE(3)
(``Log E``, ``Jr⁻¹(Log E)``, ``Ad_{Y⁻¹}``) is 943 instructions an edge, so up to
:data:`VM_EDGES` edges the machine is the faster one (measured with Jacobians: 11 edges 34
against 251 µs, 100 edges 223 against 395 µs, 297 edges 618 against 575 µs); the products with
the square-root information stay NumPy's batched ``matmul``.

CasADi is imported at the first small batch, each function is built once per group (~10 ms)
and mapped once per batch size (50–100 µs), kept for the process.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .lie import LieGroup

__all__ = ["VM_EDGES", "VM_POINTS", "between_terms", "rplus"]

FloatArray = NDArray[np.float64]

VM_EDGES = 192
"""Between factors of at most this many edges go through the virtual machine."""

VM_POINTS = 256
"""Retractions of at most this many SE(2)/SE(3) elements go through the virtual machine."""


def _se3_terms(jac: bool) -> list[Any]:
    """``(Log E, Jr⁻¹(Log E), Ad_{Y⁻¹})`` of one SE(3) edge (entries row-major), symbolic."""
    import casadi as ca

    from .casadi.lie import SymSE3, jinv_coef, q_coef2, q_coef3, sinc3
    from .lie import _formulas

    xi, xj, z_inv = (ca.SX.sym(name, 16) for name in ("xi", "xj", "z_inv"))
    y = ca.mtimes(SymSE3.inverse(_rows(xi, 4)), _rows(xj, 4))
    tau = SymSE3.log(ca.mtimes(_rows(z_inv, 4), y))
    if not jac:
        return [[xi, xj, z_inv], [tau]]
    rho, theta = (tau[0], tau[1], tau[2]), (tau[3], tau[4], tau[5])
    t = _formulas.sq3(*theta)
    coefficients = (sinc3(t), q_coef2(t), q_coef3(t))
    diagonal, corner = _formulas.se3_jacobian(rho, theta, t, (0.5, jinv_coef(t)), coefficients, True)
    d, c = _rows(ca.vertcat(*diagonal), 3), _rows(ca.vertcat(*corner), 3)
    jr_inv = ca.vertcat(ca.horzcat(d, c), ca.horzcat(ca.SX.zeros(3, 3), d))
    return [[xi, xj, z_inv], [tau, _flat(jr_inv), _flat(SymSE3.adjoint(SymSE3.inverse(y)))]]


def _se2_terms(jac: bool) -> list[Any]:
    """The same for SE(2): ``Jr⁻¹ = [[M⁻¹, −M⁻¹ w], [0, 1]]`` of ``Jr = [[M, w], [0, 1]]``
    (``lie._se2.jr_inv``)."""
    import casadi as ca

    from .casadi.lie import SymSE2, cosc, half_cot, sinc3

    xi, xj, z_inv = (ca.SX.sym(name, 9) for name in ("xi", "xj", "z_inv"))
    y = ca.mtimes(SymSE2.inverse(_rows(xi, 3)), _rows(xj, 3))
    tau = SymSE2.log(ca.mtimes(_rows(z_inv, 3), y))
    if not jac:
        return [[xi, xj, z_inv], [tau]]
    rho_x, rho_y, theta = tau[0], tau[1], tau[2]
    t = theta * theta
    c, d = cosc(t, theta), theta * sinc3(t, theta)  # w = ∂(ρ-part)/∂θ of Jr (``lie._se2.jr``)
    w0, w1 = rho_x * d - rho_y * c, rho_x * c + rho_y * d
    ai, bi = half_cot(t, theta), 0.5 * theta  # M⁻¹ = [[ai, −bi], [bi, ai]]
    jr_inv = ca.vertcat(
        ca.horzcat(ai, -bi, -(ai * w0 + -bi * w1)),
        ca.horzcat(bi, ai, -(bi * w0 + ai * w1)),
        ca.horzcat(0.0, 0.0, 1.0),
    )
    return [[xi, xj, z_inv], [tau, _flat(jr_inv), _flat(SymSE2.adjoint(SymSE2.inverse(y)))]]


def _rows(x: Any, k: int) -> Any:
    """A row-major flat column of ``k²`` entries as a ``k×k`` matrix (CasADi is column-major)."""
    import casadi as ca

    return ca.reshape(x, k, k).T


def _flat(m: Any) -> Any:
    """A matrix's entries row-major, as a column."""
    import casadi as ca

    return ca.vec(m.T)


def _rplus_terms(group: str) -> list[Any]:
    """``X·Exp(τ)`` of one element (entries row-major), symbolic."""
    import casadi as ca

    from .casadi.lie import SymSE2, SymSE3

    sym = {"SE2": SymSE2, "SE3": SymSE3}[group]
    x, tau = ca.SX.sym("x", sym.size**2), ca.SX.sym("tau", sym.dim)
    return [[x, tau], [_flat(sym.rplus(_rows(x, sym.size), tau))]]


_BETWEEN = {"SE2": _se2_terms, "SE3": _se3_terms}
_TERMS: dict[str, Callable[[str], list[Any]]] = {
    "between": lambda group: _BETWEEN[group](True),
    "log": lambda group: _BETWEEN[group](False),
    "rplus": _rplus_terms,
}


@cache
def _function(kind: str, group: str) -> Any:
    """The CasADi function of one element for ``kind`` on the group named ``group``."""
    import casadi as ca

    inputs, outputs = _TERMS[kind](group)
    return ca.Function(f"{kind}_{group}", inputs, outputs)


@lru_cache(maxsize=64)
def _mapped(kind: str, group: str, m: int) -> Callable[..., list[FloatArray]]:
    """:func:`_function` mapped over ``m`` elements, called on numpy arrays."""
    from .casadi._compile import Batched

    return Batched(_function(kind, group), m)


def _flat_rows(*arrays: FloatArray) -> list[FloatArray]:
    """Each array as a C-contiguous float64 ``(m, entries)`` array (a view when it already is one)."""
    return [np.ascontiguousarray(a, dtype=np.float64).reshape(len(a), -1) for a in arrays]


def between_terms(
    group: type[LieGroup], mi: FloatArray, mj: FloatArray, z_inv: FloatArray, jac: bool
) -> list[FloatArray]:
    """``[Log E]`` (``(m, k)``), with ``jac`` also ``Jr⁻¹(Log E)`` and ``Ad_{Y⁻¹}`` (``(m, k, k)``), of the
    edges ``Y = X_i⁻¹ X_j``, ``E = Z⁻¹ Y`` given as homogeneous matrices ``(m, s, s)``."""
    m, k = len(mi), group.dim
    out = _mapped("between" if jac else "log", group.__name__, m)(*_flat_rows(mi, mj, z_inv))
    return [out[0]] if not jac else [out[0], out[1].reshape(m, k, k), out[2].reshape(m, k, k)]


def rplus(group: type[LieGroup], x: FloatArray, tau: FloatArray) -> FloatArray:
    """``X·Exp(τ)`` of homogeneous matrices ``(m, s, s)`` and tangents ``(m, k)``, as ``(m, s, s)``."""
    (out,) = _mapped("rplus", group.__name__, len(x))(*_flat_rows(x, tau))
    return out.reshape(x.shape)
