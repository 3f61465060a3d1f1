"""Powell's dogleg: a trust-region step between the Cauchy point and the Gauss-Newton step.

At a linearization (gradient ``g``, Gauss-Newton matrix ``H = JᵀWJ``) the model
``m(δ) = f + gᵀδ + ½δᵀHδ`` has two cheap minimizers:

- the **Gauss-Newton step** ``δ_gn = −H⁻¹g`` (a sparse Cholesky solve, its symbolic
  analysis reused), the model's minimizer;
- the **Cauchy step** ``δ_sd = −α g`` with ``α = gᵀg / gᵀHg``, the model's minimizer
  along the steepest descent.

Within the trust region ``‖δ‖ ≤ Δ`` the dogleg step is ``δ_gn`` if it fits;
otherwise ``−(Δ/‖g‖) g`` if even ``δ_sd`` does not fit; otherwise the point of the
segment ``δ_sd + τ(δ_gn − δ_sd)``, ``τ ∈ [0, 1]``, on the sphere ``‖δ‖ = Δ``
(Nocedal & Wright, *Numerical Optimization*, §4.1; GTSAM's and Ceres's
``DoglegOptimizer``). A rejected step changes only ``Δ``: both legs are kept, so a
retry costs one cost evaluation and no factorization — where Levenberg-Marquardt
refactors ``H + λD`` for every new ``λ``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..linalg import LinearSolver, SingularSystemError
from . import _small_system
from .least_squares_problem import LeastSquaresProblem, Linearization
from .nonlinear_least_squares import NonlinearLeastSquares, _no_descent, _Step, model_decrease
from .optimizer import Run, StoppingCriteria
from .result import Status

__all__ = ["Dogleg"]

FloatArray = np.ndarray

# The kinds of step, for ``history.extra["dogleg"]``.
GAUSS_NEWTON, DOGLEG, CAUCHY = 0.0, 1.0, 2.0
# Shifts μ (times the cost scale) tried on H's diagonal until the Gauss-Newton leg solves.
_SHIFTS = (0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0, 1e2)


@dataclass
class _Legs:
    """The two legs at one linearization: ``δ_gn`` (``None`` if ``H`` is singular) and ``δ_sd``."""

    lin: Linearization
    gauss_newton: FloatArray | None
    cauchy: FloatArray | None  # None: the model is flat along g (no Cauchy point)
    stats: dict[str, float]


@dataclass
class _Region:
    radius: float | None
    legs: _Legs | None = None
    accepted: bool = True  # the last trial was accepted: keep the next one's Jacobians


def dogleg_step(
    gauss_newton: FloatArray | None, cauchy: FloatArray | None, g: FloatArray, radius: float
) -> tuple[FloatArray, float]:
    """The dogleg step of radius ``Δ`` and its kind (:data:`GAUSS_NEWTON`, :data:`DOGLEG`, :data:`CAUCHY`).

    With ``a = δ_sd``, ``b = δ_gn``: ``δ = b`` if ``‖b‖ ≤ Δ``; ``δ = (Δ/‖a‖) a`` if
    ``‖a‖ ≥ Δ``; ``a`` itself if there is no ``b`` and ``a`` fits (``−(Δ/‖g‖) g`` if
    there is no ``a``, a model flat along ``g``); else ``δ = a + τ(b − a)`` with the root
    ``τ ∈ [0, 1]`` of ``‖a + τ(b − a)‖² = Δ²``,

        τ = (−aᵀd + √((aᵀd)² + ‖d‖²(Δ² − ‖a‖²))) / ‖d‖²,   d = b − a,

    computed as ``(Δ² − ‖a‖²) / (aᵀd + √(…))`` when ``aᵀd > 0`` (no cancellation).
    """
    if gauss_newton is not None and float(np.linalg.norm(gauss_newton)) <= radius:
        return gauss_newton, GAUSS_NEWTON
    a_norm = math.inf if cauchy is None else float(np.linalg.norm(cauchy))
    if cauchy is not None and (gauss_newton is None or a_norm >= radius):
        return (cauchy if a_norm <= radius else cauchy * (radius / a_norm)), CAUCHY
    if gauss_newton is None or cauchy is None:
        return g * (-radius / float(np.linalg.norm(g))), CAUCHY
    d = gauss_newton - cauchy
    ad, dd, room = float(np.sum(cauchy * d)), float(np.sum(d * d)), radius * radius - a_norm * a_norm
    root = math.sqrt(ad * ad + dd * room)
    tau = room / (ad + root) if ad > 0 else (root - ad) / dd
    return cauchy + min(max(tau, 0.0), 1.0) * d, DOGLEG


class Dogleg(NonlinearLeastSquares):
    """Powell's dogleg on the Gauss-Newton model, with a trust-region radius ``Δ``.

    Each trial takes the dogleg step ``δ`` of radius ``Δ`` (:func:`dogleg_step`) and
    its gain ratio ``ρ = (f(x) − f(R_x(δ))) / (−gᵀδ − ½δᵀHδ)``; the step is accepted
    when ``ρ > 0``. The radius follows Nocedal & Wright's Algorithm 4.1 with GTSAM's
    growth: ``Δ ← ¼‖δ‖`` if ``ρ < ¼`` (accepted or not), ``Δ ← max(Δ, 3‖δ‖)`` if
    ``ρ > ¾``, unchanged otherwise. A radius below ``min_step`` ends the run (a
    collapse: converged, ``Status.STEP_SIZE``, if the Gauss-Newton model predicts only
    round-off, ``Status.NO_PROGRESS`` otherwise). A trial cost or a new linearization
    that is not finite is a failure.

    If the linear solver finds ``H`` singular or too ill-conditioned to solve (an
    unfixed gauge, repaired indefinite information), the Gauss-Newton leg is
    ``−(H + μsI)⁻¹g`` with the smallest ``μ`` of ``1e-8, 1e-6, …, 1e2`` that solves
    (``s`` the cost scale); if none does, every step is a Cauchy step (steepest
    descent with the model's step length, clipped to ``Δ``): slow, but never garbage.
    ``history.extra`` holds ``radius`` (the ``Δ`` of the trial), ``rho``, ``dogleg``
    (the step taken: 0 Gauss-Newton, 1 on the dogleg, 2 Cauchy) and
    ``gauss_newton_shift`` (``μ``, 0 for a plain Gauss-Newton leg).

    Parameters
    ----------
    initial_radius : float, optional
        ``Δ₀ > 0`` in the tangent norm; by default the length of the first Gauss-Newton
        step, so that the first trial is the Gauss-Newton step (GTSAM starts at 1,
        whatever the problem's units).
    linear_solver, stopping, **fields
        See :class:`~manopt_lie.optim.NonlinearLeastSquares`.
    """

    _compiled_as = _small_system.DOGLEG

    def __init__(
        self,
        *,
        initial_radius: float | None = None,
        linear_solver: str | LinearSolver | None = None,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(linear_solver=linear_solver, stopping=stopping, **fields)
        if initial_radius is not None and not (initial_radius > 0 and math.isfinite(initial_radius)):
            raise ValueError(f"Dogleg: initial_radius must be positive and finite, got {initial_radius}")
        self.initial_radius = initial_radius

    def _initial_state(self, lin: Linearization) -> _Region:
        return _Region(self.initial_radius)

    def _gauss_newton_leg(
        self, problem: LeastSquaresProblem, solver: LinearSolver, lin: Linearization, scale: float
    ) -> tuple[FloatArray | None, dict[str, float]]:
        """``−(H + μsI)⁻¹g`` with the smallest ``μ ∈ {0, 1e-8, 1e-6, …, 1e2}`` for which the
        solve succeeds (``None`` if none does): a nearly singular ``H`` (repaired indefinite
        information, a weak gauge) still gets a Gauss-Newton-like leg. ``μ`` goes to the stats
        as ``gauss_newton_shift``."""
        assert problem.structure is not None
        for mu in _SHIFTS:
            try:
                with problem.structure.shifted_diagonal(lin.hessian, mu * scale):
                    delta, stats = self._newton_system_step(solver, lin.hessian, lin.grad)
            except SingularSystemError:
                continue
            return delta, {"gauss_newton_shift": mu, **stats}
        return None, {"gauss_newton_shift": math.nan}

    def _legs(
        self, problem: LeastSquaresProblem, solver: LinearSolver, lin: Linearization, region: _Region, scale: float
    ) -> _Legs:
        """Both legs at ``lin``, computed once per linearization (rejections reuse them)."""
        if region.legs is not None and region.legs.lin is lin:
            return region.legs
        g = lin.grad
        gauss_newton, stats = self._gauss_newton_leg(problem, solver, lin, scale)
        flat = g.reshape(-1)
        curvature = float(flat @ lin.hessian_product(flat))
        gg = float(flat @ flat)
        # gᵀHg > 0 for an SPD H and g ≠ 0; otherwise the model is flat along g: no Cauchy point.
        cauchy = -(gg / curvature) * g if curvature > 0 else None
        region.legs = _Legs(lin, gauss_newton, cauchy, stats)
        return region.legs

    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: LinearSolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        region: _Region = state
        legs = self._legs(problem, solver, lin, region, run.scale)
        if region.radius is None:
            first = legs.gauss_newton if legs.gauss_newton is not None else legs.cauchy
            region.radius = float(np.linalg.norm(first)) if first is not None else 1.0
            if not (region.radius > 0 and math.isfinite(region.radius)):
                region.radius = 1.0
        radius = region.radius
        extra: dict[str, float] = {"radius": radius, **legs.stats}
        if not lin.grad.any():
            return _Step(x, lin.cost, math.nan, False, {**extra, "rho": math.nan, "dogleg": math.nan}, _no_descent(lin))
        delta, kind = dogleg_step(legs.gauss_newton, legs.cauchy, lin.grad, radius)
        extra["dogleg"] = kind
        predicted = model_decrease(lin, delta)
        if not predicted > 0:
            return _Step(x, lin.cost, math.nan, False, {**extra, "rho": math.nan}, _no_descent(lin))
        x_new = run.manifold.retr(x, delta)
        f_new = self._trial_cost(run, problem, x_new, region.accepted)
        rho = (lin.cost - f_new) / predicted
        extra["rho"] = rho
        region.accepted = rho > 0
        length = float(np.linalg.norm(delta))
        if rho < 0.25 or not math.isfinite(rho):
            region.radius = 0.25 * length
        elif rho > 0.75:
            region.radius = max(radius, 3.0 * length)
        if rho > 0:
            return _Step(x_new, f_new, length, True, extra)
        return self._fail(_Step(x, lin.cost, math.nan, False, extra), region, lin)

    def _fail(self, step: _Step, region: _Region, lin: Linearization | None = None) -> _Step:
        """A rejected step; a radius below ``min_step`` is a collapse, judged by the Gauss-Newton model."""
        assert region.radius is not None
        if region.radius < self.stopping.min_step or region.radius == 0:
            predicted = math.nan
            legs = region.legs
            if lin is not None and legs is not None and legs.lin is lin and legs.gauss_newton is not None:
                predicted = model_decrease(lin, legs.gauss_newton)
            return _Step(step.x, step.f, math.nan, False, step.extra, Status.NO_PROGRESS, True, predicted)
        return step

    def _reject_nonfinite(self, step: _Step, state: Any) -> _Step:
        """An accepted point whose linearization is not finite: rejected, the radius quartered."""
        region: _Region = state
        region.radius = 0.25 * (step.step if math.isfinite(step.step) else (region.radius or 1.0))
        return self._fail(_Step(step.x, step.f, math.nan, False, step.extra), region)
