"""End-to-end tests of the ``manopt-lie`` command line, run as subprocesses on
synthetic data: exit codes, JSON schemas, files written, one-line errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from manopt_lie.problems import g2o, synthetic

PNG = b"\x89PNG\r\n\x1a\n"
SOLVE_KEYS = {"fun", "nit", "time", "status", "grad_norm", "converged", "n", "m", "cost", "optimizer"}
RUN_KEYS = {"instance", "problem", "cost", "optimizer", "n", "m", "nit", "time", "init_time", "fun", "status",
            "converged", "published", "gap", "history_cost", "history_time"}  # fmt: skip
TINY_SUITE = """
[[instance]]
name = "cube-3"
generator = "cube"
params = { side = 3, seed = 1 }

[[instance]]
name = "grid-4"
generator = "grid2d"
params = { rows = 4, cols = 4, seed = 2 }
costs = ["geodesic"]

[[instance]]
name = "rotations-30"
problem = "rotation-averaging"
generator = "rotation_averaging"
params = { n = 30, degree = 4, seed = 3 }
"""


def cli(*args: str | Path, extra_path: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "MANOPT_LIE_DATA"}
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(extra_path), env.get("PYTHONPATH")]))
    command = [sys.executable, "-m", "manopt_lie", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)


def assert_usage_error(proc: subprocess.CompletedProcess[str], *words: str) -> None:
    """Exit code 2, one line on stderr naming the problem, no traceback."""
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "error" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    for word in words:
        assert word in lines[0], lines[0]


def assert_png(path: Path) -> None:
    assert path.is_file() and path.stat().st_size > 1000 and path.read_bytes()[:8] == PNG, path


@pytest.fixture(scope="module")
def graph_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("data") / "cube.g2o"
    graph = synthetic.cube(4, seed=5).graph
    g2o.write(path, graph, graph.odometry_initialization())  # VERTEX lines with dead-reckoned poses
    return path


# ---- help and arguments --------------------------------------------------------------


@pytest.mark.parametrize("command", [[], ["demo"], ["solve"], ["bench"]])
def test_help(command: list[str]) -> None:
    proc = cli(*command, "--help")
    assert proc.returncode == 0 and proc.stdout.startswith("usage: manopt-lie"), proc.stderr


def test_command_line_names_come_from_the_registries() -> None:
    from manopt_lie.bench.peers import PEERS
    from manopt_lie.cli.bench import PEER_GROUPS
    from manopt_lie.optim import OPTIMIZERS

    assert sorted(p for group in PEER_GROUPS.values() for p in group) == sorted(PEERS)
    text = cli("bench", "--help").stdout
    assert ",".join(OPTIMIZERS) in text and all(group in text for group in PEER_GROUPS)


def test_console_script_is_installed() -> None:
    script = Path(sys.executable).parent / "manopt-lie"
    proc = subprocess.run([str(script), "--version"], capture_output=True, text=True, check=True)
    assert proc.stdout.startswith("manopt-lie ")


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["frobnicate"], "invalid choice"),
        (["bench", "--optimizers", "gd,newton"], "newton"),
        (["bench", "--repeat", "0"], "positive"),
        (["bench", "--peers", "ceres"], "ceres"),
        (["solve"], "required"),
        (["demo", "--max-time", "-1"], "positive"),
        (["bench", "--rel-cost-decrease", "-1"], "non-negative"),
        (["solve", "x.g2o", "--optimizer", "bfgs"], "bfgs"),
    ],
)
def test_bad_arguments(args: list[str], word: str) -> None:
    assert_usage_error(cli(*args), word)


# ---- solve ---------------------------------------------------------------------------


def test_solve_json_and_outputs(graph_file: Path, tmp_path: Path) -> None:
    out, plot = tmp_path / "result.g2o", tmp_path / "fig.png"
    proc = cli("solve", graph_file, "--optimizer", "lm", "--out", out, "--plot", plot, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert SOLVE_KEYS <= set(summary)
    assert summary["converged"] and summary["status"] == "gradient_norm" and summary["n"] == 64
    assert summary["fun"] < summary["initial_fun"]
    solution = g2o.read(out)
    graph = g2o.read(graph_file)
    assert solution.n == graph.n and np.array_equal(solution.edges, graph.edges)
    assert graph.cost(solution.poses, "geodesic") == pytest.approx(summary["fun"], rel=1e-6)
    assert_png(plot)


@pytest.mark.parametrize(
    "options",
    [
        ["--cost", "chordal", "--optimizer", "tr"],
        ["--init", "odometry", "--optimizer", "gn"],
        ["--init", "file", "--robust", "huber:1.0", "--optimizer", "lm"],
        ["--optimizer", "cg", "--max-iterations", "5"],
        ["--optimizer", "lm", "--rel-cost-decrease", "1e-3"],
    ],
)
def test_solve_options(graph_file: Path, options: list[str]) -> None:
    proc = cli("solve", graph_file, *options, "--json")
    summary = json.loads(proc.stdout)
    assert proc.returncode == (0 if summary["converged"] else 1), proc.stderr  # 1: ran, did not converge
    assert np.isfinite(summary["fun"]) and summary["fun"] <= summary["initial_fun"]
    if "--max-iterations" in options:
        assert summary["nit"] == 5 and summary["status"] == "max_iterations" and proc.returncode == 1


def test_solve_rotation_averaging(graph_file: Path, tmp_path: Path) -> None:
    out, plot = tmp_path / "rotations.g2o", tmp_path / "conv.png"
    proc = cli("solve", graph_file, "--problem", "rotation-averaging", "--out", out, "--plot", plot)
    assert proc.returncode == 0, proc.stderr
    assert "chordal cost" in proc.stdout and "status:" in proc.stdout
    solution, source = g2o.read(out), g2o.read(graph_file)
    # The rotations are the solution's; the translations are the file's, kept (not zeroed).
    np.testing.assert_array_equal(solution.poses.translation(), source.poses.translation())
    assert_png(plot)
    from_file = cli("solve", graph_file, "--problem", "rotation-averaging", "--init", "file", "--json")
    assert from_file.returncode == 0, from_file.stderr
    assert json.loads(from_file.stdout)["cost"] == "chordal"


def test_solve_missing_file(tmp_path: Path) -> None:
    assert_usage_error(cli("solve", tmp_path / "nope.g2o"), "nope.g2o")


def test_solve_malformed_file(graph_file: Path, tmp_path: Path) -> None:
    lines = graph_file.read_text().splitlines()
    bad = tmp_path / "bad.g2o"
    bad.write_text("\n".join([*lines[:5], "EDGE_SE3:QUAT 0 1 oops", *lines[5:]]) + "\n")
    assert_usage_error(cli("solve", bad), "bad.g2o:6:", "30 fields")


def test_solve_edges_only_file_has_no_poses(graph_file: Path, tmp_path: Path) -> None:
    edges_only = tmp_path / "edges.g2o"
    edges_only.write_text(
        "".join(line + "\n" for line in graph_file.read_text().splitlines() if line.startswith("EDGE"))
    )
    assert_usage_error(cli("solve", edges_only, "--init", "file"), "VERTEX")
    assert cli("solve", edges_only, "--quiet").returncode == 0


def test_solve_bad_robust_loss(graph_file: Path) -> None:
    assert_usage_error(cli("solve", graph_file, "--robust", "tukey:1"), "tukey")


# ---- bench ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def suite_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("suite") / "tiny.toml"
    path.write_text(TINY_SUITE)
    return path


def test_bench_outputs(suite_file: Path, tmp_path: Path) -> None:
    out, report, plots = tmp_path / "results.json", tmp_path / "report.md", tmp_path / "plots"
    proc = cli("bench", "--suite", suite_file, "--optimizers", "gn,lm,tr", "--repeat", "2", "--out", out,
               "--report", report, "--plots", plots)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    for word in ("cube-3", "grid-4", "rotations-30", "final cost", "gap"):
        assert word in proc.stdout
    document = json.loads(out.read_text())
    assert set(document) == {"settings", "environment", "runs", "summary"}
    runs = document["runs"]
    # cube: 2 costs, grid: 1, rotations: 1 — each × 3 optimizers
    assert len(runs) == 12 and all(RUN_KEYS <= set(r) for r in runs)
    assert document["settings"]["repeat"] == 2
    for run in runs:
        assert run["converged"] and len(run["history_cost"]) == run["nit"] + 1 == len(run["history_time"])
    by_problem: dict[tuple[str, str], list[float]] = {}
    for run in runs:
        by_problem.setdefault((run["instance"], run["cost"]), []).append(run["fun"])
    for funs in by_problem.values():  # every optimizer reaches the same optimum
        assert max(funs) == pytest.approx(min(funs), rel=1e-6)
    text = report.read_text()
    assert text.startswith("# manopt-lie bench") and "| rotations-30 |" in text and "![" in text
    names = {p.name for p in plots.iterdir()}
    assert {"performance-profile.png", "cube-3-trajectory.png", "grid-4-trajectory.png"} <= names
    assert {"cube-3-chordal-convergence.png", "rotations-30-chordal-convergence.png"} <= names
    for path in plots.iterdir():
        assert_png(path)


def test_bench_json_to_stdout(suite_file: Path) -> None:
    proc = cli("bench", "--suite", suite_file, "--optimizers", "tr", "--json")
    assert proc.returncode == 0, proc.stderr
    document = json.loads(proc.stdout)
    assert [r["optimizer"] for r in document["runs"]] == ["tr"] * 4
    assert document["summary"][0]["solved"] == 4


def test_bench_reference_and_peers(suite_file: Path) -> None:
    peers = [p for p in ("gtsam", "pymanopt") if _installed(p)]
    args = ["--peers", ",".join(peers)] if peers else []
    proc = cli("bench", "--suite", suite_file, "--optimizers", "lm", "--reference", *args, "--json")
    assert proc.returncode == 0, proc.stderr
    runs = json.loads(proc.stdout)["runs"]
    solvers = {(r["instance"], r["cost"], r["optimizer"]): r["fun"] for r in runs}
    assert ("cube-3", "chordal", "ipopt") in solvers
    for (instance, cost, solver), fun in solvers.items():
        assert fun == pytest.approx(solvers[instance, cost, "lm"], rel=1e-5), solver
    if "gtsam" in peers:
        assert ("grid-4", "geodesic", "gtsam-dogleg") in solvers and ("cube-3", "chordal", "gtsam-lm") not in solvers
    if "pymanopt" in peers:
        assert ("rotations-30", "chordal", "pymanopt-tr") in solvers


def _installed(module: str) -> bool:
    return subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True).returncode == 0


def test_bench_missing_peer(suite_file: Path, tmp_path: Path) -> None:
    (tmp_path / "gtsam.py").write_text("raise ImportError('hidden by the test')\n")  # shadows an installed gtsam
    proc = cli("bench", "--suite", suite_file, "--peers", "gtsam", extra_path=tmp_path)
    assert_usage_error(proc, "pip install gtsam")


@pytest.mark.parametrize(
    ("content", "word"),
    [
        ("[[instance]\nname = 'x'", "line 1"),
        ("[[instance]]\nname = 'x'\ngenerator = 'cube'\ncolour = 'red'", "colour"),
        ("[[instance]]\nname = 'x'\ngenerator = 'moebius'", "moebius"),
        ("[[instance]]\nname = 'x'\ngenerator = 'cube'\nparams = { edge = 3 }", "edge"),
        ("[[instance]]\nname = 'x'\nfile = 'missing.g2o'", "missing.g2o"),
        ("title = 'no instances'", "no [[instance]]"),
    ],
)
def test_bench_bad_suite(tmp_path: Path, content: str, word: str) -> None:
    path = tmp_path / "suite.toml"
    path.write_text(content)
    assert_usage_error(cli("bench", "--suite", path, "--data-dir", tmp_path), word)


def test_bench_unknown_suite_and_missing_data(tmp_path: Path) -> None:
    assert_usage_error(cli("bench", "--suite", "huge"), "huge")
    assert_usage_error(cli("bench", "--suite", tmp_path / "none.toml"), "none.toml")
    assert_usage_error(cli("bench", "--suite", "full", "--data-dir", tmp_path), "--data-dir")


# ---- demo ----------------------------------------------------------------------------


def test_demo(tmp_path: Path) -> None:
    proc = cli("demo", "--out-dir", tmp_path / "out", "--max-time", "1")
    assert proc.returncode == 0, proc.stderr
    for word in ("cube-6", "rotations-200", "gd", "cg", "gn", "lm", "tr", "wrote"):
        assert word in proc.stdout
    out = tmp_path / "out"
    document = json.loads((out / "results.json").read_text())
    runs = document["runs"]
    assert {r["optimizer"] for r in runs} == {"gd", "cg", "gn", "lm", "tr"} and len(runs) == 15
    assert all(r["converged"] for r in runs if r["optimizer"] in ("gn", "lm", "tr"))
    assert (out / "report.md").read_text().count("![") >= 5
    for name in ("performance-profile.png", "cube-6-trajectory.png", "cube-6-geodesic-convergence.png"):
        assert_png(out / name)
