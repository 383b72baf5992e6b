"""The clip-surface package: no import circle among its modules, its public names importable
from ``refraster.clipsurface``, and the modules it replaced (``refraster.capping``,
``refraster.offsetmaps``) gone: their code lives in ``refraster.clipsurface.capping`` and
``refraster.clipsurface.offsetmaps`` only."""

import ast
import importlib
import importlib.machinery
import pathlib

import pytest

PKG = pathlib.Path(__file__).resolve().parents[1] / "refraster" / "clipsurface"


def _package_imports(path):
    """Sibling modules of the package that ``path`` imports (at any depth: lazy imports in
    functions count too)."""
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                names.add(node.module.split(".")[0])
            else:
                names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                and node.module.startswith("refraster.clipsurface."):
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
    assert {"offsetmaps", "surfaces", "capping", "fused", "render"} <= set(graph)
    assert _cycle(graph) is None, f"import circle: {' -> '.join(_cycle(graph))}"


def test_the_circle_finder_finds_a_planted_circle():
    graph = _graph()
    assert "surfaces" in graph["capping"]
    graph["surfaces"] = graph["surfaces"] + ["capping"]      # the old clipsurface <-> capping
    assert _cycle(graph) is not None


def test_the_core_never_imports_the_package():
    root = PKG.parent
    for sub in ("raster", "camera.py", "mesh.py", "framebuffer.py", "ldi.py"):
        paths = [root / sub] if sub.endswith(".py") else sorted((root / sub).glob("*.py"))
        for p in paths:
            text = p.read_text()
            assert "clipsurface" not in text and "capping" not in text \
                and "offsetmaps" not in text, p


PUBLIC_NAMES = ["ClipSurface", "ReliefClipPlane", "ClippedFramebuffer", "as_surfaces",
                "clip_function", "clip_mask", "render_clipped", "clipped_at",
                "ORTHOGONALITY_TOLERANCE"]


def test_the_package_exports_its_public_names():
    mod = importlib.import_module("refraster.clipsurface")
    for name in PUBLIC_NAMES + list(mod.__all__):
        assert hasattr(mod, name), f"refraster.clipsurface.{name}"


def _package_spec(module):
    """The module's spec as found in its package's own directories (``None``: not there). Asked
    of the package's path, not of ``sys.meta_path``: an editable install of another checkout
    adds a finder there that answers with that checkout's files."""
    parent = module.rpartition(".")[0]
    return importlib.machinery.PathFinder.find_spec(
        module, importlib.import_module(parent).__path__)


@pytest.mark.parametrize("module", ["refraster.capping", "refraster.offsetmaps"])
def test_the_removed_re_export_modules_are_gone(module):
    assert _package_spec(module) is None, f"{module} is back"
    assert _package_spec(module.replace("refraster.", "refraster.clipsurface.")) is not None
