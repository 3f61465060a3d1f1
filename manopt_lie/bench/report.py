"""Tables, markdown reports and JSON documents from benchmark runs."""

from __future__ import annotations

import hashlib
import json
import math
import platform
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write
from .record import Run, agreement, best_costs, solved, status_words

HEADER = ("instance", "start", "n", "m", "cost", "optimizer", "iters", "time (s)", "final cost", "f*", "gap",
          "status")
"""Every column a row may have; tables leave out those that are empty in every row
(:func:`columns`): ``start`` for chordal starts, ``f*`` and ``gap`` without published optima."""
_RIGHT = {"n", "m", "iters", "time (s)", "final cost", "f*"}


def _number(value: float | None, spec: str) -> str:
    return "—" if value is None or not math.isfinite(value) else format(value, spec)


def _row(r: Run, mark: str) -> list[str]:
    return [
        r.instance, "" if r.start == "chordal" else r.start, str(r.n), str(r.m), r.cost, r.optimizer, str(r.nit),
        _number(r.time, ".3f"), _number(r.fun, ".7g"), "" if r.published is None else format(r.published, ".4g"),
        agreement(r) or "", status_words(r.status) + mark,
    ]  # fmt: skip


def rows(runs: Sequence[Run]) -> list[list[str]]:
    """One formatted row per run, in :data:`HEADER` order: the status in words
    (:func:`~manopt_lie.bench.record.status_words`), starred when the run did not reach the
    best cost of its instance (to 1e-5, relative); the gap as
    :func:`~manopt_lie.bench.record.agreement` says it ("= f* to 4 digits")."""
    best = best_costs(list(runs))
    return [_row(r, "" if r.key in best and solved(r, best[r.key]) else " *") for r in runs]


def columns(table: Sequence[Sequence[str]]) -> list[int]:
    """The indices of the :data:`HEADER` columns that are not empty in every row."""
    return [k for k in range(len(HEADER)) if any(row[k] for row in table)]


def print_table(runs: Sequence[Run], *, title: str | None = None, console: Any = None) -> None:
    """The runs as a terminal table (rich), without the columns that are empty in every row."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    table_rows = rows(runs)
    keep = columns(table_rows)
    table = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False, show_edge=False,
                  collapse_padding=True)  # two spaces between columns: a 100-column terminal holds the demo
    for k in keep:
        table.add_column(HEADER[k], justify="right" if HEADER[k] in _RIGHT else "left")
    previous = None
    for r, row in zip(runs, table_rows, strict=True):
        if previous is not None and previous != r.problem_key:
            table.add_section()
        table.add_row(*(row[k] or "—" for k in keep))
        previous = r.problem_key
    if console is None:  # a pipe or file gets the whole table, not a wrapped 80 columns
        console = Console() if sys.stdout.isatty() else Console(width=200)
    console.print(table)


def markdown_table(runs: Sequence[Run]) -> str:
    table_rows = rows(runs)
    keep = columns(table_rows)
    lines = ["| " + " | ".join(HEADER[k] for k in keep) + " |", "|" + "---|" * len(keep)]
    lines += ["| " + " | ".join(row[k] or "—" for k in keep) + " |" for row in table_rows]
    return "\n".join(lines)


def summary(runs: Sequence[Run]) -> list[dict[str, Any]]:
    """Per optimizer: the problems (instance, cost, start) it attempted, those it solved (final
    cost within 1e-5 of the best of any run on the instance and cost), and the geometric mean
    over solved problems of its time over the fastest solver's."""
    best = best_costs(list(runs))
    fastest: dict[tuple[str, str, str], float] = {}
    for r in runs:
        if solved(r, best[r.key]):
            fastest[r.problem_key] = min(fastest.get(r.problem_key, math.inf), r.time)
    out = []
    for name in dict.fromkeys(r.optimizer for r in runs):
        mine = [r for r in runs if r.optimizer == name]
        ok = [r for r in mine if solved(r, best[r.key])]
        ratios = [r.time / fastest[r.problem_key] for r in ok if fastest[r.problem_key] > 0]
        mean = float(np.exp(np.mean(np.log(ratios)))) if ratios else None
        out.append({"optimizer": name, "problems": len(mine), "solved": len(ok), "time_ratio_geomean": mean})
    return out


PACKAGES = ("numpy", "scipy", "casadi", "cvxopt", "qdldl", "matplotlib", "gtsam", "pymanopt", "evo", "dask")
"""The packages whose versions every benchmark document records (``None``: not installed)."""


def environment(datasets: Iterable[str | Path] = ()) -> dict[str, Any]:
    """Where numbers come from: Python, the platform, manopt_lie's version, the versions of
    :data:`PACKAGES` (read from their installed metadata, nothing imported), and the SHA-256
    and size of every dataset file read (``datasets``): the published optima and the peers'
    times are only comparable on the same files."""
    from importlib import metadata

    from .. import __version__

    def version(name: str) -> str | None:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return None

    files = {}
    for path in map(Path, datasets):
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                digest.update(chunk)
        files[path.name] = {"sha256": digest.hexdigest(), "bytes": path.stat().st_size}
    return {
        "python": platform.python_version(), "platform": platform.platform(), "machine": platform.machine(),
        "manopt_lie": __version__, "packages": {name: version(name) for name in PACKAGES}, "datasets": files,
    }  # fmt: skip


def environment_line(env: dict[str, Any]) -> str:
    """One sentence for reports and docs tables: the versions that produced them."""
    packages = ", ".join(f"{name} {v}" for name, v in env["packages"].items() if v is not None)
    files = ", ".join(f"{name} ({d['sha256'][:12]})" for name, d in env["datasets"].items())
    return (f"manopt_lie {env['manopt_lie']}, Python {env['python']} on {env['platform']}; {packages}"
            + (f"; datasets (SHA-256): {files}" if files else "") + ".")  # fmt: skip


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float (anywhere inside lists and dicts) turned into
    ``None`` — JSON has no nan or inf — and NumPy scalars and arrays into Python ones."""
    if isinstance(value, np.generic | np.ndarray):
        value = value.tolist()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value


def json_text(document: Any, **options: Any) -> str:
    """Valid JSON for ``document`` (:func:`json_safe` first)."""
    return json.dumps(json_safe(document), allow_nan=False, **options)


def write_json(path: str | Path, results: Any, *, datasets: Iterable[str | Path] = ()) -> None:
    """Write a benchmark script's ``results`` as ``{"environment": …, "results": …}``, atomically."""
    text = json_text({"environment": environment(datasets), "results": results}, indent=1)
    with atomic_write(path) as f:
        f.write(text + "\n")


def document(runs: Sequence[Run], settings: Any, datasets: Iterable[str | Path] = ()) -> dict[str, Any]:
    """The JSON document: settings, environment (with the datasets' checksums), runs (with
    histories) and the summary."""
    return {
        "settings": settings.to_json(),
        "environment": environment(datasets),
        "runs": [r.to_json() for r in runs],
        "summary": summary(runs),
    }


def markdown(
    runs: Sequence[Run], settings: Any, *, title: str, plots: Sequence[Path] = (), base: Path | None = None
) -> str:
    """A self-contained markdown report: settings, the table, the per-optimizer summary
    and the plots (linked relative to ``base``, the report's directory)."""
    parts = [
        f"# {title}",
        "",
        environment_line(environment()),
        "Stopping rule: " + ", ".join(f"{k} = {v}" for k, v in settings.to_json().items()) + ".",
        "Times are solve times (each start's initialization is shared and excluded), medians over the repeats; "
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
