"""Riemannian nonlinear conjugate gradients (Absil, Mahony, Sepulchre §8.3; Sato 2021)."""

from __future__ import annotations

import math
from typing import Any

from .line_search import Backtracking, LineSearch, StrongWolfe, probe_decrease, select_line_search
from .optimizer import Optimizer, Run, StoppingCriteria
from .result import OptimizeResult, Status

BETA_RULES = ("fletcher-reeves", "polak-ribiere", "hestenes-stiefel", "hager-zhang")


class ConjugateGradient(Optimizer):
    """``d_k = −g_k + β_k T(d_{k−1})``, ``x_{k+1} = R_{x_k}(α_k d_k)``, ``α_k`` from a line search.

    With ``T`` the vector transport to ``x_k``, ``g̃ = T(g_{k−1})`` and
    ``y = g_k − g̃``:

    * ``"fletcher-reeves"``: ``β = ‖g_k‖² / ‖g_{k−1}‖²``;
    * ``"polak-ribiere"`` (PR+): ``β = max(0, ⟨g_k, y⟩ / ‖g_{k−1}‖²)``;
    * ``"hestenes-stiefel"`` (HS+): ``β = max(0, ⟨g_k, y⟩ / ⟨T(d_{k−1}), y⟩)``;
    * ``"hager-zhang"`` (default): ``β = ⟨y − 2 T(d) ‖y‖²/⟨T(d), y⟩, g_k⟩ / ⟨T(d), y⟩``,
      bounded below by ``−1/(‖d‖ min(0.01, ‖g_{k−1}‖))``.

    The direction restarts at ``−g_k`` when it is not a descent direction,
    every ``restart_every`` iterations (default: the manifold's dimension) and,
    if ``orthogonality`` is set, when successive gradients lose orthogonality,
    ``|⟨g_k, g̃⟩| ≥ orthogonality·‖g_k‖²`` (Powell's test; off by default, as in
    Manopt: with an inexact line search it restarts too often — on a Brockett
    cost it tripled the iteration count).

    Non-finite costs at trial points, non-finite gradients and short steps are
    handled as in :class:`~manopt_lie.optim.GradientDescent`.

    Parameters
    ----------
    beta : str
        One of the rules above.
    restart_every : int, optional
        Periodic restart; the manifold's dimension by default.
    orthogonality : float
        Powell's restart threshold (``inf``: off).
    line_search : {"wolfe", "armijo"} or LineSearch
        ``"wolfe"`` (default): :class:`~manopt_lie.optim.line_search.StrongWolfe` with
        ``c₂ = curvature``, first trial the previous ``α`` refined by one quadratic
        interpolation unless within 5% (``initial="previous", refine_tol=0.05``); the
        gradient it evaluates at the accepted point is reused. ``"armijo"``:
        :class:`~manopt_lie.optim.line_search.Backtracking` from Manopt's doubled adaptive
        trial ``2·2(f_{k−1} − f_k)/|⟨g_k, d_k⟩|``. An instance is used as given.
    sufficient_decrease : float
        ``c₁`` (both searches).
    contraction, max_backtracks
        The Armijo search's settings.
    curvature : float
        ``c₂`` of the strong Wolfe search (0.1: a nearly exact step keeps the directions
        conjugate).
    stopping, **fields
        A :class:`~manopt_lie.optim.StoppingCriteria`, or its fields as keywords.
    """

    def __init__(
        self,
        *,
        beta: str = "hager-zhang",
        restart_every: int | None = None,
        orthogonality: float = math.inf,
        line_search: str | LineSearch = "wolfe",
        sufficient_decrease: float = 1e-4,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        curvature: float = 0.1,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        if beta not in BETA_RULES:
            raise ValueError(f"ConjugateGradient: beta must be one of {BETA_RULES}, got {beta!r}")
        self.beta, self.restart_every, self.orthogonality = beta, restart_every, orthogonality
        self.line_search = select_line_search(
            line_search,
            lambda: Backtracking(sufficient_decrease, contraction, max_backtracks, optimism=2.0),
            lambda: StrongWolfe(sufficient_decrease, curvature, initial="previous", refine_tol=0.05),
            "ConjugateGradient",
        )

    def _beta(self, run: Run, x: Any, g: Any, g_norm: float, g_old: Any, g_old_norm: float, d_old: Any) -> float:
        if self.beta == "fletcher-reeves":
            ratio = g_norm / g_old_norm
            return ratio * ratio
        y = g - g_old
        if self.beta == "polak-ribiere":
            return max(0.0, run.inner(x, g, y) / g_old_norm / g_old_norm)
        dy = run.inner(x, d_old, y)
        if dy == 0.0:
            return 0.0
        if self.beta == "hestenes-stiefel":
            return max(0.0, run.inner(x, g, y) / dy)
        beta = (run.inner(x, y, g) - 2.0 * run.inner(x, y, y) * run.inner(x, d_old, g) / dy) / dy
        eta = -1.0 / (run.norm(x, d_old) * min(0.01, g_old_norm))
        return max(beta, eta)

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m, search = run.manifold, self.line_search.search
        restart_every = self.restart_every or max(1, m.dim)
        powell = math.isfinite(self.orthogonality)
        need_g_old = powell or self.beta != "fletcher-reeves"
        x = x0
        f, g, g_norm = run.initial(x0)
        d, d_norm, slope = -g, g_norm, -(g_norm * g_norm)
        f_prev: float | None = None
        alpha: float | None = None
        since_restart = 0
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            ls = search(run.cost, run.grad, m, x, f, d, d_norm, slope, f_prev=f_prev, alpha_prev=alpha)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            x_new = ls.x
            g_new = run.grad(x_new) if ls.grad is None else ls.grad
            g_new_norm = run.norm(x_new, g_new)
            if not math.isfinite(g_new_norm):
                status = Status.NON_FINITE
                break
            g_old = m.transp(x, x_new, g) if need_g_old else None
            since_restart += 1
            restart = since_restart >= restart_every or (
                powell and abs(run.inner(x_new, g_new, g_old)) >= self.orthogonality * g_new_norm * g_new_norm
            )
            beta = 0.0
            if not restart:
                d_old = m.transp(x, x_new, d) if ls.transported is None else ls.transported  # Wolfe made it
                beta = self._beta(run, x_new, g_new, g_new_norm, g_old, g_norm, d_old)
                d = -g_new + d_old * beta
                slope = run.inner(x_new, g_new, d)
                if not (slope < 0 and math.isfinite(slope)):  # not a descent direction
                    beta = 0.0
            if beta == 0.0:
                d, d_norm, slope = -g_new, g_new_norm, -(g_new_norm * g_new_norm)
            else:
                d_norm = run.norm(x_new, d)
            since_restart = 0 if beta == 0.0 else since_restart
            f_prev, x, f, g, g_norm, alpha = f, x_new, ls.fun, g_new, g_new_norm, ls.alpha
            stop = run.record(x, f, g_norm, ls.step, beta=beta, evaluations=ls.nfev)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
            if status is Status.STEP_SIZE:  # converged only if nothing is left to gain along −g
                status = run.stall_status(probe_decrease(run.cost, m, x, f, g, g_norm), f)
        return run.result(x, status)
