"""Tables, markdown reports and JSON documents from benchmark runs."""

from __future__ import annotations

import math
import platform
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .record import Run, best_costs, solved

HEADER = ("instance", "n", "m", "cost", "optimizer", "iters", "time (s)", "final cost", "f*", "gap", "status")


def _number(value: float | None, spec: str) -> str:
    return "—" if value is None or not math.isfinite(value) else format(value, spec)


def rows(runs: Sequence[Run]) -> list[list[str]]:
    """One formatted row per run, in :data:`HEADER` order; the status is starred when
    the run did not reach the best cost of its instance (to 1e-5, relative)."""
    best = best_costs(list(runs))
    out = []
    for r in runs:
        mark = "" if r.key in best and solved(r, best[r.key]) else " *"
        out.append([
            r.instance, str(r.n), str(r.m), r.cost, r.optimizer, str(r.nit), _number(r.time, ".3f"),
            _number(r.fun, ".7g"), _number(r.published, ".4g"), _number(r.gap, ".1e"), r.status + mark,
        ])  # fmt: skip
    return out


def print_table(runs: Sequence[Run], *, title: str | None = None, console: Any = None) -> None:
    """The runs as a terminal table (rich)."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for name in HEADER:
        table.add_column(name, justify="left" if name in ("instance", "cost", "optimizer", "status") else "right")
    previous = None
    for r, row in zip(runs, rows(runs), strict=True):
        if previous is not None and previous != r.key:
            table.add_section()
        table.add_row(*row)
        previous = r.key
    if console is None:  # a pipe or file gets the whole table, not a wrapped 80 columns
        console = Console() if sys.stdout.isatty() else Console(width=200)
    console.print(table)


def markdown_table(runs: Sequence[Run]) -> str:
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(row) + " |" for row in rows(runs)]
    return "\n".join(lines)


def summary(runs: Sequence[Run]) -> list[dict[str, Any]]:
    """Per optimizer: problems solved (final cost within 1e-5 of the best of any run)
    and the geometric mean over solved problems of its time over the fastest solver's."""
    best = best_costs(list(runs))
    fastest: dict[tuple[str, str], float] = {}
    for r in runs:
        if solved(r, best[r.key]):
            fastest[r.key] = min(fastest.get(r.key, math.inf), r.time)
    out = []
    for name in dict.fromkeys(r.optimizer for r in runs):
        mine = [r for r in runs if r.optimizer == name]
        ok = [r for r in mine if solved(r, best[r.key])]
        ratios = [r.time / fastest[r.key] for r in ok if fastest[r.key] > 0]
        mean = float(np.exp(np.mean(np.log(ratios)))) if ratios else None
        out.append({"optimizer": name, "problems": len(mine), "solved": len(ok), "time_ratio_geomean": mean})
    return out


def environment() -> dict[str, str]:
    import numpy
    import scipy

    return {
        "python": platform.python_version(), "platform": platform.platform(), "machine": platform.machine(),
        "numpy": numpy.__version__, "scipy": scipy.__version__,
    }  # fmt: skip


def document(runs: Sequence[Run], settings: Any) -> dict[str, Any]:
    """The JSON document: settings, environment, runs (with histories) and the summary."""
    return {
        "settings": settings.to_json(),
        "environment": environment(),
        "runs": [r.to_json() for r in runs],
        "summary": summary(runs),
    }


def markdown(
    runs: Sequence[Run], settings: Any, *, title: str, plots: Sequence[Path] = (), base: Path | None = None
) -> str:
    """A self-contained markdown report: settings, the table, the per-optimizer summary
    and the plots (linked relative to ``base``, the report's directory)."""
    env = environment()
    parts = [
        f"# {title}",
        "",
        f"Python {env['python']}, NumPy {env['numpy']}, SciPy {env['scipy']} on {env['platform']}.",
        "Stopping rule: " + ", ".join(f"{k} = {v}" for k, v in settings.to_json().items()) + ".",
        "Times are solve times (the chordal initialization is shared and excluded), medians over the repeats; "
        "`*` marks a run that did not reach the best final cost of its instance to 1e-5 relative.",
        "",
        markdown_table(runs),
        "",
        "| optimizer | problems | solved | time / fastest (geometric mean) |",
        "|---|---|---|---|",
    ]
    for s in summary(runs):
        parts.append(
            f"| {s['optimizer']} | {s['problems']} | {s['solved']} | {_number(s['time_ratio_geomean'], '.2f')} |"
        )
    if plots:
        parts += ["", "## Plots", ""]
        for path in plots:
            link = path.relative_to(base) if base is not None and path.is_relative_to(base) else path
            parts.append(f"![{path.stem}]({link.as_posix()})")
    return "\n".join(parts) + "\n"
