"""A fuzzer of the g2o reader (issue 13): mutations of real files.

Seeds: ``tinyGrid3D.g2o`` of the shared datasets, small 2-D and 3-D pose graphs written by
``g2o.write``, and small 2-D and 3-D landmark files (landmarks, observations, priors; in 3-D
two sensor offsets) written by it, one of them without vertex lines. Mutations, one to four
per example: delete, duplicate or swap lines;
truncate; flip bytes; insert garbage tokens; change numbers to huge, tiny, ``nan``,
``inf`` or ``-0.0``; change ids; insert byte order marks; change line ends to CR or CRLF;
change tags. The contract:

- only :class:`~manopt_lie.problems.g2o.ParseError` escapes ``read`` (the suite turns
  RuntimeWarnings into errors, so no numpy warning either), with a line number within
  the file;
- ``lint`` of every graph ``read`` accepts (pose or landmark graph) returns a report (and its
  text), never raises;
- every way to read the same bytes — a binary stream, a string (when they are UTF-8), a
  text stream, blocks of any size — gives the same graph or the same error.

The default hypothesis profile runs a few examples per seed (seconds); set
``HYPOTHESIS_PROFILE=thorough`` for many more.
"""

from __future__ import annotations

import dataclasses
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import SE3
from manopt_lie.problems import LandmarkGraph, LintReport, g2o, synthetic
from manopt_lie.problems.g2o import _source

BOM = b"\xef\xbb\xbf"
NUMBERS = [b"1e308", b"-1e308", b"1e309", b"-1e400", b"nan", b"inf", b"-inf", b"-0.0", b"0", b"5e-324", b"1e-320",
           b"9" * 25, b"-1", b"1.5", b"2", b"1_0", b"0x10", b"1e", b"+.5"]  # fmt: skip
GARBAGE = [
    b"abc",
    b"#",
    b"\x00",
    b"\xff",
    b"\xe2\x82",
    b"FIX",
    b"\t",
    BOM,
    b"\r",
    "é".encode(),
    b"",
    b"\x0c",
    b"\xc2\x85",
]
TAGS = [b"VERTEX_SE2", b"EDGE_SE2", b"VERTEX_SE3:QUAT", b"EDGE_SE3:QUAT", b"FIX", b"VERTEX_XY", b"vertex_se2", b"",
        b"EDGE_SE2_XY", b"EDGE_PRIOR_SE2", b"VERTEX_TRACKXYZ", b"EDGE_SE3_TRACKXYZ", b"PARAMS_SE3OFFSET",
        b"EDGE_SE3_PRIOR", b"PARAMS_SE2OFFSET"]  # fmt: skip
IDS = st.one_of(st.integers(-2, 12), st.sampled_from([2**63, -(2**63) - 1, 2**63 - 1]))

index = st.integers(0, 10**6)  # taken modulo the current number of lines, tokens or bytes
mutation = st.one_of(
    st.tuples(st.just("delete"), index),
    st.tuples(st.just("duplicate"), index),
    st.tuples(st.just("swap"), index, index),
    st.tuples(st.just("truncate"), index),
    st.tuples(st.just("flip"), index, st.integers(1, 255)),
    st.tuples(st.just("insert"), index, index, st.one_of(st.sampled_from(GARBAGE), st.binary(max_size=3))),
    st.tuples(st.just("number"), index, index, st.sampled_from(NUMBERS)),
    st.tuples(st.just("id"), index, st.integers(1, 2), IDS.map(lambda i: str(i).encode())),
    st.tuples(st.just("bom"), st.one_of(st.just(0), index)),
    st.tuples(st.just("line end"), st.sampled_from([b"\r", b"\r\n"]), st.one_of(st.none(), index)),
    st.tuples(st.just("tag"), index, st.sampled_from(TAGS)),
)


def mutate(data: bytes, op: tuple[Any, ...]) -> bytes:
    """``data`` with one mutation applied."""
    kind, *args = op
    if kind == "truncate":
        return data[: args[0] % (len(data) + 1)]
    if kind == "flip":
        if not data:
            return data
        k = args[0] % len(data)
        return data[:k] + bytes([data[k] ^ args[1]]) + data[k + 1 :]
    if kind == "bom":
        k = args[0] % (len(data) + 1)
        return data[:k] + BOM + data[k:]
    lines = data.split(b"\n")
    i = args[0] % len(lines) if kind != "line end" else 0
    if kind == "delete":
        del lines[i]
    elif kind == "duplicate":
        lines.insert(i, lines[i])
    elif kind == "swap":
        j = args[1] % len(lines)
        lines[i], lines[j] = lines[j], lines[i]
    elif kind == "line end":
        end, at = args
        if at is None:
            return data.replace(b"\n", end)
        k = at % len(lines)
        return b"\n".join(lines[:k]) + end + b"\n".join(lines[k:])
    else:
        tokens = lines[i].split(b" ")
        if kind == "insert":
            tokens.insert(args[1] % (len(tokens) + 1), args[2])
        elif kind == "number":
            tokens[max(1, args[1] % len(tokens)) if len(tokens) > 1 else 0] = args[2]
        elif kind == "id":
            tokens[args[1] % len(tokens)] = args[2]
        else:  # tag
            tokens[0] = args[1]
        lines[i] = b" ".join(tokens)
    return b"\n".join(lines)


Outcome = tuple[Any, ...]


def outcome(read: Callable[[], Any], lines: int) -> Outcome:
    """What reading gives: the error (line, reason), or the graph's arrays; lint checked."""
    try:
        graph = read()
    except g2o.ParseError as error:
        assert error.lineno is None or 1 <= error.lineno <= lines, (error.lineno, lines)
        return ("error", error.lineno, error.reason)
    report = g2o.lint(graph)
    assert isinstance(report, LintReport) and str(report)
    landmarks: tuple[Any, ...] = ()
    if isinstance(graph, LandmarkGraph):
        assert report.n_landmarks == graph.n_landmarks
        means = None if graph.prior_means is None else graph.prior_means.as_matrix()
        offsets = None if graph.sensor_offsets is None else graph.sensor_offsets.as_matrix()
        parts = (graph.landmark_ids, graph.landmarks, graph.observations, graph.points, graph.point_information,
                 offsets, graph.offset_ids, graph.prior_poses, means, graph.prior_information,
                 graph.observation_lines, graph.prior_lines)  # fmt: skip
        landmarks = tuple(None if a is None else np.asarray(a).tobytes() for a in parts)
        graph = graph.poses
    poses = None if graph.poses is None else graph.poses.as_matrix().tobytes()
    arrays = (graph.ids, graph.edges, graph.information, graph.measurements.as_matrix(), graph.fixed, graph.edge_lines)
    return ("graph", graph.group, poses, *(np.asarray(a).tobytes() for a in arrays), *landmarks)


def check(data: bytes, block: int) -> None:
    lines = data.count(b"\n") + data.count(b"\r") + 1
    expected = outcome(lambda: g2o.read(io.BytesIO(data)), lines)
    if expected[0] == "graph":
        report = g2o.lint(io.BytesIO(data))  # also for a file: never raises on a readable one
        assert report.renormalized is not None and report.renormalized >= 0
    saved = _source.BLOCK
    _source.BLOCK = block
    try:
        assert outcome(lambda: g2o.read(io.BytesIO(data)), lines) == expected, f"blocks of {block}"
        try:
            source = data.decode("utf-8")
        except UnicodeDecodeError:
            return
        assert outcome(lambda: g2o.loads(source, name="<stream>"), lines) == expected, "loads"
        stream = io.StringIO(source, newline="")
        assert outcome(lambda: g2o.read(stream), lines) == expected, "text stream"
    finally:
        _source.BLOCK = saved


@pytest.fixture(scope="session")
def seeds(dataset) -> dict[str, bytes]:
    grid = synthetic.grid2d(3, 3, loop_closure_probability=0.5, seed=1)
    cube = synthetic.cube(2, loop_closure_probability=0.5, orientation="random", seed=2)
    world2 = synthetic.landmark_world(5, 3, d=2, sensor_range=20.0, max_observations=2, prior=True, seed=3)
    world3 = synthetic.landmark_world(4, 3, d=3, sensor_range=20.0, max_observations=2, prior=True, seed=4)
    k = len(world3.graph.observations)
    sensors = SE3.exp(np.array([[0.1, 0.0, 0.2, 0.0, 0.3, 0.0], [0.0] * 6]))[np.arange(k) % 2]
    offsets = dataclasses.replace(world3.graph, sensor_offsets=sensors, offset_ids=np.array([7, 0])[np.arange(k) % 2])
    return {
        "tinyGrid3D": Path(dataset("tinyGrid3D")).read_bytes(),
        "grid2d": g2o.dumps(grid.graph, grid.truth).encode(),
        "cube": g2o.dumps(cube.graph, cube.truth).encode(),
        "landmarks2d": g2o.dumps(world2.graph, world2.truth).encode(),
        "landmarks3d": g2o.dumps(offsets, world3.truth).encode(),
        "landmarks2d, no vertices": g2o.dumps(world2.graph).encode(),
    }


SEEDS = ["tinyGrid3D", "grid2d", "cube", "landmarks2d", "landmarks3d", "landmarks2d, no vertices"]


@pytest.mark.parametrize("seed", SEEDS)
@given(ops=st.lists(mutation, min_size=1, max_size=4), block=st.sampled_from([1, 3, 64, _source.BLOCK]))
def test_mutated_files_give_a_graph_or_a_parse_error(seeds, seed, ops, block):
    data = seeds[seed]
    for op in ops:
        data = mutate(data, op)
    check(data, block)


@given(data=st.binary(max_size=200), block=st.sampled_from([1, 5, _source.BLOCK]))
def test_random_bytes_give_a_graph_or_a_parse_error(data, block):
    check(data, block)


def test_the_seeds_are_read(seeds):
    """Unmutated, every seed is a graph (so the mutations start from readable files)."""
    for data in seeds.values():
        assert outcome(lambda data=data: g2o.read(io.BytesIO(data)), data.count(b"\n") + 1)[0] == "graph"
    kinds = {name: type(g2o.read(io.BytesIO(data))) for name, data in seeds.items()}
    assert [name for name, kind in kinds.items() if kind is LandmarkGraph] == SEEDS[3:]
    assert g2o.read(io.BytesIO(seeds["landmarks3d"])).sensor_offsets is not None
