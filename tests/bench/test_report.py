"""Run records, tables, summaries and JSON documents of benchmark runs."""

from __future__ import annotations

import json
import math

import pytest

from manopt_lie.bench import report
from manopt_lie.bench.record import Run, best_costs, solved
from manopt_lie.bench.suite import Settings, plan
from manopt_lie.optim import StoppingCriteria

from .test_plots import make_run


def test_gap_and_json_without_nan() -> None:
    run = make_run("tr", fun=52.36, history=[60.0, math.nan, 52.36])
    run.published = 52.35
    assert run.gap == pytest.approx(0.01 / 52.35)
    run.grad_norm = math.inf
    document = run.to_json()
    assert document["grad_norm"] is None and document["history_cost"] == [60.0, None, 52.36]
    json.dumps(document, allow_nan=False)


def test_best_costs_and_solved() -> None:
    runs = [make_run("gn", fun=10.0), make_run("gd", fun=10.0 + 2e-4), make_run("ipopt", fun=math.nan)]
    best = best_costs(runs)
    assert best == {("intel", "geodesic"): 10.0}
    assert [solved(r, best[r.key]) for r in runs] == [True, False, False]


def test_rows_star_unsolved_and_summary() -> None:
    runs = [
        make_run("gn", fun=10.0, time=0.5),
        make_run("lm", fun=10.0, time=2.0),
        make_run("gd", fun=11.0, time=4.0),
        make_run("gn", instance="csail", fun=3.0, time=1.0),
        make_run("lm", instance="csail", fun=3.0, time=0.25),
    ]
    table = report.rows(runs)
    assert len(table) == 5 and all(len(row) == len(report.HEADER) for row in table)
    assert [row[-1].endswith("*") for row in table] == [False, False, True, False, False]
    summary = {s["optimizer"]: s for s in report.summary(runs)}
    assert summary["gn"]["solved"] == 2 and summary["gn"]["time_ratio_geomean"] == pytest.approx(2.0)  # √(1·4)
    assert summary["lm"]["time_ratio_geomean"] == pytest.approx(2.0)  # √(4·1)
    assert summary["gd"] == {"optimizer": "gd", "problems": 1, "solved": 0, "time_ratio_geomean": None}


def test_document_and_markdown(tmp_path) -> None:
    runs: list[Run] = [make_run("gn"), make_run("lm", fun=1.5)]
    settings = Settings(repeat=3)
    document = report.document(runs, settings)
    assert document["settings"]["repeat"] == 3 and len(document["runs"]) == 2
    json.dumps(document, allow_nan=False)
    plot = tmp_path / "plots" / "a.png"
    text = report.markdown(runs, settings, title="T", plots=[plot], base=tmp_path)
    assert text.startswith("# T\n") and "| intel | 5 | 7 | geodesic | lm |" in text and "(plots/a.png)" in text


def test_settings_validation() -> None:
    with pytest.raises(ValueError, match="repeat"):
        Settings(repeat=0)
    with pytest.raises(ValueError, match="unknown optimizer 'newton'"):
        plan([], ["newton"])
    assert Settings(StoppingCriteria(max_time=math.inf)).to_json()["max_time"] is None  # JSON has no inf
