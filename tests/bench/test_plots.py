import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from manopt_lie.bench.plots import (
    PALETTE,
    Reference,
    color,
    convergence,
    convergence_plots,
    figure_format,
    performance_profile,
    pose_errors,
    profile,
    trajectory,
)
from manopt_lie.bench.record import Run

PNG = b"\x89PNG\r\n\x1a\n"


def make_run(
    optimizer: str = "lm",
    instance: str = "intel",
    cost: str = "geodesic",
    fun: float = 1.0,
    time: float = 1.0,
    history: list[float] | None = None,
) -> Run:
    hist = [10.0, 3.0, fun] if history is None else history
    return Run(
        instance=instance, problem="pose-graph", cost=cost, optimizer=optimizer, n=5, m=7,
        nit=max(len(hist) - 1, 3), time=time, init_time=0.1, fun=fun, status="converged", converged=True,
        history_cost=hist, history_time=list(np.linspace(0.0, time, len(hist))),
    )  # fmt: skip


def assert_png(path) -> None:
    assert path.is_file() and path.stat().st_size > 0
    assert path.read_bytes()[:8] == PNG


def test_colors_are_stable():
    assert color("lm") == PALETTE["lm"]
    assert color("some-new-solver") == color("some-new-solver")
    assert len(set(PALETTE.values())) == len(PALETTE)


def test_every_solver_and_peer_has_a_colour_of_its_own():
    """A demo or bench figure draws every registered optimizer, graph solver and peer, each
    in its own colour (no two lines alike, none from the hashed fallback)."""
    from manopt_lie.bench.peers import PEERS
    from manopt_lie.optim import OPTIMIZERS
    from manopt_lie.problems.solvers import GRAPH_SOLVERS

    names = [*OPTIMIZERS, *GRAPH_SOLVERS, *PEERS]
    assert set(names) <= set(PALETTE)
    assert len({color(name) for name in names}) == len(names)


def test_convergence_png(tmp_path):
    runs = [
        make_run("lm", fun=1.0),
        make_run("gn", fun=1.0 + 1e-3, history=[10.0, 2.0, 1.001, 1.001]),
        make_run("ipopt", fun=1.0, history=[]),  # final cost only: a marker
        make_run("tr", fun=1.5, history=[1.5]),
    ]
    assert_png(convergence(runs, tmp_path / "sub" / "c.png"))


def test_convergence_zero_and_nonfinite_history(tmp_path):
    runs = [
        make_run("lm", fun=0.0, history=[5.0, 0.0, 0.0]),  # f_best = 0, zeros on a log axis
        make_run("gd", fun=math.nan, history=[5.0, math.inf, math.nan, -math.inf]),
        make_run("cg", fun=2.0, history=[5.0, 2.0]),
    ]
    runs[2].history_time = []  # no timings: iteration panel only
    assert_png(convergence(runs, tmp_path / "z.png"))
    only_nan = [make_run("gd", fun=math.nan, history=[math.nan, math.nan])]
    assert_png(convergence(only_nan, tmp_path / "n.png"))


def test_convergence_against_a_reference_single_runs_and_formats(tmp_path):
    runs = [make_run("lm", fun=1.0 + 1e-9), make_run("gd", fun=1.5, history=[10.0, 5.0, 1.5])]
    assert_png(convergence(runs, tmp_path / "ref.png", reference=Reference(1.0, 1e-6, "certified")))
    single = make_run("tr", fun=2.0, history=[9.0, 3.0, 2.0])
    single.history_grad_norm = [5.0, 0.1, 1e-7]
    assert_png(convergence([single], tmp_path / "one.png"))  # the cost and the gradient norm
    pdf = convergence(runs, tmp_path / "c.pdf")
    assert pdf.read_bytes()[:5] == b"%PDF-"
    svg = convergence(runs, tmp_path / "c.svg")
    assert ET.parse(svg).getroot().tag.endswith("svg")
    for bad in ("c.jpg", "c", "c.PNG.txt"):
        with pytest.raises(ValueError, match=r"\.png, \.pdf or \.svg"):
            convergence(runs, tmp_path / bad)
    assert not list(tmp_path.glob("c.jpg*")) and figure_format("x.PDF") == "pdf"


def test_convergence_rejects_mixed(tmp_path):
    with pytest.raises(ValueError, match="one"):
        convergence([make_run(instance="a"), make_run(instance="b")], tmp_path / "x.png")
    with pytest.raises(ValueError):
        convergence([make_run(cost="chordal"), make_run(cost="geodesic")], tmp_path / "x.png")
    with pytest.raises(ValueError):
        convergence([], tmp_path / "x.png")


def test_convergence_plots_groups_and_sanitizes(tmp_path):
    runs = [make_run("lm", instance="a/b c"), make_run("gn", instance="a/b c"), make_run("lm", cost="chordal")]
    paths = convergence_plots(runs, tmp_path / "out")
    assert [p.name for p in paths] == ["a_b_c-geodesic-convergence.png", "intel-chordal-convergence.png"]
    for p in paths:
        assert p.parent == tmp_path / "out"
        assert_png(p)


def handmade_runs() -> list[Run]:
    return [
        # problem P: best cost 1.0; C fails (cost too high)
        make_run("A", instance="P", fun=1.0, time=2.0),
        make_run("B", instance="P", fun=1.0 + 1e-9, time=1.0),
        make_run("C", instance="P", fun=1.1, time=0.5),
        # problem Q: all solve
        make_run("A", instance="Q", fun=3.0, time=1.0),
        make_run("B", instance="Q", fun=3.0, time=4.0),
        make_run("C", instance="Q", fun=3.0, time=3.0),
    ]


def test_profile_ratios():
    names, ratios = profile(handmade_runs())
    assert names == ["A", "B", "C"]
    np.testing.assert_array_equal(ratios, [[2.0, 1.0, np.inf], [1.0, 4.0, 3.0]])


def test_profile_missing_repeat_and_zero_time():
    runs = [
        make_run("A", instance="P", fun=1.0, time=0.0),
        make_run("B", instance="P", fun=1.0, time=0.0),
        make_run("A", instance="Q", fun=1.0, time=3.0),
        make_run("A", instance="Q", fun=1.0, time=2.0),  # repeated: the fastest counts
        make_run("A", instance="R", fun=math.nan, time=1.0),  # nobody solved R
    ]
    names, ratios = profile(runs)
    assert names == ["A", "B"]
    # B did not attempt Q and R: nan (not attempted), not inf (failed)
    np.testing.assert_array_equal(ratios, [[1.0, 1.0], [1.0, np.nan], [np.inf, np.nan]])


def test_profile_is_fair_to_solvers_that_attempt_fewer_problems(tmp_path):
    """A peer that applies to 2 of 4 problems and solves both fastest: its profile reaches 1
    (2 of the 2 it attempted) at τ = 1, instead of counting the other two as failures."""
    runs = []
    for p in "PQRS":
        runs.append(make_run("ours", instance=p, fun=1.0, time=2.0))
    for p in "PQ":
        runs.append(make_run("peer", instance=p, fun=1.0, time=1.0))
    runs.append(make_run("weak", instance="P", fun=1.0, time=4.0))
    runs.append(make_run("weak", instance="Q", fun=2.0, time=1.0))  # attempted, failed
    names, ratios = profile(runs)
    assert names == ["ours", "peer", "weak"]
    attempted = ~np.isnan(ratios)
    assert attempted.sum(axis=0).tolist() == [4, 2, 2]
    rho_at_1 = [(ratios[attempted[:, s], s] <= 1.0).mean() for s in range(3)]
    assert rho_at_1 == [0.5, 1.0, 0.0]
    np.testing.assert_array_equal(ratios[:, 2], [4.0, np.inf, np.nan, np.nan])
    assert_png(performance_profile(runs, tmp_path / "fair.png"))


def test_performance_profile_png(tmp_path):
    assert_png(performance_profile(handmade_runs(), tmp_path / "p.png"))
    assert_png(performance_profile([make_run("lm")], tmp_path / "one.png"))  # one problem, one solver
    with pytest.raises(ValueError):
        performance_profile([], tmp_path / "e.png")


def loop_graph(rng: np.random.Generator, n: int, d: int, n_loops: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(0, 4 * np.pi, n)
    after = np.stack([np.cos(t), np.sin(t), t / 10][:d], axis=1)
    before = after + 0.1 * rng.standard_normal(after.shape)
    odometry = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    loops = rng.integers(0, n, size=(n_loops, 2))
    return before, after, np.concatenate([odometry, loops])


@pytest.mark.parametrize("d", [2, 3])
def test_trajectory_png(tmp_path, rng, d):
    before, after, edges = loop_graph(rng, 50, d, 20)
    assert_png(trajectory(before, after, edges, tmp_path / f"t{d}.png", title="spiral"))


def test_trajectory_with_truth_landmarks_and_ellipses(tmp_path, rng):
    before, after, edges = loop_graph(rng, 60, 2, 10)
    truth = after + 0.05 * rng.standard_normal(after.shape)
    marks = rng.standard_normal((8, 2))
    cov = np.tile(np.diag([0.01, 0.004]), (60, 1, 1))
    path = trajectory(before, after, edges, tmp_path / "t.svg", "with truth", truth=truth, landmarks=marks,
                      truth_landmarks=marks + 0.01, covariances=cov, landmark_covariances=cov[:8])  # fmt: skip
    text = path.read_text()
    assert ET.fromstring(text).tag.endswith("svg")
    for label in ("x [m]", "y [m]", "loop closures (", "ground truth", "landmarks", "95 % ellipses", "position error"):
        assert label in text, label  # matplotlib's SVG names each text in a comment
    b3, a3, e3 = loop_graph(rng, 40, 3, 5)
    assert_png(trajectory(b3, a3, e3, tmp_path / "t3.png", truth=a3, covariances=np.tile(np.eye(3) * 1e-3, (40, 1, 1))))
    with pytest.raises(ValueError, match="covariances"):
        trajectory(before, after, edges, tmp_path / "x.png", covariances=cov[:5])


def test_pose_errors_figure(tmp_path, rng):
    ref = np.cumsum(rng.standard_normal((30, 3)), axis=0)
    est = ref + 0.1 * rng.standard_normal((30, 3))
    e = np.linalg.norm(est - ref, axis=1)
    stats = {"rmse": 1.0, "mean": 0.5, "median": 0.4, "std": 0.1}
    assert_png(pose_errors(ref, est, e, tmp_path / "ape.png", title="APE", unit="m", stats=stats,
                           times=np.arange(30) * 0.1))  # fmt: skip
    assert pose_errors(ref, est, e[:10], tmp_path / "rpe.pdf", title="RPE", unit="deg", stats=stats,
                       at=np.arange(10) + 5).read_bytes()[:5] == b"%PDF-"  # fmt: skip
    with pytest.raises(ValueError):
        pose_errors(ref, est, e[:10], tmp_path / "bad.png", title="", unit="", stats=stats, at=np.arange(10) + 25)


def test_trajectory_many_loop_closures_and_no_edges(tmp_path, rng):
    before, after, edges = loop_graph(rng, 200, 2, 6000)
    assert_png(trajectory(before, after, edges, tmp_path / "big.png"))
    assert_png(trajectory(before, after, np.zeros((0, 2), dtype=int), tmp_path / "none.png"))


def test_trajectory_rejects_bad_shapes(tmp_path, rng):
    before, after, edges = loop_graph(rng, 10, 2, 3)
    with pytest.raises(ValueError):
        trajectory(before, after[:-1], edges, tmp_path / "x.png")
    with pytest.raises(ValueError):
        trajectory(before[:, :1], after[:, :1], edges, tmp_path / "x.png")
    with pytest.raises(ValueError):
        trajectory(np.zeros((10, 4)), np.zeros((10, 4)), edges, tmp_path / "x.png")
    with pytest.raises(ValueError):
        trajectory(before, after, edges[:, :1], tmp_path / "x.png")
    with pytest.raises(ValueError):
        trajectory(before, after, edges.astype(float), tmp_path / "x.png")
    with pytest.raises(ValueError):
        trajectory(before, after, edges + 10, tmp_path / "x.png")
