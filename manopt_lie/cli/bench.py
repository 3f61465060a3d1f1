"""``manopt-lie demo`` and ``manopt-lie bench``: suites of catalogue instances × optimizers
(and optional peers and the IPOPT reference), run by :mod:`manopt_lie.bench`; a table,
JSON, a markdown report and plots."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from manopt_lie.bench import peers as peer_adapters
from manopt_lie.bench import plots, report
from manopt_lie.bench.suite import Settings, SuiteResult, execute, plan
from manopt_lie.optim import OPTIMIZERS
from manopt_lie.problems.catalogue import SUITES, Entry, load_suite

from . import _common

PEER_GROUPS: dict[str, tuple[str, ...]] = {}
"""``--peers`` names: the peer libraries, each with the peer solvers it provides."""
for _peer in peer_adapters.PEERS.values():
    PEER_GROUPS[_peer.module] = (*PEER_GROUPS.get(_peer.module, ()), _peer.name)


def add_parsers(commands: Any) -> None:
    demo = commands.add_parser(
        "demo", help="solve built-in synthetic problems with every optimizer",
        description="A synthetic 3-D pose graph and a rotation-averaging instance, each solved by every optimizer: "
        "a comparison table, convergence plots, performance profile, trajectories, a markdown report and JSON.",
    )  # fmt: skip
    demo.add_argument("--out-dir", type=Path, default=Path("manopt-lie-demo"),
                      help="where plots, report.md and results.json go (default: %(default)s)")  # fmt: skip
    _common.add_stopping(demo, max_time=5.0)
    _common.add_output(demo)
    demo.set_defaults(run=run_demo)

    bench = commands.add_parser(
        "bench", help="run a benchmark suite and compare optimizers",
        description="Run catalogue instances × optimizers; print a table, write JSON, a markdown report and plots.",
    )  # fmt: skip
    bench.add_argument("--suite", default="quick", metavar="quick|full|FILE.toml", help="default: %(default)s")
    bench.add_argument("--data-dir", type=Path, metavar="DIR",
                       help="where dataset files are (default: $MANOPT_LIE_DATA or ../shared/datasets)")
    bench.add_argument("--optimizers", type=_common.csv(tuple(OPTIMIZERS)), default=list(OPTIMIZERS),
                       metavar=",".join(OPTIMIZERS), help="default: all")
    bench.add_argument("--reference", action="store_true", help="add the CasADi/IPOPT reference solution")
    bench.add_argument("--peers", type=_common.csv(tuple(PEER_GROUPS)), default=[], metavar=",".join(PEER_GROUPS),
                       help="optional peer libraries: " + "; ".join(
                           f"{p.name}: {p.summary}" for p in peer_adapters.PEERS.values()))
    bench.add_argument("--repeat", type=_common.number(int, positive=True), default=1, metavar="N",
                       help="report the median of N solves")
    bench.add_argument("--out", type=Path, metavar="RESULTS.json", help="write the JSON document")
    bench.add_argument("--report", type=Path, metavar="REPORT.md", help="write a markdown report")
    bench.add_argument("--plots", type=Path, metavar="DIR", help="write convergence, profile and trajectory plots")
    _common.add_stopping(bench, max_time=60.0)
    _common.add_output(bench)
    bench.set_defaults(run=run_bench)  # fmt: skip


def _run_suite(entries: Sequence[Entry], args: argparse.Namespace, *, optimizers: Sequence[str],
               peers: Sequence[str], reference: bool, repeat: int,
               data_dir: Path | None) -> tuple[Settings, SuiteResult]:  # fmt: skip
    for peer in peers:
        if not peer_adapters.available(peer):
            raise _common.UsageError(f"peer {peer} is not installed: pip install {peer_adapters.PEERS[peer].module}")
    for entry in entries:
        entry.check_size()
        path = entry.path(data_dir)
        if path is not None and not path.is_file():
            raise _common.UsageError(f"instance {entry.name}: no such file {path} (set --data-dir or MANOPT_LIE_DATA)")
    tasks = plan(entries, optimizers, peers=peers, reference=reference)
    settings = Settings(_common.stopping(args), repeat)
    progress = _common.progress(args.quiet)
    if progress is None:
        return settings, execute(tasks, settings=settings, data_dir=data_dir)
    with progress:
        bar = progress.add_task("", total=len(tasks))

        def advance(task: Any) -> None:
            progress.update(bar, description=task.label, completed=tasks.index(task))

        return settings, execute(tasks, settings=settings, data_dir=data_dir, on_task=advance)


def _plots(result: SuiteResult, directory: Path) -> list[Path]:
    paths = plots.convergence_plots(result.runs, directory)
    paths.append(plots.performance_profile(result.runs, directory / "performance-profile.png"))
    for name, loaded in result.loaded.items():
        before = loaded.spec.positions(result.initial[name])
        if before is None:
            continue
        finals = [r for r in result.runs if r.instance == name]
        best = min(finals, key=lambda r: r.fun)  # the lowest-cost run on any cost of this instance
        after = loaded.spec.positions(result.solutions[name, best.cost, best.optimizer])
        title = f"{name}: chordal initialization → {best.optimizer} ({best.cost})"
        paths.append(plots.trajectory(before, after, loaded.spec.edges, directory / f"{name}-trajectory.png", title))
    return paths


def _publish(result: SuiteResult, settings: Settings, args: argparse.Namespace, *, title: str, out: Path | None,
             report_path: Path | None, plot_dir: Path | None) -> None:  # fmt: skip
    paths = _plots(result, plot_dir) if plot_dir is not None else []
    document = report.document(result.runs, settings)
    if out is not None:
        _common.write_text(out, _common.json_text(document, indent=1))
    if report_path is not None:
        text = report.markdown(result.runs, settings, title=title, plots=paths, base=report_path.parent)
        _common.write_text(report_path, text)
    if args.json:
        _common.print_json(document)
        return
    report.print_table(result.runs, title=title)
    written = [p for p in (out, report_path) if p is not None] + paths
    if written:
        shown = ", ".join(str(p) for p in written[:4])
        print(f"wrote {len(written)} files: {shown}" + (" …" if len(written) > 4 else ""))


def run_demo(args: argparse.Namespace) -> int:
    _common.output_path(args.out_dir / "results.json", "--out-dir")
    settings, result = _run_suite(SUITES["demo"], args, optimizers=tuple(OPTIMIZERS), peers=(), reference=False,
                                  repeat=1, data_dir=None)  # fmt: skip
    out = args.out_dir
    _publish(result, settings, args, title="manopt-lie demo", out=out / "results.json",
             report_path=out / "report.md", plot_dir=out)  # fmt: skip
    return _common.EXIT_OK


def run_bench(args: argparse.Namespace) -> int:
    entries = load_suite(args.suite)
    _common.output_path(args.out, "--out")
    _common.output_path(args.report, "--report")
    _common.output_path(None if args.plots is None else args.plots / "performance-profile.png", "--plots")
    peers = [p for group in args.peers for p in PEER_GROUPS[group]]
    settings, result = _run_suite(entries, args, optimizers=args.optimizers, peers=peers, reference=args.reference,
                                  repeat=args.repeat, data_dir=args.data_dir)  # fmt: skip
    _publish(result, settings, args, title=f"manopt-lie bench --suite {args.suite}", out=args.out,
             report_path=args.report, plot_dir=args.plots)  # fmt: skip
    return _common.EXIT_OK
