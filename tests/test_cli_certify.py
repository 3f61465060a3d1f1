"""The certifiable solvers on the command line (subprocess): ``--optimizer staircase`` from
random starts, ``--certify`` of any optimizer's solution, refusals; the staircase in suites."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from manopt_lie.bench.suite import plan
from manopt_lie.problems import g2o, synthetic
from manopt_lie.problems.catalogue import SUITES
from manopt_lie.problems.solvers import GRAPH_SOLVERS


def cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "manopt_lie", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("certify") / "grid.g2o"
    graph = synthetic.grid2d(8, 8, loop_closure_probability=0.3, seed=2).graph
    g2o.write(path, graph, graph.odometry_initialization())
    return path


def test_the_staircase_certifies_from_a_random_start(grid: Path, dataset) -> None:
    for args in ([grid], [dataset("intel")], [dataset("smallGrid3D"), "--problem", "rotation-averaging"]):
        proc = cli("solve", *args, "--optimizer", "staircase", "--init", "random", "--seed", "3", "--certify",
                   "--json")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        summary = json.loads(proc.stdout)
        assert summary["status"] == "certified" and summary["converged"] and summary["cost"] == "chordal"
        assert summary["certificate"]["optimal"] and summary["certificate"]["gap_bound"] >= 0
    assert summary["problem"] == "rotation-averaging"
    intel = json.loads(cli("solve", dataset("intel"), "--optimizer", "staircase", "--init", "random",
                           "--json").stdout)  # fmt: skip
    assert round(intel["fun"], 2) == 52.35  # SE-Sync's published optimum, to its four digits


def test_certify_refuses_a_point_that_is_not_optimal(grid: Path) -> None:
    proc = cli("solve", grid, "--cost", "chordal", "--optimizer", "gd", "--init", "random", "--max-iterations", "3",
               "--certify", "--json")  # fmt: skip
    assert proc.returncode == 1  # three steps of gradient descent: not converged
    certificate = json.loads(proc.stdout)["certificate"]
    assert certificate["optimal"] is False and certificate["gap_bound"] > 0
    text = cli("solve", grid, "--cost", "chordal", "--optimizer", "tr", "--certify").stdout
    assert "certificate: globally optimal" in text


def test_refusals(grid: Path, tmp_path: Path) -> None:
    proc = cli("solve", grid, "--optimizer", "staircase", "--cost", "geodesic")
    assert proc.returncode == 2 and "rotation-averaging problems with the chordal cost" in proc.stderr
    landmarks = tmp_path / "world.g2o"
    world = synthetic.landmark_world(30, 8, sensor_range=8.0, seed=1).graph
    g2o.write(landmarks, world, world.initialize("odometry"))
    proc = cli("solve", landmarks, "--certify")
    assert proc.returncode == 2 and "certificates exist for" in proc.stderr


def test_suites_run_the_staircase_where_it_applies() -> None:
    tasks = plan(SUITES["quick"], ["tr", *GRAPH_SOLVERS])
    staircase = {(t.entry.name, t.cost) for t in tasks if t.solver == "staircase"}
    assert staircase == {(e.name, "chordal") for e in SUITES["quick"] if "chordal" in (e.costs or ())
                         and e.problem in GRAPH_SOLVERS["staircase"].kinds}  # fmt: skip
    assert all(cost == "chordal" for _, cost in staircase) and staircase
