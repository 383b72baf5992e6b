"""Mesa's llvmpipe as an oracle: single-pass rasterization and classic multi-pass depth peeling.

llvmpipe is a conformant OpenGL 4.5 implementation that runs on the CPU; nobody on this project
wrote it, which makes it an outside opinion on coverage, fill rule, clipping and depth. Facts about
driving it are in ``/work/shared/LLVMPIPE.md``; the ones this module relies on:

* ``moderngl.create_standalone_context(backend="egl")`` gives llvmpipe with no display.
* moderngl's depth textures are 24-bit; peeling against 24 bits re-peels surfaces. The depth
  attachment here is re-specified as ``GL_DEPTH_COMPONENT32F`` through a raw GL call, and the peel
  compares ``gl_FragCoord.z`` against the previous layer's ``R32F`` copy of it (bit-identical to
  the stored depth) with a strict ``>``.
* Integer targets are cleared with ``glClearBufferiv`` (a plain clear writes float bit patterns).

Geometry goes in as **clip-space positions** (float32, passed straight through as
``gl_Position``) so both renderers start from the same bits; :func:`clip_positions` computes them
from object-space vertices the way refraster's float32 vertex stage does. Draw calls are drawn in
order with their index as the object id. Depth test ``GL_LESS``; front faces CCW as the picture is
seen (GL's default). Every returned image is ``(H, W, ...)`` with **row 0 at the top** (GL reads
the bottom row first; this module flips).

The API conventions (issue 39) are OpenGL state here too: ``origin`` and ``depth_range`` through
``glClipControl`` (GL 4.5, resolved with ``eglGetProcAddress``; moderngl does not wrap it),
``depth_clamp`` as ``GL_DEPTH_CLAMP``, ``depth_format`` as a ``GL_DEPTH_COMPONENT32F`` / ``24`` /
``16`` attachment, ``depth_func`` and ``clear_depth`` as ``glDepthFunc`` / the depth clear, and
Vulkan's ``ndc_y="down"`` as a negation of the clip y in the vertex shader (GL's NDC y points
up). Under ``GL_UPPER_LEFT`` GL's first row is the top of the picture (kept as read). Every
frame restores OpenGL's defaults.

Importing the module creates the context and raises :class:`LlvmpipeUnavailable` when it cannot,
so tests reach it through the ``oracle`` fixture and skip (or fail under ``CI=true``).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass

import numpy as np

from .scenes import clip_positions

__all__ = [
    "LlvmpipeUnavailable", "Frame", "Layers", "GLScene", "clip_positions", "context", "rasterize",
    "peel", "renderer",
]

CULL_MODES = ("none", "back", "front")
#: The conventions of :class:`GLScene` and OpenGL's values of them.
DEFAULT_CONVENTIONS = {"origin": "lower_left", "depth_range": "negative_one_to_one",
                       "ndc_y": "up", "depth_clamp": False, "depth_format": "float32",
                       "depth_func": "less", "clear_depth": 1.0}

_GL_TEXTURE_2D = 0x0DE1
_GL_DEPTH_COMPONENT = 0x1902
_GL_DEPTH_COMPONENT32F = 0x8CAC
_GL_FLOAT = 0x1406
_GL_COLOR = 0x1800
_GL_DEPTH = 0x1801
_GL_NO_ERROR = 0
_GL_DEPTH_CLAMP = 0x864F
_CLIP_ORIGIN = {"lower_left": 0x8CA1, "upper_left": 0x8CA2}
_CLIP_DEPTH = {"negative_one_to_one": 0x935E, "zero_to_one": 0x935F}
#: depth_format → (internal format, pixel type)
_DEPTH_FORMATS = {"float32": (_GL_DEPTH_COMPONENT32F, _GL_FLOAT),
                  "unorm24": (0x81A6, 0x1405),      # GL_DEPTH_COMPONENT24, GL_UNSIGNED_INT
                  "unorm16": (0x81A5, 0x1403)}      # GL_DEPTH_COMPONENT16, GL_UNSIGNED_SHORT
_DEPTH_FUNCS = {"less": "<", "lequal": "<=", "greater": ">", "gequal": ">="}

_VERTEX = """
#version 450 core
in vec4 in_clip;
uniform bool u_ndc_y_down;   // Vulkan's NDC y points down; GL's up: negate the clip y
#ifdef BARY
in vec3 in_bary;
out vec3 v_bary;
#endif
void main() {
    gl_Position = in_clip;
    if (u_ndc_y_down) gl_Position.y = -gl_Position.y;
#ifdef BARY
    v_bary = in_bary;
#endif
}
"""

_FRAGMENT = """
#version 450 core
uniform int u_object;
uniform bool u_peel;
uniform sampler2D u_prev;
layout(location = 0) out float o_depth;
layout(location = 1) out int o_prim;
layout(location = 2) out int o_object;
layout(location = 3) out int o_front;
#ifdef BARY
in vec3 v_bary;
layout(location = 4) out vec4 o_bary;
#endif
void main() {
    // classic depth peeling: keep only fragments strictly behind the previous layer
    if (u_peel && gl_FragCoord.z <= texelFetch(u_prev, ivec2(gl_FragCoord.xy), 0).r) discard;
    o_depth = gl_FragCoord.z;
    o_prim = gl_PrimitiveID;
    o_object = u_object;
    o_front = gl_FrontFacing ? 1 : 0;
#ifdef BARY
    o_bary = vec4(v_bary, 0.0);
#endif
}
"""


class LlvmpipeUnavailable(RuntimeError):
    """No llvmpipe context could be created (moderngl missing, no EGL, or another driver)."""


_STATE = {}


def _create_context():
    try:
        import moderngl
    except Exception as exc:
        raise LlvmpipeUnavailable(f"moderngl cannot be imported: {exc}") from exc
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:
        raise LlvmpipeUnavailable(
            "moderngl.create_standalone_context(backend='egl') failed "
            f"(are libegl1 and libegl-mesa0 installed?): {exc}") from exc
    name = ctx.info.get("GL_RENDERER", "")
    if "llvmpipe" not in name:
        raise LlvmpipeUnavailable(f"EGL gave the renderer {name!r}, not Mesa's llvmpipe")
    if ctx.version_code < 450:
        raise LlvmpipeUnavailable(f"llvmpipe offers OpenGL {ctx.version_code}, 4.5 is needed")
    return moderngl, ctx


def _load_gl():
    path = ctypes.util.find_library("EGL") or "libEGL.so.1"
    try:
        egl = ctypes.CDLL(path)
    except OSError as exc:
        raise LlvmpipeUnavailable(f"cannot load {path}: {exc}") from exc
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]

    def fn(name, restype, *argtypes):
        addr = egl.eglGetProcAddress(name.encode())
        if not addr:
            raise LlvmpipeUnavailable(f"eglGetProcAddress({name}) returned NULL")
        return ctypes.CFUNCTYPE(restype, *argtypes)(addr)

    u, i, p = ctypes.c_uint, ctypes.c_int, ctypes.c_void_p
    return {
        "BindTexture": fn("glBindTexture", None, u, u),
        "TexImage2D": fn("glTexImage2D", None, u, i, i, i, i, i, u, u, p),
        "ClearBufferiv": fn("glClearBufferiv", None, u, i, ctypes.POINTER(ctypes.c_int)),
        "ClearBufferfv": fn("glClearBufferfv", None, u, i, ctypes.POINTER(ctypes.c_float)),
        "GetError": fn("glGetError", u),
        "ClipControl": fn("glClipControl", None, u, u),
        "Enable": fn("glEnable", None, u),
        "Disable": fn("glDisable", None, u),
    }


def context():
    """The shared llvmpipe context (created on first use)."""
    if "ctx" not in _STATE:
        moderngl, ctx = _create_context()
        _STATE["moderngl"] = moderngl
        _STATE["ctx"] = ctx
        _STATE["gl"] = _load_gl()
        _STATE["programs"] = {
            bary: ctx.program(vertex_shader=_VERTEX.replace("core\n", "core\n#define BARY\n" if bary else "core\n"),
                              fragment_shader=_FRAGMENT.replace("core\n", "core\n#define BARY\n" if bary else "core\n"))
            for bary in (False, True)
        }
        # moderngl rebinds the last used framebuffer after creating one; park on this one before
        # releasing a scene's framebuffers so that it never rebinds a deleted name
        _STATE["parking"] = ctx.framebuffer(color_attachments=[ctx.renderbuffer((1, 1))])
    return _STATE["ctx"]


def renderer():
    """``GL_RENDERER`` and ``GL_VERSION`` of the oracle, for reports."""
    ctx = context()
    return f"{ctx.info['GL_RENDERER']}; {ctx.info['GL_VERSION']}"


def _check_gl(what):
    err = _STATE["gl"]["GetError"]()
    if err != _GL_NO_ERROR:
        raise RuntimeError(f"OpenGL error 0x{err:04x} after {what}")


@dataclass
class Frame:
    """One rasterization pass, every image ``(H, W, ...)`` with row 0 at the top."""

    prim_id: np.ndarray        #: int32 ``gl_PrimitiveID``, −1 background
    object_id: np.ndarray      #: int32 draw-call index, −1 background
    depth: np.ndarray          #: float32 ``gl_FragCoord.z`` from an R32F target, 1.0 background
    depth_buffer: np.ndarray   #: float32 contents of the 32-bit float depth buffer
    front_facing: np.ndarray   #: bool ``gl_FrontFacing``
    barycentric: np.ndarray | None = None  #: float32 (H, W, 3) perspective-correct, if asked

    @property
    def mask(self):
        return self.prim_id >= 0


@dataclass
class Layers:
    """Depth-peeled layers front to back, ``(K, H, W)``, row 0 at the top."""

    depth: np.ndarray          #: float32 window depth, 1.0 where a layer is empty
    prim_id: np.ndarray        #: int32, −1 empty
    object_id: np.ndarray      #: int32, −1 empty
    front_facing: np.ndarray   #: bool
    count: np.ndarray          #: (H, W) int32 number of non-empty layers

    def __len__(self):
        return self.depth.shape[0]


def _as_draws(draws):
    """One ``(clip, faces)`` pair or a list of them → list of float32/int32 contiguous pairs."""
    if isinstance(draws, tuple) and len(draws) == 2 and np.asarray(draws[0]).ndim == 2:
        draws = [draws]
    out = []
    for k, (clip, faces) in enumerate(draws):
        clip = np.ascontiguousarray(clip, dtype=np.float32)
        faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if clip.ndim != 2 or clip.shape[1] != 4:
            raise ValueError(f"draw {k}: clip positions must have shape (V, 4), got {clip.shape}")
        if faces.size and (faces.min() < 0 or faces.max() >= len(clip)):
            raise ValueError(f"draw {k}: face indices out of range")
        out.append((clip, faces.astype(np.int32)))
    return out


class GLScene:
    """Geometry uploaded once; :meth:`rasterize` and :meth:`peel` draw it (for timing too).

    Parameters
    ----------
    draws : (clip (V, 4) float32, faces (F, 3) int) or a list of them, drawn in order; the
        index of a draw is its object id.
    width, height : int
    cull : "none" | "back" | "front"
    barycentric : bool
        Expand the triangles to unindexed vertices carrying (1,0,0), (0,1,0), (0,0,1) so that the
        interpolated attribute is the perspective-correct barycentric coordinate.
    conventions : dict, optional
        The API conventions (module docstring): ``origin``, ``depth_range``, ``ndc_y``,
        ``depth_clamp``, ``depth_format``, ``depth_func`` (``less``, ``lequal``, ``greater``,
        ``gequal``; the peel needs ``less``), ``clear_depth``. Absent keys: OpenGL's defaults.
    """

    def __init__(self, draws, width, height, *, cull="none", barycentric=False,
                 conventions=None):
        if cull not in CULL_MODES:
            raise ValueError(f"cull must be one of {CULL_MODES}, got {cull!r}")
        conv = {**DEFAULT_CONVENTIONS, **(conventions or {})}
        unknown = set(conv) - set(DEFAULT_CONVENTIONS)
        if unknown:
            raise ValueError(f"unknown conventions {sorted(unknown)}")
        self.conventions = conv
        ctx = context()
        # make the oracle's context current: another context created in this process since
        # (refraster.gl's backend, e.g. by a test of its limits) is current otherwise, and the
        # raw GL calls and moderngl's draws would land in it
        ctx.__enter__()
        self.ctx = ctx
        self.width, self.height = int(width), int(height)
        self.cull = cull
        self.barycentric = bool(barycentric)
        self.prog = _STATE["programs"][self.barycentric]
        self._resources = []
        self._vaos = []
        self._n_faces = 0
        for k, (clip, faces) in enumerate(_as_draws(draws)):
            if len(faces):
                self._vaos.append((k, self._upload(clip, faces)))
                self._n_faces += len(faces)
        size = (self.width, self.height)
        self._depth = ctx.depth_texture(size)
        # moderngl allocates 24 bits; re-specify the same texture object as 32-bit float (or
        # the convention's depth_format)
        gl = _STATE["gl"]
        internal, kind = _DEPTH_FORMATS[conv["depth_format"]]
        gl["BindTexture"](_GL_TEXTURE_2D, self._depth.glo)
        gl["TexImage2D"](_GL_TEXTURE_2D, 0, internal, self.width, self.height, 0,
                         _GL_DEPTH_COMPONENT, kind, None)
        _check_gl(f"re-specifying the depth texture as {conv['depth_format']}")
        self._resources.append(self._depth)
        # two sets of colour targets, ping-ponged by the peel (each reads the other's depth)
        self._targets = [self._colour_targets() for _ in range(2)]
        self._fbos = [ctx.framebuffer(color_attachments=t, depth_attachment=self._depth)
                      for t in self._targets]
        self._resources += self._fbos
        self._query = ctx.query(samples=True)

    def _upload(self, clip, faces):
        ctx = self.ctx
        if self.barycentric:
            pos = ctx.buffer(np.ascontiguousarray(clip[faces.reshape(-1)]).tobytes())
            bary = ctx.buffer(np.tile(np.eye(3, dtype=np.float32), (len(faces), 1)).tobytes())
            vao = ctx.vertex_array(self.prog, [(pos, "4f", "in_clip"), (bary, "3f", "in_bary")])
            self._resources += [pos, bary, vao]
        else:
            pos = ctx.buffer(clip.tobytes())
            ibo = ctx.buffer(faces.tobytes())
            vao = ctx.vertex_array(self.prog, [(pos, "4f", "in_clip")], index_buffer=ibo,
                                   index_element_size=4)
            self._resources += [pos, ibo, vao]
        return vao

    def _colour_targets(self):
        ctx, size = self.ctx, (self.width, self.height)
        t = [ctx.texture(size, 1, dtype="f4"),   # gl_FragCoord.z
             ctx.texture(size, 1, dtype="i4"),   # primitive id
             ctx.texture(size, 1, dtype="i4"),   # object id
             ctx.texture(size, 1, dtype="i4")]   # front facing
        if self.barycentric:
            t.append(ctx.texture(size, 4, dtype="f4"))
        for tex in t:
            tex.filter = (_STATE["moderngl"].NEAREST, _STATE["moderngl"].NEAREST)
        self._resources += t
        return t

    def release(self):
        """Free the GL objects (the context stays)."""
        _STATE["parking"].use()
        for r in reversed(self._resources):
            r.release()
        self._resources = []
        self._vaos = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def _clear(self, which):
        gl = _STATE["gl"]
        self._fbos[which].use()
        one = (ctypes.c_float * 4)(1.0, 0.0, 0.0, 0.0)
        minus = (ctypes.c_int * 4)(-1, -1, -1, -1)
        zero = (ctypes.c_int * 4)(0, 0, 0, 0)
        gl["ClearBufferfv"](_GL_COLOR, 0, one)
        gl["ClearBufferiv"](_GL_COLOR, 1, minus)
        gl["ClearBufferiv"](_GL_COLOR, 2, minus)
        gl["ClearBufferiv"](_GL_COLOR, 3, zero)
        if self.barycentric:
            gl["ClearBufferfv"](_GL_COLOR, 4, (ctypes.c_float * 4)(0.0, 0.0, 0.0, 0.0))
        gl["ClearBufferfv"](_GL_DEPTH, 0, (ctypes.c_float * 4)(
            float(self.conventions["clear_depth"]), 0.0, 0.0, 0.0))
        _check_gl("clearing the targets")

    def _pass(self, which, peel, count_samples):
        """Clear target set ``which`` and draw every draw call into it."""
        mgl, ctx = _STATE["moderngl"], self.ctx
        conv, gl = self.conventions, _STATE["gl"]
        self._clear(which)
        ctx.enable_only(mgl.DEPTH_TEST | (mgl.CULL_FACE if self.cull != "none" else 0))
        ctx.depth_func = _DEPTH_FUNCS[conv["depth_func"]]
        if self.cull != "none":
            ctx.front_face = "ccw"
            ctx.cull_face = self.cull
        gl["ClipControl"](_CLIP_ORIGIN[conv["origin"]], _CLIP_DEPTH[conv["depth_range"]])
        (gl["Enable"] if conv["depth_clamp"] else gl["Disable"])(_GL_DEPTH_CLAMP)
        _check_gl("glClipControl / GL_DEPTH_CLAMP")
        self.prog["u_ndc_y_down"].value = conv["ndc_y"] == "down"
        try:
            return self._draw(peel, count_samples, which)
        finally:
            gl["ClipControl"](_CLIP_ORIGIN["lower_left"], _CLIP_DEPTH["negative_one_to_one"])
            gl["Disable"](_GL_DEPTH_CLAMP)

    def _draw(self, peel, count_samples, which):
        mgl = _STATE["moderngl"]
        self.prog["u_peel"].value = bool(peel)
        if peel:
            self._targets[1 - which][0].use(location=0)
            self.prog["u_prev"].value = 0
        if count_samples:
            with self._query:
                for k, vao in self._vaos:
                    self.prog["u_object"].value = k
                    vao.render(mgl.TRIANGLES)
            return self._query.samples
        for k, vao in self._vaos:
            self.prog["u_object"].value = k
            vao.render(mgl.TRIANGLES)
        return None

    def _read(self, tex, dtype, comps=1):
        a = np.frombuffer(tex.read(), dtype=dtype)
        shape = (self.height, self.width) if comps == 1 else (self.height, self.width, comps)
        a = a.reshape(shape)
        # GL's first row is the bottom under GL_LOWER_LEFT, the top under GL_UPPER_LEFT
        return np.ascontiguousarray(a if self.conventions["origin"] == "upper_left" else a[::-1])

    def rasterize(self):
        """One pass, depth test LESS → :class:`Frame`."""
        self._pass(0, peel=False, count_samples=False)
        t = self._targets[0]
        bary = self._read(t[4], np.float32, 4)[..., :3].copy() if self.barycentric else None
        return Frame(prim_id=self._read(t[1], np.int32),
                     object_id=self._read(t[2], np.int32),
                     depth=self._read(t[0], np.float32),
                     depth_buffer=self._read(self._depth, np.float32),
                     front_facing=self._read(t[3], np.int32) != 0,
                     barycentric=bary)

    def peel(self, max_layers=None, *, read=True):
        """Classic multi-pass depth peeling → :class:`Layers` (``None`` if ``read=False``).

        Pass k draws everything with depth test LESS, discarding fragments not strictly behind
        layer k−1 (``gl_FragCoord.z <= previous``). Stops after ``max_layers`` passes, or when a
        pass writes no sample (``max_layers=None``; an occlusion query counts them).
        ``read=False`` draws the passes without reading anything back (for timing).
        """
        if self.conventions["depth_func"] != "less":
            raise ValueError("the peel runs with depth_func 'less' only")
        if max_layers is not None and max_layers < 1:
            raise ValueError(f"max_layers must be positive, got {max_layers}")
        # a pixel cannot have more layers than there are triangles
        limit = max_layers if max_layers is not None else self._n_faces + 1
        depth, prim, obj, front = [], [], [], []
        for layer in range(limit):
            which = layer % 2
            samples = self._pass(which, peel=layer > 0,
                                 count_samples=max_layers is None or read)
            if samples == 0:
                break
            if read:
                t = self._targets[which]
                depth.append(self._read(t[0], np.float32))
                prim.append(self._read(t[1], np.int32))
                obj.append(self._read(t[2], np.int32))
                front.append(self._read(t[3], np.int32) != 0)
        if not read:
            self.ctx.finish()
            return None
        if not depth:
            shape = (0, self.height, self.width)
            return Layers(np.zeros(shape, np.float32), np.zeros(shape, np.int32),
                          np.zeros(shape, np.int32), np.zeros(shape, bool),
                          np.zeros(shape[1:], np.int32))
        prim = np.stack(prim)
        return Layers(depth=np.stack(depth), prim_id=prim, object_id=np.stack(obj),
                      front_facing=np.stack(front),
                      count=np.count_nonzero(prim >= 0, axis=0).astype(np.int32))


def rasterize(draws, width, height, *, cull="none", barycentric=False, conventions=None):
    """Rasterize ``draws`` (one ``(clip, faces)`` or a list) once with llvmpipe → :class:`Frame`
    (``conventions``: as :class:`GLScene`)."""
    with GLScene(draws, width, height, cull=cull, barycentric=barycentric,
                 conventions=conventions) as scene:
        return scene.rasterize()


def peel(draws, width, height, *, cull="none", max_layers=None):
    """Classic multi-pass depth peeling of ``draws`` with llvmpipe → :class:`Layers`."""
    with GLScene(draws, width, height, cull=cull) as scene:
        return scene.peel(max_layers)


# Importing this module is the availability check the ``oracle`` fixture relies on.
context()
