"""Benchmark campaigns on a ``dask.distributed`` cluster.

:func:`execute_dask` submits one task per run to a cluster — a ``LocalCluster`` of worker
processes on this machine (``scheduler="dask"``) or an existing one by its scheduler's
address (``"tcp://host:8786"``) — and yields the outcomes as they arrive. What travels is
small and picklable: the :class:`~manopt_lie.bench.suite.Task` (a catalogue entry and
names) and the settings; each worker builds its problem itself (:func:`run_task`), since
problem objects hold locks and per-thread state. What comes back is the
:class:`~manopt_lie.bench.record.Run` and the solution's positions (for plots), not the
solution itself.

Workers need ``manopt_lie`` installed and, for dataset instances, the data directory at the
same path. Dask is an optional extra (``pip install "manopt-lie[distributed]"``), imported
only here.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from .suite import Outcome, Settings, Task, run_task

EXTRA = 'pip install "manopt-lie[distributed]"'


def _work(task: Task, settings: Settings, data_dir: str | None) -> Outcome:
    """What a worker runs: one task, its problem built here; the solution stays here."""
    outcome = run_task(task, settings, data_dir)
    outcome.x = None
    return outcome


def _import() -> Any:
    try:
        import dask.distributed
    except ImportError as error:
        raise ImportError(f"--scheduler needs Dask, an optional extra: {EXTRA}") from error
    return dask.distributed


def execute_dask(
    tasks: Sequence[Task],
    settings: Settings,
    data_dir: Path | str | None = None,
    *,
    scheduler: str = "dask",
    workers: int | None = None,
    on_result: Callable[[Outcome], None] | None = None,
) -> Iterator[Outcome]:
    """Run ``tasks`` on a Dask cluster; yield each :class:`Outcome` as it arrives (after
    ``on_result``).

    Parameters
    ----------
    scheduler : ``"dask"`` (a ``LocalCluster`` of ``workers`` single-threaded processes,
        default one per CPU) or a scheduler address such as ``"tcp://10.0.0.1:8786"``
    workers : int, optional

    Raises
    ------
    ImportError
        Without Dask (naming the extra to install).
    OSError
        When the scheduler cannot be reached.
    Exception
        The first exception a task raised (the others are cancelled).
    """
    distributed = _import()
    if not tasks:
        return
    directory = None if data_dir is None else str(Path(data_dir).resolve())
    cluster = None
    quiet = {"silence_logs": logging.ERROR}
    if scheduler == "dask":
        cluster = distributed.LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                                           processes=True, dashboard_address=None, **quiet)  # fmt: skip
        client = distributed.Client(cluster)
    else:
        try:
            client = distributed.Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as error:
            raise OSError(f"cannot reach the Dask scheduler at {scheduler}: {error}") from None
    futures = []
    try:
        futures = [client.submit(_work, task, settings, directory, pure=False) for task in tasks]
        for future in distributed.as_completed(futures):
            outcome = future.result()
            if on_result is not None:
                on_result(outcome)
            yield outcome
    finally:
        for future in futures:
            future.cancel()
        client.close()
        if cluster is not None:
            cluster.close()
