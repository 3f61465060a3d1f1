"""Pose-graph benchmark on the shared SE-Sync datasets (not a timed test).

For each dataset (``$MANOPT_LIE_DATA`` or ``../shared/datasets``):

- ``TrustRegion`` on the chordal (SE-Sync) cost from the chordal initialization:
  iterations, time, final cost, the published optimum f* and the relative gap
  to its printed four digits, and the ratio of our time (initialization plus
  solve) to the C++ SE-Sync time the datasets README lists;
- ``LevenbergMarquardt`` and ``GaussNewton`` on the geodesic cost from the same
  initialization, and GTSAM's ``LevenbergMarquardtOptimizer`` in the same run
  when ``gtsam`` is installed (optional), all stopped by GTSAM's default rule
  (relative decrease of the cost below 1e-5) and all final costs evaluated with
  our definition; the ratio is our solve time over GTSAM's (both start from
  the same chordal initialization, whose time is listed apart);
- the CasADi/IPOPT reference (``problems.reference``) on both costs, run once:
  its final costs check ours independently.

Times are medians of ``--repeat`` runs. ``python benchmarks/bench_pose_graph.py [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from manopt_lie.bench import peers
from manopt_lie.bench.timing import median_time
from manopt_lie.optim import GaussNewton, LevenbergMarquardt, TrustRegion
from manopt_lie.problems import catalogue, g2o
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.reference import reference_solve

# name: (published chordal f*, SE-Sync C++ time in s), from the catalogue (datasets/README.md).
DATASETS = {e.name: (e.published.get("chordal"), e.reference_time) for e in catalogue.DATASETS[:-1]}  # no tinyGrid3D
GTSAM_RULE = 1e-5  # GTSAM's default relativeErrorTol
data_dir = catalogue.default_data_dir


def gtsam_lm(graph: PoseGraph, x0: Any, repeat: int) -> tuple[float, int, Any] | None:
    """GTSAM's LM from ``x0`` with the anchor constrained (:mod:`benchmarks.peers`, GTSAM's
    default rule): median solve time of ``repeat`` runs, iterations, poses; ``None`` without gtsam."""
    if not peers.available("gtsam-lm"):
        return None
    runs = [peers.solve("gtsam-lm", graph, x0, rel_cost_decrease=GTSAM_RULE) for _ in range(repeat)]
    return float(np.median([run.time for run in runs])), runs[-1].nit, runs[-1].x


def bench(name: str, repeat: int) -> list[dict[str, Any]]:
    path = data_dir() / f"{name}.g2o"
    graph = g2o.read(path)
    published, se_sync_time = DATASETS[name]
    init_time, x0 = median_time(graph.chordal_initialization, repeat)
    rows: list[dict[str, Any]] = []
    base = {"dataset": name, "n": graph.n, "m": graph.m}

    seconds, res = median_time(lambda: TrustRegion().solve(graph.problem("chordal"), x0), repeat)
    rows.append(
        base
        | {
            "solver": "TR (chordal)", "iterations": res.nit, "init": init_time, "time": seconds, "cost": res.fun,
            "f*": published, "gap": None if published is None else (res.fun - published) / published,
            "reference": "SE-Sync C++", "ratio": None if se_sync_time is None else (seconds + init_time) / se_sync_time,
        }
    )  # fmt: skip
    peer = gtsam_lm(graph, x0, repeat)
    for optimizer in (LevenbergMarquardt(rel_cost_decrease=GTSAM_RULE), GaussNewton(rel_cost_decrease=GTSAM_RULE)):
        seconds, res = median_time(lambda: optimizer.solve(graph.problem("geodesic"), x0), repeat)
        rows.append(
            base
            | {
                "solver": f"{type(optimizer).__name__} (geodesic)", "iterations": res.nit, "init": init_time,
                "time": seconds, "cost": res.fun, "f*": None, "gap": None, "reference": "GTSAM LM",
                "ratio": None if peer is None else seconds / peer[0],
            }
        )  # fmt: skip
    for cost in ("chordal", "geodesic"):  # the independent IPOPT reference (CasADi), once: it is slow
        ref = reference_solve(graph, x0, cost=cost)
        rows.append(
            base
            | {
                "solver": f"IPOPT reference ({cost})", "iterations": ref.iterations, "init": init_time,
                "time": ref.time, "cost": ref.fun, "f*": published if cost == "chordal" else None,
                "gap": None if published is None or cost != "chordal" else (ref.fun - published) / published,
                "reference": None, "ratio": None,
            }
        )  # fmt: skip
    if peer is not None:
        seconds, iterations, poses = peer
        rows.append(
            base
            | {
                "solver": "GTSAM LM (geodesic)", "iterations": iterations, "init": init_time, "time": seconds,
                "cost": graph.cost(poses, "geodesic"), "f*": None, "gap": None, "reference": None, "ratio": None,
            }
        )  # fmt: skip
    return rows


def fmt(value: Any, spec: str) -> str:
    return "—" if value is None else format(value, spec)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="*", default=list(DATASETS), choices=list(DATASETS))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    args = parser.parse_args()
    if not data_dir().is_dir():
        raise SystemExit(f"datasets not found at {data_dir()} (set MANOPT_LIE_DATA)")
    rows = [row for name in args.datasets for row in bench(name, args.repeat)]
    header = "| dataset | n | m | solver | iters | init (s) | solve (s) | final cost | f* | gap | ratio |"
    print(header)
    print("|---" * (header.count("|") - 1) + "|")
    for r in rows:
        ratio = "—" if r["ratio"] is None else f"{r['ratio']:.2f} vs {r['reference']}"
        print(
            f"| {r['dataset']} | {r['n']} | {r['m']} | {r['solver']} | {r['iterations']} | {r['init']:.3f} | "
            f"{r['time']:.3f} | {r['cost']:.7g} | {fmt(r['f*'], '.4g')} | {fmt(r['gap'], '.1e')} | {ratio} |"
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
