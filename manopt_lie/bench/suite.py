"""Run a suite of catalogue instances × starts × optimizers (ours, optional peers, the IPOPT
reference) and collect one :class:`~manopt_lie.bench.record.Run` per combination.

Every run on an instance starts from the same initialization — chordal by default, or
odometry, or random from each of several seeds (:func:`plan`) — and every final cost is
evaluated with the project's cost definitions (``docs/conventions.md``), so rows are
comparable across libraries. Our optimizers come from the registry
(:data:`manopt_lie.optim.OPTIMIZERS`) and share one
:class:`~manopt_lie.optim.StoppingCriteria`; times are medians over ``repeat`` solves
(:func:`~manopt_lie.bench.timing.median_time`), each on a freshly built problem (so the
sparse symbolic analysis is part of the time).

A task is self-contained (a catalogue :class:`~manopt_lie.problems.catalogue.Entry`, which
pickles, and names): :func:`run_task` builds the problem where it runs, so that
:mod:`.distributed` can ship tasks to other processes and machines; problems themselves
(locks, per-thread state) never travel. :func:`manopt_lie.bench.campaign.execute` runs a plan.
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

import numpy as np

from manopt_lie.optim import OPTIMIZERS, Status, StoppingCriteria, get_optimizer
from manopt_lie.problems.catalogue import CatalogueError, Entry, Loaded
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.rotation_averaging import RotationAveraging
from manopt_lie.problems.solvers import GRAPH_SOLVERS

from . import peers as peer_adapters
from .record import Run, finite, status_name
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
    """One planned run: an entry, a cost, a solver and a start (``seed`` for ``init="random"``)."""

    entry: Entry
    cost: str
    solver: str  # an optimizer, a peer, or "ipopt"
    init: str = "chordal"
    seed: int | None = None

    @property
    def start(self) -> str:
        return self.init if self.seed is None else f"{self.init}:{self.seed}"

    @property
    def key(self) -> tuple[str, str, str, str]:
        """``(instance, cost, start, solver)``, as :attr:`Run.task_key <manopt_lie.bench.record.Run.task_key>`."""
        return self.entry.name, self.cost, self.start, self.solver

    @property
    def label(self) -> str:
        start = "" if self.start == "chordal" else f" · {self.start}"
        return f"{self.entry.name} · {self.cost} · {self.solver}{start}"


@dataclass
class Outcome:
    """A finished task: its run, the solution (``None`` when it ran in another process) and
    what plots need of it (the solution's positions and landmark positions, or ``None``)."""

    task: Task
    run: Run
    x: Any = None
    positions: Any = None
    landmarks: Any = None


@dataclass
class SuiteResult:
    """The runs in plan order, and the outcomes and loaded instances of this process."""

    runs: list[Run] = field(default_factory=list)
    outcomes: dict[tuple[str, str, str, str], Outcome] = field(default_factory=dict)
    loaded: dict[str, Loaded] = field(default_factory=dict)


def plan(
    entries: Sequence[Entry], optimizers: Sequence[str], *, peers: Sequence[str] = (), reference: bool = False,
    init: str = "chordal", seeds: Sequence[int] = (),
) -> list[Task]:  # fmt: skip
    """The runs of a suite, in order: per entry, per start (``init``; for ``"random"`` each of
    ``seeds``, default ``(0,)``), per cost, per solver; peers only where they apply (the kind
    and cost each solves)."""
    for name in optimizers:
        if name not in GRAPH_SOLVERS:
            get_optimizer(name)  # unknown: ValueError listing the choices
    for name in peers:
        if name not in peer_adapters.PEERS:
            raise ValueError(f"unknown peer {name!r}; choose from {', '.join(peer_adapters.PEERS)}")
    if seeds and init != "random":
        raise ValueError(f"seeds apply to random initializations only, not to {init!r}")
    starts: list[int | None] = list(seeds or (0,)) if init == "random" else [None]
    tasks = []
    for entry in entries:
        for seed in starts:
            for cost in entry.costs or ():
                ours = [s for s in optimizers if s not in GRAPH_SOLVERS or _applies(s, entry.problem, cost)]
                solvers = [*ours, *(p for p in peers if peer_adapters.applies(p, entry.problem, cost))]
                if reference and entry.problem in REFERENCE_KINDS:
                    solvers.append(REFERENCE)
                tasks += [Task(entry, cost, s, init, seed) for s in solvers]
    return tasks


def _applies(solver: str, kind: str, cost: str) -> bool:
    return GRAPH_SOLVERS[solver].applies(kind, cost)


def initialize(loaded: Loaded, init: str = "chordal", seed: int | None = None) -> tuple[float, Any]:
    """The initialization by name (:meth:`manopt_lie.problems.graph.Graph.initialize`) and its time."""
    start = time.perf_counter()
    x0 = loaded.spec.initialize(init, seed=seed)
    return time.perf_counter() - start, x0


def _ours(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    graph_solver = GRAPH_SOLVERS.get(task.solver)
    optimizer = None if graph_solver is not None else get_optimizer(task.solver).make(settings.stopping)

    def solve() -> Any:
        if graph_solver is not None:
            result = graph_solver.solve(loaded.spec, x0, settings.stopping)
        else:
            result = optimizer.solve(loaded.spec.problem(task.cost), x0)  # type: ignore[union-attr]
        if result.status is Status.INTERRUPTED:  # Ctrl-C ends the campaign, not just this run
            raise KeyboardInterrupt
        return result

    seconds, result = median_time(solve, settings.repeat)
    run = _record(task, loaded, seconds, result.nit, result.fun, result.status.name.lower())
    run.converged, run.grad_norm = result.status.converged, result.grad_norm
    run.history_cost, run.history_time = result.history.cost.tolist(), result.history.time.tolist()
    run.history_grad_norm = result.history.grad_norm.tolist()
    return run, result.x


def _peer(task: Task, loaded: Loaded, x0: Any, settings: Settings) -> tuple[Run, Any]:
    s = settings.stopping
    out = [
        peer_adapters.solve(
            task.solver, loaded.spec, x0, max_iterations=s.max_iterations, max_time=s.max_time,
            grad_rtol=s.grad_rtol, rel_cost_decrease=s.rel_cost_decrease or 1e-5,
        )
        for _ in range(settings.repeat)
    ]  # fmt: skip
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
        n=spec.n, m=spec.m, nit=nit, time=seconds, init_time=math.nan, fun=fun, status=status_name(status),
        converged=False, published=task.entry.published.get(task.cost), init=task.init, seed=task.seed,
    )  # fmt: skip


def _runner(solver: str) -> Callable[[Task, Loaded, Any, Settings], tuple[Run, Any]]:
    if solver in OPTIMIZERS or solver in GRAPH_SOLVERS:
        return _ours
    return _reference if solver == REFERENCE else _peer


class Cache:
    """Instances and starts already built in this process, shared by the tasks of one instance."""

    def __init__(self) -> None:
        self.loaded: dict[str, Loaded] = {}
        self.starts: dict[tuple[str, str], tuple[float, Any]] = {}

    def get(self, task: Task, data_dir: Path | str | None) -> tuple[Loaded, float, Any]:
        name = task.entry.name
        if name not in self.loaded:
            self.loaded[name] = task.entry.load(data_dir)
        if (name, task.start) not in self.starts:
            self.starts[name, task.start] = initialize(self.loaded[name], task.init, task.seed)
        return self.loaded[name], *self.starts[name, task.start]

    def drop(self, name: str) -> None:
        self.loaded.pop(name, None)
        for key in [k for k in self.starts if k[0] == name]:
            del self.starts[key]


def run_task(task: Task, settings: Settings, data_dir: Path | str | None = None, cache: Cache | None = None) -> Outcome:
    """Build the task's problem (or take it from ``cache``), start it, solve it, record it.

    Raises
    ------
    FileNotFoundError
        When the instance's data file is missing.
    CatalogueError
        For an instance too large for memory (naming it).
    """
    cache = cache if cache is not None else Cache()
    try:
        loaded, init_time, x0 = cache.get(task, data_dir)
        run, x = _runner(task.solver)(task, loaded, x0, settings)
    except MemoryError:
        cache.drop(task.entry.name)  # let the memory go before saying so
        raise CatalogueError(f"instance {task.entry.name!r} ({task.label}): out of memory") from None
    run.init_time = init_time
    positions = loaded.spec.positions(x)
    landmark_positions = getattr(loaded.spec, "landmark_positions", None)
    landmarks = None if landmark_positions is None else np.asarray(landmark_positions(x))
    return Outcome(task, run, x, positions, landmarks)
