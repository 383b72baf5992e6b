"""llvmpipe at 4× as an outside oracle of the clip surface's discard per sample (issue 44,
item 1): the scene of ``tests/test_msaa_clipsurface.py`` (a front triangle and two planes
behind it, identity matrices so clip = world) drawn into llvmpipe's 4-sample ids and float
depth targets (``oracles.llvmpipe_msaa``) with a fragment shader that evaluates Listing 1's
plane test at its interpolated world position and discards where ``g < 0`` — at pixel rate
(no sample shading: one invocation per pixel, the position at the centre, its discard
removing every covered sample) and at sample rate (``glEnable(GL_SAMPLE_SHADING)`` with
``glMinSampleShading(1.0)``, the position at each sample). refraster's
``render_clipped(raster=RasterState(samples=4, sample_locations="gl_llvmpipe",
interpolation=...))`` at the matching rate agrees on every sample but those whose ``g`` is
within float32 rounding of 0; each rate disagrees with the other's frame."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from conftest import require
from refraster import RasterState
from test_msaa_clipsurface import NORMAL, ORIGIN, H, W, _clipped, _layers_scene

_FRAGMENT = """
#version 450 core
in vec3 v_world;
uniform vec3 u_N;
uniform vec3 u_O;
layout(location = 0) out int o_prim;
void main() {
    if (dot(u_N, v_world - u_O) < 0.0) discard;   // Listing 1 with a constant offset map
    o_prim = gl_PrimitiveID;
}
"""
_VERTEX = """
#version 450 core
in vec4 in_clip;
out vec3 v_world;
void main() { gl_Position = in_clip; v_world = in_clip.xyz; }
"""
_GL_SAMPLE_SHADING = 0x8C36


def _gl_frame(rate):
    from oracles import llvmpipe_msaa as M
    v, f = _layers_scene()
    clip = np.c_[v, np.ones(len(v), np.float32)]
    n = np.asarray(NORMAL, np.float64)
    n /= np.linalg.norm(n)
    with M.MultisampleScene(clip, f, W, H) as sc:
        ctx = sc.ctx
        prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        prog["u_N"].value = tuple(float(x) for x in n)
        prog["u_O"].value = tuple(float(x) for x in ORIGIN)
        vao = ctx.vertex_array(prog, [(sc.pos, "4f", "in_clip")], index_buffer=sc.ibo,
                               index_element_size=4)
        sc.vao, old = vao, sc.vao
        fn = M._gl()
        egl = M._S.setdefault("sample_shading", {})
        if not egl:
            import ctypes.util
            lib = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
            lib.eglGetProcAddress.restype = ctypes.c_void_p
            lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
            for name, args in (("glEnable", (ctypes.c_uint,)), ("glDisable", (ctypes.c_uint,)),
                               ("glMinSampleShading", (ctypes.c_float,))):
                egl[name] = ctypes.CFUNCTYPE(None, *args)(lib.eglGetProcAddress(name.encode()))
        try:
            if rate == "sample":
                egl["glEnable"](_GL_SAMPLE_SHADING)
                egl["glMinSampleShading"](1.0)
            sc.draw()
        finally:
            egl["glDisable"](_GL_SAMPLE_SHADING)
            sc.vao = old
            vao.release()
            prog.release()
        assert not fn["GetError"]()
        return sc.read(), sc.positions


@pytest.fixture(scope="module")
def frames():
    require("oracles.llvmpipe_msaa")
    return {rate: _gl_frame(rate)[0] for rate in ("pixel", "sample")}


def _ours(rate):
    v, f = _layers_scene()
    interp = "sample" if rate == "sample" else "center"
    fb = _clipped(v, f, RasterState(samples=4, sample_locations="gl_llvmpipe",
                                    interpolation=interp))
    return fb.prim_id


def _near_zero(rate, margin=1e-5):
    """Samples where some face's plane test is within ``margin`` of g = 0 at the point its
    rate evaluates it (float32 interpolation in GL decides them either way)."""
    from test_msaa_clipsurface import _oracle
    from refraster.raster.samples import sample_points
    pts = sample_points(RasterState(samples=4, sample_locations="gl_llvmpipe"))
    positions = [(int(round(x * 16)), int(round(y * 16))) for x, y in pts]
    v, f = _layers_scene()
    _, sure = _oracle(v, f, positions, NORMAL, ORIGIN,
                      "sample" if rate == "sample" else "center")
    return ~sure


@pytest.mark.parametrize("rate", ["pixel", "sample"])
def test_llvmpipe_4x_discard_per_sample_agrees(frames, rate):
    ours = _ours(rate)
    gl = frames[rate]
    skip = _near_zero(rate)
    bad = (ours != gl) & ~skip
    assert skip.mean() < 0.03
    assert not bad.any(), (f"{rate} rate: {int(bad.sum())} of {bad.size} samples differ "
                           f"from llvmpipe, first at {np.argwhere(bad)[:3].tolist()}")


def test_llvmpipe_4x_rates_are_told_apart(frames):
    for ours, theirs in (("pixel", "sample"), ("sample", "pixel")):
        bad = (_ours(ours) != frames[theirs]) & ~_near_zero(ours) & ~_near_zero(theirs)
        assert bad.sum() >= 5, (ours, theirs, int(bad.sum()))
