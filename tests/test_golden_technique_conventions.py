"""Technique goldens in other APIs' conventions (issue 39 item 4): ``golden generate
--convention`` renders a clip-surface or cutaway scene again through its technique with the
converted camera and raster state, and the technique allowances follow the conventions (derived
on the equivalent OpenGL scene and moved back: window depth ``d → 1 − d`` under reversed-Z,
facings under clockwise fronts). Both directions: the golden passes against itself and against
refraster's own render in those conventions at 4 sub-pixel bits and the top-left rule; planted
faults fail naming the buffer."""

from __future__ import annotations

import numpy as np
import pytest

from refraster import golden
from refraster.golden.compare.run import compare
from refraster.golden.conventions import in_convention
from refraster.golden.scenes import raster_state
from refraster.golden.technique_scenes import IN_RASTER

SCENES = ["clipsurface_relief_plane", "cutaway_shells"]
#: golden → (API, reversed-Z)
GOLDENS = {"vulkan_reversed": ("vulkan", True), "d3d12": ("d3d12", False)}


def _built(name, api, reversed_z):
    return in_convention(golden.available_scenes()[name], api, reversed=reversed_z).build()


@pytest.fixture(scope="module")
def golds(tmp_path_factory):
    out = {}
    for key, (api, rev) in GOLDENS.items():
        d = tmp_path_factory.mktemp("techconv") / key
        golden.generate(d, [in_convention(golden.available_scenes()[n], api, reversed=rev)
                            for n in SCENES], candidate_subpixel_bits=4)
        out[key] = d
    return out


def _write(tmp_path, name, buffers):
    (tmp_path / name).mkdir(parents=True, exist_ok=True)
    np.savez(tmp_path / name / "buffers.npz", **buffers)
    return tmp_path


def _stored(gold, name):
    with np.load(gold / name / "buffers.npz") as z:
        return {k: z[k] for k in z.files}


def _rerendered(scene, **changes):
    """refraster's own render of the built ``scene`` with its raster fields changed."""
    raster = {**raster_state(scene.raster), **changes}
    return IN_RASTER[scene.technique](scene, scene.camera, raster).buffers


def test_converted_scenes_keep_the_technique():
    for name in SCENES:
        gl = golden.available_scenes()[name].build()
        s = _built(name, "vulkan", True)
        assert s.technique == gl.technique and s.raster["ndc_y"] == "down"
        assert s.raster["depth_func"] == "greater" and s.raster["clear_depth"] == 0.0
        # the caps (clip) and the object of interest (cutaway) are there: not a plain render
        assert set(np.unique(s.buffers["object_id"])) == set(np.unique(gl.buffers["object_id"]))
        assert s.description.endswith("In vulkan's conventions, reversed-Z.")
        # the picture is OpenGL's mirrored top to bottom (the projection is left alone)
        flip = np.flipud(gl.buffers["object_id"])
        assert (s.buffers["object_id"] == flip).mean() > 0.99
        mask = "cap_mask" if name.startswith("clip") else "cut_mask"
        assert (s.buffers[mask] == np.flipud(gl.buffers[mask])).mean() > 0.99
        # reversed-Z: the window depth is 1 − OpenGL's
        cov = (s.buffers["prim_id"] >= 0) & (flip >= 0)
        d = 1.0 - np.flipud(gl.buffers["depth"])[cov]
        assert np.median(np.abs(s.buffers["depth"][cov] - d)) < 1e-5


def test_gl_rerun_is_the_registered_scene():
    """Running a technique scene again in its own (OpenGL) conventions gives its bytes."""
    for name in SCENES:
        s = golden.available_scenes()[name].build()
        again = IN_RASTER[s.technique](s, s.camera, raster_state(s.raster))
        for key in s.buffers:
            assert np.array_equal(s.buffers[key], again.buffers[key], equal_nan=True), key
        assert np.array_equal(s.may, again.may)


@pytest.mark.parametrize("key", sorted(GOLDENS))
def test_golden_passes_against_itself(golds, tmp_path, key):
    for name in SCENES:
        _write(tmp_path, name, _stored(golds[key], name))
    result = compare(golds[key], tmp_path, mode="tolerant", scenes=SCENES)
    assert result.exit_code == 0, "\n".join(result.failures()[:20])


@pytest.mark.parametrize("key", sorted(GOLDENS))
def test_refraster_in_the_conventions_passes(golds, tmp_path, key):
    api, rev = GOLDENS[key]
    for name in SCENES:
        _write(tmp_path, name, _rerendered(_built(name, api, rev), subpixel_bits=4,
                                           fill_rule="top_left"))
    result = compare(golds[key], tmp_path, mode="tolerant", scenes=SCENES)
    assert result.exit_code == 0, "\n".join(result.failures()[:20])


def _fault(fault, name):
    """A wrong candidate for ``name`` of the vulkan_reversed golden."""
    s = _built(name, "vulkan", True)
    right = dict(s.buffers)
    if fault == "gl_depth_direction":
        # the same frame with OpenGL's depth direction left in (the vulkan golden unreversed)
        wrong = _built(name, "vulkan", False).buffers
        return {**right, **{k: wrong[k] for k in ("depth", "cutaway_depth") if k in right}}
    if fault == "gl_conventions":
        # the technique rendered in OpenGL's conventions: not mirrored, GL's depth range
        return dict(golden.available_scenes()[name].build().buffers)
    if fault == "caps_facing_by_front_face_only":
        # the caps' facing turned by the front face alone (the picture's handedness ignored)
        right["front_facing"] = right["front_facing"] ^ right["cap_mask"]
        return right
    raise AssertionError(fault)


#: (fault, scene) → the buffers whose check must fail
FAULTS = {("gl_depth_direction", "clipsurface_relief_plane"): ("depth",),
          ("gl_depth_direction", "cutaway_shells"): ("depth", "cutaway_depth"),
          ("gl_conventions", "clipsurface_relief_plane"): ("prim_id", "depth"),
          ("gl_conventions", "cutaway_shells"): ("prim_id", "depth", "cutaway_depth"),
          ("caps_facing_by_front_face_only", "clipsurface_relief_plane"): ("front_facing",)}


@pytest.mark.parametrize("fault,name", sorted(FAULTS))
def test_wrong_candidates_fail_naming_the_buffer(golds, tmp_path, fault, name):
    _write(tmp_path, name, _fault(fault, name))
    result = compare(golds["vulkan_reversed"], tmp_path, mode="tolerant", scenes=[name])
    text = "\n".join(result.failures())
    assert result.exit_code == 1, fault
    for key in FAULTS[fault, name]:
        assert f"{name}/{key}:" in text, (fault, key, text[:2000])


def test_other_techniques_refused_naming_option_scene_and_why(tmp_path, capsys):
    """Attack: every registered technique ``--convention`` does not draw again, asked for in
    another API's conventions, is refused before anything renders, in one line naming the
    option, the scene, the technique and its own reason (never the generic one), exit 2, no
    golden written."""
    from refraster.golden import cli
    from refraster.golden.conventions import REFUSED, TECHNIQUES_IN_CONVENTIONS
    registry = golden.available_scenes()
    others = sorted({e.technique for e in registry.values()} - set(TECHNIQUES_IN_CONVENTIONS))
    assert set(others) == set(REFUSED), others          # a new technique gets its reason
    for k, technique in enumerate(others):
        name = next(n for n, e in registry.items() if e.technique == technique)
        api = ("vulkan", "d3d12", "metal", "webgpu")[k % 4]
        assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene", name,
                         "--convention", api]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"golden generate: error: --convention {api} cannot emit scene "
                       f"{name!r}: technique {technique!r} is not drawn again in other "
                       f"conventions: {REFUSED[technique]} (--convention emits render, "
                       f"clipsurface, cutaway scenes)"], err
    # a multisampled technique scene (its technique drawn again at one sample only)
    from refraster.golden.conventions import SAMPLED
    name = next(n for n, e in registry.items()
                if e.samples > 1 and e.technique in TECHNIQUES_IN_CONVENTIONS)
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene", name,
                     "--convention", "vulkan"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"golden generate: error: --convention vulkan cannot emit scene {name!r}: "
                   f"technique {registry[name].technique!r} is not drawn again in other "
                   f"conventions: {SAMPLED} (--convention emits render, clipsurface, "
                   f"cutaway scenes)"], err
    assert not (tmp_path / "g").exists()


def test_a_technique_scene_in_other_conventions_is_refused_under_gl(tmp_path, capsys):
    """Attack: ``--convention gl`` keeps a scene of another technique that is in OpenGL's
    conventions as built, but one in others (the reversed-Z peel) cannot be drawn again: one
    line naming the option, scene and technique, exit 2, no golden; and without ``--scene``
    the command emits only the techniques it draws again, for ``gl`` too."""
    from refraster.golden import cli
    from refraster.golden.cli import _in_convention
    from refraster.golden.conventions import REFUSED
    assert cli.main(["-q", "generate", "--out", str(tmp_path / "g"), "--scene",
                     "reversed_z_peel", "--convention", "gl"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["golden generate: error: --convention gl cannot emit scene "
                   "'reversed_z_peel': technique 'ldi' is not drawn again in other "
                   f"conventions: {REFUSED['ldi']} (--convention emits render, clipsurface, "
                   "cutaway scenes)"], err
    assert not (tmp_path / "g").exists()
    registry = golden.available_scenes()
    for api in ("gl", "vulkan"):
        names = {e.name for e in _in_convention(api, None, ())}
        assert "reversed_z_peel" not in names and "vulkan_cube" in names
        assert all(registry[n].samples == 1 for n in names), api


def test_all_scenes_in_a_convention_include_the_techniques():
    from refraster.golden.cli import _in_convention
    names = {e.name for e in _in_convention("webgpu", None, ())}
    techniques = {golden.available_scenes()[n].technique for n in names}
    assert {"render", "clipsurface", "cutaway"} <= techniques
    assert not techniques & {"ldi", "edges", "vds", "halos4d"}


def test_gpu_backends_render_or_skip_with_a_reason(tmp_path):
    """``golden candidate``: wgpu (lavapipe) renders the clip-surface scene in Vulkan's
    conventions and passes (its caps' facing included); both backends skip the cutaway in a
    non-OpenGL NDC with a reason (the OpenGL backend skips both: it draws the techniques in
    OpenGL's conventions only)."""
    from test_wgpu_backend import backend_or_skip
    from refraster.golden.candidate import candidate
    backend_or_skip().release()
    gold = tmp_path / "g"
    golden.generate(gold, [in_convention(golden.available_scenes()[n], "vulkan")
                           for n in SCENES])
    r = candidate(gold, tmp_path / "wgpu", backend="wgpu")
    assert r["rendered"] == ["clipsurface_relief_plane"], r
    assert "OpenGL's NDC" in r["skipped"]["cutaway_shells"]
    result = compare(gold, tmp_path / "wgpu", mode="tolerant",
                     scenes=["clipsurface_relief_plane"])
    assert result.exit_code == 0, "\n".join(result.failures()[:20])
    # the caps' facing: the GPU's and the golden's, bit for bit (an outside check of the
    # caps' rule under NDC y down)
    ref, got = _stored(gold, "clipsurface_relief_plane"), _stored(tmp_path / "wgpu",
                                                                   "clipsurface_relief_plane")
    caps = ref["cap_mask"] & got["cap_mask"]
    assert caps.sum() > 100 and np.array_equal(ref["front_facing"][caps],
                                               got["front_facing"][caps])
    try:
        r = candidate(gold, tmp_path / "gl", backend="gl")
    except golden.GoldenError as exc:   # no OpenGL context here
        pytest.skip(str(exc))
    assert not r["rendered"] and all("OpenGL's conventions only" in why
                                     for why in r["skipped"].values()), r


def test_floor_constraint_follows_the_mirrored_picture():
    """Under NDC y down the cutaway's rows run up the view plane (a negative row spacing): the
    floor-side clamp (which changes ~4 % of cutaway_shells' cut) lands where OpenGL's does,
    mirrored."""
    reg = golden.available_scenes()
    gl, vk = reg["cutaway_floor"].build(), _built("cutaway_floor", "vulkan", False)
    assert (gl.buffers["cut_mask"] != reg["cutaway_shells"].build().buffers["cut_mask"]).mean() \
        > 0.01
    assert np.array_equal(np.flipud(gl.buffers["cut_mask"]), vk.buffers["cut_mask"])
    assert np.abs(np.flipud(gl.buffers["cutaway_depth"]) - vk.buffers["cutaway_depth"]).max() \
        < 1e-6
