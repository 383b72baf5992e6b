"""The edge-enhancement package: no import circle among its modules, its public names importable
from ``refraster.edges`` and from the module that defines them, and ``refraster.npr`` gone (the
NPR styles are ``refraster.edges.npr``)."""

import ast
import importlib
import pathlib

from conftest import package_spec

PKG = pathlib.Path(__file__).resolve().parents[1] / "refraster" / "edges"
MODULES = {"gbuffer", "operators", "npr", "classify", "multisample"}


def _package_imports(path):
    """Sibling modules of the package that ``path`` imports (at any depth: lazy imports in
    functions count too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                names.add(node.module.split(".")[0])
            else:
                names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.startswith("refraster.edges."):
            names.add(node.module.split(".")[2])
    return names


def _graph():
    mods = {p.stem for p in PKG.glob("*.py") if p.stem != "__init__"}
    return {m: sorted(_package_imports(PKG / f"{m}.py") & mods) for m in mods}


def _cycle(graph):
    """A cycle of the directed graph as a list of nodes, or None (depth-first search)."""
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in graph[n]:
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state:
            found = visit(n)
            if found:
                return found
    return None


def test_no_import_circle_inside_the_package():
    graph = _graph()
    assert set(graph) == MODULES
    assert graph["operators"] == ["gbuffer"] and graph["npr"] == ["operators"]
    assert _cycle(graph) is None, f"import circle: {' -> '.join(_cycle(graph))}"


def test_the_circle_finder_finds_a_planted_circle():
    graph = _graph()
    graph["gbuffer"] = graph["gbuffer"] + ["npr"]
    assert _cycle(graph) == ["gbuffer", "npr", "operators", "gbuffer"]


def test_public_names_are_the_defining_modules_objects():
    import refraster.edges as edges
    for name in edges.__all__:
        obj = getattr(edges, name)
        homes = [m for m in MODULES
                 if name in importlib.import_module(f"refraster.edges.{m}").__all__]
        assert len(homes) == 1, (name, homes)
        assert getattr(importlib.import_module(f"refraster.edges.{homes[0]}"), name) is obj
    assert edges.npr is importlib.import_module("refraster.edges.npr")
    assert "render_mirrored" in edges.npr.__all__ and "gooch" in edges.npr.__all__


def test_the_old_npr_module_is_gone():
    assert package_spec("refraster.npr") is None, "refraster.npr is back"
    assert package_spec("refraster.edges.npr") is not None
    spec = package_spec("refraster.edges")
    assert spec is not None and spec.submodule_search_locations, "refraster.edges is a package"
