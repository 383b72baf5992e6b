"""refraster.wgpu on the convention goldens of issue 39 (issue 40, left item 1): WebGPU's own frame
(clip at 0 ≤ z ≤ w, window depth z/w, NDC y up onto an upper-left framebuffer, front faces as the
picture is seen) against the project's twelve convention scenes — Vulkan's y-down NDC (a
negation of the clip y in the vertex shader: WebGPU's NDC y points up), reversed-Z with an
infinite far plane, a peel under reversed-Z, z = 0 and eye-plane crossings with and without depth
clamp, Direct3D's exact ties, ``depth24plus`` and ``depth16unorm``. Every scene passes the
tolerant compare on lavapipe; each planted convention
fault fails the scenes it can change, naming the buffer, and passes the others. The matrix is
the one in docs/backends.md ("refraster.wgpu in the API conventions").

Also: depth clamp refused with one line on a device without ``depth-clip-control``; the unorm
formats write the depth buffer (quantised) as the candidate's depth; peeling under ``lequal`` and
``gequal`` against ``refraster.ldi.peel`` on coincident faces (where they differ from ``less`` /
``greater``).

Needs wgpu-py and a WebGPU adapter (Mesa's lavapipe): skips without them, fails under CI=true.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import check_backends_matrix, fault_matrix, generate_gold, matrix_table
from test_wgpu_backend import backend_or_skip

BEGIN = "<!-- wgpu-conventions-matrix:begin (tests/test_wgpu_conventions.py) -->"
END = "<!-- wgpu-conventions-matrix:end -->"

#: The project's convention goldens (refraster/golden/convention_scenes.py).
SCENES = ["vulkan_cube", "vulkan_icosphere_smooth", "vulkan_torus_ortho",
          "vulkan_nested_shells", "vulkan_multi_draw", "reversed_z_multi_draw",
          "reversed_z_peel", "zero_to_one_near_crossing", "depth_clamp_near_crossing",
          "d3d12_exact_ties", "unorm24_torus_ortho", "unorm16_planes"]

_VULKAN = [s for s in SCENES if s.startswith("vulkan_")]
_ZERO_TO_ONE = [s for s in SCENES if s != "unorm24_torus_ortho"]
_REVERSED = ["reversed_z_multi_draw", "reversed_z_peel"]


def _ids(scene):
    return "layer_prim_id" if scene == "reversed_z_peel" else "prim_id"


#: fault → {scene: buffer the failure must name}
EXPECTED = {
    "gl_remap_on_zero_to_one": {s: ("layer_depth" if s == "reversed_z_peel" else "depth")
                                for s in _ZERO_TO_ONE},
    "y_not_flipped": {s: _ids(s) for s in SCENES},
    "reversed_z_less": {s: _ids(s) for s in _REVERSED},
    "clear_one_under_greater": {s: _ids(s) for s in _REVERSED},
    # with back-face culling the visible faces go (ids fail; facing may stay within the band)
    "winding_not_flipped": {**{s: "front_facing" for s in _VULKAN
                               if s not in ("vulkan_nested_shells", "vulkan_icosphere_smooth")},
                            "vulkan_nested_shells": "prim_id",
                            "vulkan_icosphere_smooth": "prim_id",
                            "reversed_z_peel": "layer_front_facing"},
    "unclipped_depth_dropped": {"depth_clamp_near_crossing": "prim_id"},
}
#: scenes a fault cannot change (they must pass)
UNTOUCHED = {
    "gl_remap_on_zero_to_one": ["unorm24_torus_ortho"],
    "y_not_flipped": [],
    "reversed_z_less": [s for s in SCENES if s not in _REVERSED],
    "clear_one_under_greater": [s for s in SCENES if s not in _REVERSED],
    "winding_not_flipped": [s for s in SCENES if s not in _VULKAN + ["reversed_z_peel"]],
    "unclipped_depth_dropped": [s for s in SCENES if s != "depth_clamp_near_crossing"],
}
COLUMNS = ["correct", *EXPECTED]


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "wgpuconv", SCENES)


def test_convention_goldens_pass_and_every_convention_fault_fails(gold):
    """Every convention scene passes on refraster.wgpu; each planted convention fault fails the
    scenes it can change, naming the buffer, and passes the others (docs/backends.md)."""
    from refraster.wgpu import CONVENTION_FAULTS, FAULTS
    backend_or_skip().release()
    assert set(CONVENTION_FAULTS) - {"depth_not_quantised"} <= set(EXPECTED) <= set(FAULTS)
    assert set(EXPECTED) == set(UNTOUCHED)
    results = fault_matrix(gold, COLUMNS, SCENES, EXPECTED, UNTOUCHED, backend="wgpu")
    table = matrix_table(COLUMNS, SCENES, results)
    check_backends_matrix(BEGIN, END, table, "wgpu conventions matrix")


def _scene(gold, name):
    from refraster.gl.package import read_scene
    return read_scene(gold / "golden" / name / "package")


def test_depth_clamp_is_refused_without_depth_clip_control(gold):
    """WebGPU expresses depth clamp only through the optional feature ``depth-clip-control``
    (``unclippedDepth``): a device created without it refuses the clamp scenes with one line and
    renders the others; the default device (lavapipe offers the feature) renders them."""
    from refraster.wgpu.driver import Unsupported
    with backend_or_skip(features=[]) as gpu:
        for name in SCENES:
            clamp = _scene(gold, name)["raster"].get("depth_clamp", False)
            reason = gpu.supports(_scene(gold, name))
            if clamp:
                assert reason is not None and "depth-clip-control" in reason, name
                assert "\n" not in reason
            else:
                assert reason is None, (name, reason)
        with pytest.raises(Unsupported, match="raster.depth_clamp needs WebGPU's optional "
                                              "feature depth-clip-control"):
            gpu.render(gold / "golden" / "depth_clamp_near_crossing" / "package")
    with backend_or_skip() as gpu:
        if "depth-clip-control" not in gpu.adapter.features:
            pytest.skip("the adapter does not offer depth-clip-control")
        assert gpu.supports(_scene(gold, "depth_clamp_near_crossing")) is None


def test_unorm_formats_write_the_depth_buffer(gold):
    """Under ``unorm16`` (``depth16unorm``) the candidate's depth is the depth buffer: multiples
    of 1/(2^16 − 1) within float32's rounding, and within a quantum of the golden's depth; the
    planted ``depth_not_quantised`` (the float32 fragment depth written instead) is not on that
    grid. Under ``unorm24`` (``depth24plus``, "at least 24 bits": WebGPU may back it with
    float32, and float32 has no room to show a 24-bit grid) the written depth is the depth
    buffer's value, within a quantum of the golden's."""
    for faults, on_grid in (((), True), (("depth_not_quantised",), False)):
        with backend_or_skip(faults=faults) as gpu:
            got = {name: gpu.render(gold / "golden" / name / "package")
                   for name in ("unorm16_planes", "unorm24_torus_ortho")}
        for name, bits in (("unorm16_planes", 16), ("unorm24_torus_ortho", 24)):
            out = got[name]
            ref = np.load(gold / "golden" / name / "buffers.npz")
            both = (out["prim_id"] >= 0) & (out["prim_id"] == ref["prim_id"])
            assert both.sum() > 1000
            q = float(2 ** bits - 1)
            dz = np.abs(out["depth"][both].astype(np.float64) - ref["depth"][both])
            assert dz.max() <= 1.0 / q + 2e-5, (name, faults, dz.max())
            if bits == 16:
                k = out["depth"][both].astype(np.float64) * q
                off = np.abs(k - np.rint(k)).max()
                assert (off < 0.01) == on_grid, (faults, off)


# --- peeling under lequal / gequal ------------------------------------------------------------

def _peel_package(tmp_path, depth_func):
    """An ldi package of the nested shells drawn twice (every face twice, the copy after the
    original: coincident fragments with equal depths) under ``depth_func``; ``gequal`` in
    reversed-Z (zero-to-one, infinite far plane, clear 0, WebGPU's window conventions).
    Returns ``(package dir, refraster's LDI of the same scene)``."""
    import math

    from refraster.camera import Camera, frame_bounds, near_far, perspective
    from refraster.golden.io.package import export_package
    from refraster.golden.scenes import DEFAULT_RASTER, Draw, GoldenScene, prepare_draws
    from refraster.ldi import peel
    from refraster.raster.state import RasterState
    from refraster.scenes import solid
    shells = solid("nested_shells", quick=True)
    v = np.asarray(shells.vertices, np.float64)
    f = np.asarray(shells.faces, np.int64)
    draws = prepare_draws([Draw("twice", (v, np.concatenate([f, f])))])
    mesh = draws[0].mesh
    w, h = 128, 96
    framed = frame_bounds(np.stack([mesh.vertices.min(0), mesh.vertices.max(0)]), width=w,
                          height=h, direction=(1.2, 0.9, 1.6))
    raster = {**DEFAULT_RASTER, "depth_func": depth_func}
    conv = {}
    if depth_func in ("greater", "gequal"):
        near, _ = near_far(framed.proj)
        proj = perspective(35.0, w / h, near, math.inf, reversed=True,
                           depth_range="zero_to_one")
        raster["clear_depth"] = 0.0
        conv = dict(depth_range="zero_to_one", origin="upper_left")
    else:
        proj = framed.proj
    state = RasterState(depth_func=depth_func, clear_depth=raster["clear_depth"], **conv)
    ours = peel([d.mesh for d in draws], view=framed.view, proj=proj, width=w, height=h,
                model=[d.model for d in draws], raster=state, mode="peel", max_layers=None)
    pkg = tmp_path / f"pkg_{depth_func}"
    with np.errstate(divide="ignore"):
        export_package(pkg, f"peel_{depth_func}",
                       GoldenScene(technique="ldi", camera=Camera(framed.view, proj, w, h),
                                   draws=draws, buffers={},
                                   parameters={"mode": "peel", "max_layers": None}), raster)
    path = pkg / "scene.json"
    doc = json.loads(path.read_text())
    doc["raster"].update(conv)
    path.write_text(json.dumps(doc))
    return pkg, ours, len(f)


@pytest.mark.parametrize("depth_func, strict", [("lequal", "less"), ("gequal", "greater")])
def test_peel_under_lequal_and_gequal_agrees_with_refraster(tmp_path, depth_func, strict):
    """Classic peeling under ``lequal`` / ``gequal``: of coincident fragments the last drawn
    wins (the depth test lets it), as in ``refraster.ldi.peel`` — every face is drawn twice, so
    the copy's id (≥ F) fills the layers, where ``less`` / ``greater`` keep the original's
    (< F). Layer by layer, the ids agree with refraster's on ≥ 99.9 % of the pixels either
    covers and the counts on ≥ 99.9 %; the same package declared ``less`` / ``greater`` gives
    the originals' ids."""
    pkg, ours, n = _peel_package(tmp_path, depth_func)
    with backend_or_skip() as gpu:
        assert gpu.supports(json.loads((pkg / "scene.json").read_text())) is None
        out = gpu.render(pkg)
        doc = json.loads((pkg / "scene.json").read_text())
        doc["raster"]["depth_func"] = strict
        (pkg / "scene.json").write_text(json.dumps(doc))
        first = gpu.render(pkg)
    k = len(ours.depth)
    assert k >= 4 and out["layer_prim_id"].shape[-1] >= k - 1
    for j in range(min(k, out["layer_prim_id"].shape[-1])):
        a, b = ours.prim_id[j], out["layer_prim_id"][..., j]
        either = (a >= 0) | (b >= 0)
        assert np.mean((a == b)[either]) >= 0.999, (j, np.mean((a == b)[either]))
        same = (a == b) & (a >= 0)
        assert np.abs(ours.depth[j][same] - out["layer_depth"][..., j][same]).max() < 2e-5, j
    assert np.mean(ours.count == out["layer_count"]) >= 0.999
    covered = out["layer_prim_id"] >= 0
    assert np.mean(out["layer_prim_id"][covered] >= n) > 0.99        # the copies win
    assert np.mean(first["layer_prim_id"][first["layer_prim_id"] >= 0] < n) > 0.99


def test_peel_refuses_a_unorm_depth_format(gold, tmp_path):
    from refraster.wgpu.driver import Backend
    scene = _scene(gold, "reversed_z_peel")
    scene["raster"]["depth_format"] = "unorm16"
    with backend_or_skip() as gpu:
        reason = Backend.supports(gpu, scene)
    assert reason is not None and "raster.depth_format 'unorm16'" in reason
    assert "\n" not in reason
