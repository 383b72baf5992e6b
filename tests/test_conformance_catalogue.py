"""The catalogue of GPU bug classes (issue 41; refraster/gl/catalogue.py, docs/conformance.md):
every class's planted fault in refraster.gl fails at least one built-in scene — every scene the
catalogue lists for it — while the correct backend passes every scene, and the table of
docs/conformance.md (class → planted fault → scenes that catch it → buffers the report names)
is this run's (``docs/scripts/conformance_table.py`` measures and writes it).

CI runs the classes caught by plain, convention, peel and parity scenes (their goldens
generate in seconds); ``REFRASTER_CONFORMANCE_FULL=1`` (the long tier, ``.ci/long``) adds the
classes of the technique passes (clip surfaces, edge maps, cutaways, 4D halos), whose goldens
take minutes, and checks the whole table. Needs a headless EGL context (Mesa llvmpipe through
moderngl): skips without one, fails under CI=true.
"""

from __future__ import annotations

import ast
import importlib.util
import os
from pathlib import Path

import pytest

from conftest import generate_gold
from conftest import gl_backend_or_skip as _backend_or_skip
from refraster.gl import FAULTS
from refraster.gl.catalogue import CLASSES, GROUPS, TECHNIQUE_SCENES

ROOT = Path(__file__).resolve().parents[1]
FULL = bool(os.environ.get("REFRASTER_CONFORMANCE_FULL"))
#: the classes this run measures
RUN = CLASSES if FULL else tuple(c for c in CLASSES
                                 if not set(c.scenes) & set(TECHNIQUE_SCENES))


def _script():
    path = ROOT / "docs" / "scripts" / "conformance_table.py"
    spec = importlib.util.spec_from_file_location("conformance_table", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TABLE = _script()


# --- the catalogue itself (no GL) --------------------------------------------------------------

def test_catalogue_shape():
    from refraster.golden import available_scenes
    scenes = available_scenes()
    assert len(CLASSES) >= 30 and len(RUN) >= 30
    assert len({c.name for c in CLASSES}) == len(CLASSES)
    assert [g for g in GROUPS if any(c.group == g for c in CLASSES)] == list(GROUPS)
    for c in CLASSES:
        assert c.group in GROUPS and c.fault in FAULTS and c.scenes, c
        assert all(s in scenes for s in c.scenes), c
        assert c.bug and (not c.allowance or "planted" in c.allowance), c
    # every planted fault of refraster.gl is a class of the catalogue, once
    assert sorted(c.fault for c in CLASSES) == sorted(FAULTS)
    # the classes the golden allows by design say so (sub-pixel bits, fill rule)
    allowed = {c.name for c in CLASSES if c.allowance}
    assert {"sub-pixel precision", "fill rule on shared edges"} <= allowed


def test_catalogue_imports_only_the_standard_library():
    tree = ast.parse((ROOT / "refraster" / "gl" / "catalogue.py").read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert names == ["__future__", "dataclasses"], names


def test_doc_catalogue_is_the_registry():
    text = TABLE.CONFORMANCE_MD.read_text(encoding="utf-8")
    assert TABLE.with_catalogue(text) == text, (
        "docs/conformance.md's catalogue is stale: run python docs/scripts/conformance_table.py")


# --- measured ----------------------------------------------------------------------------------

@pytest.fixture(scope="session")
def measured(tmp_path_factory):
    _backend_or_skip().release()
    root = generate_gold(tmp_path_factory, "conformance", TABLE.scenes_of(RUN))
    results = TABLE.measure(root / "golden", root, RUN)
    return results, TABLE.rows(RUN, results), root


def test_correct_backend_passes_every_scene(measured):
    results = measured[0]
    correct = results[TABLE.CORRECT]
    assert sorted(correct) == sorted(TABLE.scenes_of(RUN))
    failing = [s for s, r in correct.items() if r.status != "pass"]
    assert not failing, f"the correct backend fails {failing}"


#: Conformant variants of refraster itself (tests/test_golden_faults.py's): a golden allows
#: either fill rule and the sub-pixel bits it declares (4 to 8), so they pass the catalogue's
#: scenes (the 4-bit ones against goldens declared for 4 bits).
VARIANTS = {"4bit": {"subpixel_bits": 4}, "top_left": {"fill_rule": "top-left"},
            "4bit_top_left": {"subpixel_bits": 4, "fill_rule": "top-left"},
            "float64": {"precision": "float64"}}


def _catalogue_scene_names():
    from refraster import golden
    registry = golden.available_scenes()
    return [n for n in TABLE.scenes_of(RUN)
            if registry[n].build.__module__ == "refraster.golden.catalogue_scenes"]


@pytest.fixture(scope="session")
def golden_4bit(tmp_path_factory):
    """The catalogue's own scenes generated for a candidate of 4 sub-pixel bits (a golden
    declares the candidate's bits, 8 by default: a 4-bit candidate is held to a 4-bit one)."""
    from refraster import golden
    root = tmp_path_factory.mktemp("conformance_4bit")
    golden.generate(root / "golden", _catalogue_scene_names(), candidate_subpixel_bits=4)
    return root / "golden"


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_allowed_variants_pass_the_catalogue_scenes(measured, golden_4bit, tmp_path, variant):
    import numpy as np

    from refraster import golden
    from refraster.golden.compare.run import compare
    from refraster.golden.scenes import raster_state, render_draws
    registry = golden.available_scenes()
    names = _catalogue_scene_names()
    assert len(names) == 5
    for name in names:
        scene = registry[name].build()
        fb = render_draws(scene.draws, scene.camera,
                          {**raster_state(scene.raster), **VARIANTS[variant]})
        (tmp_path / name).mkdir()
        np.savez(tmp_path / name / "buffers.npz", **fb.arrays())
    gold = golden_4bit if VARIANTS[variant].get("subpixel_bits", 8) < 8 else measured[2] / "golden"
    result = compare(gold, tmp_path, mode="tolerant", scenes=names)
    assert result.exit_code == 0, "\n".join(result.failures()[:20])


def test_every_class_is_caught(measured):
    rows = measured[1]
    assert len(rows) == len(RUN)
    none = [c.name for c, caught, _ in rows if not caught]
    assert not none, f"classes caught by no scene: {none}"
    missed = {c.name: m for c, _, m in rows if m}
    assert not missed, f"listed scenes that do not catch their class: {missed}"


def test_doc_table_is_this_run(measured):
    rows = measured[1]
    lines = TABLE.row_lines(rows)
    if os.environ.get("REFRASTER_WRITE_CONFORMANCE") and FULL:
        text = TABLE.CONFORMANCE_MD.read_text(encoding="utf-8")
        TABLE.CONFORMANCE_MD.write_text(
            TABLE.with_catalogue(TABLE.replaced(text, TABLE.table(rows))), encoding="utf-8")
    doc = TABLE.current_lines()
    if FULL:
        assert doc == lines, ("docs/conformance.md's table differs from this run: run python "
                              "docs/scripts/conformance_table.py\n" + TABLE.table(rows))
    else:   # the fast subset: its rows, in the doc's order
        stale = [line for line in lines if line not in doc]
        assert not stale, ("docs/conformance.md's table differs from this run: run python "
                           "docs/scripts/conformance_table.py\n" + "\n".join(stale))
        assert len(doc) == len(CLASSES)
