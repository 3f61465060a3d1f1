"""Riemannian limited-memory BFGS (Huang, Gallivan, Absil 2015; Huang, Absil, Gallivan 2018)."""

from __future__ import annotations

import math
from collections import deque
from typing import Any, NamedTuple

from .line_search import Backtracking, LineSearch, StrongWolfe, probe_decrease, select_line_search
from .optimizer import Optimizer, Run, StoppingCriteria
from .result import OptimizeResult, Status


class _Pair(NamedTuple):
    """A curvature pair at the current point: the transported step ``s``, the gradient change
    ``y`` and ``ρ = 1/⟨s, y⟩`` (measured when the pair was made)."""

    s: Any
    y: Any
    rho: float


class LBFGS(Optimizer):
    """``x_{k+1} = R_{x_k}(α_k d_k)`` with the quasi-Newton direction ``d_k = −H_k g_k`` and ``α_k``
    from a line search whose first trial is ``α = 1``.

    ``H_k`` is the inverse-Hessian approximation of limited-memory BFGS built from the last
    ``memory`` curvature pairs, kept in the current tangent space by the vector transport
    ``T`` (Huang, Gallivan, Absil 2015, Alg. 2; Absil, Mahony, Sepulchre §8.1): after a step
    ``η_k = α_k d_k`` to ``x_{k+1}``,

        s_k = T(η_k),    y_k = g_{k+1} − T(g_k),    ρ_k = 1/⟨s_k, y_k⟩,

    and every stored pair is transported along. ``H_k g`` is the two-loop recursion
    (Nocedal–Wright Alg. 7.4): with ``q = g``, for ``i = k−1, …, k−m``
    ``a_i = ρ_i⟨s_i, q⟩``, ``q ← q − a_i y_i``; then ``r = γ_k q`` with
    ``γ_k = ⟨s_{k−1}, y_{k−1}⟩/‖y_{k−1}‖²``; for ``i = k−m, …, k−1``
    ``b = ρ_i⟨y_i, r⟩``, ``r ← r + (a_i − b) s_i``; ``H_k g = r``. At the start (no pair yet)
    ``H_0 = I/‖g_0‖``: the first trial is a step of unit length, as for the other methods.

    *Cautious update* (Huang, Absil, Gallivan 2018, eq. 2.4; Li and Fukushima 2001): a pair is
    stored only if ``⟨s_k, y_k⟩ ≥ cautious·‖g_k‖·‖s_k‖²``. On a Lie group (transport the
    identity, exact for the slope along the retraction) the strong Wolfe conditions already
    give ``⟨s, y⟩ > 0``; on embedded manifolds, whose transport (projection) is not an
    isometry, the test keeps ``H`` positive definite with curvature bounded below, which is
    what the convergence proof for nonconvex costs needs. Every ``ρ_i > 0``, so ``d_k`` is a
    descent direction; should round-off make ``⟨g_k, d_k⟩ ≥ 0`` anyway, the memory is cleared
    and ``d_k = −γ_k g_k``. A line search that fails along ``d_k`` is retried once along
    ``−γ_k g_k`` with the memory cleared before the run ends with
    ``Status.LINE_SEARCH_FAILED``.

    Non-finite costs at trial points, non-finite gradients and short steps are handled as in
    :class:`~manopt_lie.optim.GradientDescent` (a collapsed step is convergence only if a fresh
    Armijo search along ``−g`` finds no decrease above round-off).

    Parameters
    ----------
    memory : int
        ``m``, the pairs kept (SciPy's L-BFGS-B: 10; Manopt's ``rlbfgs``: 30). Each costs two
        vector transports per iteration on an embedded manifold, none on a Lie group.
    line_search : {"wolfe", "armijo"} or LineSearch
        ``"wolfe"`` (default): :class:`~manopt_lie.optim.line_search.StrongWolfe` with
        ``c₂ = curvature`` from ``α = 1`` (``initial="newton"``; the gradient it evaluates at
        the accepted point, and the transported direction, are reused). ``"armijo"``:
        :class:`~manopt_lie.optim.line_search.Backtracking` from ``α = 1``, which needs the
        cautious test to keep ``H`` positive definite. An instance is used as given (its first
        trial should be ``α = 1``).
    sufficient_decrease : float
        ``c₁`` (both searches).
    curvature : float
        ``c₂`` of the strong Wolfe search (0.9, the usual value for quasi-Newton methods).
    contraction, max_backtracks
        The Armijo search's settings.
    cautious : float
        The constant of the cautious update test (Manopt's ``θ(t) = 10⁻⁴t``); 0 stores every
        pair with ``⟨s, y⟩ > 0``.
    stopping, **fields
        A :class:`~manopt_lie.optim.StoppingCriteria`, or its fields as keywords.

    Notes
    -----
    ``history.extra`` holds ``evaluations`` (cost evaluations of each line search) and
    ``memory`` (pairs stored after the iteration).
    """

    def __init__(
        self,
        *,
        memory: int = 10,
        line_search: str | LineSearch = "wolfe",
        sufficient_decrease: float = 1e-4,
        curvature: float = 0.9,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        cautious: float = 1e-4,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        if isinstance(memory, bool) or not isinstance(memory, int) or memory < 1:
            raise ValueError(f"LBFGS: memory must be a positive integer, got {memory!r}")
        if not cautious >= 0:
            raise ValueError(f"LBFGS: cautious must be non-negative, got {cautious!r}")
        self.memory, self.cautious = memory, float(cautious)
        self.line_search = select_line_search(
            line_search,
            lambda: Backtracking(sufficient_decrease, contraction, max_backtracks, initial="newton"),
            lambda: StrongWolfe(sufficient_decrease, curvature, initial="newton"),
            "LBFGS",
        )

    @staticmethod
    def _two_loop(run: Run, x: Any, g: Any, pairs: deque[_Pair], gamma: float) -> Any:
        """``H g`` by the two-loop recursion over ``pairs`` (oldest first), ``H₀ = γI``."""
        inner = run.manifold.total_inner
        q, coefficients = g, []
        for s, y, rho in reversed(pairs):
            a = rho * inner(x, s, q)
            q = q - y * a
            coefficients.append(a)
        r = q * gamma
        for (s, y, rho), a in zip(pairs, reversed(coefficients), strict=True):
            r = r + s * (a - rho * inner(x, y, r))
        return r

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m, search = run.manifold, self.line_search.search
        x = x0
        f, g, g_norm = run.initial(x0)
        pairs: deque[_Pair] = deque(maxlen=self.memory)
        gamma = 1.0 / g_norm if 0 < g_norm < math.inf else 1.0  # H₀: a first step of unit length
        f_prev: float | None = None
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            d = -self._two_loop(run, x, g, pairs, gamma) if pairs else g * -gamma
            slope = run.inner(x, g, d)
            if pairs and not (slope < 0 and math.isfinite(slope)):  # round-off: restart along −g
                pairs.clear()
                d, slope = g * -gamma, -gamma * g_norm * g_norm
            d_norm = run.norm(x, d)
            ls = search(run.cost, run.grad, m, x, f, d, d_norm, slope, f_prev=f_prev)
            if not ls.success and pairs:  # the memory misled the search: once more along −g
                pairs.clear()
                d, slope = g * -gamma, -gamma * g_norm * g_norm
                d_norm = run.norm(x, d)
                ls = search(run.cost, run.grad, m, x, f, d, d_norm, slope, f_prev=f_prev)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            x_new = ls.x
            g_new = run.grad(x_new) if ls.grad is None else ls.grad
            g_new_norm = run.norm(x_new, g_new)
            if not math.isfinite(g_new_norm):
                status = Status.NON_FINITE
                break
            td = m.transp(x, x_new, d) if ls.transported is None else ls.transported
            s = td * ls.alpha
            y = g_new - m.transp(x, x_new, g)
            pairs = deque((_Pair(m.transp(x, x_new, p.s), m.transp(x, x_new, p.y), p.rho) for p in pairs), self.memory)
            sy = run.inner(x_new, s, y)
            s_norm = run.norm(x_new, s)
            if sy > 0 and sy >= self.cautious * g_norm * s_norm * s_norm and math.isfinite(sy):
                y_norm = run.norm(x_new, y)
                gamma_new = sy / y_norm / y_norm  # ⟨s, y⟩/‖y‖² without squaring a tiny ‖y‖
                if 0 < gamma_new < math.inf:
                    pairs.append(_Pair(s, y, 1.0 / sy))
                    gamma = gamma_new
            f_prev, x, f, g, g_norm = f, x_new, ls.fun, g_new, g_new_norm
            stop = run.record(x, f, g_norm, ls.step, evaluations=ls.nfev, memory=len(pairs))
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
            if status is Status.STEP_SIZE:  # converged only if nothing is left to gain along −g
                status = run.stall_status(probe_decrease(run.cost, m, x, f, g, g_norm), f)
        return run.result(x, status)
