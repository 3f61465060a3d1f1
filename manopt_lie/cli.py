"""The ``manopt-lie`` command line (also ``python -m manopt_lie``).

- ``manopt-lie demo``: a synthetic 3-D pose graph and a rotation-averaging
  instance, each solved by every optimizer: a comparison table, convergence
  plots, performance profile, trajectories, a markdown report and JSON.
- ``manopt-lie solve FILE.g2o``: solve one file, write the result as g2o.
- ``manopt-lie bench``: a suite of catalogue instances × optimizers (and
  optional peers and the IPOPT reference): table, JSON, report, plots.

Bad arguments and bad input files end with a one-line ``manopt-lie: error: …``
on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

EXIT_USAGE = 2


class UsageError(ValueError):
    """A bad argument or input file: reported in one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


def _csv(choices: Sequence[str]) -> Any:
    def parse(text: str) -> list[str]:
        names = [t.strip() for t in text.split(",") if t.strip()]
        if bad := [n for n in names if n not in choices]:
            raise argparse.ArgumentTypeError(f"unknown {', '.join(bad)}; choose from {','.join(choices)}")
        if not names:
            raise argparse.ArgumentTypeError("empty list")
        return names

    return parse


def _positive(kind: type) -> Any:
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not value > 0:
            raise argparse.ArgumentTypeError(f"must be positive, got {text}")
        return value

    return parse


OPTIMIZER_NAMES = ("gd", "cg", "gn", "lm", "tr")
PEER_GROUPS = {"gtsam": ("gtsam-lm", "gtsam-dogleg"), "pymanopt": ("pymanopt-tr",)}


def _stopping(parser: argparse.ArgumentParser, max_time: float) -> None:
    group = parser.add_argument_group("stopping rule (shared by all optimizers)")
    group.add_argument("--max-iterations", type=_positive(int), default=1000, metavar="N", help="default: %(default)s")
    group.add_argument("--max-time", type=_positive(float), default=max_time, metavar="S",
                       help="seconds per run (default: %(default)s)")  # fmt: skip
    group.add_argument("--tol", type=_positive(float), default=1e-6,
                       help="gradient norm relative to the initial one (default: %(default)s)")  # fmt: skip
    group.add_argument("--rel-decrease", type=float, default=0.0, metavar="R",
                       help="also stop when the relative cost decrease of an iteration is below R (GTSAM's rule; "
                       "default: off, and peers then use GTSAM's default 1e-5)")  # fmt: skip


def _output(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="manopt-lie", description="Optimization on manifolds and Lie groups: pose graphs, "
                     "rotation averaging and optimizer benchmarks.")  # fmt: skip
    from . import __version__

    parser.add_argument("--version", action="version", version=f"manopt-lie {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="{demo,solve,bench}", parser_class=_Parser)

    demo = commands.add_parser("demo", help="solve built-in synthetic problems with every optimizer",
                               description=__doc__.split("- ``manopt-lie solve")[0].split("- ")[1].strip())  # fmt: skip
    demo.add_argument("--out-dir", type=Path, default=Path("manopt-lie-demo"),
                      help="where plots, report.md and results.json go (default: %(default)s)")  # fmt: skip
    _stopping(demo, max_time=5.0)
    _output(demo)

    solve = commands.add_parser("solve", help="solve a g2o file", description="Solve a g2o pose graph (or the "
                                "rotation averaging of its rotations) and write the result.")  # fmt: skip
    solve.add_argument("file", type=Path, metavar="FILE.g2o")
    solve.add_argument("--problem", choices=("pose-graph", "rotation-averaging"), default="pose-graph")
    solve.add_argument("--cost", choices=("geodesic", "chordal"),
                       help="§8 cost (default: geodesic for pose graphs, chordal for rotations)")  # fmt: skip
    solve.add_argument("--optimizer", choices=OPTIMIZER_NAMES, default="tr", help="default: %(default)s")
    solve.add_argument("--init", choices=("chordal", "odometry", "file"), default="chordal",
                       help="initial guess; 'file' takes the file's VERTEX poses (default: %(default)s)")  # fmt: skip
    solve.add_argument("--robust", metavar="LOSS:SCALE", help="robust loss, e.g. huber:1.0, cauchy:0.5")
    solve.add_argument("--out", type=Path, metavar="RESULT.g2o", help="write the solution as g2o")
    solve.add_argument("--plot", type=Path, metavar="FIG.png",
                       help="trajectories before/after (pose graphs) or convergence (rotations)")  # fmt: skip
    _stopping(solve, max_time=600.0)
    _output(solve)

    bench = commands.add_parser("bench", help="run a benchmark suite and compare optimizers",
                                description="Run catalogue instances × optimizers; print a table, write JSON, "
                                "a markdown report and plots.")  # fmt: skip
    bench.add_argument("--suite", default="quick", metavar="quick|full|FILE.toml", help="default: %(default)s")
    bench.add_argument("--data-dir", type=Path, metavar="DIR",
                       help="where dataset files are (default: $MANOPT_LIE_DATA or ../shared/datasets)")  # fmt: skip
    bench.add_argument("--optimizers", type=_csv(OPTIMIZER_NAMES), default=list(OPTIMIZER_NAMES),
                       metavar="gd,cg,gn,lm,tr", help="default: all")  # fmt: skip
    bench.add_argument("--reference", action="store_true", help="add the CasADi/IPOPT reference solution")
    bench.add_argument("--peers", type=_csv(tuple(PEER_GROUPS)), default=[], metavar="gtsam,pymanopt",
                       help="optional peer libraries (GTSAM LM and dogleg; pymanopt trust region)")  # fmt: skip
    bench.add_argument("--repeat", type=_positive(int), default=1, metavar="N", help="report the median of N solves")
    bench.add_argument("--out", type=Path, metavar="RESULTS.json", help="write the JSON document")
    bench.add_argument("--report", type=Path, metavar="REPORT.md", help="write a markdown report")
    bench.add_argument("--plots", type=Path, metavar="DIR", help="write convergence, profile and trajectory plots")
    _stopping(bench, max_time=60.0)
    _output(bench)
    return parser


# ---- progress ------------------------------------------------------------------------


def _progress(quiet: bool) -> Any:
    """A rich progress display on stderr, or ``None`` when quiet or not a terminal."""
    if quiet or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=Console(stderr=True), transient=True)  # fmt: skip


# ---- bench and demo ------------------------------------------------------------------


def _settings(args: argparse.Namespace, repeat: int = 1) -> Any:
    from manopt_lie.bench.suite import Settings

    return Settings(args.max_iterations, args.max_time, args.tol, args.rel_decrease, repeat)


def _run_suite(entries: Any, args: argparse.Namespace, *, optimizers: Sequence[str], peers: Sequence[str],
               reference: bool, repeat: int, data_dir: Path | None) -> tuple[Any, Any]:  # fmt: skip
    from manopt_lie.bench import peers as peer_adapters
    from manopt_lie.bench.suite import execute, plan

    for peer in peers:
        if not peer_adapters.available(peer):
            raise UsageError(f"peer {peer} is not installed: pip install {peer.split('-')[0]}")
    for entry in entries:
        path = entry.path(data_dir)
        if path is not None and not path.is_file():
            raise UsageError(f"instance {entry.name}: no such file {path} (set --data-dir or MANOPT_LIE_DATA)")
    tasks = plan(entries, optimizers, peers=peers, reference=reference)
    settings = _settings(args, repeat)
    progress = _progress(args.quiet)
    if progress is None:
        return settings, execute(tasks, settings=settings, data_dir=data_dir)
    with progress:
        bar = progress.add_task("", total=len(tasks))

        def advance(task: Any) -> None:
            progress.update(bar, description=task.label, completed=tasks.index(task))

        return settings, execute(tasks, settings=settings, data_dir=data_dir, on_task=advance)


def _plots(result: Any, directory: Path) -> list[Path]:
    from manopt_lie.bench import plots
    from manopt_lie.bench.suite import positions

    paths = plots.convergence_plots(result.runs, directory)
    paths.append(plots.performance_profile(result.runs, directory / "performance-profile.png"))
    for name, loaded in result.loaded.items():
        before = positions(loaded, result.initial[name])
        if before is None:
            continue
        finals = [r for r in result.runs if r.instance == name]
        best = min(finals, key=lambda r: r.fun)  # the lowest-cost run on any cost of this instance
        after = positions(loaded, result.solutions[name, best.cost, best.optimizer])
        title = f"{name}: chordal initialization → {best.optimizer} ({best.cost})"
        paths.append(plots.trajectory(before, after, loaded.spec.edges, directory / f"{name}-trajectory.png", title))
    return paths


def _publish(result: Any, settings: Any, args: argparse.Namespace, *, title: str, out: Path | None,
             report: Path | None, plot_dir: Path | None) -> None:  # fmt: skip
    from manopt_lie.bench import report as reports

    paths = _plots(result, plot_dir) if plot_dir is not None else []
    document = reports.document(result.runs, settings)
    if out is not None:
        _write(out, json.dumps(document, indent=1, allow_nan=False))
    if report is not None:
        _write(report, reports.markdown(result.runs, settings, title=title, plots=paths, base=report.parent))
    if args.json:
        print(json.dumps(document, allow_nan=False))
        return
    reports.print_table(result.runs, title=title)
    written = [p for p in (out, report) if p is not None] + paths
    if written:
        print(
            f"wrote {len(written)} files: "
            + ", ".join(str(p) for p in written[:4])
            + (" …" if len(written) > 4 else "")
        )


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def cmd_demo(args: argparse.Namespace) -> None:
    from manopt_lie.problems.catalogue import SUITES

    settings, result = _run_suite(SUITES["demo"], args, optimizers=OPTIMIZER_NAMES, peers=(), reference=False,
                                  repeat=1, data_dir=None)  # fmt: skip
    out = args.out_dir
    _publish(result, settings, args, title="manopt-lie demo", out=out / "results.json", report=out / "report.md",
             plot_dir=out)  # fmt: skip


def cmd_bench(args: argparse.Namespace) -> None:
    from manopt_lie.problems.catalogue import load_suite

    entries = load_suite(args.suite)
    peers = [p for group in args.peers for p in PEER_GROUPS[group]]
    settings, result = _run_suite(entries, args, optimizers=args.optimizers, peers=peers, reference=args.reference,
                                  repeat=args.repeat, data_dir=args.data_dir)  # fmt: skip
    _publish(result, settings, args, title=f"manopt-lie bench --suite {args.suite}", out=args.out,
             report=args.report, plot_dir=args.plots)  # fmt: skip


# ---- solve ---------------------------------------------------------------------------


def cmd_solve(args: argparse.Namespace) -> None:
    from manopt_lie.problems import g2o, rotation_averaging

    if not args.file.is_file():
        raise UsageError(f"no such file: {args.file}")
    graph = g2o.read(args.file)
    spec: Any = graph if args.problem == "pose-graph" else rotation_averaging.from_pose_graph(graph)
    cost = args.cost or ("geodesic" if args.problem == "pose-graph" else "chordal")
    start = time.perf_counter()
    if args.init == "file":
        if graph.poses is None:
            raise UsageError(f"{args.file} has no VERTEX lines: use --init chordal or odometry")
        rotations = graph.poses.as_matrix()[:, : graph.d, : graph.d]
        x0 = graph.poses if args.problem == "pose-graph" else spec.group.from_matrix(rotations)
    elif args.init == "odometry":
        x0 = spec.odometry_initialization() if args.problem == "pose-graph" else spec.spanning_tree_initialization()
    else:
        x0 = spec.chordal_initialization()
    init_time = time.perf_counter() - start
    problem = spec.problem(cost, robust=args.robust)
    optimizer = _settings(args).optimizer(args.optimizer)
    progress = _progress(args.quiet)
    if progress is None:
        result = optimizer.solve(problem, x0)
    else:
        with progress:
            bar = progress.add_task(f"{args.optimizer} on {args.file.name}", total=args.max_iterations)

            def show(info: Any) -> None:
                progress.update(bar, completed=info.iteration, description=f"{args.optimizer}: cost {info.fun:.6g}")

            result = optimizer.solve(problem, x0, callback=show)
    summary = {
        "file": str(args.file), "problem": args.problem, "cost": cost, "optimizer": args.optimizer,
        "robust": args.robust, "n": spec.n, "m": spec.m, "initial_fun": problem.cost(x0), "fun": result.fun,
        "nit": result.nit, "time": result.time, "init_time": init_time, "status": result.status.name.lower(),
        "converged": result.status.converged, "grad_norm": result.grad_norm, "message": result.message,
    }  # fmt: skip
    if args.out is not None:
        _write_solution(args.out, graph, result.x, args.problem)
    if args.plot is not None:
        _solve_plot(args, spec, x0, result, summary)
    if args.json:
        print(json.dumps(summary, allow_nan=False))
    else:
        print(
            f"{args.file.name}: {spec.n} {'poses' if args.problem == 'pose-graph' else 'rotations'}, {spec.m} edges; "
            f"{cost} cost {summary['initial_fun']:.8g} → {result.fun:.8g} by {args.optimizer} in {result.nit} "
            f"iterations, {result.time:.3f} s (+ {init_time:.3f} s {args.init} initialization)\n"
            f"status: {result.message}; ‖grad‖ = {result.grad_norm:.3g}"
        )


def _write_solution(path: Path, graph: Any, x: Any, problem: str) -> None:
    """The pose graph with the solution as its vertices (rotation averaging: the
    estimated rotations with zero translations)."""
    import numpy as np

    from manopt_lie.problems import g2o

    if problem == "rotation-averaging":
        matrices = np.array(graph.group.identity((graph.n,)).as_matrix())
        matrices[:, : graph.d, : graph.d] = x.as_matrix()
        x = graph.group.from_matrix(matrices)
    path.parent.mkdir(parents=True, exist_ok=True)
    g2o.write(path, graph, x)


def _solve_plot(args: argparse.Namespace, spec: Any, x0: Any, result: Any, summary: dict[str, Any]) -> None:
    from manopt_lie.bench import plots
    from manopt_lie.bench.record import Run

    if args.problem == "pose-graph":
        d = spec.d
        title = f"{args.file.name}: {args.init} initialization → {args.optimizer} ({summary['cost']})"
        plots.trajectory(x0.as_matrix()[:, :d, d], result.x.as_matrix()[:, :d, d], spec.edges, args.plot, title)
        return
    run = Run(args.file.stem, args.problem, summary["cost"], args.optimizer, spec.n, spec.m, result.nit, result.time,
              summary["init_time"], result.fun, summary["status"], summary["converged"], result.grad_norm,
              history_cost=result.history.cost.tolist(), history_time=result.history.time.tolist())  # fmt: skip
    plots.convergence([run], args.plot)


# ---- entry point ---------------------------------------------------------------------

COMMANDS = {"demo": cmd_demo, "solve": cmd_solve, "bench": cmd_bench}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code (0, or 2 for bad arguments or input)."""
    args = build_parser().parse_args(argv)
    try:
        COMMANDS[args.command](args)
    except (ValueError, OSError, ImportError) as error:  # bad input: files, arguments, missing extras
        message = " ".join(str(error).split())
        print(f"manopt-lie {args.command}: error: {message}", file=sys.stderr)
        return EXIT_USAGE
    return 0


if __name__ == "__main__":
    sys.exit(main())
