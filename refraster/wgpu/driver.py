"""The thin driver of refraster.wgpu: a WebGPU device with the default limits, the WGSL of
``shaders/gbuffer.wgsl``, one scene package in, the golden's buffers out.

Conventions it implements (``docs/backends.md``, "refraster.wgpu", walks through them):

* ``clip = projection @ view @ model @ [x y z 1]`` with the package's row-major matrices,
  uploaded transposed (WGSL matrices are column-major), one float32 matrix ``P·V·M`` per draw.
* The scene's convention (``scene.json``'s ``"raster"``; a field that is absent has its
  default, :data:`CONVENTION_DEFAULTS`): WebGPU clips at ``0 ≤ z ≤ w`` and puts NDC y = +1 at
  the image's top row; an OpenGL projection (``depth_range`` ``negative_one_to_one``) is
  remapped in the vertex shader (``z' = (z + w)/2``), a Vulkan one (``ndc_y`` ``down``) has
  its clip y negated. ``origin`` changes no pixel of the picture (only which triangle owns an
  exact tie, which the goldens allow either way). ``depth_clamp`` is WebGPU's
  ``unclippedDepth`` (feature ``depth-clip-control``); ``depth_format`` picks the depth
  attachment (``depth32float``, ``depth24plus``, ``depth16unorm``); under the unorm formats the
  candidate's ``depth`` is the depth buffer itself, read with ``textureLoad`` (``k/(2^n − 1)``;
  WebGPU cannot copy ``depth24plus`` to a buffer). The fill rule (``raster.fill_rule``) is not a
  WebGPU setting: the adapter's decides exact ties, which the goldens allow either way.
* Front faces as the scene says, counter-clockwise as the picture is seen (WebGPU's
  ``frontFace`` is defined on the framebuffer, whose row 0 is the image's top row); the arrays
  read back have row 0 at the top already: no flip.
* Every draw is de-indexed; each corner carries its face's index (within the draw) and flat
  face normal (``@interpolate(flat)``). Colour targets are cleared to zero and a ``covered``
  channel says which pixels a fragment wrote; background values are filled in after read-back.
* Three G-buffer passes, each within WebGPU's default 32 bytes per sample, each re-drawing the
  scene from a cleared depth buffer with the same pipeline state and an ``@invariant``
  position, so the same fragment wins every pass.

Faults (:data:`refraster.wgpu.FAULTS`) are test-only; a normal run sets none.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..gl.package import PackageError, matrix, read_map, read_ply, read_scene
from . import FAULTS, LATER_TECHNIQUES, SUPPORTED_TECHNIQUES, TECHNIQUE_FAULTS
from . import clipsurface, cutaway, edges, halos
from .common import gbuffer_arrays
from .device import WGPUUnavailable, adapter, create_device, describe, unclipped_depth

__all__ = ["Backend", "Unsupported", "WGPUUnavailable", "CONVENTION_DEFAULTS", "SHADER"]

SHADER = Path(__file__).with_name("shaders") / "gbuffer.wgsl"
#: The depth buffer read back as float under the unorm depth formats.
DEPTH_READ_SHADER = Path(__file__).with_name("shaders") / "depth_read.wgsl"

#: The convention fields of ``scene.json``'s ``"raster"`` and their values when absent
#: (OpenGL's, which every scene package had before the fields existed).
CONVENTION_DEFAULTS = {"depth_range": "negative_one_to_one", "origin": "lower_left",
                       "ndc_y": "up", "depth_clamp": False, "depth_format": "float32",
                       "depth_write": True, "front_face": "ccw"}
_CHOICES = {"depth_range": ("negative_one_to_one", "zero_to_one"),
            "origin": ("lower_left", "upper_left"), "ndc_y": ("up", "down"),
            "depth_clamp": (False, True), "depth_format": ("float32", "unorm24", "unorm16"),
            "depth_write": (True, False), "front_face": ("ccw", "cw")}

_COMPARE = {"less": "less", "lequal": "less-equal", "greater": "greater",
            "gequal": "greater-equal", "equal": "equal", "notequal": "not-equal",
            "always": "always", "never": "never"}
_DEPTH_FORMAT = {"float32": "depth32float", "unorm24": "depth24plus",
                 "unorm16": "depth16unorm"}
#: The depth functions a peel follows: ascending depth (less, lequal), descending (greater,
#: gequal: reversed-Z).
_PEEL_FUNCS = ("less", "lequal", "greater", "gequal")

#: Peel passes at most (a pixel's ray crosses each face at most once).
MAX_PEEL_PASSES = 256

#: One de-indexed vertex: position, vertex normal, flat face normal, face index (40 bytes).
VERTEX = np.dtype([("pos", "<f4", 3), ("vnormal", "<f4", 3), ("fnormal", "<f4", 3),
                   ("face", "<i4")])
#: The uniform block ``Draw`` of gbuffer.wgsl (304 bytes).
_UNIFORM_BYTES = 304

#: The G-buffer's passes: fragment entry point → colour target formats (bytes per sample:
#: 24, 32, 16; 20 with the parity test's ``inside``).
GBUFFER_PASSES = {
    "fs_ids": ("r32float", "r32float", "rgba32sint"),
    "fs_surface": ("rgba32float", "rgba32float"),
    "fs_shade": ("rgba32float",),
}
_VDS_SHADE = ("fs_shade_vds", ("rgba32float", "r32sint"))
_PEEL_TARGETS = ("r32float", "rgba32sint")
_BYTES = {"r32float": 4, "r32sint": 4, "rgba32float": 16, "rgba32sint": 16}


class Unsupported(Exception):
    """The scene's technique (or a setting of it) is not implemented by this backend."""


def convention(scene):
    """The scene's convention fields with their defaults filled in; a bad value is a
    :class:`PackageError` naming the field."""
    raster = scene["raster"]
    out = {}
    for key, default in CONVENTION_DEFAULTS.items():
        value = raster.get(key, default)
        if value not in _CHOICES[key] or type(value) is not type(default):
            raise PackageError(f"scene.json: raster.{key} must be one of "
                               f"{list(_CHOICES[key])}, got {value!r}")
        out[key] = value
    return out


def _read_scene(package_dir):
    """``scene.json`` through the package reader (it checks every raster field, the
    conventions' included)."""
    return read_scene(package_dir)


class Backend:
    """One WebGPU device (default limits) and the compiled pipelines.

    Parameters
    ----------
    faults : sequence of str
        Names of :data:`refraster.wgpu.FAULTS` to plant (tests only).
    features : sequence of str, optional
        Optional features to ask for (names of
        :data:`refraster.wgpu.device.OPTIONAL_FEATURES`); default: ``depth-clip-control``
        when the adapter offers it (scenes with ``depth_clamp`` are skipped without it).
    threads : int, optional
        ``LP_NUM_THREADS`` for Mesa's lavapipe; it must be set before the first device of the
        process exists, so it is set only when the variable is not set already.
    """

    def __init__(self, faults=(), features=None, threads=None):
        unknown = [f for f in faults if f not in FAULTS and f not in TECHNIQUE_FAULTS]
        if unknown:
            raise ValueError(f"unknown fault(s) {unknown}; known: "
                             f"{sorted([*FAULTS, *TECHNIQUE_FAULTS])}")
        self.faults = tuple(faults)
        if threads is not None:
            os.environ.setdefault("LP_NUM_THREADS", str(int(threads)))
        self.wgpu, self.adapter = adapter()
        if features is None:
            features = [f for f in ("depth-clip-control",) if f in self.adapter.features]
        self.features = tuple(features)
        try:
            self.device = create_device(self.adapter, self.features)
        except WGPUUnavailable:
            raise
        except Exception as exc:
            raise WGPUUnavailable(f"no WebGPU device with the default limits: {exc}") from None
        self.renderer = describe(self.adapter, self.wgpu)
        self.module_code = SHADER.read_text(encoding="utf-8")
        self.module = self.device.create_shader_module(code=self.module_code)
        self.depth_module = self.device.create_shader_module(
            code=DEPTH_READ_SHADER.read_text(encoding="utf-8"))
        self._pipelines = {}
        self._depth_pipeline = None
        self._layouts()

    # --- life cycle -----------------------------------------------------------------------
    def release(self):
        if self.device is not None:
            self.device.destroy()
            self.device = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    # --- what it supports -----------------------------------------------------------------
    def supports(self, scene):
        """``None`` if the scene (a ``scene.json`` dict) can be rendered, else the reason."""
        technique = scene.get("technique")
        if technique in LATER_TECHNIQUES:
            return (f"technique {technique!r} is not implemented by the wgpu backend yet "
                    "(issue 45: 4D halos in WGSL)")
        if technique not in SUPPORTED_TECHNIQUES:
            return (f"technique {technique!r} is not implemented by the wgpu backend (it "
                    f"renders {', '.join(sorted(SUPPORTED_TECHNIQUES))})")
        conv = convention(scene)
        if conv["depth_clamp"] and "depth-clip-control" not in self.features:
            return ("raster.depth_clamp needs WebGPU's optional feature depth-clip-control, "
                    "which this device was not given")
        p = scene.get("parameters", {})
        if technique == "ldi":
            if p.get("mode", "peel") != "peel":
                return f"ldi mode {p.get('mode')!r}: only classic peeling ('peel') is implemented"
            if scene["raster"]["depth_func"] not in _PEEL_FUNCS:
                return (f"peeling with depth_func {scene['raster']['depth_func']!r}: only "
                        f"{', '.join(repr(f) for f in _PEEL_FUNCS)} define a front-to-back "
                        "order")
            if conv["depth_format"] != "float32":
                return (f"peeling with raster.depth_format {conv['depth_format']!r}: the peel "
                        "compares with the previous layer's float32 depth; only 'float32'")
        if technique == "vds" and (p.get("test") != "parity" or p.get("axis") not in ("z",)
                                   or p.get("rule", "parity") != "parity"):
            return ("vds: only the parity test over one sprite (test 'parity', one axis) is "
                    "implemented")
        if technique == "edges":                # issue 45: refraster/wgpu/edges.py
            return edges.supports(scene)
        if technique == "clipsurface":          # issue 45: refraster/wgpu/clipsurface.py
            return clipsurface.supports(scene)
        if technique == "cutaway":              # issue 45: refraster/wgpu/cutaway.py
            return cutaway.supports(scene)
        if technique == "halos4d":              # issue 45: refraster/wgpu/halos.py
            return halos.supports(scene)
        return None

    def render(self, package_dir, *, layers=None):
        """Render one scene package → ``{buffer name: array}`` as the golden stores them.

        ``layers`` (ldi scenes): the number of layer slots to write (the golden's K); the
        peel runs until a pass writes no sample, and ``layer_count`` counts every layer found.
        Raises :class:`Unsupported` or :class:`refraster.gl.package.PackageError`.
        """
        loaded = self.load(package_dir)
        try:
            return self.draw(loaded, layers=layers)
        finally:
            self.unload(loaded)

    def load(self, package_dir):
        """Read a scene package and upload its meshes → an opaque handle for :meth:`draw`."""
        package_dir = Path(package_dir)
        scene = _read_scene(package_dir)
        reason = self.supports(scene)
        if reason is not None:
            raise Unsupported(reason)
        loaded = {"scene": scene, "conv": convention(scene),
                  "draws": self._upload(package_dir, scene), "sprite": None}
        if scene["technique"] == "vds":
            loaded["sprite"] = self._sprite(package_dir, scene)
        if scene["technique"] in ("edges", "clipsurface", "cutaway", "halos4d"):  # issue 45
            loaded["package_dir"] = package_dir
        if scene["technique"] == "clipsurface":
            loaded["clip"] = clipsurface.load(self, package_dir, scene)
        return loaded

    def draw(self, loaded, *, layers=None):
        """Render a :meth:`load`-ed scene → ``{buffer name: array}`` (see :meth:`render`)."""
        if loaded["scene"]["technique"] == "ldi":
            return self._peel(loaded, layers)
        if loaded["scene"]["technique"] == "edges":                # issue 45
            return edges.render(self, loaded, loaded["package_dir"])
        if loaded["scene"]["technique"] == "clipsurface":
            return clipsurface.draw(self, loaded)
        if loaded["scene"]["technique"] == "cutaway":
            return cutaway.render(self, loaded, loaded["package_dir"])
        if loaded["scene"]["technique"] == "halos4d":
            return halos.render(self, loaded, loaded["package_dir"])
        return self._gbuffer(loaded)

    def unload(self, loaded):
        for d in loaded.get("draws", ()):
            for buf in (d["vbo"], d["ubo"]):
                if buf is not None:
                    buf.destroy()
        for tex in loaded.get("sprite") or ():
            tex.destroy()
        clipsurface.release(loaded.pop("clip", None))           # issue 45
        loaded["draws"], loaded["sprite"] = [], None

    # --- geometry ---------------------------------------------------------------------------
    def _upload(self, package_dir, scene):
        wgpu, dev = self.wgpu, self.device
        view = matrix(scene["camera"]["view"], "camera.view")
        proj = matrix(scene["camera"]["projection"], "camera.projection")
        smooth = scene["raster"]["normals"] == "smooth"
        shading, palette = scene["shading"], scene["shading"]["palette"]
        vp = scene["viewport"]
        sprite = None
        if scene["technique"] == "vds":
            sprite = matrix(scene["parameters"]["sprite_matrix"], "parameters.sprite_matrix")
        out = []
        for i, d in enumerate(scene["draws"]):
            vertices, faces, normals = read_ply(package_dir / d["mesh"], d.get("n_vertices"),
                                                d.get("n_faces"))
            if smooth and normals is None:
                raise PackageError(f"{package_dir / d['mesh']}: the scene is smooth-shaded but "
                                   "the PLY has no vertex normals")
            model = matrix(d["model"], f"draws[{i}].model")
            mv = view @ model
            try:
                nmat = np.linalg.inv(mv[:3, :3]).T
            except np.linalg.LinAlgError:
                raise PackageError(f"draws[{i}]: view·model is singular") from None
            data = self._deindex(vertices, faces, normals)
            vbo = (dev.create_buffer_with_data(data=data.tobytes(),
                                               usage=wgpu.BufferUsage.VERTEX)
                   if len(data) else None)
            n4 = np.eye(4)
            n4[:3, :3] = nmat
            tmat = np.eye(4) if sprite is None else sprite @ model
            block = np.zeros(_UNIFORM_BYTES // 4, np.float32)
            for k, m in enumerate((proj @ mv, mv, n4, tmat)):
                block[16 * k:16 * (k + 1)] = np.asarray(m, np.float32).T.reshape(-1)
            block[64:67] = palette[d["object_id"] % len(palette)]
            block[68:72] = [shading[k] for k in ("ambient", "diffuse", "specular", "shininess")]
            block[72:74] = [vp["width"], vp["height"]]
            ints = block.view(np.int32)
            ints[74] = int(d["object_id"])
            ints[75] = 1 if smooth else 0
            ubo = dev.create_buffer_with_data(data=block.tobytes(),
                                              usage=wgpu.BufferUsage.UNIFORM)
            group = dev.create_bind_group(layout=self._group0, entries=[
                {"binding": 0, "resource": {"buffer": ubo, "offset": 0,
                                            "size": _UNIFORM_BYTES}}])
            out.append({"object_id": d["object_id"], "n_faces": len(faces), "vbo": vbo,
                        "ubo": ubo, "group": group})
        return out

    def _deindex(self, vertices, faces, normals):
        """The de-indexed vertex stream of one draw (:data:`VERTEX`): three vertices per face,
        each with its face's index and flat normal ``(v1 − v0) × (v2 − v0)`` (float32)."""
        n_faces = len(faces)
        data = np.zeros(3 * n_faces, VERTEX)
        if not n_faces:
            return data
        corners = faces.reshape(-1)
        data["pos"] = vertices[corners]
        if normals is not None:
            data["vnormal"] = normals[corners]
        tri = vertices[faces]                                       # (F, 3, 3) float32
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).astype(np.float32)
        data["fnormal"] = np.repeat(fn, 3, axis=0)
        if "provoking_vertex_face_id" in self.faults:
            # planted fault: the face id stored per vertex of the indexed mesh (the last face
            # that lists it) and read flat from the provoking (first) vertex
            last = np.zeros(len(vertices), np.int32)
            last[corners] = np.repeat(np.arange(n_faces, dtype=np.int32), 3)
            data["face"] = last[corners]
        else:
            data["face"] = np.repeat(np.arange(n_faces, dtype=np.int32), 3)
        return data

    def _sprite(self, package_dir, scene):
        """The sprite's layers as a 2D array texture (r32float) and its counts (r32sint); the
        package's maps have row 0 at the top, texture row 0 is t = 0: uploaded flipped."""
        p = scene["parameters"]
        layers = [read_map(package_dir, scene, name) for name in p["sprite_depth"]]
        count = read_map(package_dir, scene, p["sprite_count"])
        h, w = count.shape
        if not layers or any(a.shape != (h, w) for a in layers):
            raise PackageError(f"{package_dir}: sprite maps must all be (h, w) = {(h, w)}")
        if len(layers) > 256 or max(h, w) > 8192:
            raise Unsupported("the sprite exceeds WebGPU's default texture limits (256 layers, "
                              "8192 texels)")
        wgpu, dev = self.wgpu, self.device
        usage = wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST
        depth = np.ascontiguousarray(np.stack([a[::-1] for a in layers]), np.float32)
        arr = dev.create_texture(size=(w, h, len(layers)), format="r32float", usage=usage)
        dev.queue.write_texture({"texture": arr}, depth.tobytes(),
                                {"bytes_per_row": 4 * w, "rows_per_image": h},
                                (w, h, len(layers)))
        cnt = dev.create_texture(size=(w, h, 1), format="r32sint", usage=usage)
        dev.queue.write_texture({"texture": cnt},
                                np.ascontiguousarray(count[::-1], np.int32).tobytes(),
                                {"bytes_per_row": 4 * w, "rows_per_image": h}, (w, h, 1))
        return [arr, cnt]

    # --- pipelines --------------------------------------------------------------------------
    def _layouts(self):
        dev, s = self.device, self.wgpu.ShaderStage
        self._group0 = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": s.VERTEX | s.FRAGMENT,
             "buffer": {"type": "uniform"}}])
        self._group_vds = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": s.FRAGMENT,
             "texture": {"sample_type": "unfilterable-float", "view_dimension": "2d-array"}},
            {"binding": 1, "visibility": s.FRAGMENT,
             "texture": {"sample_type": "sint", "view_dimension": "2d"}}])
        self._group_peel = dev.create_bind_group_layout(entries=[
            {"binding": 2, "visibility": s.FRAGMENT,
             "texture": {"sample_type": "unfilterable-float", "view_dimension": "2d"}},
            {"binding": 3, "visibility": s.FRAGMENT,
             "texture": {"sample_type": "sint", "view_dimension": "2d"}}])
        self._layout = {
            None: dev.create_pipeline_layout(bind_group_layouts=[self._group0]),
            "vds": dev.create_pipeline_layout(bind_group_layouts=[self._group0,
                                                                  self._group_vds]),
            "peel": dev.create_pipeline_layout(bind_group_layouts=[self._group0,
                                                                   self._group_peel])}

    def _state(self, scene, conv):
        """The pipeline state and constants of a scene → ``(key, compare, clear)``."""
        raster = scene["raster"]
        compare = _COMPARE[raster["depth_func"]]
        clear = float(raster["clear_depth"])
        if raster["depth_func"] in ("greater", "gequal"):
            if "reversed_z_less" in self.faults:
                compare = "less"                        # planted fault
            if "clear_one_under_greater" in self.faults:
                clear = 1.0                             # planted fault
        remap = (conv["depth_range"] == "negative_one_to_one"
                 or "gl_remap_on_zero_to_one" in self.faults)
        ysign = -1.0 if conv["ndc_y"] == "down" else 1.0
        if self._mirrored(conv):
            ysign = 1.0             # planted fault: mirrored at read-back instead (_mirrored)
        if "y_not_flipped" in self.faults:
            ysign = -ysign                              # planted fault
        clamp = conv["depth_clamp"] and "unclipped_depth_dropped" not in self.faults
        constants = {"DEPTH_REMAP": float(remap), "Y_SIGN": ysign,
                     "DEPTH_CLAMP": float(conv["depth_clamp"]),
                     "PEEL_GREATER": float(raster["depth_func"] in ("greater", "gequal")),
                     "HALF_PIXEL": float("half_pixel" in self.faults),
                     "SPRITE_ROWS_FLIPPED": float("sprite_rows_flipped" in self.faults)}
        state = (compare, raster["cull"], conv["front_face"], conv["depth_write"],
                 _DEPTH_FORMAT[conv["depth_format"]], clamp,
                 tuple(sorted(constants.items())))
        return state, clear

    def _mirrored(self, conv):
        """The planted ``winding_not_flipped`` fault on a scene with NDC y down: drawn without
        the y negation, so WebGPU's framebuffer holds the Vulkan picture mirrored top to
        bottom; its rows are mirrored back at read-back, but ``frontFace`` stays as the
        scene says although a mirror reverses every winding as seen."""
        return "winding_not_flipped" in self.faults and conv["ndc_y"] == "down"

    def _pipeline(self, entry, targets, state, layout=None, peel=False):
        key = (entry, targets, state, layout, peel)
        if key not in self._pipelines:
            compare, cull, front, write, fmt, clamp, constants = state
            constants = dict(constants)
            if entry == "fs_peel":
                constants["PEEL"] = float(peel)
            with unclipped_depth(clamp):   # the C field wgpu-py 0.32 does not set
                self._pipelines[key] = self.device.create_render_pipeline(
                    layout=self._layout[layout],
                    vertex={"module": self.module, "entry_point": "vs", "constants": constants,
                            "buffers": [{"array_stride": VERTEX.itemsize, "attributes": [
                                {"format": "float32x3", "offset": 0, "shader_location": 0},
                                {"format": "float32x3", "offset": 12, "shader_location": 1},
                                {"format": "float32x3", "offset": 24, "shader_location": 2},
                                {"format": "sint32", "offset": 36, "shader_location": 3}]}]},
                    primitive={"topology": "triangle-list", "front_face": front,
                               "cull_mode": cull, "unclipped_depth": clamp},
                    depth_stencil={"format": fmt, "depth_write_enabled": write,
                                   "depth_compare": compare},
                    multisample={"count": 1},
                    fragment={"module": self.module, "entry_point": entry,
                              "constants": constants,
                              "targets": [{"format": f} for f in targets]})
        return self._pipelines[key]

    # --- passes -----------------------------------------------------------------------------
    def _targets(self, formats, size, sampled=False):
        usage = self.wgpu.TextureUsage.RENDER_ATTACHMENT | self.wgpu.TextureUsage.COPY_SRC
        if sampled:
            usage |= self.wgpu.TextureUsage.TEXTURE_BINDING
        return [self.device.create_texture(size=(*size, 1), format=f, usage=usage)
                for f in formats]

    def _pass(self, encoder, pipeline, targets, depth, clear, draws, group1=None):
        rp = encoder.begin_render_pass(
            color_attachments=[{"view": t.create_view(), "clear_value": (0, 0, 0, 0),
                                "load_op": "clear", "store_op": "store"} for t in targets],
            depth_stencil_attachment={"view": depth.create_view(), "depth_clear_value": clear,
                                      "depth_load_op": "clear", "depth_store_op": "store"})
        rp.set_pipeline(pipeline)
        if group1 is not None:
            rp.set_bind_group(1, group1)
        for d in draws:
            if not d["n_faces"]:
                continue
            rp.set_bind_group(0, d["group"])
            rp.set_vertex_buffer(0, d["vbo"])
            rp.draw(3 * d["n_faces"])
        rp.end()

    def _read(self, texture, fmt, size):
        w, h = size
        comps = 4 if fmt.startswith("rgba") else 1
        dtype = "<i4" if "sint" in fmt else "<f4"
        data = self.device.queue.read_texture(
            {"texture": texture, "mip_level": 0, "origin": (0, 0, 0)},
            {"offset": 0, "bytes_per_row": w * comps * 4}, (w, h, 1))
        return np.frombuffer(data, dtype).reshape(h, w, comps).copy()   # row 0: the top

    def _depth(self, state, size, sampled=False):
        usage = self.wgpu.TextureUsage.RENDER_ATTACHMENT
        if sampled:
            usage |= self.wgpu.TextureUsage.TEXTURE_BINDING
        return self.device.create_texture(size=(*size, 1), format=state[4], usage=usage)

    def _read_depth_buffer(self, depth, size):
        """The depth attachment's values as float32 ``(H, W)``, row 0 at the top: one
        full-screen pass of ``depth_read.wgsl`` (``textureLoad`` of the depth texture)."""
        if self._depth_pipeline is None:
            self._depth_pipeline = self.device.create_render_pipeline(
                layout="auto",
                vertex={"module": self.depth_module, "entry_point": "vs_full"},
                primitive={"topology": "triangle-list"},
                fragment={"module": self.depth_module, "entry_point": "fs_depth",
                          "targets": [{"format": "r32float"}]})
        pipe = self._depth_pipeline
        group = self.device.create_bind_group(
            layout=pipe.get_bind_group_layout(0),
            entries=[{"binding": 0, "resource": depth.create_view(aspect="depth-only")}])
        target = self._targets(("r32float",), size)[0]
        encoder = self.device.create_command_encoder()
        rp = encoder.begin_render_pass(color_attachments=[
            {"view": target.create_view(), "clear_value": (0, 0, 0, 0), "load_op": "clear",
             "store_op": "store"}])
        rp.set_pipeline(pipe)
        rp.set_bind_group(0, group)
        rp.draw(3)
        rp.end()
        self.device.queue.submit([encoder.finish()])
        try:
            return self._read(target, "r32float", size)[..., 0]
        finally:
            target.destroy()

    # --- the G-buffer -----------------------------------------------------------------------
    def _gbuffer(self, loaded):
        scene, draws, conv = loaded["scene"], loaded["draws"], loaded["conv"]
        vds = loaded["sprite"] is not None
        size = (scene["viewport"]["width"], scene["viewport"]["height"])
        state, clear = self._state(scene, conv)
        passes = dict(GBUFFER_PASSES)
        group1, layout = None, None
        if vds:
            del passes["fs_shade"]
            passes[_VDS_SHADE[0]] = _VDS_SHADE[1]
            layout = "vds"
            arr, cnt = loaded["sprite"]
            group1 = self.device.create_bind_group(layout=self._group_vds, entries=[
                {"binding": 0, "resource": arr.create_view(dimension="2d-array")},
                {"binding": 1, "resource": cnt.create_view()}])
        quantised = (conv["depth_format"] != "float32"
                     and "depth_not_quantised" not in self.faults)
        depth = self._depth(state, size, sampled=quantised)
        encoder = self.device.create_command_encoder()
        made = {}
        for entry, formats in passes.items():
            targets = self._targets(formats, size)
            lay = layout if entry == "fs_shade_vds" else None
            pipe = self._pipeline(entry, formats, state, lay)
            self._pass(encoder, pipe, targets, depth, clear, draws,
                       group1 if entry == "fs_shade_vds" else None)
            made[entry] = (targets, formats)
        self.device.queue.submit([encoder.finish()])
        got = {entry: [self._read(t, f, size) for t, f in zip(ts, fs)]
               for entry, (ts, fs) in made.items()}
        # the last pass leaves the frame's depth buffer (every pass has the same winners)
        stored = self._read_depth_buffer(depth, size) if quantised else None
        for ts, _ in made.values():
            for t in ts:
                t.destroy()
        depth.destroy()
        if self._mirrored(conv):                        # planted fault (see _mirrored)
            got = {entry: [a[::-1] for a in arrays] for entry, arrays in got.items()}
            stored = None if stored is None else stored[::-1]
        win, eye, ids = got["fs_ids"]
        normal, bary = got["fs_surface"]
        shade = got["fs_shade_vds" if vds else "fs_shade"]
        written = win[..., 0] if stored is None else stored   # unorm: the depth buffer
        out, covered = gbuffer_arrays(scene, written, eye, ids, normal, bary, shade[0])
        if vds:
            out["inside"] = covered & (shade[1][..., 0] == 1)
        return out

    # --- classic depth peeling --------------------------------------------------------------
    def _peel(self, loaded, layers):
        scene, draws, conv = loaded["scene"], loaded["draws"], loaded["conv"]
        size = (scene["viewport"]["width"], scene["viewport"]["height"])
        state, clear = self._state(scene, conv)
        raster = scene["raster"]
        max_layers = scene.get("parameters", {}).get("max_layers")
        faces = sum(d["n_faces"] for d in draws)
        limit = min(MAX_PEEL_PASSES, faces + 1) if max_layers is None else int(max_layers)
        sets = [self._targets(_PEEL_TARGETS, size, sampled=True) for _ in range(2)]
        groups = [self.device.create_bind_group(layout=self._group_peel, entries=[
            {"binding": 2, "resource": s[0].create_view()},
            {"binding": 3, "resource": s[1].create_view()}]) for s in sets]
        depth = self._depth(state, size)
        found_depth, found_ids = [], []
        try:
            for k in range(limit):
                cur, prev = k % 2, 1 - k % 2
                pipe = self._pipeline("fs_peel", _PEEL_TARGETS, state, "peel", peel=k > 0)
                encoder = self.device.create_command_encoder()
                self._pass(encoder, pipe, sets[cur], depth, clear, draws, groups[prev])
                self.device.queue.submit([encoder.finish()])
                ids = self._read(sets[cur][1], _PEEL_TARGETS[1], size)
                if not np.any(ids[..., 3] == 1):
                    break
                dep = self._read(sets[cur][0], _PEEL_TARGETS[0], size)[..., 0]
                if self._mirrored(conv):                # planted fault (see _mirrored)
                    dep, ids = dep[::-1], ids[::-1]
                found_depth.append(dep)
                found_ids.append(ids)
        finally:
            for s in sets:
                for t in s:
                    t.destroy()
            depth.destroy()
        w, h = size
        k_out = len(found_depth) if layers is None else int(layers)
        background = np.float32(raster["clear_depth"])
        out_depth = np.full((h, w, k_out), background, np.float32)
        out_prim = np.full((h, w, k_out), -1, np.int32)
        out_front = np.zeros((h, w, k_out), np.bool_)
        count = np.zeros((h, w), np.int32)
        for k, (dep, ids) in enumerate(zip(found_depth, found_ids)):
            covered = ids[..., 3] == 1
            count += covered
            if k < k_out:
                out_depth[..., k] = np.where(covered, dep, background)
                out_prim[..., k] = np.where(covered, ids[..., 0], -1)
                out_front[..., k] = covered & (ids[..., 2] == 1)
        return {"layer_depth": out_depth, "layer_prim_id": out_prim,
                "layer_front_facing": out_front, "layer_count": count}
