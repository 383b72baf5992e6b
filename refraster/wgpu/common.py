"""What the technique modules of refraster.wgpu (:mod:`refraster.wgpu.edges`,
:mod:`refraster.wgpu.clipsurface`, :mod:`refraster.wgpu.cutaway`; :mod:`refraster.wgpu.halos`
uses only :data:`SHADER_DIR` and :func:`uniform`) share: their WGSL modules (each compiled after
``shaders/gbuffer.wgsl``, whose ``Draw``, ``VOut``, ``vs`` and helpers they use), the pipelines
that draw a scene's de-indexed meshes with the scene's raster state, the full-screen pipelines,
and uniform and texture helpers. The technique modules import this module and
:mod:`refraster.gl.package`, never the driver; the ``backend`` argument is the driver's
``Backend`` (its ``device``, ``wgpu`` module, planted ``faults``, ``module_code`` and
``_state``/``_targets``/``_read``/``_depth``/``_pass``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["SHADER_DIR", "VERTEX_BUFFER", "module", "scene_pipeline", "fullscreen_pipeline",
           "uniform", "fullscreen", "float_texture", "gbuffer_arrays"]

SHADER_DIR = Path(__file__).with_name("shaders")

#: The de-indexed vertex of the driver (``driver.VERTEX``: position, vertex normal, flat face
#: normal, face index; 40 bytes) as a WebGPU vertex buffer layout.
VERTEX_BUFFER = {"array_stride": 40, "attributes": [
    {"format": "float32x3", "offset": 0, "shader_location": 0},
    {"format": "float32x3", "offset": 12, "shader_location": 1},
    {"format": "float32x3", "offset": 24, "shader_location": 2},
    {"format": "sint32", "offset": 36, "shader_location": 3}]}


def module(backend, name):
    """The shader module ``gbuffer.wgsl`` + ``shaders/<name>``, compiled once per backend."""
    cache = backend.__dict__.setdefault("_technique_modules", {})
    if name not in cache:
        code = backend.module_code + "\n" + (SHADER_DIR / name).read_text(encoding="utf-8")
        cache[name] = backend.device.create_shader_module(code=code)
    return cache[name]


def _cached(backend, key, make):
    cache = backend.__dict__.setdefault("_technique_pipelines", {})
    if key not in cache:
        cache[key] = make()
    return cache[key]


def scene_pipeline(backend, shader, entry, targets, state, layout, constants=(), depth=None):
    """A pipeline drawing de-indexed meshes with ``vs`` of gbuffer.wgsl and fragment ``entry``
    of ``shader`` (a file of :data:`SHADER_DIR`) into colour ``targets`` (formats) under the
    scene's ``state`` (the driver's ``_state``) and the pipeline ``layout``; ``constants``:
    extra override constants (name, value) pairs; ``depth``: ``(compare, write)`` replacing
    the state's."""
    key = ("scene", shader, entry, tuple(targets), state, id(layout), tuple(constants), depth)

    def make():
        from .device import unclipped_depth
        compare, cull, front, write, fmt, clamp, base = state
        if depth is not None:
            compare, write = depth
        const = dict(base)
        const.update(constants)
        mod = module(backend, shader)
        with unclipped_depth(clamp):
            return backend.device.create_render_pipeline(
                layout=layout,
                vertex={"module": mod, "entry_point": "vs", "constants": const,
                        "buffers": [VERTEX_BUFFER]},
                primitive={"topology": "triangle-list", "front_face": front,
                           "cull_mode": cull, "unclipped_depth": clamp},
                depth_stencil={"format": fmt, "depth_write_enabled": write,
                               "depth_compare": compare},
                multisample={"count": 1},
                fragment={"module": mod, "entry_point": entry, "constants": const,
                          "targets": [{"format": f} for f in targets]})
    return _cached(backend, key, make)


def fullscreen_pipeline(backend, shader, entry, target, layout, constants=()):
    """A full-screen pipeline (``vs_full`` of ``shader``) writing one colour ``target`` (a
    format; a tuple of formats: several targets)."""
    key = ("full", shader, entry, target, id(layout), tuple(constants))
    targets = target if isinstance(target, tuple) else (target,)

    def make():
        mod = module(backend, shader)
        return backend.device.create_render_pipeline(
            layout=layout,
            vertex={"module": mod, "entry_point": "vs_full", "constants": dict(constants)},
            primitive={"topology": "triangle-list"},
            fragment={"module": mod, "entry_point": entry, "constants": dict(constants),
                      "targets": [{"format": f} for f in targets]})
    return _cached(backend, key, make)


def uniform(backend, data):
    """A uniform buffer holding ``data`` (a NumPy array, padded to 16 bytes)."""
    raw = np.ascontiguousarray(data).tobytes()
    raw += b"\0" * (-len(raw) % 16)
    return backend.device.create_buffer_with_data(data=raw,
                                                  usage=backend.wgpu.BufferUsage.UNIFORM)


def fullscreen(backend, encoder, pipeline, target, group, clear=(0, 0, 0, 0)):
    """One full-screen triangle of ``pipeline`` into ``target`` (a texture, or a list of them)
    with bind group 0 ``group``."""
    targets = target if isinstance(target, (list, tuple)) else [target]
    rp = encoder.begin_render_pass(color_attachments=[
        {"view": t.create_view(), "clear_value": clear, "load_op": "clear",
         "store_op": "store"} for t in targets])
    rp.set_pipeline(pipeline)
    rp.set_bind_group(0, group)
    rp.draw(3)
    rp.end()


def float_texture(backend, arrays):
    """An rgba32float texture from 1 to 4 ``(H, W)`` arrays (its channels; the rest 0), row 0
    of the arrays in texture row 0 (no flip: the package's maps are indexed by t directly)."""
    h, w = arrays[0].shape
    data = np.zeros((h, w, 4), np.float32)
    for c, a in enumerate(arrays):
        data[..., c] = a
    tex = backend.device.create_texture(
        size=(w, h, 1), format="rgba32float",
        usage=backend.wgpu.TextureUsage.TEXTURE_BINDING | backend.wgpu.TextureUsage.COPY_DST)
    backend.device.queue.write_texture({"texture": tex}, data.tobytes(),
                                       {"bytes_per_row": 16 * w, "rows_per_image": h},
                                       (w, h, 1))
    return tex


def gbuffer_arrays(scene, window_depth, eye, ids, normal, bary, color):
    """The G-buffer's buffers from a G-buffer pass's read-backs → ``(out, covered)``.

    ``ids`` is the ``(H, W, 4)`` int target (face, object, front facing, covered flag);
    ``window_depth`` ``(H, W)``, ``eye``, ``normal``, ``bary``, ``color`` the float targets
    (their first channels used). Uncovered pixels get the package's clear depth, infinite eye
    depth, zero normal and barycentrics, id −1 and the background colour, as refraster's
    Framebuffer.
    """
    covered = ids[..., 3] == 1
    c3 = covered[..., None]
    bg = np.asarray(scene["shading"]["background"], np.float32)
    out = {
        "depth": np.where(covered, window_depth,
                          np.float32(scene["raster"]["clear_depth"])).astype(np.float32),
        "eye_depth": np.where(covered, eye[..., 0], np.float32(np.inf)).astype(np.float32),
        "normal": np.where(c3, normal[..., :3], 0).astype(np.float32),
        "prim_id": np.where(covered, ids[..., 0], -1).astype(np.int32),
        "object_id": np.where(covered, ids[..., 1], -1).astype(np.int32),
        "front_facing": covered & (ids[..., 2] == 1),
        "barycentric": np.where(c3, bary[..., :3], 0).astype(np.float32),
        "color": np.where(c3, color[..., :3], bg).astype(np.float32),
    }
    return out, covered
