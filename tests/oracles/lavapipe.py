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

Importing the module makes the device and raises :class:`LavapipeUnavailable` when it cannot
(no wgpu, no lavapipe, or an adapter that is not Mesa's CPU one), so tests reach it through
``conftest.require`` and skip (or fail under ``CI=true``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LavapipeUnavailable", "Frame", "clip_positions", "rasterize", "renderer",
           "DEPTH_FORMATS"]


class LavapipeUnavailable(RuntimeError):
    """wgpu or lavapipe is missing, or the adapter found is not Mesa's CPU one."""


#: refraster's ``depth_format`` → the WebGPU depth format read back here.
DEPTH_FORMATS = {"float32": "depth32float", "unorm16": "depth16unorm"}

_SHADER = """
struct VIn { @location(0) clip: vec4<f32>, @location(1) face: i32 };
struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) face: i32,
};
@vertex fn vs(v: VIn) -> VOut {
    var o: VOut;
    // ndc_y = "down" (Vulkan) through WebGPU, whose NDC y points up: the clip y negated
    o.pos = vec4<f32>(v.clip.x, YSIGN * v.clip.y, v.clip.z, v.clip.w);
    o.face = v.face;
    return o;
}
struct FOut { @location(0) face: i32, @location(1) front: u32 };
@fragment fn fs(i: VOut, @builtin(front_facing) ff: bool) -> FOut {
    var o: FOut;
    o.face = i.face;
    o.front = select(0u, 1u, ff);
    return o;
}
"""


def _device():
    # the adapter as refraster.wgpu finds it (refraster/wgpu/device.py); the oracle's device
    # keeps wgpu-py's own limits (it renders two small targets)
    from refraster.wgpu.device import WGPUUnavailable, adapter
    try:
        wgpu, found = adapter(require_lavapipe=True)
    except WGPUUnavailable as exc:
        raise LavapipeUnavailable(str(exc)) from exc
    if "depth-clip-control" not in found.features:
        raise LavapipeUnavailable("lavapipe does not expose depth-clip-control")
    device = found.request_device_sync(required_features=["depth-clip-control"])
    return wgpu, found, device


_WGPU, _ADAPTER, _DEVICE = _device()
_PIPELINES: dict = {}


def renderer():
    """The adapter's device and driver description (for reports)."""
    info = _ADAPTER.info
    return f"{info.get('device')} ({info.get('description')}) via wgpu {_WGPU.__version__}"


def clip_positions(vertices, mvp):
    """Clip coordinates ``(V, 4) float32`` of ``vertices (V, 3)`` under one float32 ``mvp``:
    ``((m0·x + m1·y) + m2·z) + m3`` in float32 without fused multiply-add, the order of
    refraster's float32 vertex stage."""
    v = np.asarray(vertices, dtype=np.float64).astype(np.float32)
    m = np.asarray(mvp, dtype=np.float64).astype(np.float32)
    out = np.zeros((len(v), 4), np.float32)
    for r in range(4):
        out[:, r] = ((m[r, 0] * v[:, 0] + m[r, 1] * v[:, 1]) + m[r, 2] * v[:, 2]) + m[r, 3]
    return out


@dataclass
class Frame:
    """One pass; every image ``(H, W)`` with row 0 at the top of the picture."""

    prim_id: np.ndarray   #: int32 global face index (draw calls in order), −1 background
    depth: np.ndarray     #: float32 the depth buffer (a unorm16 buffer as its value k/65535)
    front: np.ndarray     #: bool ``front_facing``

    @property
    def mask(self):
        return self.prim_id >= 0


#: wgpu-py 0.32 does not pass ``primitive.unclipped_depth`` on: the struct it builds is patched
#: for the ``with`` body (shared with refraster.wgpu).
from refraster.wgpu.device import unclipped_depth as _UnclippedDepth  # noqa: E402


def _pipeline(ndc_y, compare, unclipped, cull, front_face, fmt):
    key = (ndc_y, compare, unclipped, cull, front_face, fmt)
    if key not in _PIPELINES:
        ysign = "-1.0" if ndc_y == "down" else "1.0"
        mod = _DEVICE.create_shader_module(code=_SHADER.replace("YSIGN", ysign))
        with _UnclippedDepth(unclipped):
            _PIPELINES[key] = _create(mod, compare, unclipped, cull, front_face, fmt)
    return _PIPELINES[key]


def _create(mod, compare, unclipped, cull, front_face, fmt):
    return _DEVICE.create_render_pipeline(
        layout="auto",
        vertex={"module": mod, "entry_point": "vs", "buffers": [{
            "array_stride": 20, "attributes": [
                {"format": "float32x4", "offset": 0, "shader_location": 0},
                {"format": "sint32", "offset": 16, "shader_location": 1}]}]},
        primitive={"topology": "triangle-list", "front_face": front_face, "cull_mode": cull,
                   "unclipped_depth": unclipped},
        depth_stencil={"format": fmt, "depth_write_enabled": True, "depth_compare": compare},
        multisample={"count": 1},
        fragment={"module": mod, "entry_point": "fs",
                  "targets": [{"format": "r32sint"}, {"format": "r32uint"}]})


def _read(texture, width, height, dtype):
    size = np.dtype(dtype).itemsize
    data = _DEVICE.queue.read_texture({"texture": texture, "mip_level": 0, "origin": (0, 0, 0)},
                                      {"offset": 0, "bytes_per_row": width * size},
                                      (width, height, 1))
    return np.frombuffer(data, dtype).reshape(height, width).copy()


def rasterize(draws, width, height, *, ndc_y="up", depth_compare="less", clear_depth=1.0,
              unclipped_depth=False, cull="none", front_face="ccw", depth_format="float32"):
    """Draw ``draws`` (a list of ``(clip (V, 4) float32, faces (F, 3))``, in order) into one
    ``width × height`` frame with a depth buffer cleared to ``clear_depth`` and the WebGPU
    ``depth_compare``; returns a :class:`Frame`."""
    wgpu = _WGPU
    clip = np.concatenate([np.asarray(c, np.float32)[np.asarray(f, np.int64)].reshape(-1, 4)
                           for c, f in draws]) if draws else np.zeros((0, 4), np.float32)
    n_faces = sum(len(f) for _, f in draws)
    data = np.zeros(3 * n_faces, dtype=[("c", "<f4", 4), ("f", "<i4")])
    data["c"] = clip
    data["f"] = np.repeat(np.arange(n_faces, dtype=np.int32), 3)
    fmt = DEPTH_FORMATS[depth_format]
    pipe = _pipeline(ndc_y, depth_compare, bool(unclipped_depth), cull, front_face, fmt)
    usage = wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC
    ids, fronts, depth = (_DEVICE.create_texture(size=(width, height, 1), format=f, usage=usage)
                          for f in ("r32sint", "r32uint", fmt))
    enc = _DEVICE.create_command_encoder()
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
        vb = _DEVICE.create_buffer_with_data(data=data.tobytes(), usage=wgpu.BufferUsage.VERTEX)
        rp.set_pipeline(pipe)
        rp.set_vertex_buffer(0, vb)
        rp.draw(3 * n_faces)
    rp.end()
    _DEVICE.queue.submit([enc.finish()])
    if fmt == "depth16unorm":
        z = _read(depth, width, height, np.uint16).astype(np.float64) / 65535.0
    else:
        z = _read(depth, width, height, np.float32)
    return Frame(_read(ids, width, height, np.int32), np.asarray(z, np.float32),
                 _read(fronts, width, height, np.uint32) != 0)
