"""The type stub `_core.pyi` matches the extension: same names, same parameters, same defaults."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from picopit import _core

STUB = Path(_core.__file__).with_name("_core.pyi")
if not STUB.exists():  # installed without the editable layout: look next to the package source
    STUB = Path(__file__).resolve().parents[1] / "py" / "python" / "picopit" / "_core.pyi"


def stub_tree():
    return ast.parse(STUB.read_text())


def stub_params(fn: ast.FunctionDef):
    """[(name, kind, default)] of a stub function, without self."""
    a = fn.args
    out = []
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    for arg, d in zip(positional, defaults):
        if arg.arg == "self":
            continue
        out.append((arg.arg, "pos", None if d is None else ast.literal_eval(d)))
    for arg, d in zip(a.kwonlyargs, a.kw_defaults):
        out.append((arg.arg, "kw", None if d is None else ast.literal_eval(d)))
    return out


def runtime_params(obj):
    sig = inspect.signature(obj)
    out = []
    for p in sig.parameters.values():
        if p.name == "self":
            continue
        kind = "kw" if p.kind is inspect.Parameter.KEYWORD_ONLY else "pos"
        out.append((p.name, kind, None if p.default is inspect.Parameter.empty else p.default))
    return out


def is_property(fn: ast.FunctionDef) -> bool:
    """``@property`` or its ``@name.setter``."""
    return any((isinstance(d, ast.Name) and d.id == "property")
               or (isinstance(d, ast.Attribute) and d.attr == "setter" and isinstance(d.value, ast.Name)
                   and d.value.id == fn.name)
               for d in fn.decorator_list)


def test_module_level_names_match():
    tree = stub_tree()
    stub_names = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    stub_names |= {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign)}
    stub_names -= typing_helpers()
    runtime = {n for n in dir(_core) if not n.startswith("_")}
    assert stub_names == runtime


def test_functions_match():
    for node in stub_tree().body:
        if isinstance(node, ast.FunctionDef):
            assert stub_params(node) == runtime_params(getattr(_core, node.name)), node.name


def _bases(node: ast.ClassDef) -> set:
    return {b.id for b in node.bases if isinstance(b, ast.Name)}


def typing_helpers() -> set:
    """Stub-only classes (TypedDicts describing returned dicts): not in the runtime module."""
    return {n.name for n in ast.parse(STUB.read_text()).body
            if isinstance(n, ast.ClassDef) and "TypedDict" in _bases(n)}


@pytest.mark.parametrize(
    "cls_name", [n.name for n in ast.parse(STUB.read_text()).body
                 if isinstance(n, ast.ClassDef)
                 and not _bases(n) & {"TypedDict", "ValueError"}]  # typing helpers, exceptions
)
def test_class_members_match(cls_name):
    node = next(n for n in stub_tree().body if isinstance(n, ast.ClassDef) and n.name == cls_name)
    cls = getattr(_core, cls_name)
    stub_members = {f.name for f in node.body if isinstance(f, ast.FunctionDef)}
    runtime_members = {n for n in vars(cls) if not n.startswith("_")} | {"__init__"}
    assert stub_members == runtime_members, cls_name
    for f in node.body:
        if not isinstance(f, ast.FunctionDef):
            continue
        if is_property(f):
            assert inspect.isgetsetdescriptor(vars(cls)[f.name]), f"{cls_name}.{f.name}"
        elif f.name == "__init__":
            assert stub_params(f) == runtime_params(cls), f"{cls_name}.__init__"
        else:
            assert stub_params(f) == runtime_params(getattr(cls, f.name)), f"{cls_name}.{f.name}"


def test_the_episode_result_keys_match_the_stub():
    """``EpisodeResult`` in the stub lists exactly the keys ``run_episode`` returns."""
    import json

    tree = stub_tree()
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "EpisodeResult")
    stub_keys = {n.target.id for n in cls.body if isinstance(n, ast.AnnAssign)}
    root = Path(__file__).resolve().parents[1]
    with open(root / "data" / "scenarios.jsonl") as f:
        sc = json.loads(f.readline())
    sc["t_max"] = 1.0
    r = _core.run_episode(json.dumps(sc), "4dof", 0)
    assert set(r) == stub_keys, (set(r) ^ stub_keys)
