"""Trajectory metrics: Umeyama alignment, APE, RPE, statistics and timestamp association.

The always-run tests check numbers worked out by hand (closed forms); the peer tests run
evo (``pip install evo``, an optional peer: skipped without it) on the same TUM/KITTI files
and ask for agreement to 1e-6 relative.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.problems import evaluation as ev
from manopt_lie.problems import trajectory_io as tio


def rz(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def poses(rotations: np.ndarray, positions: np.ndarray) -> SE3:
    return SE3.from_rotation_translation(SO3.from_matrix(rotations), positions)


def line(n: int, step: float = 1.0) -> SE3:
    return poses(np.broadcast_to(np.eye(3), (n, 3, 3)), np.stack([step * np.arange(n), np.zeros(n), np.zeros(n)], 1))


# ---- statistics and relations, by hand ------------------------------------------------------


def test_statistics_by_hand() -> None:
    s = ev.Stats.of([3.0, 4.0])
    assert (s.rmse, s.mean, s.median, s.std, s.min, s.max, s.sse) == (math.sqrt(12.5), 3.5, 3.5, 0.5, 3.0, 4.0, 25.0)
    assert s.rms == s.rmse
    with pytest.raises(ValueError):
        ev.Stats.of([])


def test_ape_without_alignment_by_hand() -> None:
    ref = line(2)
    est = poses(np.broadcast_to(np.eye(3), (2, 3, 3)), ref.translation() + [[3.0, 0, 0], [0, 4.0, 0]])
    result = ev.ape(ref, est)
    np.testing.assert_allclose(result.errors, [3.0, 4.0], rtol=1e-15)
    assert result.stats.sse == pytest.approx(25.0) and result.alignment.method == "none"
    assert result.title == "APE w.r.t. translation part (m)\n(not aligned)"


def test_rotation_relations_by_hand() -> None:
    angles = np.array([0.1, 0.2, 3.0])
    ref = line(3)
    est = poses(np.stack([rz(a) for a in angles]), ref.translation())
    np.testing.assert_allclose(ev.ape(ref, est, relation="angle_rad").errors, angles, rtol=1e-14)
    np.testing.assert_allclose(ev.ape(ref, est, relation="angle_deg").errors, np.degrees(angles), rtol=1e-14)
    # ‖Rz(θ) − I‖_F² = 4(1 − cos θ); the translation part of E = P⁻¹Q is 0 here, so full = rot_part.
    np.testing.assert_allclose(ev.ape(ref, est, relation="rot_part").errors, 2 * np.sqrt(1 - np.cos(angles)))
    np.testing.assert_allclose(ev.ape(ref, est, relation="full").errors, 2 * np.sqrt(1 - np.cos(angles)))
    assert ev.ape(ref, est, relation="trans_part").stats.max == pytest.approx(0.0, abs=1e-15)
    with pytest.raises(ValueError, match="pose relation"):
        ev.ape(ref, est, relation="angle")


def test_rpe_by_hand() -> None:
    ref, est = line(11, 1.0), line(11, 1.1)  # the estimate drifts 0.1 m a step
    one = ev.rpe(ref, est)
    np.testing.assert_allclose(one.errors, np.full(10, 0.1), rtol=1e-12)
    two = ev.rpe(ref, est, delta=2)  # pairs (0, 2), (2, 4), …, (8, 10)
    assert two.pairs.tolist() == [[0, 2], [2, 4], [4, 6], [6, 8], [8, 10]]
    np.testing.assert_allclose(two.errors, np.full(5, 0.2), rtol=1e-12)
    every = ev.rpe(ref, est, delta=3, all_pairs=True)
    assert every.pairs.tolist() == [[i, i + 3] for i in range(8)]
    np.testing.assert_allclose(every.errors, np.full(8, 0.3), rtol=1e-12)
    # Sim(3) alignment takes out the scale of a zigzag (a straight line leaves its rotation open).
    zigzag = poses(
        np.broadcast_to(np.eye(3), (11, 3, 3)),
        np.stack([np.arange(11.0), np.arange(11) % 2, 0 * ref.translation()[:, 2]], 1),
    )
    bigger = SE3.from_rotation_translation(zigzag.rotation(), 1.1 * zigzag.translation())
    assert ev.rpe(zigzag, bigger).stats.max == pytest.approx(0.1 * math.sqrt(2))
    assert ev.rpe(zigzag, bigger, align=True, correct_scale=True).stats.max == pytest.approx(0.0, abs=1e-12)
    assert "for delta = 2 (frames) using consecutive pairs" in two.title
    with pytest.raises(ValueError, match="no pairs"):
        ev.rpe(ref, est, delta=11)
    with pytest.raises(ValueError, match="positive"):
        ev.rpe_pairs(5, 0)


def test_rpe_rotation_by_hand() -> None:
    # The estimate turns 0.1 rad more than the reference at every step: each relative error is 0.1 rad.
    n = 6
    ref = poses(np.stack([rz(0.3 * k) for k in range(n)]), np.zeros((n, 3)))
    est = poses(np.stack([rz(0.4 * k) for k in range(n)]), np.zeros((n, 3)))
    np.testing.assert_allclose(ev.rpe(ref, est, relation="angle_rad").errors, np.full(n - 1, 0.1), rtol=1e-12)


# ---- alignment --------------------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_umeyama_recovers_a_known_similarity(rng: np.random.Generator, d: int) -> None:
    x = rng.standard_normal((30, d))
    r = SO3.random(rng).as_matrix() if d == 3 else rz(0.7)[:2, :2]
    t, s = rng.standard_normal(d), 2.5
    y = s * x @ r.T + t
    r_fit, t_fit, s_fit = ev.umeyama(x, y, with_scale=True)
    np.testing.assert_allclose(r_fit, r, atol=1e-12)
    np.testing.assert_allclose(t_fit, t, atol=1e-12)
    assert s_fit == pytest.approx(s, rel=1e-12)
    r_se, _, s_se = ev.umeyama(x, y)
    assert s_se == 1.0 and np.allclose(r_se, r, atol=1e-12)  # the rotation does not depend on the scale


def test_umeyama_never_reflects_and_refuses_degenerate_points(rng: np.random.Generator) -> None:
    x = rng.standard_normal((20, 3))
    y = x * [1.0, 1.0, -1.0]  # a mirror image: the best proper rotation, det +1
    r, _, _ = ev.umeyama(x, y)
    assert np.linalg.det(r) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="degenerate"):
        ev.umeyama(np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="degenerate"):
        ev.umeyama(np.outer(np.arange(5.0), [1, 2, 3]), np.outer(np.arange(5.0), [3, 2, 1]))
    with pytest.raises(ValueError):
        ev.umeyama(np.zeros((5, 3)), np.zeros((4, 3)))


def test_ape_alignments_with_a_known_transform(rng: np.random.Generator) -> None:
    ref = SE3.from_rotation_translation(SO3.random(rng, (50,)), rng.standard_normal((50, 3)) * 5)
    g = SE3.from_rotation_translation(SO3.random(rng), [1.0, -2.0, 3.0])
    moved = g @ ref  # the reference in another frame
    scaled = SE3.from_rotation_translation(moved.rotation(), 0.5 * moved.translation())
    assert ev.ape(ref, moved).stats.rmse > 1.0
    se = ev.ape(ref, moved, align=True)
    assert se.stats.max < 1e-12 and se.alignment.method == "se"
    np.testing.assert_allclose(se.alignment.matrix, g.inverse().as_matrix(), atol=1e-12)
    assert ev.ape(ref, moved, align=True, relation="angle_rad").stats.max < 1e-7  # rotations follow
    assert ev.ape(ref, scaled, align=True).stats.rmse > 1.0  # SE(3) cannot take out a scale
    sim = ev.ape(ref, scaled, align=True, correct_scale=True)
    assert sim.stats.max < 1e-12 and sim.alignment.scale == pytest.approx(2.0) and "Sim(3)" in sim.title
    only = ev.ape(moved, SE3.from_rotation_translation(moved.rotation(), 0.5 * moved.translation()),
                  correct_scale=True)  # fmt: skip
    assert only.alignment.method == "scale" and only.alignment.scale == pytest.approx(2.0, rel=1e-12)
    origin = ev.ape(ref, moved, align_origin=True)
    assert origin.errors[0] == pytest.approx(0.0, abs=1e-12) and origin.stats.max < 1e-11
    with pytest.raises(ValueError):
        ev.ape(ref, moved, align=True, align_origin=True)


def test_planar_metrics_and_graph_errors(rng: np.random.Generator) -> None:
    x = SE2.exp(rng.standard_normal((20, 3)))
    g = SE2.exp(np.array([1.0, 2.0, 0.3]))
    assert ev.ape(x, g @ x, align=True).stats.max < 1e-12
    errors = ev.errors(g @ x, x)  # the gauge is aligned away
    assert errors.translation_stats.max < 1e-12 and errors.rotation_stats.max < 1e-12
    rotations = SO3.random(rng, (10,))
    assert ev.errors(SO3.random(rng) @ rotations, rotations).rotation_stats.max < 1e-7


# ---- association ---------------------------------------------------------------------------


def test_association_by_hand() -> None:
    ref = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    est = np.array([0.004, 1.02, 2.995, 3.006, 9.0])  # 1.02 is too far; 2.995 and 3.006 are nearest 3
    i_ref, i_est = ev.associate(ref, est)
    assert i_ref.tolist() == [0, 3, 3] and i_est.tolist() == [0, 2, 3]
    i_ref, i_est = ev.associate(ref, est, max_diff=0.05)
    assert i_ref.tolist() == [0, 1, 3, 3] and i_est.tolist() == [0, 1, 2, 3]
    i_ref, i_est = ev.associate(ref, est - 1.0, offset=1.0)  # the estimate's clock runs 1 s behind
    assert i_ref.tolist() == [0, 3, 3] and i_est.tolist() == [0, 2, 3]
    shorter = np.array([1.001, 2.0])  # the shorter trajectory's stamps are the ones matched
    i_ref, i_est = ev.associate(shorter, ref)
    assert i_ref.tolist() == [0, 1] and i_est.tolist() == [1, 2]
    unsorted = np.array([3.0, 0.0, 2.0, 1.0, 4.0])
    i_ref, i_est = ev.associate(unsorted, np.array([0.001, 2.999]))
    assert i_ref.tolist() == [1, 0] and i_est.tolist() == [0, 1]
    with pytest.raises(ValueError, match="no matching timestamps"):
        ev.associate(ref, ref + 0.5)


# ---- evo, on the same files -------------------------------------------------------------


def noisy_pair(rng: np.random.Generator, n: int = 300) -> tuple[tio.Trajectory, tio.Trajectory]:
    """A smooth 3-D reference and an estimate in another frame, scaled by 0.8, with noise,
    sampled at other times (every 2nd stamp, jittered by up to 3 ms) — association needed."""
    t = np.arange(n) * 0.05
    positions = np.stack([np.cos(t / 3) * 10, np.sin(t / 2) * 5, 0.1 * t], axis=1)
    rotations = SO3.exp(np.stack([0.2 * np.sin(t), 0.1 * np.cos(t), t / 4], axis=1))
    ref = SE3.from_rotation_translation(rotations, positions)
    g = SE3.from_rotation_translation(SO3.exp([0.3, -0.2, 1.0]), [2.0, -1.0, 0.5])
    noise = SE3.exp(np.concatenate([0.05 * rng.standard_normal((n, 3)), 0.01 * rng.standard_normal((n, 3))], 1))
    est = g @ ref @ noise
    est = SE3.from_rotation_translation(est.rotation(), 0.8 * est.translation())
    keep = np.arange(0, n, 2)
    return (tio.Trajectory(ref, 100.0 + t, "ref"),
            tio.Trajectory(est[keep], 100.0 + t[keep] + rng.uniform(-0.003, 0.003, keep.size), "est"))  # fmt: skip


OURS_TO_EVO = {"trans_part": "translation_part", "angle_deg": "rotation_angle_deg", "angle_rad": "rotation_angle_rad",
               "rot_part": "rotation_part", "full": "full_transformation"}  # fmt: skip
ALIGNMENTS = [(False, False), (True, False), (True, True), (False, True)]


@pytest.fixture(scope="module")
def evo_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    ref, est = noisy_pair(np.random.default_rng(7))
    folder = tmp_path_factory.mktemp("evo")
    tio.write_tum(folder / "ref.txt", ref)
    tio.write_tum(folder / "est.txt", est)
    return folder / "ref.txt", folder / "est.txt"


def _evo_pair(ref_path: Path, est_path: Path) -> tuple:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import sync

    ref, est = file_interface.read_tum_trajectory_file(ref_path), file_interface.read_tum_trajectory_file(est_path)
    return sync.associate_trajectories(ref, est, max_diff=0.01)


def _ours_pair(ref_path: Path, est_path: Path) -> tuple[SE3, SE3]:
    ref, est = tio.read_tum(ref_path), tio.read_tum(est_path)
    i_ref, i_est = ev.associate(ref.stamps, est.stamps)
    return ref.poses[i_ref], est.poses[i_est]


def _assert_same(ours: ev.PoseError, theirs: object) -> None:
    stats = theirs.get_all_statistics()
    assert set(stats) == set(ours.stats.to_json())
    for key, value in stats.items():
        assert getattr(ours.stats, key) == pytest.approx(value, rel=1e-6, abs=1e-12), key


@pytest.mark.parametrize(("align", "scale"), ALIGNMENTS)
@pytest.mark.parametrize("relation", list(OURS_TO_EVO))
def test_ape_agrees_with_evo(evo_files: tuple[Path, Path], relation: str, align: bool, scale: bool) -> None:
    ref_evo, est_evo = _evo_pair(*evo_files)
    from evo.core import metrics

    if align or scale:
        est_evo.align(ref_evo, correct_scale=scale, correct_only_scale=scale and not align)
    metric = metrics.APE(metrics.PoseRelation[OURS_TO_EVO[relation]])
    metric.process_data((ref_evo, est_evo))
    ref, est = _ours_pair(*evo_files)
    assert len(ref) == ref_evo.num_poses
    _assert_same(ev.ape(ref, est, relation=relation, align=align, correct_scale=scale), metric)


@pytest.mark.parametrize(("delta", "all_pairs"), [(1, False), (5, False), (4, True)])
@pytest.mark.parametrize("relation", ["trans_part", "angle_deg", "full"])
@pytest.mark.parametrize(("align", "scale"), ALIGNMENTS[:1] + ALIGNMENTS[2:3])
def test_rpe_agrees_with_evo(evo_files: tuple[Path, Path], relation: str, delta: int, all_pairs: bool,
                             align: bool, scale: bool) -> None:  # fmt: skip
    ref_evo, est_evo = _evo_pair(*evo_files)
    from evo.core import metrics

    if align:
        est_evo.align(ref_evo, correct_scale=scale)
    metric = metrics.RPE(metrics.PoseRelation[OURS_TO_EVO[relation]], delta, metrics.Unit.frames,
                         all_pairs=all_pairs)  # fmt: skip
    metric.process_data((ref_evo, est_evo))
    ref, est = _ours_pair(*evo_files)
    _assert_same(ev.rpe(ref, est, delta=delta, all_pairs=all_pairs, relation=relation, align=align,
                        correct_scale=scale), metric)  # fmt: skip


def test_kitti_agrees_with_evo(tmp_path: Path) -> None:
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics

    ref, est = noisy_pair(np.random.default_rng(3), 120)
    ref = ref.subset(np.arange(0, 120, 2))  # same count as the estimate: KITTI matches by index
    tio.write_kitti(tmp_path / "ref.txt", ref)
    tio.write_kitti(tmp_path / "est.txt", est)
    ref_evo = file_interface.read_kitti_poses_file(tmp_path / "ref.txt")
    est_evo = file_interface.read_kitti_poses_file(tmp_path / "est.txt")
    est_evo.align(ref_evo, correct_scale=True)
    metric = metrics.APE(metrics.PoseRelation.translation_part)
    metric.process_data((ref_evo, est_evo))
    ours = ev.ape(tio.read_kitti(tmp_path / "ref.txt").poses, tio.read_kitti(tmp_path / "est.txt").poses,
                  align=True, correct_scale=True)  # fmt: skip
    _assert_same(ours, metric)


def test_association_agrees_with_evo(rng: np.random.Generator) -> None:
    pytest.importorskip("evo")
    from evo.core.sync import matching_time_indices

    a = np.sort(rng.uniform(0, 10, 400))
    b = np.sort(rng.uniform(0, 10, 300))
    for max_diff in (0.001, 0.01, 0.1):
        ours = ev._match(b, a, max_diff)
        theirs = matching_time_indices(b, a, max_diff)
        assert ours[0].tolist() == theirs[0] and ours[1].tolist() == theirs[1]
    shuffled = rng.permutation(a)
    ours = ev._match(b, shuffled, 0.01)
    theirs = matching_time_indices(b, shuffled, 0.01)
    assert ours[0].tolist() == theirs[0] and ours[1].tolist() == theirs[1]
