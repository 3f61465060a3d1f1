"""The command line's contract, in subprocesses: nothing lost (atomic writes, the input never
overwritten, outputs checked before the solve), documented exit codes, interrupts, broken
pipes, JSON always valid."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from manopt_lie.cli._common import json_safe, json_text
from manopt_lie.problems import g2o, synthetic

SCRIPT = Path(sys.executable).parent / "manopt-lie"


def cli(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "manopt_lie", *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=cwd)


def one_line_error(proc: subprocess.CompletedProcess[str], code: int, *words: str) -> None:
    assert proc.returncode == code, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.fixture(scope="module")
def cube(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("data") / "cube.g2o"
    graph = synthetic.cube(4, seed=5).graph
    g2o.write(path, graph, graph.odometry_initialization())
    return path


@pytest.fixture
def copy(cube: Path, tmp_path: Path) -> Path:
    path = tmp_path / "input.g2o"
    path.write_bytes(cube.read_bytes())
    return path


# ---- nothing lost ----------------------------------------------------------------------


def test_out_equal_to_the_input_is_refused(copy: Path) -> None:
    """Audit: `solve X.g2o --out X.g2o` overwrote the input, even without convergence."""
    before = copy.read_bytes()
    one_line_error(cli("solve", copy, "--out", copy), 2, "is the input file", "--force")
    link = copy.with_name("link.g2o")
    link.symlink_to(copy)
    one_line_error(cli("solve", copy, "--out", link), 2, "is the input file")
    assert copy.read_bytes() == before
    forced = cli("solve", copy, "--out", copy, "--force", "--quiet")
    assert forced.returncode == 0, forced.stderr
    assert copy.read_bytes() != before and g2o.read(copy).n == 64


def test_rotation_averaging_keeps_the_translations(copy: Path, tmp_path: Path) -> None:
    """Audit: with --problem rotation-averaging the written translations were zeros."""
    out = tmp_path / "rotations.g2o"
    proc = cli("solve", copy, "--problem", "rotation-averaging", "--out", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert (g2o.read(out).poses.translation() == g2o.read(copy).poses.translation()).all()


def test_a_write_that_fails_halfway_leaves_the_old_file(copy: Path, tmp_path: Path) -> None:
    """Audit: a write cut by `ulimit -f` left a truncated file that no longer parsed."""
    out = tmp_path / "out.g2o"
    out.write_text("# the previous result\n")
    limit_blocks = 4  # 2 KiB (bash counts 512-byte blocks): far less than the solution
    command = f"ulimit -f {limit_blocks}; exec {sys.executable} -m manopt_lie solve {copy} --out {out} --quiet"
    proc = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=600)
    one_line_error(proc, 1, "File too large")
    assert out.read_text() == "# the previous result\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["input.g2o", "out.g2o"]  # no temporary file left


def test_bad_output_paths_are_found_before_the_solve(copy: Path, tmp_path: Path) -> None:
    """Audit: a bad --out directory was found only after the whole solve."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    start = time.perf_counter()
    one_line_error(cli("solve", copy, "--out", blocker / "x.g2o", "--max-iterations", "1000000"), 2,
                   "not a directory")  # fmt: skip
    one_line_error(cli("solve", copy, "--plot", tmp_path), 2, "is a directory")
    one_line_error(cli("bench", "--suite", "quick", "--out", blocker / "r.json"), 2, "not a directory")
    assert time.perf_counter() - start < 30


def test_a_directory_is_not_a_file(tmp_path: Path) -> None:
    one_line_error(cli("solve", tmp_path), 2, "is a directory")


# ---- exit codes --------------------------------------------------------------------------


def test_exit_codes_are_documented() -> None:
    for command in ([], ["solve"], ["bench"], ["demo"]):
        text = cli(*command, "--help").stdout
        assert "exit codes:" in text and "130" in text and "did not converge" in text


def test_not_converged_exits_1(cube: Path) -> None:
    """Audit: runs that did not converge exited 0."""
    proc = cli("solve", cube, "--max-iterations", "1", "--json", "--optimizer", "gd")
    assert proc.returncode == 1, proc.stderr
    assert json.loads(proc.stdout)["converged"] is False
    assert cli("solve", cube, "--quiet").returncode == 0


def test_json_errors(tmp_path: Path) -> None:
    """With --json, errors are JSON on stdout too (and one line on stderr)."""
    for args in (["solve", tmp_path / "nope.g2o"], ["solve", "--optimizer", "bfgs", "x.g2o"]):
        proc = cli(*args, "--json")
        assert proc.returncode == 2, proc.stderr
        document = json.loads(proc.stdout)
        assert document["exit_code"] == 2 and document["error"]


def test_json_is_always_valid() -> None:
    """Audit: --json with a non-finite result failed (after --out was written)."""
    document = {"fun": float("nan"), "history": [1.0, float("inf"), [float("-inf")]], "nested": {"x": float("nan")}}
    assert json.loads(json_text(document)) == {"fun": None, "history": [1.0, None, [None]], "nested": {"x": None}}
    assert json_safe((1, 2.0)) == [1, 2.0]


def test_a_huge_suite_instance_is_refused_by_name(tmp_path: Path) -> None:
    """Audit: a bench TOML with a huge instance died with MemoryError."""
    suite = tmp_path / "huge.toml"
    suite.write_text('[[instance]]\nname = "galaxy"\ngenerator = "cube"\nparams = { side = 5000 }\n')
    one_line_error(cli("bench", "--suite", suite), 2, "galaxy", "GB")


# ---- interrupts and pipes ----------------------------------------------------------------


def test_ctrl_c_exits_130_writes_nothing(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path) -> None:
    """Audit: Ctrl-C gave a traceback and no result."""
    # A solve that cannot end before --max-time however fast the machine: steepest descent
    # from the odometry start of a 1000-pose cube (it is still descending after 2 minutes).
    cube = tmp_path_factory.mktemp("large") / "cube10.g2o"
    graph = synthetic.cube(10, seed=5).graph
    g2o.write(cube, graph, graph.odometry_initialization())
    out = tmp_path / "out.g2o"
    command = [sys.executable, "-m", "manopt_lie", "solve", cube, "--optimizer", "gd", "--max-iterations",
               "1000000", "--max-time", "120", "--grad-rtol", "1e-15", "--init", "odometry", "--out", out]  # fmt: skip
    # Deep inside the solve: past the imports, the reading and the set-up, however long they
    # take on this machine (timed first by the same command stopped after one iteration).
    start = time.perf_counter()
    subprocess.run([*command[:8], "1", *command[9:-2]], capture_output=True, timeout=300)
    startup = time.perf_counter() - start
    # The child takes Ctrl-C as a terminal would deliver it, even when this suite runs where
    # SIGINT is ignored (a background job of a script, ``nohup``): ignored dispositions are
    # inherited, and Python then installs no KeyboardInterrupt handler.
    def interruptible() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=interruptible)  # fmt: skip
    time.sleep(max(4.0, 2.0 * startup + 1.0))
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == ["manopt-lie solve: interrupted"], stderr
    assert not out.exists() and not list(tmp_path.iterdir())


def test_a_closed_pipe_is_quiet(tmp_path: Path) -> None:
    """Audit: `| head -1` printed a broken-pipe error."""
    suite = tmp_path / "tiny.toml"
    suite.write_text('[[instance]]\nname = "grid"\ngenerator = "grid2d"\nparams = { rows = 4, cols = 4 }\n')
    command = f"{SCRIPT} bench --suite {suite} --optimizers gd,cg --max-iterations 3000 --json | head -c 10"
    proc = subprocess.run(["bash", "-c", f"set -o pipefail; {command}"], capture_output=True, text=True,
                          timeout=600, env={**os.environ})  # fmt: skip
    assert proc.stderr == "", proc.stderr
    assert proc.returncode in (0, 141)
    assert len(proc.stdout) == 10
