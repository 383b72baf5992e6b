"""refraster.wgpu, the WebGPU backend in WGSL (issue 40): it reads only scene packages, runs on a
device with WebGPU's default limits, ``golden candidate --backend wgpu`` writes a candidate by the
golden write rules and lists what it skipped, every supported scene passes the tolerant compare
on lavapipe (Vulkan on llvmpipe, through wgpu-py) in the convention the scene declares, and
every planted fault fails it naming the buffer. The pass/fail matrix is the one in
docs/backends.md ("refraster.wgpu").

The goldens hold OpenGL-convention scenes; the other conventions are their exact twins
(:func:`twin_golden`): the same scene with its projection re-expressed and ``scene.json``'s
``raster`` saying so — WebGPU (``zero_to_one``, upper-left), Vulkan (``zero_to_one``,
upper-left, NDC y down) and reversed-Z (``zero_to_one``, ``greater``, clear 0). In exact
arithmetic a twin draws the same picture with the same window depth (reversed-Z: 1 − depth,
mapped back before the compare), so the GL golden's allowances judge it.

Needs wgpu-py and a WebGPU adapter (Mesa's lavapipe: ``mesa-vulkan-drivers``): skips without
them, fails under CI=true (the project's optional-oracle rule).
"""

import ast
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import IN_CI, check_backends_matrix, generate_gold, matrix_cell, matrix_table

ROOT = Path(__file__).resolve().parents[1]
WGPU_DIR = ROOT / "refraster" / "wgpu"
BEGIN, END = "<!-- wgpu-matrix:begin (tests/test_wgpu_backend.py) -->", "<!-- wgpu-matrix:end -->"

PLAIN = ["render_cube", "render_icosphere_smooth", "render_torus_ortho", "render_fluted_column",
         "render_nested_shells", "render_building", "render_crank", "render_multi_draw"]
LDI, VDS = "ldi_nested_shells", "vds_parity_building"
SCENES = PLAIN + [LDI, VDS]
#: the scene the candidate command must skip with its reason: the ldi scene's package edited to
#: an option refraster.wgpu does not draw (every technique of the goldens is in WGSL)
SKIPPED, SKIP_EDIT = LDI, {"mode": "all"}

#: OpenGL clip space → WebGPU's 0 ≤ z ≤ w, the same planes: z' = (z + w)/2.
ZERO_TO_ONE = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0.5, 0.5], [0, 0, 0, 1.0]])
#: Vulkan's NDC y points down: the clip y negated.
Y_DOWN = np.diag([1.0, -1.0, 1.0, 1.0])
#: Reversed-Z in 0 ≤ z ≤ w: z'' = w − z' (near → 1, far → 0).
REVERSED = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, -1.0, 1.0], [0, 0, 0, 1.0]])

#: convention → (projection map, scene.json raster fields, the scenes drawn in it)
CONVENTIONS = {
    "webgpu": (ZERO_TO_ONE, dict(depth_range="zero_to_one", origin="upper_left", ndc_y="up"),
               ["render_cube", "render_torus_ortho", "render_multi_draw", LDI, VDS]),
    "vulkan": (Y_DOWN @ ZERO_TO_ONE,
               dict(depth_range="zero_to_one", origin="upper_left", ndc_y="down"),
               ["render_building", "render_crank", LDI]),
    "reversed_z": (REVERSED @ ZERO_TO_ONE,
                   dict(depth_range="zero_to_one", origin="upper_left", ndc_y="up",
                        depth_func="greater", clear_depth=0.0),
                   ["render_cube", "render_torus_ortho", "render_building", LDI, VDS]),
}
#: the convention fields scene.json gains (issue 39); the twins need them in SCENE_SCHEMA
CONVENTION_SCHEMA = {"depth_range": {"enum": ["negative_one_to_one", "zero_to_one"]},
                     "origin": {"enum": ["lower_left", "upper_left"]},
                     "ndc_y": {"enum": ["up", "down"]}, "depth_clamp": {"type": "boolean"},
                     "depth_format": {"enum": ["float32", "unorm24", "unorm16"]}}

#: the matrix's rows: (convention or None for the scene as generated, scene)
ROWS = [(None, s) for s in SCENES] + [(c, s) for c, (_, _, ss) in CONVENTIONS.items()
                                       for s in ss]
NATIVE = [(c, s) for c, s in ROWS if c is not None]        # zero_to_one projections
REV = [(c, s) for c, s in ROWS if c == "reversed_z"]


def _ids(scene):
    return "layer_prim_id" if scene == LDI else "prim_id"


#: fault → {row: buffer that must be named among the failing ones}
EXPECTED = {
    "gl_remap_on_zero_to_one": {r: ("layer_depth" if r[1] == LDI else "depth") for r in NATIVE},
    "y_not_flipped": {r: _ids(r[1]) for r in ROWS},
    "reversed_z_less": {r: ("layer_count" if r[1] == LDI else "prim_id") for r in REV},
    "clear_one_under_greater": {r: ("layer_count" if r[1] == LDI else "prim_id") for r in REV},
    "half_pixel": {r: ("layer_depth" if r[1] == LDI else "prim_id") for r in ROWS},
    "provoking_vertex_face_id": {r: _ids(r[1]) for r in ROWS},
    "sprite_rows_flipped": {r: "inside" for r in ROWS if r[1] == VDS},
}
#: rows a fault cannot change (so they must pass)
UNTOUCHED = {
    "gl_remap_on_zero_to_one": [r for r in ROWS if r[0] is None],
    "reversed_z_less": [r for r in ROWS if r[0] != "reversed_z"],
    "clear_one_under_greater": [r for r in ROWS if r[0] != "reversed_z"],
    "sprite_rows_flipped": [r for r in ROWS if r[1] != VDS],
}


def row_name(row):
    convention, scene = row
    return scene if convention is None else f"{scene} ({convention})"


def backend_or_skip(**kw):
    """A :class:`refraster.wgpu.driver.Backend`; skips without wgpu or an adapter (a failure
    under ``CI=true``)."""
    from refraster.wgpu.device import WGPUUnavailable
    from refraster.wgpu.driver import Backend
    try:
        return Backend(**kw)
    except WGPUUnavailable as exc:
        if IN_CI:
            pytest.fail(f"CI=true but the wgpu backend has no device: {exc}")
        pytest.skip(f"no WebGPU device (wgpu-py and Mesa's lavapipe): {exc}")


# --- the import rule -------------------------------------------------------------------------

def _foreign_imports(source):
    """Imports of ``source`` outside numpy, wgpu, the standard library, refraster.wgpu and the
    package reader refraster.gl.package."""
    allowed = set(sys.stdlib_module_names) | {"numpy", "wgpu", "__future__"}
    bad = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            bad += [a.name for a in node.names if a.name.split(".")[0] not in allowed]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level == 1 or (node.level == 2 and module == "gl.package"):
                continue
            if node.level > 1:
                bad.append("." * node.level + module)
            elif module.split(".")[0] not in allowed:
                bad.append(module)
    return bad


def test_wgpu_imports_only_numpy_wgpu_stdlib_and_the_package_reader():
    files = sorted(WGPU_DIR.glob("*.py"))
    assert {p.name for p in files} >= {"__init__.py", "driver.py", "device.py"}
    for path in files:
        assert _foreign_imports(path.read_text()) == [], path
    assert _foreign_imports("def f():\n    from ..golden import read\n") == ["..golden"]
    assert _foreign_imports("from ..gl import driver\n") == ["..gl"]
    assert _foreign_imports("import refraster.mesh\n") == ["refraster.mesh"]
    assert _foreign_imports("import moderngl\n") == ["moderngl"]


def test_import_refraster_does_not_import_wgpu():
    code = ("import sys, refraster, refraster.golden, refraster.golden.cli, refraster.cli;"
            "print([m for m in sys.modules if m.startswith('refraster.wgpu') or m == 'wgpu'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
    code = "import sys, refraster.wgpu, refraster.wgpu.driver; print('wgpu' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert out.stdout.strip() == "False", out.stderr


# --- portable: WebGPU's default limits ------------------------------------------------------

def test_passes_fit_the_default_bytes_per_sample():
    from refraster.wgpu.device import DEFAULT_LIMITS
    from refraster.wgpu.driver import _BYTES, _PEEL_TARGETS, _VDS_SHADE, GBUFFER_PASSES
    budget = DEFAULT_LIMITS["max-color-attachment-bytes-per-sample"]
    for formats in (*GBUFFER_PASSES.values(), _VDS_SHADE[1], _PEEL_TARGETS):
        assert sum(_BYTES[f] for f in formats) <= budget, formats
        assert len(formats) <= DEFAULT_LIMITS["max-color-attachments"]


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    # declared for 4 sub-pixel bits: at the default 8, lavapipe's barycentrics on the crank
    # leave the interval at 2 of 27,648 pixels (by ~5e-4; llvmpipe through GL stays inside);
    # open in docs/backends.md
    return generate_gold(tmp_path_factory, "wgpu", SCENES, candidate_subpixel_bits=4)


def test_the_device_has_the_default_limits_and_the_scenes_pass_on_it(gold):
    """The backend's device is created with WebGPU's default limits (lavapipe would grant 128
    bytes per sample unasked); a pipeline over the 32-byte budget is refused on it, and the
    G-buffer scenes pass on it."""
    from refraster import golden
    from refraster.golden.candidate import candidate
    from refraster.wgpu.device import DEFAULT_LIMITS
    with backend_or_skip() as gpu:
        limits = gpu.device.limits
        known = [k for k in DEFAULT_LIMITS if k in limits]
        assert len(known) >= 30
        # wgpu-native reports max-bind-groups-plus-vertex-buffers as 0 (it does not track it)
        differ = {k: limits[k] for k in known if limits[k] != DEFAULT_LIMITS[k]}
        assert set(differ) <= {"max-bind-groups-plus-vertex-buffers"} and \
            not any(differ.values()), differ
        key = "max-color-attachment-bytes-per-sample"
        assert limits[key] == 32 and gpu.adapter.limits[key] >= 32
        assert set(gpu.device.features) <= {"depth-clip-control"}
        # the other direction: 48 bytes per sample are refused by this device
        module = gpu.device.create_shader_module(code=gpu.module_code + """
struct Big { @location(0) a: vec4<f32>, @location(1) b: vec4<f32>, @location(2) c: vec4<f32> };
@fragment fn fs_big(i: VOut) -> Big { var o: Big; return o; }
""")
        gpu.module = module
        scene = {"raster": {"depth_func": "less", "clear_depth": 1.0, "cull": "none"}}
        from refraster.wgpu.driver import convention
        state, _ = gpu._state(scene, convention(scene))
        with pytest.raises(Exception, match="bytes per sample"):
            gpu._pipeline("fs_big", ("rgba32float",) * 3, state)
    out = gold / "cand_limits"
    r = candidate(gold / "golden", out, backend="wgpu", scenes=["render_cube", VDS, LDI])
    assert sorted(r["rendered"]) == sorted(["render_cube", VDS, LDI])
    cmp = golden.compare(gold / "golden", out, mode="tolerant", scenes=r["rendered"])
    assert cmp.exit_code == 0, "\n".join(cmp.failures())


# --- the conventions' twins -----------------------------------------------------------------

@pytest.fixture(scope="module")
def convention_schema():
    """SCENE_SCHEMA knowing the convention fields of scene.json's raster (issue 39 adds them;
    until then the twins widen it for this module)."""
    from refraster.golden.io.schema import SCENE_SCHEMA
    props = SCENE_SCHEMA["properties"]["raster"]["properties"]
    added = [k for k in CONVENTION_SCHEMA if k not in props]
    props.update({k: CONVENTION_SCHEMA[k] for k in added})
    yield
    for k in added:
        props.pop(k)


def twin_golden(gold, convention, scenes=None):
    """``gold/twin_<convention>``: a copy of the golden whose scenes of ``convention`` (or
    ``scenes``) have the projection ``map @ P`` and the convention's raster fields in scene.json
    (and the manifest's sha256 of it). Other scenes are left out of the comparison (they stay as
    generated)."""
    mapping, fields, own = CONVENTIONS[convention]
    scenes = own if scenes is None else scenes

    def edit(doc):
        doc["camera"]["projection"] = (mapping @ np.array(doc["camera"]["projection"])).tolist()
        doc["raster"].update(fields)
    return _edited_golden(gold, f"twin_{convention}", scenes, edit)


def _edited_golden(gold, name, scenes, edit):
    """``gold/<name>``: a copy of ``gold/golden`` (made once) whose ``scenes`` have their
    scene.json changed by ``edit(doc)`` in place, the manifest's sha256 of it following."""
    where = gold / name
    if where.exists():
        return where
    shutil.copytree(gold / "golden", where)
    manifest = json.loads((where / "manifest.json").read_text())
    for scene in scenes:
        rel = manifest["scenes"][scene]["package"]
        doc = json.loads((where / rel).read_text())
        edit(doc)
        data = (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode()
        (where / rel).write_bytes(data)
        manifest["files"][rel] = hashlib.sha256(data).hexdigest()
    (where / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return where


def unreverse(candidate_dir, scenes):
    """Reversed-Z window depth d'' = 1 − d back to the golden's d (in the candidate's files)."""
    for scene in scenes:
        path = candidate_dir / scene / "buffers.npz"
        with np.load(path) as z:
            arrays = {k: z[k] for k in z.files}
        for key in ("depth", "layer_depth"):
            if key in arrays:
                arrays[key] = (np.float32(1.0) - arrays[key]).astype(np.float32)
        np.savez_compressed(path, **arrays)


def run_matrix(gold, columns):
    """Every row rendered by the correct backend and each planted fault, compared tolerantly
    → ``{column: {row: SceneResult}}``; checks EXPECTED and UNTOUCHED as it goes."""
    from refraster import golden
    from refraster.golden.candidate import candidate
    goldens = {None: (gold / "golden", SCENES)}
    goldens.update({c: (twin_golden(gold, c), CONVENTIONS[c][2]) for c in CONVENTIONS})
    results = {}
    for column in columns:
        faults = () if column == "correct" else (column,)
        results[column], failures = {}, []
        for convention, (gdir, scenes) in goldens.items():
            out = gold / f"cand_{column}_{convention or 'as_generated'}"
            r = candidate(gdir, out, backend="wgpu", scenes=scenes, faults=faults)
            assert sorted(r["rendered"]) == sorted(scenes) and not r["skipped"], r["skipped"]
            marker = json.loads((out / ".refraster-candidate").read_text())
            assert marker["faults"] == list(faults) and marker["backend"] == "wgpu"
            assert marker["renderer"].startswith("llvmpipe") or not IN_CI
            if convention == "reversed_z":
                unreverse(out, scenes)
            cmp = golden.compare(gdir, out, mode="tolerant", scenes=scenes)
            assert all(s.status in ("pass", "fail") for s in cmp.scenes), cmp.summary()
            for s in cmp.scenes:
                results[column][(convention, s.name)] = s
            failures += [(convention, line) for line in cmp.failures()]
        if column == "correct":
            assert not failures, "\n".join(f"{c}: {line}" for c, line in failures)
            continue
        assert failures, f"fault {column} passed every scene"
        for (convention, scene), buffer in EXPECTED[column].items():
            assert [1 for c, line in failures
                    if c == convention and line.startswith(f"{scene}/{buffer}")], \
                f"fault {column}: {row_name((convention, scene))}/{buffer} not named"
        for row in UNTOUCHED.get(column, ()):
            assert results[column][row].status == "pass", (column, row)
    return results


def test_candidate_passes_and_every_planted_fault_fails(gold, convention_schema):
    from refraster.wgpu import CONVENTION_FAULTS, FAULTS
    backend_or_skip().release()
    # the convention faults have their matrix in tests/test_wgpu_conventions.py
    columns = ["correct", *[f for f in FAULTS if f not in CONVENTION_FAULTS]]
    results = run_matrix(gold, columns)
    named = {c: {row_name(r): s for r, s in results[c].items()} for c in columns}
    table = matrix_table(columns, [row_name(r) for r in ROWS], named)
    check_backends_matrix(BEGIN, END, table, "wgpu matrix")
    # the parity decision only
    assert matrix_cell(results["sprite_rows_flipped"][(None, VDS)]) == "**FAIL** `inside`"


def test_peel_layer_slots_and_count(gold):
    """``layers`` only shapes the output; layer_count counts every layer the peel found."""
    with backend_or_skip() as gpu:
        pkg = gold / "golden" / LDI / "package"
        full = gpu.render(pkg)
        three = gpu.render(pkg, layers=3)
    k = full["layer_depth"].shape[-1]
    assert k == 8 and three["layer_depth"].shape[-1] == 3
    np.testing.assert_array_equal(full["layer_count"], three["layer_count"])
    np.testing.assert_array_equal(full["layer_depth"][..., :3], three["layer_depth"])


def test_face_ids_agree_with_primitive_index(gold):
    """Cross-check (optional feature ``primitive-index``, asked for by name here only): the
    flat face attribute of the de-indexed draw equals ``@builtin(primitive_index)`` at every
    covered pixel, and the provoking-vertex fault's does not."""
    from refraster.wgpu.device import adapter
    from refraster.wgpu.driver import convention
    _, found = adapter()
    if "primitive-index" not in found.features:
        pytest.skip("the adapter does not offer primitive-index")
    extra = """
@fragment fn fs_prim(i: VOut, @builtin(primitive_index) p: u32) -> @location(0) vec4<i32> {
    return vec4<i32>(i.face, i32(p), 0, 1);
}
"""
    for faults, agree in (((), True), (("provoking_vertex_face_id",), False)):
        with backend_or_skip(features=["primitive-index"], faults=faults) as gpu:
            gpu.module = gpu.device.create_shader_module(
                code="enable primitive_index;\n" + gpu.module_code + extra)
            loaded = gpu.load(gold / "golden" / "render_crank" / "package")
            scene = loaded["scene"]
            size = (scene["viewport"]["width"], scene["viewport"]["height"])
            state, clear = gpu._state(scene, convention(scene))
            target = gpu._targets(("rgba32sint",), size)
            depth = gpu._depth(state, size)
            enc = gpu.device.create_command_encoder()
            gpu._pass(enc, gpu._pipeline("fs_prim", ("rgba32sint",), state), target, depth,
                      clear, loaded["draws"])
            gpu.device.queue.submit([enc.finish()])
            got = gpu._read(target[0], "rgba32sint", size)
            gpu.unload(loaded)
        covered = got[..., 3] == 1
        assert covered.sum() > 1000
        same = got[..., 0][covered] == got[..., 1][covered]
        assert same.all() if agree else not same.all()


# --- the command -----------------------------------------------------------------------------

def _cli(*args):
    return subprocess.run([sys.executable, "-m", "refraster.cli", "golden", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})


def _skip_golden(gold):
    """``gold/skip``: a copy of the golden whose SKIPPED package asks for SKIP_EDIT (the
    manifest's sha256 of its scene.json follows)."""
    return _edited_golden(gold, "skip", [SKIPPED], lambda doc: doc["parameters"].update(SKIP_EDIT))


def test_candidate_command_writes_and_lists_what_it_skipped(gold):
    """The command renders what it can and lists every scene it skipped with its reason (a
    non-empty sentence, printed and in the marker); no technique of the goldens is skipped as
    not implemented."""
    from refraster.wgpu import LATER_TECHNIQUES
    assert LATER_TECHNIQUES == ()
    backend_or_skip().release()
    g, out = _skip_golden(gold), gold / "cli_cand"
    run = _cli("candidate", g, "--backend", "wgpu", "--out", out, "--scene", "render_cube",
               "--scene", SKIPPED)
    assert run.returncode == 0, run.stderr
    assert "wgpu backend (llvmpipe" in run.stdout or not IN_CI
    assert f"skipped {SKIPPED}: ldi mode 'all': only classic peeling ('peel') is " \
           "implemented" in run.stdout, run.stdout
    assert "--scene render_cube" in run.stdout
    assert sorted(p.name for p in out.iterdir()) == [".refraster-candidate", "render_cube"]
    marker = json.loads((out / ".refraster-candidate").read_text())
    assert marker["backend"] == "wgpu" and marker["rendered"] == ["render_cube"]
    assert list(marker["skipped"]) == [SKIPPED]
    assert all(isinstance(r, str) and r.strip() for r in marker["skipped"].values())
    assert "not implemented by the wgpu backend" not in marker["skipped"][SKIPPED]
    cmp = _cli("compare", g, out, "--scene", "render_cube")
    assert cmp.returncode == 0, cmp.stderr
    bad = _cli("candidate", g, "--backend", "vulkan", "--out", gold / "x")
    assert bad.returncode == 2 and "wgpu" in bad.stderr


def test_wgpu_frames_are_bit_identical_across_runs(gold):
    with backend_or_skip() as gpu:
        pkg = gold / "golden" / "render_crank" / "package"
        a, b = gpu.render(pkg), gpu.render(pkg)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_bad_convention_values_are_refused(gold, tmp_path):
    from refraster.gl.package import PackageError
    src = gold / "golden" / "render_cube" / "package"
    pkg = tmp_path / "pkg"
    shutil.copytree(src, pkg)
    doc = json.loads((pkg / "scene.json").read_text())
    with backend_or_skip() as gpu:
        for key, value in (("depth_range", "minus_one_to_one"), ("ndc_y", "sideways"),
                           ("depth_clamp", "yes"), ("front_face", "left")):
            bad = json.loads(json.dumps(doc))
            bad["raster"][key] = value
            (pkg / "scene.json").write_text(json.dumps(bad))
            with pytest.raises(PackageError, match=f"raster.{key} must be (one of|true or false)"):
                gpu.render(pkg)
