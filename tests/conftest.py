import importlib
import importlib.machinery
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

# The same examples on every run and machine: a property test that passes here passes in CI
# (a new counter-example is found by widening a test, not by luck).
settings.register_profile("refraster", derandomize=True, print_blob=True)
settings.load_profile("refraster")

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")

# The full tier of the render kernels, whatever the cache holds: no second process compiling
# it behind the tests' backs, the same frame speed on every run (refraster/_tiers.py;
# tests/test_tiers.py runs the quick tier, tests/test_warmup.py a first render as users get it).
os.environ.setdefault("REFRASTER_TIER", "full")


def require(module_name, reason=None):
    """Import an optional oracle; skip the test when it is missing, fail under CI=true."""
    try:
        return importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or an EGL/driver failure inside the import
        msg = reason or f"optional oracle {module_name!r} is not available: {exc}"
        if IN_CI:
            pytest.fail(f"CI=true but {msg}")
        pytest.skip(msg)


@pytest.fixture
def oracle():
    return require


def package_spec(module):
    """The module's spec as found in its package's own directories (``None``: not there). Asked
    of the package's path, not of ``sys.meta_path``: an editable install of another checkout
    adds a finder there that answers with that checkout's files."""
    parent = module.rpartition(".")[0]
    return importlib.machinery.PathFinder.find_spec(
        module, importlib.import_module(parent).__path__)


LLVMPIPE_BACKEND = Path(__file__).with_name("golden_llvmpipe_backend.py")


def llvmpipe_frames(gold, out, *, timeout=600):
    """Render every scene of the golden ``gold`` with llvmpipe into the candidate directory
    ``out`` (``tests/golden_llvmpipe_backend.py`` in an isolated interpreter, so that it cannot
    import refraster); returns the backend's JSON line (``renderer``, ``scenes``). Skips when
    EGL is missing locally, fails under CI=true or on any other backend failure."""
    proc = subprocess.run([sys.executable, "-I", str(LLVMPIPE_BACKEND), str(gold), str(out)],
                          capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        if IN_CI or "EGL" not in proc.stderr:
            pytest.fail(f"llvmpipe backend failed: {proc.stderr[-2000:]}")
        pytest.skip(f"llvmpipe backend failed: {proc.stderr[-500:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def gl_backend_or_skip():
    """A :class:`refraster.gl.driver.Backend` on a headless context; skips without one (a
    failure under ``CI=true``)."""
    from refraster.gl.driver import Backend, GLUnavailable
    try:
        return Backend()
    except GLUnavailable as exc:
        if IN_CI:
            pytest.fail(f"CI=true but the gl backend has no context: {exc}")
        pytest.skip(f"no headless OpenGL context (EGL/llvmpipe): {exc}")


# --- the pass/fail matrices of docs/backends.md (tests/test_gl_*.py) -------------------------

BACKENDS_DOC = Path(__file__).resolve().parents[1] / "docs" / "backends.md"


def matrix_cell(scene_result, *, all_count=True):
    """One cell of a backend matrix: ``pass``, or ``**FAIL**`` with the failing buffers
    (``(all N)`` when every buffer failed and ``all_count``)."""
    if scene_result.status == "pass":
        return "pass"
    failing = [b.name for b in scene_result.buffers if not b.passed]
    if all_count and len(failing) == len(scene_result.buffers):
        return f"**FAIL** (all {len(failing)})"
    return "**FAIL** " + ", ".join(f"`{b}`" for b in failing)


def matrix_table(columns, scenes, results, *, skipped=(), all_count=True):
    """The Markdown matrix: one row per scene, one column per candidate (``correct`` or a
    planted fault, in backticks)."""
    head = ["scene"] + [c if c == "correct" else f"`{c}`" for c in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene in scenes:
        cells = (["skipped"] * len(columns) if scene in skipped else
                 [matrix_cell(results[c][scene], all_count=all_count) for c in columns])
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def check_backends_matrix(begin_marker, end_marker, table, what):
    """The matrix between the markers of docs/backends.md must be ``table``; with
    ``REFRASTER_WRITE_BACKENDS_MATRIX=1`` it is written there first."""
    doc = BACKENDS_DOC.read_text()
    begin, end = doc.index(begin_marker) + len(begin_marker), doc.index(end_marker)
    if os.environ.get("REFRASTER_WRITE_BACKENDS_MATRIX"):
        BACKENDS_DOC.write_text(doc[:begin] + "\n" + table + "\n" + doc[end:])
        doc = BACKENDS_DOC.read_text()
        begin, end = doc.index(begin_marker) + len(begin_marker), doc.index(end_marker)
    assert doc[begin:end].strip() == table, (
        f"docs/backends.md's {what} differs from this run; re-run with "
        "REFRASTER_WRITE_BACKENDS_MATRIX=1 and review the change\n" + table)


def generate_gold(tmp_path_factory, name, scenes, candidate_subpixel_bits=None):
    """A module's golden directory: ``<tmp>/<name>/golden`` with ``scenes`` generated (for a
    candidate of ``candidate_subpixel_bits``; default: generate's own default)."""
    from refraster import golden
    root = tmp_path_factory.mktemp(name)
    bits = {} if candidate_subpixel_bits is None else {
        "candidate_subpixel_bits": candidate_subpixel_bits}
    golden.generate(root / "golden", scenes, **bits)
    return root


# --- framebuffers rendered again (tests/test_render_reuse.py, tests/test_gbuffer_paths.py) ----

#: Every array of a :class:`refraster.Framebuffer`, the colour included.
FB_FIELDS = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
             "barycentric", "color")


def mesh_of(tm):
    """A refraster mesh with the vertices and faces of a trimesh (copies, float64 / int64)."""
    import numpy as np
    from refraster.mesh import as_mesh
    return as_mesh((np.array(tm.vertices, np.float64), np.array(tm.faces, np.int64)))


def camera_kw(w=96, h=72, eye=(1.6, 1.2, 2.4)):
    """``view``, ``proj``, ``width``, ``height`` of a perspective camera looking at the origin."""
    import refraster as rf
    return dict(view=rf.look_at(list(eye), [0, 0, 0]), proj=rf.perspective(45, w / h, 0.5, 10),
                width=w, height=h)


def fault_matrix(gold, columns, scenes, expected, untouched=None, *, only_scenes=False,
                 backend="gl"):
    """Render the golden ``gold/golden``'s scenes with refraster.gl (``backend="wgpu"``:
    refraster.wgpu) once correct and once per
    planted fault (``columns``: ``correct`` and fault names) and compare each candidate
    tolerantly: the correct one must pass every scene; each fault must fail, naming
    ``expected[fault]``'s ``{scene: buffer}``, and pass ``untouched[fault]``'s scenes. Returns
    ``{column: {scene: SceneResult}}`` (the matrix's cells). ``only_scenes``: render just
    ``scenes`` (the golden holds others)."""
    import json

    from refraster import golden
    from refraster.golden.candidate import candidate
    results = {}
    for column in columns:
        out = gold / f"cand_{column}"
        faults = () if column == "correct" else (column,)
        r = candidate(gold / "golden", out, backend=backend, faults=faults,
                      **({"scenes": scenes} if only_scenes else {}))
        assert sorted(r["rendered"]) == sorted(scenes) and not r["skipped"], r["skipped"]
        marker = json.loads((out / ".refraster-candidate").read_text())
        assert marker["faults"] == list(faults) and marker["backend"] == backend
        assert marker["renderer"].startswith("llvmpipe") or not IN_CI
        cmp = golden.compare(gold / "golden", out, mode="tolerant", scenes=r["rendered"])
        results[column] = {s.name: s for s in cmp.scenes}
        assert all(s.status in ("pass", "fail") for s in cmp.scenes), cmp.summary()
        if column == "correct":
            assert cmp.exit_code == 0, "\n".join(cmp.failures())
            continue
        assert cmp.exit_code == 1, f"fault {column} passed every scene"
        for scene, buffer in expected[column].items():
            assert [line for line in cmp.failures() if line.startswith(f"{scene}/{buffer}")], \
                f"fault {column}: {scene}/{buffer} not named ({cmp.failures()})"
        for scene in (untouched or {}).get(column, ()):
            assert results[column][scene].status == "pass", (column, scene)
    return results


@pytest.fixture
def empty_output_pool(monkeypatch):
    """The output pool (``refraster._scratch.OUTPUTS``) emptied before and after the test, with
    ``REFRASTER_POOL_MB`` unset (its default)."""
    from refraster._scratch import OUTPUTS
    monkeypatch.delenv("REFRASTER_POOL_MB", raising=False)
    OUTPUTS.clear()
    yield OUTPUTS
    OUTPUTS.clear()
