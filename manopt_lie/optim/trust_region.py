"""Riemannian trust region with truncated conjugate gradients (Absil, Baker, Gallivan 2007)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

from ._values import structure
from .optimizer import Optimizer, Run, StoppingCriteria
from .preconditioners import Preconditioner, bind_preconditioner, check_preconditioner, from_gauss_newton
from .result import OptimizeResult, Status


class _InnerResult(NamedTuple):
    eta: Any
    model_decrease: float  # m(0) − m(η)
    iterations: int
    reason: str  # "residual", "negative curvature", "boundary", "max iterations" or "non-finite"


def _identity(x: Any, r: Any) -> Any:
    return r


def _power(a: float, b: float) -> float:
    """``a**b``, ``inf`` on overflow (Python's ``**`` raises ``OverflowError``)."""
    try:
        return a**b
    except OverflowError:
        return math.inf


def default_max_radius(typical_dist: float, f0: float, gauss_newton_norm: bool) -> float:
    """``Δ̄`` when none is given: the manifold's ``typical_dist``; in the norm of a preconditioner
    built from ``G = JᵀWJ`` (``gauss_newton_norm``), at least ``√(2 f(x₀))``.

    That norm, ``‖η‖_P = √(ηᵀP⁻¹η)``, is in units of the square root of the cost, not of
    distance: a Gauss-Newton step of plain least squares has ``½‖η‖²_G = m(0) − m(η) ≤ f``, so
    from ``x₀`` or any later (cheaper) point none is longer than ``√(2 f(x₀))``. A distance cap
    measured in it would bind far from the solution: a landmark world of 2000 poses, started
    517 from its optimum, needs a first step of ``‖η‖_G = 1.9·10⁴`` and took 238 steps of 82."""
    if gauss_newton_norm and math.isfinite(f0) and f0 > 0:
        return max(typical_dist, math.sqrt(2.0 * f0))
    return typical_dist


class TrustRegion(Optimizer):
    """Minimize the model ``m(η) = f + ⟨g, η⟩ + ½⟨η, H[η]⟩`` over ``‖η‖ ≤ Δ`` by truncated CG
    (Steihaug–Toint), accept ``R_x(η)`` when ``ρ = (f(x) − f(R_x(η)))/(m(0) − m(η)) > rho_prime``,
    and adapt ``Δ``: ×¼ when ``ρ < ¼``, ×2 (at most ``Δ̄``) when ``ρ > ¾`` on the boundary.

    ``H`` is the problem's Hessian when it has one, otherwise the finite difference
    ``H[v] ≈ (T_{y→x} grad f(y) − grad f(x))/t`` with ``y = R_x(t v)``,
    ``t = fd_step/‖v‖`` (as Manopt does), so a cost with a gradient suffices.
    The inner iteration stops at ``‖r_j‖ ≤ ‖r_0‖ min(‖r_0‖^θ, κ)`` (superlinear
    local convergence for ``θ = 1``), on negative curvature or at the boundary.
    It runs on ``g/‖g‖`` and ``H/‖g‖`` (the same iterates), so that costs of any
    magnitude neither under- nor overflow.

    A trial point whose cost or gradient is not finite is rejected (the radius
    shrinks); a non-finite Hessian product ends the run with
    ``Status.NON_FINITE`` at the current point. When the radius falls below
    ``min_step``, or an accepted step is shorter, the model is solved once more
    at the full radius ``Δ̄``: if even that predicts no decrease above
    round-off the run has converged (``Status.STEP_SIZE``), otherwise the cost
    and its derivatives disagree (``Status.NO_PROGRESS``).

    Parameters
    ----------
    max_radius : float, optional
        ``Δ̄``, in the region's norm; by default the manifold's ``typical_dist``, and with a
        preconditioner built from ``JᵀWJ`` at least ``√(2 f(x₀))`` (that norm's units are the
        cost's square root: :func:`default_max_radius`).
    initial_radius : float, optional
        ``Δ₀``; ``Δ̄/8`` by default.
    rho_prime : float
        Acceptance threshold, in ``[0, ¼)``.
    kappa, theta : float
        Inner stopping parameters.
    max_inner_iterations : int, optional
        Default: the manifold's dimension.
    preconditioner : {"auto", "gauss-newton", "block-jacobi", "identity"} or callable ``(x, r) ↦ z``
        A symmetric positive definite operator ``P ≈ H⁻¹`` on tangent vectors (the
        trust region is then measured in the norm ``‖η‖_P = √⟨η, P⁻¹η⟩``).
        ``"gauss-newton"``: ``(JᵀWJ)⁻¹`` of a least-squares problem at the current
        point, by a sparse Cholesky factorization per outer iteration (analysis
        once per run); ``"block-jacobi"``: the inverse of the diagonal blocks of
        ``JᵀWJ``; ``"identity"``: none; ``"auto"`` (default): ``"gauss-newton"``
        for a :class:`~manopt_lie.optim.LeastSquaresProblem`, ``"identity"``
        otherwise (see :mod:`~manopt_lie.optim.preconditioners`). A named one built
        from ``JᵀWJ`` on another problem raises ``ValueError`` in :meth:`solve`.
    fd_step : float
        The finite-difference step, relative to ``‖v‖``.
    """

    def __init__(
        self,
        *,
        max_radius: float | None = None,
        initial_radius: float | None = None,
        rho_prime: float = 0.1,
        kappa: float = 0.1,
        theta: float = 1.0,
        max_inner_iterations: int | None = None,
        preconditioner: str | Preconditioner = "auto",
        fd_step: float = 2.0**-14,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        if not 0 <= rho_prime < 0.25:
            raise ValueError(f"TrustRegion: rho_prime must be in [0, 1/4), got {rho_prime}")
        self.max_radius, self.initial_radius = max_radius, initial_radius
        self.rho_prime, self.kappa, self.theta = rho_prime, kappa, theta
        self.preconditioner = check_preconditioner(preconditioner)
        self.max_inner_iterations, self.fd_step = max_inner_iterations, fd_step

    # ---- the model's Hessian ------------------------------------------------------

    def _hessian(self, run: Run, x: Any, g: Any) -> Callable[[Any], Any]:
        if run.problem.has_hessian:
            return run.hess_operator(x)
        m = run.manifold

        def finite_difference(v: Any) -> Any:
            v_norm = run.norm(x, v)
            if v_norm == 0.0:
                return m.zero_vector(x)
            t = self.fd_step / v_norm
            y = m.retr(x, v * t)
            return (m.transp(y, x, run.grad(y)) - g) * (1.0 / t)

        return finite_difference

    # ---- truncated CG -------------------------------------------------------------

    def _tcg(
        self,
        run: Run,
        x: Any,
        g: Any,
        g_norm: float,
        hess: Callable[[Any], Any],
        radius: float,
        precon: Preconditioner,
        reproject: bool = False,
    ) -> _InnerResult:
        """Steihaug–Toint truncated CG on ``m(η)`` in the (preconditioned) trust region.

        It runs on the system scaled by ``σ = ‖g‖`` (``r₀ = g/σ``, products ``H d/σ``),
        with the preconditioner rescaled too if ``‖P r₀‖`` is far from 1: the
        iterates ``η`` and the region are those of the unscaled system, and the
        model decrease is ``σ·(−⟨r₀, η⟩ − ½⟨η, Hη/σ⟩)``. With ``reproject`` (tangent
        vectors that are ambient arrays: embedded manifolds) ``r₀`` is projected onto
        the tangent space again: near convergence the round-off of ``proj(∇f)``, relative
        to ``‖g‖``, is no longer small, and CG cannot reduce a normal component.
        """
        m = run.manifold
        inner = m.total_inner
        max_inner = self.max_inner_iterations or max(1, m.dim)
        if not g_norm > 0:  # a critical point: the model's minimizer is η = 0
            return _InnerResult(m.zero_vector(x), 0.0, 0, "residual")
        inv_sigma = 1.0 / g_norm
        r0 = (m.proj(x, g) if reproject else g) * inv_sigma
        eta = h_eta = m.zero_vector(x)  # h_eta = H η / σ (never updated in place)

        def result(eta: Any, h_eta: Any, j: int, reason: str) -> _InnerResult:
            decrease = -g_norm * (inner(x, r0, eta) + 0.5 * inner(x, eta, h_eta))
            return _InnerResult(eta, decrease, j, reason)

        r = r0
        z = precon(x, r)
        z_norm = run.norm(x, z)
        if not 0.0 < z_norm < math.inf:
            return _InnerResult(eta, math.nan, 0, "non-finite")
        # P' = cP gives the same iterates, and ‖η‖²_P' = ‖η‖²_P / c: a P far from unit
        # scale (a tiny cost's (JᵀJ)⁻¹) is rescaled so that ⟨d, Hd⟩ cannot overflow.
        c = 1.0 if 1e-100 < z_norm < 1e100 else 1.0 / z_norm
        if c != 1.0:
            z = z * c
        radius_sq = radius * radius / c
        d = -z
        rz = inner(x, r, z)
        target = min(_power(g_norm, self.theta), self.kappa)  # ‖r_j‖/‖r_0‖ at which to stop
        # ‖r‖ ≤ target tested on squares (‖r₀‖ = 1), unless the square of target underflows.
        target_sq = target * target

        def small(r: Any) -> bool:
            return inner(x, r, r) <= target_sq if target > 1e-120 else run.norm(x, r) <= target

        e_pe, e_pd, d_pd = 0.0, 0.0, rz  # ⟨η, P'⁻¹η⟩, ⟨η, P'⁻¹d⟩, ⟨d, P'⁻¹d⟩: the region's norm
        for j in range(1, max_inner + 1):
            hd = hess(d) * inv_sigma
            d_hd = inner(x, d, hd)
            if not (math.isfinite(d_hd) and math.isfinite(rz)):
                return _InnerResult(eta, math.nan, j, "non-finite")
            alpha = rz / d_hd if d_hd != 0 else math.inf
            e_pe_new = e_pe + 2.0 * alpha * e_pd + alpha * alpha * d_pd
            if not d_pd > 0:  # a preconditioner that is not positive definite (or round-off): stop at η
                return result(eta, h_eta, j, "indefinite preconditioner")
            if d_hd <= 0 or e_pe_new >= radius_sq:
                # Follow d to the boundary: ‖η + τ d‖ = Δ.
                tau = (-e_pd + math.sqrt(max(e_pd * e_pd + d_pd * (radius_sq - e_pe), 0.0))) / d_pd
                reason = "negative curvature" if d_hd <= 0 else "boundary"
                return result(eta + d * tau, h_eta + hd * tau, j, reason)
            eta, h_eta, e_pe = eta + d * alpha, h_eta + hd * alpha, e_pe_new
            r = r + hd * alpha
            if small(r):
                return result(eta, h_eta, j, "residual")
            z = precon(x, r) if c == 1.0 else precon(x, r) * c
            rz, rz_old = inner(x, r, z), rz
            beta = rz / rz_old
            e_pd = beta * (e_pd + alpha * d_pd)
            d_pd = rz + beta * beta * d_pd
            d = -z + d * beta
        return result(eta, h_eta, max_inner, "max iterations")

    # ---- outer iteration ----------------------------------------------------------

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m = run.manifold
        bound = bind_preconditioner(self.preconditioner, run.problem)  # this run's own state
        precon = bound or _identity
        x = x0
        f, g, g_norm = run.initial(x0, hessian=run.problem.has_hessian)
        max_radius = self.max_radius or default_max_radius(m.typical_dist, f, from_gauss_newton(bound))
        radius = self.initial_radius or max_radius / 8.0
        zero = m.zero_vector(x0)
        reproject = structure(m.to_ambient(x0, zero)) == structure(zero)  # tangents are ambient arrays
        status = Status.CALLBACK if run.record(x, f, g_norm, radius=radius) else run.stop_reason()
        while status is None:
            inner = self._tcg(run, x, g, g_norm, self._hessian(run, x, g), radius, precon, reproject)
            if inner.reason == "non-finite":
                status = Status.NON_FINITE
                break
            x_new = m.retr(x, inner.eta)
            f_new = run.cost(x_new)  # inf if not finite: ρ = −inf, rejected
            model_decrease = inner.model_decrease
            # Regularized ratio: near convergence both decreases drown in round-off.
            reg = run.roundoff(f)
            rho = (f - f_new + reg) / (model_decrease + reg)
            eta_norm = run.norm(x, inner.eta)
            accepted = rho > self.rho_prime and model_decrease > 0
            if accepted:
                g_new = run.grad(x_new)
                g_new_norm = run.norm(x_new, g_new)
                if not math.isfinite(g_new_norm):  # no usable gradient there: reject it
                    accepted, rho = False, -math.inf
            if not rho >= 0.25:
                radius /= 4.0
            elif rho > 0.75 and inner.reason in ("negative curvature", "boundary"):
                radius = min(2.0 * radius, max_radius)
            f_prev = f
            if accepted:
                x, f, g, g_norm = x_new, f_new, g_new, g_new_norm
            stop = run.record(
                x, f, g_norm, eta_norm if accepted else math.nan,  # nan: no step was taken
                radius=radius, rho=rho, inner_iterations=inner.iterations, accepted=float(accepted),
            )  # fmt: skip
            status = Status.CALLBACK if stop else run.stop_reason(f_prev if accepted else None)
            if status is None and radius < self.stopping.min_step:
                status = Status.STEP_SIZE
            if status is Status.STEP_SIZE:  # converged only if the model sees nothing left to gain
                final = self._tcg(run, x, g, g_norm, self._hessian(run, x, g), max_radius, precon, reproject)
                status = run.stall_status(final.model_decrease, f)
        return run.result(x, status)
