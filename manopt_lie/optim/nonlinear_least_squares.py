"""Gauss-Newton and Levenberg-Marquardt: one nonlinear-least-squares loop, two step rules.

Each iteration linearizes at ``x`` (gradient ``g = JᵀWr``, ``H = JᵀWJ`` with a
fixed sparsity pattern), computes a tangent step ``δ`` from a sparse
Cholesky solve whose symbolic analysis is done once, and moves to
``R_x(δ)``. A singular system (an unfixed gauge, a variable no factor touches)
raises :class:`~manopt_lie.linalg.SingularSystemError` rather than taking a
garbage step.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..linalg import CholeskySolver
from .least_squares_problem import LeastSquaresProblem, Linearization
from .line_search import armijo
from .optimizer import Optimizer, Run
from .result import OptimizeResult, Status


@dataclass
class _Step:
    x: Any
    f: float
    step: float  # ‖δ‖, nan when rejected
    accepted: bool
    extra: dict[str, float]


@dataclass
class _Damping:
    lam: float
    nu: float = 2.0


class NonlinearLeastSquares(Optimizer):
    """The shared loop; subclasses implement :meth:`_step`."""

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        problem = run.problem
        if not isinstance(problem, LeastSquaresProblem):
            raise TypeError(f"{type(self).__name__} needs a LeastSquaresProblem, got {type(problem).__name__}")
        solver = CholeskySolver()
        x = x0
        lin = self._linearize(run, problem, x)
        f_prev: float | None = None
        status = Status.CALLBACK if run.record(x, lin.cost, self._norm(lin)) else run.stop_reason()
        state = self._initial_state(lin)
        while status is None:
            step = self._step(run, problem, solver, x, lin, state)
            if step.accepted:
                f_prev, x = lin.cost, step.x
                lin = self._linearize(run, problem, x)
            stop = run.record(x, lin.cost, self._norm(lin), step.step, **step.extra)
            status = Status.CALLBACK if stop else self._stop_reason(run, f_prev if step.accepted else None, step, state)
        return run.result(x, status)

    @staticmethod
    def _linearize(run: Run, problem: LeastSquaresProblem, x: Any) -> Linearization:
        run.nfev += 1
        run.ngev += 1
        return problem.linearize(x)

    @staticmethod
    def _norm(lin: Linearization) -> float:
        return float(np.linalg.norm(lin.grad))

    @staticmethod
    def _newton_system_step(solver: CholeskySolver, h: Any, g: Any) -> Any:
        return solver(h, -g.reshape(-1)).reshape(g.shape)

    def _initial_state(self, lin: Linearization) -> Any:
        """Per-run state (e.g. the damping), kept out of the optimizer so ``solve`` is reentrant."""
        return None

    def _stop_reason(self, run: Run, f_prev: float | None, step: _Step, state: Any) -> Status | None:
        return run.stop_reason(f_prev)

    @abstractmethod
    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: CholeskySolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        """One iteration from the linearization ``lin`` at ``x``."""


class GaussNewton(NonlinearLeastSquares):
    """``δ = −H⁻¹g`` with ``H = JᵀWJ``, then a backtracking Armijo search on ``R_x(α δ)``
    from ``α = 1`` (full Gauss-Newton steps near the solution)."""

    def __init__(self, *, sufficient_decrease: float = 1e-4, max_backtracks: int = 30, **stopping: Any) -> None:
        super().__init__(**stopping)
        self.sufficient_decrease, self.max_backtracks = sufficient_decrease, max_backtracks

    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: CholeskySolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        delta = self._newton_system_step(solver, lin.hessian, lin.grad)
        slope = float(np.sum(lin.grad * delta))
        d_norm = float(np.linalg.norm(delta))
        if not slope < 0:  # only when g = 0 to round-off
            return _Step(x, lin.cost, 0.0, False, {"alpha": 0.0})
        ls = armijo(
            run.cost, run.manifold, x, lin.cost, delta, d_norm, slope, 1.0,
            sufficient_decrease=self.sufficient_decrease, max_backtracks=self.max_backtracks,
        )  # fmt: skip
        if not ls.success:
            return _Step(x, lin.cost, math.nan, False, {"alpha": 0.0, "failed": 1.0})
        return _Step(ls.x, ls.fun, ls.step, True, {"alpha": ls.alpha})

    def _stop_reason(self, run: Run, f_prev: float | None, step: _Step, state: Any) -> Status | None:
        if step.extra.get("failed"):
            return Status.LINE_SEARCH_FAILED
        if not step.accepted:
            return Status.STEP_SIZE
        return run.stop_reason(f_prev)


class LevenbergMarquardt(NonlinearLeastSquares):
    """``(H + λD) δ = −g`` with Marquardt's scaling ``D = diag(H)`` (clipped to
    ``[1e-6, 1e32]`` as Ceres does), accepted when the gain ratio
    ``ρ = (f(x) − f(R_x(δ))) / (½ δᵀ(λDδ − g))`` is positive.

    Nielsen's damping update: on success ``λ ← λ·max(⅓, 1 − (2ρ − 1)³)``,
    ``ν ← 2`` (``λ`` at least 1e-15); on failure ``λ ← λν``, ``ν ← 2ν``. Since ``D`` carries the scale
    of ``H``, ``λ`` is dimensionless and starts at ``initial_damping``, by default
    1e-6. Pose graphs' normal equations are ill-conditioned (condition 10⁸–10¹¹):
    there Ceres's ``10⁻⁴`` freezes the weak directions for several iterations and
    needed 2-3x the iterations of ``10⁻⁶`` (``benchmarks/bench_pose_graph.py``);
    ``λ`` grows quickly when the model is poor.
    """

    def __init__(self, *, initial_damping: float = 1e-6, max_damping: float = 1e32, **stopping: Any) -> None:
        super().__init__(**stopping)
        if not initial_damping > 0:
            raise ValueError(f"LevenbergMarquardt: initial_damping must be positive, got {initial_damping}")
        self.initial_damping, self.max_damping = initial_damping, max_damping

    def _initial_state(self, lin: Linearization) -> _Damping:
        return _Damping(self.initial_damping)

    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: CholeskySolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        assert problem.structure is not None
        scaling = np.clip(lin.hessian.diagonal(), 1e-6, 1e32)
        damped = problem.structure.add_diagonal(lin.hessian, state.lam * scaling)
        delta = self._newton_system_step(solver, damped, lin.grad)
        flat = delta.reshape(-1)
        predicted = 0.5 * float(flat @ (state.lam * scaling * flat - lin.grad.reshape(-1)))
        x_new = run.manifold.retr(x, delta)
        f_new = run.cost(x_new)
        rho = (lin.cost - f_new) / predicted if predicted > 0 else -math.inf
        extra = {"damping": state.lam, "rho": rho}
        if rho > 0:
            # Floored: after hundreds of successes λ would underflow to 0, and 0·ν = nan on a failure.
            state.lam = max(state.lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-15)
            state.nu = 2.0
            return _Step(x_new, f_new, float(np.linalg.norm(flat)), True, extra)
        state.lam *= state.nu
        state.nu *= 2.0
        return _Step(x, lin.cost, math.nan, False, extra)

    def _stop_reason(self, run: Run, f_prev: float | None, step: _Step, state: Any) -> Status | None:
        if state.lam > self.max_damping:
            return Status.STEP_SIZE  # no step of any size decreases the cost
        return run.stop_reason(f_prev)
