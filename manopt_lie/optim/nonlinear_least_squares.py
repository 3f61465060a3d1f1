"""Gauss-Newton and Levenberg-Marquardt: one nonlinear-least-squares loop, its step rules
(Powell's dogleg, the third, is in :mod:`.dogleg`).

Each iteration linearizes at ``x`` (gradient ``g = JᵀWr``, ``H = JᵀWJ`` with a
fixed sparsity pattern), computes a tangent step ``δ`` from the normal
equations with a pluggable :class:`~manopt_lie.linalg.LinearSolver` — by
default a sparse Cholesky solve whose symbolic analysis is done once per run,
or preconditioned conjugate gradients (``linear_solver="pcg"``) — and moves to
``R_x(δ)``. A singular system (an unfixed gauge, a variable no factor touches)
makes Gauss-Newton raise :class:`~manopt_lie.linalg.SingularSystemError` rather
than take a garbage step; Levenberg-Marquardt damps it (a failure: more damping),
the dogleg falls back on the Cauchy step.

A trial point whose cost is not finite is rejected (Gauss-Newton backtracks,
Levenberg-Marquardt raises its damping, the dogleg shrinks its radius); so is,
for those two, an accepted point whose linearization is not finite, where
Gauss-Newton stops with ``Status.NON_FINITE``. When the step collapses — a step
shorter than ``min_step``, Gauss-Newton's failed line search, a failure at
``max_damping``, the dogleg's radius below ``min_step`` — the run has converged
(``Status.STEP_SIZE``) only if the Gauss-Newton model at the point predicts no
decrease above round-off, ``ROUNDOFF·max(s, |f|)``; otherwise it ends with
``Status.NO_PROGRESS`` (the failed line search keeps
``Status.LINE_SEARCH_FAILED``).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..linalg import LinearSolver, SingularSystemError, get_linear_solver
from . import _small_system
from .least_squares_problem import LeastSquaresProblem, Linearization
from .line_search import armijo
from .optimizer import Optimizer, Run, StoppingCriteria
from .result import OptimizeResult, Status


@dataclass
class _Step:
    """One iteration's outcome. ``status`` ends the run (e.g. a failed line search);
    ``extra`` holds only numbers, for the history."""

    x: Any
    f: float
    step: float  # ‖δ‖, nan when rejected
    accepted: bool
    extra: dict[str, float]
    status: Status | None = None
    stalled: bool = False  # the step collapsed: converged if the model sees no decrease left, else ``status``
    predicted: float = math.nan  # the Gauss-Newton model's decrease at x, when known


@dataclass
class _Damping:
    lam: float
    nu: float
    accepted: bool = True  # the last trial was accepted: keep the next one's Jacobians


_DAMPINGS = ("identity", "diagonal")


def model_decrease(lin: Linearization, delta: Any) -> float:
    """``m(0) − m(δ) = −gᵀδ − ½δᵀHδ``: the decrease the Gauss-Newton model predicts for ``δ``."""
    flat, g = np.asarray(delta).reshape(-1), lin.grad.reshape(-1)
    return -float(g @ flat) - 0.5 * float(flat @ lin.hessian_product(flat))


def _no_descent(lin: Linearization) -> Status:
    """Why a step that is no descent direction ends the run: a stationary point
    (``g = 0`` exactly, so ``δ = 0``) or a failed linear solve."""
    return Status.STEP_SIZE if not lin.grad.any() else Status.LINEAR_SOLVER_FAILED


class NonlinearLeastSquares(Optimizer):
    """The shared loop; subclasses implement :meth:`_step`.

    A small pose graph — one SE(2)/SE(3) between factor with native kernels, at most
    :data:`~manopt_lie.optim._small_system.DENSE_UNKNOWNS` unknowns
    (:data:`~manopt_lie.optim._small_system.MAX_UNKNOWNS` where ``H`` is banded), the default
    linear solver (and for Levenberg-Marquardt the default damping), no callback, progress table
    or time limit — runs the iterations of :class:`GaussNewton`, :class:`LevenbergMarquardt` and
    :class:`~manopt_lie.optim.Dogleg` in compiled code (:mod:`._small_system`), with the same
    results up to round-off.

    Parameters
    ----------
    linear_solver : {"auto", "cholesky", "pcg"}, LinearSolver or None
        How the normal equations are solved: a name of
        :data:`~manopt_lie.linalg.LINEAR_SOLVERS`, or a
        :class:`~manopt_lie.linalg.LinearSolver` used as a template (e.g.
        ``PCGSolver(tol=1e-8)``); ``None`` is ``"auto"``: Cholesky, or PCG first where the
        factor would be nearly dense (:class:`~manopt_lie.linalg.AutoSolver`). Each run binds a
        fresh solver to the problem's structure, so ``solve`` is reentrant. An
        iterative solver's numbers (``linear_iterations``, ``linear_residual``,
        ``linear_converged``) go to the history's extras.
    stopping, **fields
        A :class:`~manopt_lie.optim.StoppingCriteria`, or its fields as keywords.
    """

    _compiled_as: ClassVar[int | None] = None
    """The code of the class's iterations in ``small_system.c`` (:mod:`._small_system`), set by the
    classes it mirrors, each for itself only (a subclass may change a step)."""

    def __init__(
        self,
        *,
        linear_solver: str | LinearSolver | None = None,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        self.linear_solver = get_linear_solver(linear_solver)

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        problem = run.problem
        if not isinstance(problem, LeastSquaresProblem):
            raise TypeError(f"{type(self).__name__} needs a LeastSquaresProblem, got {type(problem).__name__}")
        compiled = _small_system.solve(self, run, x0)  # a small pose graph's iterations in compiled code
        if compiled is not None:
            return compiled
        x = x0
        run.initial(x0)  # checks the factors' values and shapes at x0
        lin = problem.linearize(x0)  # the linearization validate made (remembered)
        assert problem.structure is not None  # built by the first linearization
        solver = self.linear_solver.bind(problem.structure)
        f_prev: float | None = None
        status = Status.CALLBACK if run.record(x, lin.cost, run.norm(x, lin.grad)) else run.stop_reason()
        state = self._initial_state(lin)
        while status is None:
            step = self._step(run, problem, solver, x, lin, state)
            if step.accepted:
                new = self._linearize(run, problem, step.x)
                if new.is_finite():
                    new.recycle(lin)  # the next H overwrites this one's: one H resident, not two
                    f_prev, x, lin = lin.cost, step.x, new
                else:
                    step = self._reject_nonfinite(step, state)
            else:  # a rejected trial's kept Jacobians: not held through the next factorization
                problem.discard_trial()
            if run.record(x, lin.cost, run.norm(x, lin.grad), step.step, **step.extra):
                status = Status.CALLBACK
                break
            status = step.status or run.stop_reason(f_prev if step.accepted else None)
            fallback = step.status if step.stalled else None
            if status is Status.STEP_SIZE and step.status is None:  # a short accepted step
                fallback = Status.NO_PROGRESS
            if fallback is not None:  # the step collapsed: converged only if nothing is left to gain
                predicted = step.predicted
                if math.isnan(predicted):
                    predicted = self._predicted_decrease(problem, solver, lin, run.scale)
                status = Status.STEP_SIZE if run.stall_status(predicted, lin.cost) is Status.STEP_SIZE else fallback
        return run.result(x, status)

    def _predicted_decrease(
        self, problem: LeastSquaresProblem, solver: LinearSolver, lin: Linearization, scale: float
    ) -> float:
        """``−gᵀδ − ½δᵀHδ`` for the Gauss-Newton step ``δ = −H⁻¹g`` at ``lin`` (``nan`` if
        the system cannot be solved): how much the Gauss-Newton model says is left to gain."""
        try:
            delta, _ = self._newton_system_step(solver, lin.hessian, lin.grad)
        except SingularSystemError:
            return math.nan
        return model_decrease(lin, delta)

    def _reject_nonfinite(self, step: _Step, state: Any) -> _Step:
        """An accepted point whose linearization is not finite: stop there (Gauss-Newton)."""
        return _Step(step.x, step.f, math.nan, False, step.extra, Status.NON_FINITE)

    @staticmethod
    def _linearize(run: Run, problem: LeastSquaresProblem, x: Any) -> Linearization:
        """The linearization at an accepted point (its cost not evaluated again if the
        trial kept its residuals: :meth:`_trial_cost`)."""
        run.nfev += not problem.kept_at(x)
        run.ngev += 1
        return problem.linearize(x)

    @staticmethod
    def _trial_cost(run: Run, problem: LeastSquaresProblem, x: Any, keep: bool) -> float:
        """The cost at a trial point; with ``keep`` its residuals and Jacobians are kept for
        the linearization if it is accepted (:meth:`LeastSquaresProblem.trial_cost`): worth
        it when acceptance is likely — after an accepted step — and the Jacobians' work
        wasted otherwise. A trial without ``keep`` drops what an earlier one kept."""
        if not keep:
            problem.discard_trial()
        return run.cost(x, problem.trial_cost if keep else None)

    @staticmethod
    def _newton_system_step(solver: LinearSolver, h: Any, g: Any) -> tuple[Any, dict[str, float]]:
        """``δ = −h⁻¹g`` and the solver's numbers about it."""
        delta = solver(h, -g.reshape(-1)).reshape(g.shape)
        return delta, dict(solver.stats)

    def _initial_state(self, lin: Linearization) -> Any:
        """Per-run state (e.g. the damping), kept out of the optimizer so ``solve`` is reentrant."""
        return None

    @abstractmethod
    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: LinearSolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        """One iteration from the linearization ``lin`` at ``x``."""


class GaussNewton(NonlinearLeastSquares):
    """``δ = −H⁻¹g`` with ``H = JᵀWJ``, then a backtracking Armijo search on ``R_x(α δ)``
    from ``α = 1`` (full Gauss-Newton steps near the solution).

    A direction that is not one of descent, ``gᵀδ ≥ 0``, is never taken: with an
    exact solve it arises only at ``g = 0`` (stop with ``Status.STEP_SIZE``);
    otherwise the linear solver failed (``Status.LINEAR_SOLVER_FAILED``). No
    decrease along ``δ`` stops the run: converged (``Status.STEP_SIZE``) if the
    model's decrease ``−gᵀδ − ½δᵀHδ`` is round-off, ``Status.LINE_SEARCH_FAILED``
    otherwise. Trial points whose cost is not finite are backtracked from; a new
    point whose linearization is not finite ends the run with ``Status.NON_FINITE``.
    ``history.extra["alpha"]`` is the accepted ``α``.

    Parameters
    ----------
    sufficient_decrease, max_backtracks
        The Armijo search's ``c₁`` and its number of backtracks before it fails.
    linear_solver, stopping, **fields
        See :class:`NonlinearLeastSquares`.
    """

    _compiled_as = _small_system.GAUSS_NEWTON

    def __init__(
        self,
        *,
        sufficient_decrease: float = 1e-4,
        max_backtracks: int = 30,
        linear_solver: str | LinearSolver | None = None,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(linear_solver=linear_solver, stopping=stopping, **fields)
        self.sufficient_decrease, self.max_backtracks = sufficient_decrease, max_backtracks

    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: LinearSolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        delta, extra = self._newton_system_step(solver, lin.hessian, lin.grad)
        slope = float(np.sum(lin.grad * delta))
        d_norm = float(np.linalg.norm(delta))
        if not slope < 0:
            return _Step(x, lin.cost, math.nan, False, {"alpha": 0.0, **extra}, _no_descent(lin))
        first = iter((True,))  # the full step's Jacobians are kept (usually accepted), no backtrack's

        def cost(point: Any) -> float:
            return self._trial_cost(run, problem, point, next(first, False))

        ls = armijo(
            cost, run.manifold, x, lin.cost, delta, d_norm, slope, 1.0,
            sufficient_decrease=self.sufficient_decrease, max_backtracks=self.max_backtracks,
        )  # fmt: skip
        if not ls.success:
            predicted = model_decrease(lin, delta)
            extra = {"alpha": 0.0, **extra}
            return _Step(x, lin.cost, math.nan, False, extra, Status.LINE_SEARCH_FAILED, True, predicted)
        return _Step(ls.x, ls.fun, ls.step, True, {"alpha": ls.alpha, **extra})


class LevenbergMarquardt(NonlinearLeastSquares):
    """``(H + λD) δ = −g``, accepted when the gain ratio
    ``ρ = (f(x) − f(R_x(δ))) / (−gᵀδ − ½δᵀHδ)`` is positive.

    The denominator is the decrease of the Gauss-Newton model; for an exact
    solve it equals ``½δᵀ(λDδ − g)``, and for an inexact one (PCG) it is still
    the model's, so a poor step is judged honestly. A step the model does not
    predict to decrease the cost is not taken (nor evaluated): it ends the run
    as for :class:`GaussNewton`.

    The damping matrix ``D`` is ``s·I`` (``damping="identity"``, the default, as
    GTSAM's) or Marquardt's ``diag(H)`` clipped to ``[1e-6·s, 1e32·s]``
    (``damping="diagonal"``, Ceres's bounds for ``s = 1``), ``s`` the cost scale
    of :class:`~manopt_lie.optim.StoppingCriteria`, so that ``λ`` is relative to
    the size of the cost. The update is GTSAM's with Nielsen's growth on repeated
    failures: on success ``λ ← max(λ/κ, 1e-15)``, ``ν ← κ`` (``κ = damping_factor``,
    10); on failure ``λ ← min(λν, max_damping)``, ``ν ← 2ν``; a failure at
    ``max_damping`` ends the run, converged (``Status.STEP_SIZE``) if the model
    with ``λ₀`` predicts only round-off, ``Status.NO_PROGRESS`` otherwise. A trial
    cost or a new linearization that is not finite, and a damped system the linear
    solver finds singular (:class:`~manopt_lie.linalg.SingularSystemError`), count
    as failures. The damping is added to the diagonal of ``H`` in place for the
    solve and removed after it (no copy of ``H``).

    Why these choices (``benchmarks/bench_pose_graph.py``): pose graphs' normal
    equations are ill-conditioned (condition 10⁸–10¹¹) with weak, long-wavelength
    directions whose curvature ``vᵀHv/vᵀv`` is small next to the diagonal. Any
    ``λ·diag(H)`` above the inverse condition number freezes them, and Nielsen's
    shrink by at most 3× per success then needed 1.7× GTSAM's iterations; ``λ·s·I``
    from ``λ₀ = 1e-8``, divided by 10 per success, starts as Gauss-Newton from a
    good initialization and needs at most GTSAM's iterations on every SE-Sync
    dataset, while a poor start raises ``λ`` tenfold per failure (random
    initializations take as many iterations as GTSAM's LM). ``history.extra``
    holds ``damping`` (the ``λ`` of the step) and ``rho``.

    Parameters
    ----------
    initial_damping, max_damping : float
        ``λ₀ > 0`` and the largest ``λ`` tried before the run stops.
    damping : {"identity", "diagonal"}
        ``D = s·I`` or ``D = diag(H)`` (clipped), see above.
    damping_factor : float
        ``κ > 1``: the division on success and the first multiplication on failure.
    linear_solver, stopping, **fields
        See :class:`NonlinearLeastSquares`.
    """

    _compiled_as = _small_system.LEVENBERG_MARQUARDT

    def __init__(
        self,
        *,
        initial_damping: float = 1e-8,
        max_damping: float = 1e32,
        damping: str = "identity",
        damping_factor: float = 10.0,
        linear_solver: str | LinearSolver | None = None,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(linear_solver=linear_solver, stopping=stopping, **fields)
        if not initial_damping > 0:
            raise ValueError(f"LevenbergMarquardt: initial_damping must be positive, got {initial_damping}")
        if not max_damping >= initial_damping:
            raise ValueError(f"LevenbergMarquardt: max_damping must be ≥ initial_damping, got {max_damping}")
        if damping not in _DAMPINGS:
            raise ValueError(f"LevenbergMarquardt: damping must be one of {', '.join(_DAMPINGS)}, got {damping!r}")
        if not damping_factor > 1:
            raise ValueError(f"LevenbergMarquardt: damping_factor must be > 1, got {damping_factor}")
        self.initial_damping, self.max_damping = initial_damping, max_damping
        self.damping, self.damping_factor = damping, damping_factor

    def _initial_state(self, lin: Linearization) -> _Damping:
        return _Damping(self.initial_damping, self.damping_factor)

    def _scaling(self, lin: Linearization, scale: float) -> Any:
        """``D``: the scalar ``s`` (``s·I``) or the clipped ``diag(H)``."""
        if self.damping == "identity":
            return scale
        return np.clip(lin.hessian.diagonal(), 1e-6 * scale, 1e32 * scale)

    def _damped_step(
        self, problem: LeastSquaresProblem, solver: LinearSolver, lin: Linearization, shift: Any
    ) -> tuple[Any, dict[str, float]]:
        """``δ = −(H + diag(shift))⁻¹g``, the shift added to ``H``'s diagonal in place and removed after."""
        assert problem.structure is not None
        with problem.structure.shifted_diagonal(lin.hessian, shift):
            return self._newton_system_step(solver, lin.hessian, lin.grad)

    def _step(
        self, run: Run, problem: LeastSquaresProblem, solver: LinearSolver, x: Any, lin: Linearization, state: Any
    ) -> _Step:
        extra: dict[str, float] = {"damping": state.lam}
        try:
            delta, stats = self._damped_step(problem, solver, lin, state.lam * self._scaling(lin, run.scale))
        except SingularSystemError:  # too little damping for a (nearly) singular H: more
            return self._fail(_Step(x, lin.cost, math.nan, False, {**extra, "rho": math.nan}), state)
        extra.update(stats)
        predicted = model_decrease(lin, delta)
        if not predicted > 0:  # (H + λD) is SPD, so an exact solve always predicts a decrease unless g = 0
            return _Step(x, lin.cost, math.nan, False, {**extra, "rho": math.nan}, _no_descent(lin))
        x_new = run.manifold.retr(x, delta)
        f_new = self._trial_cost(run, problem, x_new, state.accepted)
        rho = (lin.cost - f_new) / predicted
        extra["rho"] = rho
        state.accepted = rho > 0
        if rho > 0:
            # Floored: after many successes λ would underflow to 0, and 0·ν = 0 on a failure.
            state.lam = max(state.lam / self.damping_factor, 1e-15)
            state.nu = self.damping_factor
            return _Step(x_new, f_new, float(np.linalg.norm(delta)), True, extra)
        return self._fail(_Step(x, lin.cost, math.nan, False, extra), state)

    def _fail(self, step: _Step, state: _Damping) -> _Step:
        """A rejected step: ``λ ← min(λν, max_damping)``, ``ν ← 2ν``; a failure at
        ``max_damping`` means no step of any size decreases the cost, and the run stops
        (a collapse, judged by the model with ``λ₀``)."""
        if state.lam >= self.max_damping:
            return _Step(step.x, step.f, math.nan, False, step.extra, Status.NO_PROGRESS, True)
        state.lam = min(state.lam * state.nu, self.max_damping)
        state.nu *= 2.0
        return _Step(step.x, step.f, math.nan, False, step.extra)

    def _reject_nonfinite(self, step: _Step, state: Any) -> _Step:
        """An accepted point whose linearization is not finite: rejected, the damping raised.

        ``step.x`` is the rejected point; the returned step stays where the run is,
        which the loop keeps (it only moves on accepted steps)."""
        return self._fail(_Step(step.x, step.f, math.nan, False, step.extra), state)

    def _predicted_decrease(
        self, problem: LeastSquaresProblem, solver: LinearSolver, lin: Linearization, scale: float
    ) -> float:
        """The decrease of the Gauss-Newton model for the step with ``λ₀`` (``H`` may be singular)."""
        try:
            delta, _ = self._damped_step(problem, solver, lin, self.initial_damping * self._scaling(lin, scale))
        except SingularSystemError:
            return math.nan
        return model_decrease(lin, delta)
