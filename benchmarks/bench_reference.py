"""Reference solutions: IPOPT (through CasADi) against our optimizers (not a timed test).

For synthetic instances of growing size and the shared SE-Sync datasets
(``$MANOPT_LIE_DATA`` or ``../shared/datasets``), pose graphs and rotation averaging,
chordal and geodesic costs, all from the chordal initialization:

- ``reference``: :func:`problems.reference.reference_solve` — building time, IPOPT's
  time, iterations and status, and the final cost (our definition, at the projected
  solution);
- ``ours``: ``TrustRegion()`` on the chordal cost, ``LevenbergMarquardt()`` on the
  geodesic one, default settings — time and final cost;
- ``rel``: ``(f_ours − f_ref)/f_ref``. Positive: ours stopped above the reference.

``--parametrization both`` runs quaternions and matrices side by side; ``--robust-study``
compares them on robust costs with 20 % outliers instead (the measurements behind the
default ``"auto"``, see ``docs/_casadi_reference.md``). Times are medians of ``--repeat``
runs. ``python benchmarks/bench_reference.py [--quick] [--json out.json]``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import median_time
from manopt_lie.optim import LevenbergMarquardt, TrustRegion
from manopt_lie.problems import g2o, rotation_averaging, synthetic
from manopt_lie.problems.catalogue import default_data_dir
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.reference import reference_solve
from manopt_lie.problems.rotation_averaging import RotationAveraging

Spec = PoseGraph | RotationAveraging


data_dir = default_data_dir


def dataset(name: str) -> Callable[[], Spec]:
    return lambda: g2o.read(data_dir() / f"{name}.g2o")


def rotations_of(name: str) -> Callable[[], Spec]:
    return lambda: rotation_averaging.from_pose_graph(g2o.read(data_dir() / f"{name}.g2o"))


# name: (make, quick?) — synthetic instances of growing size, then the datasets.
INSTANCES: dict[str, tuple[Callable[[], Spec], bool]] = {
    "grid2d 10x10": (lambda: synthetic.grid2d(10, 10, seed=0).graph, True),
    "grid2d 40x40": (lambda: synthetic.grid2d(40, 40, seed=0).graph, False),
    "cube 5": (lambda: synthetic.cube(5, seed=0).graph, True),
    "cube 12": (lambda: synthetic.cube(12, seed=0).graph, False),
    "torus 10x100": (lambda: synthetic.torus(10, 100, seed=0).graph, False),
    "SO(3) n=100": (lambda: synthetic.rotation_averaging(100, seed=0).graph, True),
    "SO(3) n=1000": (lambda: synthetic.rotation_averaging(1000, seed=0).graph, False),
    "SO(2) n=2000": (lambda: synthetic.rotation_averaging(2000, d=2, seed=0).graph, False),
    "smallGrid3D": (dataset("smallGrid3D"), True),
    "intel": (dataset("intel"), False),
    "manhattan": (dataset("manhattan"), False),
    "parking-garage": (dataset("parking-garage"), False),
    "sphere2500": (dataset("sphere2500"), False),
    "sphere2500 rotations": (rotations_of("sphere2500"), False),
}


def bench(name: str, spec: Spec, parametrizations: list[str], repeat: int) -> list[dict[str, Any]]:
    x0 = spec.chordal_initialization()
    rows = []
    for cost in ("chordal", "geodesic"):
        optimizer = TrustRegion() if cost == "chordal" else LevenbergMarquardt()
        ours_time, ours = median_time(lambda: optimizer.solve(spec.problem(cost), x0), repeat)
        for parametrization in parametrizations:
            _, ref = median_time(lambda: reference_solve(spec, x0, cost=cost, parametrization=parametrization), repeat)
            rows.append(
                {
                    "instance": name, "n": spec.n, "m": spec.m, "cost": cost, "parametrization": ref.parametrization,
                    "build": ref.build_time, "ipopt": ref.time, "iterations": ref.iterations, "status": ref.status,
                    "reference": ref.fun, "ours_solver": type(optimizer).__name__, "ours_time": ours_time,
                    "ours": ours.fun, "rel": (ours.fun - ref.fun) / abs(ref.fun),
                }
            )  # fmt: skip
            print(f"  {name} {cost} {ref.parametrization}: {ref.status} in {ref.time:.2f} s", flush=True)
    return rows


def robust_study() -> str:
    """Quaternions against matrices on robust instances (20 % outliers, chordal initialization):
    how often IPOPT succeeds, its total time and median iterations, per problem class."""
    instances = (
        [synthetic.grid2d(8, 8, loop_closure_probability=0.5, outlier_rate=0.2, seed=s) for s in (3, 4)]
        + [synthetic.cube(4, loop_closure_probability=0.5, outlier_rate=0.2, seed=s) for s in (1, 2, 3)]
        + [synthetic.rotation_averaging(60, outlier_rate=0.2, seed=s) for s in (1, 2)]
        + [synthetic.rotation_averaging(60, d=2, outlier_rate=0.2, seed=1)]
    )
    stats: dict[tuple[str, str], list[Any]] = {}
    for inst in instances:
        spec, x0 = inst.graph, inst.graph.chordal_initialization()
        kind = f"{'pose graph' if isinstance(spec, PoseGraph) else 'rotation averaging'} {spec.d}-D"
        for cost in ("chordal", "geodesic"):
            for robust in ("huber:3.0", "cauchy:3.0", "l1:1.0"):
                for parametrization in ("quaternion", "matrix"):
                    ref = reference_solve(spec, x0, cost=cost, robust=robust, parametrization=parametrization)
                    entry = stats.setdefault((kind, parametrization), [0, 0, 0.0, []])
                    entry[0] += 1
                    entry[1] += ref.success
                    entry[2] += ref.time
                    entry[3].append(ref.iterations)
    lines = ["| problems | rotations | solved | IPOPT total (s) | median iterations |", "|---|---|---|---|---|"]
    for (kind, parametrization), (count, ok, seconds, iterations) in stats.items():
        lines.append(f"| {kind} | {parametrization} | {ok}/{count} | {seconds:.1f} | {np.median(iterations):.0f} |")
    return "\n".join(lines)


def table(rows: list[dict[str, Any]]) -> str:
    header = (
        "| instance | n | m | cost | rotations | build (s) | IPOPT (s) | iters | status | reference cost "
        "| ours | ours (s) | ours cost | rel |"
    )
    lines = [header, "|---" * (header.count("|") - 1) + "|"]
    for r in rows:
        lines.append(
            f"| {r['instance']} | {r['n']} | {r['m']} | {r['cost']} | {r['parametrization']} | {r['build']:.2f} | "
            f"{r['ipopt']:.2f} | {r['iterations']} | {r['status']} | {r['reference']:.10g} | "
            f"{'TR' if r['ours_solver'] == 'TrustRegion' else 'LM'} | {r['ours_time']:.2f} | {r['ours']:.10g} | "
            f"{r['rel']:.1e} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--instances", nargs="*", choices=list(INSTANCES), help="default: all (or the quick ones)")
    parser.add_argument("--quick", action="store_true", help="only the small instances")
    parser.add_argument("--parametrization", choices=["auto", "quaternion", "matrix", "both"], default="auto")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    parser.add_argument("--robust-study", action="store_true", help="compare parametrizations on robust costs instead")
    args = parser.parse_args()
    if args.robust_study:
        print(robust_study())
        return
    names = args.instances or [k for k, (_, quick) in INSTANCES.items() if quick or not args.quick]
    parametrizations = ["quaternion", "matrix"] if args.parametrization == "both" else [args.parametrization]
    rows: list[dict[str, Any]] = []
    for name in names:
        try:
            spec = INSTANCES[name][0]()
        except FileNotFoundError as err:
            print(f"  skipping {name}: {err}")
            continue
        rows += bench(name, spec, parametrizations, args.repeat)
    print(table(rows))
    if args.json:
        write_json(args.json, rows, datasets=sorted(data_dir().glob("*.g2o")))


if __name__ == "__main__":
    main()
