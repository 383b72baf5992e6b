"""The floors of refraster (docs/architecture.md, "Floors"): no import circle anywhere, and no
import up a floor.

Every ``.py`` file under ``refraster/`` is found by walking the tree (a module moved or added
is seen without editing this file) and every import in it is read with ``ast``: top of the
file, inside functions and methods, under ``if``/``try`` alike. Relative imports are resolved
to absolute module names; ``from P import n`` imports the module ``P.n`` when there is one,
else the package ``P`` itself (its ``__init__``); the implicit import of a module's parent
packages is not counted (Python runs it for every submodule, so it is no choice of the code).

:data:`FLOORS` is the one table of floors; docs/architecture.md mirrors it (a test checks
that every key is named there).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "refraster"

#: The floors, lowest first. A module may import its own floor and the floors below.
ORDER = ("core", "techniques", "tools", "goldens", "gallery", "command")
#: Beside the floors: the GLSL backend (imports nothing of refraster; see GL_USERS).
GL = "gl"
#: Beside the floors: the WebGPU backend (imports only itself and WGPU_USES).
WGPU = "wgpu"
#: What refraster.wgpu imports of refraster beside itself: the standalone scene package
#: reader (standard library and NumPy; no moderngl, no core).
WGPU_USES = {"refraster.gl.package"}

#: module-name prefix → floor. A key names a module or package and everything under it
#: (``refraster.edges`` covers ``edges.py`` today and the package ``edges/`` with
#: ``refraster.edges.npr``); the longest key that matches wins; the key ``refraster`` names
#: only the package's own ``__init__``. Keys of modules that are moving (both names listed)
#: may match nothing for a while. Mirrored in docs/architecture.md.
FLOORS = {
    # the core: the pipeline, its data, the conformance model, the canonical solids
    "refraster": "core",
    "refraster.raster": "core",
    "refraster.framebuffer": "core",
    "refraster.multisample": "core",
    "refraster.sample_rate": "core",
    "refraster.mesh": "core",
    "refraster.camera": "core",
    "refraster.io": "core",
    "refraster.ldi": "core",
    "refraster.scenes": "core",
    "refraster.conformance": "core",
    "refraster._validate": "core",
    "refraster._config": "core",
    "refraster._compile_speed": "core",
    "refraster._threads": "core",
    "refraster._scratch": "core",
    "refraster._logs": "core",
    # the techniques: one package per paper
    "refraster.clipsurface": "techniques",
    "refraster.edges": "techniques",
    "refraster.cutaway": "techniques",
    "refraster.halos4d": "techniques",
    # the tools: compiling ahead, worker processes
    "refraster.warmup": "tools",
    "refraster._workers": "tools",
    # the goldens
    "refraster.golden": "goldens",
    # the gallery
    "refraster.gallery": "gallery",
    # what a user runs: the command line, the pytest plugin
    "refraster.cli": "command",
    "refraster.testing": "command",
    # beside the floors
    "refraster.gl": GL,
    "refraster.wgpu": WGPU,
}

#: A technique imports another technique only as listed here (technique key → the technique
#: keys it may import; a technique's own modules import each other freely).
TECHNIQUE_USES = {
    # ghost lines classify the mesh's edges (classify_edges); the cutaway's outlines are an
    # edge map (edge_map)
    "refraster.cutaway": {"refraster.edges"},
}


def gl_user(module):
    """The one module outside refraster.gl (and refraster.wgpu) that may import it: the
    golden's ``candidate`` (wherever the goldens' grouping puts it)."""
    return module.startswith("refraster.golden.") and module.rsplit(".", 1)[1] == "candidate"


#: Inside the goldens, arrows that point one way (modules named below ``refraster.golden``):
#: module → modules it never imports.
GOLDEN_ONE_WAY = {
    # compare.run hands a finished comparison to the report
    "compare.report": ("compare.run", "generate"),
    # compare.run checks with the allowances
    "allowances.core": ("compare.run",),
}


# --- the graph -----------------------------------------------------------------------------

def discover(root=ROOT, package=PACKAGE):
    """{module name: (path, is a package's __init__)} for every .py file under root/package."""
    found = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        is_init = parts[-1] == "__init__"
        if is_init:
            parts = parts[:-1]
        if all(p.isidentifier() for p in parts):
            found[".".join(parts)] = (path, is_init)
    return found


def _imports(tree, module, is_init):
    """(absolute dotted name, line) for every import in ``tree`` (any depth): the names a
    statement imports, with ``from P import n`` giving ``P.n`` (resolved against the tree later)
    and relative imports made absolute."""
    package = module if is_init else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                if node.level - 1 > len(parts) - 1:
                    raise AssertionError(f"{module}:{node.lineno}: relative import beyond the "
                                         "top package")
                base = ".".join(parts[:len(parts) - (node.level - 1)])
                source = base + ("." + node.module if node.module else "")
            else:
                source = node.module
            for alias in node.names:
                yield source, alias.name, node.lineno


def module_graph(root=ROOT, package=PACKAGE):
    """(graph, external, unresolved): graph = {module: {imported module: first line}} inside
    the package; external = {module: {top-level name of another distribution: line}};
    unresolved = [(module, line, name)] imports of the package naming no module of the tree."""
    mods = discover(root, package)
    graph, external, unresolved = {}, {}, []
    for mod, (path, is_init) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        deps, ext = {}, {}
        for source, name, line in _imports(tree, mod, is_init):
            if source.split(".")[0] != package:
                ext.setdefault(source.split(".")[0], line)
                continue
            if name is not None and f"{source}.{name}" in mods:
                target = f"{source}.{name}"                   # from P import submodule
            elif source in mods:
                target = source                              # import P / from P import name
            else:
                unresolved.append((mod, line, source if name is None else f"{source}.{name}"))
                continue
            if target != mod:
                deps.setdefault(target, line)
        graph[mod], external[mod] = deps, ext
    return graph, external, unresolved


def components(graph):
    """The strongly connected components of more than one module (Tarjan), each a sorted
    list: the modules tangled in import circles."""
    index, low, on, stack, comps, counter = {}, {}, set(), [], [], [0]

    def connect(v):
        # iterative Tarjan (the graph is small, but recursion depth is not ours to spend)
        work = [(v, iter(sorted(graph.get(v, ()))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            advanced = False
            for w in it:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    advanced = True
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = set()
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.add(w)
                    if w == node:
                        break
                comps.append(comp)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return sorted(sorted(c) for c in comps if len(c) > 1)


def cycles(graph):
    """One import circle per component of :func:`components`, as a path [a, b, ..., a]: the
    shortest way from its first module back to itself."""
    found = []
    for comp in components(graph):
        start = comp[0]
        # breadth-first from start's imports back to start, inside the component
        prev = {w: start for w in sorted(graph[start]) if w in comp}
        frontier = list(prev)
        while start not in prev:
            nxt = []
            for u in frontier:
                for w in sorted(graph[u]):
                    if w in comp and w not in prev:
                        prev[w] = u
                        nxt.append(w)
            frontier = nxt
        path, node = [start], prev[start]
        while node != start:
            path.append(node)
            node = prev[node]
        path.append(start)
        found.append(path[::-1])
    return found


def floor_key(module):
    """The key of :data:`FLOORS` that places ``module``, or None."""
    keys = [k for k in FLOORS
            if module == k or (k != PACKAGE and module.startswith(k + "."))]
    return max(keys, key=len) if keys else None


def floor_violations(graph, mods):
    """Lines naming each import that breaks a rule of the floors."""
    bad = []

    def where(a, b):
        path = mods[a][0].relative_to(ROOT) if ROOT in mods[a][0].parents else mods[a][0]
        return f"{path}:{graph[a][b]}: {a}"

    for a in sorted(graph):
        ka = floor_key(a)
        if ka is None:
            bad.append(f"{a} has no floor: add its name (or its package's) to FLOORS in "
                       "tests/test_architecture.py and to docs/architecture.md")
            continue
        fa = FLOORS[ka]
        for b in sorted(graph[a]):
            kb = floor_key(b)
            if kb is None:
                continue                                      # reported as b's own line
            fb = FLOORS[kb]
            if fa == WGPU or fb == WGPU:
                if fa == WGPU and fb != WGPU and b not in WGPU_USES:
                    bad.append(f"{where(a, b)} (wgpu) imports {b} ({fb}): refraster.wgpu "
                               f"imports only itself and {sorted(WGPU_USES)}")
                elif fb == WGPU and fa != WGPU and not gl_user(a):
                    bad.append(f"{where(a, b)} ({fa}) imports {b} (wgpu): only the golden's "
                               "candidate module imports refraster.wgpu")
                continue
            if fa == GL and fb != GL:
                bad.append(f"{where(a, b)} (gl) imports {b} ({fb}): refraster.gl imports "
                           "nothing of refraster")
            elif fb == GL and fa != GL and not gl_user(a):
                bad.append(f"{where(a, b)} ({fa}) imports {b} (gl): only the golden's "
                           "candidate module imports refraster.gl")
            elif GL in (fa, fb):
                continue
            elif ORDER.index(fb) > ORDER.index(fa):
                bad.append(f"{where(a, b)} ({fa}) imports {b} ({fb}): a floor imports only "
                           f"its own floor and those below ({' < '.join(ORDER)})")
            elif fa == fb == "techniques" and ka != kb and kb not in TECHNIQUE_USES.get(ka, ()):
                bad.append(f"{where(a, b)} imports {b}: technique {ka} does not import "
                           f"technique {kb} (allow it in TECHNIQUE_USES and say why in "
                           "docs/architecture.md)")
            elif fa == fb == "goldens":
                la, lb = (m[len("refraster.golden."):] for m in (a, b))
                if lb in GOLDEN_ONE_WAY.get(la, ()):
                    bad.append(f"{where(a, b)} imports {b}: in the goldens {la} never "
                               f"imports {lb} (the arrow points the other way)")
    return bad


# --- the checks ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tree():
    mods = discover()
    graph, external, unresolved = module_graph()
    return mods, graph, external, unresolved


def test_every_module_is_found_and_every_import_resolves(tree):
    mods, graph, _, unresolved = tree
    assert {"refraster", "refraster.raster.resolve", "refraster.golden", "refraster.gl.driver",
            "refraster.cli"} <= set(mods)
    assert unresolved == [], "imports of no module of the tree: " + "; ".join(
        f"{m}:{line} imports {name}" for m, line, name in unresolved)


def test_no_import_circle(tree):
    _, graph, _, _ = tree
    found = cycles(graph)
    assert not found, "import circle(s):\n" + "\n".join(
        f"{' -> '.join(path)}  (tangled: {', '.join(comp)})"
        for path, comp in zip(found, components(graph)))


def test_floors(tree):
    mods, graph, _, _ = tree
    bad = floor_violations(graph, mods)
    assert not bad, "imports against the floors (docs/architecture.md, Floors):\n" + \
        "\n".join(bad)


def test_only_refraster_gl_imports_moderngl(tree):
    _, _, external, _ = tree
    users = sorted(m for m, ext in external.items() if "moderngl" in ext
                   and FLOORS.get(floor_key(m)) != GL)
    assert users == [], f"moderngl imported outside refraster.gl: {users}"


def test_the_docs_name_every_floor_key():
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    missing = [k for k in FLOORS if f"`{k}`" not in text]
    assert not missing, f"docs/architecture.md does not name {missing} (mirror FLOORS there)"
    for floor in ORDER + (GL, WGPU):
        assert re.search(rf"\b{floor}\b", text), floor


# --- the checker sees what it must (planted faults in a throw-away tree) -------------------

def _write(root, files):
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_the_walker_sees_every_form_of_import(tmp_path):
    _write(tmp_path, {
        "refraster/__init__.py": "from .camera import look_at\n",
        "refraster/camera.py": "import numpy as np\n",
        "refraster/raster/__init__.py": "",
        "refraster/raster/resolve.py": (
            "from .. import camera\n"                          # from package import module
            "from . import thing\n"                            # a name of raster/__init__
            "def f():\n"
            "    if True:\n"
            "        from ..golden import common\n"              # function level, conditional
            "class C:\n"
            "    def m(self):\n"
            "        import refraster.golden.write as w\n"        # absolute, in a method
            "        from refraster import gl\n"
            "        from ..missing import x\n"),
        "refraster/golden/__init__.py": "",
        "refraster/golden/common.py": "",
        "refraster/golden/write.py": "",
        "refraster/gl/__init__.py": "import moderngl\n",
    })
    graph, external, unresolved = module_graph(tmp_path)
    assert set(graph["refraster.raster.resolve"]) == {
        "refraster.camera", "refraster.raster", "refraster.golden.common",
        "refraster.golden.write", "refraster.gl"}
    assert graph["refraster.raster.resolve"]["refraster.golden.common"] == 5
    assert graph["refraster"] == {"refraster.camera": 1}
    assert graph["refraster.raster"] == {}        # parents are not counted as imports
    assert external["refraster.gl"] == {"moderngl": 1}
    assert unresolved == [("refraster.raster.resolve", 10, "refraster.missing.x")]


def test_the_cycle_finder_reports_a_planted_circle_as_a_path():
    graph = {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1, "d": 1}, "d": {}, "e": {"e": 1}}
    assert cycles(graph) == [["a", "b", "c", "a"]]
    assert cycles({"x": {"y": 1}, "y": {}}) == []
    two = {"p": {"q": 1}, "q": {"p": 1}, "r": {"s": 1}, "s": {"r": 1}}
    assert cycles(two) == [["p", "q", "p"], ["r", "s", "r"]]


def test_the_floor_rules_report_planted_back_imports(tmp_path):
    _write(tmp_path, {
        "refraster/__init__.py": "",
        "refraster/raster/__init__.py": "",
        "refraster/raster/resolve.py": "def f():\n    from ..golden import common\n",
        "refraster/clipsurface/__init__.py": "from ..halos4d import render\n",
        "refraster/cutaway/__init__.py": "from ..edges import edge_map\n",   # documented
        "refraster/edges/__init__.py": "edge_map = None\n",
        "refraster/edges/npr.py": "from . import edge_map\n",                # one technique
        "refraster/halos4d/__init__.py": "",
        "refraster/halos4d/render.py": "from ..cli import main\n",
        "refraster/golden/__init__.py": "",
        "refraster/golden/common.py": "",
        "refraster/golden/compare/__init__.py": "",
        "refraster/golden/compare/run.py": "",
        "refraster/golden/compare/report.py": "def f():\n    from . import run\n",
        "refraster/golden/io/candidate.py": "from ...gl import driver\n",
        "refraster/gl/__init__.py": "",
        "refraster/gl/driver.py": "from ..io import read\n",
        "refraster/io.py": "read = None\n",
        "refraster/gallery/__init__.py": "from ..gl import driver\n",
        "refraster/cli.py": "from .gallery import x\n",
        "refraster/newthing.py": "",
        "refraster/gl/package.py": "",
        "refraster/wgpu/__init__.py": "",
        "refraster/wgpu/driver.py": "from ..gl.package import read_ply\nfrom ..gl import driver\n"
                                    "from ..golden import common\n",
        "refraster/golden/io/read.py": "from ...wgpu import driver\n",
    })
    graph, _, _ = module_graph(tmp_path)
    assert cycles(graph) == []
    bad = "\n".join(floor_violations(graph, discover(tmp_path)))
    assert "refraster.raster.resolve (core) imports refraster.golden.common (goldens)" in bad
    assert "refraster/raster/resolve.py:2:" in bad
    assert "technique refraster.clipsurface does not import technique refraster.halos4d" in bad
    assert "refraster.halos4d.render (techniques) imports refraster.cli (command)" in bad
    assert "in the goldens compare.report never imports compare.run" in bad
    assert "refraster.gl.driver (gl) imports refraster.io (core)" in bad
    assert "refraster.gallery (gallery) imports refraster.gl.driver (gl)" in bad
    assert "refraster.newthing has no floor" in bad
    assert "refraster.wgpu.driver (wgpu) imports refraster.gl.driver (gl)" in bad
    assert "refraster.wgpu.driver (wgpu) imports refraster.golden.common (goldens)" in bad
    assert "refraster.golden.io.read (goldens) imports refraster.wgpu.driver (wgpu)" in bad
    for allowed in ("refraster.cutaway", "refraster.edges.npr", "refraster.golden.io.candidate",
                    "imports refraster.gl.package"):
        assert allowed not in bad, allowed
    assert "/refraster/cli.py:" not in bad            # the command imports the gallery
    assert len(bad.splitlines()) == 10, bad
