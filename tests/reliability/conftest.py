"""The shared datasets' fixtures (``datasets_dir``, ``dataset``) for the reliability tests."""

from tests.problems.conftest import dataset, datasets_dir  # noqa: F401
