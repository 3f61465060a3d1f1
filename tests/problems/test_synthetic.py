"""Synthetic instances: reproducibility, sizes, connectivity, the noise and outlier models."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.problems import PoseGraph, RotationAveraging, synthetic
from manopt_lie.problems.synthetic import Instance

# Small instances of every generator, by name.
SMALL = {
    "cube": lambda **kw: synthetic.cube(4, **kw),
    "cube-random": lambda **kw: synthetic.cube(3, orientation="random", **kw),
    "grid2d": lambda **kw: synthetic.grid2d(5, 6, **kw),
    "sphere": lambda **kw: synthetic.sphere(5, 8, **kw),
    "torus": lambda **kw: synthetic.torus(4, 6, **kw),
    "circle2d": lambda **kw: synthetic.circle2d(3, 10, **kw),
    "ra-so3": lambda **kw: synthetic.rotation_averaging(30, **kw),
    "ra-so2": lambda **kw: synthetic.rotation_averaging(30, d=2, **kw),
}
POSE_GRAPHS = [name for name in SMALL if not name.startswith("ra")]


def arrays(inst: Instance) -> list[np.ndarray]:
    g = inst.graph
    weights = g.information if isinstance(g, PoseGraph) else g.kappa
    return [g.edges, g.measurements.as_matrix(), weights, inst.truth.as_matrix(), inst.outliers, inst.backbone]


def relative_truth(inst: Instance):
    e = inst.graph.edges
    return inst.truth[e[:, 0]].between(inst.truth[e[:, 1]])


def n_components(inst: Instance) -> int:
    e, n = inst.graph.edges, inst.graph.n
    adjacency = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(adjacency, directed=False)[0]


@pytest.mark.parametrize("name", SMALL)
def test_reproducible_from_seed(name):
    make = SMALL[name]
    a, b, c = make(seed=3, outlier_rate=0.3), make(seed=3, outlier_rate=0.3), make(seed=4, outlier_rate=0.3)
    for x, y in zip(arrays(a), arrays(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert a.graph.name == b.graph.name and a.graph.name.endswith("-seed3") and c.graph.name.endswith("-seed4")
    assert a.params == b.params and a.params["seed"] == 3
    differs = [
        x.shape != y.shape or not np.array_equal(x, y) for x, y in zip(arrays(a)[:2], arrays(c)[:2], strict=True)
    ]
    assert any(differs)


@pytest.mark.parametrize("name", SMALL)
def test_well_formed_and_connected(name):
    inst = SMALL[name](outlier_rate=0.2)
    g = inst.graph
    assert inst.truth.batch_shape == (g.n,) and type(inst.truth) is g.group
    assert inst.outliers.shape == inst.backbone.shape == (g.m,)
    assert np.all(g.edges[:, 0] < g.edges[:, 1])
    assert len(np.unique(g.edges, axis=0)) == g.m  # no duplicate edges
    assert inst.backbone.sum() == g.n - 1
    assert n_components(inst) == 1
    assert not np.any(inst.outliers & inst.backbone)
    assert np.all(inst.errors(inst.truth).rotation < 1e-7)


@pytest.mark.parametrize("name", POSE_GRAPHS)
def test_trajectories_start_with_odometry(name):
    inst = SMALL[name]()
    n = inst.graph.n
    np.testing.assert_array_equal(inst.graph.edges[: n - 1], np.stack([np.arange(n - 1), np.arange(1, n)], 1))
    assert np.all(inst.backbone[: n - 1]) and not np.any(inst.backbone[n - 1 :])
    closures = inst.graph.edges[n - 1 :]
    assert np.all(closures[:, 1] - closures[:, 0] >= 2)
    np.testing.assert_array_equal(closures, closures[np.lexsort((closures[:, 1], closures[:, 0]))])


@pytest.mark.parametrize(
    ("make", "group", "n", "m"),
    [
        (lambda p: synthetic.cube(5, loop_closure_probability=p), SE3, 125, {0: 124, 1: 3 * 25 * 4}),
        (lambda p: synthetic.grid2d(4, 7, loop_closure_probability=p), SE2, 28, {0: 27, 1: 4 * 6 + 7 * 3}),
        (lambda p: synthetic.sphere(6, 9, loop_closure_probability=p), SE3, 54, {0: 53, 1: 53 + 45}),
        (lambda p: synthetic.torus(3, 5, loop_closure_probability=p), SE3, 15, {0: 14, 1: 14 + 15}),
        (lambda p: synthetic.circle2d(4, 7, loop_closure_probability=p), SE2, 28, {0: 27, 1: 27 + 21}),
        (lambda p: synthetic.rotation_averaging(12, edge_probability=p), SO3, 12, {0: 11, 1: 66}),
        (lambda p: synthetic.rotation_averaging(12, d=2, edge_probability=p), SO2, 12, {0: 11, 1: 66}),
    ],
)
def test_sizes(make, group, n, m):
    for p, size in m.items():
        g = make(p).graph
        assert (g.group, g.n, g.m) == (group, n, size)
    g = make(0.5).graph
    assert m[0] < g.m < m[1]


@pytest.mark.parametrize(
    "call",
    [
        lambda: synthetic.cube(2, loop_closure_probability=1),
        lambda: synthetic.grid2d(2, 2, loop_closure_probability=1),
        lambda: synthetic.sphere(2, 2),
        lambda: synthetic.torus(3, 2),
        lambda: synthetic.circle2d(2, 2),
        lambda: synthetic.rotation_averaging(2),
        lambda: synthetic.rotation_averaging(3, edge_probability=0.0),
    ],
)
def test_smallest_sizes(call):
    inst = call()
    assert n_components(inst) == 1 and len(np.unique(inst.graph.edges, axis=0)) == inst.graph.m


def test_sphere2500_shape():
    g = synthetic.sphere().graph
    assert (g.n, g.m, g.name) == (2500, 4949, "sphere-50x50-seed0")


def test_loop_closure_probability_and_degree():
    g = synthetic.cube(12, loop_closure_probability=0.3, seed=1).graph
    candidates = 3 * 12**2 * 11 - (12**3 - 1)
    assert (g.m - 12**3 + 1) / candidates == pytest.approx(0.3, abs=0.03)
    ra = synthetic.rotation_averaging(2000, degree=8).graph
    assert 2 * ra.m / ra.n == pytest.approx(8 + 2, rel=0.05)  # Erdős–Rényi part + path


@pytest.mark.parametrize("name", SMALL)
def test_zero_noise_gives_exact_measurements(name):
    noise = {"noise": 0.0} if name.startswith("ra") else {"translation_noise": 0.0, "rotation_noise": 0.0}
    inst = SMALL[name](**noise)
    np.testing.assert_allclose(inst.graph.measurements.as_matrix(), relative_truth(inst).as_matrix(), atol=1e-12)
    g = inst.graph
    if isinstance(g, PoseGraph):
        np.testing.assert_array_equal(g.information, np.broadcast_to(np.eye(g.group.dim), g.information.shape))
        assert g.cost(inst.truth) < 1e-20
    else:
        np.testing.assert_array_equal(g.kappa, synthetic.EXACT_WEIGHT)


def test_path_orientation_and_geometry():
    cube = synthetic.cube(4, translation_noise=0, rotation_noise=0)
    odometry = cube.graph.measurements[: cube.n - 1]
    # Each pose looks at the next one, one metre ahead along its x axis.
    np.testing.assert_array_equal(odometry.translation(), np.broadcast_to([1.0, 0, 0], (cube.n - 1, 3)))
    positions = cube.truth.translation()
    assert set(map(tuple, positions.astype(int))) == {(x, y, z) for x in range(4) for y in range(4) for z in range(4)}
    np.testing.assert_array_equal(np.abs(np.diff(positions, axis=0)).sum(axis=1), 1.0)

    sphere = synthetic.sphere(5, 8, radius=3.0)
    t, r = sphere.truth.translation(), sphere.truth.rotation().as_matrix()
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 3.0)
    np.testing.assert_allclose(r[:, :, 2], t / 3.0, atol=1e-12)  # z axis: outward normal
    np.testing.assert_allclose(r[:, 2, 0], 0.0, atol=1e-12)  # x axis along the ring

    torus = synthetic.torus(4, 6, major_radius=5.0, minor_radius=2.0)
    x, y, z = torus.truth.translation().T
    np.testing.assert_allclose((np.hypot(x, y) - 5.0) ** 2 + z**2, 4.0)


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: synthetic.cube(20, loop_closure_probability=1.0, **kw),
        lambda **kw: synthetic.grid2d(120, 120, loop_closure_probability=1.0, **kw),
        lambda **kw: synthetic.sphere(100, 100, **kw),
    ],
)
def test_noise_statistics_match_the_information(make):
    sigma_t, sigma_r = 0.05, 0.02
    inst = make(translation_noise=sigma_t, rotation_noise=sigma_r, seed=7)
    g = inst.graph
    d, k = g.d, g.group.dim
    sigma = np.diag(np.repeat([sigma_t**2, sigma_r**2], [d, k - d]))
    np.testing.assert_allclose(g.information, np.broadcast_to(np.linalg.inv(sigma), g.information.shape))
    eps = g.measurements.rminus(relative_truth(inst))  # Log((X_i⁻¹X_j)⁻¹ Z)
    assert len(eps) > 15000
    cov = np.cov(eps, rowvar=False)
    np.testing.assert_allclose(np.diag(cov), np.diag(sigma), rtol=0.04)
    corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(corr, np.eye(k), atol=0.03)
    np.testing.assert_allclose(eps.mean(axis=0) / np.sqrt(np.diag(sigma)), 0.0, atol=0.03)
    # Ω = Σ⁻¹: at the truth, 2·cost is χ² with m·k degrees of freedom.
    assert 2 * g.cost(inst.truth) / (g.m * k) == pytest.approx(1.0, abs=0.02)


def test_rotation_averaging_noise_statistics():
    inst = synthetic.rotation_averaging(3000, degree=10, noise=0.03, seed=2)
    np.testing.assert_allclose(inst.graph.kappa, 1 / 0.03**2)
    eps = inst.graph.measurements.rminus(relative_truth(inst))
    np.testing.assert_allclose(np.cov(eps, rowvar=False), 0.03**2 * np.eye(3), atol=0.04 * 0.03**2)


@pytest.mark.parametrize("name", SMALL)
def test_outliers(name):
    big = {"cube": dict(side=12, loop_closure_probability=0.5)}.get(name)
    if big is not None:
        inst = synthetic.cube(**big, outlier_rate=0.3, translation_noise=0, rotation_noise=0, seed=5)
    elif name.startswith("ra"):
        inst = SMALL[name](outlier_rate=0.3, noise=0.0, seed=5)
    else:
        inst = SMALL[name](outlier_rate=0.3, translation_noise=0.0, rotation_noise=0.0, seed=5)
    candidates = ~inst.backbone
    assert not np.any(inst.outliers & inst.backbone)
    # Exact inliers; outliers far from the truth, within the scene.
    distance = inst.graph.measurements.dist(relative_truth(inst))
    assert np.all(distance[~inst.outliers] < 1e-12) and np.all(distance[inst.outliers] > 1e-6)
    if big is not None:
        assert inst.outliers.sum() / candidates.sum() == pytest.approx(0.3, abs=0.03)
        extent = np.ptp(inst.truth.translation(), axis=0)
        assert np.all(np.abs(inst.graph.measurements[inst.outliers].translation()) <= extent)
        # Outliers keep the nominal information.
        info = inst.graph.information
        np.testing.assert_array_equal(info[inst.outliers], np.broadcast_to(info[0], info[inst.outliers].shape))
    assert synthetic.cube(4, outlier_rate=0.0).outliers.sum() == 0


def test_outlier_rate_in_rotation_averaging():
    inst = synthetic.rotation_averaging(500, degree=10, outlier_rate=0.3, seed=1)
    assert inst.outliers.sum() / (~inst.backbone).sum() == pytest.approx(0.3, abs=0.03)
    assert n_components(inst) == 1 and isinstance(inst.graph, RotationAveraging)


@pytest.mark.parametrize("name", ["cube", "grid2d", "torus", "ra-so3"])
def test_chordal_initialization_recovers_exact_truth(name):
    noise = {"noise": 0.0} if name.startswith("ra") else {"translation_noise": 0.0, "rotation_noise": 0.0}
    inst = SMALL[name](**noise)
    errors = inst.errors(inst.graph.chordal_initialization())
    assert np.max(errors.rotation) < 1e-8
    assert errors.translation is None or np.max(errors.translation) < 1e-8


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: synthetic.cube(1), "side must be ≥ 2"),
        (lambda: synthetic.cube(2.5), "side must be an integer"),
        (lambda: synthetic.cube(True), "side must be an integer"),
        (lambda: synthetic.cube(loop_closure_probability=1.5), "loop_closure_probability must lie in"),
        (lambda: synthetic.cube(translation_noise=-0.1), "translation_noise must be ≥ 0"),
        (lambda: synthetic.cube(rotation_noise=float("nan")), "rotation_noise must be a finite"),
        (lambda: synthetic.cube(outlier_rate=-0.01), "outlier_rate must lie in"),
        (lambda: synthetic.cube(orientation="up"), "orientation"),
        (lambda: synthetic.grid2d(1, 5), "rows must be ≥ 2"),
        (lambda: synthetic.grid2d(5, 0), "cols must be ≥ 2"),
        (lambda: synthetic.sphere(1, 5), "n_rings"),
        (lambda: synthetic.sphere(radius=0.0), "radius must be > 0"),
        (lambda: synthetic.torus(2, 5), "n_laps must be ≥ 3"),
        (lambda: synthetic.torus(minor_radius=20.0), "minor_radius must be < major_radius"),
        (lambda: synthetic.circle2d(poses_per_lap=1), "poses_per_lap"),
        (lambda: synthetic.rotation_averaging(1), "n must be ≥ 2"),
        (lambda: synthetic.rotation_averaging(d=4), "d must be 2 or 3"),
        (lambda: synthetic.rotation_averaging(edge_probability=0.5, degree=3), "not both"),
        (lambda: synthetic.rotation_averaging(edge_probability=2), "edge_probability must lie in"),
        (lambda: synthetic.rotation_averaging(degree=-1), "degree must be ≥ 0"),
        (lambda: synthetic.rotation_averaging(noise=-1), "noise must be ≥ 0"),
        (lambda: synthetic.rotation_averaging(outlier_rate=1.1), "outlier_rate"),
    ],
)
def test_invalid_arguments_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_pair_indexing_is_a_bijection():
    for n in (2, 3, 7, 50):
        pairs = synthetic.rotations._pairs_from_index(np.arange(n * (n - 1) // 2), n)
        np.testing.assert_array_equal(pairs, np.stack(np.triu_indices(n, 1), axis=1))
    n = 100_000  # large n: floating point must not put a pair in the wrong row
    rows = np.array([1, 2, 50_000, n - 2])
    starts = synthetic.rotations._pair_index(rows, rows + 1, n)
    for t in (starts, starts - 1, starts[:-1] + 1):  # row n − 2 holds one pair
        i, j = synthetic.rotations._pairs_from_index(t, n).T
        assert np.all((i < j) & (j < n)) and np.array_equal(synthetic.rotations._pair_index(i, j, n), t)


def test_large_instances():
    cube = synthetic.cube(47)
    assert cube.graph.n == 47**3 > 10**5 and cube.graph.m > cube.graph.n - 1
    grid = synthetic.grid2d(317, 317)
    assert grid.graph.n == 317**2 > 10**5 and grid.graph.m > grid.graph.n - 1
    assert n_components(grid) == 1
