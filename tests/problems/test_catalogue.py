"""The benchmark catalogue: built-in suites load, entries validate, TOML suites parse."""

from __future__ import annotations

from pathlib import Path

import pytest

from manopt_lie.problems import catalogue
from manopt_lie.problems.catalogue import SUITES, CatalogueError, Entry, load_suite
from manopt_lie.problems.rotation_averaging import RotationAveraging

SYNTHETIC = sorted({e.name: e for suite in SUITES.values() for e in suite if e.generator}.items())


@pytest.mark.parametrize(("name", "entry"), SYNTHETIC, ids=[name for name, _ in SYNTHETIC])
def test_synthetic_entries_load(name: str, entry: Entry) -> None:
    loaded = entry.load()
    assert loaded.spec.kind == entry.problem and loaded.truth is not None
    truth = loaded.truth["poses"] if entry.problem == "landmark-slam" else loaded.truth
    assert len(truth) == loaded.spec.n
    assert entry.load().spec.m == loaded.spec.m  # reproducible from the seed


def test_full_suite_covers_every_dataset(datasets_dir: Path) -> None:
    files = {e.file for e in SUITES["full"] if e.file}
    assert files == {p.name for p in datasets_dir.glob("*.g2o")}
    for entry in catalogue.DATASETS:
        assert entry.path(datasets_dir).is_file()
    rotations = next(e for e in SUITES["full"] if e.problem == "rotation-averaging" and e.file)
    loaded = rotations.load(datasets_dir)
    assert isinstance(loaded.spec, RotationAveraging) and loaded.spec.n == 2500 and loaded.truth is None


def test_published_optima_match_the_datasets_readme(datasets_dir: Path) -> None:
    readme = (datasets_dir / "README.md").read_text()
    for entry in catalogue.DATASETS:
        if "chordal" in entry.published:
            row = next(line for line in readme.splitlines() if line.startswith(f"| {entry.file} |"))
            printed = f"{entry.published['chordal']:.3e}".replace("e+0", "e").replace("e+", "e")  # 3.170e1
            assert f"| {printed} " in row and f"| {entry.reference_time:.3f} |" in row


def test_missing_file_and_data_dir_override(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(catalogue.DATA_ENV, str(tmp_path))
    assert catalogue.default_data_dir() == tmp_path
    with pytest.raises(FileNotFoundError, match=r"intel\.g2o"):
        catalogue.DATASETS[1].load()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"problem": "bundle-adjustment", "generator": "cube"}, "problem must be"),
        ({}, "exactly one"),
        ({"generator": "cube", "file": "x.g2o"}, "exactly one"),
        ({"generator": "klein_bottle"}, "generator must be"),
        ({"generator": "rotation_averaging"}, "rotation-averaging problem"),
        ({"generator": "cube", "costs": ()}, "costs"),
        ({"generator": "cube", "costs": ("chordal", "l1")}, "costs"),
        ({"generator": "cube", "costs": ("geodesic",), "published": {"chordal": 1.0}}, "published"),
        ({"generator": "cube", "published": {"chordal": float("nan")}}, "published"),
    ],
)
def test_entry_validation(kwargs: dict, match: str) -> None:
    with pytest.raises(CatalogueError, match=match):
        Entry("x", **kwargs)


def test_bad_generator_parameter() -> None:
    with pytest.raises(CatalogueError, match="sides"):
        Entry("x", generator="cube", params={"sides": 3}).load()


def test_toml_suite(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text(
        '[[instance]]\nname = "a"\ngenerator = "grid2d"\nparams = { rows = 3, cols = 4 }\n'
        '[[instance]]\nname = "b"\nproblem = "rotation-averaging"\ngenerator = "rotation_averaging"\n'
        "params = { n = 10 }\n"
        '[[instance]]\nname = "c"\nfile = "intel.g2o"\npublished = { chordal = 52.35 }\n'
    )
    a, b, c = load_suite(path)
    assert a.costs == ("chordal", "geodesic") and a.source == "grid2d(rows=3, cols=4)"
    assert b.costs == ("chordal",) and b.problem == "rotation-averaging"
    assert c.published == {"chordal": 52.35} and c.path(tmp_path) == tmp_path / "intel.g2o"
    assert load_suite("quick") is SUITES["quick"]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('[[instance]]\nname = "a"\ngenerator = "cube"\n[[instance]]\nname = "a"\ngenerator = "cube"\n', "duplicate"),
        ('[[instance]]\ngenerator = "cube"\n', "needs a string 'name'"),
        ('[[instance]]\nname = "a"\ngenerator = "cube"\nparams = 3\n', "params must be a table"),
        ('[[instance]]\nname = "a"\nfile = "x.g2o"\npublished = 3.0\n', "published must be a table"),
        ('[[instance]]\nname = "a"\ngenerator = "cube"\nseed = 3\n', "unknown keys"),
        ('[instance\nname = "a"\n', "line 1"),
    ],
)
def test_bad_toml_suites(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(CatalogueError, match=match):
        load_suite(path)


def test_unknown_suite_names() -> None:
    with pytest.raises(CatalogueError, match="quick"):
        load_suite("medium")
    with pytest.raises(FileNotFoundError):
        load_suite("absent.toml")
