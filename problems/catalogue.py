"""The catalogue of benchmark instances and the suites built from it.

An :class:`Entry` names its source — a synthetic generator with its arguments
(seed included), or a g2o file under the data directory — the problem built
from it (a pose graph, or the rotation averaging of its rotations), the costs to
run, and the published optimum where one exists. Suites are tuples of entries:
``quick`` (synthetic, self-contained, under two minutes), ``full`` (every shared
dataset and larger synthetic instances) and ``demo`` (the embedded default of
``manopt-lie demo``); :func:`load_suite` also reads a user's TOML file::

    [[instance]]
    name = "cube-8"                  # unique
    generator = "cube"               # a function of problems.synthetic …
    params = { side = 8, seed = 1 }
    costs = ["chordal", "geodesic"]  # optional (default: the kind's, see problems.kinds)

    [[instance]]
    name = "intel"
    file = "intel.g2o"               # … or a file under the data directory
    published = { chordal = 52.35 }  # optional
    problem = "pose-graph"           # or "rotation-averaging" (optional)
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import g2o, synthetic
from .graph import Graph
from .kinds import KINDS, convert, convertible, get_kind
from .landmarks import LandmarkGraph
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

GENERATORS: dict[str, str] = {  # the generators of problems.synthetic and the kind each makes
    **dict.fromkeys(("cube", "grid2d", "sphere", "torus", "circle2d"), PoseGraph.kind),
    "rotation_averaging": RotationAveraging.kind,
    "landmark_world": LandmarkGraph.kind,
}
DATA_ENV = "MANOPT_LIE_DATA"


class CatalogueError(ValueError):
    """A malformed catalogue entry or suite file."""


def default_data_dir() -> Path:
    """``$MANOPT_LIE_DATA``, else ``../shared/datasets`` beside the repository."""
    if DATA_ENV in os.environ:
        return Path(os.environ[DATA_ENV])
    return Path(__file__).resolve().parents[1] / ".." / "shared" / "datasets"


@dataclass(frozen=True)
class Loaded:
    """A catalogue entry made concrete: the problem and, for synthetic ones, the truth."""

    entry: Entry
    spec: Graph
    truth: Any = None


@dataclass(frozen=True)
class Entry:
    """One benchmark instance.

    Attributes
    ----------
    name : unique name in its suite
    problem : a kind of :mod:`manopt_lie.problems.kinds` ("pose-graph", or "rotation-averaging" of the
        source's rotations)
    generator, params : a :mod:`problems.synthetic` function and its keyword arguments
    file : a g2o file name, relative to the data directory (or absolute)
    costs : the costs to run (default: the kind's ``bench_costs``)
    published : published optimum per cost, e.g. ``{"chordal": 52.35}`` (SE-Sync's f*)
    reference_time : a published peer time in seconds (SE-Sync C++), for context
    """

    name: str
    problem: str = PoseGraph.kind
    generator: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    file: str | None = None
    costs: tuple[str, ...] | None = None  # default: the kind's bench_costs
    published: Mapping[str, float] = field(default_factory=dict)
    reference_time: float | None = None

    def __post_init__(self) -> None:
        where = f"instance {self.name!r}"
        if self.problem not in KINDS:
            raise CatalogueError(f"{where}: problem must be one of {tuple(KINDS)}, got {self.problem!r}")
        if (self.generator is None) == (self.file is None):
            raise CatalogueError(f"{where}: give exactly one of 'generator' and 'file'")
        if self.generator is not None and self.generator not in GENERATORS:
            raise CatalogueError(f"{where}: generator must be one of {tuple(GENERATORS)}, got {self.generator!r}")
        made = GENERATORS.get(self.generator, PoseGraph.kind) if self.generator is not None else PoseGraph.kind
        if not convertible(made, self.problem):
            raise CatalogueError(f"{where}: the {self.generator} generator makes a {made} problem, not {self.problem}")
        kind = KINDS[self.problem]
        costs = kind.bench_costs if self.costs is None else self.costs
        object.__setattr__(self, "costs", costs)
        bad = [c for c in costs if c not in kind.graph.costs]
        if not costs or bad:
            raise CatalogueError(f"{where}: costs must be a non-empty subset of {kind.graph.costs}, got {bad}")
        for cost, value in self.published.items():
            if cost not in costs or not isinstance(value, int | float) or not math.isfinite(value):
                raise CatalogueError(f"{where}: published optimum for {cost!r} must be a number for a listed cost")

    @property
    def source(self) -> str:
        """``"cube(side=8, seed=1)"`` or the file name."""
        if self.file is not None:
            return self.file
        return f"{self.generator}({', '.join(f'{k}={v}' for k, v in self.params.items())})"

    def path(self, data_dir: Path | str | None = None) -> Path | None:
        """The file, resolved against ``data_dir`` (default :func:`default_data_dir`)."""
        if self.file is None:
            return None
        return Path(data_dir if data_dir is not None else default_data_dir()) / self.file

    def check_size(self, available: float | None = None) -> None:
        """Refuse, naming the instance, a synthetic instance whose estimated memory
        (:data:`BYTES_PER_VERTEX`, :data:`BYTES_PER_EDGE` times its size) exceeds
        ``available`` bytes (default: the memory this machine has available).

        Raises
        ------
        CatalogueError
        """
        if self.generator is None:
            return
        try:
            n, m = _size(self.generator, _Params(self.params))
        except (TypeError, ValueError):
            return  # bad parameters: the generator itself says what is wrong
        need = BYTES_PER_VERTEX * n + BYTES_PER_EDGE * m
        have = available_memory() if available is None else available
        if need > have:
            raise CatalogueError(
                f"instance {self.name!r}: about {n:.3g} variables and {m:.3g} edges need some {need / 1e9:.3g} GB, "
                f"more than the {have / 1e9:.3g} GB available"
            )

    def load(self, data_dir: Path | str | None = None) -> Loaded:
        """Generate or read the instance. A missing file raises ``FileNotFoundError``; a
        synthetic instance too large for memory raises :class:`CatalogueError` (:meth:`check_size`)."""
        self.check_size()
        truth = None
        if self.generator is not None:
            try:
                instance = getattr(synthetic, self.generator)(**self.params)
            except TypeError as error:  # unknown keyword
                raise CatalogueError(f"instance {self.name!r}: {error}") from None
            spec, truth = instance.graph, instance.truth
        else:
            path = self.path(data_dir)
            assert path is not None
            if not path.is_file():
                raise FileNotFoundError(f"instance {self.name!r}: no such file {path}")
            spec = g2o.read(path)
        if spec.kind != self.problem:  # e.g. the rotation averaging of a pose graph
            kind = get_kind(self.problem)
            spec, truth = convert(spec, self.problem), None if truth is None else kind.from_truth(truth)
        return Loaded(self, spec, truth)


BYTES_PER_VERTEX = 2_000
"""A generous estimate of the memory a solve needs per variable (points, tangents, the
Cholesky factor's share), and per edge (measurements, residuals, Jacobians, Hessian blocks)."""
BYTES_PER_EDGE = 5_000


def available_memory() -> float:
    """Bytes of memory available to a new allocation (``MemAvailable`` of ``/proc/meminfo``,
    else all physical memory)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


class _Params(dict):  # type: ignore[type-arg]
    """Generator parameters with the generators' defaults for the sizes (floats: no overflow)."""

    def __missing__(self, key: str) -> float:
        return {"side": 10, "rows": 20, "cols": 20, "n_rings": 50, "poses_per_ring": 50, "n_laps": 10,
                "poses_per_lap": 100, "n": 100, "degree": 10, "n_poses": 200, "n_landmarks": 50,
                "max_observations": 10}[key]  # fmt: skip


_SIZE_PARAMS = {
    "cube": ("side", "side", "side"), "grid2d": ("rows", "cols"), "sphere": ("n_rings", "poses_per_ring"),
    "torus": ("n_laps", "poses_per_lap"), "circle2d": ("n_laps", "poses_per_lap"), "rotation_averaging": ("n",),
}  # fmt: skip


def _size(generator: str, p: _Params) -> tuple[float, float]:
    """``(n, m)`` of a generator's instance, at most: trajectories have ``m ≤ 3n`` (every
    loop-closure candidate kept), random graphs ``n − 1 + p n(n−1)/2``."""
    if generator == "landmark_world":
        poses = float(p["n_poses"])
        return poses + float(p["n_landmarks"]), poses * (1 + float(p["max_observations"]))
    n = math.prod(float(p[k]) for k in _SIZE_PARAMS[generator])
    if generator != "rotation_averaging":
        return n, 3 * n
    rate = p["edge_probability"] if p.get("edge_probability") is not None else float(p["degree"]) / max(n - 1, 1)
    return n, n - 1 + min(float(rate), 1.0) * n * (n - 1) / 2


def _dataset(name: str, published: float | None = None, seconds: float | None = None) -> Entry:
    return Entry(
        name, file=f"{name}.g2o", published={} if published is None else {"chordal": published},
        reference_time=seconds,
    )  # fmt: skip


# SE-Sync's datasets with the published chordal optima and C++ times (../shared/datasets/README.md).
DATASETS = (
    _dataset("CSAIL", 3.170e1, 0.010),
    _dataset("intel", 5.235e1, 0.071),
    _dataset("manhattan", 6.431e3, 0.080),
    _dataset("sphere2500", 1.687e3, 0.580),
    _dataset("parking-garage", 1.263e0, 0.468),
    _dataset("smallGrid3D"),
    _dataset("tinyGrid3D"),
)


def _rotations(n: int, degree: float) -> Entry:
    return Entry(
        f"rotations-{n}", RotationAveraging.kind, generator="rotation_averaging",
        params={"n": n, "degree": degree, "noise": 0.05, "seed": 0},
    )  # fmt: skip


SUITES: dict[str, tuple[Entry, ...]] = {
    "demo": (Entry("cube-6", generator="cube", params={"side": 6, "seed": 0}), _rotations(200, 8)),
    "quick": (
        Entry("grid2d-20x20", generator="grid2d", params={"rows": 20, "cols": 20, "seed": 0}),
        Entry("cube-8", generator="cube", params={"side": 8, "seed": 0}),
        Entry("sphere-20x25", generator="sphere", params={"n_rings": 20, "poses_per_ring": 25, "seed": 0}),
        _rotations(500, 10),
        Entry("landmarks2d-200", LandmarkGraph.kind, generator="landmark_world",
              params={"n_poses": 200, "n_landmarks": 50, "seed": 0}),
    ),
    "full": (
        *DATASETS,
        Entry("sphere2500-rotations", RotationAveraging.kind, file="sphere2500.g2o"),
        Entry("cube-15", generator="cube", params={"side": 15, "seed": 0}),
        Entry("torus-20x100", generator="torus", params={"n_laps": 20, "poses_per_lap": 100, "seed": 0}),
        _rotations(2000, 10),
        Entry("landmarks2d-2000", LandmarkGraph.kind, generator="landmark_world",
              params={"n_poses": 2000, "n_landmarks": 400, "laps": 4, "radius": 30, "seed": 0}),
        Entry("landmarks3d-1000", LandmarkGraph.kind, generator="landmark_world",
              params={"n_poses": 1000, "n_landmarks": 200, "d": 3, "laps": 3, "radius": 20, "seed": 0}),
    ),
}


def _entry(table: Any, where: str) -> Entry:
    if not isinstance(table, dict) or not isinstance(table.get("name"), str):
        raise CatalogueError(f"{where}: each [[instance]] needs a string 'name'")
    known = {"name", "problem", "generator", "params", "file", "costs", "published", "reference_time"}
    if unknown := set(table) - known:
        raise CatalogueError(f"{where}: unknown keys {sorted(unknown)} (known: {sorted(known)})")
    args = dict(table)
    if "costs" in args:
        args["costs"] = tuple(args["costs"])
    if "published" in args and not isinstance(args["published"], dict):
        raise CatalogueError(f"{where}: published must be a table such as {{ chordal = 52.35 }}")
    if "params" in args and not isinstance(args["params"], dict):
        raise CatalogueError(f"{where}: params must be a table such as {{ side = 8, seed = 1 }}")
    try:
        return Entry(**args)
    except CatalogueError as error:
        raise CatalogueError(f"{where}: {error}") from None


def load_suite(name_or_path: str | Path) -> tuple[Entry, ...]:
    """A named suite (``quick``, ``full``, ``demo``) or the instances of a TOML file."""
    if str(name_or_path) in SUITES:
        return SUITES[str(name_or_path)]
    path = Path(name_or_path)
    if path.suffix != ".toml":
        raise CatalogueError(f"suite must be one of {tuple(SUITES)} or a .toml file, got {str(name_or_path)!r}")
    if not path.is_file():
        raise FileNotFoundError(f"no such suite file: {path}")
    try:
        document = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:  # its message carries the line and column
        raise CatalogueError(f"{path}: {error}") from None
    tables = document.get("instance")
    if not isinstance(tables, list) or not tables:
        raise CatalogueError(f"{path}: no [[instance]] tables")
    entries = tuple(_entry(table, f"{path}: instance {k + 1}") for k, table in enumerate(tables))
    names = [e.name for e in entries]
    if duplicated := sorted({n for n in names if names.count(n) > 1}):
        raise CatalogueError(f"{path}: duplicate instance names {duplicated}")
    return entries
