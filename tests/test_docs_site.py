"""The documentation site builds with ``mkdocs build --strict`` (warnings are errors).

Skipped when MkDocs and its plugins are not installed, except on CI (``$CI`` set, as
``.ci/run`` runs with ``CI=true``), where a missing tool fails: the strict build is part
of what CI checks. The built pages are then checked for what a reader needs: math
wrapped for MathJax, the API reference listing the main classes, the changelog included.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOLS = (
    "mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "griffe_inherited_docstrings", "pymdownx",
)


def _missing_tools() -> list[str]:
    missing = []
    for name in TOOLS:
        try:
            if importlib.util.find_spec(name) is None:
                missing.append(name)
        except ModuleNotFoundError:
            missing.append(name)
    return missing


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    missing = _missing_tools()
    if missing:
        message = f"the docs tools are not installed ({', '.join(missing)}): pip install -e '.[docs]'"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", str(out)],
        cwd=ROOT, capture_output=True, text=True, env=env, timeout=300,
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    return out


def _inventory(site: Path) -> list[str]:
    """The object names of the site's ``objects.inv`` (Sphinx inventory v2, zlib after four header lines)."""
    data = (site / "objects.inv").read_bytes()
    body = data.split(b"\n", 4)[4]
    return [line.split(" ", 1)[0] for line in zlib.decompress(body).decode().splitlines()]


def test_site_builds_strict(site):
    assert (site / "index.html").is_file()
    assert (site / "api" / "lie" / "index.html").is_file()


def test_math_is_wrapped_for_mathjax(site):
    conventions = (site / "conventions" / "index.html").read_text()
    assert 'class="arithmatex"' in conventions
    assert "javascripts/mathjax.js" in conventions
    factors = (site / "api" / "factors" / "index.html").read_text()
    assert 'class="arithmatex"' in factors  # the docstrings' `.. math::` blocks
    assert ".. math::" not in factors and ":class:`" not in factors


def test_api_reference_lists_the_public_names(site):
    names = set(_inventory(site))
    for name in ("manopt_lie.lie.SO3", "manopt_lie.lie.SE3", "manopt_lie.lie.SO3.from_quaternion",
                 "manopt_lie.optim.LevenbergMarquardt", "manopt_lie.optim.TrustRegion",
                 "manopt_lie.manifolds.Stiefel", "manopt_lie.linalg.CholeskySolver",
                 "manopt_lie.factors.between_factor", "manopt_lie.casadi.problem_from_casadi",
                 "manopt_lie.problems.PoseGraph", "manopt_lie.problems.g2o.read",
                 "manopt_lie.problems.certify.staircase.staircase", "manopt_lie.minimize.minimize"):
        assert name in names, name
    lie = (site / "api" / "lie" / "index.html").read_text()
    assert 'id="manopt_lie.lie.SO3"' in lie and 'id="manopt_lie.lie.SE3"' in lie


def test_changelog_is_included(site):
    changelog = (site / "changelog" / "index.html").read_text()
    first = next(line for line in (ROOT / "CHANGELOG.md").read_text().splitlines() if line.startswith("## "))
    assert first[3:].split()[0] in changelog and "--8&lt;--" not in changelog
