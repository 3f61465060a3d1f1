"""g2o files as they come (issue 13's audit): printed quaternions, byte order marks and old
Mac line ends, binary files, values at the edge of the double range, a lint that never
raises, and a reader that streams."""

from __future__ import annotations

import dataclasses
import io
import re
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from manopt_lie import SE3
from manopt_lie.problems import PoseGraph, checks, g2o, synthetic
from manopt_lie.problems.costs import InformationMatrixError
from manopt_lie.problems.g2o import _source
from tests.problems.test_g2o import INFO2, INFO3, e2, e3, text, v2, v3

BLOCK = _source.BLOCK


def quaternion_line(tag: str, ids: str, t: np.ndarray, q: np.ndarray, decimals: int, info: str = "") -> str:
    numbers = " ".join(f"{x:.6f}" for x in t) + " " + " ".join(f"{x:.{decimals}f}" for x in q)
    return f"{tag} {ids} {numbers} {info}".rstrip()


def printed(graph, decimals: int) -> str:
    """``graph`` as a g2o text whose quaternions are printed with ``decimals`` decimals (as
    C's ``%f`` and most tools do), so their norms are off by up to ~``10⁻ᵈ``."""
    lines = []
    for i, x in zip(graph.ids, graph.poses, strict=True):
        lines.append(
            quaternion_line("VERTEX_SE3:QUAT", str(i), x.translation(), x.rotation().as_quaternion(), decimals)
        )
    for (i, j), z in zip(graph.ids[graph.edges], graph.measurements, strict=True):
        q = z.rotation().as_quaternion()
        lines.append(quaternion_line("EDGE_SE3:QUAT", f"{i} {j}", z.translation(), q, decimals, INFO3))
    return text(*lines)


def norm_errors(source: str) -> np.ndarray:
    """``| ‖q‖ − 1 |`` of every quaternion of a 3-D g2o text, computed independently."""
    rows = [line.split() for line in source.splitlines()]
    q = np.array([r[5:9] if r[0].startswith("VERTEX") else r[6:10] for r in rows], dtype=np.float64)
    return np.abs(np.linalg.norm(q, axis=1) - 1.0)


# ---- printed quaternions (the audit: SE-Sync's cubicle.g2o was refused) ----------------


@pytest.fixture(scope="module")
def random_cube() -> PoseGraph:
    instance = synthetic.cube(3, orientation="random", loop_closure_probability=0.5, seed=7)
    return dataclasses.replace(instance.graph, poses=instance.truth)


@pytest.mark.parametrize("decimals", [4, 6, 9])
def test_quaternions_printed_with_few_decimals_are_read_and_counted(tmp_path: Path, random_cube, decimals: int):
    """Audit: 107 of cubicle.g2o's quaternions, printed with 6 decimals, were 1.9e-6 off unit
    norm and the default tolerance (1e-6) refused the file. Now 1e-4 accepts 4+ decimals."""
    source = printed(random_cube, decimals)
    path = tmp_path / "printed.g2o"
    path.write_text(source)
    graph = g2o.read(path)
    assert (graph.n, graph.m) == (random_cube.n, random_cube.m)
    rotation_error = 4 * 10.0**-decimals  # what the printing lost, not the normalization
    np.testing.assert_allclose(
        graph.poses.rotation().as_matrix(), random_cube.poses.rotation().as_matrix(), rtol=0, atol=rotation_error
    )
    errors = norm_errors(source)
    report = g2o.lint(path)
    assert report.renormalized == np.count_nonzero(errors > 1e-12) > 0
    assert report.quaternion_error == pytest.approx(errors.max(), rel=1e-6)
    assert report.ok and "quaternions normalized" in str(report)
    # A graph does not keep the count: lint(graph) cannot know it.
    assert g2o.lint(graph).renormalized is None and g2o.lint(graph).quaternion_error is None


def test_cubicles_worst_quaternion_is_accepted_and_the_old_tolerance_refused_it():
    worst = text(v3(0), v3(1, "0 0 0 0 0 0 1.0000019"), e3(0, 1, "1 0 0 0 0 0 0.9999981"))
    graph = g2o.loads(worst)
    np.testing.assert_array_equal(graph.poses.rotation().as_matrix()[1], np.eye(3))
    with pytest.raises(g2o.ParseError, match=r"vertex quaternion norm 1\.0000019 is not 1") as info:
        g2o.loads(worst, quaternion_tol=1e-6)  # the old default
    assert info.value.lineno == 2
    assert g2o.QUATERNION_TOL == 1e-4


@pytest.mark.parametrize(
    "q, norm",
    [
        ("0 0 0.7071 0.7017", r"0\.996"),  # a wrong digit
        ("0 0 0 0.9998", r"0\.9998"),
        ("1 1 1 1", r"2\.0"),  # not normalized at all
        ("0 0 0 0", r"0\.0"),
        ("0 0 0 1e308", r"1e\+308"),  # huge: no overflow warning
    ],
)
def test_grossly_wrong_quaternions_stay_errors_naming_the_line(q: str, norm: str):
    pattern = rf"edge quaternion norm {norm}\S* is not 1 within quaternion_tol=0\.0001"
    with pytest.raises(g2o.ParseError, match=pattern) as info:
        g2o.loads(text(v3(0), v3(1), "# a comment", e3(0, 1, f"1 2 3 {q}")))
    assert info.value.lineno == 4


def test_quaternion_tol_is_checked():
    for tol in (-1e-3, 1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match=r"quaternion_tol must be in \[0, 1\)"):
            g2o.loads(text(v3(0)), quaternion_tol=tol)


# ---- byte order marks and line ends, for every kind of source --------------------------

SOURCE = text("# ünïcode comment", v2(0), v2(1, "1 0 0.5"), "", "FIX 1", e2(0, 1), e2(1, 0, info="1 0 0 1 0 1"))
VARIANTS = {
    "LF": SOURCE,
    "CRLF": SOURCE.replace("\n", "\r\n"),
    "CR": SOURCE.replace("\n", "\r"),
    "mixed": "\r".join(SOURCE.split("\n", 2)[:2]) + "\r\n" + SOURCE.split("\n", 2)[2],
    "no final line end": SOURCE.rstrip("\n"),
}
VARIANTS.update({f"BOM, {k}": "\ufeff" + v for k, v in list(VARIANTS.items())})


def read_as(kind: str, source: str, tmp_path: Path) -> PoseGraph:
    data = source.encode("utf-8")
    if kind == "loads":
        return g2o.loads(source)
    path = tmp_path / "quirks.g2o"
    path.write_bytes(data)
    if kind == "path":
        return g2o.read(path)
    if kind == "binary stream":
        return g2o.read(io.BytesIO(data))
    newline = None if kind == "text stream" else ""  # "text stream, raw": CRs reach the reader
    with open(path, encoding="utf-8", newline=newline) as f:
        return g2o.read(f)


KINDS = ["path", "binary stream", "text stream", "text stream, raw", "loads"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("variant", VARIANTS)
def test_bom_and_every_line_end_are_read_alike(tmp_path: Path, kind: str, variant: str):
    """Audit: a BOM became an unknown tag, CR-only files one long line."""
    expected = g2o.loads(SOURCE)
    graph = read_as(kind, VARIANTS[variant], tmp_path)
    assert g2o.dumps(graph) == g2o.dumps(expected)
    np.testing.assert_array_equal(graph.edge_lines, [6, 7])


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("variant", ["CR", "BOM, CRLF", "BOM, mixed"])
def test_line_numbers_count_every_kind_of_line_end(tmp_path: Path, kind: str, variant: str):
    source = VARIANTS[variant].replace("FIX 1", "FIX x")
    with pytest.raises(g2o.ParseError, match="FIX field 'x'") as info:
        read_as(kind, source, tmp_path)
    assert info.value.lineno == 5


def test_a_bom_elsewhere_is_not_whitespace():
    with pytest.raises(g2o.ParseError, match=r"unknown tag '\\ufeffVERTEX_SE2'") as info:
        g2o.loads(text(v2(0), "\ufeff" + v2(1)))
    assert info.value.lineno == 2


@pytest.mark.parametrize("block", [1, 2, 3, 5, 8, 13])
def test_blocks_cut_anywhere_read_the_same(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, block: int):
    """Blocks that cut a CRLF, the BOM or a multi-byte character in two change nothing."""
    monkeypatch.setattr(_source, "BLOCK", block)
    for variant, source in VARIANTS.items():
        for kind in KINDS:
            graph = read_as(kind, source, tmp_path)
            assert g2o.dumps(graph) == g2o.dumps(g2o.loads(SOURCE)), (variant, kind)
            np.testing.assert_array_equal(graph.edge_lines, [6, 7])


# ---- binary files ---------------------------------------------------------------------


class CountingBytes(io.BytesIO):
    """A binary stream that counts the bytes read from it."""

    total = 0

    def read(self, size: int | None = -1) -> bytes:
        data = super().read(size)
        self.total += len(data)
        return data


JUNK = np.random.default_rng(0).integers(0, 256, 30 * BLOCK, dtype=np.uint8).tobytes()


@pytest.mark.parametrize(
    "bad, reason",
    [
        (b"VERTEX_SE2 2 0 \x00\x00 0", r"a NUL character in the line; is it a binary file\?"),
        (b"VERTEX_SE2 2 0 \xff\xfe 0", r"not UTF-8 text \(byte 0xff at offset \d+\); is it a binary file\?"),
        (b"\x89PNG\r\n\x1a\n", r"not UTF-8 text \(byte 0x89"),
        (b"VERTEX_SE2 2 0 \xe2\x82", r"not UTF-8 text \(byte 0xe2"),  # a truncated character
    ],
)
def test_a_binary_file_is_refused_at_its_first_bad_line_without_reading_the_rest(bad: bytes, reason: str):
    """Audit: a binary file was decoded whole (with replacement characters) before parsing."""
    data = text(v2(0), v2(1)).encode() + bad + b"\n" + JUNK
    stream = CountingBytes(data)
    with pytest.raises(g2o.ParseError, match=reason) as info:
        g2o.read(stream)
    assert info.value.lineno == 3
    assert stream.total <= 2 * BLOCK < len(data) / 10


def test_a_binary_path_names_the_file_and_line(tmp_path: Path):
    path = tmp_path / "photo.g2o"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + JUNK)
    with pytest.raises(g2o.ParseError) as info:
        g2o.read(path)
    assert str(info.value).startswith(f"{path}:1: not UTF-8 text")


def test_an_earlier_bad_line_is_reported_before_the_binary_one():
    data = text(v2(0), "VERTEX_SE2 1 1 0").encode() + b"\x00\x01\n" + JUNK
    with pytest.raises(g2o.ParseError, match="VERTEX_SE2 needs 4 fields, got 3") as info:
        g2o.read(io.BytesIO(data))
    assert info.value.lineno == 2


def test_a_text_stream_that_cannot_decode_is_a_parse_error(tmp_path: Path):
    path = tmp_path / "latin1.g2o"
    path.write_bytes(text(v2(0), v2(1)).encode() + "# caf\xe9\n".encode("latin-1"))
    with open(path, encoding="utf-8") as f, pytest.raises(g2o.ParseError, match="cannot decode") as info:
        g2o.read(f)
    assert info.value.lineno == 1  # the stream decodes in blocks: this line or one of the next
    with pytest.raises(g2o.ParseError, match="byte 0xe9") as info:
        g2o.read(path)  # from bytes, the line is exact
    assert info.value.lineno == 3
    with pytest.raises(g2o.ParseError, match="NUL") as info:
        g2o.read(io.StringIO(text(v2(0), v2(1), "\0")))
    assert info.value.lineno == 3


# ---- values at the edge of the double range --------------------------------------------

HUGE = "1e308 1e308 1e308 1e308 1e308 1e308"


@pytest.mark.parametrize(
    "info, overflow, indefinite",
    [
        (HUGE, True, True),  # eigenvalues 3e308, 0, 0: beyond the range (and singular)
        ("1e308 0 0 1e308 0 1e308", False, False),  # λ = 1e308: representable
        ("1e308 -1e308 1e308 1e308 -1e308 1e308", True, True),
        ("-1e308 0 0 -1e308 0 -1e308", False, True),
        ("1e-308 0 0 1e-308 0 1e-308", False, False),
        ("5e-324 0 0 5e-324 0 5e-324", False, False),  # subnormal, still positive definite
        ("0 0 0 0 0 0", False, True),
    ],
)
def test_lint_never_raises_on_huge_or_tiny_information(info: str, overflow: bool, indefinite: bool):
    """Audit: information entries of 1e308 made lint raise LinAlgError."""
    graph = g2o.loads(text(v2(0), v2(1), v2(2), e2(0, 1), e2(1, 2, info=info)))
    report = g2o.lint(graph)  # RuntimeWarnings are errors in the test suite: none either
    assert report.overflow.tolist() == ([1] if overflow else [])
    assert report.overflow_ids.tolist() == ([[1, 2]] if overflow else [])
    assert report.indefinite.tolist() == ([1] if indefinite else [])
    assert report.ok == (not overflow and not indefinite)
    if overflow:
        assert "1 information matrix beyond double precision (eigenvalues overflow): 1→2" in str(report)


def test_lint_of_huge_3d_information_and_of_non_finite_matrices():
    info = " ".join(["1e308"] * 21)
    report = g2o.lint(g2o.loads(text(v3(0), v3(1), e3(0, 1, info=info))))
    assert report.overflow.tolist() == [0] and not report.ok
    lam, asymmetric, overflow = checks.eigenvalues(
        np.array([np.eye(3), np.full((3, 3), np.nan), np.diag([np.inf, 1.0, 1.0])])
    )
    assert overflow.tolist() == [1, 2] and asymmetric.size == 0
    assert lam[0] == 1.0 and np.isnan(lam[1:]).all()


@pytest.mark.parametrize(
    "line, field, value",
    [
        (e2(0, 1, "1e309 0 0"), 3, "1e309"),
        (e2(0, 1, "0 -1e400 0"), 4, "-1e400"),
        (e2(0, 1, info="1e309 0 0 1 0 1"), 6, "1e309"),
        (e3(0, 1, "1 0 1e999 0 0 0 1"), 5, "1e999"),
    ],
)
def test_values_beyond_the_double_range_are_parse_errors_naming_the_line(line: str, field: int, value: str):
    dims = v2 if line.startswith("EDGE_SE2") else v3
    with pytest.raises(g2o.ParseError, match=rf"field {field} is '{re.escape(value)}', not a finite number") as info:
        g2o.loads(text(dims(0), dims(1), line))
    assert info.value.lineno == 3


def test_huge_but_finite_poses_are_read():
    """What a double can hold is read as such: the costs see it (and name the edges)."""
    graph = g2o.loads(text(v2(0, "1e308 -1e308 1e308"), v2(1), e2(0, 1, "1e308 0 -1e308", HUGE)))
    assert graph.poses.translation()[0, 0] == 1e308
    assert np.isfinite(graph.measurements.as_matrix()).all()
    assert g2o.lint(graph).overflow.tolist() == [0]


# ---- the earliest bad line, in any chunk -----------------------------------------------


@pytest.mark.parametrize(
    "source, lineno, pattern",
    [
        (text(v2(0, "x 0 0"), "BOGUS 1"), 1, r"field 2 is 'x'"),  # a number before a tag
        (text(v3(0), v3(1, "0 0 0 0 0 0 2"), "BOGUS 1"), 2, r"quaternion norm 2\.0"),
        (text(v2(0), e2(0, 0), v3(1)), 2, r"self-loop"),
        (text(v2(0), v2(1), "FIX 0", "FIX 1.5", e2(0, 1, "nan 0 0")), 4, r"FIX field '1\.5'"),
    ],
)
@pytest.mark.parametrize("block", [3, BLOCK])
def test_the_earliest_bad_line_is_reported(monkeypatch: pytest.MonkeyPatch, source, lineno, pattern, block):
    monkeypatch.setattr(_source, "BLOCK", block)
    with pytest.raises(g2o.ParseError, match=pattern) as info:
        g2o.loads(source)
    assert info.value.lineno == lineno


def test_a_bad_line_in_a_late_chunk_has_its_number(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    monkeypatch.setattr(_source, "BLOCK", 4096)
    n = 2000
    lines = [v2(i, f"{i} 0 0") for i in range(n)] + [e2(i, i + 1) for i in range(n - 1)]
    lines[-5] = lines[-5].replace(" 500 ", " 5OO ")
    path = tmp_path / "long.g2o"
    path.write_text(text(*lines))
    with pytest.raises(g2o.ParseError, match=r"EDGE_SE2 field 6 is '5OO', not a number") as info:
        g2o.read(path)
    assert info.value.lineno == len(lines) - 4


# ---- what the graph keeps of its file ------------------------------------------------------


def test_edges_know_their_lines_and_costs_name_them():
    source = text("# header", v2(0), v2(1), v2(2), "", e2(0, 1), "# more", e2(1, 2, info="0 0 0 0 0 0"))
    graph = g2o.loads(source.replace("\n", "\r"))
    np.testing.assert_array_equal(graph.edge_lines, [6, 8])
    with pytest.raises(InformationMatrixError, match=r"1→2 \(line 8\)"):
        graph.problem("geodesic")


def test_lint_of_a_file_object(tmp_path: Path, random_cube):
    source = printed(random_cube, 6)
    expected = np.count_nonzero(norm_errors(source) > 1e-12)
    assert g2o.lint(io.StringIO(source)).renormalized == expected
    assert g2o.lint(io.BytesIO(source.encode())).renormalized == expected
    assert g2o.lint(io.StringIO(g2o.dumps(random_cube))).renormalized == 0  # write's norms are exact
    assert g2o.lint(io.StringIO(text(v2(0), v2(1), e2(0, 1)))).quaternion_error == 0.0


# ---- streaming (time and memory of big files: benchmarks/bench_g2o.py) ------------------


def test_reading_keeps_memory_near_the_graphs_size(tmp_path: Path):
    """Audit: a 100 MB file took 1.7 GB (17x) to read. Now: the arrays, plus a block's worth."""
    rng = np.random.default_rng(1)
    n = 60_000
    poses = rng.standard_normal((n, 3))
    vertices = [f"VERTEX_SE2 {i} {x!r} {y!r} {t!r}" for i, (x, y, t) in enumerate(poses.tolist())]
    edges = [f"EDGE_SE2 {i} {i + 1} {x!r} {y!r} {t!r} {INFO2}" for i, (x, y, t) in enumerate(poses[1:].tolist())]
    path = tmp_path / "big.g2o"
    path.write_text(text(*vertices, *edges))
    size = path.stat().st_size
    tracemalloc.start()
    try:
        graph = g2o.read(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert (graph.n, graph.m) == (n, n - 1)
    assert peak < 4 * size, f"reading {size / 1e6:.1f} MB peaked at {peak / 1e6:.1f} MB"


def test_se3_elements_are_built_per_chunk_as_a_whole_file_would(monkeypatch: pytest.MonkeyPatch):
    source = g2o.dumps(synthetic.cube(3, orientation="random", seed=2).graph)
    whole = g2o.loads(source)
    monkeypatch.setattr(_source, "BLOCK", 97)
    chunked = g2o.loads(source)
    assert isinstance(chunked.measurements, SE3)
    np.testing.assert_array_equal(chunked.measurements.as_matrix(), whole.measurements.as_matrix())
    np.testing.assert_array_equal(chunked.information, whole.information)
    np.testing.assert_array_equal(chunked.edge_lines, whole.edge_lines)


# ---- landmark files stream alike ----------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_reading_a_landmark_file_keeps_memory_near_its_size(tmp_path: Path, d: int):
    world = synthetic.landmark_world(4000, 600, d=d, seed=0, max_observations=10, prior=True)
    path = tmp_path / "landmarks.g2o"
    g2o.write(path, world.graph, world.truth)
    size = path.stat().st_size
    tracemalloc.start()
    try:
        graph = g2o.read(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert graph.describe() == world.graph.describe()
    assert peak < 4 * size, f"reading {size / 1e6:.1f} MB peaked at {peak / 1e6:.1f} MB"


def test_a_bad_observation_in_a_late_chunk_has_its_number(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    monkeypatch.setattr(_source, "BLOCK", 4096)
    world = synthetic.landmark_world(300, 40, d=3, seed=1)
    lines = g2o.dumps(world.graph, world.truth).splitlines()
    at = max(i for i, line in enumerate(lines) if line.startswith("EDGE_SE3_TRACKXYZ")) - 3
    parts = lines[at].split()
    parts[3] = "5"  # a parameter id no PARAMS_SE3OFFSET line defines
    lines[at] = " ".join(parts)
    path = tmp_path / "late.g2o"
    path.write_text(text(*lines))
    with pytest.raises(g2o.ParseError, match=r"names parameter 5, which has no PARAMS_SE3OFFSET line") as info:
        g2o.read(path)
    assert info.value.lineno == at + 1
    parts[3] = "0"
    lines[at] = " ".join(parts[:-1])  # the last information entry missing
    path.write_text(text(*lines))
    with pytest.raises(g2o.ParseError, match=r"EDGE_SE3_TRACKXYZ needs 12 fields, got 11") as info:
        g2o.read(path)
    assert info.value.lineno == at + 1
