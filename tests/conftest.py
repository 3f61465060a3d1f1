"""Shared fixtures: an ``rng``, the hypothesis profiles, and where the benchmark datasets live.

The SE-Sync g2o files are not part of the repository: they are read from
``$MANOPT_LIE_DATA``, else ``<repo>/../shared/datasets``. Without them the tests
that need them are skipped, except on CI (``$CI`` set), where they fail.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("default", deadline=None, max_examples=10, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", parent=settings.get_profile("default"), derandomize=True)
settings.register_profile("thorough", deadline=None, max_examples=200)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "default"))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


REPO = Path(__file__).resolve().parents[1]


def _missing(message: str) -> None:
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="session")
def datasets_dir() -> Path:
    """The directory holding the benchmark ``.g2o`` files."""
    path = Path(os.environ.get("MANOPT_LIE_DATA", REPO.parent / "shared" / "datasets"))
    if not path.is_dir():
        _missing(f"benchmark datasets not found: {path} is not a directory (set MANOPT_LIE_DATA to the g2o files)")
    return path


@pytest.fixture(scope="session")
def dataset(datasets_dir: Path) -> Callable[[str], Path]:
    """``dataset("intel")`` → the path of ``intel.g2o`` in :func:`datasets_dir`."""

    def path(name: str) -> Path:
        file = datasets_dir / (name if name.endswith(".g2o") else f"{name}.g2o")
        if not file.is_file():
            _missing(f"benchmark dataset {file} not found")
        return file

    return path
