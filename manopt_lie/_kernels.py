"""Element kernels built from CasADi expressions: the between kernel of SE(2)/SE(3) factors and
the group retraction ``X·Exp(τ)``, one function of one element run over the batch.

NumPy spends about a microsecond on every call whatever the size of its arrays; SE(3)'s ``Log``,
``Exp`` and ``Jr⁻¹`` are a few hundred calls, and each makes a pass over memory. Written once as
CasADi expressions — the formulas of :mod:`manopt_lie.casadi.lie` and
:mod:`manopt_lie.lie._formulas`, with the small-angle series of :mod:`manopt_lie.lie._series` —
an edge is a few hundred scalar operations (SE(3)'s whole whitened residual and both Jacobians:
1,648), run in one of three places, the first available:

1. **native code** (:func:`native_kernel`, :mod:`manopt_lie._native`): the functions compiled to
   C by the system's compiler, at every batch size, the results written straight into the
   caller's arrays (SE(3), whitened, with Jacobians: 11 edges 18 µs, 297 edges 105 µs, 10⁴ edges
   3.3 ms, 10⁵ edges 40 ms, against the array kernels' 249 µs, 552 µs, 10.4 ms and 114 ms:
   ``benchmarks/bench_kernels.py``);
2. **CasADi's virtual machine**, for batches of up to :data:`VM_EDGES` edges or
   :data:`VM_POINTS` retractions, where its ~2 ns an instruction beats NumPy's per-call cost
   (SE(3), 11 edges: 34 against 251 µs; it breaks even at ~250), the products with the
   square-root information left to NumPy's batched ``matmul``;
3. otherwise the callers' own array kernels (:mod:`manopt_lie.factors._poses`, the groups).

CasADi is imported at the first use; each function is built once per process (~10 ms for all of
a group's), mapped for the machine once per batch size (50–100 µs).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .lie import SE2, SE3, LieGroup

if TYPE_CHECKING:
    from ._native import Native

__all__ = ["NATIVE_KINDS", "PATHS", "VM_EDGES", "VM_POINTS", "between_terms", "flat_rows", "native_kernel"]
__all__ += ["path_settings", "rplus"]

FloatArray = NDArray[np.float64]

VM_EDGES = 192
"""Between factors of at most this many edges go through the virtual machine."""

VM_POINTS = 256
"""Retractions of at most this many SE(2)/SE(3) elements go through the virtual machine."""


def _se3_edge(xi: Any, xj: Any, z_inv: Any) -> tuple[Any, Any, Any]:
    """``(Log E, Jr⁻¹(Log E), Ad_{Y⁻¹})`` of one SE(3) edge from its flat matrices, symbolic."""
    import casadi as ca

    from .casadi.lie import SymSE3, jinv_coef, q_coef2, q_coef3, sinc3
    from .lie import _formulas

    y = ca.mtimes(SymSE3.inverse(_rows(xi, 4)), _rows(xj, 4))
    tau = SymSE3.log(ca.mtimes(_rows(z_inv, 4), y))
    rho, theta = (tau[0], tau[1], tau[2]), (tau[3], tau[4], tau[5])
    t = _formulas.sq3(*theta)
    coefficients = (sinc3(t), q_coef2(t), q_coef3(t))
    diagonal, corner = _formulas.se3_jacobian(rho, theta, t, (0.5, jinv_coef(t)), coefficients, True)
    d, c = _rows(ca.vertcat(*diagonal), 3), _rows(ca.vertcat(*corner), 3)
    jr_inv = ca.vertcat(ca.horzcat(d, c), ca.horzcat(ca.SX.zeros(3, 3), d))
    return tau, jr_inv, SymSE3.adjoint(SymSE3.inverse(y))


def _se2_edge(xi: Any, xj: Any, z_inv: Any) -> tuple[Any, Any, Any]:
    """The same for SE(2): ``Jr⁻¹ = [[M⁻¹, −M⁻¹ w], [0, 1]]`` of ``Jr = [[M, w], [0, 1]]``
    (``lie._se2.jr_inv``)."""
    import casadi as ca

    from .casadi.lie import SymSE2, cosc, half_cot, sinc3

    y = ca.mtimes(SymSE2.inverse(_rows(xi, 3)), _rows(xj, 3))
    tau = SymSE2.log(ca.mtimes(_rows(z_inv, 3), y))
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
    return tau, jr_inv, SymSE2.adjoint(SymSE2.inverse(y))


def _rows(x: Any, k: int) -> Any:
    """A row-major flat column of ``k²`` entries as a ``k×k`` matrix (CasADi is column-major)."""
    import casadi as ca

    return ca.reshape(x, k, k).T


def _flat(m: Any) -> Any:
    """A matrix's entries row-major, as a column."""
    import casadi as ca

    return ca.vec(m.T)


_EDGES = {"SE2": (_se2_edge, 9, 3), "SE3": (_se3_edge, 16, 6)}  # the edge, matrix entries, tangent dimension


def _terms(kind: str, group: str) -> tuple[list[Any], list[Any]]:
    """Symbolic inputs and outputs (entries row-major) of one element for ``kind``:

    - ``"terms"``: ``(X_i, X_j, Z⁻¹) ↦ (Log E, Jr⁻¹(Log E), Ad_{Y⁻¹})`` (the virtual machine's:
      its products with ``L`` are NumPy's);
    - ``"log"``: ``(X_i, X_j, Z⁻¹) ↦ Log E``, ``"whitened log"``: ``(…, L) ↦ L Log E``;
    - ``"between"``: ``(X_i, X_j, Z⁻¹) ↦ (r, [∂r/∂X_i, ∂r/∂X_j])``, ``"whitened between"`` with ``L``
      (``r = L Log E``, ``∂r/∂X_j = L Jr⁻¹``, ``∂r/∂X_i = −L Jr⁻¹ Ad_{Y⁻¹}``);
    - ``"rplus"``: ``(X, τ) ↦ X·Exp(τ)``.
    """
    import casadi as ca

    from .casadi.lie import SymSE2, SymSE3

    edge, size, k = _EDGES[group]
    if kind == "rplus":
        sym = {"SE2": SymSE2, "SE3": SymSE3}[group]
        x, step = ca.SX.sym("x", size), ca.SX.sym("tau", k)
        return [x, step], [_flat(sym.rplus(_rows(x, sym.size), step))]
    inputs = [ca.SX.sym(name, size) for name in ("xi", "xj", "z_inv")]
    tau, jr_inv, adjoint_y_inv = edge(*inputs)
    if kind == "terms":
        return inputs, [tau, _flat(jr_inv), _flat(adjoint_y_inv)]
    whitened = kind.startswith("whitened")
    if whitened:
        inputs.append(ca.SX.sym("L", k * k))
        sqrt_information = _rows(inputs[-1], k)
        r, j_j = ca.mtimes(sqrt_information, tau), ca.mtimes(sqrt_information, jr_inv)
    else:
        r, j_j = tau, jr_inv
    if kind.endswith("log"):
        return inputs, [r]
    return inputs, [r, _flat(ca.horzcat(-ca.mtimes(j_j, adjoint_y_inv), j_j))]


NATIVE_KINDS = ("log", "whitened log", "between", "whitened between", "rplus")


@cache
def native(group: str) -> dict[str, Native] | None:
    """The native kernels of the group named ``group`` by kind (:data:`NATIVE_KINDS`), compiled
    together (:mod:`manopt_lie._native`), or ``None`` where native code cannot be built."""
    from ._native import compile_functions

    functions = {kind: _function(kind, group) for kind in NATIVE_KINDS}
    natives = compile_functions(list(functions.values()))
    return None if natives is None else {kind: natives[f.name()] for kind, f in functions.items()}


@cache
def _function(kind: str, group: str) -> Any:
    """The CasADi function of one element for ``kind`` on the group named ``group``."""
    import casadi as ca

    inputs, outputs = _terms(kind, group)
    return ca.Function(f"{kind.replace(' ', '_')}_{group}", inputs, outputs)


@lru_cache(maxsize=64)
def _mapped(kind: str, group: str, m: int) -> Callable[..., list[FloatArray]]:
    """:func:`_function` mapped over ``m`` elements, called on numpy arrays."""
    from .casadi._compile import Batched

    return Batched(_function(kind, group), m)


USE_NATIVE = True
"""Whether native kernels are used where they can be built (``MANOPT_LIE_NATIVE=0`` in the
environment keeps them from being built)."""

PATHS = ("native", "machine", "arrays")
_VM_LIMITS = (VM_EDGES, VM_POINTS)


def path_settings(name: str) -> dict[str, Any]:
    """The values of this module's switches that send the kernels down one of :data:`PATHS`:
    native code where it can be built, CasADi's virtual machine up to its limits, or the array
    kernels alone — for tests and benchmarks that check each path (set them, then restore)."""
    if name not in PATHS:
        raise ValueError(f"kernel path: expected one of {PATHS}, got {name!r}")
    limits = (0, 0) if name == "arrays" else _VM_LIMITS
    return {"USE_NATIVE": name == "native", "VM_EDGES": limits[0], "VM_POINTS": limits[1]}


def native_kernel(group: type[LieGroup], kind: str) -> Native | None:
    """The native kernel ``kind`` (:data:`NATIVE_KINDS`) of ``group`` (SE(2), SE(3)), or ``None``."""
    if not USE_NATIVE or group not in (SE2, SE3):
        return None
    kernels = native(group.__name__)
    return None if kernels is None else kernels[kind]


def flat_rows(*arrays: FloatArray) -> list[FloatArray]:
    """Each array as a C-contiguous float64 ``(m, entries)`` array (a view when it already is one)."""
    return [np.ascontiguousarray(a, dtype=np.float64).reshape(len(a), -1) for a in arrays]


def between_terms(
    group: type[LieGroup], mi: FloatArray, mj: FloatArray, z_inv: FloatArray, jac: bool
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """``Log E`` (``(m, k)``) and, with ``jac``, ``Jr⁻¹(Log E)`` and ``Ad_{Y⁻¹}`` (``(m, k, k)``; else
    ``None``) of the edges ``Y = X_i⁻¹ X_j``, ``E = Z⁻¹ Y`` given as homogeneous matrices
    ``(m, s, s)``, on the virtual machine."""
    m, k = len(mi), group.dim
    out = _mapped("terms" if jac else "log", group.__name__, m)(*flat_rows(mi, mj, z_inv))
    return (out[0], None, None) if not jac else (out[0], out[1].reshape(m, k, k), out[2].reshape(m, k, k))


def rplus(group: type[LieGroup], x: FloatArray, tau: FloatArray) -> FloatArray | None:
    """``X·Exp(τ)`` of homogeneous matrices ``(m, s, s)`` and tangents ``(m, k)``, as ``(m, s, s)``:
    native, or on the virtual machine up to :data:`VM_POINTS` elements; ``None`` (neither) beyond."""
    kernel = native_kernel(group, "rplus")
    if kernel is not None:
        out = np.empty(x.shape)
        kernel(len(x), flat_rows(x, tau), flat_rows(out))
        return out
    if len(x) > VM_POINTS:
        return None
    (out,) = _mapped("rplus", group.__name__, len(x))(*flat_rows(x, tau))
    return out.reshape(x.shape)
