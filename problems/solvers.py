"""Solvers that work on a graph rather than on a least-squares problem, by name.

The optimizers of :data:`manopt_lie.optim.OPTIMIZERS` solve a
:class:`~manopt_lie.optim.Problem` from a point. Some solvers need the graph itself — the
certifiable staircase builds its own relaxation from the measurements. Each is registered
here with the kinds and costs it solves, and returns the same
:class:`~manopt_lie.optim.OptimizeResult` as the optimizers, so the command line and the
benchmarks treat both alike: a new one is a function plus one entry.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from manopt_lie.optim import OptimizeResult, Status, StoppingCriteria
from manopt_lie.optim.result import History

from .graph import Graph
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

__all__ = ["GRAPH_SOLVERS", "GraphSolver", "get_graph_solver"]


@dataclass(frozen=True)
class GraphSolver:
    """A solver of graphs of some kinds, with some costs.

    Attributes
    ----------
    name, summary : str
    kinds, costs : tuple of str
        What it solves (graph ``kind`` names; cost names).
    solve : callable ``(graph, x0, stopping) -> OptimizeResult``
    """

    name: str
    summary: str
    kinds: tuple[str, ...]
    costs: tuple[str, ...]
    solve: Callable[[Graph, Any, StoppingCriteria], OptimizeResult]

    def applies(self, kind: str, cost: str) -> bool:
        """Whether this solver solves problems of ``kind`` (e.g. ``"pose-graph"``) on ``cost``."""
        return kind in self.kinds and cost in self.costs


def _staircase(graph: Graph, x0: Any, stopping: StoppingCriteria) -> OptimizeResult:
    """:func:`~manopt_lie.problems.certify.staircase` from ``x0``, as an :class:`OptimizeResult`:
    ``Status.CERTIFIED`` when the rounded solution is certified; the history concatenates the
    levels' trust-region runs (their costs are the relaxation's, equal to the chordal cost at
    rank ``d``). ``stopping`` bounds each level's trust region and the total time."""
    from .certify import StaircaseStatus, staircase  # the relaxation's machinery, loaded when asked for

    result = staircase(graph, x0, stopping=stopping, max_time=stopping.max_time)  # type: ignore[arg-type]
    status = {
        StaircaseStatus.OPTIMAL: Status.CERTIFIED, StaircaseStatus.MAX_TIME: Status.MAX_TIME,
        StaircaseStatus.MAX_RANK: Status.MAX_ITERATIONS,
    }.get(result.status, Status.NO_PROGRESS)  # fmt: skip
    runs = [r for level in result.levels for r in (level.result, level.polish) if r is not None]
    cost = np.concatenate([r.history.cost for r in runs]) if runs else np.array([result.fun])
    grad = np.concatenate([r.history.grad_norm for r in runs]) if runs else np.array([math.nan])
    step = np.concatenate([r.history.step for r in runs]) if runs else np.array([math.nan])
    offsets = np.cumsum([0.0, *(r.time for r in runs)])[:-1] if runs else np.zeros(1)
    time = np.concatenate([r.history.time + t0 for r, t0 in zip(runs, offsets, strict=True)]) if runs else np.zeros(1)
    problem = graph.problem("chordal")
    grad_norm = float(np.sqrt(np.sum(problem.manifold.inner(result.x, g := problem.grad(result.x), g))))
    message = f"{result.status.value} (rank {result.rank}, f − f* ≤ {result.suboptimality:.3g})"
    return OptimizeResult(
        x=result.x, fun=result.fun, grad_norm=grad_norm, nit=result.iterations, nfev=sum(r.nfev for r in runs),
        ngev=sum(r.ngev for r in runs), nhev=sum(r.nhev for r in runs), time=result.time, status=status,
        message=message, history=History(cost, grad, step, time),
    )  # fmt: skip


GRAPH_SOLVERS: dict[str, GraphSolver] = {
    solver.name: solver
    for solver in (
        GraphSolver("staircase", "Riemannian staircase (SE-Sync; Shonan for rotations): a certified global optimum "
                    "of the chordal cost from any start", (PoseGraph.kind, RotationAveraging.kind), ("chordal",),
                    _staircase),
    )
}  # fmt: skip
"""The graph solvers by name (``--optimizer staircase`` on the command line and in suites)."""


def get_graph_solver(name: str) -> GraphSolver:
    """The solver called ``name``; ``ValueError`` listing the choices otherwise."""
    if name not in GRAPH_SOLVERS:
        raise ValueError(f"unknown graph solver {name!r}; choose from {', '.join(GRAPH_SOLVERS)}")
    return GRAPH_SOLVERS[name]
