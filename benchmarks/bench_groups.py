"""SO(3) kernels on 10⁶ elements against SciPy's compiled ``Rotation``, in one process.

Run from the repository root::

    python benchmarks/bench_groups.py            # table of times and ratios
    python benchmarks/bench_groups.py --json out.json

For each operation the median of ``--repeat`` runs is reported for manopt_lie
and for SciPy (``Rotation.from_rotvec / as_rotvec / * / apply``), with the ratio
ours/SciPy (goal: ≤ 1.5). A per-element Python loop over ``--loop-n`` elements
shows what vectorization buys. A second table gives the throughput of every
group's batched operations; a third compares Sim3, SE23, Sim2, S3 and a Bundle with SE3 at
``--new-n`` elements (default 10⁶), with ratios.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from manopt_lie import S3, SE2, SE3, SE23, SO2, SO3, Bundle, Rn, Sim2, Sim3
from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import median_time


def seconds(f: Callable[[], Any], repeat: int) -> float:
    """Median wall time of ``repeat`` calls, after one warm-up call."""
    return median_time(f, repeat, warmup=1)[0]


def bench_against_scipy(n: int, loop_n: int, repeat: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    tau = rng.standard_normal((n, 3))
    tau2 = rng.standard_normal((n, 3))
    p = rng.standard_normal((n, 3))
    x, y = SO3.exp(tau), SO3.exp(tau2)
    r, r2 = Rotation.from_rotvec(tau), Rotation.from_rotvec(tau2)
    cases: list[tuple[str, Callable[[], Any], Callable[[], Any], Callable[[int], Any]]] = [
        ("exp", lambda: SO3.exp(tau), lambda: Rotation.from_rotvec(tau), lambda i: SO3.exp(tau[i])),
        ("log", lambda: x.log(), lambda: r.as_rotvec(), lambda i: x[i].log()),
        ("compose", lambda: x @ y, lambda: r * r2, lambda i: x[i] @ y[i]),
        ("act", lambda: x.act(p), lambda: r.apply(p), lambda i: x[i].act(p[i])),
    ]
    rows = []
    # Our exp returns the rotation matrix; SciPy's from_rotvec stops at a quaternion.
    matrix_ms = 1e3 * seconds(lambda: Rotation.from_rotvec(tau).as_matrix(), repeat)
    for name, ours, theirs, one in cases:
        t_ours = seconds(ours, repeat)
        t_scipy = seconds(theirs, repeat)
        t_loop = seconds(lambda: [one(i) for i in range(loop_n)], max(1, repeat // 2)) / loop_n
        rows.append(
            {
                "op": name,
                "n": n,
                "ours_ms": 1e3 * t_ours,
                "scipy_ms": 1e3 * t_scipy,
                "ratio": t_ours / t_scipy,
                "loop_us_per_element": 1e6 * t_loop,
                "vectorized_speedup": t_loop * n / t_ours,
            }
        )
    rows[0]["ratio_vs_scipy_to_matrix"] = rows[0]["ours_ms"] / matrix_ms
    return rows


def bench_all_groups(n: int, repeat: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    rows = []
    for group in (SO2, SO3, SE2, SE3, Rn(3)):
        tau = rng.standard_normal((n, group.dim))
        x, y = group.exp(tau), group.random(rng, (n,))
        p = rng.standard_normal((n, group.point_dim))
        ops = {
            "exp": lambda: group.exp(tau),
            "log": lambda: x.log(),
            "compose": lambda: x @ y,
            "act": lambda: x.act(p),
            "rminus": lambda: y.rminus(x),
            "rminus+jac": lambda: y.rminus(x, jac=True),
        }
        row = {"group": group.__name__, "n": n}
        row.update({f"{k}_ns": 1e9 * seconds(f, repeat) / n for k, f in ops.items()})
        rows.append(row)
    return rows


def bench_new_groups(n: int, repeat: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    """Sim3, Sim2, SE23, S3 and a Bundle against SE3 at ``n`` elements: ns per element, ratio to SE3."""
    rows: list[dict[str, Any]] = []
    for group in (SE3, Sim3, SE23, Sim2, S3, Bundle(SO3, Rn(3))):
        tau = 0.5 * rng.standard_normal((n, group.dim))
        x, y = group.exp(tau), group.random(rng, (n,))
        p = rng.standard_normal((n, group.point_dim))
        ops = {
            "exp": lambda: group.exp(tau),
            "log": lambda: x.log(),
            "compose": lambda: x @ y,
            "act": lambda: x.act(p),
            "jr": lambda: group.jr(tau),
        }
        row: dict[str, Any] = {"group": group.__name__, "n": n}
        row.update({f"{k}_ns": 1e9 * seconds(f, repeat) / n for k, f in ops.items()})
        rows.append(row)
    for row in rows:
        for k in ("exp", "log", "compose", "act", "jr"):
            row[f"{k}/SE3"] = row[f"{k}_ns"] / rows[0][f"{k}_ns"]
    return rows


def print_table(title: str, rows: list[dict[str, Any]], fmt: dict[str, str]) -> None:
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        print(f"\n{title}")
        keys = list(dict.fromkeys(k for row in rows for k in row))
        print("  ".join(f"{k:>14}" for k in keys))
        for row in rows:
            print("  ".join(f"{format(row[k], fmt.get(k, '')) if k in row else '':>14}" for k in keys))
        return
    keys = list(dict.fromkeys(k for row in rows for k in row))
    table = Table(title=title)
    for key in keys:
        table.add_column(key, justify="right")
    for row in rows:
        table.add_row(*(format(row[k], fmt.get(k, "")) if k in row else "" for k in keys))
    Console().print(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=1_000_000, help="batch size (default 10^6)")
    parser.add_argument("--loop-n", type=int, default=10_000, help="elements in the per-element Python loop")
    parser.add_argument("--repeat", type=int, default=7, help="timed runs per case (median reported)")
    parser.add_argument("--new-n", type=int, default=1_000_000, help="batch size of the Sim3/SE23 vs SE3 table")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)

    vs_scipy = bench_against_scipy(args.n, args.loop_n, args.repeat, rng)
    print_table(
        f"SO(3), {args.n:,} elements: manopt_lie vs scipy Rotation (median of {args.repeat})",
        vs_scipy,
        {
            "ours_ms": ".1f",
            "scipy_ms": ".1f",
            "ratio": ".2f",
            "ratio_vs_scipy_to_matrix": ".2f",
            "loop_us_per_element": ".1f",
            "vectorized_speedup": ".0f",
        },
    )
    groups = bench_all_groups(args.n // 10, args.repeat, rng)
    print_table(
        f"All groups, {args.n // 10:,} elements: ns per element", groups, {k: ".0f" for k in groups[0] if k != "group"}
    )
    new = bench_new_groups(args.new_n, max(1, args.repeat // 2), rng)
    print_table(
        f"Sim3, SE23, Sim2, S3, Bundle(SO3, R3) vs SE3, {args.new_n:,} elements: ns per element, ratio to SE3",
        new,
        {k: (".2f" if "/" in k else ".0f") for k in new[0] if k != "group"},
    )
    if args.json:
        write_json(args.json, {"vs_scipy": vs_scipy, "groups": groups, "new_groups": new})
    return 0


if __name__ == "__main__":
    sys.exit(main())
