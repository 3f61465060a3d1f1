"""Run a benchmark plan: one task after another in this process, or on a Dask cluster
(:mod:`.distributed`); skip what a resumed campaign already has; report each run as it arrives."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from .record import Run
from .suite import Cache, Outcome, Settings, SuiteResult, Task, run_task

__all__ = ["execute"]


def execute(
    tasks: Sequence[Task],
    *,
    settings: Settings | None = None,
    data_dir: Path | str | None = None,
    on_task: Callable[[Task], None] | None = None,
    on_result: Callable[[Outcome], None] | None = None,
    done: Sequence[Run] = (),
    scheduler: str | None = None,
    workers: int | None = None,
) -> SuiteResult:
    """Run ``tasks`` (from :func:`plan`), except those whose runs are in ``done`` (a resumed
    campaign's; they are reported as they are).

    Parameters
    ----------
    on_task, on_result : callables, optional
        Called before each task (sequential runs only) and with each :class:`Outcome` as it
        arrives (progress, the results store).
    scheduler : None, ``"dask"`` or a Dask scheduler address (``"tcp://host:8786"``)
        ``None`` runs the tasks one after another in this process; otherwise
        :func:`~manopt_lie.bench.distributed.execute_dask` runs them on a
        ``dask.distributed`` cluster (``"dask"``: a local one of ``workers`` processes).
        The final costs are the same either way; the times are each worker's.

    Raises
    ------
    FileNotFoundError, CatalogueError
        As :func:`run_task`.
    """
    settings = settings or Settings()
    finished = {run.task_key: run for run in done}
    todo = [task for task in tasks if task.key not in finished]
    out = SuiteResult()
    if scheduler is None:
        cache = Cache()
        for task in todo:
            if on_task is not None:
                on_task(task)
            outcome = run_task(task, settings, data_dir, cache)
            out.outcomes[task.key] = outcome
            if on_result is not None:
                on_result(outcome)
        out.loaded = cache.loaded
    else:
        from .distributed import execute_dask  # dask is imported only when asked for

        for outcome in execute_dask(todo, settings, data_dir, scheduler=scheduler, workers=workers,
                                    on_result=on_result):  # fmt: skip
            out.outcomes[outcome.task.key] = outcome
    runs = {key: o.run for key, o in out.outcomes.items()} | finished
    out.runs = [runs[task.key] for task in tasks if task.key in runs]
    return out
