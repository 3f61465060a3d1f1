"""``manopt-lie demo`` and ``manopt-lie bench``: suites of catalogue instances × starts ×
optimizers (and optional peers and the IPOPT reference), run by :mod:`manopt_lie.bench` in
this process or on a Dask cluster; a table, JSON, a markdown report, plots and a results
store that an interrupted campaign resumes from."""

from __future__ import annotations

import argparse
import importlib.util
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from manopt_lie.bench import peers as peer_adapters
from manopt_lie.bench import report
from manopt_lie.bench.campaign import execute
from manopt_lie.bench.figures import FORMATS
from manopt_lie.bench.record import Run, status_words
from manopt_lie.bench.store import Store, StoreError
from manopt_lie.bench.suite import Outcome, Settings, SuiteResult, Task, plan, run_task
from manopt_lie.optim import OPTIMIZERS
from manopt_lie.problems.catalogue import SUITES, Entry, load_suite
from manopt_lie.problems.graph import Graph
from manopt_lie.problems.solvers import GRAPH_SOLVERS

from . import _common

SOLVERS = (*OPTIMIZERS, *GRAPH_SOLVERS)
"""``--optimizers`` names: the registry's optimizers and the graph solvers (each runs where it applies)."""

PEER_GROUPS: dict[str, tuple[str, ...]] = {}
"""``--peers`` names: the peer libraries, each with the peer solvers it provides."""
for _peer in peer_adapters.PEERS.values():
    PEER_GROUPS[_peer.module] = (*PEER_GROUPS.get(_peer.module, ()), _peer.name)

SCHEDULERS = "sequential|dask|tcp://HOST:PORT"


def _plot_format(parser: Any) -> None:
    parser.add_argument("--plot-format", choices=FORMATS, default="png",
                        help="the figures' file format (default: %(default)s)")  # fmt: skip


def add_parsers(commands: Any) -> None:
    demo = commands.add_parser(
        "demo", help="solve built-in synthetic problems with every optimizer",
        description="Solve a synthetic 3-D pose graph (216 poses) and a rotation-averaging instance (200 rotations) "
        "with every optimizer from the same chordal initialization; print a comparison table and write convergence "
        "plots, a performance profile, trajectory plots, report.md and results.json. Needs no files.",
    )  # fmt: skip
    demo.add_argument("--out-dir", type=Path, default=Path("manopt-lie-demo"),
                      help="where plots, report.md and results.json go (default: %(default)s)")  # fmt: skip
    _plot_format(demo)
    _common.add_stopping(demo, max_time=5.0)
    _common.add_output(demo)
    demo.set_defaults(run=run_demo)

    bench = commands.add_parser(
        "bench", help="run a benchmark suite and compare optimizers",
        description="Run catalogue instances × starts × optimizers (every run of an instance from the same start); "
        "print a table, write JSON, a markdown report and plots. With --scheduler the runs are spread over a Dask "
        "cluster; with --store every finished run is saved at once, and --resume continues an interrupted campaign.",
    )  # fmt: skip
    bench.add_argument("--suite", default="quick", metavar="quick|full|FILE.toml",
                       help="quick: synthetic, about a minute; full: the SE-Sync datasets and larger synthetic "
                       "instances (needs --data-dir); or your own TOML file (default: %(default)s)")  # fmt: skip
    bench.add_argument("--data-dir", type=Path, metavar="DIR",
                       help="where dataset files are (default: $MANOPT_LIE_DATA or ../shared/datasets)")
    bench.add_argument("--optimizers", type=_common.csv(SOLVERS), default=list(SOLVERS),
                       metavar=",".join(SOLVERS), help="; ".join(f"{e.name}: {e.summary}" for e in
                       (*OPTIMIZERS.values(), *GRAPH_SOLVERS.values())) + " (default: all; each where it "
                       "applies)")  # fmt: skip
    bench.add_argument("--reference", action="store_true", help="add the CasADi/IPOPT reference solution")
    bench.add_argument("--peers", type=_common.csv(tuple(PEER_GROUPS)), default=[], metavar=",".join(PEER_GROUPS),
                       help="optional peer libraries: " + "; ".join(
                           f"{p.name}: {p.summary}" for p in peer_adapters.PEERS.values()))  # fmt: skip
    bench.add_argument("--repeat", type=_common.number(int, positive=True), default=1, metavar="N",
                       help="report the median time of N solves (default: %(default)s)")
    starts = bench.add_argument_group("starts")
    starts.add_argument("--init", choices=("chordal", "odometry", "random"), default="chordal",
                        help="the start of every run: the chordal relaxation, odometry (a spanning tree) or random "
                        "(Haar rotations and wide random translations; one start per --seeds) (default: %(default)s)")
    starts.add_argument("--seeds", type=_common.seeds, metavar="0-9",
                        help="seeds of --init random, e.g. 0-9 or 0,3,7 (default: 0)")
    campaign = bench.add_argument_group("campaigns")
    campaign.add_argument("--scheduler", default="sequential", metavar=SCHEDULERS,
                          help="sequential: one run after another in this process; dask: a Dask LocalCluster of "
                          "--workers processes on this machine; tcp://HOST:PORT: an existing Dask cluster's scheduler "
                          f"(needs {_extra()}) (default: %(default)s)")
    campaign.add_argument("--workers", type=_common.number(int, positive=True), metavar="N",
                          help="worker processes of --scheduler dask (default: one per CPU)")
    campaign.add_argument("--store", type=Path, metavar="RUNS.jsonl",
                          help="save every run as one JSON line the moment it finishes (an interrupted campaign "
                          "keeps them)")
    campaign.add_argument("--resume", action="store_true",
                          help="continue the campaign of --store: run only what it lacks (same settings needed)")
    outputs = bench.add_argument_group("outputs")
    outputs.add_argument("--out", type=Path, metavar="RESULTS.json", help="write the JSON document")
    outputs.add_argument("--report", type=Path, metavar="REPORT.md", help="write a markdown report")
    outputs.add_argument("--plots", type=Path, metavar="DIR", help="write convergence, profile and trajectory plots")
    _plot_format(outputs)
    _common.add_stopping(bench, max_time=60.0)
    _common.add_output(bench)
    bench.set_defaults(run=run_bench)  # fmt: skip


def _extra() -> str:
    from manopt_lie.bench.distributed import EXTRA

    return EXTRA


def _check_scheduler(args: argparse.Namespace) -> str | None:
    scheduler = args.scheduler
    if scheduler == "sequential":
        if args.workers is not None:
            raise _common.UsageError("--workers needs --scheduler dask")
        return None
    if scheduler != "dask" and "://" not in scheduler:
        raise _common.UsageError(f"--scheduler must be {SCHEDULERS}, got {scheduler!r}")
    if args.workers is not None and scheduler != "dask":
        raise _common.UsageError("--workers applies to --scheduler dask (an existing cluster has its own workers)")
    if importlib.util.find_spec("dask") is None or importlib.util.find_spec("distributed") is None:
        raise _common.UsageError(f"--scheduler {scheduler} needs Dask: {_extra()}")
    return str(scheduler)


class _Progress:
    """What the user sees while the runs go: a rich bar on a terminal, plain lines in logs,
    nothing with ``--quiet``; and the results store, fed as runs arrive."""

    def __init__(self, command: str, tasks: Sequence[Task], quiet: bool, store: Store | None, preamble: str, *,
                 lines: bool = True) -> None:  # fmt: skip
        self.store, self.total = store, len(tasks)
        self.bar = _common.progress(quiet)
        lines = lines and not quiet and self.bar is None
        self.lines = _common.Lines(command, len(tasks), preamble=preamble) if lines else None
        self.count = 0

    def __enter__(self) -> _Progress:
        if self.bar is not None:
            self.bar.__enter__()
            self.task = self.bar.add_task("", total=self.total)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)

    def start(self, task: Task) -> None:
        if self.bar is not None:
            self.bar.update(self.task, description=task.label)

    def result(self, outcome: Outcome) -> None:
        run = outcome.run
        if self.store is not None:
            self.store.add(run)
        self.count += 1
        if self.bar is not None:
            self.bar.update(self.task, completed=self.count)
        if self.lines is not None:
            text = f"cost {run.fun:.7g} in {run.time:.3f} s ({status_words(run.status)})"
            self.lines.finished(outcome.task.label, text, important=not run.converged)


def _run_suite(entries: Sequence[Entry], args: argparse.Namespace, *, optimizers: Sequence[str],
               peers: Sequence[str] = (), reference: bool = False, repeat: int = 1, data_dir: Path | None = None,
               init: str = "chordal", seeds: Sequence[int] = (), scheduler: str | None = None,
               workers: int | None = None, store_path: Path | None = None,
               resume: bool = False) -> tuple[Settings, SuiteResult]:  # fmt: skip
    for peer in peers:
        if not peer_adapters.available(peer):
            raise _common.UsageError(f"peer {peer} is not installed: pip install {peer_adapters.PEERS[peer].module}")
    for entry in entries:
        entry.check_size()
        path = entry.path(data_dir)
        if path is not None and not path.is_file():
            raise _common.UsageError(f"instance {entry.name}: no such file {path} (set --data-dir or MANOPT_LIE_DATA)")
    tasks = plan(entries, optimizers, peers=peers, reference=reference, init=init, seeds=seeds)
    settings = Settings(_common.stopping(args), repeat)
    try:
        store = None if store_path is None else Store(store_path, settings.to_json(), resume=resume)
    except StoreError as error:
        raise _common.UsageError(str(error)) from None
    done = [] if store is None else store.runs
    finished = {r.task_key for r in done}
    todo = [t for t in tasks if t.key not in finished]
    where = "in this process" if scheduler is None else f"on {scheduler}"
    resumed = f" ({len(tasks) - len(todo)} resumed from {store_path})" if len(todo) < len(tasks) else ""
    preamble = f"{len(todo)} runs of {len(entries)} instances {where}{resumed}"
    # --json: a document for a program; its stderr gets no plain lines (a terminal still gets the bar)
    with _Progress(args.command, todo, args.quiet, store, preamble, lines=not args.json) as progress:
        result = execute(tasks, settings=settings, data_dir=data_dir, on_task=progress.start,
                         on_result=progress.result, done=done, scheduler=scheduler, workers=workers)  # fmt: skip
    return settings, result


def _best(runs: Sequence[Run], spec: Graph) -> Run:
    """The run whose solution a trajectory plot shows: the lowest cost of the first start, on the
    graph's default cost when it was run."""
    first = [r for r in runs if r.start == runs[0].start]
    cost = spec.costs[0] if any(r.cost == spec.costs[0] for r in first) else first[0].cost
    return min((r for r in first if r.cost == cost), key=lambda r: (r.fun != r.fun, r.fun))


def _plots(result: SuiteResult, entries: Sequence[Entry], settings: Settings, data_dir: Path | None,
           directory: Path, fmt: str) -> list[Path]:  # fmt: skip
    from manopt_lie.bench import optimum, plots  # Matplotlib: loaded only for figures

    specs = {name: loaded.spec for name, loaded in result.loaded.items()}
    solutions = {key: o.x for key, o in result.outcomes.items() if o.x is not None}
    references = optimum.references(result.runs, solutions, specs)
    paths = plots.convergence_plots(result.runs, directory, references=references, format=fmt)
    paths.append(plots.performance_profile(result.runs, directory / f"performance-profile.{fmt}"))
    for entry in entries:
        runs = [r for r in result.runs if r.instance == entry.name]
        if not runs:
            continue
        loaded = result.loaded.get(entry.name) or entry.load(data_dir)
        spec = loaded.spec
        best = _best(runs, spec)
        task = Task(entry, best.cost, best.optimizer, best.init, best.seed)
        outcome = result.outcomes.get(task.key) or run_task(task, settings, data_dir)  # resumed: solved again
        if outcome.positions is None:
            continue
        try:
            before, label = spec.positions(spec.initialize("odometry")), "odometry initialization"
        except ValueError:
            before, label = spec.positions(spec.initialize(best.init, seed=best.seed)), f"{best.start} start"
        truth = None if loaded.truth is None else spec.positions(loaded.truth)
        landmark_positions = getattr(spec, "landmark_positions", None)
        true_marks = None if truth is None or landmark_positions is None else landmark_positions(loaded.truth)
        title = f"{entry.name}: {label} and the {best.optimizer} solution ({best.cost} cost)"
        target = directory / f"{entry.name}-trajectory.{fmt}"
        paths.append(plots.trajectory(before, outcome.positions, spec.edges, target, title, truth=truth,
                                      landmarks=outcome.landmarks, truth_landmarks=true_marks,
                                      labels=(label, f"{best.optimizer} solution")))  # fmt: skip
    return paths


def _publish(result: SuiteResult, entries: Sequence[Entry], settings: Settings, args: argparse.Namespace, *,
             title: str, out: Path | None, report_path: Path | None, plot_dir: Path | None,
             data_dir: Path | None = None, store: Path | None = None) -> None:  # fmt: skip
    paths = _plots(result, entries, settings, data_dir, plot_dir, args.plot_format) if plot_dir is not None else []
    files = [p for p in (entry.path(data_dir) for entry in entries) if p is not None]
    document = report.document(result.runs, settings, datasets=files)
    if out is not None:
        _common.write_text(out, _common.json_text(document, indent=1))
    if report_path is not None:
        text = report.markdown(result.runs, settings, title=title, plots=paths, base=report_path.parent)
        _common.write_text(report_path, text)
    if args.json:
        _common.print_json(document)
        return
    report.print_table(result.runs, title=title)
    written = [p for p in (out, report_path, store) if p is not None] + paths
    if written:
        shown = ", ".join(str(p) for p in written[:4])
        print(f"wrote {len(written)} files: {shown}" + (" …" if len(written) > 4 else ""))


def run_demo(args: argparse.Namespace) -> int:
    _common.output_path(args.out_dir / "results.json", "--out-dir")
    entries = SUITES["demo"]
    settings, result = _run_suite(entries, args, optimizers=SOLVERS)
    out = args.out_dir
    _publish(result, entries, settings, args, title="manopt-lie demo", out=out / "results.json",
             report_path=out / "report.md", plot_dir=out)  # fmt: skip
    return _common.EXIT_OK


def run_bench(args: argparse.Namespace) -> int:
    entries = load_suite(args.suite)
    _common.output_path(args.out, "--out")
    _common.output_path(args.report, "--report")
    _common.output_path(None if args.plots is None else args.plots / f"performance-profile.{args.plot_format}",
                        "--plots")  # fmt: skip
    _common.output_path(args.store, "--store")
    if args.resume and args.store is None:
        raise _common.UsageError("--resume needs --store RUNS.jsonl (the campaign to continue)")
    if args.seeds is not None and args.init != "random":
        raise _common.UsageError(f"--seeds applies to --init random, not --init {args.init}")
    scheduler = _check_scheduler(args)
    peers = [p for group in args.peers for p in PEER_GROUPS[group]]
    settings, result = _run_suite(entries, args, optimizers=args.optimizers, peers=peers, reference=args.reference,
                                  repeat=args.repeat, data_dir=args.data_dir, init=args.init, seeds=args.seeds or (),
                                  scheduler=scheduler, workers=args.workers, store_path=args.store,
                                  resume=args.resume)  # fmt: skip
    _publish(result, entries, settings, args, title=f"manopt-lie bench --suite {args.suite}", out=args.out,
             report_path=args.report, plot_dir=args.plots, data_dir=args.data_dir, store=args.store)  # fmt: skip
    return _common.EXIT_OK
