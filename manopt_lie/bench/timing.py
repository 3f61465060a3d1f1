"""Timing for benchmarks: medians of repeats, and competitors timed in alternation.

Every benchmark script and the suite runner time through these two functions, so a
"time" means the same thing everywhere: the median wall time (``time.perf_counter``)
of ``repeat`` calls, optionally after warm-up calls that are not counted.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from typing import Any


def median_time(fn: Callable[[], Any], repeat: int = 1, *, warmup: int = 0) -> tuple[float, Any]:
    """The median wall time (seconds) of ``repeat`` calls of ``fn`` after ``warmup`` uncounted
    ones, and the last call's result."""
    if repeat < 1 or warmup < 0:
        raise ValueError(f"median_time: need repeat ≥ 1 and warmup ≥ 0, got {repeat} and {warmup}")
    for _ in range(warmup):
        fn()
    times, out = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), out


def interleaved(fns: Sequence[Callable[[], Any]], repeat: int = 1) -> list[tuple[float, Any] | BaseException]:
    """Time competitors in turn, ``repeat`` rounds, so that other load on the machine hits all
    of them alike: per competitor the median time and its last result, or the exception it
    raised (a failing competitor is reported, not fatal; it is not run again)."""
    if repeat < 1:
        raise ValueError(f"interleaved: need repeat ≥ 1, got {repeat}")
    times: list[list[float]] = [[] for _ in fns]
    last: list[Any] = [None] * len(fns)
    failed: dict[int, BaseException] = {}
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            if i in failed:
                continue
            start = time.perf_counter()
            try:
                last[i] = fn()
            except Exception as exc:
                failed[i] = exc
                continue
            times[i].append(time.perf_counter() - start)
    return [failed[i] if i in failed else (statistics.median(times[i]), last[i]) for i in range(len(fns))]
