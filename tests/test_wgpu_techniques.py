"""refraster.wgpu on the technique scenes of issue 45 (edge maps with NPR compositing; 2.5D
clip surfaces with the parity test and caps; adaptive cutaways; 4D halos): ``golden candidate
--backend wgpu`` renders every edges, clipsurface, cutaway and halos4d scene and each passes
the tolerant compare on lavapipe; each planted fault of a technique
(``refraster.wgpu.TECHNIQUE_FAULTS``, an override constant of the technique's WGSL or a host
switch) fails it on the scenes whose passes contain the faulty code,
naming the buffer, and passes the scenes whose passes do not. The pass/fail matrix is the one
in docs/backends.md ("refraster.wgpu: technique scenes").

Needs wgpu-py and a WebGPU adapter (Mesa's lavapipe): skips without them, fails under CI=true
(the project's optional-oracle rule).
"""

import json

import numpy as np
import pytest

from conftest import IN_CI, check_backends_matrix, generate_gold, matrix_cell
from test_wgpu_backend import backend_or_skip

BEGIN = "<!-- wgpu-techniques-matrix:begin (tests/test_wgpu_techniques.py) -->"
END = "<!-- wgpu-techniques-matrix:end -->"

EDGES = ["edges_building", "edges_sobel", "edges_c1", "edges_diagonal2", "edges_c1_paper",
         "edges_npr_gooch"]
CLIPS = ["clipsurface_building", "clipsurface_textured_caps", "clipsurface_two_surfaces",
         "clipsurface_relief_plane"]
CUTS = ["cutaway_shells", "cutaway_shells_jfa", "cutaway_shells_jfa2", "cutaway_shells_1jfa",
        "cutaway_floor", "cutaway_floor_jfa"]
FLOORS = ["cutaway_floor", "cutaway_floor_jfa"]
HALOS = ["halos4d_figure1", "halos4d_perspective"]
SCENES = EDGES + CLIPS + CUTS + HALOS

#: fault → the scenes it is run on (its technique's)
RUN = {"sobel_transposed": EDGES, "one_diagonal": EDGES,
       "offset_wrong_address_mode": CLIPS, "parity_far_end": CLIPS,
       "jfa_halved_once_more": CUTS, "ghost_not_depth_tested": CUTS, "ndc_y_from_row": CUTS,
       "plane_half_slab": HALOS, "halo_depth_max": HALOS}
#: fault → {scene: buffer that must be named among the failing ones}
EXPECTED = {
    # Sobel operators: edges_sobel (normal and depth), edges_c1_paper (normal)
    "sobel_transposed": {"edges_sobel": "edge_map", "edges_c1_paper": "edge_map"},
    # diagonal operators: edges_building, edges_npr_gooch (both), edges_diagonal2 (normal)
    "one_diagonal": {"edges_building": "edge_map", "edges_diagonal2": "edge_map",
                     "edges_npr_gooch": "npr_color"},
    # every scene's clip test reads an offset map outside [0, 1] or across its border
    "offset_wrong_address_mode": {s: "object_id" for s in CLIPS},
    # every scene's caps are seen where the sprite has layers behind the cap: caps appear and
    # vanish, so the ids name it (cap_mask's own check allows the pixels the ids fail)
    "parity_far_end": {s: "object_id" for s in CLIPS},
    # jumps n/2, n/8, …: the flood misses the best seed wherever the schedule's own does not
    "jfa_halved_once_more": {s: "cutaway_depth" for s in CUTS},
    # line pieces behind the removed layer (z ≥ D) counted where nothing of interest is seen
    "ghost_not_depth_tested": {s: "ghost" for s in CUTS},
    # the cut normals unprojected upside down (every scene's cut surfaces' colour); with the
    # floor constraint, D itself
    "ndc_y_from_row": {s: ("cutaway_depth" if s in FLOORS else "color") for s in CUTS},
    # every plane on a slab boundary: other voxels, classes and opacities
    "plane_half_slab": {s: "halo_class" for s in HALOS},
    # the halo depth's maximum: surface voxels in front of a halo counted as carved
    "halo_depth_max": {s: "halo_class" for s in HALOS},
}
#: scenes of a fault's technique whose passes do not contain the faulty code (they must pass)
UNTOUCHED = {
    "sobel_transposed": ["edges_building", "edges_c1", "edges_diagonal2", "edges_npr_gooch"],
    "one_diagonal": ["edges_sobel", "edges_c1", "edges_c1_paper"],
    "offset_wrong_address_mode": [],
    "parity_far_end": [],
    "jfa_halved_once_more": [],
    "ghost_not_depth_tested": [],
    "ndc_y_from_row": [],
    "plane_half_slab": [],
    "halo_depth_max": [],
}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "wgputech", SCENES)


def run_matrix(gold, columns):
    """Every scene rendered by the correct backend and each fault on its technique's scenes
    through ``golden candidate``, compared tolerantly → ``{column: {scene: SceneResult}}``."""
    from refraster import golden
    from refraster.golden.candidate import candidate
    results = {}
    for column in columns:
        faults = () if column == "correct" else (column,)
        scenes = SCENES if column == "correct" else RUN[column]
        out = gold / f"cand_{column}"
        r = candidate(gold / "golden", out, backend="wgpu", scenes=scenes, faults=faults)
        assert sorted(r["rendered"]) == sorted(scenes) and not r["skipped"], r["skipped"]
        marker = json.loads((out / ".refraster-candidate").read_text())
        assert marker["faults"] == list(faults) and marker["backend"] == "wgpu"
        assert marker["renderer"].startswith("llvmpipe") or not IN_CI
        cmp = golden.compare(gold / "golden", out, mode="tolerant", scenes=scenes)
        assert all(s.status in ("pass", "fail") for s in cmp.scenes), cmp.summary()
        results[column] = {s.name: s for s in cmp.scenes}
        if column == "correct":
            assert cmp.exit_code == 0, "\n".join(cmp.failures())
            continue
        assert cmp.exit_code == 1, f"fault {column} passed every scene"
        for scene, buffer in EXPECTED[column].items():
            assert [line for line in cmp.failures() if line.startswith(f"{scene}/{buffer}")], \
                f"fault {column}: {scene}/{buffer} not named ({cmp.failures()})"
        for scene in UNTOUCHED[column]:
            assert results[column][scene].status == "pass", (column, scene)
    return results


def matrix(columns, results):
    """The Markdown matrix; a fault's cell on another technique's scene is "—" (not run: the
    fault's code is in no pass of that technique)."""
    head = ["scene"] + [c if c == "correct" else f"`{c}`" for c in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene in SCENES:
        cells = [matrix_cell(results[c][scene], all_count=False) if scene in results[c]
                 else "—" for c in columns]
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def test_technique_scenes_pass_and_every_planted_fault_fails(gold):
    from refraster.wgpu import FAULTS, TECHNIQUE_FAULTS
    backend_or_skip().release()
    assert set(EXPECTED) == set(UNTOUCHED) == set(RUN) == set(TECHNIQUE_FAULTS)
    assert not set(TECHNIQUE_FAULTS) & set(FAULTS)
    columns = ["correct", *TECHNIQUE_FAULTS]
    results = run_matrix(gold, columns)
    check_backends_matrix(BEGIN, END, matrix(columns, results), "wgpu technique matrix")


def test_techniques_ask_for_no_optional_feature_and_ids_are_exact(gold):
    """The techniques run on a device given no optional feature at all (float32 maps are
    filtered in WGSL, nothing is blended: the ghost lines' maximum and the halo depth's minimum
    are kept by a depth test, the halos composited through ping-pong textures);
    the clip scenes' ids and cap mask equal the
    golden's pixel for pixel, and two runs give the same bytes."""
    with backend_or_skip(features=[]) as gpu:
        assert list(gpu.device.features) == []
        for scene in ("edges_npr_gooch", "clipsurface_two_surfaces", "cutaway_floor",
                      "halos4d_figure1"):
            pkg = gold / "golden" / scene / "package"
            a, b = gpu.render(pkg), gpu.render(pkg)
            for key in a:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{scene}/{key}")
            if scene.startswith("clip"):
                with np.load(gold / "golden" / scene / "buffers.npz") as z:
                    for key in ("object_id", "front_facing", "cap_mask"):
                        np.testing.assert_array_equal(a[key], z[key], err_msg=f"{scene}/{key}")
                assert a["cap_mask"].sum() > 500


def test_address_modes_match_a_numpy_bilinear_filter():
    """clip.wgsl's address function against NumPy's np.pad modes (wrap, edge, symmetric =
    WebGPU's repeat, clamp-to-edge, mirror-repeat), both directions: the planted fault's mode
    differs from the surface's."""
    from refraster.wgpu.clipsurface import ADDRESS_MODES
    pad = {0: "wrap", 1: "edge", 2: "symmetric"}
    n, idx = 5, np.arange(-12, 13)

    def address(i, mode):                       # clip.wgsl's address(), transcribed
        if mode == 1:
            return np.clip(i, 0, n - 1)
        if mode == 0:
            return ((i % n) + n) % n
        p = ((i % (2 * n)) + 2 * n) % (2 * n)
        return np.where(p >= n, 2 * n - 1 - p, p)

    base = np.arange(n)
    for mode in set(ADDRESS_MODES.values()):
        padded = np.pad(base, 12, mode=pad[mode])
        np.testing.assert_array_equal(address(idx, mode), padded[idx + 12], err_msg=pad[mode])
        wrong = 0 if mode == 1 else 1             # WRONG_ADDRESS_MODE
        assert not np.array_equal(address(idx, wrong), padded[idx + 12])
    src = (__import__("pathlib").Path(__file__).parents[1] / "refraster" / "wgpu" / "shaders"
           / "clip.wgsl").read_text()
    assert "return ((i % n) + n) % n;" in src and "select(p, 2 * n - 1 - p, p >= n)" in src


def test_bad_parameters_are_one_clear_error_and_unsupported_options_a_reason(gold):
    """A malformed edges parameter is one PackageError naming the key; a clip-surface option
    the backend does not draw makes ``supports`` give the reason (candidate skips with it). No
    device needed."""
    from refraster.gl.package import PackageError
    from refraster.wgpu import clipsurface, edges
    doc = json.loads((gold / "golden" / "edges_npr_gooch" / "package" / "scene.json")
                     .read_text())
    good = doc["parameters"]
    assert edges.options(good)["gbuffer_format"] == "rgba8" and "npr" in edges.options(good)
    for edit, words in (({"depth_filter": "roberts"}, "depth_filter"), ({"width": 0}, "width"),
                        ({"inner_threshold": 2}, "inner_threshold"),
                        ({"output_format": "rgb565"}, "output_format"),
                        ({"ids": "yes"}, "ids"), ({"npr": {**good["npr"], "style": "toon"}},
                                                  "npr.style"),
                        ({"npr": {**good["npr"], "alpha": 3}}, "npr.alpha")):
        with pytest.raises(PackageError, match=words):
            edges.options({**good, **edit})
        assert words in edges.supports({"parameters": {**good, **edit}})
    with pytest.raises(PackageError, match="parameters.bounds"):
        edges.near_far({**doc, "parameters": {**good, "bounds": [[0, 0], [1, 1]]}})
    clip = json.loads((gold / "golden" / "clipsurface_building" / "package" / "scene.json")
                      .read_text())
    assert clipsurface.supports(clip) is None
    for edit, words in (({"cap_mode": "exact"}, "cap_mode"), ({"space": "object"}, "world"),
                        ({"surfaces": []}, "1 to 2 surfaces")):
        assert words in clipsurface.supports({"parameters": {**clip["parameters"], **edit}})
    assert "depth_format" in clipsurface.supports({**clip, "raster": {**clip["raster"],
                                                                      "depth_format": "unorm16"}})


#: convention → the technique scenes drawn in its twin (test_wgpu_backend.twin_golden's maps)
TWINS = {"vulkan": ["edges_npr_gooch", "clipsurface_two_surfaces"],
         "reversed_z": ["edges_sobel", "clipsurface_building"]}


def test_techniques_pass_in_the_vulkan_and_reversed_z_twins(gold):
    """The technique passes follow the scene's declared convention: the same scenes with the
    projection re-expressed in Vulkan's (NDC y down, [0, 1]) and reversed-Z's (greater, clear
    0) conventions and scene.json's raster saying so pass the golden's allowances (reversed-Z
    depth mapped back, as tests/test_wgpu_backend.py does for the G-buffer)."""
    from refraster import golden
    from refraster.golden.candidate import candidate
    from test_wgpu_backend import twin_golden, unreverse
    backend_or_skip().release()
    for convention, scenes in TWINS.items():
        where = twin_golden(gold, convention, scenes)
        out = gold / f"cand_twin_{convention}"
        r = candidate(where, out, backend="wgpu", scenes=scenes)
        assert sorted(r["rendered"]) == sorted(scenes), r["skipped"]
        if convention == "reversed_z":
            unreverse(out, scenes)
        cmp = golden.compare(where, out, mode="tolerant", scenes=scenes)
        assert cmp.exit_code == 0, "\n".join(cmp.failures())


def test_edge_width_is_the_disk_dilation_of_the_width_one_map(gold, tmp_path):
    """No golden scene sets ``width > 1``: the dilation pass against scipy's grey dilation
    (footprint the disk dx² + dy² ≤ r², r = width − 1, outside the image not part of the
    neighbourhood) of the same backend's width-1 map, exactly (float32 edge map)."""
    import shutil

    from scipy import ndimage
    src = gold / "golden" / "edges_sobel" / "package"
    pkg = tmp_path / "pkg"
    shutil.copytree(src, pkg)
    doc = json.loads((pkg / "scene.json").read_text())
    doc["parameters"]["width"] = 3
    (pkg / "scene.json").write_text(json.dumps(doc))
    with backend_or_skip() as gpu:
        one = gpu.render(src)["edge_map"]
        three = gpu.render(pkg)["edge_map"]
    yy, xx = np.mgrid[-2:3, -2:3]
    disk = xx * xx + yy * yy <= 4
    want = np.stack([ndimage.grey_dilation(one[..., c], footprint=disk, mode="constant",
                                           cval=0.0) for c in range(4)], -1)
    assert np.abs(three - one).max() > 0.1               # the pass changes something
    np.testing.assert_array_equal(three, want)


def test_id_edges_and_thresholds_agree_with_refraster(gold, tmp_path):
    """No golden scene sets id edges or thresholds (every edges scene is the paper's raw
    preset): the ``clean`` preset (second-order diagonal depth, id edges, thresholds 0.1 and
    0.03) of refraster.wgpu against refraster.edges.edge_map on the reference framebuffer of the
    same building, away from the pixels whose visible face may differ and from reference values
    within 2e-3 of a threshold (float32 against float64). Seen failing with the id edges off
    and with the profile threshold read as the inner one; the inner threshold itself is not
    exercised (away from those pixels the building's flat faces give E_N = 0 or E_N > 0.1)."""
    import shutil

    from scipy import ndimage

    from refraster.edges import edge_map
    from refraster.golden.technique_scenes import _building_edges
    src = gold / "golden" / "edges_diagonal2" / "package"
    pkg = tmp_path / "clean"
    shutil.copytree(src, pkg)
    doc = json.loads((pkg / "scene.json").read_text())
    p = doc["parameters"]
    for key in ("normal_filter", "depth_filter", "ids", "inner_threshold", "profile_threshold"):
        p.pop(key)
    p["preset"] = "clean"
    (pkg / "scene.json").write_text(json.dumps(doc))
    with backend_or_skip() as gpu:
        got = gpu.render(pkg)["edge_map"]
    _, _, fb, params, _ = _building_edges("diagonal", "diagonal2")
    ref = edge_map(fb, preset="clean", bounds=np.array(params["bounds"]))
    with np.load(gold / "golden" / "edges_diagonal2" / "tolerance.npz") as z:
        may = z["may"]
    keep = ~ndimage.binary_dilation(may, iterations=1)
    for c, t in ((0, 0.1), (3, 0.03)):
        keep &= np.abs(ref[..., c] - t) > 2e-3
    assert keep.sum() > 0.5 * keep.size
    assert (ref[..., 3][keep] == 1.0).sum() > 40           # the id edges are seen
    np.testing.assert_allclose(got[..., 0][keep], ref[..., 0][keep], atol=2e-3)
    np.testing.assert_allclose(got[..., 3][keep], ref[..., 3][keep], atol=2e-3)


def test_cutaway_options_the_backends_do_not_draw_are_a_reason(gold):
    """A cutaway option neither GPU backend draws, or a package in another NDC than OpenGL's
    (the cutaway function is stated in it), makes ``supports`` give the reason, the same for
    refraster.wgpu and the shared reader of refraster.gl.package; a malformed one names the
    parameter. No device needed."""
    from refraster.gl.package import cutaway_supports
    from refraster.wgpu import cutaway
    doc = json.loads((gold / "golden" / "cutaway_floor" / "package" / "scene.json").read_text())
    assert cutaway.supports(doc) is None
    p = doc["parameters"]
    for edit, words in (({"variant": "exact"}, "only the jump-flooding schedules"),
                        ({"cutaway_size": [48, 36]}, "'cutaway_size' is not implemented"),
                        ({"ghost": "visible"}, "ghost 'visible'"),
                        ({"angle": 2.0}, "parameters.angle"),
                        ({"floor_normal": [0, 0, 0]}, "parameters.floor_normal"),
                        ({"interest": ["nope"]}, "parameters.interest")):
        scene = {**doc, "parameters": {**p, **edit}}
        assert words in cutaway.supports(scene), edit
        assert cutaway_supports(scene) == cutaway.supports(scene)
    for raster, words in (({"depth_range": "zero_to_one"}, "OpenGL's NDC"),
                          ({"ndc_y": "down"}, "OpenGL's NDC"),
                          ({"depth_format": "unorm16"}, "depth_format")):
        assert words in cutaway.supports({**doc, "raster": {**doc["raster"], **raster}})


def test_the_planted_jfa_schedule_halves_once_too_often():
    """The planted schedule halves from pass to pass once too often (n/2, n/8, …) and keeps the
    variant's extra passes; the correct one is the package's. No device needed."""
    from refraster.gl.package import cutaway_step_schedule
    from refraster.wgpu.cutaway import schedule
    bad = ("jfa_halved_once_more",)
    for v in ("jfa", "jfa+1", "jfa+2", "1+jfa"):
        assert schedule(72, 96, v) == cutaway_step_schedule(72, 96, v)
    assert schedule(72, 96, "jfa", bad) == [64, 16, 4, 1]
    assert schedule(72, 96, "jfa+2", bad) == [64, 16, 4, 1, 2, 1]
    assert schedule(72, 96, "1+jfa", bad) == [1, 64, 16, 4, 1]


def test_halo_options_the_backends_do_not_draw_are_a_reason(gold):
    """A halos4d option neither GPU backend draws makes ``supports`` give the reason and a
    malformed one names the parameter, the same for refraster.wgpu and refraster.gl (one reader,
    refraster.gl.package.halos_supports). No device needed."""
    from refraster.gl import halos as gl_halos
    from refraster.wgpu import halos
    doc = json.loads((gold / "golden" / "halos4d_figure1" / "package" / "scene.json")
                     .read_text())
    assert halos.supports(doc) is None
    for edit, words in (({"stereo": 6.0}, "'stereo' is not implemented by the GPU backends"),
                        ({"boundary_color": [0, 1, 0]}, "'boundary_color' is not implemented"),
                        ({"slices": 0}, "parameters.slices"),
                        ({"split": "dompierre"}, "parameters.split"),
                        ({"rotation": [[2, 0, 0, 0]] * 4}, "parameters.rotation")):
        scene = {**doc, "parameters": {**doc["parameters"], **edit}}
        assert words in halos.supports(scene), edit
        assert gl_halos.supports(scene) == halos.supports(scene)
