"""One benchmark run: an optimizer (ours, a peer, or the IPOPT reference) on one
instance, cost and start, as a record that tables, reports, plots, JSON and the results
store share.

**Status names.** ``Run.status`` (and every JSON document) spells a status in snake_case —
our optimizers' :class:`~manopt_lie.optim.Status` names lowercased (``gradient_norm``,
``max_iterations``, ``max_time`` …), the peers' ``converged``, ``max_iterations``,
``max_time``, ``diverged``, IPOPT's return status lowercased (``solve_succeeded``); tables
show the same words with spaces (:func:`status_words`: "gradient norm").
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from decimal import Decimal
from typing import Any

SOLVE_RTOL = 1e-5
"""A run *solves* its instance when its final cost is within this relative
distance of the best cost any run reached on it (performance profiles, reports)."""

PUBLISHED_DIGITS = 4
"""Published optima are taken to carry at least this many significant digits (SE-Sync prints
four: its ``3.170e1`` is stored as the float ``31.7``), or as many as their shortest decimal
representation has, if more."""


def status_words(status: str) -> str:
    """A status as tables show it: ``"gradient_norm"`` → ``"gradient norm"``."""
    return status.replace("_", " ")


def status_name(text: str) -> str:
    """A status as records and JSON spell it: ``"Solve_Succeeded"``, ``"max iterations"`` →
    ``"solve_succeeded"``, ``"max_iterations"``."""
    return "_".join(text.lower().replace("-", " ").split())


@dataclass
class Run:
    """The outcome of one optimizer on one ``(instance, cost)`` from one start.

    ``time`` is the median solve time over the repeats (initialization excluded,
    its time is ``init_time``); ``fun`` is the final cost by the project's definition of
    the cost (``docs/conventions.md``), also for peers; ``gap = (fun − published)/|published|``
    when the instance has a published optimum for this cost. ``history_cost``,
    ``history_time`` and ``history_grad_norm`` hold one entry per iteration, starting at the
    initial point (time 0); the gradient norms only where the solver reports them. ``init``
    and ``seed`` name the start (``seed`` only for ``init = "random"``).
    """

    instance: str
    problem: str  # a kind of manopt_lie.problems.kinds
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
    history_grad_norm: list[float] = field(default_factory=list)
    init: str = "chordal"
    seed: int | None = None

    @property
    def gap(self) -> float | None:
        """Relative gap to the published optimum, if there is one."""
        if self.published is None:
            return None
        return (self.fun - self.published) / abs(self.published)

    @property
    def key(self) -> tuple[str, str]:
        """``(instance, cost)``: the problem whose optimum every run of it is compared with."""
        return self.instance, self.cost

    @property
    def start(self) -> str:
        """``"chordal"``, ``"random:3"``…: the start of the run."""
        return self.init if self.seed is None else f"{self.init}:{self.seed}"

    @property
    def problem_key(self) -> tuple[str, str, str]:
        """``(instance, cost, start)``: one problem of a performance profile."""
        return self.instance, self.cost, self.start

    @property
    def task_key(self) -> tuple[str, str, str, str]:
        """``(instance, cost, start, optimizer)``: what identifies a run in a results store."""
        return self.instance, self.cost, self.start, self.optimizer

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["gap"] = self.gap
        return {k: [finite(x) for x in v] if isinstance(v, list) else finite(v) for k, v in out.items()}

    @classmethod
    def from_json(cls, document: dict[str, Any]) -> Run:
        """The run of :meth:`to_json` (``null`` numbers become ``nan``).

        Raises
        ------
        ValueError
            When a field is missing.
        """
        fields = {f.name: f for f in dataclasses.fields(cls)}
        missing = [name for name, f in fields.items() if name not in document and f.default is dataclasses.MISSING
                   and f.default_factory is dataclasses.MISSING]  # fmt: skip
        if missing:
            raise ValueError(f"a run record lacks {', '.join(missing)}")
        args = {k: v for k, v in document.items() if k in fields}
        for name in ("time", "init_time", "fun"):
            args[name] = math.nan if args[name] is None else float(args[name])
        for name in ("history_cost", "history_time", "history_grad_norm"):
            args[name] = [math.nan if v is None else float(v) for v in args.get(name, [])]
        return cls(**args)


def finite(value: Any) -> Any:
    """JSON has no nan or inf: they become null."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def best_costs(runs: list[Run]) -> dict[tuple[str, str], float]:
    """The lowest final cost per ``(instance, cost)`` over all runs and starts (published
    optima are printed to four digits only, too coarse to judge convergence by)."""
    best: dict[tuple[str, str], float] = {}
    for run in runs:
        if math.isfinite(run.fun):
            best[run.key] = min(best.get(run.key, math.inf), run.fun)
    return best


def solved(run: Run, best: float) -> bool:
    """Whether ``run`` reached ``best`` to :data:`SOLVE_RTOL`."""
    return math.isfinite(run.fun) and run.fun <= best + SOLVE_RTOL * max(abs(best), 1e-12)


def published_precision(value: float) -> tuple[int, float]:
    """``(digits, half_unit)``: the significant digits of a published optimum
    (:data:`PUBLISHED_DIGITS` at least) and half a unit of its last digit — how far the
    printed value may lie from the true optimum by rounding alone."""
    if value == 0 or not math.isfinite(value):
        return PUBLISHED_DIGITS, 0.0
    shortest = Decimal(repr(float(value))).normalize()
    digits = max(PUBLISHED_DIGITS, len(shortest.as_tuple().digits))
    exponent = math.floor(math.log10(abs(value)))
    return digits, 0.5 * 10.0 ** (exponent - digits + 1)


def agreement(run: Run) -> str | None:
    """How the run's final cost compares with the published optimum: ``"= f* to 4 digits"``
    when they differ by no more than the rounding of the printed value, else the signed
    relative gap (``"+1.2e-03"``; a negative one, below the rounding, reads ``"-2.0e-03 < f*"``);
    ``None`` without a published value."""
    if run.published is None or not math.isfinite(run.fun):
        return None
    digits, half_unit = published_precision(run.published)
    if abs(run.fun - run.published) <= half_unit:
        return f"= f* to {digits} digits"
    gap = run.gap
    assert gap is not None
    return f"{gap:+.1e}" + (" < f*" if gap < 0 else "")
