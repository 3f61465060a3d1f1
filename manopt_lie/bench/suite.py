"""Run a suite of catalogue instances × optimizers (ours, optional peers, the IPOPT
reference) and collect one :class:`~manopt_lie.bench.record.Run` per combination.

Every run on an instance starts from the same chordal initialization (timed once,
``init_time``) and every final cost is evaluated with CONVENTIONS §8, so rows are
comparable across libraries. Our optimizers come from the registry
(:data:`manopt_lie.optim.OPTIMIZERS`) and share one
:class:`~manopt_lie.optim.StoppingCriteria`; times are medians over ``repeat`` solves
(:func:`~manopt_lie.bench.timing.median_time`), each on a freshly built problem (so the
sparse symbolic analysis is part of the time).
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from manopt_lie.optim import OPTIMIZERS, Status, StoppingCriteria, get_optimizer
from manopt_lie.problems.catalogue import CatalogueError, Entry, Loaded
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.rotation_averaging import RotationAveraging

from . import peers as peer_adapters
from .record import Run, finite
from .timing import median_time

REFERENCE = "ipopt"
REFERENCE_KINDS = (PoseGraph.kind, RotationAveraging.kind)
"""The kinds the IPOPT reference solves (:data:`manopt_lie.problems.reference.KINDS`, not
imported here: CasADi's NLP machinery loads only when a reference run is asked for)."""


@dataclass(frozen=True)
class Settings:
    """The stopping rule shared by all runs (peers get the equivalents they have: iteration
    cap, relative cost decrease or gradient tolerance) and the number of repeats."""

    stopping: StoppingCriteria = field(default_factory=lambda: StoppingCriteria(max_time=60.0))
    repeat: int = 1

    def __post_init__(self) -> None:
        if self.repeat < 1:
            raise ValueError(f"repeat must be at least 1, got {self.repeat}")

    def to_json(self) -> dict[str, Any]:
        return {**{k: finite(v) for k, v in dataclasses.asdict(self.stopping).items()}, "repeat": self.repeat}


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
    """The runs of a suite, in order; peers only where they apply (the kind and cost each solves)."""
    for name in optimizers:
        get_optimizer(name)  # unknown: ValueError listing the choices
    for name in peers:
        if name not in peer_adapters.PEERS:
            raise ValueError(f"unknown peer {name!r}; choose from {', '.join(peer_adapters.PEERS)}")
    tasks = []
    for entry in entries:
        for cost in entry.costs or ():
            solvers = [*optimizers, *(p for p in peers if peer_adapters.applies(p, entry.problem, cost))]
            if reference and entry.problem in REFERENCE_KINDS:
                solvers.append(REFERENCE)
            tasks += [Task(entry, cost, s) for s in solvers]
    return tasks


def initialize(loaded: Loaded) -> tuple[float, Any]:
    """The chordal initialization and its time."""
    start = time.perf_counter()
    x0 = loaded.spec.initialize("chordal")
    return time.perf_counter() - start, x0


def _ours(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    optimizer = get_optimizer(task.solver).make(settings.stopping)

    def solve() -> Any:
        result = optimizer.solve(loaded.spec.problem(task.cost), x0)
        if result.status is Status.INTERRUPTED:  # Ctrl-C ends the campaign, not just this run
            raise KeyboardInterrupt
        return result

    seconds, result = median_time(solve, settings.repeat)
    run = _record(task, loaded, seconds, result.nit, result.fun, result.status.name.lower().replace("_", " "))
    run.converged, run.grad_norm = result.status.converged, result.grad_norm
    run.history_cost, run.history_time = result.history.cost.tolist(), result.history.time.tolist()
    return run, result.x


def _peer(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    s = settings.stopping
    out = [
        peer_adapters.solve(
            task.solver, loaded.spec, x0, max_iterations=s.max_iterations, max_time=s.max_time,
            grad_rtol=s.grad_rtol, rel_cost_decrease=s.rel_cost_decrease or 1e-5,
        )
        for _ in range(settings.repeat)
    ]
    seconds = statistics.median(o.time for o in out)  # the peers time themselves, building excluded
    last = out[-1]
    run = _record(task, loaded, seconds, last.nit, loaded.spec.cost(last.x, task.cost), last.status)
    run.converged = last.converged
    run.history_cost, run.history_time = list(last.history_cost), list(last.history_time)
    return run, last.x


def _reference(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    from manopt_lie.problems.reference import reference_solve  # CasADi's IPOPT: built only when asked for

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


def _runner(solver: str) -> Callable[[Task, Loaded, Any, Settings], tuple[Run, Any]]:
    if solver in OPTIMIZERS:
        return _ours
    return _reference if solver == REFERENCE else _peer


def execute(
    tasks: Sequence[Task],
    *,
    settings: Settings | None = None,
    data_dir: Path | str | None = None,
    on_task: Callable[[Task], None] | None = None,
) -> SuiteResult:
    """Run ``tasks`` (from :func:`plan`). ``on_task`` is called before each one (progress
    display). An instance whose data file is missing raises ``FileNotFoundError``; one too
    large for memory raises :class:`~manopt_lie.problems.catalogue.CatalogueError` naming it."""
    settings = settings or Settings()
    out = SuiteResult()
    for task in tasks:
        if on_task is not None:
            on_task(task)
        name = task.entry.name
        try:
            if name not in out.loaded:
                out.loaded[name] = task.entry.load(data_dir)
                out.init_time[name], out.initial[name] = initialize(out.loaded[name])
            loaded, x0 = out.loaded[name], out.initial[name]
            run, x = _runner(task.solver)(task, loaded, x0, settings)
        except MemoryError:
            out.loaded.pop(name, None)  # let the memory go before saying so
            raise CatalogueError(f"instance {name!r} ({task.label}): out of memory") from None
        run.init_time = out.init_time[name]
        out.runs.append(run)
        out.solutions[name, task.cost, task.solver] = x
    return out
