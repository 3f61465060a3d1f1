"""Floors import downwards: optim and linalg never import casadi (nor anything above the core)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE = [ROOT / "manopt_lie" / "optim", ROOT / "manopt_lie" / "linalg"]
FORBIDDEN = ("casadi", "cli", "bench", "problems", "benchmarks")


def _imports(path: Path) -> list[tuple[int, str]]:
    """Every module an ``import`` names (module level or inside functions), relative ones
    resolved against the package of ``path``."""
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = list(package[: len(package) - node.level + 1]) if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            found += [(node.lineno, module)] + [(node.lineno, f"{module}.{a.name}") for a in node.names]
    return found


@pytest.mark.parametrize("path", sorted(p for d in CORE for p in d.glob("*.py")), ids=lambda p: p.name)
def test_core_modules_import_nothing_above_them(path):
    for line, module in _imports(path):
        parts = module.split(".")
        assert not (parts[0] in FORBIDDEN or (parts[0] == "manopt_lie" and len(parts) > 1 and parts[1] in FORBIDDEN)), (
            f"{path.relative_to(ROOT)}:{line} imports {module}"
        )


def test_importing_optim_loads_no_casadi():
    code = "import sys, manopt_lie.optim, manopt_lie.linalg; print(sorted(m for m in sys.modules if 'casadi' in m))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
