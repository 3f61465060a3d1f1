"""Where SE(2)/SE(3) between factors and retractions run, for tests that check each path:
``"native"`` (compiled, :mod:`manopt_lie._native`), ``"machine"`` (CasADi's virtual machine, small
batches) or ``"arrays"`` (the NumPy array kernels)."""

from __future__ import annotations

import pytest

from manopt_lie import _kernels

PATHS = _kernels.PATHS


def use(path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Send the kernels down ``path`` for the rest of the test."""
    for name, value in _kernels.path_settings(path).items():
        monkeypatch.setattr(_kernels, name, value)
