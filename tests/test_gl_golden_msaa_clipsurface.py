"""refraster.gl at 4 samples on the multisampled clip-surface goldens (issue 44, item 3): the
building cut by a Perlin clip surface with caps, at llvmpipe's GL positions, drawn by
``refraster.gl.clipsurface.draw_samples`` into multisample targets — at sample rate with
``GL_SAMPLE_SHADING`` (``glMinSampleShading(1.0)``), at pixel rate without — passes both
4× goldens of its positions; a golden of Vulkan's standard positions is skipped with one line.
At sample rate the clip program interpolates at the sample itself (``shaders/sample_interp.glsl``,
shared with the technique G-buffers): llvmpipe's own
perspective divide of an input at the sample uses the pixel centre's ``1/w`` (measured here
against the exact value, :func:`test_llvmpipe_divides_a_sample_input_by_the_centres_w`), and
the planted ``msaa_divide_at_centre`` (that divide left to llvmpipe) fails the sample-rate
golden. The pass/fail matrix of the four scenes (refraster, the other rate's frame,
refraster.gl, refraster.gl with the planted fault) is in docs/backends.md ("Technique scenes at
4×"), checked against this run."""

from __future__ import annotations

import pytest

from conftest import check_backends_matrix, generate_gold, gl_backend_or_skip
from refraster.golden.compare.run import compare

GL = ["msaa4gl_clipsurface_sample", "msaa4gl_clipsurface_pixel", "msaa4gl_clipsurface_centroid"]
OTHER = ["msaa4_clipsurface_sample"]
ALL = ["msaa4_clipsurface_sample", "msaa4_clipsurface_pixel"] + GL
BEGIN = "<!-- msaa-clip-matrix:begin (tests/test_gl_golden_msaa_clipsurface.py) -->"
END = "<!-- msaa-clip-matrix:end -->"


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "gl_msaa_clip", ALL)


def test_gl_passes_the_4x_pixel_rate_clip_surface_goldens(gold):
    """At the centre and at a centroid point (``shaders/clip.frag``'s ``CENTROID_INTERP``:
    the corners method at the centroid point, :func:`test_the_centroid_point_is_llvmpipes`);
    the centroid one with the decision at the pixel centre fails (the last column of the
    matrix, ``msaa_divide_at_centre``: at pixel rate llvmpipe's own inputs are the centre's)."""
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    out = gold / "cand_gl"
    r = candidate(gold / "golden", out, backend="gl", scenes=GL + OTHER)
    assert sorted(r["rendered"]) == sorted(GL), r
    assert r["skipped"]["msaa4_clipsurface_sample"].startswith(
        "clipsurface: this OpenGL's 4x sample positions are (6, 14) (14, 10) (2, 6) (10, 2), "
        "the scene declares (6, 2) (14, 6) (2, 10) (10, 14)")
    res = compare(gold / "golden", out, mode="tolerant",
                  scenes=["msaa4gl_clipsurface_pixel", "msaa4gl_clipsurface_centroid"])
    assert res.exit_code == 0, res.failures()[:5]


def test_gl_passes_the_4x_sample_rate_clip_surface_golden(gold):
    """Both directions: the correct backend passes; with the divide left to llvmpipe (the
    planted ``msaa_divide_at_centre``) the ids, cap mask and barycentrics fail at every
    sample index (68 samples' ids at the caps' rims, measured 2026-12-04)."""
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    scene = ["msaa4gl_clipsurface_sample"]
    out = gold / "cand_gl_sample"
    candidate(gold / "golden", out, backend="gl", scenes=scene)
    res = compare(gold / "golden", out, mode="tolerant", scenes=scene)
    assert res.exit_code == 0, res.failures()[:5]
    bad = gold / "cand_gl_sample_fault"
    candidate(gold / "golden", bad, backend="gl", scenes=scene, faults=["msaa_divide_at_centre"])
    failing = {b.name for b in compare(gold / "golden", bad, mode="tolerant",
                                       scenes=scene).scenes[0].buffers if not b.passed}
    assert {f"sample{s}_{ch}" for s in range(4)
            for ch in ("object_id", "cap_mask", "barycentric")} <= failing, sorted(failing)


_PROBE_VS = """#version 400 core
in vec4 p; in vec3 b;
out vec3 v_b; noperspective out vec4 v_np;
void main() { gl_Position = p; v_b = b; v_np = vec4(b / p.w, 1.0 / p.w); }"""
_PROBE_FS = """#version 400 core
in vec3 v_b; noperspective in vec4 v_np;
layout(location = 0) out vec4 o_smooth;
layout(location = 1) out vec4 o_divided;
layout(location = 2) out vec4 o_position;
void main() { o_smooth = vec4(v_b, 1.0); o_divided = vec4(v_np.xyz / v_np.w, 1.0);
              o_position = vec4(gl_SamplePosition, 0.0, 1.0); }"""


def test_llvmpipe_divides_a_sample_input_by_the_centres_w():
    """The cause of the sample-rate anomaly, against the exact value: one perspective triangle
    (clip w 1, 4, 2) with barycentric corners at 4× under ``GL_SAMPLE_SHADING``, 16×16. At each
    covered sample the exact perspective-correct barycentrics at the sample (float64, from the
    window positions and the clip w) are (λ/w)/Σ(λ/w) with λ the window-space barycentrics. The
    noperspective a/w divided by 1/w in the shader equals them within 1e-5; llvmpipe's smooth
    input equals (a/w at the sample) / (1/w at the pixel centre) within 1e-5 and is off the
    exact value by up to 6 % (its components sum to 1 ± 7 %) — a defect of this llvmpipe
    (Mesa 22.3.6): OpenGL 4.6 §14.3.1.1 evaluates a sample's inputs at the sample."""
    import ctypes
    import numpy as np
    from refraster.gl.common import gl_function
    gl = gl_backend_or_skip()
    try:
        ctx, mgl = gl.ctx, gl.mgl
        w_, h_ = 16, 16
        clip = np.array([[-0.9, -0.9, 0.0, 1.0], [3.6, -3.6, 0.0, 4.0], [-1.8, 1.8, 0.0, 2.0]],
                        np.float32)
        prog = ctx.program(vertex_shader=_PROBE_VS, fragment_shader=_PROBE_FS)
        vbo = ctx.buffer(np.concatenate([clip, np.eye(3, dtype=np.float32)], 1).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "4f 3f", "p", "b")])
        ms = [ctx.texture((w_, h_), 4, samples=4, dtype="f4") for _ in range(3)]
        fbo = ctx.framebuffer(color_attachments=ms)
        fbo.use()
        ctx.viewport = (0, 0, w_, h_)
        fbo.clear()
        gl_function("glEnable", None, ctypes.c_uint)(0x8C36)          # GL_SAMPLE_SHADING
        gl_function("glMinSampleShading", None, ctypes.c_float)(1.0)
        vao.render(mgl.TRIANGLES)
        gl_function("glDisable", None, ctypes.c_uint)(0x8C36)
        got = _read_samples(gl, ms, (w_, h_))
        for obj in (vao, vbo, prog, fbo, *ms):
            obj.release()
    finally:
        gl.release()
    win = (clip[:, :2].astype(np.float64) / clip[:, 3:] * 0.5 + 0.5) * (w_, h_)
    m = np.vstack([win.T, np.ones(3)])

    def oow_terms(x, y):              # λ / w at window point (x, y), y up
        return np.linalg.solve(m, [x, y, 1.0]) / clip[:, 3]

    n, exact_err, divided_err, defect_err = 0, 0.0, 0.0, 0.0
    for s in range(4):
        smooth, divided, pos = got[0, s], got[1, s], got[2, s]
        for y, x in zip(*np.nonzero(smooth[..., 3] > 0)):
            q = oow_terms(x + pos[y, x, 0], y + pos[y, x, 1])
            exact = q / q.sum()
            centre = oow_terms(x + 0.5, y + 0.5).sum()
            n += 1
            divided_err = max(divided_err, np.abs(divided[y, x, :3] - exact).max())
            defect_err = max(defect_err, np.abs(smooth[y, x, :3] - q / centre).max())
            exact_err = max(exact_err, np.abs(smooth[y, x, :3] - exact).max())
    assert n > 300
    assert divided_err < 1e-5, divided_err
    assert defect_err < 1e-5 and exact_err > 0.05, (
        f"llvmpipe's smooth input at the sample: off the centre-divided value by {defect_err}, "
        f"off the exact one by {exact_err} (if it is now exact, llvmpipe was fixed: update "
        "docs/backends.md)")


_CENTROID_VS = """#version 400 core
in vec4 p; uniform vec2 vp; noperspective centroid out vec2 v_win;
void main() { gl_Position = p; v_win = (p.xy / p.w * 0.5 + 0.5) * vp; }"""
_CENTROID_FS = """#version 400 core
noperspective centroid in vec2 v_win; uniform vec2 u_sample_xy[4];
layout(location = 0) out vec4 o_point;
vec2 centroid_point() {     // as clip.frag's CENTROID_INTERP (4 samples)
    int mask = gl_SampleMaskIn[0];
    if (mask == 15) return gl_FragCoord.xy;
    for (int s = 0; s < 4; ++s)
        if (((mask >> s) & 1) != 0) return floor(gl_FragCoord.xy) + u_sample_xy[s];
    return gl_FragCoord.xy;
}
void main() { o_point = vec4(centroid_point(), v_win); }"""


def test_the_centroid_point_is_llvmpipes():
    """The point ``clip.frag`` interpolates at under ``CENTROID_INTERP`` (the centre where all
    4 samples are covered, else the first covered one, from ``gl_SampleMaskIn`` and the
    declared positions) is the point llvmpipe's own ``centroid noperspective`` window position
    gives, within 1e-5, at every fragment of a perspective triangle (4×, 16×16, pixel rate:
    ``gl_FragCoord`` at the centre), and lies inside both the pixel and the triangle (float64
    edge functions, 1e-6) — the golden's allowance admits any such point. 35 of 127 fragments
    are partly covered."""
    import numpy as np
    from refraster.gl.msaa import sample_pattern
    gl = gl_backend_or_skip()
    try:
        ctx, mgl = gl.ctx, gl.mgl
        w_, h_ = 16, 16
        clip = np.array([[-0.93, -0.87, 0.3, 1.0], [3.6, -3.2, 0.1, 4.0], [-1.7, 1.9, 0.2, 2.0]],
                        np.float32)
        prog = ctx.program(vertex_shader=_CENTROID_VS, fragment_shader=_CENTROID_FS)
        prog["vp"].value = (w_, h_)
        pos = sample_pattern(gl, 4)["positions"]
        prog["u_sample_xy"].value = [(x / 16.0, 1.0 - y / 16.0) for x, y in pos]
        vbo = ctx.buffer(clip.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "4f", "p")])
        ms = ctx.texture((w_, h_), 4, samples=4, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[ms])
        fbo.use()
        ctx.viewport = (0, 0, w_, h_)
        fbo.clear(-1.0, -1.0, -1.0, -1.0)
        vao.render(mgl.TRIANGLES)
        got = [_read_samples(gl, [ms], (w_, h_))[0, s] for s in range(4)]
        for obj in (vao, vbo, prog, fbo, ms):
            obj.release()
    finally:
        gl.release()
    win = (clip[:, :2].astype(np.float64) / clip[:, 3:] * 0.5 + 0.5) * (w_, h_)

    def cross(a, b):
        return a[0] * b[1] - a[1] * b[0]
    area = cross(win[1] - win[0], win[2] - win[0])
    n = partial = 0
    for y in range(h_):
        for x in range(w_):
            vals = [g[y, x] for g in got if g[y, x, 0] >= 0]
            if not vals:
                continue
            n += 1
            partial += len(vals) < 4
            pt = vals[0][:2].astype(np.float64)
            assert np.abs(vals[0][:2] - vals[0][2:]).max() < 1e-5, (x, y, vals[0])
            assert x <= pt[0] <= x + 1 and y <= pt[1] <= y + 1, (x, y, pt)
            edges = [cross(win[(i + 1) % 3] - win[i], pt - win[i]) * np.sign(area)
                     for i in range(3)]
            assert min(edges) > -1e-6, (x, y, pt, edges)
    assert n > 100 and partial > 20, (n, partial)


_FETCH_FS = """#version 330 core
uniform sampler2DMS u_tex; uniform int u_sample; out vec4 o;
void main() { o = texelFetch(u_tex, ivec2(gl_FragCoord.xy), u_sample); }"""


def _read_samples(gl, textures, size):
    """``{(k, s): (h, w, 4) float32}``: sample ``s`` of the 4× RGBA32F texture ``textures[k]``,
    read with ``texelFetch`` in a full-screen pass."""
    import numpy as np
    from refraster.gl.common import fullscreen, shader_source
    ctx = gl.ctx
    fetch = ctx.program(vertex_shader=shader_source("fullscreen.vert"), fragment_shader=_FETCH_FS)
    one = ctx.texture(size, 4, dtype="f4")
    out = ctx.framebuffer(color_attachments=[one])
    got = {}
    for k, tex in enumerate(textures):
        for s in range(4):
            out.use()
            out.clear()
            tex.use(location=0)
            fetch["u_tex"].value, fetch["u_sample"].value = 0, s
            fullscreen(gl, fetch)
            got[k, s] = np.frombuffer(one.read(), np.float32).reshape(size[1], size[0], 4)
    for obj in (fetch, out, one):
        obj.release()
    return got


def _cell(result):
    if result.status == "pass":
        return "pass"
    failing = sorted({b.name for b in result.buffers if not b.passed})
    samples = sorted({b.split("_", 1)[1] for b in failing if b.startswith("sample")})
    whole = [f"`{b}`" for b in failing if not b.startswith("sample")]
    return "**FAIL** " + ", ".join(whole + [f"`{c}` per sample" for c in samples])


def test_the_clip_surface_matrix_at_4x(gold):
    """refraster's own frame passes each scene; the frame of the other rate (the discard and
    parity at pixel rate where sample rate is declared, and the reverse) fails it; refraster.gl
    draws the scenes of its own positions (skipping the others in one line), and with the
    planted ``msaa_divide_at_centre`` fails the sample-rate one (the pixel-rate one does not
    divide in the shader: unchanged)."""
    from refraster.golden.candidate import candidate
    from test_golden_msaa_clipsurface import _candidate
    gl_backend_or_skip().release()
    other = {"sample": "center", "center": "sample", "centroid": "center"}
    rows = ["| scene | rate | refraster | the other rate's frame | refraster.gl | "
            "refraster.gl `msaa_divide_at_centre` |", "|---|---|---|---|---|---|"]
    own = compare(gold / "golden", _candidate(gold, "m_own", ALL), mode="tolerant")
    by_name = {r.name: r for r in own.scenes}
    gl_out = gold / "cand_gl_matrix"
    made = candidate(gold / "golden", gl_out, backend="gl", scenes=ALL)
    gl = {r.name: r for r in compare(gold / "golden", gl_out, mode="tolerant",
                                     scenes=sorted(made["rendered"])).scenes}
    bad_out = gold / "cand_gl_matrix_fault"
    candidate(gold / "golden", bad_out, backend="gl", scenes=sorted(made["rendered"]),
              faults=["msaa_divide_at_centre"])
    bad = {r.name: r for r in compare(gold / "golden", bad_out, mode="tolerant",
                                      scenes=sorted(made["rendered"])).scenes}
    for name in ALL:
        rate = name.rsplit("_", 1)[1].replace("pixel", "center")
        flip = compare(gold / "golden", _candidate(gold, f"m_{name}", [name],
                                                   interpolation=other[rate]),
                       mode="tolerant", scenes=[name]).scenes[0]
        skipped = "skipped: another sample pattern"
        gl_cell = _cell(gl[name]) if name in gl else skipped
        bad_cell = _cell(bad[name]) if name in bad else skipped
        rows.append(f"| {name} | {'pixel' if rate == 'center' else rate} | "
                    f"{_cell(by_name[name])} | {_cell(flip)} | {gl_cell} | {bad_cell} |")
        assert by_name[name].status == "pass"
        assert flip.status != "pass", name
    check_backends_matrix(BEGIN, END, "\n".join(rows), "multisampled clip-surface matrix")
