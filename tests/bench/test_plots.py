import math

import numpy as np
import pytest

from manopt_lie.bench.plots import (
    PALETTE,
    color,
    convergence,
    convergence_plots,
    performance_profile,
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
    np.testing.assert_array_equal(ratios, [[1.0, 1.0], [1.0, np.inf], [np.inf, np.inf]])


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
