"""Single elements and small batches: manopt_lie against GTSAM's Python wrapper, op by op.

Run from the repository root::

    python benchmarks/bench_small.py               # tables of µs per call and ratios
    python benchmarks/bench_small.py --json out.json

Every case times ``--number`` calls of ours and of GTSAM's equivalent in alternation, for
``--repeat`` rounds (:func:`manopt_lie.bench.timing.interleaved`), and reports the medians per call
and the ratio ours/GTSAM. The headline is the chain ``exp → compose → log(jac=True)`` of one SE(3)
element against ``gtsam.Pose3.Expmap(ξ)``, ``a.compose(b)``, ``gtsam.Pose3.Logmap(c, H)`` (goal: ≤ 20×).
Then the single-element costs of SO(3), SE(2), SE(3) ``exp``, ``log``, ``compose``, ``act``,
``rplus(jac)``, ``rminus(jac)``, ``jr``, ``jr_inv`` next to GTSAM's (``Expmap``, ``Logmap``,
``compose``, ``rotate``/``transformFrom`` (no Jacobians), ``retract``/``localCoordinates`` with Jacobians where the
wrapper has them, else ``Expmap``/``Logmap`` with theirs, ``ExpmapDerivative``,
``LogmapDerivative``), and the cost of small batches (ours, one call) against a Python loop of GTSAM
calls. Tangents are ``(ρ, θ)`` for us and ``(ω, v)`` for GTSAM: the same motion in both.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3, SO3
from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import interleaved

try:
    import gtsam
except ImportError:  # pragma: no cover - the tables then show our times only
    gtsam = None

GOAL = 20.0


def per_call(fns: list[Callable[[], Any]], number: int, repeat: int) -> list[float]:
    """Median µs per call of each function, ``number`` calls per round, rounds interleaved."""

    def loop(f: Callable[[], Any]) -> Callable[[], None]:
        def run() -> None:
            for _ in range(number):
                f()

        return run

    results = interleaved([loop(f) for f in fns], repeat)
    out = []
    for r in results:
        if isinstance(r, BaseException):
            raise r
        out.append(1e6 * r[0] / number)
    return out


def _swap(xi: np.ndarray) -> np.ndarray:
    """``(ρ, θ)`` ↔ ``(θ, ρ)``: our SE(3)/SE(2) tangent order against GTSAM's."""
    k = len(xi) // 2 if len(xi) == 6 else 2
    return np.r_[xi[k:], xi[:k]]


def cases(rng: np.random.Generator) -> dict[str, dict[str, tuple[Callable[[], Any], Callable[[], Any] | None]]]:
    """``{group: {op: (ours, gtsam's)}}`` on fixed random single elements."""
    out: dict[str, dict[str, tuple[Callable[[], Any], Callable[[], Any] | None]]] = {}
    for group in (SO3, SE2, SE3):
        tau, sigma = 0.8 * rng.standard_normal(group.dim), 0.8 * rng.standard_normal(group.dim)
        p = rng.standard_normal(group.point_dim)
        x, y = group.exp(tau), group.exp(sigma)
        ours: dict[str, Callable[[], Any]] = {
            "exp": lambda g=group, t=tau: g.exp(t),
            "log": lambda x=x: x.log(),
            "compose": lambda x=x, y=y: x.compose(y),
            "act": lambda x=x, p=p: x.act(p),
            "rplus(jac)": lambda x=x, s=sigma: x.rplus(s, jac=True),
            "rminus(jac)": lambda x=x, y=y: y.rminus(x, jac=True),
            "jr": lambda g=group, t=tau: g.jr(t),
            "jr_inv": lambda g=group, t=tau: g.jr_inv(t),
        }
        theirs: dict[str, Callable[[], Any] | None] = dict.fromkeys(ours)
        if gtsam is not None:
            theirs = _gtsam_cases(group, tau, sigma, p)
        out[group.__name__] = {op: (ours[op], theirs[op]) for op in ours}
    return out


def _gtsam_cases(group: type, tau: np.ndarray, sigma: np.ndarray, p: np.ndarray) -> dict[str, Callable[[], Any]]:
    n = group.dim
    h1, h2 = np.zeros((n, n), order="F"), np.zeros((n, n), order="F")
    if group is SO3:
        cls, t, s = gtsam.Rot3, tau, sigma
        a, b = cls.Expmap(t), cls.Expmap(s)
        act = lambda: a.rotate(p)
        # No Jacobian variants of Rot3.retract/localCoordinates in the wrapper: Expmap/Logmap with theirs.
        rplus = lambda: a.compose(cls.Expmap(s, h2))
        rminus = lambda: cls.Logmap(a.between(b), h1)
    else:
        cls = gtsam.Pose2 if group is SE2 else gtsam.Pose3
        t, s = _swap(tau), _swap(sigma)
        a, b = cls.Expmap(t), cls.Expmap(s)
        act = lambda: a.transformFrom(p)
        rplus = lambda: a.retract(s, h1, h2)
        rminus = lambda: a.localCoordinates(b, h1, h2)
    return {
        "exp": lambda: cls.Expmap(t),
        "log": lambda: cls.Logmap(a),
        "compose": lambda: a.compose(b),
        "act": act,
        "rplus(jac)": rplus,
        "rminus(jac)": rminus,
        "jr": lambda: cls.ExpmapDerivative(t),
        "jr_inv": lambda: cls.LogmapDerivative(t),
    }


def bench_chain(rng: np.random.Generator, number: int, repeat: int) -> dict[str, Any]:
    """One SE(3) element through ``exp → compose → log(jac=True)``, both libraries."""
    xi = rng.standard_normal(6)
    b = SE3.exp(rng.standard_normal(6))
    fns: list[Callable[[], Any]] = [lambda: SE3.exp(xi).compose(b).log(jac=True)]
    if gtsam is not None:
        gb, gxi, h = gtsam.Pose3(b.as_matrix()), _swap(xi), np.zeros((6, 6), order="F")
        fns.append(lambda: gtsam.Pose3.Logmap(gtsam.Pose3.Expmap(gxi).compose(gb), h))
        # The chain computes the same thing in both (up to the tangent order).
        tau, j = fns[0]()
        perm = np.r_[3:6, 0:3]
        assert np.allclose(_swap(tau), fns[1]().ravel()) and np.allclose(j[np.ix_(perm, perm)], h)
    times = per_call(fns, number, repeat)
    row = {"chain": "SE3 exp→compose→log(jac)", "ours_us": times[0]}
    if gtsam is not None:
        row.update(gtsam_us=times[1], ratio=times[0] / times[1], goal=GOAL)
    return row


def bench_ops(rng: np.random.Generator, number: int, repeat: int) -> list[dict[str, Any]]:
    rows = []
    for group, ops in cases(rng).items():
        for op, (ours, theirs) in ops.items():
            times = per_call([ours] if theirs is None else [ours, theirs], number, repeat)
            row: dict[str, Any] = {"group": group, "op": op, "ours_us": times[0]}
            if theirs is not None:
                row.update(gtsam_us=times[1], ratio=times[0] / times[1])
            rows.append(row)
    return rows


def bench_batches(rng: np.random.Generator, sizes: list[int], number: int, repeat: int) -> list[dict[str, Any]]:
    """SE(3) ``exp``, ``compose``, ``log(jac=True)`` on batches of ``n``: one call of ours against a
    Python loop of ``n`` GTSAM calls."""
    rows = []
    for n in sizes:
        tau = rng.standard_normal((n, 6))
        x, y = SE3.exp(tau), SE3.exp(rng.standard_normal((n, 6)))
        ours = {"exp": lambda: SE3.exp(tau), "compose": lambda: x.compose(y), "log(jac)": lambda: x.log(jac=True)}
        theirs: dict[str, Callable[[], Any]] = {}
        if gtsam is not None:
            gt = [_swap(t) for t in tau]
            gx, gy = [gtsam.Pose3(m) for m in x.as_matrix()], [gtsam.Pose3(m) for m in y.as_matrix()]
            h = np.zeros((6, 6), order="F")
            theirs = {
                "exp": lambda: [gtsam.Pose3.Expmap(t) for t in gt],
                "compose": lambda: [a.compose(b) for a, b in zip(gx, gy, strict=True)],
                "log(jac)": lambda: [gtsam.Pose3.Logmap(a, h) for a in gx],
            }
        for op, f in ours.items():
            times = per_call([f] + ([theirs[op]] if theirs else []), max(1, number // n), repeat)
            row: dict[str, Any] = {"n": n, "op": op, "ours_us": times[0], "ours_us_per_element": times[0] / n}
            if theirs:
                row.update(gtsam_loop_us=times[1], ratio=times[0] / times[1])
            rows.append(row)
    return rows


def print_table(title: str, rows: list[dict[str, Any]]) -> None:
    keys = list(dict.fromkeys(k for row in rows for k in row))
    fmt = {k: (".2f" if k in ("ratio", "goal") else ".1f" if k.endswith("us") or "us_" in k else "") for k in keys}
    print(f"\n{title}")
    print("  ".join(f"{k:>22}" for k in keys))
    for row in rows:
        print("  ".join(f"{format(row[k], fmt[k]) if k in row else '':>22}" for k in keys))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--number", type=int, default=200, help="calls per timed round (default 200)")
    parser.add_argument("--repeat", type=int, default=31, help="interleaved rounds (median reported; default 31)")
    parser.add_argument("--sizes", type=int, nargs="*", default=[1, 4, 16, 32], help="small batch sizes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    if gtsam is None:
        print("gtsam is not installed: our times only", file=sys.stderr)

    chain = bench_chain(rng, args.number, args.repeat)
    print_table(f"One SE(3) element, median of {args.repeat} interleaved rounds of {args.number} calls", [chain])
    if "ratio" in chain:
        verdict = "meets" if chain["ratio"] <= GOAL else "MISSES"
        print(f"chain ratio {chain['ratio']:.1f}x GTSAM: {verdict} the goal of {GOAL:g}x")
    ops = bench_ops(rng, args.number, args.repeat)
    print_table("Single elements: µs per call", ops)
    batches = bench_batches(rng, args.sizes, args.number, args.repeat)
    print_table("Small SE(3) batches: one call of ours against a Python loop of GTSAM calls", batches)
    if args.json:
        write_json(args.json, {"chain": chain, "ops": ops, "batches": batches})
    return 0


if __name__ == "__main__":
    sys.exit(main())
