"""refraster.gl's interpolation at the sample (issue 44; ``shaders/sample_interp.glsl``, used by
the multisampled technique G-buffers and the clip-surface program at sample rate): under sample
shading llvmpipe interpolates a ``smooth`` input wrongly, and a ``noperspective`` one on a
triangle its clipper cuts, so both shader families interpolate in the shader. Against an
analytic oracle: the perspective-correct barycentrics of a perspective triangle at each of the
context's sample positions, computed here in float64 from the clip-space corners."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import gl_backend_or_skip

#: A triangle with three different w (strong perspective), clip space.
CLIP = np.array([[-1.0, -1.0, 0.0, 1.0], [12.0, -4.0, 0.0, 4.0], [-2.0, 6.0, 0.0, 2.0]])
SIZE = (8, 8)

_VERT = """#version 330 core
in vec4 in_clip;
out vec3 vs_eye;
out vec3 vs_obj;
out vec3 vs_normal;
out vec3 vs_world;
void main() { gl_Position = in_clip; vs_eye = vec3(0.0, 0.0, -1.0); vs_obj = in_clip.xyz;
              vs_normal = vec3(0.0, 0.0, 1.0); vs_world = in_clip.xyz; }
"""

#: The two shader families that interpolate at the sample with sample_interp.glsl.
FAMILIES = {"gbuffer": ("gbuffer.geom", "gbuffer.frag"), "clip": ("clip.geom", "clip.frag")}


def _oracle(positions):
    """(8, 8, S, 3) perspective-correct barycentrics at the samples (rows bottom first, as GL
    stores them); NaN where a sample is outside the triangle."""
    w = CLIP[:, 3]
    win = (CLIP[:, :2] / w[:, None] * 0.5 + 0.5) * np.array(SIZE)
    out = np.full((SIZE[1], SIZE[0], len(positions), 3), np.nan)
    a = np.vstack([win.T, np.ones(3)])
    for y in range(SIZE[1]):
        for x in range(SIZE[0]):
            for s, (px, py) in enumerate(positions):
                # positions: 1/16 pixel, y down from the pixel's upper-left corner
                lam = np.linalg.solve(a, [x + px / 16.0, y + 1.0 - py / 16.0, 1.0])
                if (lam > 1e-6).all():
                    q = lam / w
                    out[y, x, s] = q / q.sum()
    return out


def _barycentrics(gl, defines, family="gbuffer"):
    """The G-buffer's barycentric target at every sample, drawn at sample rate by the
    ``family``'s geometry and fragment shaders."""
    from refraster.gl.common import fullscreen, programs, shader_source
    from refraster.gl.msaa_techniques import SHADERS, _fns, _sample_rate
    ctx = gl.ctx
    if not isinstance(family, str):    # a (vertex, fragment) pair without a geometry stage
        prog = ctx.program(vertex_shader=family[0], fragment_shader=family[1])
    else:
        prog = ctx.program(vertex_shader=_VERT,
                           geometry_shader=shader_source(FAMILIES[family][0], defines),
                           fragment_shader=shader_source(FAMILIES[family][1], defines))
    gl._set(prog, "u_viewport_px", tuple(float(s) for s in SIZE))
    for unit, name in enumerate(("u_sprite_depth", "u_sprite_count", "u_cap_shading"), 2):
        gl._set(prog, name, unit)          # the clip program's samplers of other types
    gl._write(prog, "u_nmat", np.eye(3))
    ms = [ctx.texture(SIZE, 4, samples=4, dtype="f4") for _ in range(6)]
    fbo = ctx.framebuffer(color_attachments=ms)
    vbo = ctx.buffer(np.ascontiguousarray(CLIP, np.float32).tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "4f", "in_clip")])
    single = ctx.texture(SIZE, 4, dtype="f4")
    out_fbo = ctx.framebuffer(color_attachments=[single])
    try:
        fbo.use()
        ctx.viewport = (0, 0, *SIZE)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(gl.mgl.DEPTH_TEST | gl.mgl.CULL_FACE)
        _sample_rate(gl, True)
        vao.render(gl.mgl.TRIANGLES)
        _sample_rate(gl, False)
        res = programs(gl, SHADERS)["resolve"]
        ms[3].use(location=0)
        gl._set(res, "u_src", 0)
        out = []
        out_fbo.use()
        for s in range(4):
            gl._set(res, "u_sample", s)
            fullscreen(gl, res)
            out.append(np.frombuffer(single.read(), np.float32).reshape(*SIZE[::-1], 4)[..., :3])
        return np.stack(out, axis=2)
    finally:
        _fns()["Disable"](0x8C36)
        gl._parking.use()
        for obj in (vao, vbo, fbo, out_fbo, single, *ms, prog):
            obj.release()


@pytest.fixture(scope="module")
def gl():
    with gl_backend_or_skip() as backend:
        yield backend


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_interpolation_in_the_shader_is_the_analytic_one_at_every_sample(gl, family):
    """At all four samples, on a triangle llvmpipe clips (its noperspective inputs read NaN on
    part of it: :func:`test_llvmpipes_noperspective_inputs_on_a_clipped_triangle`)."""
    positions = gl.sample_pattern(4)["positions"]
    want = _oracle(positions)
    got = _barycentrics(gl, ["SAMPLE_INTERP"], family)
    inside = ~np.isnan(want[..., 0])
    assert inside.sum() > 100 and set(np.nonzero(inside)[2]) == {0, 1, 2, 3}
    np.testing.assert_allclose(got[inside], want[inside], atol=2e-6)


_NP_VERT = """#version 330 core
in vec4 in_clip;
noperspective out vec4 v_np;
void main() { gl_Position = in_clip;
              v_np = vec4(vec3(gl_VertexID == 0, gl_VertexID == 1, gl_VertexID == 2), 1.0) / in_clip.w; }
"""
_NP_FRAG = """#version 330 core
noperspective in vec4 v_np;
layout(location = 3) out vec4 o_bary;
void main() { o_bary = vec4(v_np.xyz / v_np.w, 0.0); }
"""


def test_llvmpipes_noperspective_inputs_on_a_clipped_triangle(gl):
    """Why the corners and not noperspective a/w and 1/w: on this triangle (it crosses the
    viewport's edges; llvmpipe clips it) Mesa 22.3.6's noperspective inputs are NaN on part of
    it at every sample, with or without sample shading (its clipper's screen-space parameter of
    an edge whose two ends have the same NDC x is 0/0). When a Mesa fixes it this test fails."""
    positions = gl.sample_pattern(4)["positions"]
    want = _oracle(positions)
    got = _barycentrics(gl, [], (_NP_VERT, _NP_FRAG))
    inside = ~np.isnan(want[..., 0])
    nan = np.isnan(got[inside]).any(axis=1)
    assert nan.any(), "noperspective inputs are no longer NaN on a clipped triangle"
    np.testing.assert_allclose(got[inside][~nan], want[inside][~nan], atol=2e-6)


def test_llvmpipes_own_interpolation_at_the_sample_is_not(gl):
    """Why the shader interpolates itself: GL_SAMPLE_SHADING with a ``smooth`` input gives the
    numerator at the sample over 1/w at the pixel centre (Mesa 22.3.6). When a Mesa fixes it
    this test fails, and the workaround can go."""
    positions = gl.sample_pattern(4)["positions"]
    want = _oracle(positions)
    got = _barycentrics(gl, [])
    inside = ~np.isnan(want[..., 0])
    err = np.abs(got[inside] - want[inside]).max()
    assert err > 1e-2, err
    assert np.abs(got[inside].sum(axis=1) - 1.0).max() > 1e-2


def test_the_backend_states_its_pattern_and_refuses_another(gl, tmp_path):
    """A 4x technique scene is drawn only at this context's own positions (one line else)."""
    from refraster.gl.common import Unsupported
    from refraster.gl.msaa_techniques import render_sampled
    scene = {"technique": "edges", "raster": {"samples": 4},
             "parameters": {"sample_pattern": {"positions": [[6, 2], [14, 6], [2, 10],
                                                             [10, 14]]}}}
    with pytest.raises(Unsupported, match=r"^edges at 4x: this OpenGL's sample positions are "
                                          r"\(6, 14\) .* the scene declares \(6, 2\)"):
        render_sampled(gl, {"scene": scene, "draws": []})


@pytest.mark.parametrize("key,value", [("origin", "upper_left"),
                                       ("depth_range", "zero_to_one")])
def test_a_4x_technique_scene_in_other_conventions_is_refused(key, value):
    """The corners' interpolation assumes GL's window origin: a 4x edges or cutaway scene in
    another API's conventions is refused in one line, not drawn wrong (no GL context needed)."""
    from refraster.gl.driver import Backend
    for technique in ("edges", "cutaway"):
        scene = {"technique": technique,
                 "raster": {"samples": 4, "interpolation": "sample"}, "parameters": {}}
        assert Backend.supports(scene) is None
        scene["raster"][key] = value
        reason = Backend.supports(scene)
        assert reason is not None and "\n" not in reason
        assert reason.startswith(f"{technique} at samples > 1 renders OpenGL's conventions only")
        assert key in reason
