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

from manopt_lie.bench.record import status_words
from manopt_lie.problems import g2o, synthetic

PNG = b"\x89PNG\r\n\x1a\n"
SOLVE_KEYS = {"fun", "nit", "time", "status", "grad_norm", "converged", "n", "m", "cost", "optimizer"}
RUN_KEYS = {"instance", "problem", "cost", "optimizer", "n", "m", "nit", "time", "init_time", "fun", "status",
            "converged", "published", "gap", "history_cost", "history_time", "history_grad_norm", "init",
            "seed"}  # fmt: skip
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


@pytest.mark.parametrize("command", [[], ["demo"], ["solve"], ["bench"], ["eval"], ["eval", "ape"], ["eval", "rpe"]])
def test_help(command: list[str]) -> None:
    proc = cli(*command, "--help")
    assert proc.returncode == 0 and proc.stdout.startswith("usage: manopt-lie"), proc.stderr
    assert "§" not in proc.stdout and "CONVENTIONS" not in proc.stdout  # readable without the docs


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
        (["bench", "--resume"], "--store"),
        (["bench", "--seeds", "0-3"], "--init random"),
        (["bench", "--seeds", "3-1", "--init", "random"], "range"),
        (["bench", "--scheduler", "slurm"], "--scheduler"),
        (["bench", "--workers", "2"], "--scheduler dask"),
        (["bench", "--plot-format", "jpg"], "invalid choice"),
        (["eval", "ape", "a.txt"], "required"),
        (["eval", "rpe", "a.txt", "b.txt", "-r", "angle"], "angle"),
        (["eval", "ape", "a.txt", "b.txt", "--plot", "ape.jpg"], ".png, .pdf or .svg"),
        (["eval", "ape", "a.txt", "b.txt"], "no such file"),
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
    # LM on a least-squares problem: the cost-decrease rule (1e-5, GTSAM's) is on by default
    assert summary["converged"] and summary["status"] == "cost_decrease" and summary["n"] == 64
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
    for word in ("cube-3", "grid-4", "rotations-30", "final cost", "status"):
        assert word in proc.stdout
    header = next(line for line in proc.stdout.splitlines() if "final cost" in line)
    assert "f*" not in header and "gap" not in header and "start" not in header  # empty in every row
    progress = proc.stderr.strip().splitlines()  # stderr is no terminal: plain progress lines
    assert progress and all(line.startswith("manopt-lie bench: ") for line in progress), proc.stderr
    assert progress[0].startswith("manopt-lie bench: 12 runs of 3 instances") and "[12/12]" in progress[-1]
    document = json.loads(out.read_text())
    assert set(document) == {"settings", "environment", "runs", "summary"}
    runs = document["runs"]
    # cube: 2 costs, grid: 1, rotations: 1 — each × 3 optimizers
    assert len(runs) == 12 and all(RUN_KEYS <= set(r) for r in runs)
    assert document["settings"]["repeat"] == 2
    for run in runs:
        assert run["converged"] and len(run["history_cost"]) == run["nit"] + 1 == len(run["history_time"])
        assert run["status"] in ("gradient_norm", "cost_decrease", "step_size") and run["init"] == "chordal"
        assert status_words(run["status"]) in proc.stdout  # JSON: snake_case; the table: words
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
    optimizers = {"gd", "cg", "lbfgs", "gn", "lm", "dogleg", "tr", "staircase"}  # every registered solver
    assert {r["optimizer"] for r in runs} == optimizers and len(runs) == 7 * 3 + 2  # staircase: chordal only
    assert all(r["converged"] for r in runs if r["optimizer"] in ("gn", "lm", "dogleg", "tr", "staircase"))
    certified = [r for r in runs if r["optimizer"] == "staircase"]  # on the two chordal problems
    assert [r["status"] for r in certified] == ["certified", "certified"]
    assert (out / "report.md").read_text().count("![") >= 5
    for name in ("performance-profile.png", "cube-6-trajectory.png", "cube-6-geodesic-convergence.png"):
        assert_png(out / name)
    table = proc.stdout.split("wrote")[0].splitlines()
    assert max(len(line.rstrip()) for line in table) < 100  # no wrapping in a 100-column terminal
    assert "f*" not in proc.stdout and "gap" not in proc.stdout


def test_demo_plot_format(tmp_path: Path) -> None:
    proc = cli("demo", "--out-dir", tmp_path, "--max-time", "0.2", "--plot-format", "pdf", "--quiet")
    assert proc.returncode == 0, proc.stderr
    figures = sorted(tmp_path.glob("*.pdf"))
    assert len(figures) >= 5 and not list(tmp_path.glob("*.png"))
    assert all(path.read_bytes()[:5] == b"%PDF-" for path in figures)
    assert proc.stderr == ""  # --quiet


def test_bench_dask_store_and_resume(suite_file: Path, tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    store = tmp_path / "runs.jsonl"
    args = ["bench", "--suite", suite_file, "--optimizers", "gn,tr", "--json"]
    sequential = cli(*args)
    assert sequential.returncode == 0, sequential.stderr
    proc = cli(*args, "--scheduler", "dask", "--workers", "2", "--store", store)
    assert proc.returncode == 0, proc.stderr
    ours = {(r["instance"], r["cost"], r["optimizer"]): r["fun"] for r in json.loads(sequential.stdout)["runs"]}
    theirs = {(r["instance"], r["cost"], r["optimizer"]): r["fun"] for r in json.loads(proc.stdout)["runs"]}
    assert theirs.keys() == ours.keys()
    for key, fun in ours.items():
        assert theirs[key] == pytest.approx(fun, rel=1e-12), key
    lines = store.read_text().splitlines()
    assert len(lines) == 1 + len(ours) and "manopt_lie_results" in lines[0]
    assert_usage_error(cli(*args, "--store", store), "--resume")  # never overwritten
    lines.pop()  # as if the campaign had been interrupted before its last run
    store.write_text("\n".join(lines) + "\n")
    out = tmp_path / "results.json"
    resumed = cli(*args[:-1], "--store", store, "--resume", "--out", out)
    assert resumed.returncode == 0, resumed.stderr
    assert "manopt-lie bench: 1 runs of 3 instances in this process (7 resumed" in resumed.stderr
    again = {(r["instance"], r["cost"], r["optimizer"]): r["fun"] for r in json.loads(out.read_text())["runs"]}
    assert again == theirs and len(store.read_text().splitlines()) == 1 + len(ours)
    other = cli(*args[:-1], "--max-iterations", "7", "--store", store, "--resume")
    assert_usage_error(other, "other settings")


# ---- eval ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def trajectories(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A reference and an estimate at half the rate, 1 ms late, in another frame and at scale 2."""
    from manopt_lie import SE3, SO3
    from manopt_lie.problems import trajectory_io as tio

    folder = tmp_path_factory.mktemp("trajectories")
    t = np.arange(100) * 0.1
    ref = SE3.from_rotation_translation(SO3.exp(np.stack([0 * t, 0 * t, t], 1)), np.stack([t, np.sin(t), 0 * t], 1))
    g = SE3.from_rotation_translation(SO3.exp([0.1, 0.2, 0.3]), [1.0, 2.0, 3.0])
    est = g @ ref[::2]
    est = SE3.from_rotation_translation(est.rotation(), 2.0 * est.translation())
    tio.write_tum(folder / "ref.txt", tio.Trajectory(ref, t))
    tio.write_tum(folder / "est.tum", tio.Trajectory(est, t[::2] + 0.001))
    return folder / "ref.txt", folder / "est.tum"


def test_eval_ape(trajectories: tuple[Path, Path], tmp_path: Path) -> None:
    ref, est = trajectories
    plain = json.loads(cli("eval", "ape", ref, est, "--json").stdout)
    assert plain["matched"] == 50 and plain["reference_poses"] == 100 and plain["alignment"] == "none"
    assert plain["rmse"] > 1.0 and set(plain) >= {"rmse", "mean", "median", "std", "min", "max", "sse"}
    sim = cli("eval", "ape", ref, est, "-as", "--json", "--plot", tmp_path / "ape.svg")
    assert sim.returncode == 0, sim.stderr
    document = json.loads(sim.stdout)
    assert document["alignment"] == "sim" and document["scale"] == pytest.approx(0.5) and document["max"] < 1e-9
    assert (tmp_path / "ape.svg").read_text().startswith("<?xml") and document["written"] == [str(tmp_path / "ape.svg")]
    se = json.loads(cli("eval", "ape", ref, est, "--align", "--json").stdout)
    assert se["rmse"] > 0.1  # SE(3) does not take out the scale
    text = cli("eval", "ape", ref, est, "-a", "-s", "--plot", tmp_path / "ape.png")
    assert text.returncode == 0 and "APE w.r.t. translation part (m)" in text.stdout and "Sim(3)" in text.stdout
    assert "rmse" in text.stdout and f"wrote {tmp_path / 'ape.png'}" in text.stdout
    assert_png(tmp_path / "ape.png")
    late = json.loads(cli("eval", "ape", ref, est, "--t-max-diff", "0.0005", "--json").stdout)
    assert late["error"] and "no matching timestamps" in late["error"]


def test_eval_rpe(trajectories: tuple[Path, Path], tmp_path: Path) -> None:
    ref, est = trajectories
    angle = json.loads(cli("eval", "rpe", ref, est, "-r", "angle_deg", "--json").stdout)
    assert angle["max"] < 1e-9 and angle["count"] == 49 and angle["delta"] == 1  # rotations are exact
    # translations of consecutive matched poses (0.2 s apart) are twice the reference's: error = their length
    scaled = json.loads(cli("eval", "rpe", ref, est, "--json").stdout)
    assert scaled["min"] > 0.1 and json.loads(cli("eval", "rpe", ref, est, "-as", "--json").stdout)["max"] < 1e-9
    pairs = json.loads(cli("eval", "rpe", ref, est, "-d", "4", "--all-pairs", "--json").stdout)
    assert pairs["count"] == 46 and pairs["all_pairs"]
    save = tmp_path / "rpe.json"
    proc = cli("eval", "rpe", ref, est, "--delta", "3", "--save-results", save, "--plot", tmp_path / "rpe.pdf")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(save.read_text())["count"] == 16 and (tmp_path / "rpe.pdf").read_bytes()[:5] == b"%PDF-"


def test_eval_kitti_and_g2o(tmp_path: Path) -> None:
    from manopt_lie.problems import trajectory_io as tio

    inst = synthetic.grid2d(3, 4, seed=1)
    g2o.write(tmp_path / "truth.g2o", inst.graph, inst.truth)
    g2o.write(tmp_path / "odometry.g2o", inst.graph, inst.graph.odometry_initialization())
    proc = cli("eval", "ape", tmp_path / "truth.g2o", tmp_path / "odometry.g2o", "-a", "--json")
    assert proc.returncode == 0, proc.stderr
    document = json.loads(proc.stdout)
    assert document["matched"] == 12 and document["rmse"] > 0
    tio.write_kitti(tmp_path / "truth.kitti", tio.read_g2o(tmp_path / "truth.g2o"))
    tio.write_kitti(tmp_path / "odometry.txt", tio.read_g2o(tmp_path / "odometry.g2o"))
    kitti = json.loads(cli("eval", "ape", tmp_path / "truth.kitti", tmp_path / "odometry.txt", "-a", "--json").stdout)
    assert kitti["rmse"] == pytest.approx(document["rmse"], rel=1e-9)  # lifted to z = 0: the same numbers
    tio.write_kitti(tmp_path / "short.txt", tio.read_g2o(tmp_path / "odometry.g2o").subset(np.arange(5)))
    assert_usage_error(cli("eval", "ape", tmp_path / "truth.kitti", tmp_path / "short.txt"), "matched by index")
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")
    assert_usage_error(cli("eval", "ape", bad, bad, "--format", "tum"), "bad.txt:2")


def test_eval_agrees_with_evo(trajectories: tuple[Path, Path]) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    ref, est = trajectories
    ref_evo, est_evo = sync.associate_trajectories(file_interface.read_tum_trajectory_file(ref),
                                                   file_interface.read_tum_trajectory_file(est))  # fmt: skip
    est_evo.align(ref_evo, correct_scale=False)
    metric = metrics.APE(metrics.PoseRelation.translation_part)
    metric.process_data((ref_evo, est_evo))
    ours = json.loads(cli("eval", "ape", ref, est, "-a", "--json").stdout)
    for key, value in metric.get_all_statistics().items():
        assert ours[key] == pytest.approx(value, rel=1e-6), key
