"""Every public name has a docstring: what the API reference shows must exist.

Public means: every module of ``manopt_lie`` (``manopt_lie.problems`` included) whose
dotted path has no ``_``-prefixed part, every name in the ``__all__`` of such a module
(what a private module exports counts where a public one re-exports it), and the
public methods and properties of every public class defined in the package. A method
that overrides a documented method of a base class inherits its docstring, as
``help()`` and the site (``griffe-inherited-docstrings``) show it. A constant is
documented by a string literal right after its assignment (an attribute docstring,
which griffe reads), found in the module that assigns it.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import functools
import importlib
import inspect
import pkgutil
import types
from pathlib import Path

import manopt_lie
import manopt_lie.problems

SKIP_MODULES = {"manopt_lie.__main__"}  # runs the command line when imported


def _modules() -> list[types.ModuleType]:
    names = ["manopt_lie", "manopt_lie.problems"]
    for pkg in (manopt_lie, manopt_lie.problems):
        names += [info.name for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")]
    return [importlib.import_module(name) for name in dict.fromkeys(names) if name not in SKIP_MODULES]


MODULES = _modules()


def _is_public(module: types.ModuleType) -> bool:
    return not any(part.startswith("_") for part in module.__name__.split("."))


def _own_doc(obj: object) -> str:
    doc = (obj.__dict__.get("__doc__") if inspect.isclass(obj) else getattr(obj, "__doc__", None)) or ""
    if inspect.isclass(obj) and (dataclasses.is_dataclass(obj) or issubclass(obj, tuple)):
        if doc.startswith(f"{obj.__name__}("):  # generated from the fields, not written
            return ""
    return doc.strip()


def _ours(obj: object) -> bool:
    return (getattr(obj, "__module__", None) or "").startswith("manopt_lie")


@functools.cache
def _tree(path: str) -> ast.Module:
    return ast.parse(Path(path).read_text(encoding="utf-8"))


def _attribute_doc(module: types.ModuleType, name: str, depth: int = 0) -> str | None:
    """The docstring after ``name = …`` where ``module`` (or the module it imports ``name`` from) assigns it."""
    tree = _tree(module.__file__)
    body = tree.body
    for k, node in enumerate(body):
        targets = (
            node.targets if isinstance(node, ast.Assign)
            else [node.target] if isinstance(node, ast.AnnAssign) else []
        )
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            nxt = body[k + 1] if k + 1 < len(body) else None
            if isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str):
                return nxt.value.value.strip()
            return ""
    for node in body:
        if isinstance(node, ast.ImportFrom) and any((a.asname or a.name) == name for a in node.names) and depth < 5:
            source = importlib.import_module(("." * node.level) + (node.module or ""), module.__package__)
            original = next(a.name for a in node.names if (a.asname or a.name) == name)
            return _attribute_doc(source, original, depth + 1)
    return None


def _members(cls: type) -> list[tuple[str, object]]:
    out = []
    for name, value in vars(cls).items():
        if name.startswith("_") or isinstance(value, enum.Enum):
            continue
        func = value.__func__ if isinstance(value, staticmethod | classmethod) else value
        if isinstance(value, property):
            func = value.fget
        elif isinstance(value, functools.cached_property):
            func = value.func
        elif not inspect.isfunction(func):
            continue
        out.append((name, func))
    return out


def _inherits_doc(cls: type, name: str) -> bool:
    for base in cls.__mro__[1:]:
        value = base.__dict__.get(name)
        if value is None:
            continue
        if isinstance(value, staticmethod | classmethod):
            value = value.__func__
        if isinstance(value, property):
            value = value.fget
        if isinstance(value, functools.cached_property):
            value = value.func
        if (getattr(value, "__doc__", None) or "").strip():
            return True
    return False


def undocumented() -> list[str]:
    missing: set[str] = set()
    classes: dict[str, type] = {}
    for module in MODULES:
        if not _is_public(module):
            continue
        if not (module.__doc__ or "").strip():
            missing.add(f"module {module.__name__}")
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            where = f"{module.__name__}.{name}"
            if isinstance(obj, types.ModuleType):
                if not (obj.__doc__ or "").strip():
                    missing.add(f"module {obj.__name__}")
            elif inspect.isclass(obj) or inspect.isfunction(inspect.unwrap(obj)):  # functools.cache'd too
                if _ours(obj) and not _own_doc(obj):
                    missing.add(f"{obj.__module__}.{obj.__qualname__}")
                if inspect.isclass(obj) and _ours(obj):
                    classes[f"{obj.__module__}.{obj.__qualname__}"] = obj
            elif not _attribute_doc(module, name):
                missing.add(f"constant {where} (no docstring after its assignment)")
    for path, cls in classes.items():
        for name, func in _members(cls):
            if not (getattr(func, "__doc__", None) or "").strip() and not _inherits_doc(cls, name):
                missing.add(f"{path}.{name}")
    return sorted(missing)


def test_every_public_name_has_a_docstring():
    missing = undocumented()
    assert not missing, f"{len(missing)} public names without a docstring:\n" + "\n".join(missing)


def test_the_check_sees_the_package():
    assert len(MODULES) > 80 and any(m.__name__ == "manopt_lie.problems.g2o" for m in MODULES)
