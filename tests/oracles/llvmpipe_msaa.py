"""llvmpipe at 4× as an oracle of per-sample coverage and the per-sample depth test.

A multisample ``R32I`` colour texture and a multisample 32-bit float depth texture (4 samples)
take one draw of the clip positions (``oracles.llvmpipe.clip_positions``), the fragment shader
writing ``gl_PrimitiveID`` (no sample shading: one fragment per pixel, written to the samples it
covers that pass the depth test ``GL_LESS``). A second pass over the whole viewport reads each
sample with ``texelFetch(isampler2DMS, p, s)`` and writes the four ids into an ``RGBA32I``
texture, read back with row 0 at the top (GL reads the bottom row first: flipped here).
:func:`sample_positions` is what ``glGetMultisamplefv(GL_SAMPLE_POSITION, i)`` reports.

Importing :mod:`oracles.llvmpipe` creates its context (``LlvmpipeUnavailable`` when it cannot);
reach this module through the ``oracle`` fixture.
"""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np

from oracles import llvmpipe as L

SAMPLES = 4
_GL_TEXTURE_2D_MULTISAMPLE = 0x9100
_GL_DEPTH_COMPONENT32F = 0x8CAC
_GL_SAMPLE_POSITION = 0x8E50

_VERTEX = """
#version 450 core
in vec4 in_clip;
void main() { gl_Position = in_clip; }
"""
_FRAGMENT = """
#version 450 core
layout(location = 0) out int o_prim;
void main() { o_prim = gl_PrimitiveID; }
"""
_RESOLVE_VS = """
#version 450 core
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""
_RESOLVE_FS = """
#version 450 core
uniform isampler2DMS u_ids;
layout(location = 0) out ivec4 o_ids;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    o_ids = ivec4(texelFetch(u_ids, p, 0).r, texelFetch(u_ids, p, 1).r,
                  texelFetch(u_ids, p, 2).r, texelFetch(u_ids, p, 3).r);
}
"""

_S = {}


def _gl():
    if "fns" not in _S:
        egl = ctypes.CDLL(ctypes.util.find_library("EGL") or "libEGL.so.1")
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]

        def fn(name, restype, *argtypes):
            return ctypes.CFUNCTYPE(restype, *argtypes)(egl.eglGetProcAddress(name.encode()))

        u, i, p = ctypes.c_uint, ctypes.c_int, ctypes.c_void_p
        _S["fns"] = {
            "BindTexture": fn("glBindTexture", None, u, u),
            "TexImage2DMultisample": fn("glTexImage2DMultisample", None, u, i, u, i, i,
                                        ctypes.c_ubyte),
            "GetMultisamplefv": fn("glGetMultisamplefv", None, u, u,
                                   ctypes.POINTER(ctypes.c_float)),
            "GetError": fn("glGetError", u),
            "ClearBufferiv": fn("glClearBufferiv", None, u, i, ctypes.POINTER(ctypes.c_int)),
        }
    return _S["fns"]


def _programs(ctx):
    if "prog" not in _S:
        _S["prog"] = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        _S["resolve"] = ctx.program(vertex_shader=_RESOLVE_VS, fragment_shader=_RESOLVE_FS)
    return _S["prog"], _S["resolve"]


def sample_positions(fbo):
    """``glGetMultisamplefv(GL_SAMPLE_POSITION, i)`` for the bound multisample framebuffer."""
    gl = _gl()
    fbo.use()
    out = []
    for i in range(SAMPLES):
        v = (ctypes.c_float * 2)()
        gl["GetMultisamplefv"](_GL_SAMPLE_POSITION, i, v)
        out.append((float(v[0]), float(v[1])))
    return out


def rasterize_samples(clip, faces, width, height):
    """Per-sample primitive ids ``(H, W, 4)`` int32 (−1: no primitive), row 0 at the top, and
    the sample positions llvmpipe reports."""
    ctx = L.context()
    ctx.__enter__()
    mgl = L._STATE["moderngl"]
    gl = _gl()
    prog, resolve = _programs(ctx)
    size = (int(width), int(height))
    ids_ms = ctx.texture(size, 1, samples=SAMPLES, dtype="i4")
    depth_ms = ctx.depth_texture(size, samples=SAMPLES)
    gl["BindTexture"](_GL_TEXTURE_2D_MULTISAMPLE, depth_ms.glo)
    gl["TexImage2DMultisample"](_GL_TEXTURE_2D_MULTISAMPLE, SAMPLES, _GL_DEPTH_COMPONENT32F,
                                size[0], size[1], 1)
    err = gl["GetError"]()
    if err:
        raise RuntimeError(f"GL error 0x{err:04x} re-specifying the multisample depth")
    fbo = ctx.framebuffer(color_attachments=[ids_ms], depth_attachment=depth_ms)
    out_tex = ctx.texture(size, 4, dtype="i4")
    out_fbo = ctx.framebuffer(color_attachments=[out_tex])
    pos = ctx.buffer(np.ascontiguousarray(clip, np.float32).tobytes())
    ibo = ctx.buffer(np.ascontiguousarray(faces, np.int32).tobytes())
    vao = ctx.vertex_array(prog, [(pos, "4f", "in_clip")], index_buffer=ibo,
                           index_element_size=4)
    quad = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
    qvao = ctx.vertex_array(resolve, [(quad, "2f", "in_pos")])
    try:
        fbo.use()
        ctx.viewport = (0, 0, size[0], size[1])
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        ctx.enable(mgl.DEPTH_TEST)
        ctx.depth_func = "<"
        minus = (ctypes.c_int * 4)(-1, -1, -1, -1)
        ctx.clear(depth=1.0)
        gl["ClearBufferiv"](0x1800, 0, minus)   # GL_COLOR: an integer clear to -1
        positions = sample_positions(fbo)
        fbo.use()
        vao.render(mgl.TRIANGLES)
        out_fbo.use()
        ctx.disable(mgl.DEPTH_TEST)
        ids_ms.use(location=0)
        resolve["u_ids"].value = 0
        qvao.render(mgl.TRIANGLES)
        ctx.finish()
        a = np.frombuffer(out_tex.read(), np.int32).reshape(size[1], size[0], 4)
        return np.ascontiguousarray(a[::-1]), positions
    finally:
        for r in (qvao, quad, vao, ibo, pos, out_fbo, out_tex, fbo, depth_ms, ids_ms):
            r.release()
        L._STATE["parking"].use()
