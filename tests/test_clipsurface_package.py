"""The clip-surface package: no import circle among its modules, and every name importable
from where it was before the package existed (refraster.clipsurface, .capping, .offsetmaps)."""

import ast
import importlib
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


OLD_NAMES = {
    "refraster.clipsurface": ["ClipSurface", "ReliefClipPlane", "ClippedFramebuffer",
                              "as_surfaces", "clip_function", "clip_mask", "render_clipped",
                              "clipped_at", "ORTHOGONALITY_TOLERANCE"],
    "refraster.capping": ["CAP_STYLES", "check_watertight", "cap_mesh", "cull_cap",
                          "exact_caps", "light_caps", "shade_cap_pixels", "shade_caps",
                          "solid_texture", "surely_inside", "MAX_CAP_VERTICES",
                          "FOOTPRINT_MARGIN", "SURE_EXTRAPOLATION", "pixel_rays",
                          "texture_caps"],
    "refraster.offsetmaps": ["WRAP_MODES", "as_offset_map", "load_offset_map", "sample",
                             "constant", "value_noise", "perlin_noise", "ragged_cut",
                             "sinusoid", "steps", "blend", "normal_map", "encode_normal_map",
                             "occlusion_map", "as_wrap", "bilinear_taps", "bilinear",
                             "texture2d_flat"],
}


@pytest.mark.parametrize("module", sorted(OLD_NAMES))
def test_every_old_name_is_importable_from_its_old_place(module):
    mod = importlib.import_module(module)
    for name in OLD_NAMES[module] + list(getattr(mod, "__all__", [])):
        assert hasattr(mod, name), f"{module}.{name}"


def test_the_shims_are_the_package_modules_objects():
    from refraster import capping, offsetmaps
    from refraster.clipsurface import capping as c2
    from refraster.clipsurface import offsetmaps as o2
    assert capping.cap_mesh is c2.cap_mesh and offsetmaps.sample is o2.sample
    assert capping.__all__ == c2.__all__ and offsetmaps.__all__ == o2.__all__
