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


class MultisampleScene:
    """The geometry uploaded and the 4× targets made once; :meth:`draw` renders a frame
    (``glFinish`` included), :meth:`read` resolves the per-sample ids and reads them back.
    Use as a context manager (releases the GL objects)."""

    def __init__(self, clip, faces, width, height):
        ctx = L.context()
        ctx.__enter__()   # the oracle's context, whatever context is current
        self.ctx, self.mgl, self.gl = ctx, L._STATE["moderngl"], _gl()
        self.prog, self.resolve = _programs(ctx)
        self.size = size = (int(width), int(height))
        self.ids_ms = ctx.texture(size, 1, samples=SAMPLES, dtype="i4")
        self.depth_ms = ctx.depth_texture(size, samples=SAMPLES)
        gl = self.gl
        gl["BindTexture"](_GL_TEXTURE_2D_MULTISAMPLE, self.depth_ms.glo)
        gl["TexImage2DMultisample"](_GL_TEXTURE_2D_MULTISAMPLE, SAMPLES, _GL_DEPTH_COMPONENT32F,
                                    size[0], size[1], 1)
        err = gl["GetError"]()
        if err:
            raise RuntimeError(f"GL error 0x{err:04x} re-specifying the multisample depth")
        self.fbo = ctx.framebuffer(color_attachments=[self.ids_ms],
                                   depth_attachment=self.depth_ms)
        self.out_tex = ctx.texture(size, 4, dtype="i4")
        self.out_fbo = ctx.framebuffer(color_attachments=[self.out_tex])
        self.pos = ctx.buffer(np.ascontiguousarray(clip, np.float32).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(faces, np.int32).tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self.pos, "4f", "in_clip")],
                                    index_buffer=self.ibo, index_element_size=4)
        self.quad = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
        self.qvao = ctx.vertex_array(self.resolve, [(self.quad, "2f", "in_pos")])
        self.positions = sample_positions(self.fbo)

    def draw(self):
        ctx, mgl = self.ctx, self.mgl
        ctx.__enter__()
        self.fbo.use()
        ctx.viewport = (0, 0, self.size[0], self.size[1])
        ctx.disable(mgl.CULL_FACE | mgl.BLEND)
        ctx.enable(mgl.DEPTH_TEST)
        ctx.depth_func = "<"
        ctx.clear(depth=1.0)
        minus = (ctypes.c_int * 4)(-1, -1, -1, -1)
        self.gl["ClearBufferiv"](0x1800, 0, minus)   # GL_COLOR: an integer clear to -1
        self.vao.render(mgl.TRIANGLES)
        ctx.finish()

    def read(self):
        """Per-sample ids ``(H, W, 4)`` int32, row 0 at the top."""
        ctx, mgl = self.ctx, self.mgl
        self.out_fbo.use()
        ctx.disable(mgl.DEPTH_TEST)
        self.ids_ms.use(location=0)
        self.resolve["u_ids"].value = 0
        self.qvao.render(mgl.TRIANGLES)
        ctx.finish()
        a = np.frombuffer(self.out_tex.read(), np.int32).reshape(self.size[1], self.size[0], 4)
        return np.ascontiguousarray(a[::-1])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for r in (self.qvao, self.quad, self.vao, self.ibo, self.pos, self.out_fbo,
                  self.out_tex, self.fbo, self.depth_ms, self.ids_ms):
            r.release()
        L._STATE["parking"].use()


def rasterize_samples(clip, faces, width, height):
    """Per-sample primitive ids ``(H, W, 4)`` int32 (−1: no primitive), row 0 at the top, and
    the sample positions llvmpipe reports."""
    with MultisampleScene(clip, faces, width, height) as sc:
        sc.draw()
        return sc.read(), sc.positions
