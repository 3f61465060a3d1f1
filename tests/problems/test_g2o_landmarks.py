"""g2o files with landmarks, sensor offsets and priors: each tag read in g2o's field order,
errors with their lines, exact round trips, solves of synthetic worlds, lint, GTSAM's reader."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manopt_lie import SE2, SE3, SO3
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.lie.base import LieGroup
from manopt_lie.optim import LevenbergMarquardt
from manopt_lie.problems import LandmarkGraph, PoseGraph, g2o, synthetic
from manopt_lie.problems.g2o import _source
from tests.problems.test_g2o import ATOL, INFO2, INFO3, e2, e3, text, v2, v3

XY_INFO = "10 1 20"  # 2×2 upper triangle
XYZ_INFO = "10 1 2 20 3 30"  # 3×3 upper triangle
IDENTITY = "0 0 0 0 0 0 1"


def vxy(i: int, point: str = "1 2") -> str:
    return f"VERTEX_XY {i} {point}"


def exy(i: int, a: int, point: str = "1 0.5", info: str = XY_INFO) -> str:
    return f"EDGE_SE2_XY {i} {a} {point} {info}"


def pr2(i: int, pose: str = "0.5 -1 0.25", info: str = INFO2) -> str:
    return f"EDGE_PRIOR_SE2 {i} {pose} {info}"


def vxyz(i: int, point: str = "1 2 3") -> str:
    return f"VERTEX_TRACKXYZ {i} {point}"


def exyz(i: int, a: int, p: int = 0, point: str = "1 0.5 -2", info: str = XYZ_INFO) -> str:
    return f"EDGE_SE3_TRACKXYZ {i} {a} {p} {point} {info}"


def par(p: int, pose: str = IDENTITY) -> str:
    return f"PARAMS_SE3OFFSET {p} {pose}"


def pr3(i: int, p: int = 0, pose: str = "1 2 3 0 0 0 1", info: str = INFO3) -> str:
    return f"EDGE_SE3_PRIOR {i} {p} {pose} {info}"


GRAPH2 = text(v2(0), v2(1, "1 0 0.5"), vxy(7, "1 0.5"), e2(0, 1), exy(0, 7), exy(1, 7, "0.5 0.5"), pr2(0))
GRAPH3 = text(par(0), v3(0), v3(1), vxyz(7, "1 0.5 -2"), e3(0, 1), exyz(0, 7), exyz(1, 7), pr3(0))


def assert_round_trip(graph: LandmarkGraph, estimates=None) -> str:
    """write → read reproduces the arrays (bit for bit where the format allows), and
    write ∘ read is the identity on the text."""
    written = g2o.dumps(graph, estimates)
    back = g2o.loads(written, name=graph.name)
    assert isinstance(back, LandmarkGraph) and back.group is graph.group
    atol = ATOL[graph.group]
    order = np.argsort(graph.landmark_ids, kind="stable")
    np.testing.assert_array_equal(back.landmark_ids, graph.landmark_ids[order])
    np.testing.assert_array_equal(back.poses.ids, graph.poses.ids)
    np.testing.assert_array_equal(back.poses.edges, graph.poses.edges)
    np.testing.assert_array_equal(back.poses.information, graph.poses.information)
    np.testing.assert_array_equal(back.observations[:, 0], graph.observations[:, 0])
    np.testing.assert_array_equal(
        back.landmark_ids[back.observations[:, 1]], graph.landmark_ids[graph.observations[:, 1]]
    )
    if graph.group is SE3 or graph.sensor_offsets is None:
        np.testing.assert_array_equal(back.points, graph.points)
        np.testing.assert_array_equal(back.point_information, graph.point_information)
    np.testing.assert_array_equal(back.prior_poses, graph.prior_poses)
    np.testing.assert_array_equal(back.prior_information, graph.prior_information)
    if len(graph.prior_poses):
        np.testing.assert_allclose(back.prior_means.as_matrix(), graph.prior_means.as_matrix(), rtol=0, atol=atol)
    landmarks = graph.landmarks if estimates is None else np.asarray(estimates["landmarks"])
    if landmarks is not None:
        np.testing.assert_array_equal(back.landmarks, landmarks[order])
    assert g2o.dumps(back) == written
    return written


# ---- each tag, in g2o's field order ----------------------------------------------------


def test_2d_tags_are_read_in_g2o_field_order():
    source = text(v2(3), v2(5), vxy(9, "4 -2"), vxy(1, "-1 0.5"), e2(3, 5), exy(5, 9, "0.25 -3", "1 2 3"),
                  exy(3, 1), "", pr2(5, "7 8 0.5", "1 2 3 4 5 6"), "FIX 3")  # fmt: skip
    graph = g2o.loads(source, name="two")
    assert isinstance(graph, LandmarkGraph) and isinstance(graph.poses, PoseGraph) and graph.group is SE2
    np.testing.assert_array_equal(graph.poses.ids, [3, 5])
    np.testing.assert_array_equal(graph.landmark_ids, [1, 9])  # increasing order, like the poses
    np.testing.assert_array_equal(graph.landmarks, [[-1, 0.5], [4, -2]])
    np.testing.assert_array_equal(graph.observations, [[1, 1], [0, 0]])
    np.testing.assert_array_equal(graph.points, [[0.25, -3], [1, 0.5]])
    np.testing.assert_array_equal(graph.point_information[0], [[1, 2], [2, 3]])
    np.testing.assert_array_equal(graph.prior_poses, [1])
    np.testing.assert_array_equal(graph.prior_means.translation(), [[7, 8]])
    assert graph.prior_means.rotation().angle()[0] == pytest.approx(0.5, abs=1e-15)
    np.testing.assert_array_equal(graph.prior_information[0], [[1, 2, 3], [2, 4, 5], [3, 5, 6]])
    np.testing.assert_array_equal(graph.observation_lines, [6, 7])
    np.testing.assert_array_equal(graph.prior_lines, [9])
    np.testing.assert_array_equal(graph.poses.edge_lines, [5])
    np.testing.assert_array_equal(graph.poses.fixed, [0])
    assert graph.sensor_offsets is None and graph.offset_ids is None and graph.name == "two"


def test_3d_tags_are_read_in_g2o_field_order():
    a = 0.3  # a rotation about z by a, scalar last
    q = f"0 0 {float(np.sin(a / 2))!r} {float(np.cos(a / 2))!r}"
    info6 = " ".join(str(i) for i in range(1, 7))
    info21 = " ".join(str(i) for i in range(1, 22))
    source = text(par(4, f"0.1 0.2 0.3 {q}"), par(0), v3(0), v3(1), vxyz(7, "4 5 6"), e3(0, 1),
                  exyz(0, 7, 4, "1 2 3", info6), exyz(1, 7, 0), pr3(1, 0, f"7 8 9 {q}", info21))  # fmt: skip
    graph = g2o.loads(source)
    assert isinstance(graph, LandmarkGraph) and graph.group is SE3
    np.testing.assert_array_equal(graph.landmarks, [[4, 5, 6]])
    np.testing.assert_array_equal(graph.observations, [[0, 0], [1, 0]])
    np.testing.assert_array_equal(graph.points[0], [1, 2, 3])
    np.testing.assert_array_equal(graph.point_information[0], [[1, 2, 3], [2, 4, 5], [3, 5, 6]])
    np.testing.assert_array_equal(graph.offset_ids, [4, 0])
    offsets = graph.sensor_offsets.as_matrix()
    np.testing.assert_array_equal(offsets[0, :3, 3], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(offsets[0, :3, :3], SO3.exp([0, 0, a]).as_matrix(), atol=1e-15)
    np.testing.assert_array_equal(offsets[1], np.eye(4))
    omega = graph.prior_information[0]  # identity offset: as in the file
    assert (omega[0, 0], omega[0, 5], omega[1, 1], omega[2, 4], omega[5, 5], omega[5, 0]) == (1, 6, 7, 14, 21, 6)
    np.testing.assert_array_equal(graph.prior_means.translation(), [[7, 8, 9]])
    np.testing.assert_array_equal(graph.prior_poses, [1])


def test_a_file_of_pose_lines_stays_a_pose_graph():
    assert type(g2o.loads(text(v2(0), v2(1), e2(0, 1)))) is PoseGraph
    # A parameter nobody uses does not make a landmark graph (and is dropped).
    graph = g2o.loads(text(par(0), v3(0), v3(1), e3(0, 1)))
    assert type(graph) is PoseGraph and "PARAMS" not in g2o.dumps(graph)
    for extra in (vxy(5), exy(0, 1), pr2(0)):
        source = text(v2(0), v2(1), e2(0, 1), extra) if extra != exy(0, 1) else text(v2(0), vxy(1), extra)
        assert type(g2o.loads(source)) is LandmarkGraph


@pytest.mark.parametrize("source", [GRAPH2, GRAPH3], ids=["2-D", "3-D"])
def test_every_tag_round_trips(source):
    graph = g2o.loads(source)
    written = assert_round_trip(graph)
    tags = [line.split()[0] for line in written.splitlines()]
    if graph.group is SE2:
        assert tags == ["VERTEX_SE2"] * 2 + ["VERTEX_XY", "EDGE_SE2"] + ["EDGE_SE2_XY"] * 2 + ["EDGE_PRIOR_SE2"]
    else:
        expected = ["PARAMS_SE3OFFSET"] + ["VERTEX_SE3:QUAT"] * 2 + ["VERTEX_TRACKXYZ", "EDGE_SE3:QUAT"]
        assert tags == expected + ["EDGE_SE3_TRACKXYZ"] * 2 + ["EDGE_SE3_PRIOR"]


def test_written_order_puts_parameters_and_vertices_before_their_edges():
    """g2o resolves parameters and vertices when it reads an edge: they come first."""
    graph = g2o.loads(text(exyz(0, 7, 3), pr3(0, 3), e3(0, 1), v3(1), vxyz(7), v3(0), par(3), "FIX 1"))
    written = g2o.dumps(graph)
    assert written.splitlines()[0] == "PARAMS_SE3OFFSET 3 0.0 0.0 0.0 0.0 0.0 0.0 1.0"
    assert [line.split()[:2] for line in written.splitlines()[1:5]] == [
        ["VERTEX_SE3:QUAT", "0"], ["VERTEX_SE3:QUAT", "1"], ["VERTEX_TRACKXYZ", "7"], ["FIX", "1"]]  # fmt: skip
    assert_round_trip(graph)


# ---- errors, with their lines ----------------------------------------------------------

PARSE_ERRORS = {
    # field counts and numbers, per tag
    "VERTEX_XY fields": (text(v2(0), "VERTEX_XY 5 1"), 2, r"VERTEX_XY needs 3 fields, got 2"),
    "EDGE_SE2_XY fields": (text(v2(0), vxy(5), exy(0, 5, info="1 0")), 3, r"EDGE_SE2_XY needs 7 fields, got 6"),
    "EDGE_PRIOR_SE2 fields": (text(v2(0), pr2(0) + " 1"), 2, r"EDGE_PRIOR_SE2 needs 10 fields, got 11"),
    "VERTEX_TRACKXYZ fields": (text(v3(0), "VERTEX_TRACKXYZ 5 1 2"), 2, r"VERTEX_TRACKXYZ needs 4 fields, got 3"),
    "EDGE_SE3_TRACKXYZ fields": (
        text(par(0), v3(0), vxyz(5), "EDGE_SE3_TRACKXYZ 0 5 1 2 3 " + XYZ_INFO),
        4,
        r"EDGE_SE3_TRACKXYZ needs 12 fields, got 11",
    ),  # the parameter id forgotten
    "PARAMS_SE3OFFSET fields": (
        text("PARAMS_SE3OFFSET 0 0 0 0 0 0 1", v3(0)),
        1,
        r"PARAMS_SE3OFFSET needs 8 fields, got 7",
    ),
    "EDGE_SE3_PRIOR fields": (
        text(par(0), v3(0), "EDGE_SE3_PRIOR 0 1 2 3 0 0 0 1 " + INFO3),
        3,
        r"EDGE_SE3_PRIOR needs 30 fields, got 29",
    ),  # the parameter id forgotten
    "point not a number": (text(v2(0), vxy(5, "1 x")), 2, r"VERTEX_XY field 3 is 'x', not a number"),
    "observation info nan": (text(v2(0), vxy(5), exy(0, 5, info="1 nan 1")), 3, r"field 6 is 'nan', not a finite"),
    "param id not an integer": (
        text(par(0), v3(0), vxyz(5), exyz(0, 5).replace(" 5 0 ", " 5 0.0 ")),
        4,
        r"EDGE_SE3_TRACKXYZ field 3 is '0.0', not an integer id",
    ),
    "prior param not an integer": (
        text(par(0), v3(0), pr3(0).replace("PRIOR 0 0", "PRIOR 0 x")),
        3,
        r"EDGE_SE3_PRIOR field 2 is 'x', not an integer id",
    ),
    "param quaternion": (text(par(0, "0 0 0 0 0 0 1.1"), v3(0)), 1, r"parameter quaternion norm 1\.1 is not 1"),
    "prior quaternion": (text(par(0), v3(0), pr3(0, pose="1 2 3 0 0 0 2")), 3, r"prior quaternion norm 2\.0 is not"),
    # dimensions
    "VERTEX_XY in 3-D": (text(v3(0), vxy(5)), 2, r"VERTEX_XY in a file of 3-D records \(line 1 is VERTEX_SE3:QUAT\)"),
    "VERTEX_TRACKXYZ in 2-D": (text(v2(0), vxyz(5)), 2, r"VERTEX_TRACKXYZ in a file of 2-D records"),
    "PARAMS in 2-D": (text(v2(0), par(0)), 2, r"PARAMS_SE3OFFSET in a file of 2-D records"),
    "2-D prior in 3-D": (text(par(0), v3(0), pr2(0)), 3, r"EDGE_PRIOR_SE2 in a file of 3-D records"),
    # parameters
    "undefined param": (
        text(par(0), v3(0), vxyz(5), exyz(0, 5, 3)),
        4,
        r"observation 0 → 5 names parameter 3, which has no PARAMS_SE3OFFSET line",
    ),
    "param 0 undefined": (
        text(v3(0), vxyz(5), exyz(0, 5, 0)),
        3,
        r"observation 0 → 5 names parameter 0, which has no PARAMS_SE3OFFSET line",
    ),
    "prior param undefined": (text(v3(0), pr3(0, 2)), 2, r"prior on 0 names parameter 2, which has no PARAMS_SE3"),
    "duplicate param": (
        text(par(1), v3(0), par(1, "1 0 0 0 0 0 1")),
        3,
        r"duplicate parameter id 1 \(first on line 1\)",
    ),
    # ids: undefined, wrong kind, one id space
    "undefined pose": (
        text(v2(0), vxy(5), exy(2, 5)),
        3,
        r"observation 2 → 5 names pose 2, which has no VERTEX_SE2 line",
    ),
    "undefined landmark": (
        text(v2(0), vxy(5), exy(0, 6)),
        3,
        r"observation 0 → 6 names landmark 6, which has no VERTEX_XY line",
    ),
    "undefined 3-D landmark": (
        text(par(0), v3(0), vxyz(5), exyz(0, 6)),
        4,
        r"names landmark 6, which has no VERTEX_TRACKXYZ line",
    ),
    "prior on undefined pose": (text(v2(0), pr2(4)), 2, r"prior on 4 names pose 4, which has no VERTEX_SE2 line"),
    "landmark id is a pose id": (
        text(v2(0), v2(5), vxy(5), e2(0, 5)),
        3,
        r"vertex id 5 is used as a landmark here and as a pose on line 2 \(one id space\)",
    ),
    "pose id is a landmark id": (
        text(vxy(5), v2(0), v2(5)),
        3,
        r"vertex id 5 is used as a pose here and as a landmark on",
    ),
    "duplicate landmark": (text(v2(0), vxy(5), vxy(5, "3 3")), 3, r"duplicate vertex id 5 \(first on line 2\)"),
    "observation of a pose": (
        text(v2(0), v2(1), vxy(5), exy(0, 1)),
        4,
        r"observation 0 → 1 names landmark 1, but 1 is a pose \(line 2\)",
    ),
    "observation from a landmark": (
        text(v2(0), vxy(5), vxy(6), exy(5, 6)),
        4,
        r"observation 5 → 6 names pose 5, but 5 is a landmark \(line 2\)",
    ),
    "edge to a landmark": (
        text(v2(0), vxy(5), e2(0, 5)),
        3,
        r"edge 0 → 5 names vertex 5, a landmark \(line 2\), not a",
    ),
    "prior on a landmark": (text(v2(0), vxy(5), pr2(5)), 3, r"prior on 5 names pose 5, but 5 is a landmark"),
    "FIX a landmark": (text(v2(0), vxy(5), exy(0, 5), "FIX 5"), 4, r"FIX names landmark 5: only poses can be fixed"),
    # files without VERTEX lines of a kind: the measurements define the ids, consistently
    "edges only, landmark is a pose": (
        text(e2(0, 1), exy(0, 1)),
        2,
        r"vertex id 1 is used as a landmark here and as a pose on line 1",
    ),
    "edges only, pose is a landmark": (
        text(exy(0, 5), e2(0, 5)),
        2,
        r"vertex id 5 is used as a pose here and as a landmark on line 1",
    ),
    "edges only, self-observation": (
        text(e2(0, 1), exy(2, 2)),
        2,
        r"vertex id 2 is named as both the pose and the landmark of the observation",
    ),
    "implicit landmark is a pose vertex": (
        text(v2(0), v2(1), exy(0, 1)),
        3,
        r"vertex id 1 is used as a landmark here and as a pose on line 2",
    ),
    "implicit pose is a landmark vertex": (
        text(vxy(5), vxy(6), exy(5, 6)),
        3,
        r"vertex id 5 is used as a pose here and as a landmark on line 1",
    ),
    # the earliest line wins, whatever the kind of problem
    "earliest": (text(v2(0), exy(0, 9), vxy(5), vxy(5), exy(3, 5)), 2, r"names landmark 9"),
    "earliest, params": (text(v3(0), vxyz(5), exyz(0, 5, 2), par(1), par(1), "FIX 9"), 3, r"names parameter 2"),
}


@pytest.mark.parametrize("case", PARSE_ERRORS)
def test_parse_errors_name_the_line(case):
    source, lineno, pattern = PARSE_ERRORS[case]
    with pytest.raises(g2o.ParseError, match=pattern) as info:
        g2o.loads(source, name="bad.g2o")
    assert (info.value.filename, info.value.lineno) == ("bad.g2o", lineno)
    assert str(info.value) == f"bad.g2o:{lineno}: {info.value.reason}"


@pytest.mark.parametrize("block", [7, 64, _source.BLOCK])
def test_landmark_files_read_alike_in_any_blocks(monkeypatch: pytest.MonkeyPatch, block: int):
    whole = g2o.dumps(g2o.loads(GRAPH3))
    monkeypatch.setattr(_source, "BLOCK", block)
    for source in (GRAPH2, GRAPH3):
        assert g2o.dumps(g2o.read(io.BytesIO(source.replace("\n", "\r\n").encode()))) == g2o.dumps(g2o.loads(source))
    assert g2o.dumps(g2o.loads(GRAPH3)) == whole
    with pytest.raises(g2o.ParseError, match="names parameter 3") as info:
        g2o.read(io.BytesIO((GRAPH3 + exyz(1, 7, 3) + "\n").encode()))
    assert info.value.lineno == len(GRAPH3.splitlines()) + 1


# ---- files without vertices of a kind --------------------------------------------------


def test_measurements_define_the_vertices_a_file_does_not_list():
    source = text(e2(0, 5), exy(0, 100), exy(5, 100), exy(5, 101), pr2(9))
    graph = g2o.loads(source)
    assert graph.poses.poses is None and graph.landmarks is None and graph.estimates is None
    np.testing.assert_array_equal(graph.poses.ids, [0, 5, 9])
    np.testing.assert_array_equal(graph.landmark_ids, [100, 101])
    written = assert_round_trip(graph)
    assert "VERTEX" not in written
    # Poses without a measurement or landmarks without an observation need estimates.
    lonely = dataclasses.replace(graph, landmark_ids=np.array([100, 101, 102]))
    with pytest.raises(ValueError, match=r"landmarks \[102\] have no observation and no estimate"):
        g2o.dumps(lonely)
    x = lonely.values(SE2.identity((3,)), np.zeros((3, 2)))
    assert "VERTEX_XY 102 0.0 0.0" in g2o.dumps(lonely, x)
    lonely = dataclasses.replace(graph, poses=dataclasses.replace(graph.poses, ids=np.array([0, 5, 9, 11])))
    with pytest.raises(ValueError, match=r"poses \[11\] have no measurement and no estimate"):
        g2o.dumps(lonely)


def test_poses_listed_landmarks_implied():
    graph = g2o.loads(text(v2(0, "1 2 3"), v2(1), e2(0, 1), exy(0, 50), exy(1, 50)))
    assert graph.poses.poses is not None and graph.landmarks is None
    x = graph.initialize("file")  # the landmarks are triangulated
    np.testing.assert_allclose(x["landmarks"], graph.triangulate(graph.poses.poses))
    assert_round_trip(graph)
    assert_round_trip(graph, x)


# ---- writing -------------------------------------------------------------------------


def test_write_takes_the_estimates_as_values_and_checks_them(tmp_path):
    graph = g2o.loads(GRAPH2, name="small")
    x = graph.values(SE2.exp(np.arange(6.0).reshape(2, 3) / 7), [[3.5, -1.25]])
    path = tmp_path / "small.g2o"
    g2o.write(path, graph, x)
    back = g2o.read(path)
    np.testing.assert_array_equal(back.landmarks, [[3.5, -1.25]])
    np.testing.assert_allclose(back.poses.poses.as_matrix(), x["poses"].as_matrix(), rtol=0, atol=1e-15)
    assert back.name == "small" and g2o.dumps(back) == path.read_text()
    assert_round_trip(graph, x)
    with pytest.raises(TypeError, match=r"must be Values \(poses, landmarks\), got SE2"):
        g2o.dumps(graph, x["poses"])
    with pytest.raises(ShapeError, match=r"estimates\['landmarks'\] must have shape \(1, 2\)"):
        g2o.dumps(graph, graph.values(x["poses"], [[1.0, 2.0]]).replace(landmarks=np.zeros((2, 2))))
    with pytest.raises(ShapeError, match=r"estimates\['poses'\] must be SE2 with batch shape \(2,\)"):
        g2o.dumps(graph, x.replace(poses=SE2.identity((3,))))
    with pytest.raises(NonFiniteError, match=r"non-finite landmarks at vertex ids \[7\]"):
        g2o.dumps(graph, x.replace(landmarks=np.array([[np.inf, 0.0]])))


def random_landmark_graph(group: type[LieGroup], rng: np.random.Generator, n: int, count: int, k: int,
                          p: int) -> tuple[LandmarkGraph, object]:  # fmt: skip
    """A landmark graph with random shuffled ids in one space, random scales, symmetric
    (sometimes indefinite) information, sensor offsets (3-D, with parameter ids) and priors."""
    d, dim = group.point_dim, group.dim
    ids = rng.permutation(rng.choice(50 * (n + count), size=n + count, replace=False) - 10 * n)
    pose_ids, landmark_ids = np.sort(ids[:n]), ids[n:]
    chain = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)

    def elements(r: int) -> LieGroup:
        x = group.random(rng, (r,))
        t = rng.standard_normal((r, d)) * 10.0 ** rng.uniform(-6, 6, (r, 1))
        return group.from_rotation_translation(x.rotation(), t)  # type: ignore[attr-defined]

    def information(r: int, size: int) -> np.ndarray:
        a = rng.standard_normal((r, size, size)) * 10.0 ** rng.uniform(-6, 6, (r, 1, 1))
        return a + np.swapaxes(a, 1, 2)

    poses = PoseGraph(group, chain, elements(n - 1), information(n - 1, dim), ids=pose_ids, poses=elements(n),
                      fixed=rng.choice(n, size=int(rng.integers(0, 2)), replace=False), name="random")  # fmt: skip
    obs = np.stack([rng.integers(0, n, k), np.concatenate([np.arange(count), rng.integers(0, count, k - count)])], 1)
    offsets = offset_ids = None
    if group is SE3:
        sensors = elements(3)
        which = rng.integers(0, 3, k)
        offsets, offset_ids = sensors[which], np.array([5, 0, 2])[which]
    graph = LandmarkGraph(
        poses, landmark_ids=landmark_ids, observations=obs, points=rng.standard_normal((k, d)) * 10.0,
        point_information=information(k, d), landmarks=rng.standard_normal((count, d)), sensor_offsets=offsets,
        offset_ids=offset_ids, prior_poses=rng.integers(0, n, p), prior_means=elements(p) if p else None,
        prior_information=information(p, dim), name="random",
    )  # fmt: skip
    return graph, graph.estimates


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 12), count=st.integers(1, 8), extra=st.integers(0, 20),
       p=st.integers(0, 3))  # fmt: skip
def test_round_trip_of_random_landmark_graphs(group, seed, n, count, extra, p):
    rng = np.random.default_rng(seed)
    graph, _ = random_landmark_graph(group, rng, n, count, count + extra, p)
    if group is SE2:
        assert_round_trip(graph)
        return
    written = assert_round_trip(graph)
    back = g2o.loads(written)
    np.testing.assert_array_equal(back.offset_ids, graph.offset_ids)
    np.testing.assert_allclose(back.sensor_offsets.as_matrix(), graph.sensor_offsets.as_matrix(), rtol=0, atol=4e-15)
    if p:  # the priors name an identity parameter: the smallest free id, as no sensor is the identity
        free = str(int(np.setdiff1d(np.arange(len(graph.offset_ids) + 1), graph.offset_ids)[0]))
        assert {line.split()[2] for line in written.splitlines() if line.startswith("EDGE_SE3_PRIOR")} == {free}


def test_offsets_without_ids_get_one_parameter_per_distinct_offset():
    graph, _ = random_landmark_graph(SE3, np.random.default_rng(3), 4, 3, 9, 1)
    plain = dataclasses.replace(graph, offset_ids=None)
    written = assert_round_trip(plain)
    back = g2o.loads(written)
    assert len(np.unique(back.offset_ids)) == len(np.unique(graph.offset_ids)) == 3
    assert sum(line.startswith("PARAMS_SE3OFFSET") for line in written.splitlines()) == 4  # 3 sensors, 1 identity
    np.testing.assert_allclose(back.sensor_offsets.as_matrix(), graph.sensor_offsets.as_matrix(), rtol=0, atol=4e-15)
    # Without offsets at all: one identity parameter 0 for the observations and the priors.
    none = dataclasses.replace(graph, sensor_offsets=None, offset_ids=None)
    written = g2o.dumps(none)
    assert [line for line in written.splitlines() if line.startswith("PARAMS")] == [
        "PARAMS_SE3OFFSET 0 0.0 0.0 0.0 0.0 0.0 0.0 1.0"]  # fmt: skip
    assert g2o.loads(written).sensor_offsets is None
    # One parameter id cannot carry two offsets.
    clash = dataclasses.replace(graph, offset_ids=np.zeros(len(graph.observations), dtype=np.int64))
    with pytest.raises(ValueError, match=r"has offset_id 0 with another sensor offset than observation"):
        g2o.dumps(clash)


# ---- synthetic worlds: written, read back, solved ----------------------------------------


def solve(graph: LandmarkGraph) -> float:
    result = LevenbergMarquardt(grad_rtol=1e-12).solve(graph.problem(), graph.initialize("odometry"))
    assert result.status.converged, result
    return float(result.fun)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("prior", [False, True], ids=["FIX", "prior"])
def test_synthetic_worlds_are_written_read_and_solved_alike(tmp_path, d: int, prior: bool):
    instance = synthetic.landmark_world(60, 20, d=d, seed=4, sensor_range=8.0, prior=prior)
    graph = instance.graph
    path = tmp_path / "world.g2o"
    g2o.write(path, graph, instance.truth)
    back = g2o.read(path)
    assert isinstance(back, LandmarkGraph) and back.describe() == graph.describe()
    assert len(back.prior_poses) == prior and back.poses.fixed.size == (not prior)
    assert back.cost(back.estimates) == pytest.approx(graph.cost(instance.truth), rel=1e-12)
    assert solve(back) == pytest.approx(solve(graph), rel=1e-9, abs=1e-9)
    assert_round_trip(graph, instance.truth)


def offset_world(d: int, seed: int = 5) -> tuple[LandmarkGraph, object]:
    """A synthetic world whose points are measured by two sensors mounted off the robot's frame."""
    instance = synthetic.landmark_world(60, 20, d=d, seed=seed, sensor_range=8.0)
    graph, truth = instance.graph, instance.truth
    group = graph.group
    rng = np.random.default_rng(seed)
    which = np.arange(len(graph.observations)) % 2
    offsets = group.exp(rng.standard_normal((2, group.dim)) * 0.4)[which]
    x, points = truth["poses"][graph.observations[:, 0]], truth["landmarks"][graph.observations[:, 1]]
    measured = (x @ offsets).inverse().act(points) + 0.05 * rng.standard_normal(points.shape)
    ids = np.array([3, 8])[which] if d == 3 else None
    world = dataclasses.replace(graph, points=measured, sensor_offsets=offsets, offset_ids=ids, name="offsets")
    return world, truth


def test_3d_sensor_offsets_are_written_as_parameters_and_solved_alike():
    graph, truth = offset_world(3)
    written = assert_round_trip(graph, truth)
    params = [line.split()[1] for line in written.splitlines() if line.startswith("PARAMS_SE3OFFSET")]
    assert params == ["3", "8"]
    back = g2o.loads(written)
    np.testing.assert_array_equal(back.offset_ids, graph.offset_ids)
    np.testing.assert_allclose(back.sensor_offsets.as_matrix(), graph.sensor_offsets.as_matrix(), rtol=0, atol=4e-15)
    assert back.cost(back.estimates) == pytest.approx(graph.cost(truth), rel=1e-12)
    assert solve(back) == pytest.approx(solve(graph), rel=1e-9, abs=1e-9)
    # The offsets matter: without them the same numbers are another, worse-fitting problem.
    assert dataclasses.replace(back, sensor_offsets=None).cost(back.estimates) > 10 * back.cost(back.estimates)


def test_2d_sensor_offsets_are_folded_into_the_points():
    graph, truth = offset_world(2)
    written = g2o.dumps(graph, truth)
    back = g2o.loads(written)
    assert back.sensor_offsets is None and back.offset_ids is None
    s = graph.sensor_offsets.as_matrix()
    np.testing.assert_allclose(back.points, np.einsum("kij,kj->ki", s[:, :2, :2], graph.points) + s[:, :2, 2],
                               rtol=1e-15, atol=1e-15)  # fmt: skip
    assert back.cost(back.estimates) == pytest.approx(graph.cost(truth), rel=1e-12)
    assert solve(back) == pytest.approx(solve(graph), rel=1e-9, abs=1e-9)
    assert g2o.dumps(back) == written


# ---- priors --------------------------------------------------------------------------


def test_priors_2d_and_3d_are_costed_as_g2o_defines_them():
    """A prior's term is ``½ rᵀΩr``, ``r = Log(Z⁻¹ X)`` (EDGE_PRIOR_SE2; EDGE_SE3_PRIOR with the identity offset)."""
    rng = np.random.default_rng(0)
    for group, source in ((SE2, GRAPH2), (SE3, GRAPH3)):
        graph = g2o.loads(source)
        without = dataclasses.replace(graph, prior_poses=np.zeros(0, np.int64), prior_means=None,
                                      prior_information=None, prior_lines=None)  # fmt: skip
        for _ in range(3):
            x = graph.values(group.exp(rng.standard_normal((2, group.dim))), rng.standard_normal((1, group.point_dim)))
            r = graph.prior_means[0].inverse().compose(x["poses"][0]).log()
            expected = 0.5 * r @ graph.prior_information[0] @ r
            assert graph.cost(x) - without.cost(x) == pytest.approx(expected, rel=1e-9)


def numbers(x: SE3) -> str:
    """``x y z qx qy qz qw`` of one element, exactly."""
    return " ".join(map(repr, [*x.translation().tolist(), *x.rotation().as_quaternion().tolist()]))


def test_a_3d_prior_on_an_offset_sensor_is_folded_into_an_equivalent_prior():
    """EDGE_SE3_PRIOR measures X·S: its term is ½ rᵀΩr with r = Log(Z⁻¹ X S), for any X."""
    rng = np.random.default_rng(1)
    a = rng.standard_normal((6, 6))
    omega = a @ a.T + np.eye(6)
    s_text, z_text = numbers(SE3.exp(rng.standard_normal(6) * 0.5)), numbers(SE3.exp(rng.standard_normal(6)))
    info = " ".join(map(repr, omega[np.triu_indices(6)].tolist()))
    source = text(par(2, s_text), v3(0), vxyz(9), exyz(0, 9, 2), pr3(0, 2, z_text, info))
    graph = g2o.loads(source)
    s, z = (SE3.from_translation_quaternion(v[:3], v[3:], normalize=True)
            for v in (np.array(t.split(), dtype=float) for t in (s_text, z_text)))  # fmt: skip
    for _ in range(3):
        x = SE3.exp(rng.standard_normal(6))
        r = z.inverse().compose(x).compose(s).log()  # g2o's error, with the Log of CONVENTIONS §8
        ours = graph.prior_means[0].inverse().compose(x).log()
        assert 0.5 * ours @ graph.prior_information[0] @ ours == pytest.approx(0.5 * r @ omega @ r, rel=1e-10)
    written = assert_round_trip(graph)
    prior_line = next(line for line in written.splitlines() if line.startswith("EDGE_SE3_PRIOR"))
    assert prior_line.split()[2] == "0"  # a new identity parameter (2 is the sensor's)
    assert "PARAMS_SE3OFFSET 0 0.0 0.0 0.0 0.0 0.0 0.0 1.0" in written


# ---- lint ------------------------------------------------------------------------------

LINT2 = text(
    v2(0), v2(1, "1 0 0"), v2(2, "2 0 0"), v2(3, "0 5 0"), v2(4, "50 50 0"),
    vxy(10, "1 1"), vxy(11, "0 -1"), vxy(12, "100 -100"), vxy(13, "0 3"), vxy(14, "50 51"),
    e2(0, 1, "1 0 0"),
    exy(0, 10, "1 1", "1 0 -1"),  # indefinite
    exy(1, 10, "0 1"),
    exy(0, 10, "1 1"),  # a duplicate of the first
    exy(0, 11, "0 -1"),
    exy(0, 13, "0 3"),
    exy(3, 13, "0 -2"),  # pose 3 is linked to the others through landmark 13
    exy(4, 14, "0 1", "1e308 1e308 1e308"),  # beyond double precision (and singular)
)  # fmt: skip


def test_lint_reports_the_landmarks_observations_and_priors():
    graph = g2o.loads(LINT2 + pr2(1, "1 0 0", "1 0 0 -1 0 1"), name="quirks")
    report = g2o.lint(graph)
    assert (report.n, report.m, report.n_landmarks, report.n_observations, report.n_priors) == (5, 1, 5, 7, 1)
    np.testing.assert_array_equal(report.unseen, [12])
    np.testing.assert_array_equal(report.seen_once, [11, 14])
    np.testing.assert_array_equal(report.out_of_view, [12])
    assert report.view_range == 3.0  # the largest measured range, ‖(0, 3)‖
    np.testing.assert_array_equal(report.duplicate_observations, [2])
    np.testing.assert_array_equal(report.duplicate_observation_ids, [[0, 10]])
    np.testing.assert_array_equal(report.indefinite_observations, [0, 6])
    np.testing.assert_array_equal(report.indefinite_observation_ids, [[0, 10], [4, 14]])
    assert report.observation_min_eigenvalues[0] == pytest.approx(-1.0)
    np.testing.assert_array_equal(report.overflow_observations, [6])
    np.testing.assert_array_equal(report.overflow_observation_ids, [[4, 14]])
    np.testing.assert_array_equal(report.indefinite_priors, [0])
    np.testing.assert_array_equal(report.indefinite_prior_ids, [1])
    np.testing.assert_allclose(report.prior_min_eigenvalues, [-1.0])
    np.testing.assert_array_equal(report.isolated, [2])  # poses without any measurement
    # The prior fixes the gauge: what is linked to pose 1 is determined, pose 3 through landmark 13.
    np.testing.assert_array_equal(report.unreachable, [2, 4, 12, 14])
    assert report.indefinite.size == 0 and report.duplicates.size == 0 and not report.ok
    lines = str(report).splitlines()
    assert lines[0] == "quirks: 5 poses, 5 landmarks, 1 edge, 7 observations, 1 prior"
    for expected in [
        "  1 observation information matrix beyond double precision (eigenvalues overflow): 4→14",
        "  2 observation information matrices not positive definite: 0→10 (λmin -1), 4→14 (λmin 0)",
        "  1 prior information matrix not positive definite: on 1 (λmin -1)",
        "  1 duplicate observation: 0→10",
        "  1 landmark never seen: 12",
        "  2 landmarks seen only once (fewer than twice): 11, 14",
        "  1 landmark out of view (farther than the largest measured range, 3, from every pose): 12",
        "  1 pose without measurements: 2",
        "  not connected: 4 vertices unreachable from what fixes the gauge (FIX-ed poses, priors, else pose 0): "
        "2, 4, 12, 14",
    ]:
        assert expected in lines, (expected, lines)


def test_lint_links_to_the_gauge_as_the_problem_fixes_it():
    # No prior, no FIX: the anchor pose 0.
    np.testing.assert_array_equal(g2o.lint(g2o.loads(LINT2)).unreachable, [2, 4, 12, 14])
    # FIX 4: only what is linked to pose 4 is determined.
    report = g2o.lint(g2o.loads(LINT2 + "FIX 4\n"))
    np.testing.assert_array_equal(report.unreachable, [0, 1, 2, 3, 10, 11, 12, 13])
    assert report.anchor == 4


def test_lint_of_in_memory_quirks_and_of_clean_worlds():
    graph = g2o.loads(GRAPH2, name="clean")
    assert str(g2o.lint(graph)) == "clean: 2 poses, 1 landmark, 1 edge, 2 observations, 1 prior: ok"
    skew = graph.point_information.copy()
    skew[1, 0, 1] += 1.0
    prior_skew = graph.prior_information.copy()
    prior_skew[0, 2, 0] += 1.0
    report = g2o.lint(dataclasses.replace(graph, point_information=skew, prior_information=prior_skew))
    np.testing.assert_array_equal(report.asymmetric_observations, [1])
    np.testing.assert_array_equal(report.asymmetric_priors, [0])
    assert "  1 observation information matrix not symmetric: observations 1" in str(report).splitlines()
    assert "  1 prior information matrix not symmetric: priors 0" in str(report).splitlines()
    for d in (2, 3):
        world = synthetic.landmark_world(60, 20, d=d, seed=1, sensor_range=8.0)
        poses = dataclasses.replace(world.graph.poses, poses=world.truth["poses"])
        report = g2o.lint(dataclasses.replace(world.graph, landmarks=world.truth["landmarks"], poses=poses))
        assert report.ok, str(report)
        assert report.view_range is not None and report.out_of_view.size == 0
    # Without estimates the view is not checked.
    assert g2o.lint(world.graph).view_range is None


def test_lint_of_a_landmark_file_counts_its_normalized_quaternions(tmp_path):
    source = GRAPH3.replace(par(0), par(0, "0 0 0 0 0 0 1.000001")).replace(pr3(0), pr3(0, pose="1 2 3 0 0 0 0.99999"))
    path = tmp_path / "printed.g2o"
    path.write_text(source)
    report = g2o.lint(path)
    assert report.renormalized == 2 and report.quaternion_error == pytest.approx(1e-5, rel=1e-6)
    assert report.ok and "2 quaternions normalized" in str(report)


@pytest.mark.parametrize(
    "source",
    [
        text(vxy(1, "0 0")),  # no pose at all
        text(pr2(0)),  # a prior alone
        text(v2(0, "1e308 -1e308 0"), vxy(1, "-1e308 1e308"), exy(0, 1, "1e308 1e308", "1e308 0 1e308")),
        text(
            par(0, "1e308 1e308 1e308 0 0 0 1"),
            v3(0, "-1e308 0 0 0 0 0 1"),
            vxyz(1, "1e308 1e308 1e308"),
            exyz(0, 1, 0, "1e308 -1e308 1e308"),
        ),
    ],
    ids=["no poses", "prior only", "huge 2-D", "huge 3-D"],
)
def test_lint_never_raises_on_odd_landmark_graphs(source):
    report = g2o.lint(g2o.loads(source))  # RuntimeWarnings are errors in the suite: none either
    assert str(report).startswith("<string>: ")


# ---- GTSAM's reader, an optional peer ----------------------------------------------------


def test_gtsam_reads_what_it_supports_of_our_landmark_files(tmp_path):
    """GTSAM 4.3's ``readG2o`` reads poses, landmarks (as ``L(id)``) and pose–pose edges; in 3-D
    ``EDGE_SE3_TRACKXYZ`` as a bearing–range factor, refusing a missing or non-identity
    ``PARAMS_SE3OFFSET`` (as we refuse the missing one); ``EDGE_SE2_XY`` and the priors it skips."""
    gtsam = pytest.importorskip("gtsam")
    for d in (2, 3):
        world = synthetic.landmark_world(30, 10, d=d, seed=2, sensor_range=8.0, prior=True)
        graph, truth = world.graph, world.truth
        path = tmp_path / f"world{d}.g2o"
        g2o.write(path, graph, truth)
        back = g2o.read(path)
        factors, values = gtsam.readG2o(str(path), d == 3)
        landmark = [gtsam.symbol("l", int(i)) for i in back.landmark_ids]
        points = np.array([values.atPoint2(k) if d == 2 else values.atPoint3(k) for k in landmark])
        np.testing.assert_array_equal(points, back.landmarks)
        poses = back.poses.poses.as_matrix()
        for i, pose_id in enumerate(back.poses.ids):
            theirs = values.atPose2(int(pose_id)).matrix() if d == 2 else values.atPose3(int(pose_id)).matrix()
            np.testing.assert_allclose(theirs, poses[i], rtol=0, atol=1e-12)
        kinds = [type(factors.at(i)).__name__ for i in range(factors.size())]
        between = f"BetweenFactorPose{d}"
        assert kinds.count(between) == back.poses.m
        if d == 2:
            assert len(kinds) == back.poses.m  # EDGE_SE2_XY and EDGE_PRIOR_SE2 are skipped
        else:
            assert kinds.count("BearingRangeFactor3D") == len(back.observations) and len(kinds) == back.m - 1
            measured = [factors.at(i).measured() for i in range(factors.size()) if kinds[i] != between]
            z = np.array([m.bearing().point3() * m.range() for m in measured])
            np.testing.assert_allclose(z, back.points, rtol=1e-12, atol=1e-12)
        # The pose–pose part: GTSAM's error is our geodesic cost (CONVENTIONS §8).
        only_between = gtsam.NonlinearFactorGraph()
        for i in range(factors.size()):
            if kinds[i] == between:
                only_between.add(factors.at(i))
        assert only_between.error(values) == pytest.approx(back.poses.cost(back.poses.poses), rel=1e-9)
    missing = tmp_path / "missing.g2o"
    missing.write_text(text(v3(0), vxyz(5), exyz(0, 5, 0)))
    with pytest.raises(g2o.ParseError, match="names parameter 0"):
        g2o.read(missing)
    with pytest.raises(ValueError, match="PARAMS_SE3OFFSET"):
        gtsam.readG2o(str(missing), True)
    offset = tmp_path / "offset.g2o"
    offset.write_text(text(par(0, "0.5 0 0 0 0 0 1"), v3(0), vxyz(5), exyz(0, 5, 0)))
    assert g2o.read(offset).sensor_offsets is not None
    with pytest.raises(ValueError, match="identity PARAMS_SE3OFFSET"):
        gtsam.readG2o(str(offset), True)
