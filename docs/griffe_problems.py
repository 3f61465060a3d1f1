"""Griffe extension for the site: ``manopt_lie.problems`` found, Sphinx markup turned into Markdown.

1. setuptools installs the top-level folder ``problems/`` as the subpackage
   ``manopt_lie.problems`` (``package-dir`` in pyproject.toml). An installed wheel has it
   under ``manopt_lie/``, but in a source tree or an editable install griffe, which reads
   files rather than importing them, does not see it there. This extension loads it
   (statically, like every other module) when it is missing.
2. The docstrings are numpydoc, which allows Sphinx roles and directives. mkdocstrings
   renders Markdown, so ``:class:`~a.B``` becomes a cross-reference (optional: a target
   that is not on the site stays plain code), ``:math:`x``` inline math and a
   ``.. math::`` block display math (MathJax through ``pymdownx.arithmatex``).
   The source files are not changed.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(class|func|meth|mod|attr|data|exc|obj|const):`(~?)([^`<]*?)(?:\s*<([^`>]+)>)?`")
_MATH_ROLE = re.compile(r":math:`([^`]+)`")
_MATH_BLOCK = re.compile(r"^(?P<indent>[ \t]*)\.\. math::[ \t]*\n(?P<body>(?:(?:(?P=indent)[ \t]+.*)?\n)+)", re.M)


def _math_block(match: re.Match[str]) -> str:
    indent = match["indent"]
    lines = [line.strip() for line in match["body"].splitlines()]
    body = "\n".join(f"{indent}{line}" for line in lines if line)
    return f"{indent}\\[\n{body}\n{indent}\\]\n\n"


def _resolve(obj: griffe.Object, target: str) -> str:
    """The full path of ``target`` seen from ``obj`` (as Sphinx's Python domain would look it up)."""
    if target.startswith("."):
        scope: griffe.Object | None = obj.module
        target = target.lstrip(".")
        try:
            return scope.resolve(target.split(".")[0]) + target[len(target.split(".")[0]) :]  # type: ignore[union-attr]
        except Exception:
            return f"{obj.module.path}.{target}"
    head, _, rest = target.partition(".")
    for scope in (obj, obj.parent, obj.module):
        if scope is None:
            continue
        try:
            return scope.resolve(head) + (f".{rest}" if rest else "")
        except Exception:
            continue
    return target


def markdown_docstring(obj: griffe.Object, text: str) -> str:
    """``text`` with its Sphinx roles and math directives written for mkdocstrings."""

    def role(match: re.Match[str]) -> str:
        _kind, tilde, title, explicit = match.groups()
        target = (explicit or title).strip().rstrip("()")
        shown = title.strip() if explicit else (target.split(".")[-1] if tilde else target.lstrip("."))
        if match.group(1) in ("func", "meth") and not explicit:
            shown += "()"
        return f'<autoref identifier="{_resolve(obj, target)}" optional><code>{shown}</code></autoref>'

    text = _MATH_BLOCK.sub(_math_block, text + "\n").rstrip("\n")
    text = _MATH_ROLE.sub(lambda m: f"\\({m.group(1)}\\)", text)
    return _ROLE.sub(role, text)


class ProblemsSubpackage(griffe.Extension):
    """Attach ``problems/`` under ``manopt_lie`` and rewrite the package's docstrings for Markdown."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        """Load ``problems/`` as ``manopt_lie.problems`` if absent, then convert every docstring."""
        if pkg.name != "manopt_lie":
            return
        if "problems" not in pkg.members:
            init = Path(str(pkg.filepath)).parent.parent / "problems" / "__init__.py"
            if init.is_file():
                pkg.set_member("problems", loader._load_module("problems", init, submodules=True, parent=pkg))
        self._convert(pkg)

    def _convert(self, obj: griffe.Object) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown_docstring(obj, obj.docstring.value)
        for member in obj.members.values():
            if not member.is_alias:
                self._convert(member)  # type: ignore[arg-type]
