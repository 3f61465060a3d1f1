"""One benchmark run: an optimizer (ours, a peer, or the IPOPT reference) on one
instance and cost, as a record that tables, reports, plots and JSON share."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

SOLVE_RTOL = 1e-5
"""A run *solves* its instance when its final cost is within this relative
distance of the best cost any run reached on it (performance profiles, reports)."""


@dataclass
class Run:
    """The outcome of one optimizer on one ``(instance, cost)``.

    ``time`` is the median solve time over the repeats (initialization excluded,
    its time is ``init_time``); ``fun`` is the final cost by CONVENTIONS §8, also
    for peers; ``gap = (fun − published)/published`` when the instance has a
    published optimum for this cost. ``history_cost``/``history_time`` hold one
    entry per iteration, starting at the initial point (time 0).
    """

    instance: str
    problem: str  # "pose-graph" | "rotation-averaging"
    cost: str  # "chordal" | "geodesic"
    optimizer: str  # "gd", "cg", "gn", "lm", "tr", "gtsam-lm", "gtsam-dogleg", "pymanopt-tr", "ipopt"
    n: int
    m: int
    nit: int
    time: float
    init_time: float
    fun: float
    status: str
    converged: bool
    grad_norm: float | None = None
    published: float | None = None
    history_cost: list[float] = field(default_factory=list)
    history_time: list[float] = field(default_factory=list)

    @property
    def gap(self) -> float | None:
        """Relative gap to the published optimum, if there is one."""
        if self.published is None:
            return None
        return (self.fun - self.published) / abs(self.published)

    @property
    def key(self) -> tuple[str, str]:
        return self.instance, self.cost

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["gap"] = self.gap
        return {k: [finite(x) for x in v] if isinstance(v, list) else finite(v) for k, v in out.items()}


def finite(value: Any) -> Any:
    """JSON has no nan or inf: they become null."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def best_costs(runs: list[Run]) -> dict[tuple[str, str], float]:
    """The lowest final cost per ``(instance, cost)`` over all runs (published optima
    are printed to four digits only, too coarse to judge convergence by)."""
    best: dict[tuple[str, str], float] = {}
    for run in runs:
        if math.isfinite(run.fun):
            best[run.key] = min(best.get(run.key, math.inf), run.fun)
    return best


def solved(run: Run, best: float) -> bool:
    """Whether ``run`` reached ``best`` to :data:`SOLVE_RTOL`."""
    return math.isfinite(run.fun) and run.fun <= best + SOLVE_RTOL * max(abs(best), 1e-12)
