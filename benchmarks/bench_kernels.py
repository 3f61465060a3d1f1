"""The SE(2)/SE(3) pose kernels on their three paths: native code, CasADi's virtual machine and
the NumPy array kernels (``manopt_lie/_kernels.py``), in one process (not a timed test).

For each group and batch size: the between factor's whitened residuals with both Jacobians
(``between_factor(…).residual(xi, xj, jac=True)``, a shared information matrix) and the
retraction of ``Power(LieGroupManifold(G), m)``. The paths run in alternation, ``--repeat``
rounds of ``--number`` calls (:func:`manopt_lie.bench.timing.interleaved`); the table gives µs
per call and each path's time over the array kernels'. The virtual machine runs only up to its
sizes (``VM_EDGES``, ``VM_POINTS``); without a C compiler there is no native row.

    python benchmarks/bench_kernels.py                  # sizes 11, 297, 10⁴, 10⁵
    python benchmarks/bench_kernels.py --sizes 11 192 --json kernels.json
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3, _kernels
from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import interleaved
from manopt_lie.factors import Information, between_factor
from manopt_lie.lie import LieGroup
from manopt_lie.manifolds import LieGroupManifold, Power

PATHS = _kernels.PATHS


@contextmanager
def path(name: str) -> Iterator[None]:
    """Send the kernels down one path while the block runs."""
    settings = _kernels.path_settings(name)
    saved = {key: getattr(_kernels, key) for key in settings}
    for key, value in settings.items():
        setattr(_kernels, key, value)
    try:
        yield
    finally:
        for key, value in saved.items():
            setattr(_kernels, key, value)


def cases(group: type[LieGroup], m: int, rng: np.random.Generator) -> dict[str, tuple[Callable[[], Any], int]]:
    """The timed calls and the size each path must not exceed to run (the machine's limits)."""
    xi, xj, z = (group.random(rng, (m,)) for _ in range(3))
    a = rng.standard_normal((group.dim, group.dim))
    factor = between_factor(np.c_[np.arange(m), np.arange(m, 2 * m)], z, Information(a @ a.T + np.eye(group.dim)))
    manifold = Power(LieGroupManifold(group), m)
    step = 0.1 * rng.standard_normal((m, group.dim))
    return {
        "between": (lambda: factor.residual(xi, xj, jac=True), _kernels.VM_EDGES),
        "retraction": (lambda: manifold.retr(xi, step), _kernels.VM_POINTS),
    }


def measure(sizes: list[int], repeat: int, number: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng(0)
    native = _kernels.native_kernel(SE3, "between") is not None
    rows = []
    for group in (SE2, SE3):
        for m in sizes:
            for kernel, (call, vm_limit) in cases(group, m, rng).items():
                names = [p for p in PATHS if (p != "native" or native) and (p != "machine" or m <= vm_limit)]
                calls = max(1, number * 1000 // m)

                def timed(p: str, call: Callable[[], Any] = call, calls: int = calls) -> Callable[[], None]:
                    def run() -> None:
                        with path(p):
                            for _ in range(calls):
                                call()
                    return run

                for p in names:  # warm up: build, compile or map each path once
                    timed(p)()
                results = interleaved([timed(p) for p in names], repeat)
                done = [(p, r) for p, r in zip(names, results, strict=True) if not isinstance(r, BaseException)]
                us = {p: 1e6 * r[0] / calls for p, r in done}
                rows.append({"group": group.__name__, "kernel": kernel, "m": m, "us": us,
                             "ratio": {p: us[p] / us["arrays"] for p in us}})  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[11, 297, 10_000, 100_000])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--number", type=int, default=20, help="calls per round for 1,000 elements (more for fewer)")
    parser.add_argument("--json", help="write the rows as JSON")
    args = parser.parse_args()
    rows = measure(args.sizes, args.repeat, args.number)
    print(f"µs per call, medians of {args.repeat} interleaved rounds; ratio = path / array kernels")
    print("| group | kernel | m | native µs | machine µs | arrays µs | native ratio | machine ratio |")
    print("|---|---|---|---|---|---|---|---|")
    def cell(values: dict[str, float], p: str, form: str) -> str:
        return form.format(values[p]) if p in values else "—"

    for r in rows:
        us, ratio = r["us"], r["ratio"]
        print(f"| {r['group']} | {r['kernel']} | {r['m']} | {cell(us, 'native', '{:.1f}')} | "
              f"{cell(us, 'machine', '{:.1f}')} | {us['arrays']:.1f} | {cell(ratio, 'native', '{:.2f}')} | "
              f"{cell(ratio, 'machine', '{:.2f}')} |")  # fmt: skip
    if args.json:
        write_json(args.json, rows)


if __name__ == "__main__":
    main()
