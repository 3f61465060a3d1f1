"""How a rotation is stored in the reference NLP: unit quaternions (complex numbers in 2-D)
or matrices, each with its constraints, its matrix and the residual rotation vector —
with every ``x/sin x``-like coefficient safe at zero residual."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from manopt_lie import SO2, SO3
from manopt_lie.casadi.lie import atan2_ratio
from manopt_lie.lie._matrix import project_rotation
from manopt_lie.optim.losses import L1, Cauchy, GemanMcClure, Huber, RobustLoss, Trivial, TruncatedL2

FloatArray = NDArray[np.float64]

# ---- scalar helpers, safe at zero residual ----------------------------------------------


def _rho(loss: RobustLoss, s: Any) -> Any:
    """``ρ(s)`` of :mod:`manopt_lie.optim.losses`, symbolically (safe ``√`` in Huber's linear part)."""
    if isinstance(loss, Trivial):
        return s
    c2 = loss.c**2  # type: ignore[attr-defined]
    if isinstance(loss, Huber):
        return ca.if_else(s <= c2, s, 2.0 * loss.c * ca.sqrt(ca.fmax(s, c2)) - c2)
    if isinstance(loss, Cauchy):
        return c2 * ca.log1p(s / c2)
    if isinstance(loss, GemanMcClure):
        return c2 * s / (c2 + s)
    if isinstance(loss, TruncatedL2):
        return ca.fmin(s, c2)
    if isinstance(loss, L1):
        return 2.0 * c2 * (ca.sqrt(1.0 + s / c2) - 1.0)
    raise ValueError(f"reference_solve: no symbolic form for the robust loss {loss!r}")


def _cross(a: Any, b: Any) -> Any:
    return ca.vertcat(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _qmul(p: Any, q: Any) -> Any:
    """Hamilton product of ``(x, y, z, w)`` quaternions."""
    pv, pw, qv, qw = p[:3], p[3], q[:3], q[3]
    return ca.vertcat(pw * qv + qw * pv + _cross(pv, qv), pw * qw - ca.dot(pv, qv))


def _cmul(a: Any, b: Any) -> Any:
    """Product of complex numbers stored ``(re, im)``."""
    return ca.vertcat(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


# ---- rotation parametrizations --------------------------------------------------------------


class _Rotations:
    """How a rotation is stored in the NLP: ``size`` numbers per rotation, its matrix,
    its constraints, the rotation vector (or angle) of ``R̃ᵀR_iᵀR_j``, and conversions."""

    size: int
    n_constraints: int

    def __init__(self, d: int) -> None:
        self.d = d

    def matrix(self, r: Any) -> Any:  # SX d×d
        raise NotImplementedError

    def constraints(self, r: Any) -> Any:
        raise NotImplementedError

    def residual(self, ri: Any, rj: Any, meas: Any, meas_matrix: Any) -> tuple[Any, Any]:
        """``(θ², θ)`` of ``Log(R̃ᵀR_iᵀR_j)``: ``θ`` the angle (2-D) or rotation vector (3-D)."""
        raise NotImplementedError

    def pack(self, r: FloatArray) -> FloatArray:  # (n, d, d) -> (n, size)
        raise NotImplementedError

    def unpack(self, v: FloatArray) -> tuple[FloatArray, int]:  # (n, size) -> rotations (n, d, d), reflections
        raise NotImplementedError


class _MatrixRotations(_Rotations):
    def __init__(self, d: int) -> None:
        super().__init__(d)
        self.size, self.n_constraints = d * d, d * (d + 1) // 2
        self._upper = [(a, b) for a in range(d) for b in range(a, d)]

    def matrix(self, r: Any) -> Any:
        return ca.reshape(r, self.d, self.d)  # column-major, as packed

    def constraints(self, r: Any) -> Any:
        m = self.matrix(r)
        gram = m.T @ m - ca.DM.eye(self.d)
        return ca.vertcat(*[gram[a, b] for a, b in self._upper])

    def residual(self, ri: Any, rj: Any, meas: Any, meas_matrix: Any) -> tuple[Any, Any]:
        e = meas_matrix.T @ self.matrix(ri).T @ self.matrix(rj)
        if self.d == 2:
            theta = ca.atan2(e[1, 0] - e[0, 1], e[0, 0] + e[1, 1])
            return theta * theta, theta
        a = 0.5 * ca.vertcat(e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1])
        s2, c = ca.dot(a, a), 0.5 * (ca.trace(e) - 1.0)
        g = atan2_ratio(s2, c)
        return s2 * g * g, g * a

    def pack(self, r: FloatArray) -> FloatArray:
        return np.swapaxes(r, 1, 2).reshape(len(r), -1)

    def unpack(self, v: FloatArray) -> tuple[FloatArray, int]:
        m = np.swapaxes(v.reshape(len(v), self.d, self.d), 1, 2)
        return project_rotation(m), int(np.sum(np.linalg.det(m) <= 0))


class _UnitRotations(_Rotations):
    """Unit quaternions ``(x, y, z, w)`` (3-D) or unit complex numbers ``(cos θ, sin θ)`` (2-D)."""

    def __init__(self, d: int) -> None:
        super().__init__(d)
        self.size, self.n_constraints = (2 if d == 2 else 4), 1

    def matrix(self, r: Any) -> Any:
        if self.d == 2:
            return ca.vertcat(ca.horzcat(r[0], -r[1]), ca.horzcat(r[1], r[0]))
        v, w = r[:3], r[3]
        return (w * w - ca.dot(v, v)) * ca.DM.eye(3) + 2.0 * (v @ v.T) + 2.0 * w * ca.skew(v)

    def constraints(self, r: Any) -> Any:
        return ca.dot(r, r) - 1.0

    def residual(self, ri: Any, rj: Any, meas: Any, meas_matrix: Any) -> tuple[Any, Any]:
        conj = ca.DM([1, -1]) if self.d == 2 else ca.DM([-1, -1, -1, 1])
        if self.d == 2:
            e = _cmul(_cmul(meas * conj, ri * conj), rj)
            theta = ca.atan2(e[1], e[0])
            return theta * theta, theta
        e = _qmul(_qmul(meas * conj, ri * conj), rj)
        v, w = e[:3], e[3]
        s2, c = ca.dot(v, v), ca.fabs(w)
        g = 2.0 * atan2_ratio(s2, c)
        return s2 * g * g, ca.sign(w) * g * v

    def pack(self, r: FloatArray) -> FloatArray:
        if self.d == 2:
            return np.stack([r[:, 0, 0], r[:, 1, 0]], axis=1)
        return SO3.from_matrix(r).as_quaternion()

    def unpack(self, v: FloatArray) -> tuple[FloatArray, int]:
        if self.d == 2:
            return SO2.from_angle(np.arctan2(v[:, 1], v[:, 0])).as_matrix(), 0
        return SO3.from_quaternion(v, normalize=True).as_matrix(), 0


def rotations(parametrization: str, d: int) -> _Rotations:
    if parametrization == "matrix":
        return _MatrixRotations(d)
    if parametrization == "quaternion":
        return _UnitRotations(d)
    raise ValueError(f"unknown parametrization {parametrization!r}")
