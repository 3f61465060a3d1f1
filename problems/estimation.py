"""State estimation on Lie groups: the error-state EKF, beacon factors, consistency statistics.

The estimation examples of the seed notes (Solà, Deray, Atchuthan, *A micro Lie theory for
state estimation in robotics*; ``docs/ekf.md``, ``docs/landmarks.md``), built from the
library's right Jacobians (CONVENTIONS §3–4): a state ``X ~ N(X̂, P)`` means
``X = X̂ ⊕ τ = X̂·Exp(τ)``, ``τ ~ N(0, P)``, ``P`` in the right (local) tangent of ``X̂``,
translation first.

- :class:`ErrorStateEKF` and :class:`Motion` — prediction ``X̂ ← X̂ ⊕ u``,
  ``P ← F P Fᵀ + G Q Gᵀ`` with ``F = Ad_{Exp(u)}⁻¹``, ``G = Jr(u)`` (the Jacobians of
  ``X ⊕ u``, Solà eqs. 80–81);
  correction by innovations ``y`` with Jacobians ``H`` (Kalman gain, Joseph form), and
  :meth:`~ErrorStateEKF.correct_points` for known points (beacons) seen in the state's
  frame, ``z = X⁻¹ b + v``. Batched over leading axes, so Monte-Carlo runs filter at once.
- :func:`known_point_factor` — the same measurement as a unary least-squares factor
  (:func:`~manopt_lie.factors.relative_point_factor` with the point given), for the batch
  smoother over the poses only.
- :func:`nees`, :func:`chi2_interval`, :func:`mean_nees_interval`, :func:`residual_chi2` —
  the consistency checks: normalized estimation errors ``eᵀ Σ⁻¹ e ~ χ²(d)`` and the
  chi-square ``Σ rᵀΩr ~ χ²(#residuals − #free coordinates)`` of a least-squares optimum.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from manopt_lie.errors import ShapeError
from manopt_lie.factors import NoiseModel, relative_point_factor
from manopt_lie.lie.base import LieGroup
from manopt_lie.optim import Factor, LeastSquaresProblem

FloatArray = NDArray[np.float64]

__all__ = [
    "ErrorStateEKF",
    "Motion",
    "known_point_factor",
    "nees",
    "chi2_interval",
    "mean_nees_interval",
    "residual_chi2",
]


def _swap(a: NDArray[np.floating[Any]]) -> FloatArray:
    return np.swapaxes(a, -1, -2).astype(np.float64, copy=False)


def _symmetric(a: FloatArray) -> FloatArray:
    return 0.5 * (a + _swap(a))


@dataclass(frozen=True)
class Motion:
    """The prediction terms of increments ``u`` with noise ``w ~ N(0, Q)``: ``Exp(u)``,
    ``F = Ad_{Exp(u)}⁻¹`` and ``W = G Q Gᵀ``, ``G = Jr(u)``, batched (e.g. over time steps).

    They do not depend on the state, so a filter's steps can take them from one batched
    call (:meth:`of`) before its time loop; ``motion[k]`` is step ``k``.

    Attributes
    ----------
    increment : LieGroup
        ``Exp(u)``, batch shape ``B``.
    F, W : arrays ``(*B, n, n)``
    """

    increment: LieGroup
    F: FloatArray
    W: FloatArray

    @classmethod
    def of(cls, group: type[LieGroup], u: ArrayLike, Q: ArrayLike) -> Motion:
        """The terms of increments ``u`` with noise covariances ``Q``, in one batched call.

        From ``identity.rplus(u, jac=True)``: the Jacobians of ``X ⊕ u`` do not depend on ``X``.

        Parameters
        ----------
        group : type of LieGroup
        u : array ``(*B, n)``
        Q : array ``(*B', n, n)``
            Broadcasting against ``B``.
        """
        t = np.asarray(u, dtype=np.float64)
        increment, F, G = group.identity(t.shape[:-1]).rplus(t, jac=True)
        W = G @ np.asarray(Q, dtype=np.float64) @ _swap(G)
        return cls(increment, F, _symmetric(W))

    def __getitem__(self, index: Any) -> Motion:
        return Motion(self.increment[index], self.F[index], self.W[index])


@dataclass(frozen=True)
class ErrorStateEKF:
    """A Gaussian ``X = X̂ ⊕ τ``, ``τ ~ N(0, P)`` on a Lie group, and the error-state EKF's steps.

    Each step returns a new filter (the object is immutable). Everything broadcasts over
    the leading batch axes of ``x`` and ``P`` (CONVENTIONS §1): a batch of ``N`` filters
    runs ``N`` Monte-Carlo runs in one call per time step.

    Parameters
    ----------
    x : LieGroup
        The mean ``X̂``, batch shape ``B``.
    P : array ``(*B', n, n)``
        The covariance of ``τ`` in the right tangent of ``X̂`` (``n = x.dim``). ``x`` and
        ``P`` are broadcast to their common batch shape.
    nis : array ``B``, optional
        The normalized innovation squared ``yᵀ S⁻¹ y`` of the last correction
        (``None`` before any): ``~ χ²(m)`` for ``m`` measured coordinates when the
        filter is consistent.
    """

    x: LieGroup
    P: FloatArray
    nis: FloatArray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.x, LieGroup):
            raise TypeError(f"ErrorStateEKF: x must be a Lie group element, got {type(self.x).__name__}")
        p = np.asarray(self.P, dtype=np.float64)
        n = self.x.dim
        if p.ndim < 2 or p.shape[-2:] != (n, n):
            raise ShapeError(f"ErrorStateEKF: P must have shape (..., {n}, {n}), got {p.shape}")
        batch = np.broadcast_shapes(self.x.batch_shape, p.shape[:-2])
        if self.x.batch_shape != batch:
            object.__setattr__(self, "x", self.x.broadcast_to(batch))
        object.__setattr__(self, "P", np.broadcast_to(p, batch + (n, n)))

    def predict(self, u: ArrayLike, Q: ArrayLike) -> ErrorStateEKF:
        r"""The motion ``X ← X ⊕ (u + w)``, ``w ~ N(0, Q)``, to first order.

        .. math::

            \hat X \leftarrow \hat X \oplus u, \qquad
            P \leftarrow F P F^\top + G Q G^\top, \qquad
            F = \operatorname{Ad}_{\operatorname{Exp}(u)}^{-1}, \quad G = J_r(u)

        (the Jacobians of ``X ⊕ u`` wrt ``X`` and ``u``, from ``rplus(jac=True)``; Solà
        eqs. 80–81, the seed's *EKF prediction*). ``Motion.of(group, u, Q)`` computes the
        same terms for every step at once, and :meth:`propagate` applies one of them.

        Parameters
        ----------
        u : array ``(*B', n)``
            The increment in the tangent (e.g. ``(v, ω)·dt``), broadcasting against ``B``.
        Q : array ``(*B'', n, n)``
            The covariance of its noise ``w``.
        """
        return self.propagate(Motion.of(type(self.x), u, Q))

    def propagate(self, motion: Motion) -> ErrorStateEKF:
        """``X̂ ← X̂·Exp(u)``, ``P ← F P Fᵀ + W``: :meth:`predict` with precomputed terms.

        Parameters
        ----------
        motion : Motion
            One step's terms (``Motion.of(group, u, Q)[k]``), or a batch broadcasting
            against the filter's.
        """
        P = motion.F @ self.P @ _swap(motion.F) + motion.W
        return ErrorStateEKF(self.x @ motion.increment, _symmetric(P), None)

    def correct(self, innovation: ArrayLike, H: ArrayLike, R: ArrayLike) -> ErrorStateEKF:
        r"""The update by measurements ``z = h(X) + v``, ``v ~ N(0, R)``, linearized at ``X̂``.

        .. math::

            S = H P H^\top + R, \quad K = P H^\top S^{-1}, \quad
            \hat X \leftarrow \hat X \oplus K y, \quad
            P \leftarrow (I - K H) P (I - K H)^\top + K R K^\top

        (the seed's *EKF correction*, with Joseph's form of ``P ← P − K S Kᵀ``: symmetric
        and positive semidefinite whatever the round-off in ``K``). ``H = ∂h/∂X`` is the
        right Jacobian at ``X̂``. The covariance stays in the tangent of the *prior* mean;
        the reset ``P ← Jr(Ky) P Jr(Ky)ᵀ`` to the new mean's tangent is second order in the
        correction and left out, as in the seed.

        Parameters
        ----------
        innovation : array ``(*B, m)``
            ``y = z − h(X̂)``.
        H : array ``(*B, m, n)``
        R : array ``(*B', m, m)``
            Measurement noise covariance.
        """
        y = np.asarray(innovation, dtype=np.float64)
        h = np.asarray(H, dtype=np.float64)
        r = np.asarray(R, dtype=np.float64)
        m, n = y.shape[-1], self.x.dim
        if h.shape[-2:] != (m, n) or r.shape[-2:] != (m, m):
            raise ShapeError(f"correct: expected H (..., {m}, {n}) and R (..., {m}, {m}), got {h.shape}, {r.shape}")
        ph = self.P @ _swap(h)
        s = _symmetric(h @ ph + r)
        gain = _swap(np.linalg.solve(s, _swap(ph)))  # P Hᵀ S⁻¹ (S symmetric)
        delta = np.einsum("...ij,...j->...i", gain, y)
        a = np.eye(n) - gain @ h
        P = a @ self.P @ _swap(a) + gain @ r @ _swap(gain)
        nis = np.einsum("...i,...i->...", y, np.linalg.solve(s, y[..., None])[..., 0])
        return ErrorStateEKF(self.x.rplus(delta), _symmetric(P), nis)

    def correct_points(self, points: ArrayLike, measured: ArrayLike, R: ArrayLike) -> ErrorStateEKF:
        """The update by known points ``b_k`` seen in the state's frame, ``z_k = X⁻¹ b_k + v_k``.

        The seed's beacon measurement (the relative-point factor's model with the point
        known). Its Jacobian by the chain rule of the library's blocks,
        ``H_k = ∂(X⁻¹ b)/∂X⁻¹ · ∂X⁻¹/∂X`` (``X⁻¹.act(b, jac=True)`` and
        ``X.inverse(jac=True)``, i.e. ``[R, −R[b]×]·(−Ad_X) = [−I, [X⁻¹b]×]`` on SE(3)); the
        ``k`` points are stacked into one update.

        Parameters
        ----------
        points : array ``(*B', k, d)``
            The known points ``b_k`` (``d = x.point_dim``).
        measured : array ``(*B, k, d)``
            Their measurements ``z_k``.
        R : array ``(d, d)``, ``(k, d, d)`` or with batch axes
            The noise covariance of each point (independent points).
        """
        b = np.asarray(points, dtype=np.float64)
        z = np.asarray(measured, dtype=np.float64)
        d, n = self.x.point_dim, self.x.dim
        if b.ndim < 2 or b.shape[-1] != d or z.shape[-1] != d:
            raise ShapeError(f"correct_points: points and measured must be (..., k, {d}), got {b.shape}, {z.shape}")
        k = b.shape[-2]
        inverse, J_inv = self.x.inverse(jac=True)
        batch = self.x.batch_shape
        predicted, J_act, _ = inverse.reshape(batch + (1,)).act(b, jac=True)
        y = z - predicted
        H = np.broadcast_to(J_act @ J_inv[..., None, :, :], y.shape + (n,)).reshape(y.shape[:-2] + (k * d, n))
        r = np.broadcast_to(np.asarray(R, dtype=np.float64), np.broadcast_shapes(np.shape(R)[:-2], (k,)) + (d, d))
        block = np.einsum("...kij,kl->...kilj", r, np.eye(k)).reshape(r.shape[:-3] + (k * d, k * d))
        return self.correct(y.reshape(y.shape[:-2] + (k * d,)), H, block)


def known_point_factor(
    variables: ArrayLike,
    points: ArrayLike,
    measured: ArrayLike,
    noise: NoiseModel | None = None,
    *,
    offset: LieGroup | None = None,
    name: str = "known_point",
    blocks: tuple[str, ...] | str | None = None,
) -> Factor:
    """A known point ``b_e`` seen from a pose: ``z_e ≈ (X S)⁻¹ b_e``, a unary factor on ``X``.

    :func:`~manopt_lie.factors.relative_point_factor` with its point slot given, so its
    residual ``r = (X S)⁻¹ b − z`` and right Jacobian ``∂r/∂X = R_Sᵀ[−I, [q]×]``
    (``q = Rᵀ(b − t)``) are the library's: the EKF's :meth:`ErrorStateEKF.correct_points`
    measurement as a least-squares factor (beacons, known landmarks).

    Parameters
    ----------
    variables : int array ``(m,)``
        The pose of each edge.
    points : array ``(m, d)``
        The known points ``b_e``.
    measured : array ``(m, d)``
        ``z_e``, in the sensor frame.
    noise : NoiseModel, optional
        Of dimension ``d``.
    offset, name, blocks
        As for :func:`~manopt_lie.factors.relative_point_factor` (one block name: the poses').
    """
    v = np.asarray(variables).reshape(-1)
    b = np.array(points, dtype=np.float64)
    if b.ndim != 2 or b.shape[0] != v.shape[0]:
        raise ShapeError(f"{name}: points must have shape ({v.shape[0]}, d), got {b.shape}")
    b.flags.writeable = False
    pairs = np.stack([v, np.arange(len(v))], axis=1)
    inner = relative_point_factor(pairs, measured, noise, offset=offset, name=name)
    block = blocks[0] if isinstance(blocks, tuple) else blocks

    def residual(x: Any, jac: bool = False) -> Any:
        if not jac:
            return inner.residual(x, b, jac=False)
        r, (j_x, _) = inner.residual(x, b, jac=True)
        return r, [j_x]

    return Factor(v[:, None], residual, name=name, blocks=block, residual_dim=inner.residual_dim)


def nees(errors: ArrayLike, covariances: ArrayLike) -> FloatArray:
    """Normalized estimation errors ``eᵀ Σ⁻¹ e``, batched.

    For an estimate ``X̂`` with covariance ``Σ`` (of ``τ`` in ``X = X̂ ⊕ τ``) and the truth
    ``X``, ``e = X ⊖ X̂ = truth.rminus(estimate)``; a consistent estimator has
    ``NEES ~ χ²(d)``, mean ``d``.

    Parameters
    ----------
    errors : array ``(..., d)``
    covariances : array ``(..., d, d)``
        Symmetric positive definite, broadcasting against ``errors``.

    Returns
    -------
    array ``(...)``
    """
    e = np.asarray(errors, dtype=np.float64)
    c = np.asarray(covariances, dtype=np.float64)
    if c.ndim < 2 or c.shape[-2:] != (e.shape[-1],) * 2:
        raise ShapeError(f"nees: covariances must be (..., {e.shape[-1]}, {e.shape[-1]}), got {c.shape}")
    lower = np.linalg.cholesky(c)
    w = np.linalg.solve(lower, np.broadcast_to(e[..., None], np.broadcast_shapes(e.shape, c.shape[:-1]) + (1,)))
    return np.asarray(np.sum(w[..., 0] ** 2, axis=-1))


def chi2_interval(dof: float, probability: float = 0.998) -> tuple[float, float]:
    """The central interval of ``χ²(dof)`` holding ``probability``: by default its 0.1 % and
    99.9 % quantiles (``scipy.stats.chi2.ppf``)."""
    if not 0 < probability < 1 or not dof > 0:
        raise ValueError(f"chi2_interval: need dof > 0 and 0 < probability < 1, got {dof}, {probability}")
    lo, hi = chi2.ppf([(1 - probability) / 2, (1 + probability) / 2], dof)
    return float(lo), float(hi)


def mean_nees_interval(dim: int, samples: int, probability: float = 0.998) -> tuple[float, float]:
    """Where the mean of ``samples`` *independent* ``χ²(dim)`` variables lies with ``probability``.

    ``samples · mean ~ χ²(samples · dim)``, so the interval is
    :func:`chi2_interval` ``(samples · dim) / samples``. Errors of one estimate's
    variables are correlated (they share measurements): count independent runs, not
    variables, for ``samples`` (``docs/landmarks.md``).
    """
    lo, hi = chi2_interval(dim * samples, probability)
    return lo / samples, hi / samples


def residual_chi2(problem: LeastSquaresProblem, x: Any) -> tuple[float, int]:
    """``Σ rᵀΩr`` at ``x`` and its degrees of freedom.

    The whitened residuals' squared norm (``2f`` for plain least squares) and
    ``dof = #residual entries − #free tangent coordinates``: at the optimum of a problem
    whose noise models are right, ``Σ rᵀΩr ~ χ²(dof)`` to first order (the residual is
    the noise projected off the ``#free``-dimensional column space of ``J``).

    Parameters
    ----------
    problem : LeastSquaresProblem
    x : point of ``problem.manifold``

    Returns
    -------
    value : float
    dof : int
    """
    lin = problem.linearize(x)
    value = float(sum(np.sum(r * r) for r in lin.residuals))
    entries = sum(int(r.size) for r in lin.residuals)
    free = int(np.sum(problem.dims[~problem.fixed]))
    return value, entries - free
