"""``manopt-lie solve`` on g2o files with landmarks and priors (subprocess): the optimum,
``--out`` writing every vertex back, ``--covariances`` by vertex id."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from manopt_lie.optim import LevenbergMarquardt, marginal_covariances
from manopt_lie.problems import LandmarkGraph, g2o, synthetic


def cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "manopt_lie", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def world(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, LandmarkGraph]:
    d = request.param
    graph = synthetic.landmark_world(60, 15, d=d, sensor_range=8.0, prior=(d == 3), seed=4).graph
    path = tmp_path_factory.mktemp("landmarks") / f"world{d}d.g2o"
    g2o.write(path, graph, graph.initialize("odometry"))
    return path, g2o.read(path)


def test_solve_reaches_the_optimum_and_writes_every_vertex(world, tmp_path: Path) -> None:
    path, graph = world
    out, cov_path = tmp_path / "out.g2o", tmp_path / "cov.json"
    proc = cli("solve", path, "--optimizer", "lm", "--rel-cost-decrease", "0", "--out", out,
               "--covariances", cov_path, "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["problem"] == "landmark-slam" and summary["converged"]
    assert summary["written"] == [str(out), str(cov_path)]

    problem = graph.problem()
    ours = LevenbergMarquardt(rel_cost_decrease=0).solve(problem, graph.initialize("chordal"))
    assert summary["fun"] == pytest.approx(ours.fun, rel=1e-8)

    solution = g2o.read(out)
    assert isinstance(solution, LandmarkGraph) and solution.estimates is not None
    tag = "VERTEX_XY" if graph.d == 2 else "VERTEX_TRACKXYZ"
    assert out.read_text().count(tag) == graph.n_landmarks
    np.testing.assert_allclose(solution.landmarks, ours.x["landmarks"], atol=1e-6)
    assert graph.cost(solution.estimates) == pytest.approx(ours.fun, rel=1e-8)

    covariances = json.loads(cov_path.read_text())
    assert list(covariances) == [str(i) for i in graph.vertex_ids]
    expected = marginal_covariances(problem, ours.x, variables=np.arange(len(graph.vertex_ids)))
    for v, vertex in enumerate(graph.vertex_ids):
        block = np.array(covariances[str(vertex)])
        dim = graph.group.dim if v < graph.n else graph.d
        assert block.shape == (dim, dim)
        np.testing.assert_allclose(block, expected[v], rtol=1e-4, atol=1e-10)
    gauge = graph.gauge  # the fixed pose of the 2-D world (the 3-D one has a prior instead)
    for v in gauge:
        assert not np.any(covariances[str(graph.vertex_ids[v])])
    free = [v for v in range(graph.n) if v not in gauge]
    assert all(np.linalg.eigvalsh(covariances[str(graph.vertex_ids[v])])[0] > 0 for v in free)


def test_a_landmark_file_as_a_pose_graph(world) -> None:
    path, graph = world
    proc = cli("solve", path, "--problem", "pose-graph", "--json")
    summary = json.loads(proc.stdout)
    assert summary["problem"] == "pose-graph" and summary["m"] == graph.poses.m
    proc = cli("solve", path, "--problem", "rotation-averaging", "--json")
    assert json.loads(proc.stdout)["problem"] == "rotation-averaging"


def test_a_pose_graph_file_is_not_a_landmark_problem(tmp_path: Path) -> None:
    path = tmp_path / "grid.g2o"
    graph = synthetic.grid2d(3, 3, seed=0).graph
    g2o.write(path, graph, graph.odometry_initialization())
    proc = cli("solve", path, "--problem", "landmark-slam")
    assert proc.returncode == 2 and "cannot be solved as a landmark-slam problem" in proc.stderr
