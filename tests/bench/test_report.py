"""Run records, tables, summaries and JSON documents of benchmark runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import manopt_lie
from manopt_lie.bench import report
from manopt_lie.bench.record import Run, agreement, best_costs, published_precision, solved, status_name, status_words
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
    # no published optimum, chordal starts: the f*, gap and start columns are left out
    kept = [report.HEADER[k] for k in report.columns(table)]
    assert "f*" not in kept and "gap" not in kept and "start" not in kept and "status" in kept
    assert "| f* |" not in report.markdown_table(runs) and "| status |" in report.markdown_table(runs)
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


def test_published_agreement_is_honest() -> None:
    assert published_precision(52.35) == (4, pytest.approx(0.005))
    assert published_precision(31.7) == (4, pytest.approx(0.005))  # SE-Sync's 3.170e1
    assert published_precision(6431.0) == (4, pytest.approx(0.5))
    assert published_precision(1.262524) == (7, pytest.approx(5e-7))
    cases = [
        (1.262524, 1.263, "= f* to 4 digits"),
        (52.34823, 52.35, "= f* to 4 digits"),
        (52.5, 52.35, "+2.9e-03"),
        (52.2, 52.35, "-2.9e-03 < f*"),
        (31.70372, 31.7, "= f* to 4 digits"),
    ]
    for fun, published, text in cases:
        run = make_run("tr", fun=fun)
        run.published = published
        assert agreement(run) == text, (fun, published)
    table = report.rows([run])
    assert [report.HEADER[k] for k in report.columns(table)][-3:] == ["f*", "gap", "status"]
    assert agreement(make_run("tr")) is None


def test_status_spellings() -> None:
    assert status_name("Solve_Succeeded") == "solve_succeeded" and status_name("max iterations") == "max_iterations"
    assert status_words("gradient_norm") == "gradient norm"
    run = make_run("gn")
    run.status = "gradient_norm"
    assert report.rows([run])[0][-1] == "gradient norm" and run.to_json()["status"] == "gradient_norm"


def test_run_json_round_trip() -> None:
    run = make_run("lm", fun=2.0, history=[5.0, math.nan, 2.0])
    run.grad_norm, run.init, run.seed = 1e-9, "random", 3
    again = Run.from_json(json.loads(json.dumps(run.to_json())))
    assert again.start == "random:3" and again.problem_key == ("intel", "geodesic", "random:3")
    assert math.isnan(again.history_cost[1]) and again.history_cost[::2] == [5.0, 2.0]
    assert again.to_json() == run.to_json()
    with pytest.raises(ValueError, match="lacks"):
        Run.from_json({"instance": "x"})


def test_store_appends_resumes_and_refuses(tmp_path) -> None:
    from manopt_lie.bench.store import Store, StoreError

    settings = Settings().to_json()
    path = tmp_path / "runs.jsonl"
    store = Store(path, settings)
    store.add(make_run("gn"))
    store.add(make_run("lm"))
    with pytest.raises(StoreError, match="--resume"):
        Store(path, settings)
    with open(path, "a") as f:
        f.write('{"run": {"instance": "cut sh')  # the line an interruption cut
    again = Store(path, settings, resume=True)
    assert [r.optimizer for r in again.runs] == ["gn", "lm"]
    again.add(make_run("tr"))
    assert [r.optimizer for r in Store(path, settings, resume=True).runs] == ["gn", "lm", "tr"]
    with pytest.raises(StoreError, match="other settings"):
        Store(path, Settings(repeat=2).to_json(), resume=True)
    (tmp_path / "other.jsonl").write_text("hello\n")
    with pytest.raises(StoreError, match="not a manopt-lie results store"):
        Store(tmp_path / "other.jsonl", settings, resume=True)


# ---- where the numbers come from -------------------------------------------------------------


def test_environment_records_versions_and_dataset_checksums(tmp_path):
    import hashlib
    import importlib.metadata

    data = tmp_path / "tiny.g2o"
    data.write_bytes(b"VERTEX_SE2 0 0 0 0\n")
    env = report.environment([data])
    assert env["manopt_lie"] == manopt_lie.__version__
    assert env["packages"]["numpy"] == importlib.metadata.version("numpy") == np.__version__
    assert set(env["packages"]) == set(report.PACKAGES)  # absent ones are None, not missing
    assert env["datasets"] == {"tiny.g2o": {"sha256": hashlib.sha256(data.read_bytes()).hexdigest(), "bytes": 19}}
    line = report.environment_line(env)
    assert f"numpy {np.__version__}" in line and "tiny.g2o (" in line


def test_benchmark_json_is_valid_and_carries_the_environment(tmp_path):
    out = tmp_path / "bench.json"
    report.write_json(out, {"ratio": np.float64(0.5), "times": np.array([1.0, np.nan]), "gap": math.inf})
    document = json.loads(out.read_text())
    assert document["results"] == {"ratio": 0.5, "times": [1.0, None], "gap": None}
    assert document["environment"]["manopt_lie"] == manopt_lie.__version__
    assert [p.name for p in tmp_path.iterdir()] == ["bench.json"]  # no temporary left behind
