"""The shape of the public API (issue 38): options travel as values, not as ever longer keyword
lists.

* No public function or method takes more than :data:`MAX_PARAMETERS` parameters. Numba
  kernels are not API (they take arrays positionally, as a GPU kernel its bindings) and are
  skipped; result records (dataclasses) are not functions and hold what they hold.
* No public function passes ``**kwargs`` through to hide its options; the exceptions are
  named in :data:`KWARGS_ALLOWED` with the reason.

The scan reads the source with ``ast`` (nothing is imported, so the optional GL backend is
covered too).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "refraster"
MAX_PARAMETERS = 15

#: (module path, function) pairs whose ``**`` parameter is data, not options.
KWARGS_ALLOWED = {
    # arrays by name, as numpy.savez: the names are the file's members
    ("io.py", "write_npz"): "arrays by member name",
}
#: ``replace(**changes)`` of an immutable value: a copy with some constructor fields changed,
#: validated by the constructor (as dataclasses.replace).
KWARGS_ALLOWED_NAMES = {"replace"}


def _jitted(fn):
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if "jit" in name or name in ("vectorize", "guvectorize", "stencil"):
            return True
    return False


def _public_functions(path):
    """(qualified name, FunctionDef) of the public module-level functions and public methods
    of public classes of one module."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if not node.name.startswith("_"):
                yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and (
                        not item.name.startswith("_") or item.name == "__init__"):
                    yield f"{node.name}.{item.name}", item


def _modules():
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if any(part.startswith("_") and part != "__init__.py" for part in rel.parts):
            continue   # private modules (_scratch, _workers, ...) are not API
        yield rel, path


def _count(fn, method):
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args]
    n = len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
    if method and names and names[0] in ("self", "cls"):
        n -= 1
    return n


def violations(max_parameters=MAX_PARAMETERS):
    too_many, kwargs = [], []
    for rel, path in _modules():
        for qual, fn in _public_functions(path):
            if _jitted(fn):
                continue
            n = _count(fn, "." in qual)
            if n > max_parameters:
                too_many.append(f"{rel}: {qual} takes {n} parameters")
            name = qual.rsplit(".", 1)[-1]
            if (fn.args.kwarg is not None and (rel.as_posix(), qual) not in KWARGS_ALLOWED
                    and name not in KWARGS_ALLOWED_NAMES):
                kwargs.append(f"{rel}: {qual} passes **{fn.args.kwarg.arg} through")
    return too_many, kwargs


def test_no_public_function_takes_more_than_15_parameters():
    too_many, _ = violations()
    assert not too_many, "\n".join(too_many)


def test_no_public_function_hides_options_behind_kwargs():
    _, kwargs = violations()
    assert not kwargs, "\n".join(kwargs)


def test_the_scan_sees_a_long_signature_and_kwargs(tmp_path, monkeypatch):
    """Both directions: a planted 16-parameter function and a **kwargs pass-through are found
    (and a jitted kernel with as many is not API)."""
    pkg = tmp_path / "refraster"
    pkg.mkdir()
    params = ", ".join(f"p{i}" for i in range(16))
    (pkg / "planted.py").write_text(
        f"def long_one({params}):\n    pass\n\n"
        "def hides(mesh, **options):\n    pass\n\n"
        "class Value:\n    def method(self, " + ", ".join(f"q{i}" for i in range(15)) + "):\n"
        "        pass\n\n"
        f"@njit(cache=True)\ndef kernel({params}):\n    pass\n")
    monkeypatch.setitem(globals(), "ROOT", pkg)
    too_many, kwargs = violations()
    assert too_many == ["planted.py: long_one takes 16 parameters"]
    assert kwargs == ["planted.py: hides passes **options through"]


@pytest.mark.parametrize("name", ["render", "draw", "rasterize", "resolve"])
def test_the_pipeline_takes_the_raster_state_not_its_fields(name):
    """The old keywords are gone (nothing was released): the state is one value."""
    import inspect

    import refraster as rf
    params = set(inspect.signature(getattr(rf, name)).parameters)
    assert "raster" in params
    fields = {"depth_func", "depth_write", "clear_depth", "cull", "front_face",
              "subpixel_bits", "fill_rule", "precision", "normals"}
    assert not params & fields, sorted(params & fields)
