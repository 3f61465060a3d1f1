"""Certifiably optimal pose graphs and rotation averaging: our staircase against SE-Sync (C++)
and GTSAM's Shonan averaging (not a timed test).

For each SE-Sync dataset (``$MANOPT_LIE_DATA`` or ``../shared/datasets``), one process, one
solver at a time, medians of ``--repeat`` runs:

- **pose graphs**: ``staircase`` from the chordal initialization and from a random one (rank
  ``d``, and rank 5 as SE-Sync), timed from the graph to the certified poses (the reduced
  data, the initialization and every certificate included; reading the file excluded);
  against SE-Sync's C++ solver (``/work/shared/tools/sesync_cpp.sh`` builds it; ``--sesync``
  names the ``SE-Sync-bench`` binary; single-threaded, its ``construct_s + total_s``: the
  same span), from its chordal and its random initialization;
- **rotation averaging** (the rotations of each pose graph, SE-Sync's ``κ``): ``staircase``
  against ``gtsam.ShonanAveraging2/3`` (optional peer) from the same initial rotations (our
  chordal initialization; the same random rotations), Shonan's noise models ``σ² = 1/(2κ)``
  so that its cost is ours; GTSAM's results are certified by ``certify``. Both start from
  given rotations (the chordal initialization is computed outside the timing).

Competitors run in turn, ``--repeat`` rounds (other load hits them alike), but for Shonan
from random rotations (minutes per run: ``--peer-repeat`` runs); Shonan's problem is built
outside its timing, ours inside. Reported: time, cost, certified or not, rank, the
certificate's share of our time, and the ratios (ours / theirs).

``python benchmarks/bench_certifiable.py [--repeat 5] [--kinds pose-graphs rotations] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from manopt_lie import SO2, SO3
from manopt_lie.bench.report import write_json
from manopt_lie.problems import catalogue, g2o, rotation_averaging
from manopt_lie.problems.certify import certify, staircase

NAMES = ["CSAIL", "intel", "manhattan", "sphere2500", "parking-garage", "smallGrid3D"]
SESYNC = Path(os.environ.get("SESYNC_BIN", "/tmp/sesync/build/bin/SE-Sync-bench"))


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def ours(graph: Any, x0: Any, rank: int | None, seed: int) -> dict[str, Any]:
    """One staircase timed from the graph: data, initialization, solve, certificates."""
    start = time.perf_counter()
    result = staircase(graph, graph.chordal_initialization() if x0 == "chordal" else x0, rank=rank, seed=seed)
    return {
        "time": time.perf_counter() - start, "fun": result.fun, "optimal": result.optimal, "rank": result.rank,
        "levels": len(result.levels), "iterations": result.iterations,
        "cert_share": result.time_certificates / result.time, "status": result.status.name,
    }  # fmt: skip


def sesync(path: Path, init: str) -> dict[str, Any] | None:
    """One run of SE-Sync's C++ solver, single-threaded: its own ``construct_s + total_s``."""
    if not SESYNC.is_file():
        return None
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([str(SESYNC), str(path), init, "1", "-", "-"], capture_output=True, text=True, env=env)
    line = next((x for x in out.stdout.splitlines() if x.startswith("BENCH_RESULT")), "")
    fields = dict(re.findall(r"(\w+)=(\S+)", line))
    return {
        "time": float(fields["construct_s"]) + float(fields["total_s"]), "fun": float(fields["Fxhat"]),
        "optimal": fields["certified"] == "1",
    }  # fmt: skip


def interleaved_runs(runs: list[Any], repeat: int) -> list[dict[str, Any] | None]:
    """``repeat`` rounds of the competitors in turn (other load hits them alike); per
    competitor its last run's record with the median time."""
    records: list[list[dict[str, Any]]] = [[] for _ in runs]
    for _ in range(repeat):
        for i, run in enumerate(runs):
            out = run()
            if out is not None:
                records[i].append(out)
    return [{**r[-1], "time": float(np.median([x["time"] for x in r]))} if r else None for r in records]


def shonan(ra: Any, rotations: np.ndarray) -> Any:
    """One run of GTSAM's Shonan averaging from the given rotations (its ``run``, the problem
    built beforehand, untimed); its result certified by ours. ``None`` without GTSAM."""
    try:
        import gtsam
    except ImportError:
        return None
    d, sigma = ra.d, 1.0 / np.sqrt(2.0 * ra.kappa)
    z = ra.measurements.as_matrix()
    lm = gtsam.LevenbergMarquardtParams.CeresDefaults()
    if d == 3:
        measurements = gtsam.BinaryMeasurementsRot3()
        for (i, j), zij, s in zip(ra.edges, z, sigma, strict=True):
            noise = gtsam.noiseModel.Isotropic.Sigma(3, float(s))
            measurements.append(gtsam.BinaryMeasurementRot3(int(i), int(j), gtsam.Rot3(zij), noise))
        problem = gtsam.ShonanAveraging3(measurements, gtsam.ShonanAveragingParameters3(lm))
    else:
        factors = [
            gtsam.BetweenFactorPose2(
                int(i), int(j), gtsam.Pose2(0.0, 0.0, float(np.arctan2(zij[1, 0], zij[0, 0]))),
                gtsam.noiseModel.Isotropic.Sigma(3, float(s)),
            )
            for (i, j), zij, s in zip(ra.edges, z, sigma, strict=True)
        ]  # fmt: skip
        problem = gtsam.ShonanAveraging2(factors, gtsam.ShonanAveragingParameters2(lm))
    initial = gtsam.Values()
    for k, r in enumerate(rotations):
        initial.insert(k, gtsam.Rot3(r) if d == 3 else gtsam.Rot2.fromCosSin(r[0, 0], r[1, 0]))

    def run() -> dict[str, Any]:
        start = time.perf_counter()
        try:
            values, min_eig = problem.run(initial, d, 10)
        except RuntimeError as err:  # e.g. "Shonan::run did not converge for given max_p"
            return {"time": time.perf_counter() - start, "fun": float("nan"), "optimal": False, "failed": str(err)}
        elapsed = time.perf_counter() - start
        at = values.atRot3 if d == 3 else values.atRot2
        estimate = np.stack([at(k).matrix() for k in range(ra.n)])
        cert = certify(ra, (SO3 if d == 3 else SO2).from_matrix(estimate, project=True))
        return {"time": elapsed, "fun": cert.fun, "optimal": cert.optimal, "min_eig": float(min_eig), "gap": cert.gap}

    return run


def _fmt(entry: dict[str, Any] | None) -> str:
    if entry is None:
        return "—"
    if "failed" in entry:
        return f"{entry['time']:.3f} s, failed: {entry['failed']}"
    mark = "✓" if entry["optimal"] else "✗"
    return f"{entry['time']:.3f} s {mark} f={entry['fun']:.6g}"


def _ratio(a: dict[str, Any] | None, b: dict[str, Any] | None) -> str:
    return "—" if a is None or b is None else f"{a['time'] / b['time']:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--peer-repeat", type=int, default=1, help="repeats of GTSAM's Shonan (slow)")
    parser.add_argument("--datasets", nargs="*", default=NAMES)
    parser.add_argument("--kinds", nargs="*", default=["pose-graphs", "rotations"])
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    folder = catalogue.default_data_dir()
    report: dict[str, Any] = {"load_before": _load(), "pose_graphs": {}, "rotations": {}}
    print(f"# load average before: {report['load_before']}")
    print("\n## Pose graphs: staircase vs SE-Sync (C++, 1 thread)\n")
    print("| dataset | init | ours rank d | ours rank 5 | SE-Sync | ours d / SE-Sync | certificate share |")
    print("|---|---|---|---|---|---|---|")
    for name in args.datasets if "pose-graphs" in args.kinds else []:
        path = folder / f"{name}.g2o"
        graph = g2o.read(path)
        rng = np.random.default_rng(0)
        random_rot = (SO3 if graph.d == 3 else SO2).random(rng, (graph.n,))
        for init, x0 in (("chordal", "chordal"), ("random", random_rot)):
            a, b, c = interleaved_runs(
                [lambda: ours(graph, x0, None, 0), lambda: ours(graph, x0, 5, 0), lambda: sesync(path, init)],
                args.repeat,
            )
            report["pose_graphs"][f"{name}/{init}"] = {"ours": a, "ours_rank5": b, "sesync": c}
            print(f"| {name} | {init} | {_fmt(a)} | {_fmt(b)} | {_fmt(c)} | {_ratio(a, c)} | {a['cert_share']:.0%} |")
    print("\n## Rotation averaging: staircase vs GTSAM Shonan (same initial rotations)\n")
    print("| dataset | init | ours | Shonan (certified by ours) | Shonan λ_min | ours / Shonan | certificate share |")
    print("|---|---|---|---|---|---|---|")
    for name in args.datasets if "rotations" in args.kinds else []:
        ra = rotation_averaging.from_pose_graph(g2o.read(folder / f"{name}.g2o"))
        rng = np.random.default_rng(0)
        random_rot = (SO3 if ra.d == 3 else SO2).random(rng, (ra.n,))
        chordal = ra.chordal_initialization()
        for init, x0 in (("chordal", chordal), ("random", random_rot)):  # both from given rotations
            peer = shonan(ra, np.asarray(x0.as_matrix()))
            t0 = time.perf_counter()
            if init == "chordal" and peer is not None:  # both fast: in turn, --repeat rounds
                a, c = interleaved_runs([lambda: ours(ra, x0, None, 0), peer], args.repeat)
            else:  # Shonan from random rotations takes minutes: --peer-repeat runs
                (a,) = interleaved_runs([lambda: ours(ra, x0, None, 0)], args.repeat)
                c = None if peer is None else interleaved_runs([peer], args.peer_repeat)[0]
            report["rotations"][f"{name}/{init}"] = {"ours": a, "shonan": c, "wall": time.perf_counter() - t0}
            eig = "—" if c is None or "min_eig" not in c else f"{c['min_eig']:.1e}"
            print(f"| {name} | {init} | {_fmt(a)} | {_fmt(c)} | {eig} | {_ratio(a, c)} | {a['cert_share']:.0%} |")
    report["load_after"] = _load()
    print(f"\n# load average after: {report['load_after']}")
    if args.json:
        files = [folder / f"{name}.g2o" for name in args.datasets]
        write_json(args.json, report, datasets=files)


if __name__ == "__main__":
    main()
