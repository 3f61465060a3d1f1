"""Riemannian nonlinear conjugate gradients (Absil, Mahony, Sepulchre §8.3; Sato 2021)."""

from __future__ import annotations

import math
from typing import Any

from .line_search import Backtracking
from .optimizer import Optimizer, Run
from .result import OptimizeResult, Status

BETA_RULES = ("fletcher-reeves", "polak-ribiere", "hestenes-stiefel", "hager-zhang")


class ConjugateGradient(Optimizer):
    """``d_k = −g_k + β_k T(d_{k−1})``, ``x_{k+1} = R_{x_k}(α_k d_k)`` (Armijo search).

    With ``T`` the vector transport to ``x_k``, ``g̃ = T(g_{k−1})`` and
    ``y = g_k − g̃``:

    * ``"fletcher-reeves"``: ``β = ‖g_k‖² / ‖g_{k−1}‖²``;
    * ``"polak-ribiere"`` (PR+): ``β = max(0, ⟨g_k, y⟩ / ‖g_{k−1}‖²)``;
    * ``"hestenes-stiefel"`` (HS+): ``β = max(0, ⟨g_k, y⟩ / ⟨T(d_{k−1}), y⟩)``;
    * ``"hager-zhang"`` (default): ``β = ⟨y − 2 T(d) ‖y‖²/⟨T(d), y⟩, g_k⟩ / ⟨T(d), y⟩``,
      bounded below by ``−1/(‖d‖ min(0.01, ‖g_{k−1}‖))``. With the Armijo search it
      took 2–3× fewer iterations than PR+ on Rayleigh (S⁹⁹⁹) and Brockett (St(200, 5)).

    The direction restarts at ``−g_k`` when it is not a descent direction,
    every ``restart_every`` iterations (default: the manifold's dimension) and,
    if ``orthogonality`` is set, when successive gradients lose orthogonality,
    ``|⟨g_k, g̃⟩| ≥ orthogonality·‖g_k‖²`` (Powell's test; off by default, as in
    Manopt: with an inexact line search it restarts too often — on a Brockett
    cost it tripled the iteration count).
    """

    def __init__(
        self,
        *,
        beta: str = "hager-zhang",
        restart_every: int | None = None,
        orthogonality: float = math.inf,
        sufficient_decrease: float = 1e-4,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        **stopping: Any,
    ) -> None:
        super().__init__(**stopping)
        if beta not in BETA_RULES:
            raise ValueError(f"ConjugateGradient: beta must be one of {BETA_RULES}, got {beta!r}")
        self.beta, self.restart_every, self.orthogonality = beta, restart_every, orthogonality
        self.line_search = Backtracking(sufficient_decrease, contraction, max_backtracks)

    def _beta(self, run: Run, x: Any, g: Any, g_norm: float, g_old: Any, g_old_norm: float, d_old: Any) -> float:
        y = g - g_old
        if self.beta == "fletcher-reeves":
            return g_norm**2 / g_old_norm**2
        if self.beta == "polak-ribiere":
            return max(0.0, run.inner(x, g, y) / g_old_norm**2)
        dy = run.inner(x, d_old, y)
        if dy == 0.0:
            return 0.0
        if self.beta == "hestenes-stiefel":
            return max(0.0, run.inner(x, g, y) / dy)
        beta = (run.inner(x, y, g) - 2.0 * run.inner(x, y, y) * run.inner(x, d_old, g) / dy) / dy
        eta = -1.0 / (run.norm(x, d_old) * min(0.01, g_old_norm))
        return max(beta, eta)

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m = run.manifold
        restart_every = self.restart_every or max(1, m.dim)
        x, f = x0, run.cost(x0)
        g = run.grad(x)
        g_norm = run.norm(x, g)
        d, slope = -g, -(g_norm**2)
        f_prev: float | None = None
        since_restart = 0
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            d_norm = run.norm(x, d)
            ls = self.line_search.search(run.cost, m, x, f, f_prev, d, d_norm, slope)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            x_new = ls.x
            g_new = run.grad(x_new)
            g_new_norm = run.norm(x_new, g_new)
            g_old = m.transp(x, x_new, g)
            d_old = m.transp(x, x_new, d)
            since_restart += 1
            restart = since_restart >= restart_every or (
                abs(run.inner(x_new, g_new, g_old)) >= self.orthogonality * g_new_norm**2
            )
            beta = 0.0 if restart else self._beta(run, x_new, g_new, g_new_norm, g_old, g_norm, d_old)
            d = -g_new + d_old * beta if beta else -g_new
            slope = run.inner(x_new, g_new, d)
            if not (slope < 0 and math.isfinite(slope)):  # not a descent direction
                d, slope, beta = -g_new, -(g_new_norm**2), 0.0
            since_restart = 0 if beta == 0.0 else since_restart
            f_prev, x, f, g, g_norm = f, x_new, ls.fun, g_new, g_new_norm
            stop = run.record(x, f, g_norm, ls.step, beta=beta)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
        return run.result(x, status)
