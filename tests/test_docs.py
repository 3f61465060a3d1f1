"""Every ```python block of the README and of every page of the site runs as written (each in a fresh namespace).

The pages are those of ``nav`` in ``mkdocs.yml`` (read without PyYAML, so this runs
without the docs tools) together with every Markdown file under ``docs/``: a page left
out of the navigation fails :func:`test_every_page_is_in_the_nav`.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def nav_pages() -> list[Path]:
    """The Markdown files named in the ``nav`` section of mkdocs.yml, in order."""
    text = (ROOT / "mkdocs.yml").read_text()
    nav = text[text.index("\nnav:") :]
    nav = re.split(r"\n(?=\S)", nav[1:])[0]  # up to the next top-level key
    return [DOCS / name for name in re.findall(r"([\w./-]+\.md)\s*$", nav, re.M)]


NAV = nav_pages()
PAGES = [ROOT / "README.md", *dict.fromkeys([*NAV, *sorted(DOCS.rglob("*.md"))])]
BLOCKS = [
    pytest.param(code, id=f"{page.relative_to(ROOT)}:{i}")
    for page in PAGES
    for i, code in enumerate(re.findall(r"^```python\n(.*?)^```", page.read_text(), re.S | re.M))
]


@pytest.mark.parametrize("code", BLOCKS)
def test_example_runs(code, capsys):
    exec(compile(code, "<docs>", "exec"), {"__name__": "__docs__"})


def test_every_page_is_in_the_nav():
    assert all(page.is_file() for page in NAV), [str(p) for p in NAV if not p.is_file()]
    missing = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md") if p not in NAV)
    assert not missing, f"pages under docs/ missing from nav in mkdocs.yml: {missing}"
    for page in ("index.md", "getting_started.md", "conventions.md", "changelog.md", "api/lie.md"):
        assert DOCS / page in NAV
