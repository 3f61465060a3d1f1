"""Pose graphs from 10³ to 10⁶ poses: our GN and LM against GTSAM's LM (not a timed test).

Instances are synthetic (``manopt_lie.problems.synthetic``): planar grids ``grid2d(s, s)``
(SE(2), up to 10⁶ poses) and SE-Sync's cubes ``cube(s)`` (SE(3), up to ~10⁵ poses: a
10⁶-pose cube's Cholesky factor fills in to ~10⁹ entries, beyond this machine for both
libraries), loop closures kept with probability 0.1, the default noise, seed 0. Every
solver starts from our chordal initialization and stops by GTSAM's rule (relative cost
decrease below 1e-5).

Time: in one process, ours (GN, LM) and GTSAM's LM alternate, ``--repeat`` rounds, medians;
our pools of structures and symbolic analyses are emptied before each of our runs (so each
pays its own set-up, as GTSAM pays its ordering); each side's problem (our ``graph.problem``, GTSAM's
factor graph) is built before its clock starts. Time per iteration is the median of the
iterations' wall times (each library's own history). Memory: each solver runs in a
subprocess of its own (``--worker``) that rebuilds the instance, loads the start, resets
its peak resident set (``/proc/self/clear_refs``), builds its problem and solves; the
peak resident set above the start (``VmHWM − VmRSS`` before) is the solver's memory, the
C++ allocations of GTSAM and CHOLMOD included (tracemalloc would miss them).

``python benchmarks/bench_scaling.py [--sizes 2d:32,100 3d:10] [--repeat 3] [--no-memory]
[--plot docs/img/scaling.png] [--json out.json]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from manopt_lie import _kernels  # noqa: E402
from manopt_lie.bench import peers  # noqa: E402
from manopt_lie.bench.report import write_json  # noqa: E402
from manopt_lie.linalg import clear_caches  # noqa: E402
from manopt_lie.optim import GaussNewton, LevenbergMarquardt  # noqa: E402
from manopt_lie.problems import synthetic  # noqa: E402

RULE = 1e-5  # GTSAM's default relativeErrorTol
SIZES = {"2d": [32, 100, 316, 1000], "3d": [10, 22, 46]}


def instance(kind: str, side: int) -> Any:
    """The pose graph of ``kind`` (``"2d"`` or ``"3d"``) and ``side``."""
    if kind == "2d":
        return synthetic.grid2d(side, side, loop_closure_probability=0.1, seed=0).graph
    return synthetic.cube(side, loop_closure_probability=0.1, seed=0).graph


def per_iteration(times: list[float] | np.ndarray) -> float:
    """The median wall time of an iteration from a history of elapsed times (index 0 = x₀)."""
    steps = np.diff(np.asarray(times, dtype=np.float64))
    return float(np.median(steps)) if steps.size else float("nan")


def ours(name: str, graph: Any, x0: Any) -> dict[str, Any]:
    clear_caches()  # a cold analysis, as GTSAM orders anew
    make = GaussNewton if name == "GN" else LevenbergMarquardt
    problem = graph.problem("geodesic")  # before the clock, as GTSAM's factor graph (bench_pose_graph.py)
    start = time.perf_counter()
    res = make(rel_cost_decrease=RULE).solve(problem, x0)
    seconds = time.perf_counter() - start
    return {"time": seconds, "nit": res.nit, "per_iteration": per_iteration(res.history.time), "cost": res.fun}


def gtsam(graph: Any, x0: Any) -> dict[str, Any]:
    run = peers.solve("gtsam-lm", graph, x0, rel_cost_decrease=RULE)
    return {"time": run.time, "nit": run.nit, "per_iteration": per_iteration(run.history_time),
            "cost": graph.cost(run.x, "geodesic")}  # fmt: skip


def median_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    out = {k: statistics.median(r[k] for r in runs) for k in ("time", "per_iteration")}
    return out | {"nit": runs[-1]["nit"], "cost": runs[-1]["cost"]}


# ---- memory: one subprocess per solver ---------------------------------------------------------


def _status() -> dict[str, int]:
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmHWM:", "VmRSS:")):
                key, value = line.split(":")
                out[key] = int(value.split()[0]) * 1024
    return out


def worker(kind: str, side: int, solver: str, start_path: str) -> None:
    """Solve one instance with one solver and print its memory and time as JSON."""
    graph = instance(kind, side)
    x0 = graph.group.from_matrix(np.load(start_path))
    __import__("gtsam")  # both workers carry both libraries, ours with its compiled kernels: the baselines are alike
    _kernels.native(graph.group.__name__)

    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the peak resident set to the current one
    before = _status()["VmRSS"]
    start = time.perf_counter()
    nit = gtsam(graph, x0)["nit"] if solver == "GTSAM" else ours(solver, graph, x0)["nit"]
    seconds = time.perf_counter() - start
    peak = _status()["VmHWM"]
    print(json.dumps({"peak": peak - before, "baseline": before, "time": seconds, "nit": nit}))


def memory(kind: str, side: int, x0: Any, solvers: tuple[str, ...]) -> dict[str, dict[str, Any]]:
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "x0.npy")
        np.save(path, x0.as_matrix())
        out = {}
        for solver in solvers:
            cmd = [sys.executable, __file__, "--worker", kind, str(side), solver, path]
            done = subprocess.run(cmd, capture_output=True, text=True, check=True)
            out[solver] = json.loads(done.stdout.strip().splitlines()[-1])
        return out


# ---- the report --------------------------------------------------------------------------------


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Log-log time per iteration against n (matplotlib Figure + Agg canvas, no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 4.6), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    styles = {"LM": ("C0", "-", "o"), "GN": ("C2", "--", "s"), "GTSAM": ("C3", "-", "^")}
    for kind, label in (("2d", "SE(2) grid"), ("3d", "SE(3) cube")):
        sub = sorted((r for r in rows if r["kind"] == kind), key=lambda r: r["n"])
        if not sub:
            continue
        for solver, (colour, line, marker) in styles.items():
            ls = line if kind == "2d" else ":"
            ax.loglog([r["n"] for r in sub], [r[solver]["per_iteration"] for r in sub], color=colour, ls=ls,
                      marker=marker, label=f"{'ours ' if solver != 'GTSAM' else ''}{solver}, {label}")  # fmt: skip
    ax.set_xlabel("poses n")
    ax.set_ylabel("time per iteration (s)")
    ax.set_title("Pose graphs: time per iteration vs size (median of repeats)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="*", help="kind:side,side… e.g. 2d:32,100 3d:10 (default: all)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-memory", action="store_true", help="skip the subprocess memory runs")
    parser.add_argument("--plot", type=Path, help="write the log-log figure here (PNG)")
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    parser.add_argument("--worker", nargs=4, metavar=("KIND", "SIDE", "SOLVER", "X0"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        kind, side, solver, path = args.worker
        worker(kind, int(side), solver, path)
        return
    sizes = {k: list(v) for k, v in SIZES.items()}
    if args.sizes:
        sizes = {}
        for spec in args.sizes:
            kind, sides = spec.split(":")
            sizes[kind] = [int(s) for s in sides.split(",")]
    print(f"load average at the start: {os.getloadavg()[0]:.2f}", flush=True)
    head = ("| instance | n | m | iterations LM / GN / GTSAM | time per iteration LM, GTSAM (s) | LM ratio | GN ratio |"
            " per-iteration ratio LM | peak memory LM / GN / GTSAM (MB) | memory ratio LM, GN |")  # fmt: skip
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    rows = []
    for kind, sides in sizes.items():
        for side in sides:
            graph = instance(kind, side)
            x0 = graph.chordal_initialization()
            runs: dict[str, list[dict[str, Any]]] = {"LM": [], "GN": [], "GTSAM": []}
            for _ in range(args.repeat):  # alternating: other load hits every solver alike
                runs["LM"].append(ours("LM", graph, x0))
                runs["GTSAM"].append(gtsam(graph, x0))
                runs["GN"].append(ours("GN", graph, x0))
            row: dict[str, Any] = {"kind": kind, "side": side, "n": graph.n, "m": graph.m}
            row |= {k: median_runs(v) for k, v in runs.items()}
            mem = {} if args.no_memory else memory(kind, side, x0, ("LM", "GN", "GTSAM"))
            row["memory"] = mem
            rows.append(row)
            lm, gn, gt = row["LM"], row["GN"], row["GTSAM"]
            mb = "—" if not mem else " / ".join(f"{mem[s]['peak'] / 2**20:.0f}" for s in ("LM", "GN", "GTSAM"))
            mratio = "—" if not mem else (f"{mem['LM']['peak'] / mem['GTSAM']['peak']:.2f}, "
                                          f"{mem['GN']['peak'] / mem['GTSAM']['peak']:.2f}")  # fmt: skip
            print(
                f"| {'grid2d' if kind == '2d' else 'cube'}-{side} | {graph.n} | {graph.m} | "
                f"{lm['nit']} / {gn['nit']} / {gt['nit']} | {lm['per_iteration']:.3g}, {gt['per_iteration']:.3g} | "
                f"{lm['time'] / gt['time']:.2f} | {gn['time'] / gt['time']:.2f} | "
                f"{lm['per_iteration'] / gt['per_iteration']:.2f} | {mb} | {mratio} |",
                flush=True,
            )
    if args.plot:
        plot(rows, args.plot)
    if args.json:
        write_json(args.json, rows)


if __name__ == "__main__":
    main()
