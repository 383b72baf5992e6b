"""The thin driver of refraster.gl: a headless EGL context (moderngl), the shaders of
``shaders/``, one scene package in, the golden's buffers out.

Conventions it implements (``docs/backends.md`` walks through them):

* ``clip = projection @ view @ model @ [x y z 1]`` with the package's row-major matrices,
  uploaded transposed (GL uniforms are column-major), one float32 matrix ``P·V·M`` per draw.
* Depth: a depth attachment of ``raster.depth_format`` (``GL_DEPTH_COMPONENT32F``, ``24`` or
  ``16``; moderngl's own is 24-bit), cleared to ``raster.clear_depth``, test
  ``raster.depth_func``; the window depth written out is ``gl_FragCoord.z`` into an ``R32F``
  target (bit-identical to a float32 depth buffer), or the depth buffer read back under the
  unorm formats (its quantised values) and under ``GL_DEPTH_CLAMP`` (the buffer holds the
  clamped depth; ``gl_FragCoord.z`` is not clamped: GL clamps at the depth test).
* The API conventions of the raster state (issue 39; ``docs/backends.md``, "Conventions"):
  ``glClipControl(origin, depth mode)`` from ``raster.origin`` and ``raster.depth_range``,
  ``GL_DEPTH_CLAMP`` from ``raster.depth_clamp``; ``raster.ndc_y = "down"`` (Vulkan) is a
  negation of the clip y in the vertex shader (GL's NDC y points up).
* Front faces: ``glFrontFace`` of ``raster.front_face`` (as the picture is seen) in every
  convention — GL negates the polygon area under ``GL_UPPER_LEFT``, and the y negation of
  ``ndc_y = "down"`` happens before GL judges facing. The arrays read back have GL's bottom row
  first under ``GL_LOWER_LEFT`` (flipped to row 0 at the top) and the top row first under
  ``GL_UPPER_LEFT`` (kept).
* Every target is cleared to zero (one clear of all attachments; zero bits are 0 in float and
  integer targets alike) and a ``covered`` channel of the integer target says which pixels a
  fragment wrote; background values (``docs/golden-schema.md``) are filled in after read-back.
* Integer ids come from ``gl_PrimitiveID`` (the face index within its draw call) and the draw's
  ``object_id`` uniform.

Faults (:data:`refraster.gl.FAULTS`) are test-only ``#define`` lines inserted after
``#version``; those of the conventions and of the catalogue of GPU bug classes
(:mod:`refraster.gl.catalogue`) are also switches of the driver's GL state and upload. A normal
run sets none.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np

from . import FAULTS, SUPPORTED_TECHNIQUES
from . import clipsurface
from .common import GLUnavailable, Unsupported, gl_function, programs, shader_source
from .cutaway import render_cutaway
from .cutaway import supports as cutaway_supports
from .edges import render_edges
from .edges import supports as edges_supports
from .halos import render_halos
from .halos import supports as halos_supports
from .msaa import render_msaa
from .msaa import sample_pattern as _sample_pattern
from .msaa import supports as msaa_supports
from .msaa_techniques import render_sampled
from .msaa_techniques import supports as sampled_supports
from .package import (CONVENTION_DEFAULTS, PackageError, conventions, matrix, read_map,
                      read_ply, read_scene)

__all__ = ["Backend", "GLUnavailable", "Unsupported", "programs", "shader_source"]

_GL_TEXTURE_2D = 0x0DE1
_GL_DEPTH_COMPONENT = 0x1902
_GL_DEPTH_COMPONENT32F = 0x8CAC
_GL_FLOAT = 0x1406
_GL_UNSIGNED_SHORT = 0x1403
_GL_UNSIGNED_INT = 0x1405
_GL_DEPTH_CLAMP = 0x864F
_GL_LOWER_LEFT, _GL_UPPER_LEFT = 0x8CA1, 0x8CA2
_GL_NEGATIVE_ONE_TO_ONE, _GL_ZERO_TO_ONE = 0x935E, 0x935F

#: ``raster.depth_format`` → (internal format, pixel type) of the depth attachment.
_DEPTH_FORMATS = {"float32": (_GL_DEPTH_COMPONENT32F, _GL_FLOAT),
                  "unorm24": (0x81A6, _GL_UNSIGNED_INT),      # GL_DEPTH_COMPONENT24
                  "unorm16": (0x81A5, _GL_UNSIGNED_SHORT)}    # GL_DEPTH_COMPONENT16
_CLIP_ORIGIN = {"lower_left": _GL_LOWER_LEFT, "upper_left": _GL_UPPER_LEFT}
_CLIP_DEPTH = {"negative_one_to_one": _GL_NEGATIVE_ONE_TO_ONE, "zero_to_one": _GL_ZERO_TO_ONE}
#: the reversed depth tests and what the planted ``reversed_z_less`` fault draws instead
_REVERSED = {"greater": "less", "gequal": "lequal"}

_DEPTH_FUNCS = {"less": "<", "lequal": "<=", "greater": ">", "gequal": ">=", "equal": "==",
                "notequal": "!=", "always": "1", "never": "0"}

#: Peel passes at most (a pixel's ray crosses each face at most once, so the face count
#: also bounds it).
MAX_PEEL_PASSES = 256


def _gl_functions():
    """glTexImage2D and glGetError through eglGetProcAddress (the context is EGL's)."""
    fn = gl_function
    u, i, p = ctypes.c_uint, ctypes.c_int, ctypes.c_void_p
    out = {"BindTexture": fn("glBindTexture", None, u, u),
           "TexImage2D": fn("glTexImage2D", None, u, i, i, i, i, i, u, u, p),
           "GetError": fn("glGetError", u), "Clear": fn("glClear", None, u),
           "Enable": fn("glEnable", None, u), "Disable": fn("glDisable", None, u)}
    try:       # OpenGL 4.5 core or ARB_clip_control; moderngl does not wrap it
        out["ClipControl"] = fn("glClipControl", None, u, u)
    except GLUnavailable:
        out["ClipControl"] = None
    return out


class Backend:
    """One headless context and the compiled programs.

    Parameters
    ----------
    faults : sequence of str
        Names of :data:`refraster.gl.FAULTS` to plant (tests only).
    threads : int, optional
        ``LP_NUM_THREADS`` for Mesa's llvmpipe; it must be set before the first context of the
        process exists, so it is set only when the variable is not set already.
    """

    def __init__(self, faults=(), threads=None):
        unknown = [f for f in faults if f not in FAULTS]
        if unknown:
            raise ValueError(f"unknown fault(s) {unknown}; known: {sorted(FAULTS)}")
        if threads is not None:
            os.environ.setdefault("LP_NUM_THREADS", str(int(threads)))
        try:
            import moderngl
        except Exception as exc:
            raise GLUnavailable(f"moderngl cannot be imported ({exc}); install the 'gl' extra: "
                                "pip install refraster[gl]") from None
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as exc:
            raise GLUnavailable("no headless OpenGL 3.3 context through EGL (libEGL and a "
                                f"driver such as Mesa's libegl-mesa0): {exc}") from None
        self.mgl, self.ctx = moderngl, ctx
        self.faults = tuple(faults)
        self._programs = {}         # the technique modules' programs: see programs()
        self.renderer = f"{ctx.info['GL_RENDERER']}; OpenGL {ctx.info['GL_VERSION']}"
        self._gl = _gl_functions()
        defines = [FAULTS[f][0] for f in self.faults]
        vert = shader_source("gbuffer.vert", defines)
        self.gbuffer = ctx.program(vertex_shader=vert,
                                   geometry_shader=shader_source("gbuffer.geom", defines),
                                   fragment_shader=shader_source("gbuffer.frag", defines))
        self.peeler = ctx.program(vertex_shader=vert,
                                  fragment_shader=shader_source("peel.frag", defines))
        vds = [*defines, "VDS"]
        self.vds = ctx.program(vertex_shader=shader_source("gbuffer.vert", vds),
                               geometry_shader=shader_source("gbuffer.geom", vds),
                               fragment_shader=shader_source("gbuffer.frag", vds))
        # moderngl binds the last framebuffer it made; park on this one before releasing others
        self._parking = ctx.framebuffer(color_attachments=[ctx.renderbuffer((1, 1))])

    # --- life cycle -----------------------------------------------------------------------
    def release(self):
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    # --- what it supports -----------------------------------------------------------------
    @staticmethod
    def supports(scene):
        """``None`` if the scene (a ``scene.json`` dict) can be rendered, else the reason."""
        technique = scene.get("technique")
        if technique == "msaa":           # issue 43: refraster/gl/msaa.py
            return msaa_supports(scene)
        if scene.get("raster", {}).get("samples", 1) != 1 and technique != "clipsurface":
            return sampled_supports(scene)   # issue 44: gl/msaa_techniques.py
        conv = conventions(scene.get("raster", {}))
        if technique not in ("render", "vds", "ldi") and conv != CONVENTION_DEFAULTS:
            changed = sorted(k for k in conv if conv[k] != CONVENTION_DEFAULTS[k])
            return (f"technique {technique!r} renders OpenGL's conventions only; the scene sets "
                    f"raster {', '.join(changed)}")
        if scene.get("exact_ties"):
            return (f"exact_ties: the golden decides pixel centres exactly on edges by "
                    f"raster.fill_rule {scene.get('raster', {}).get('fill_rule')!r}, which "
                    f"OpenGL cannot be asked for (llvmpipe owns a centre on a horizontal edge "
                    f"by the left/bottom rule under either origin)")
        if technique == "ldi" and conv["depth_format"] != "float32":
            return ("ldi: peeling compares gl_FragCoord.z with the previous layer's; it needs "
                    "depth_format 'float32'")
        if technique not in SUPPORTED_TECHNIQUES:
            return (f"technique {technique!r} is not implemented by the gl backend (it renders "
                    f"{', '.join(sorted(SUPPORTED_TECHNIQUES))})")
        p = scene.get("parameters", {})
        if technique == "ldi" and p.get("mode", "peel") != "peel":
            return f"ldi mode {p.get('mode')!r}: only classic peeling ('peel') is implemented"
        if technique == "edges":          # issue 26: refraster/gl/edges.py
            return edges_supports(scene)
        if technique == "cutaway":        # issue 26: refraster/gl/cutaway.py
            return cutaway_supports(scene)
        if technique == "halos4d":        # issue 26: refraster/gl/halos.py
            return halos_supports(scene)
        if technique == "vds" and (p.get("test") != "parity" or p.get("axis") not in ("z",)
                                   or p.get("rule", "parity") != "parity"):
            return ("vds: only the parity test over one sprite (test 'parity', one axis) is "
                    "implemented")
        if technique == "clipsurface":
            return clipsurface.supports(scene)
        return None

    def sample_pattern(self, samples):
        """This context's sample pattern at ``samples`` as a candidate states it
        (``{"samples": S, "positions": [[x, y], ...]}``, 1/16 pixel, y down as the picture is
        seen), or ``None`` without such a multisample framebuffer."""
        return _sample_pattern(self, samples)

    def render(self, package_dir, *, layers=None):
        """Render one scene package → ``{buffer name: array}`` as the golden stores them.

        ``layers`` (ldi scenes): the number of layer slots to write (the golden's K); the
        peel itself runs until a pass writes no sample, and ``layer_count`` counts every layer
        found, so a backend that finds more layers than the golden still fails the compare.
        Raises :class:`Unsupported` or :class:`refraster.gl.package.PackageError`.
        """
        loaded = self.load(package_dir)
        try:
            return self.draw(loaded, layers=layers)
        finally:
            self.unload(loaded)

    def load(self, package_dir):
        """Read a scene package and upload its meshes → an opaque handle for :meth:`draw`
        (timing a frame without the upload); free it with :meth:`unload`."""
        package_dir = Path(package_dir)
        scene = read_scene(package_dir)
        reason = self.supports(scene) or self._size_limit(scene)
        if reason is not None:
            raise Unsupported(reason)
        if scene["raster"].get("samples", 1) != 1 \
                and scene["technique"] not in ("msaa", "clipsurface"):
            # issue 44: multisampled G-buffers (refraster/gl/msaa_techniques.py)
            return {"scene": scene, "sampled": True, "draws": self._upload(package_dir, scene),
                    "textures": [], "package_dir": package_dir}
        if scene["technique"] == "clipsurface":            # issue 26 item 1
            return {"scene": scene, "clip": clipsurface.load(self, package_dir, scene),
                    "draws": [], "textures": []}
        loaded = {"scene": scene, "draws": self._upload(package_dir, scene), "textures": [],
                  "package_dir": package_dir}
        if scene["technique"] == "vds":
            loaded["textures"] = self._sprite(package_dir, scene)
        return loaded

    def _sprite(self, package_dir, scene):
        """The sprite's layers as a texture array (R32F, one slice per layer) and its counts
        (R32I); the package's maps have row 0 at the top, GL's first row is t = 0: flipped."""
        p = scene["parameters"]
        layers = [read_map(package_dir, scene, name) for name in p["sprite_depth"]]
        count = read_map(package_dir, scene, p["sprite_count"])
        h, w = count.shape
        if not layers or any(a.shape != (h, w) for a in layers):
            raise PackageError(f"{package_dir}: sprite maps must all be (h, w) = {(h, w)}")
        depth = np.ascontiguousarray(np.stack([a[::-1] for a in layers]), np.float32)
        arr = self.ctx.texture_array((w, h, len(layers)), 1, depth.tobytes(), dtype="f4")
        cnt = self.ctx.texture((w, h), 1, np.ascontiguousarray(count[::-1], np.int32).tobytes(),
                               dtype="i4")
        for tex in (arr, cnt):
            tex.filter = (self.mgl.NEAREST, self.mgl.NEAREST)
        return [arr, cnt]

    def draw(self, loaded, *, layers=None):
        """Render a :meth:`load`-ed scene → ``{buffer name: array}`` (see :meth:`render`)."""
        if "clip" in loaded:
            return clipsurface.draw(self, loaded["scene"], loaded["clip"])
        if "sampled" in loaded:                         # issue 44
            return render_sampled(self, loaded)
        if loaded["scene"]["technique"] == "edges":    # issue 26: refraster/gl/edges.py
            return render_edges(self, loaded, loaded.get("package_dir"))
        if loaded["scene"]["technique"] == "cutaway":  # issue 26: refraster/gl/cutaway.py
            return render_cutaway(self, loaded, loaded.get("package_dir"))
        if loaded["scene"]["technique"] == "halos4d":  # issue 26: refraster/gl/halos.py
            return render_halos(self, loaded, loaded.get("package_dir"))
        if loaded["scene"]["technique"] == "msaa":     # issue 43: refraster/gl/msaa.py
            return render_msaa(self, loaded)
        if loaded["scene"]["technique"] in ("render", "vds"):
            return self._gbuffer(loaded["scene"], loaded["draws"], loaded["textures"])
        return self._peel(loaded["scene"], loaded["draws"], layers)

    def unload(self, loaded):
        if "clip" in loaded:
            clipsurface.release(loaded.pop("clip"))
        for tex in loaded.get("textures", ()):
            tex.release()
        loaded["textures"] = []
        for d in loaded["draws"]:
            for obj in d["release"]:
                obj.release()
        loaded["draws"] = []

    def _size_limit(self, scene):
        """``None`` if this context can hold the scene's viewport, else the reason naming the
        size and the limit (the render targets are textures and the viewport is clamped, so a
        larger side would fail as GL error 0x501, GL_INVALID_VALUE)."""
        w, h = scene["viewport"]["width"], scene["viewport"]["height"]
        info = self.ctx.info
        limits = [("GL_MAX_TEXTURE_SIZE", int(info["GL_MAX_TEXTURE_SIZE"])),
                  ("GL_MAX_RENDERBUFFER_SIZE", int(info["GL_MAX_RENDERBUFFER_SIZE"]))]
        dims = info.get("GL_MAX_VIEWPORT_DIMS")
        if dims:
            limits.append(("GL_MAX_VIEWPORT_DIMS", int(min(dims))))
        name, limit = min(limits, key=lambda item: item[1])
        if max(w, h) > limit:
            return (f"viewport {w}x{h} is larger than this OpenGL's limit of {limit} pixels "
                    f"per side ({name} = {limit}, {info['GL_RENDERER']})")
        return None

    # --- geometry ---------------------------------------------------------------------------
    def _upload(self, package_dir, scene):
        view = matrix(scene["camera"]["view"], "camera.view")
        proj = matrix(scene["camera"]["projection"], "camera.projection")
        smooth = scene["raster"]["normals"] == "smooth"
        faults = self.faults
        if "projection_left_handed" in faults:   # planted fault: eye z negated
            proj = proj @ np.diag([1.0, 1.0, -1.0, 1.0])
        out, packed = [], []
        for i, d in enumerate(scene["draws"]):
            vertices, faces, normals = read_ply(package_dir / d["mesh"], d.get("n_vertices"),
                                                d.get("n_faces"))
            if smooth and normals is None:
                raise PackageError(f"{package_dir / d['mesh']}: the scene is smooth-shaded but "
                                   "the PLY has no vertex normals")
            if normals is None:
                normals = np.zeros_like(vertices)
            model = matrix(d["model"], f"draws[{i}].model")
            mv = view @ model
            try:
                nmat = np.linalg.inv(mv[:3, :3]).T
            except np.linalg.LinAlgError:
                raise PackageError(f"draws[{i}]: view·model is singular") from None
            if "normal_matrix_modelview" in faults:   # planted fault: not the inverse transpose
                nmat = mv[:3, :3]
            if "degenerate_dropped" in faults and len(faces):   # planted fault
                tri = vertices[faces].astype(np.float64)
                area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                      axis=1)
                faces = faces[area > 0]
            if "index_offset" in faults and len(faces):   # planted fault: one index late
                faces = np.roll(faces.ravel(), -1).reshape(faces.shape)
            if "base_vertex_ignored" in faults:   # planted fault: packed, no base vertex
                packed.append(np.concatenate([vertices, normals], 1))
                data = np.concatenate(packed)
            else:
                data = np.concatenate([vertices, normals], 1)
            ctx = self.ctx
            vbo = ctx.buffer(np.ascontiguousarray(data, np.float32).tobytes())
            index_size = 4
            if "index16" in faults:   # planted fault: 16-bit indices, truncated
                index_size = 2
                ibo = ctx.buffer(faces.astype(np.uint16).tobytes()) if len(faces) else None
            else:
                ibo = ctx.buffer(faces.tobytes()) if len(faces) else None
            out.append(dict(
                object_id=d["object_id"], n_faces=len(faces), vbo=vbo, ibo=ibo, model=model,
                index_size=index_size, mirrored=bool(np.linalg.det(model[:3, :3]) < 0),
                mvp=(proj @ mv).astype(np.float32), mv=mv.astype(np.float32),
                nmat=nmat.astype(np.float32), release=[b for b in (vbo, ibo) if b is not None],
                vaos={}))
        return out

    def _vao(self, draw, prog):
        key = id(prog)
        if key not in draw["vaos"]:
            # the peel's compiled program drops the unused normal attribute: skip its bytes
            layout = ((draw["vbo"], "3f 3f", "in_pos", "in_normal") if "in_normal" in prog
                      else (draw["vbo"], "3f 12x", "in_pos"))
            vao = self.ctx.vertex_array(prog, [layout], index_buffer=draw["ibo"],
                                        index_element_size=draw.get("index_size", 4))
            draw["vaos"][key] = vao
            draw["release"].insert(0, vao)
        return draw["vaos"][key]

    @staticmethod
    def _set(prog, name, value):
        if name in prog:   # the compiler may drop an unused uniform
            prog[name].value = value

    def _write(self, prog, name, m):
        if name in prog:
            # GL reads uniforms column-major: the row-major matrix is uploaded transposed
            # (not with the planted fault matrix_row_major)
            data = m if "matrix_row_major" in self.faults else m.T
            prog[name].write(np.ascontiguousarray(data, np.float32).tobytes())

    def _draw(self, prog, draw, palette=None):
        """One draw of a G-buffer program: the draw's matrices and object id as uniforms, its
        palette colour as ``u_base`` when ``palette`` is given, then its triangles."""
        self._write(prog, "u_mvp", draw["mvp"])
        self._write(prog, "u_mv", draw["mv"])
        self._write(prog, "u_nmat", draw["nmat"])
        self._set(prog, "u_object", int(draw["object_id"]))
        if palette is not None:
            self._set(prog, "u_base", tuple(float(c) for c in
                                            palette[draw["object_id"] % len(palette)]))
        self._vao(draw, prog).render(self.mgl.TRIANGLES)

    def _depth_attachment(self, size, depth_format="float32"):
        """A depth texture re-specified as ``GL_DEPTH_COMPONENT32F`` (moderngl's is 24-bit),
        or ``24`` / ``16`` for ``depth_format`` ``"unorm24"`` / ``"unorm16"``."""
        if "depth_unorm16_declared_float" in self.faults:   # planted fault
            depth_format = "unorm16"
        internal, kind = _DEPTH_FORMATS[depth_format]
        tex = self.ctx.depth_texture(size)
        gl = self._gl
        while gl["GetError"]():
            pass
        gl["BindTexture"](_GL_TEXTURE_2D, tex.glo)
        gl["TexImage2D"](_GL_TEXTURE_2D, 0, internal, size[0], size[1], 0,
                         _GL_DEPTH_COMPONENT, kind, None)
        err = gl["GetError"]()
        if err:
            tex.release()
            raise GLUnavailable(f"glTexImage2D(depth {depth_format}, {internal:#x}) failed: GL "
                                f"error {err:#x}")
        return tex

    def _clear_depth(self, raster):
        """The depth clear value: ``raster.clear_depth`` (1 under a reversed depth test with
        the planted ``reversed_z_clear_one`` fault)."""
        if "reversed_z_clear_one" in self.faults and raster["depth_func"] in _REVERSED:
            return 1.0
        return float(raster["clear_depth"])

    def _state(self, scene):
        """The fixed-function state of ``scene``'s raster fields: depth test, culling, front
        face, ``glClipControl`` and ``GL_DEPTH_CLAMP`` (set for every frame: the context is
        shared by the scenes)."""
        mgl, ctx, raster = self.mgl, self.ctx, scene["raster"]
        conv = conventions(raster)
        cull = raster["cull"]
        ctx.enable_only(mgl.DEPTH_TEST | (mgl.CULL_FACE if cull != "none" else 0))
        func = raster["depth_func"]
        if "reversed_z_less" in self.faults:
            func = _REVERSED.get(func, func)
        if "depth_func_always" in self.faults:
            func = "always"
        ctx.depth_func = _DEPTH_FUNCS[func]
        # glFrontFace is judged as the picture is seen in every convention: GL negates the
        # polygon area under GL_UPPER_LEFT, and ndc_y="down" is negated in the vertex shader
        # before GL judges facing (docs/backends.md, "Conventions")
        front = raster["front_face"]
        if "winding_not_flipped" in self.faults and conv["origin"] == "upper_left":
            front = {"ccw": "cw", "cw": "ccw"}[front]
        if "front_face_inverted" in self.faults:
            front = {"ccw": "cw", "cw": "ccw"}[front]
        ctx.front_face = front
        if cull != "none":
            if "cull_face_inverted" in self.faults:
                cull = {"back": "front", "front": "back"}[cull]
            ctx.cull_face = cull
        self._conventions(conv)

    def _conventions(self, conv):
        """``glClipControl`` and ``GL_DEPTH_CLAMP`` for the convention fields ``conv``."""
        gl = self._gl
        depth_mode = conv["depth_range"]
        if "depth_remap_on_zero_to_one" in self.faults:
            depth_mode = "negative_one_to_one"
        if gl["ClipControl"] is None:
            if (conv["origin"], depth_mode) != ("lower_left", "negative_one_to_one"):
                raise Unsupported("this OpenGL has no glClipControl (4.5 or ARB_clip_control): "
                                  f"origin {conv['origin']!r}, depth_range "
                                  f"{conv['depth_range']!r} cannot be drawn")
        else:
            while gl["GetError"]():
                pass
            gl["ClipControl"](_CLIP_ORIGIN[conv["origin"]], _CLIP_DEPTH[depth_mode])
            err = gl["GetError"]()
            if err:
                raise Unsupported(f"glClipControl failed: GL error {err:#x}")
        clamp = conv["depth_clamp"] or "depth_clamp_always" in self.faults
        (gl["Enable"] if clamp else gl["Disable"])(_GL_DEPTH_CLAMP)

    def _default_conventions(self):
        """OpenGL's conventions again (after a frame that changed them)."""
        self._conventions(dict(CONVENTION_DEFAULTS))

    def _read(self, tex, dtype, comps, size, *, top_first=False):
        """A target's pixels as ``(H, W, comps)`` with row 0 at the top of the picture: GL's
        first row is the bottom under ``GL_LOWER_LEFT`` (flipped), the top under
        ``GL_UPPER_LEFT`` (``top_first``; kept)."""
        w, h = size
        a = np.frombuffer(tex.read(), dtype=dtype).reshape(h, w, comps)
        if "readback_rows_unflipped" in self.faults:   # planted fault: GL's rows kept
            top_first = True
        return np.ascontiguousarray(a if top_first else a[::-1])

    @staticmethod
    def _top_first(scene):
        return conventions(scene["raster"])["origin"] == "upper_left"

    def _read_gbuffer(self, scene, targets, size):
        """The G-buffer's first six targets (window depth, eye depth, normal, barycentric,
        colour, ids + covered) read back → ``({buffer: array}, covered)``: the golden's eight
        G-buffer buffers with the background values (``docs/golden-schema.md``) filled in where
        no fragment was written. Used by :meth:`_gbuffer` and the cutaway's clipped G-buffer."""
        top = self._top_first(scene)
        win, eye = (self._read(t, "<f4", 1, size, top_first=top)[..., 0] for t in targets[:2])
        normal, bary, color = (self._read(t, "<f4", 4, size, top_first=top)[..., :3]
                               for t in targets[2:5])
        ids = self._read(targets[5], "<i4", 4, size, top_first=top)
        covered = ids[..., 3] == 1
        c3 = covered[..., None]
        raster = scene["raster"]
        bg = np.asarray(scene["shading"]["background"], np.float32)
        return {
            "depth": np.where(covered, win, np.float32(raster["clear_depth"])).astype(np.float32),
            "eye_depth": np.where(covered, eye, np.float32(np.inf)).astype(np.float32),
            "normal": np.where(c3, normal, 0).astype(np.float32),
            "prim_id": np.where(covered, ids[..., 0], -1).astype(np.int32),
            "object_id": np.where(covered, ids[..., 1], -1).astype(np.int32),
            "front_facing": covered & (ids[..., 2] == 1),
            "barycentric": np.where(c3, bary, 0).astype(np.float32),
            "color": np.where(c3, color, bg).astype(np.float32),
        }, covered

    # --- the G-buffer -----------------------------------------------------------------------
    def _gbuffer(self, scene, draws, textures=()):
        ctx = self.ctx
        vds = scene["technique"] == "vds"
        prog = self.vds if vds else self.gbuffer
        size = (scene["viewport"]["width"], scene["viewport"]["height"])
        raster, shading = scene["raster"], scene["shading"]
        targets = [ctx.texture(size, 1, dtype="f4"), ctx.texture(size, 1, dtype="f4"),
                   ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="f4"),
                   ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="i4")]
        if vds:
            targets.append(ctx.texture(size, 1, dtype="i4"))     # inside (parity test)
            textures[0].use(location=0)
            textures[1].use(location=1)
            self._set(prog, "u_sprite_depth", 0)
            self._set(prog, "u_sprite_count", 1)
            sprite = matrix(scene["parameters"]["sprite_matrix"], "parameters.sprite_matrix")
        conv = conventions(raster)
        depth = self._depth_attachment(size, conv["depth_format"])
        fbo = ctx.framebuffer(color_attachments=targets, depth_attachment=depth)
        try:
            fbo.use()
            ctx.viewport = (0, 0, *size)
            fbo.clear(0.0, 0.0, 0.0, 0.0, depth=self._clear_depth(raster))
            self._state(scene)
            self._set(prog, "u_ndc_y_down", conv["ndc_y"] == "down")
            self._set(prog, "u_light", tuple(float(shading[k]) for k in
                                             ("ambient", "diffuse", "specular", "shininess")))
            self._set(prog, "u_smooth", raster["normals"] == "smooth")
            self._set(prog, "u_viewport", tuple(float(s) for s in size))
            self._set(prog, "u_upper_left", conv["origin"] == "upper_left")
            palette = shading["palette"]
            front = ctx.front_face
            for k, d in enumerate(draws):
                if not d["n_faces"]:
                    continue
                if "depth_cleared_per_draw" in self.faults and k:   # planted fault
                    self._gl["Clear"](0x100)                         # GL_DEPTH_BUFFER_BIT
                if "mirror_compensated" in self.faults:   # planted fault
                    ctx.front_face = ({"ccw": "cw", "cw": "ccw"}[front] if d["mirrored"]
                                      else front)
                self._write(prog, "u_mvp", d["mvp"])
                self._write(prog, "u_mv", d["mv"])
                self._write(prog, "u_nmat", d["nmat"])
                if vds:
                    self._write(prog, "u_tmat", (sprite @ d["model"]).astype(np.float32))
                if "object_id_stale" not in self.faults or k == 0:   # planted fault: first only
                    self._set(prog, "u_object", int(d["object_id"]))
                self._set(prog, "u_base", tuple(float(c) for c in
                                                palette[d["object_id"] % len(palette)]))
                self._vao(d, prog).render(self.mgl.TRIANGLES)
            ctx.finish()
            out, covered = self._read_gbuffer(scene, targets, size)
            top = self._top_first(scene)
            inside = (self._read(targets[6], "<i4", 1, size, top_first=top)[..., 0] if vds
                      else None)
            if conv["depth_format"] != "float32" or conv["depth_clamp"] \
                    or "depth_unorm16_declared_float" in self.faults:
                # the candidate's depth is its depth buffer: k / (2^n − 1), read as float, or
                # under depth clamp the clamped depth (gl_FragCoord.z is not clamped)
                stored = self._read(depth, "<f4", 1, size, top_first=top)[..., 0]
                out["depth"] = np.where(covered, stored, out["depth"]).astype(np.float32)
        finally:
            self._default_conventions()
            self._parking.use()
            for obj in (fbo, depth, *targets):
                obj.release()
        if vds:
            out["inside"] = covered & (inside == 1)
        return out

    # --- classic depth peeling --------------------------------------------------------------
    def _peel(self, scene, draws, layers):
        mgl, ctx, prog = self.mgl, self.ctx, self.peeler
        size = (scene["viewport"]["width"], scene["viewport"]["height"])
        raster = scene["raster"]
        if raster["depth_func"] not in ("less", "greater"):
            raise Unsupported(f"peeling with depth_func {raster['depth_func']!r}: only 'less' "
                              "and 'greater' (reversed-Z, peeled from the largest depth)")
        conv = conventions(raster)
        top = conv["origin"] == "upper_left"
        max_layers = scene.get("parameters", {}).get("max_layers")
        faces = sum(d["n_faces"] for d in draws)
        limit = min(MAX_PEEL_PASSES, faces + 1) if max_layers is None else int(max_layers)
        sets = []
        for _ in range(2):   # ping-pong: each pass reads the other set as the previous layer
            t = [ctx.texture(size, 1, dtype="f4"), ctx.texture(size, 4, dtype="i4")]
            for tex in t:
                tex.filter = (mgl.NEAREST, mgl.NEAREST)
            sets.append(t)
        depth = self._depth_attachment(size, conv["depth_format"])
        fbos = [ctx.framebuffer(color_attachments=t, depth_attachment=depth) for t in sets]
        query = ctx.query(samples=True)
        found_depth, found_ids = [], []
        try:
            ctx.viewport = (0, 0, *size)
            self._set(prog, "u_viewport", tuple(float(s) for s in size))
            self._set(prog, "u_prev_depth", 0)
            self._set(prog, "u_prev_ids", 1)
            self._set(prog, "u_ndc_y_down", conv["ndc_y"] == "down")
            self._set(prog, "u_reversed", raster["depth_func"] == "greater")
            for k in range(limit):
                cur, prev = k % 2, 1 - k % 2
                fbos[cur].use()
                fbos[cur].clear(0.0, 0.0, 0.0, 0.0, depth=self._clear_depth(raster))
                self._state(scene)
                self._set(prog, "u_peel", k > 0)
                sets[prev][0].use(location=0)
                sets[prev][1].use(location=1)
                with query:
                    for d in draws:
                        if not d["n_faces"]:
                            continue
                        self._write(prog, "u_mvp", d["mvp"])
                        self._write(prog, "u_mv", d["mv"])
                        self._set(prog, "u_object", int(d["object_id"]))
                        self._vao(d, prog).render(mgl.TRIANGLES)
                if query.samples == 0:
                    break
                found_depth.append(self._read(sets[cur][0], "<f4", 1, size,
                                              top_first=top)[..., 0])
                found_ids.append(self._read(sets[cur][1], "<i4", 4, size, top_first=top))
        finally:
            self._default_conventions()
            self._parking.use()
            for obj in (*fbos, depth, *sets[0], *sets[1]):
                obj.release()
        w, h = size
        k_out = len(found_depth) if layers is None else int(layers)
        clear = np.float32(raster["clear_depth"])
        out_depth = np.full((h, w, k_out), clear, np.float32)
        out_prim = np.full((h, w, k_out), -1, np.int32)
        out_front = np.zeros((h, w, k_out), np.bool_)
        count = np.zeros((h, w), np.int32)
        for k, (dep, ids) in enumerate(zip(found_depth, found_ids)):
            covered = ids[..., 3] == 1
            count += covered
            if k < k_out:
                out_depth[..., k] = np.where(covered, dep, clear)
                out_prim[..., k] = np.where(covered, ids[..., 0], -1)
                out_front[..., k] = covered & (ids[..., 2] == 1)
        return {"layer_depth": out_depth, "layer_prim_id": out_prim,
                "layer_front_facing": out_front, "layer_count": count}
