"""Run a suite of catalogue instances × optimizers (ours, optional peers, the IPOPT
reference) and collect one :class:`~benchmarks.record.Run` per combination.

Every run on an instance starts from the same chordal initialization (timed once,
``init_time``) and every final cost is evaluated with CONVENTIONS §8, so rows are
comparable across libraries. Our optimizers share the stopping rule of
:class:`Settings`; times are medians over ``repeat`` solves, each on a freshly built
problem (so the sparse symbolic analysis is part of the time).
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from manopt_lie.optim import (
    ConjugateGradient,
    GaussNewton,
    GradientDescent,
    LevenbergMarquardt,
    OptimizeResult,
    TrustRegion,
)
from manopt_lie.optim.optimizer import Optimizer
from manopt_lie.problems.catalogue import Entry, Loaded
from manopt_lie.problems.pose_graph import PoseGraph

from . import peers as peer_adapters
from .record import Run

OPTIMIZERS: dict[str, tuple[type[Optimizer], str]] = {
    "gd": (GradientDescent, "Riemannian gradient descent, Armijo backtracking"),
    "cg": (ConjugateGradient, "Riemannian nonlinear CG (Hager-Zhang), strong Wolfe"),
    "gn": (GaussNewton, "Gauss-Newton with line search, sparse Cholesky"),
    "lm": (LevenbergMarquardt, "Levenberg-Marquardt, Nielsen damping, sparse Cholesky"),
    "tr": (TrustRegion, "Riemannian trust region, truncated CG"),
}
REFERENCE = "ipopt"


@dataclass(frozen=True)
class Settings:
    """The stopping rule and budget shared by all runs (peers get the equivalents
    they have: iteration cap, relative cost decrease or gradient tolerance)."""

    max_iterations: int = 1000
    max_time: float = 60.0
    grad_rtol: float = 1e-6
    rel_cost_decrease: float = 0.0
    repeat: int = 1

    def __post_init__(self) -> None:
        if self.max_iterations < 1 or self.repeat < 1:
            raise ValueError("max_iterations and repeat must be at least 1")
        if not (self.max_time > 0 and 0 < self.grad_rtol < 1 and 0 <= self.rel_cost_decrease < 1):
            raise ValueError("need max_time > 0, 0 < grad_rtol < 1 and 0 ≤ rel_cost_decrease < 1")

    def optimizer(self, name: str) -> Optimizer:
        """Our optimizer ``name`` (a key of :data:`OPTIMIZERS`) with these settings."""
        if name not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {tuple(OPTIMIZERS)}, got {name!r}")
        return OPTIMIZERS[name][0](
            max_iterations=self.max_iterations, max_time=self.max_time, grad_rtol=self.grad_rtol,
            rel_cost_decrease=self.rel_cost_decrease,
        )  # fmt: skip


@dataclass(frozen=True)
class Task:
    """One planned run."""

    entry: Entry
    cost: str
    solver: str  # an optimizer, a peer, or "ipopt"

    @property
    def label(self) -> str:
        return f"{self.entry.name} · {self.cost} · {self.solver}"


@dataclass
class SuiteResult:
    """The runs, and the points behind them (for trajectory plots and g2o output)."""

    runs: list[Run] = field(default_factory=list)
    loaded: dict[str, Loaded] = field(default_factory=dict)
    initial: dict[str, Any] = field(default_factory=dict)
    init_time: dict[str, float] = field(default_factory=dict)
    solutions: dict[tuple[str, str, str], Any] = field(default_factory=dict)


def plan(
    entries: Sequence[Entry], optimizers: Sequence[str], *, peers: Sequence[str] = (), reference: bool = False
) -> list[Task]:
    """The runs of a suite, in order; peers only where they apply (GTSAM: geodesic pose
    graphs; pymanopt: chordal rotation averaging)."""
    for name in optimizers:
        if name not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {name!r}; choose from {', '.join(OPTIMIZERS)}")
    for name in peers:
        if name not in peer_adapters.PEERS:
            raise ValueError(f"unknown peer {name!r}; choose from {', '.join(peer_adapters.PEERS)}")
    tasks = []
    for entry in entries:
        for cost in entry.costs:
            solvers = [*optimizers, *(p for p in peers if peer_adapters.applies(p, entry.problem, cost))]
            tasks += [Task(entry, cost, s) for s in solvers + ([REFERENCE] if reference else [])]
    return tasks


def initialize(loaded: Loaded) -> tuple[float, Any]:
    """The chordal initialization and its time."""
    start = time.perf_counter()
    x0 = loaded.spec.chordal_initialization()
    return time.perf_counter() - start, x0


def _status(result: OptimizeResult) -> str:
    return result.status.name.lower().replace("_", " ")


def _ours(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    times, result = [], None
    for _ in range(settings.repeat):
        problem = loaded.spec.problem(task.cost)
        start = time.perf_counter()
        result = settings.optimizer(task.solver).solve(problem, x0)
        times.append(time.perf_counter() - start)
    assert result is not None
    run = _record(task, loaded, statistics.median(times), result.nit, result.fun, _status(result))
    run.converged, run.grad_norm = result.status.converged, result.grad_norm
    run.history_cost, run.history_time = result.history.cost.tolist(), result.history.time.tolist()
    return run, result.x


def _peer(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    times, out = [], None
    for _ in range(settings.repeat):
        out = peer_adapters.solve(
            task.solver, loaded.spec, x0, max_iterations=settings.max_iterations, max_time=settings.max_time,
            grad_rtol=settings.grad_rtol, rel_cost_decrease=settings.rel_cost_decrease or 1e-5,
        )  # fmt: skip
        times.append(out.time)
    assert out is not None
    run = _record(task, loaded, statistics.median(times), out.nit, loaded.spec.cost(out.x, task.cost), out.status)
    run.converged = out.converged
    run.history_cost, run.history_time = list(out.history_cost), list(out.history_time)
    return run, out.x


def _reference(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    from manopt_lie.problems.reference import reference_solve  # CasADi: imported only when asked for

    ref = reference_solve(loaded.spec, x0, cost=task.cost)
    run = _record(task, loaded, ref.time, ref.iterations, ref.fun, ref.status)
    run.converged = ref.success
    return run, ref.x


def _record(task: Task, loaded: Loaded, seconds: float, nit: int, fun: float, status: str) -> Run:
    spec = loaded.spec
    return Run(
        instance=task.entry.name, problem=task.entry.problem, cost=task.cost, optimizer=task.solver,
        n=spec.n, m=spec.m, nit=nit, time=seconds, init_time=math.nan, fun=fun, status=status,
        converged=False, published=task.entry.published.get(task.cost),
    )  # fmt: skip


def execute(
    tasks: Sequence[Task],
    *,
    settings: Settings | None = None,
    data_dir: Path | str | None = None,
    on_task: Callable[[Task], None] | None = None,
) -> SuiteResult:
    """Run ``tasks`` (from :func:`plan`). ``on_task`` is called before each one (progress
    display). An instance whose data file is missing raises ``FileNotFoundError``."""
    settings = settings or Settings()
    out = SuiteResult()
    for task in tasks:
        if on_task is not None:
            on_task(task)
        name = task.entry.name
        if name not in out.loaded:
            out.loaded[name] = task.entry.load(data_dir)
            out.init_time[name], out.initial[name] = initialize(out.loaded[name])
        loaded, x0 = out.loaded[name], out.initial[name]
        if task.solver in OPTIMIZERS:
            run, x = _ours(task, loaded, x0, settings)
        elif task.solver == REFERENCE:
            run, x = _reference(task, loaded, x0, settings)
        else:
            run, x = _peer(task, loaded, x0, settings)
        run.init_time = out.init_time[name]
        out.runs.append(run)
        out.solutions[name, task.cost, task.solver] = x
    return out


def positions(loaded: Loaded, x: Any) -> Any:
    """Pose positions ``(n, d)`` for trajectory plots; ``None`` for rotation averaging."""
    if not isinstance(loaded.spec, PoseGraph):
        return None
    d = loaded.spec.d
    return x.as_matrix()[:, :d, d]
