"""Instructions per Levenberg-Marquardt solve, ours against GTSAM's, counted by Valgrind.

Run from the repository root (needs ``valgrind`` on the PATH; GTSAM for its column)::

    python benchmarks/bench_instructions.py                      # tinyGrid3D, 40 solves each
    python benchmarks/bench_instructions.py --dataset smallGrid3D --solves 10 --json out.json

Wall-clock ratios on small problems move by 10–30 % with the machine's speed; an instruction
count does not (with one BLAS thread and a fixed hash seed it repeats to 0.2 %), so it tells
whether a change to a small system's path removed work. Each solver runs in a child process under
``valgrind --tool=cachegrind`` twice — building ``solves`` problems (or GTSAM factor graphs) and
solving none or all of them after one warm-up solve — and the difference over ``solves`` is the
count per solve: the problem's construction and the imports cancel. Ours is
``LevenbergMarquardt(rel_cost_decrease=1e-5).solve``, GTSAM's the construction of its
``LevenbergMarquardtOptimizer`` and ``optimize()`` (what ``bench_pose_graph.py`` times of each),
both from the chordal initialization with the pools of structures and analyses emptied before each of ours.

Instructions are not time: interpreted code retires fewer per cycle than compiled C++ (on
tinyGrid3D the Python loop ran ~2.2× GTSAM's instructions in ~4× its time; the compiled small-system
loop now runs 0.83× in ~0.8×), but fewer instructions on the same path are less time.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from typing import Any

from manopt_lie.bench.report import write_json

SOLVERS = ("ours", "gtsam")


def worker(solver: str, dataset: str, solves: int, count: int) -> None:
    """Build ``solves`` problems, warm up with one solve, then solve ``count`` of them."""
    from manopt_lie.bench import peers
    from manopt_lie.linalg import clear_caches
    from manopt_lie.optim import LevenbergMarquardt
    from manopt_lie.problems import catalogue, g2o

    graph = g2o.read(catalogue.default_data_dir() / f"{dataset}.g2o")
    x0 = graph.chordal_initialization()
    if solver == "ours":
        problems = [graph.problem("geodesic") for _ in range(solves + 1)]

        def solve(k: int) -> None:
            clear_caches()
            LevenbergMarquardt(rel_cost_decrease=1e-5).solve(problems[k], x0)

    else:
        import gtsam

        built = [peers.gtsam_problem(gtsam, graph, x0) for _ in range(solves + 1)]
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-5)

        def solve(k: int) -> None:
            gtsam.LevenbergMarquardtOptimizer(*built[k], params).optimize()

    solve(solves)  # the warm-up: first calls' caches, native kernels loaded
    for k in range(count):
        solve(k)


def instructions(solver: str, dataset: str, solves: int, count: int) -> int:
    """Valgrind's instruction count of one worker process."""
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    command = ["valgrind", "--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null",
               sys.executable, __file__, "--worker", solver, "--dataset", dataset, "--solves", str(solves),
               "--count", str(count)]  # fmt: skip
    run = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    found = re.search(r"I\s+refs:\s+([\d,]+)", run.stderr)
    if run.returncode or found is None:
        raise RuntimeError(f"{solver}: valgrind failed ({run.returncode}):\n{run.stderr[-2000:]}")
    return int(found.group(1).replace(",", ""))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", default="tinyGrid3D", help="a dataset of the data directory (default tinyGrid3D)")
    parser.add_argument("--solves", type=int, default=40, help="solves counted per solver (default 40)")
    parser.add_argument("--json", metavar="PATH", help="also write the counts as JSON")
    parser.add_argument("--worker", choices=SOLVERS, help=argparse.SUPPRESS)
    parser.add_argument("--count", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.worker, args.dataset, args.solves, args.count)
        return 0
    if shutil.which("valgrind") is None:
        print("bench_instructions: valgrind is not on the PATH", file=sys.stderr)
        return 1
    from manopt_lie.bench import peers

    rows: list[dict[str, Any]] = []
    for solver in SOLVERS if peers.available("gtsam-lm") else SOLVERS[:1]:
        base, total = (instructions(solver, args.dataset, args.solves, c) for c in (0, args.solves))
        rows.append({"solver": solver, "dataset": args.dataset, "instructions": (total - base) / args.solves})
    for row in rows:
        print(f"{row['solver']:6s} {row['dataset']}: {row['instructions'] / 1e6:.3f} M instructions per solve")
    if len(rows) == 2:
        print(f"ours / GTSAM: {rows[0]['instructions'] / rows[1]['instructions']:.2f}")
    if args.json:
        write_json(args.json, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
