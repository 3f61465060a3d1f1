"""TUM, KITTI and g2o trajectories: round trips, format sniffing, malformed lines named."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.problems import g2o, synthetic
from manopt_lie.problems import trajectory_io as tio
from manopt_lie.problems.g2o import ParseError


def random_trajectory(rng: np.random.Generator, n: int = 40) -> tio.Trajectory:
    poses = SE3.from_rotation_translation(SO3.random(rng, (n,)), rng.standard_normal((n, 3)) * 10)
    return tio.Trajectory(poses, 1.3e9 + 0.05 * np.arange(n) + 1e-4 * rng.random(n), "random")


def test_tum_round_trip(rng: np.random.Generator, tmp_path: Path) -> None:
    traj = random_trajectory(rng)
    path = tmp_path / "t.txt"
    tio.write_tum(path, traj)
    back = tio.read_tum(path)
    assert back.name == "t" and back.n == traj.n
    np.testing.assert_array_equal(back.stamps, traj.stamps)  # repr-exact
    np.testing.assert_array_equal(back.positions, traj.positions)
    np.testing.assert_allclose(back.poses.as_matrix(), traj.poses.as_matrix(), atol=1e-15)
    again = np.array([line.split() for line in tio.dumps_tum(back).splitlines()], dtype=float)
    np.testing.assert_allclose(again, np.loadtxt(path), rtol=0, atol=1e-15)  # quaternions move by an ulp or so
    first = path.read_text().splitlines()[0].split()
    assert len(first) == 8 and float(first[-1]) >= 0  # t tx ty tz qx qy qz qw, w ≥ 0


def test_tum_fields_are_as_documented() -> None:
    # 90° about z at (1, 2, 3): q = (0, 0, sin 45°, cos 45°), scalar last.
    h = np.sqrt(0.5)
    traj = tio.read_tum(io.StringIO(f"# t x y z qx qy qz qw\n\n0.5 1 2 3 0 0 {h} {h}  # a comment\n"))
    np.testing.assert_allclose(traj.poses.as_matrix()[0], [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]],
                               atol=1e-15)  # fmt: skip
    assert traj.stamps.tolist() == [0.5]


def test_kitti_round_trip_and_layout(rng: np.random.Generator, tmp_path: Path) -> None:
    traj = random_trajectory(rng)
    path = tmp_path / "poses.txt"
    tio.write_kitti(path, traj)
    back = tio.read_kitti(path)
    assert back.stamps is None
    np.testing.assert_array_equal(back.positions, traj.positions)
    np.testing.assert_allclose(back.poses.as_matrix(), traj.poses.as_matrix(), atol=1e-15)
    row = np.array(path.read_text().splitlines()[3].split(), dtype=float)
    np.testing.assert_array_equal(row, traj.poses.as_matrix()[3, :3, :].reshape(12))  # [R t] row-major


def test_kitti_projects_printed_rotations() -> None:
    line = "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 " \
           "3.330669e-16 2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n"  # fmt: skip
    traj = tio.read_kitti(io.StringIO(line * 3))
    r = traj.poses.as_matrix()[:, :3, :3]
    np.testing.assert_allclose(np.swapaxes(r, 1, 2) @ r, np.broadcast_to(np.eye(3), r.shape), atol=1e-15)


def test_g2o_conversions(tmp_path: Path, rng: np.random.Generator) -> None:
    # A pose graph's VERTEX poses, ids as stamps; written back as the trajectory's odometry.
    inst = synthetic.cube(3, seed=2)
    path = tmp_path / "cube.g2o"
    g2o.write(path, inst.graph, inst.truth)
    traj = tio.read(path)
    assert traj.n == 27 and traj.stamps.tolist() == list(range(27))
    np.testing.assert_allclose(traj.poses.as_matrix(), inst.truth.as_matrix(), atol=1e-14)
    graph = tio.to_pose_graph(traj)
    assert graph.m == 26 and np.array_equal(graph.edges[:, 1] - graph.edges[:, 0], np.ones(26))
    assert graph.cost(graph.poses, "geodesic") == pytest.approx(0.0, abs=1e-20)  # the odometry is exact
    out = tmp_path / "odometry.g2o"
    tio.write_g2o(out, traj)
    again = tio.read_g2o(out)
    np.testing.assert_allclose(again.poses.as_matrix(), traj.poses.as_matrix(), atol=1e-14)
    # TUM stamps that are not integers do not become ids.
    tum = tio.Trajectory(traj.poses, 0.1 * np.arange(27))
    assert tio.to_pose_graph(tum).ids.tolist() == list(range(27))


def test_landmark_file_poses(tmp_path: Path) -> None:
    world = synthetic.landmark_world(n_poses=20, n_landmarks=8, seed=0)
    path = tmp_path / "slam.g2o"
    g2o.write(path, *world.graph.to_g2o(world.truth))
    traj = tio.read_g2o(path)
    assert traj.n == 20 and isinstance(traj.poses, SE2)
    np.testing.assert_allclose(traj.positions, world.graph.positions(world.truth), atol=1e-12)


def test_planar_trajectories_lift_to_z0() -> None:
    poses = SE2.exp(np.array([[1.0, 2.0, 0.5], [3.0, -1.0, -2.0]]))
    traj = tio.Trajectory(poses, np.array([0.0, 1.0]))
    lifted = traj.lift()
    assert isinstance(lifted.poses, SE3)
    np.testing.assert_allclose(lifted.positions[:, :2], traj.positions)
    assert not lifted.positions[:, 2].any()
    back = tio.read_tum(io.StringIO(tio.dumps_tum(traj)))
    np.testing.assert_allclose(back.poses.as_matrix(), lifted.poses.as_matrix(), atol=1e-15)


def test_sniff(tmp_path: Path) -> None:
    for name, text, fmt in [
        ("a.txt", "# c\n0 1 2 3 0 0 0 1\n", "tum"),
        ("b.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n", "kitti"),
        ("c.txt", "VERTEX_SE2 0 0 0 0\n", "g2o"),
        ("d.kitti", "", "kitti"),
        ("e.g2o", "", "g2o"),
    ]:
        (tmp_path / name).write_text(text)
        assert tio.sniff(tmp_path / name) == fmt
    (tmp_path / "f.txt").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="--format"):
        tio.sniff(tmp_path / "f.txt")


@pytest.mark.parametrize(
    ("reader", "text", "where", "words"),
    [
        (tio.read_tum, "0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n", 2, "8 numbers, got 7"),
        (tio.read_tum, "# x\n0 0 0 0 0 0 0 1\n1 0 0 zero 0 0 0 1\n", 3, "'zero'"),
        (tio.read_tum, "0 0 0 0 0 0 0 2\n", 1, "norm"),
        (tio.read_tum, "0 0 0 nan 0 0 0 1\n", 1, "not finite"),
        (tio.read_kitti, "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n", 2, "not a rotation"),
        (tio.read_kitti, "-1 0 0 0 0 1 0 0 0 0 1 0\n", 1, "not a rotation"),  # a reflection
        (tio.read_kitti, "1 0 0 0 0 1 0 0 0 0 1\n", 1, "12 numbers"),
    ],
)
def test_malformed_lines_are_named(reader, text: str, where: int, words: str) -> None:
    with pytest.raises(ParseError, match=words) as info:
        reader(io.StringIO(text))
    assert info.value.lineno == where


def test_empty_and_vertexless_files(tmp_path: Path) -> None:
    with pytest.raises(ParseError, match="no TUM lines"):
        tio.read_tum(io.StringIO("# nothing\n"))
    edges_only = tmp_path / "edges.g2o"
    graph = synthetic.grid2d(2, 2, seed=0).graph
    edges_only.write_text("".join(ln + "\n" for ln in g2o.dumps(graph).splitlines() if ln.startswith("EDGE")))
    with pytest.raises(ValueError, match="no VERTEX poses"):
        tio.read_g2o(edges_only)
    with pytest.raises(ValueError, match="timestamps"):
        tio.dumps_tum(tio.Trajectory(graph.initialize("odometry")))
