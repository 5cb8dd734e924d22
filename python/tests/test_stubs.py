"""The type stubs (photometeor/__init__.pyi) describe the module as it is: the same public names,
and every function with the same parameters (names, kinds, defaults) as the runtime object."""

from __future__ import annotations

import ast
import dataclasses
import inspect
from pathlib import Path

import photometeor

STUB = Path(photometeor.__file__).with_name("__init__.pyi")


def stub_tree():
    return ast.parse(STUB.read_text())


def stub_all(tree) -> list:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError("the stub has no __all__")


def test_the_stub_names_what_the_module_exports():
    tree = stub_tree()
    assert sorted(stub_all(tree)) == sorted(photometeor.__all__)
    defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    assert defined == set(photometeor.__all__)
    for name in photometeor.__all__:
        assert hasattr(photometeor, name), name
    # Nothing public of the package's own is left out of __all__ (imports such as np aside).
    own = {
        n
        for n, v in vars(photometeor).items()
        if not n.startswith("_") and (getattr(v, "__module__", None) or "").split(".")[-1] in ("photometeor", "_native")
    }
    assert own == set(photometeor.__all__)


def runtime_parameters(obj):
    return [(p.name, p.kind, p.default) for p in inspect.signature(obj).parameters.values()]


def stub_parameters(fn: ast.FunctionDef):
    a = fn.args
    out = []
    positional = a.posonlyargs + a.args
    defaults = [inspect.Parameter.empty] * (len(positional) - len(a.defaults)) + [
        ast.literal_eval(d) for d in a.defaults
    ]
    for arg, default in zip(positional, defaults):
        out.append((arg.arg, inspect.Parameter.POSITIONAL_OR_KEYWORD, default))
    for arg, default in zip(a.kwonlyargs, a.kw_defaults):
        d = inspect.Parameter.empty if default is None else ast.literal_eval(default)
        out.append((arg.arg, inspect.Parameter.KEYWORD_ONLY, d))
    return out


def test_every_function_has_the_stub_signature():
    tree = stub_tree()
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert set(functions) == {"mie", "refractive_index", "size_parameter", "phase", "crystal_phase", "load", "bake"}
    for name, fn in functions.items():
        assert runtime_parameters(getattr(photometeor, name)) == stub_parameters(fn), name


def test_every_class_has_the_stub_fields():
    tree = stub_tree()
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            stub_fields = [s.target.id for s in node.body if isinstance(s, ast.AnnAssign)]
            runtime = [f.name for f in dataclasses.fields(getattr(photometeor, node.name))]
            assert stub_fields == runtime, node.name


def test_every_public_function_documents_its_units():
    for name in ("mie", "phase", "crystal_phase", "bake", "load", "refractive_index", "size_parameter"):
        doc = getattr(photometeor, name).__doc__ or ""
        assert len(doc) > 100 or name == "size_parameter", name
        assert any(unit in doc for unit in ("nm", "µm", "1/sr", "degrees")), name
