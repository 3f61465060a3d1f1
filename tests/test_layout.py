"""The layout: one import root, floors that import in one direction, no import cycles.

- The wheel holds ``manopt_lie/…`` and its dist-info, nothing else, and every module
  of the repository's ``manopt_lie/`` and ``problems/`` folders.
- The commands work from a directory holding a decoy ``problems.py`` and ``benchmarks/``.
- Floors: core (``lie``, ``manifolds``, ``optim``, ``linalg``, ``casadi``, ``check``,
  ``errors``) < ``problems`` < ``bench`` < ``cli``; a module imports only from its own
  floor or lower ones, and the module graph (every import, also inside functions) has no cycle.
- The command line and the bench harness ask problems what they are; they never branch on
  a problem's kind.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"manopt_lie": ROOT / "manopt_lie", "manopt_lie.problems": ROOT / "problems"}
FLOORS = {"core": 0, "problems": 1, "bench": 2, "cli": 3}


def _modules() -> dict[str, Path]:
    """Every module of the installed package, by dotted name."""
    out = {}
    for prefix, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            parts = path.relative_to(folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join((prefix, *parts))] = path
    return out


MODULES = _modules()


def _floor(module: str) -> int:
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in ("problems", "bench", "cli"):
        return FLOORS[parts[1]]
    if module == "manopt_lie.__main__":
        return FLOORS["cli"]
    return FLOORS["core"]


def _imports(module: str, path: Path) -> set[str]:
    """The project modules ``module`` imports anywhere in its body, inside functions too
    (relative ones resolved; ``from package import name`` counts the submodule
    ``package.name`` when there is one); ``if TYPE_CHECKING:`` blocks are left out."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):  # imports only for type checkers are not imports
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            node.body = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base for alias in node.names]
        else:
            continue
        for name in names:
            while name and name not in MODULES:  # ``a.b.c`` as attribute access: the longest module prefix
                name = name.rpartition(".")[0]
            if name and name != module:
                found.add(name)
    return found


GRAPH = {module: _imports(module, path) for module, path in MODULES.items()}


def test_floors_import_downwards_only() -> None:
    upward = [
        f"{module} (floor {_floor(module)}) imports {target} (floor {_floor(target)})"
        for module, targets in GRAPH.items()
        for target in targets
        if _floor(target) > _floor(module)
    ]
    assert not upward, "\n".join(upward)


def test_no_import_cycles() -> None:
    """Tarjan's strongly connected components of the module graph: all of size one."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(GRAPH):
        if module not in index:
            visit(module)
    assert not cycles, f"import cycles: {cycles}"


def test_the_graph_sees_the_known_edges() -> None:
    """The walker itself: relative, absolute and function-level imports are all found."""
    assert "manopt_lie.problems.graph" in GRAPH["manopt_lie.problems.pose_graph"]
    assert "manopt_lie.optim" in GRAPH["manopt_lie.problems.graph"]
    assert "manopt_lie.bench.plots" in GRAPH["manopt_lie.cli.solve"]  # imported inside a function
    assert len(MODULES) > 60


KIND_NAMES = ("pose-graph", "rotation-averaging", "landmark-slam")
KIND_CLASSES = ("PoseGraph", "RotationAveraging", "LandmarkGraph")


def _kind_branches(path: Path) -> list[str]:
    """Comparisons with a kind's name, and ``isinstance`` tests against a kind's class that
    choose what to do (validating an argument — ``if not isinstance(…): raise`` — is not a branch)."""
    tree = ast.parse(path.read_text(), str(path))
    validations = {
        id(call)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and len(node.body) == 1 and isinstance(node.body[0], ast.Raise)
        for call in ast.walk(node.test)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(isinstance(o, ast.Constant) and o.value in KIND_NAMES for o in operands):
                found.append(f"{path.name}:{node.lineno}: comparison with a kind's name")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "isinstance":
            if id(node) in validations:
                continue
            if any(isinstance(n, ast.Name) and n.id in KIND_CLASSES for n in ast.walk(node.args[1])):
                found.append(f"{path.name}:{node.lineno}: isinstance against a kind's class")
    return found


def test_no_kind_branches() -> None:
    paths = [p for name, p in MODULES.items() if _floor(name) >= 0]
    branches = [b for path in paths for b in _kind_branches(path)]
    assert not branches, "\n".join(branches)


# ---- the installed distribution --------------------------------------------------------


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    out = tmp_path_factory.mktemp("wheel")
    # Without setuptools and wheel at hand, pip builds in an isolated environment (from the index).
    local = all(importlib.util.find_spec(name) is not None for name in ("setuptools", "wheel"))
    isolation = ["--no-build-isolation"] if local else []
    command = [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(out), *isolation]
    subprocess.run(command, check=True, capture_output=True, text=True, timeout=600)
    (path,) = out.glob("manopt_lie-*.whl")
    return zipfile.ZipFile(path)


def test_the_wheel_has_one_import_root(wheel: zipfile.ZipFile) -> None:
    names = wheel.namelist()
    roots = {name.split("/")[0] for name in names}
    (dist_info,) = [r for r in roots if r.endswith(".dist-info")]
    assert roots == {"manopt_lie", dist_info}, roots
    top_level = wheel.read(f"{dist_info}/top_level.txt").decode().split()
    assert top_level == ["manopt_lie"]


def test_the_wheel_has_every_module(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    expected = {
        "/".join(module.split(".")) + ("/__init__.py" if path.name == "__init__.py" else ".py")
        for module, path in MODULES.items()
    }
    assert not expected - names, f"modules missing from the wheel: {sorted(expected - names)}"
    assert "manopt_lie/py.typed" in names


def _decoy(tmp_path: Path) -> Path:
    (tmp_path / "problems.py").write_text("raise ImportError('the decoy problems.py was imported')\n")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "__init__.py").write_text("raise ImportError('the decoy benchmarks was imported')\n")
    return tmp_path


def test_commands_ignore_a_decoy_problems_module(tmp_path: Path) -> None:
    cwd = _decoy(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    script = Path(sys.executable).parent / "manopt-lie"
    for command in ([str(script), "demo", "--help"], [sys.executable, "-m", "manopt_lie", "--help"]):
        proc = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0 and proc.stdout.startswith("usage: manopt-lie"), proc.stderr
    # A command that really imports the applications.
    from manopt_lie.problems import g2o, synthetic

    graph = synthetic.grid2d(3, 3, seed=1).graph
    g2o.write(cwd / "grid.g2o", graph, graph.odometry_initialization())
    proc = subprocess.run([sys.executable, "-m", "manopt_lie", "solve", "grid.g2o", "--json"], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
