"""The habits CI keeps: lint (ruff) and types (mypy) clean, and pre-commit running the same.

- ``.pre-commit-config.yaml`` runs ruff through astral-sh/ruff-pre-commit at a rev that the
  ``test`` extra of ``pyproject.toml`` allows, and mypy on the package as ``.ci/run`` does.
- ``ruff check`` and ``mypy`` pass on the repository when they are installed; on CI (``$CI``
  set) they must be (``pip install -e ".[test]"`` installs both), so there a missing one fails.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
MYPY = "mypy manopt_lie problems"
RUFF = "ruff check ."


def _pre_commit() -> dict[str, Any]:
    yaml = pytest.importorskip("yaml")
    return yaml.safe_load((ROOT / ".pre-commit-config.yaml").read_text(encoding="utf-8"))


def _test_extra(name: str) -> Requirement:
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    found = [r for r in map(Requirement, extra["test"]) if r.name == name]
    assert len(found) == 1, f"the test extra should name {name} once, got {found}"
    return found[0]


def _repo(url: str) -> dict[str, Any]:
    found = [r for r in _pre_commit()["repos"] if r["repo"] == url]
    assert len(found) == 1, f".pre-commit-config.yaml should list {url} once"
    return found[0]


def test_pre_commit_runs_ruff_at_a_version_the_test_extra_allows():
    repo = _repo("https://github.com/astral-sh/ruff-pre-commit")
    assert "ruff-check" in [h["id"] for h in repo["hooks"]]
    ruff = _test_extra("ruff")
    assert ruff.specifier, "pin ruff in the test extra: its rules change between releases"
    assert ruff.specifier.contains(repo["rev"].removeprefix("v")), (
        f"ruff-pre-commit rev {repo['rev']} is outside the test extra's {ruff}: update one of them"
    )


def test_pre_commit_runs_mypy_as_ci_does():
    (hook,) = [h for h in _repo("local")["hooks"] if h["id"] == "mypy"]
    assert hook["entry"] == MYPY and hook["language"] == "system" and hook["pass_filenames"] is False
    assert _test_extra("mypy").specifier
    script = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert MYPY in script and RUFF in script


def _tool(module: str, *args: str, timeout: float) -> subprocess.CompletedProcess[str]:
    if importlib.util.find_spec(module) is None:
        message = f"{module} is not installed (pip install -e '.[test]')"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )


def test_ruff_check_passes():
    out = _tool("ruff", *RUFF.split()[1:], "--no-cache", timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def test_mypy_passes():
    # Under a second with mypy's cache warm (.ci/run's mypy step leaves it so), ~20 s cold.
    out = _tool("mypy", *MYPY.split()[1:], timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
