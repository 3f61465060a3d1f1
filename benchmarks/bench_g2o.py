"""Reading big g2o files: time and peak memory of ``g2o.read`` (a benchmark, not a timed test).

Synthetic files of about ``--sizes`` megabytes are written once with ``g2o.write`` from
``problems.synthetic.cube`` (SE(3)) and ``problems.synthetic.grid2d`` (SE(2)) instances
into ``--dir`` (default: a folder in the system's temporary directory, reused between
runs). Each measurement runs in a fresh interpreter, so that one file's memory does not
hide another's:

- ``time``: the median wall time of ``--repeat`` calls of ``g2o.read(path)``;
- ``rss``: the process's peak resident set (``getrusage``'s ``ru_maxrss``) after one read
  less its resident set before it, in MB and as a multiple of the file size;
- ``traced``: the peak of the memory ``tracemalloc`` traces during one read (Python
  objects and NumPy arrays), in MB and as a multiple of the file size.

The targets of issue 13 for a 100 MB file: at most 5 s and 4× the file size.
``python benchmarks/bench_g2o.py [--sizes 10 100] [--kinds cube grid2d] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path
from typing import Any

from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import median_time
from manopt_lie.problems import g2o, synthetic

MB = 1e6


def _instance(kind: str, size: int) -> Any:
    """The ``kind`` instance with about ``size`` poses (side³ or rows·cols)."""
    if kind == "cube":
        return synthetic.cube(max(2, round(size ** (1 / 3))), seed=0)
    side = max(2, round(size**0.5))
    return synthetic.grid2d(side, side, seed=0)


def synthetic_file(kind: str, megabytes: float, folder: Path) -> Path:
    """A g2o file of about ``megabytes`` MB written from a ``kind`` instance (made once)."""
    path = folder / f"{kind}-{megabytes:g}MB.g2o"
    if not path.exists():
        probe = _instance(kind, 4000).graph
        per_pose = len(g2o.dumps(probe)) / probe.n
        graph = _instance(kind, int(megabytes * MB / per_pose)).graph
        partial = path.with_suffix(".partial")
        g2o.write(partial, graph)
        partial.replace(path)
    return path


def measure(path: Path, repeat: int) -> dict[str, Any]:
    """Time and memory of reading ``path``, each in a fresh interpreter."""
    rows: dict[str, Any] = {}
    for mode in ("time", "rss", "traced"):
        out = subprocess.run(
            [sys.executable, __file__, "--child", mode, "--repeat", str(repeat), str(path)],
            check=True,
            capture_output=True,
            text=True,
        )
        rows.update(json.loads(out.stdout))
    return rows


def _current_rss() -> int:
    """The resident set now, in bytes (``/proc``; else the peak so far, an upper bound)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def child(mode: str, path: Path, repeat: int) -> dict[str, Any]:
    """One measurement in this interpreter (``--child``)."""
    size = path.stat().st_size
    if mode == "time":
        seconds, graph = median_time(lambda: g2o.read(path), repeat)
        return {"n": graph.n, "m": graph.m, "time": seconds}
    if mode == "rss":  # one read: no earlier graph is alive
        before = _current_rss()
        g2o.read(path)
        grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - before  # KiB on Linux
        return {"rss_MB": grown / MB, "rss_x": grown / size}
    tracemalloc.start()
    g2o.read(path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"traced_MB": peak / MB, "traced_x": peak / size}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="*", type=float, default=[10.0, 100.0], help="file sizes in MB")
    parser.add_argument("--kinds", nargs="*", default=["cube", "grid2d"], choices=["cube", "grid2d"])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()) / "manopt-lie-bench-g2o")
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    parser.add_argument("--child", choices=["time", "rss", "traced"], help=argparse.SUPPRESS)
    parser.add_argument("path", nargs="?", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.path, args.repeat)))
        return
    os.makedirs(args.dir, exist_ok=True)
    rows = []
    print(f"{'file':<18} {'MB':>7} {'n':>8} {'m':>8} {'time s':>7} {'rss MB':>8} {'×file':>6} ", end="")
    print(f"{'traced MB':>9} {'×file':>6}")
    for kind in args.kinds:
        for megabytes in args.sizes:
            path = synthetic_file(kind, megabytes, args.dir)
            row = {"file": path.name, "MB": path.stat().st_size / MB, **measure(path, args.repeat)}
            rows.append(row)
            print(
                f"{row['file']:<18} {row['MB']:>7.1f} {row['n']:>8} {row['m']:>8} {row['time']:>7.2f} "
                f"{row['rss_MB']:>8.0f} {row['rss_x']:>6.2f} {row['traced_MB']:>9.0f} {row['traced_x']:>6.2f}",
                flush=True,
            )
    if args.json:
        write_json(args.json, rows)


if __name__ == "__main__":
    main()
