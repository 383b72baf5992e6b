"""Mesa's lavapipe (Vulkan on llvmpipe) through wgpu: an outside opinion on the API conventions.

lavapipe is Mesa's conformant Vulkan driver on the CPU (Debian package ``mesa-vulkan-drivers``);
wgpu-py drives it through WebGPU (``wgpu.gpu.request_adapter_sync()`` returns the CPU adapter,
``llvmpipe``, backend Vulkan; the ``XDG_RUNTIME_DIR`` warning it prints is harmless). Nobody on
this project wrote either, so they judge refraster's ``depth_range="zero_to_one"``, upper-left
origin, NDC y, reversed-Z and depth clamp from outside.

What WebGPU fixes and how the other conventions are reached through it:

* clip volume ``0 ≤ z ≤ w``, window depth ``z/w`` (refraster's ``depth_range="zero_to_one"``);
  ``unclipped_depth=True`` (the ``depth-clip-control`` feature) turns near/far clipping off and
  clamps the depth to the viewport's [0, 1] (refraster's ``depth_clamp=True``);
* window origin upper-left and NDC y **up** (refraster's ``origin="upper_left", ndc_y="up"``:
  Direct3D, Metal, WebGPU). Vulkan's NDC y points **down**; through WebGPU that is a negation of
  the clip y in the vertex shader (``ndc_y="down"`` here). The negation is exact, and wgpu on
  Vulkan flips y with a negative viewport height, so the window y lavapipe computes is Vulkan's
  own ``y_c·(1/w)·H/2 + H/2`` — the arithmetic refraster does under ``ndc_y="down"``;
* ``front_face`` as WebGPU defines it: counter-clockwise as the picture is seen;
* the depth buffer ``depth32float`` or ``depth16unorm`` (both copyable; ``depth24plus`` is not).

Geometry goes in as **clip-space positions** (float32, passed through as the vertex position)
so both renderers start from the same bits; :func:`clip_positions` computes them as refraster's
float32 vertex stage does (checked bit for bit in ``tests/test_lavapipe_oracle.py``). Vertices
are de-indexed and each carries its face's global index (draw calls in order), written to an
``r32sint`` target with ``@interpolate(flat)``; facing to an ``r32uint`` one. Images come back
``(H, W)`` with row 0 at the top of the picture (WebGPU's first row).

The device, the vertex stage and the vertex data are :mod:`oracles._vulkan`'s (shared with
:mod:`oracles.lavapipe_msaa`; neither imports refraster's WebGPU backend). Importing the module
makes the device and raises :class:`LavapipeUnavailable` when it cannot (no wgpu, no lavapipe, or
an adapter that is not Mesa's CPU one), so tests reach it through ``conftest.require`` and skip
(or fail under ``CI=true``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._vulkan import (DEVICE, VERTEX_BUFFER, WGPU, LavapipeUnavailable, renderer,
                      unclipped_depth, vertex_data, vertex_wgsl)
from .scenes import clip_positions

__all__ = ["LavapipeUnavailable", "Frame", "clip_positions", "rasterize", "renderer",
           "DEPTH_FORMATS"]


#: refraster's ``depth_format`` → the WebGPU depth format read back here.
DEPTH_FORMATS = {"float32": "depth32float", "unorm16": "depth16unorm"}

_FRAGMENT = """
struct FOut { @location(0) face: i32, @location(1) front: u32 };
@fragment fn fs(i: VOut, @builtin(front_facing) ff: bool) -> FOut {
    var o: FOut;
    o.face = i.face;
    o.front = select(0u, 1u, ff);
    return o;
}
"""

_PIPELINES: dict = {}


@dataclass
class Frame:
    """One pass; every image ``(H, W)`` with row 0 at the top of the picture."""

    prim_id: np.ndarray   #: int32 global face index (draw calls in order), −1 background
    depth: np.ndarray     #: float32 the depth buffer (a unorm16 buffer as its value k/65535)
    front: np.ndarray     #: bool ``front_facing``

    @property
    def mask(self):
        return self.prim_id >= 0


def _pipeline(ndc_y, compare, unclipped, cull, front_face, fmt):
    key = (ndc_y, compare, unclipped, cull, front_face, fmt)
    if key not in _PIPELINES:
        mod = DEVICE.create_shader_module(code=vertex_wgsl(ndc_y) + _FRAGMENT)
        with unclipped_depth(unclipped):
            _PIPELINES[key] = _create(mod, compare, unclipped, cull, front_face, fmt)
    return _PIPELINES[key]


def _create(mod, compare, unclipped, cull, front_face, fmt):
    return DEVICE.create_render_pipeline(
        layout="auto",
        vertex={"module": mod, "entry_point": "vs", "buffers": [VERTEX_BUFFER]},
        primitive={"topology": "triangle-list", "front_face": front_face, "cull_mode": cull,
                   "unclipped_depth": unclipped},
        depth_stencil={"format": fmt, "depth_write_enabled": True, "depth_compare": compare},
        multisample={"count": 1},
        fragment={"module": mod, "entry_point": "fs",
                  "targets": [{"format": "r32sint"}, {"format": "r32uint"}]})


def _read(texture, width, height, dtype):
    size = np.dtype(dtype).itemsize
    data = DEVICE.queue.read_texture({"texture": texture, "mip_level": 0, "origin": (0, 0, 0)},
                                      {"offset": 0, "bytes_per_row": width * size},
                                      (width, height, 1))
    return np.frombuffer(data, dtype).reshape(height, width).copy()


def rasterize(draws, width, height, *, ndc_y="up", depth_compare="less", clear_depth=1.0,
              unclipped_depth=False, cull="none", front_face="ccw", depth_format="float32"):
    """Draw ``draws`` (a list of ``(clip (V, 4) float32, faces (F, 3))``, in order) into one
    ``width × height`` frame with a depth buffer cleared to ``clear_depth`` and the WebGPU
    ``depth_compare``; returns a :class:`Frame`."""
    wgpu = WGPU
    data, n_faces = vertex_data(draws)
    fmt = DEPTH_FORMATS[depth_format]
    pipe = _pipeline(ndc_y, depth_compare, bool(unclipped_depth), cull, front_face, fmt)
    usage = wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC
    ids, fronts, depth = (DEVICE.create_texture(size=(width, height, 1), format=f, usage=usage)
                          for f in ("r32sint", "r32uint", fmt))
    enc = DEVICE.create_command_encoder()
    rp = enc.begin_render_pass(
        color_attachments=[
            {"view": ids.create_view(), "clear_value": (-1, 0, 0, 0), "load_op": "clear",
             "store_op": "store"},
            {"view": fronts.create_view(), "clear_value": (0, 0, 0, 0), "load_op": "clear",
             "store_op": "store"}],
        depth_stencil_attachment={"view": depth.create_view(),
                                  "depth_clear_value": float(clear_depth),
                                  "depth_load_op": "clear", "depth_store_op": "store"})
    if n_faces:
        vb = DEVICE.create_buffer_with_data(data=data.tobytes(), usage=wgpu.BufferUsage.VERTEX)
        rp.set_pipeline(pipe)
        rp.set_vertex_buffer(0, vb)
        rp.draw(3 * n_faces)
    rp.end()
    DEVICE.queue.submit([enc.finish()])
    if fmt == "depth16unorm":
        z = _read(depth, width, height, np.uint16).astype(np.float64) / 65535.0
    else:
        z = _read(depth, width, height, np.float32)
    return Frame(_read(ids, width, height, np.int32), np.asarray(z, np.float32),
                 _read(fronts, width, height, np.uint32) != 0)
