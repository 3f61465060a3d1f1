"""Benchmark campaigns: starts and seeds, the Dask scheduler, the results store and resuming."""

from __future__ import annotations

import math
import pickle

import pytest

from manopt_lie.bench.campaign import execute
from manopt_lie.bench.store import Store
from manopt_lie.bench.suite import Settings, plan
from manopt_lie.optim import StoppingCriteria
from manopt_lie.problems.catalogue import Entry

ENTRIES = (
    Entry("grid-4", generator="grid2d", params={"rows": 4, "cols": 4, "seed": 2}, costs=("geodesic",)),
    Entry("rotations-30", "rotation-averaging", generator="rotation_averaging",
          params={"n": 30, "degree": 4, "seed": 3}),
)  # fmt: skip
SETTINGS = Settings(StoppingCriteria(max_iterations=200, max_time=30.0))


def costs(runs) -> dict:
    return {run.task_key: run.fun for run in runs}


@pytest.fixture(scope="module")
def sequential():
    tasks = plan(ENTRIES, ["gn", "tr"], init="random", seeds=[0, 1])
    return tasks, execute(tasks, settings=SETTINGS)


def test_starts_and_seeds(sequential) -> None:
    tasks, result = sequential
    assert len(tasks) == 2 * 2 * 2 and [t.start for t in tasks[:4]] == ["random:0"] * 2 + ["random:1"] * 2
    assert {r.start for r in result.runs} == {"random:0", "random:1"}
    by_start = costs(result.runs)
    assert by_start["grid-4", "geodesic", "random:0", "gn"] != by_start["grid-4", "geodesic", "random:1", "gn"]
    assert [t.start for t in plan(ENTRIES, ["gn"])] == ["chordal", "chordal"]
    with pytest.raises(ValueError, match="random"):
        plan(ENTRIES, ["gn"], init="odometry", seeds=[1])


def test_tasks_travel(sequential) -> None:
    """What a scheduler ships (tasks, settings) and gets back (outcomes without solutions) pickles."""
    tasks, result = sequential
    assert pickle.loads(pickle.dumps(tasks)) == tasks
    outcome = next(iter(result.outcomes.values()))
    outcome_copy = pickle.loads(pickle.dumps((outcome.run, outcome.positions, SETTINGS)))
    assert outcome_copy[0] == outcome.run


def test_dask_local_cluster_gives_the_sequential_costs(sequential) -> None:
    pytest.importorskip("dask.distributed")
    tasks, result = sequential
    seen = []
    distributed = execute(tasks, settings=SETTINGS, scheduler="dask", workers=2, on_result=seen.append)
    assert len(seen) == len(tasks)  # progress as results arrive
    assert [r.task_key for r in distributed.runs] == [r.task_key for r in result.runs]  # plan order
    ours, theirs = costs(result.runs), costs(distributed.runs)
    for key, fun in ours.items():
        assert theirs[key] == pytest.approx(fun, rel=1e-12, abs=1e-14), key
    assert all(o.x is None and o.run.converged == result.outcomes[k].run.converged
               for k, o in distributed.outcomes.items())  # fmt: skip


def test_an_interrupted_campaign_resumes(sequential, tmp_path) -> None:
    tasks, result = sequential
    path = tmp_path / "runs.jsonl"
    store = Store(path, SETTINGS.to_json())

    def interrupt_after_three(outcome) -> None:
        store.add(outcome.run)
        if len(store.runs) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        execute(tasks, settings=SETTINGS, on_result=interrupt_after_three)
    resumed = Store(path, SETTINGS.to_json(), resume=True)
    assert len(resumed.runs) == 3
    ran = []
    again = execute(
        tasks, settings=SETTINGS, done=resumed.runs, on_result=lambda o: (ran.append(o), resumed.add(o.run))
    )
    assert len(ran) == len(tasks) - 3  # only what the store lacked
    assert [r.task_key for r in again.runs] == [t.key for t in tasks]
    ours = costs(result.runs)
    for key, fun in costs(again.runs).items():
        assert fun == pytest.approx(ours[key], rel=1e-12), key
    assert len(Store(path, SETTINGS.to_json(), resume=True).runs) == len(tasks)
    assert all(not math.isnan(r.time) for r in again.runs)
