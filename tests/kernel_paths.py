"""Where SE(2)/SE(3) between factors and retractions run, for tests that check each path:
``"native"`` (compiled, :mod:`manopt_lie._native`), ``"machine"`` (CasADi's virtual machine, small
batches) or ``"arrays"`` (the NumPy array kernels)."""

from __future__ import annotations

import pytest

from manopt_lie import _kernels
from manopt_lie.factors import _poses

PATHS = ("native", "machine", "arrays")


def use(path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Send the kernels down ``path`` for the rest of the test."""
    assert path in PATHS
    monkeypatch.setattr(_kernels, "USE_NATIVE", path == "native")
    if path == "arrays":
        monkeypatch.setattr(_poses, "VM_EDGES", 0)
        monkeypatch.setattr(_kernels, "VM_POINTS", 0)
