"""g2o I/O: parsing (every error path with its line number), writing, exact round trips, lint."""

from __future__ import annotations

import io
import pickle
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup
from manopt_lie.problems import PoseGraph, g2o

# The README's table (sizes checked against the files): group, vertices, edges, has VERTEX lines.
DATASETS = {
    "CSAIL": (SE2, 1045, 1172, False),
    "intel": (SE2, 1728, 2512, True),
    "manhattan": (SE2, 3500, 5453, False),
    "sphere2500": (SE3, 2500, 4949, True),
    "parking-garage": (SE3, 1661, 6275, True),
    "smallGrid3D": (SE3, 125, 297, True),
    "tinyGrid3D": (SE3, 9, 11, True),
}

# Largest change of a rotation matrix entry over write → read. SE2's angle ↔ matrix
# conversions stay within an ulp or two; SE3's quaternion ↔ matrix conversions
# (SO3.from_quaternion, as_quaternion) alone move entries by up to ~1.6e-15, so 1e-15
# cannot hold there (observed: ≤ 1.8e-15 on the datasets, ≤ 3e-15 on random rotations).
ATOL: dict[type[LieGroup], float] = {SE2: 1e-15, SE3: 4e-15}

INFO2 = "500 0 0 500 0 1000"
INFO3 = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1"  # identity, upper triangle row by row


def v2(i: int, pose: str = "0 0 0") -> str:
    return f"VERTEX_SE2 {i} {pose}"


def e2(i: int | str, j: int | str, pose: str = "1 0 0.5", info: str = INFO2) -> str:
    return f"EDGE_SE2 {i} {j} {pose} {info}"


def v3(i: int, pose: str = "0 0 0 0 0 0 1") -> str:
    return f"VERTEX_SE3:QUAT {i} {pose}"


def e3(i: int, j: int, pose: str = "1 0 0 0 0 0 1", info: str = INFO3) -> str:
    return f"EDGE_SE3:QUAT {i} {j} {pose} {info}"


def text(*lines: str) -> str:
    return "\n".join(lines) + "\n"


def assert_round_trip(graph: PoseGraph) -> str:
    """write → read reproduces the arrays, and write ∘ read is the identity on the text."""
    written = g2o.dumps(graph)
    back = g2o.loads(written, name=graph.name)
    assert back.group is graph.group
    np.testing.assert_array_equal(back.ids, graph.ids)
    np.testing.assert_array_equal(back.edges, graph.edges)
    np.testing.assert_array_equal(back.information, graph.information)
    np.testing.assert_array_equal(back.fixed, graph.fixed)
    atol = ATOL[graph.group]
    np.testing.assert_allclose(back.measurements.as_matrix(), graph.measurements.as_matrix(), rtol=0, atol=atol)
    assert (back.poses is None) == (graph.poses is None)
    if back.poses is not None and graph.poses is not None:
        np.testing.assert_allclose(back.poses.as_matrix(), graph.poses.as_matrix(), rtol=0, atol=atol)
    assert g2o.dumps(back) == written
    return written


# ---- parsing ---------------------------------------------------------------------------

SE2_GRAPH = text("# a 2-D graph", v2(0), v2(1, "1 0 0.5"), "", v2(2, "2 0 1"), e2(0, 1), e2(1, 2))
SE3_GRAPH = text(v3(0), v3(1), e3(0, 1))

# (text, line number, pattern of the reason, read keywords)
PARSE_ERRORS = {
    "unknown tag": (text(v2(0), v2(1), "VERTEX_SE2_XY 2 1 2", e2(0, 1)), 3, r"unknown tag 'VERTEX_SE2_XY'", {}),
    "too few fields": (text(v2(0), v2(1), "EDGE_SE2 0 1 1 0 0.5 5 0 0 5"), 3, r"EDGE_SE2 needs 11 fields, got 9", {}),
    "too many fields": (text(v2(0), v2(1), e2(0, 1) + " 7"), 3, r"EDGE_SE2 needs 11 fields, got 12", {}),
    "vertex fields": (text(v3(0), "VERTEX_SE3:QUAT 1 0 0 0 0 0 1"), 2, r"VERTEX_SE3:QUAT needs 8 fields, got 7", {}),
    "edge3 fields": (text(v3(0), v3(1), e3(0, 1, info="1 0 0")), 3, r"EDGE_SE3:QUAT needs 30 fields, got 12", {}),
    "not a number": (text(v2(0), v2(1), e2(0, 1, "1 0 abc")), 3, r"EDGE_SE2 field 5 is 'abc', not a number", {}),
    "not an integer id": (text(v2(0), v2(1), e2(0, 1), e2(0, "1.0")), 4, r"field 2 is '1.0', not an integer id", {}),
    "id out of range": (text(e2(0, 2**70)), 1, r"field 2 is '\d+', out of the 64-bit id range", {}),
    "nan": (text(v2(0), v2(1, "nan 0 0")), 2, r"VERTEX_SE2 field 2 is 'nan', not a finite number", {}),
    "inf": (text(v2(0), v2(1), e2(0, 1, info="500 0 0 inf 0 1000")), 3, r"field 9 is 'inf', not a finite", {}),
    "overflow": (text(v2(0), v2(1), e2(0, 1, "1e400 0 0")), 3, r"field 3 is '1e400', not a finite number", {}),
    "mixed dimensions": (text(v2(0), v2(1), v3(2)), 3, r"VERTEX_SE3:QUAT in a file of 2-D records \(line 1", {}),
    "mixed edges": (text(v3(0), v3(1), e2(0, 1)), 3, r"EDGE_SE2 in a file of 3-D records", {}),
    "duplicate vertex": (text(v2(0), v2(1), v2(0), e2(0, 1)), 3, r"duplicate vertex id 0 \(first on line 1\)", {}),
    "self-loop": (text(v2(0), v2(1), e2(0, 1), e2(1, 1)), 4, r"self-loop edge 1 → 1", {}),
    "self-loop, edges only": (text(e2(0, 1), "", e2(2, 2)), 3, r"self-loop", {}),
    "missing vertex": (text(v2(0), v2(1), e2(0, 1), e2(1, 5)), 4, r"names vertex 5, which has no VERTEX line", {}),
    "FIX unknown vertex": (text(v2(0), v2(1), "FIX 0 9", e2(0, 1)), 3, r"FIX names vertex 9", {}),
    "FIX not an integer": (text(v2(0), v2(1), "FIX x", e2(0, 1)), 3, r"FIX field 'x' is not an integer id", {}),
    "FIX without ids": (text(v2(0), "FIX", v2(1), e2(0, 1)), 2, r"FIX needs at least 1 vertex id", {}),
    "vertex quaternion": (text(v3(0), v3(1, "0 0 0 0 0 0 1.0002")), 2, r"vertex quaternion norm 1\.0002 ", {}),
    "edge quaternion": (text(v3(0), v3(1), e3(0, 1, "1 0 0 0 0 0 0.9")), 3, r"edge quaternion norm 0\.9 is not 1", {}),
    "zero quaternion": (text(v3(0), v3(1), e3(0, 1, "1 0 0 0 0 0 0")), 3, r"quaternion norm 0\.0", {}),
    "quaternion_tol": (SE3_GRAPH.replace("0 0 0 1 1", "0 0 0 1.001 1"), 3, r"quaternion", {"quaternion_tol": 1e-4}),
    # Several problems: the earliest line is reported, whatever the kind or tag.
    "earliest, numbers": (text(e2(0, 1, "x 0 0"), v2(0, "y 0 0"), v2(1)), 1, r"EDGE_SE2 field 3 is 'x'", {}),
    "earliest, nan before text": (text(v2(0), v2(1, "inf 0 0"), v2(2, "z 0 0")), 2, r"'inf', not a finite", {}),
    "earliest, semantics": (text(e2(0, 7), v2(0), v2(1), v2(0)), 1, r"names vertex 7", {}),
}


@pytest.mark.parametrize("case", PARSE_ERRORS)
def test_parse_errors_name_the_line(case):
    source, lineno, pattern, kwargs = PARSE_ERRORS[case]
    with pytest.raises(g2o.ParseError, match=pattern) as info:
        g2o.loads(source, name="bad.g2o", **kwargs)
    error = info.value
    assert isinstance(error, ValueError)
    assert (error.filename, error.lineno) == ("bad.g2o", lineno)
    assert str(error).startswith(f"bad.g2o:{lineno}: ")
    assert str(error) == f"bad.g2o:{lineno}: {error.reason}"


@pytest.mark.parametrize("source", ["", "\n\n", "# nothing but comments\n\n# here\n", "FIX 1\n"])
def test_a_file_without_records_is_a_parse_error_without_line(source):
    with pytest.raises(g2o.ParseError, match=r"^empty\.g2o: no VERTEX or EDGE lines$") as info:
        g2o.loads(source, name="empty.g2o")
    assert info.value.lineno is None


def test_parse_error_from_a_file_names_the_path_and_pickles(tmp_path):
    path = tmp_path / "intel.g2o"
    path.write_text(text(v2(0), v2(1), "EDGE_SE2 0 1 1 0 0.5 500 0 0 500"))
    with pytest.raises(g2o.ParseError) as info:
        g2o.read(path)
    assert str(info.value) == f"{path}:3: EDGE_SE2 needs 11 fields, got 9"
    copy = pickle.loads(pickle.dumps(info.value))
    assert (str(copy), copy.filename, copy.lineno) == (str(info.value), str(path), 3)


def test_fields_are_read_in_g2o_order():
    graph = g2o.loads(text(v2(4, "1 2 0.25"), v2(9), e2(4, 9, "3 -4 -2.5", "1 2 3 4 5 6"), "FIX 9"))
    assert graph.group is SE2 and (graph.n, graph.m) == (2, 1)
    np.testing.assert_array_equal(graph.information[0], [[1, 2, 3], [2, 4, 5], [3, 5, 6]])
    np.testing.assert_array_equal(graph.measurements.translation(), [[3, -4]])
    assert graph.measurements.rotation().angle()[0] == pytest.approx(-2.5, abs=1e-15)
    np.testing.assert_array_equal(graph.poses.translation(), [[1, 2], [0, 0]])
    np.testing.assert_array_equal(graph.fixed, [1])
    assert graph.anchor == 1

    info = " ".join(str(i) for i in range(1, 22))
    a = 0.3  # rotation about z by a: q = (0, 0, sin(a/2), cos(a/2)), scalar last
    q = " ".join(map(repr, [0.0, 0.0, float(np.sin(a / 2)), float(np.cos(a / 2))]))
    graph = g2o.loads(text(v3(0), v3(1), e3(0, 1, f"1 2 3 {q}", info)))
    omega = graph.information[0]
    assert (omega[0, 0], omega[0, 5], omega[1, 1], omega[2, 4], omega[5, 5], omega[5, 0]) == (1, 6, 7, 14, 21, 6)
    np.testing.assert_array_equal(omega, omega.T)
    np.testing.assert_array_equal(graph.measurements.translation(), [[1, 2, 3]])
    np.testing.assert_allclose(graph.measurements.rotation().as_matrix()[0], SO3.exp([0, 0, a]).as_matrix(), atol=1e-15)


def test_comments_blank_lines_and_fix_lines():
    source = (
        "# header comment\n"
        "\n"
        "VERTEX_SE2 0 0 0 0   # inline comment\n"
        "   VERTEX_SE2 1 1 0 0\r\n"
        "FIX 1\n"
        "\t\n"
        f"{e2(0, 1)}\n"
        "FIX 0 1  # 1 again: kept once, in first-seen order\n"
        "# trailing comment\n"
        "\n"
        "\n"
    )
    graph = g2o.loads(source)
    assert (graph.n, graph.m) == (2, 1)
    np.testing.assert_array_equal(graph.fixed, [1, 0])
    assert graph.anchor == 1
    written = assert_round_trip(graph)
    assert [line.split()[0] for line in written.splitlines()] == ["VERTEX_SE2", "VERTEX_SE2", "FIX", "EDGE_SE2"]
    assert "FIX 1 0\n" in written


def test_edges_only_files_take_their_vertices_from_the_edges():
    graph = g2o.loads(text(e2(0, 5), e2(5, 9), e2(9, 0), "FIX 5"))
    assert graph.poses is None
    np.testing.assert_array_equal(graph.ids, [0, 5, 9])
    np.testing.assert_array_equal(graph.edges, [[0, 1], [1, 2], [2, 0]])
    written = assert_round_trip(graph)
    assert "VERTEX" not in written and "FIX 5\n" in written
    # Poses given to write add the vertex lines.
    poses = SE2.exp(np.arange(9.0).reshape(3, 3) / 10)
    back = g2o.loads(g2o.dumps(graph, poses))
    np.testing.assert_allclose(back.poses.as_matrix(), poses.as_matrix(), rtol=0, atol=1e-15)


def test_a_file_with_vertices_only():
    graph = g2o.loads(text(v2(3, "1 2 0.5"), v2(1)))
    assert (graph.n, graph.m) == (2, 0)
    assert_round_trip(graph)
    report = g2o.lint(graph)
    np.testing.assert_array_equal(report.isolated, [1, 3])
    np.testing.assert_array_equal(report.unreachable, [3])


def test_non_contiguous_unsorted_ids_are_kept_for_writing():
    source = text(v2(10, "10 0 0"), v2(3, "3 0 0"), v2(7, "7 0 0"), e2(10, 3), e2(3, 7), "FIX 10")
    graph = g2o.loads(source)
    np.testing.assert_array_equal(graph.ids, [3, 7, 10])
    np.testing.assert_array_equal(graph.poses.translation()[:, 0], [3, 7, 10])
    np.testing.assert_array_equal(graph.edges, [[2, 0], [0, 1]])
    np.testing.assert_array_equal(graph.fixed, [2])
    written = assert_round_trip(graph)
    assert written.startswith("VERTEX_SE2 3 3.0 0.0 0.0\nVERTEX_SE2 7 ")
    assert "EDGE_SE2 10 3 1.0 0.0 " in written and "FIX 10\n" in written


def test_quaternions_within_tolerance_are_normalized():
    c, s = np.cos(0.2), np.sin(0.2)
    scaled = " ".join(repr(float(x) * (1 + 5e-5)) for x in (0.0, 0.0, s, c))
    graph = g2o.loads(text(v3(0, f"0 0 0 {scaled}"), v3(1), e3(0, 1)))
    np.testing.assert_allclose(graph.poses.rotation().as_matrix()[0], SO3.exp([0, 0, 0.4]).as_matrix(), atol=1e-15)
    off = text(v3(0), v3(1, "0 0 0 0 0 0 1.0002"), e3(0, 1))
    with pytest.raises(g2o.ParseError, match=r"quaternion_tol=0\.0001") as info:
        g2o.loads(off)
    assert info.value.lineno == 2
    graph = g2o.loads(off, quaternion_tol=1e-3)
    np.testing.assert_array_equal(graph.poses.rotation().as_matrix()[1], np.eye(3))
    with pytest.raises(g2o.ParseError, match=r"quaternion_tol=1e-06"):
        g2o.loads(text(v3(0), v3(1, "0 0 0 0 0 0 1.00002"), e3(0, 1)), quaternion_tol=1e-6)


def test_indefinite_information_is_read_and_reported_by_lint():
    source = text(v2(0), v2(1), v2(2), e2(0, 1), e2(1, 2, info="1 0 0 -2 0 1"), e2(2, 0, info="1 2 0 1 0 1"))
    graph = g2o.loads(source, name="bad-info")
    np.testing.assert_array_equal(graph.information[1], np.diag([1.0, -2.0, 1.0]))
    report = g2o.lint(graph)
    np.testing.assert_array_equal(report.indefinite, [1, 2])
    np.testing.assert_array_equal(report.indefinite_ids, [[1, 2], [2, 0]])
    np.testing.assert_allclose(report.min_eigenvalues, [-2.0, -1.0], atol=1e-12)
    assert not report.ok and report.connected
    assert "2 information matrices not positive definite: 1→2 (λmin -2), 2→0 (λmin -1)" in str(report)
    assert g2o.lint(graph).indefinite.tolist() == [1, 2]
    assert_round_trip(graph)


# ---- lint ------------------------------------------------------------------------------


def test_lint_of_a_clean_graph_is_ok(tmp_path):
    path = tmp_path / "clean.g2o"
    path.write_text(SE2_GRAPH)
    report = g2o.lint(path)
    assert report.ok and report.connected and (report.n, report.m) == (3, 2)
    assert str(report) == "clean: 3 vertices, 2 edges: ok"


def test_lint_finds_duplicates_isolated_and_unreachable_vertices():
    source = text(*(v2(i) for i in (0, 1, 2, 3, 4, 8)), e2(0, 1), e2(1, 0), e2(2, 3), e2(0, 1), e2(3, 8))
    report = g2o.lint(g2o.loads(source, name="messy"))
    np.testing.assert_array_equal(report.duplicates, [1, 3])
    np.testing.assert_array_equal(report.duplicate_ids, [[1, 0], [0, 1]])
    np.testing.assert_array_equal(report.isolated, [4])
    np.testing.assert_array_equal(report.unreachable, [2, 3, 4, 8])
    assert not report.ok and not report.connected and report.indefinite.size == 0
    lines = str(report).splitlines()
    assert lines[0] == "messy: 6 vertices, 5 edges"
    assert "2 duplicate edges: 1→0, 0→1" in lines[1]
    assert "1 vertex without edges: 4" in lines[2]
    assert "4 vertices unreachable from vertex 0: 2, 3, 4, 8" in lines[3]
    # Connectivity is judged from the anchor, the first FIX-ed vertex.
    report = g2o.lint(g2o.loads(source + "FIX 3\n"))
    assert report.anchor == 3
    np.testing.assert_array_equal(report.unreachable, [0, 1, 4])


def test_lint_flags_asymmetric_information():
    info = np.stack([np.eye(3), [[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]]])
    graph = PoseGraph(SE2, np.array([[0, 1], [1, 2]]), SE2.identity((2,)), info)
    report = g2o.lint(graph)
    np.testing.assert_array_equal(report.asymmetric, [1])
    assert report.indefinite.size == 0 and not report.ok
    assert "1 information matrix not symmetric: edges 1" in str(report)


# ---- writing ---------------------------------------------------------------------------


def test_write_to_paths_and_files_and_read_from_files(tmp_path):
    graph = g2o.loads(SE3_GRAPH, name="small")
    path = tmp_path / "small.g2o"
    g2o.write(path, graph)
    buffer = io.StringIO()
    g2o.write(buffer, graph)
    assert path.read_text() == buffer.getvalue() == g2o.dumps(graph)
    assert g2o.read(path).name == "small"
    assert g2o.read(str(path), name="other").name == "other"
    with open(path) as f:
        assert g2o.read(f).name == "small"
    from_bytes = g2o.read(io.BytesIO(path.read_bytes()))
    assert g2o.dumps(from_bytes) == buffer.getvalue()


def test_write_checks_its_poses():
    graph = g2o.loads(SE2_GRAPH)
    with pytest.raises(ShapeError, match=r"batch shape \(3,\)"):
        g2o.dumps(graph, SE2.identity((2,)))
    with pytest.raises(ShapeError, match="must be SE2"):
        g2o.dumps(graph, SE3.identity((3,)))
    lonely = PoseGraph(SE2, np.array([[0, 1]]), SE2.identity((1,)), np.eye(3)[None], ids=np.array([0, 1, 2]))
    with pytest.raises(ValueError, match=r"vertices \[2\] have no edge and no pose"):
        g2o.dumps(lonely)


def special_graph(group: type[LieGroup]) -> PoseGraph:
    """Rotations where conversions are delicate: 0, ±π, tiny angles, quaternions with w = 0."""
    if group is SE2:
        angles = np.array([0.0, -0.0, np.pi, -np.pi, np.nextafter(np.pi, 0), 1e-300, 5e-324, 1e-9, -3e-5, 7.0, -100.0])
        rotations: LieGroup = SO2.from_angle(angles)
    else:
        q = np.array(
            [
                [0, 0, 0, 1],
                [1, 0, 0, 0],
                [0, 1, 0, 0],
                [0, 0, 1, 0],
                [1, 1, 1, 0],
                [1, -1, 0, 1e-12],
                [0.5, 0.5, 0.5, -0.5],
                [1e-12, 0, 0, 1],
                [3e-9, -1e-8, 2e-10, 1],
                [0.6, 0.8, 0, 1e-17],
                [1, 2, 3, 4],
            ]
        )
        rotations = SO3.from_quaternion(q, normalize=True)
    k = len(rotations)
    translations = np.linspace(-1e3, 1e-3, k * group.point_dim).reshape(k, group.point_dim)
    measurements = group.from_rotation_translation(rotations, translations)  # type: ignore[attr-defined]
    edges = np.stack([np.arange(k) % 3, np.arange(k) % 3 + 1], axis=1)
    information = np.broadcast_to(np.eye(group.dim), (k, group.dim, group.dim))
    return PoseGraph(group, edges, measurements, information, poses=measurements[:4], name="special")


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_round_trip_of_delicate_rotations(group):
    assert_round_trip(special_graph(group))


def random_graph(group: type[LieGroup], rng: np.random.Generator, n: int, extra: int, with_poses: bool) -> PoseGraph:
    """A connected graph on ``n`` vertices with non-contiguous ids, random measurements of
    random scales, symmetric (sometimes indefinite) information and a few FIX-ed vertices."""
    ids = np.sort(rng.choice(50 * n, size=n, replace=False)) - 5 * n
    chain = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    more = rng.integers(0, n, size=(extra, 2))
    edges = np.concatenate([chain, more[more[:, 0] != more[:, 1]]])
    edges = np.where(rng.random((len(edges), 1)) < 0.5, edges, edges[:, ::-1])
    m, k = len(edges), group.dim

    def elements(count: int) -> LieGroup:
        x = group.random(rng, (count,))
        t = rng.standard_normal((count, group.point_dim)) * 10.0 ** rng.uniform(-6, 6, (count, 1))
        return group.from_rotation_translation(x.rotation(), t)  # type: ignore[attr-defined]

    a = rng.standard_normal((m, k, k)) * 10.0 ** rng.uniform(-6, 6, (m, 1, 1))
    information = a + np.swapaxes(a, 1, 2)
    fixed = rng.choice(n, size=int(rng.integers(0, 3)), replace=False)
    poses = elements(n) if with_poses else None
    return PoseGraph(group, edges, elements(m), information, ids=ids, poses=poses, fixed=fixed, name="random")


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    extra=st.integers(0, 60),
    with_poses=st.booleans(),
)
def test_round_trip_of_random_graphs(group, seed, n, extra, with_poses):
    assert_round_trip(random_graph(group, np.random.default_rng(seed), n, extra, with_poses))


def test_a_15k_pose_file_loads_well_under_a_second(tmp_path):
    graph = random_graph(SE2, np.random.default_rng(0), 15000, 1000, with_poses=True)
    path = tmp_path / "big.g2o"
    g2o.write(path, graph)
    start = time.perf_counter()
    back = g2o.read(path)
    elapsed = time.perf_counter() - start
    assert (back.n, back.m) == (graph.n, graph.m)
    assert elapsed < 1.0, f"reading {back} took {elapsed:.2f} s"


# ---- the shared datasets ---------------------------------------------------------------


@pytest.mark.parametrize("name", DATASETS)
def test_datasets_have_the_documented_sizes(dataset, name):
    group, n, m, has_vertices = DATASETS[name]
    graph = g2o.read(dataset(name))
    assert (graph.name, graph.group, graph.n, graph.m) == (name, group, n, m)
    assert (graph.poses is not None) == has_vertices
    np.testing.assert_array_equal(graph.ids, np.arange(n))
    report = g2o.lint(graph)
    assert report.connected and report.indefinite.size == 0 and report.isolated.size == 0
    # CSAIL repeats one loop closure; nothing else is wrong with any of them.
    assert report.duplicate_ids.tolist() == ([[323, 855]] if name == "CSAIL" else [])


def test_every_dataset_round_trips(datasets_dir: Path):
    files = sorted(datasets_dir.glob("*.g2o"))
    assert files, f"no .g2o files in {datasets_dir}"
    for path in files:
        assert_round_trip(g2o.read(path))
