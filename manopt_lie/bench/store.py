"""The results store of a benchmark campaign: JSON lines, written as runs finish.

The first line is a header, ``{"manopt_lie_results": 1, "settings": {…}}``; every further
line is one run, ``{"run": {…}}`` (:meth:`Run.to_json <manopt_lie.bench.record.Run.to_json>`),
appended, flushed and ``fsync``-ed as soon as the run finishes. A campaign that is
interrupted (Ctrl-C, a lost machine, a killed job) keeps every run it finished;
``manopt-lie bench … --store FILE --resume`` reads them back and runs only the rest. A last
line cut short by the interruption is dropped.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .record import Run

FORMAT = 1


class StoreError(ValueError):
    """A results store that cannot be used as asked (exists without ``resume``, other
    settings, not a store)."""


class Store:
    """An open results store.

    Parameters
    ----------
    path : the ``.jsonl`` file
    settings : the campaign's settings (``Settings.to_json()``): a resumed store must have
        been written with the same ones, so that its runs are comparable
    resume : bool
        Read the runs of an existing store and append to it. Without it, an existing
        non-empty store is refused (nothing is overwritten).

    Raises
    ------
    StoreError
    """

    def __init__(self, path: Path | str, settings: dict[str, Any], *, resume: bool = False) -> None:
        self.path = Path(path)
        self.runs: list[Run] = []
        exists = self.path.is_file() and self.path.stat().st_size > 0
        if exists and not resume:
            raise StoreError(f"results store {self.path} exists: pass --resume to continue that campaign, "
                             "or remove the file")  # fmt: skip
        if exists:
            self._read(settings)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._append({"manopt_lie_results": FORMAT, "settings": settings})

    def _read(self, settings: dict[str, Any]) -> None:
        data = self.path.read_bytes()
        end = data.rfind(b"\n") + 1
        if end < len(data):  # a line cut short by the interruption: drop it before appending
            with open(self.path, "r+b") as f:
                f.truncate(end)
        lines = data[:end].decode("utf-8").splitlines()
        try:
            header = json.loads(lines[0]) if lines else None
        except json.JSONDecodeError:
            header = None
        if not isinstance(header, dict) or header.get("manopt_lie_results") != FORMAT:
            raise StoreError(f"{self.path} is not a manopt-lie results store (its first line is no store header)")
        if header.get("settings") != settings:
            changed = _differences(header.get("settings"), settings)
            raise StoreError(f"{self.path} was written with other settings ({changed}): its runs would not be "
                             "comparable; use another --store")  # fmt: skip
        for lineno, line in enumerate(lines[1:], 2):
            try:
                self.runs.append(Run.from_json(json.loads(line)["run"]))
            except (ValueError, KeyError, TypeError) as error:
                raise StoreError(f"{self.path}:{lineno}: not a run record ({error})") from None

    def _append(self, document: dict[str, Any]) -> None:
        line = json.dumps(document, allow_nan=False) + "\n"
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())

    def add(self, run: Run) -> None:
        """Append ``run`` (durably: flushed and ``fsync``-ed)."""
        self.runs.append(run)
        self._append({"run": run.to_json()})


def _differences(old: Any, new: dict[str, Any]) -> str:
    if not isinstance(old, dict):
        return "none recorded"
    keys = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    return ", ".join(f"{k}: {old.get(k)} there, {new.get(k)} now" for k in keys)
