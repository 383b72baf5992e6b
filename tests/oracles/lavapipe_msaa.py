"""lavapipe at 4× (Vulkan on llvmpipe, through wgpu) as an oracle of per-sample coverage and the
per-sample depth test, in WebGPU's conventions.

One draw of the clip positions (de-indexed, each vertex carrying its face's global index, as
``oracles.lavapipe.rasterize``) into a 4-sample colour texture and a 4-sample ``depth32float``
texture, the fragment shader writing the face index (no sample shading: one fragment per pixel,
written to the samples it covers that pass the depth test). The colour format is ``r32float``
holding the index as an exact integer (< 2^24): WebGPU guarantees 4× for ``r32float`` but not for
``r32sint`` (lavapipe offers ``r32sint`` at 4× only under the adapter-specific feature
``texture-adapter-specific-format-features``, which this oracle does not ask for). A compute pass
reads each sample with ``textureLoad(t, p, s)`` into a storage buffer, read back ``(H, W, 4)``,
row 0 at the top of the picture.

Conventions (WebGPU's, fixed): clip volume ``0 ≤ z ≤ w``, window depth ``z/w``, window origin
upper-left with NDC y **up**; ``ndc_y="down"`` negates the clip y in the vertex shader (Vulkan's
NDC, as ``oracles.lavapipe``). wgpu draws on Vulkan with a negative viewport height, so the
picture's row 0 is Vulkan's framebuffer row 0 and the sample locations lavapipe uses are given in
the picture's coordinates (x right, y down from the pixel's upper-left corner): refraster's
``origin="upper_left"`` frame with the same pattern.

WebGPU has no query for sample positions (Vulkan reports only that the standard locations are
used, ``VkPhysicalDeviceLimits::standardSampleLocations``, which wgpu does not pass on), so
:func:`probe_sample_positions` measures them: 64 pixel columns, column ``c`` holding a quad whose
right edge lies ``(2c + 1)/128`` px into the pixel; sample ``s`` is covered in column ``c`` exactly
when its x is below that edge, so the number of columns leaving it uncovered is its x in 1/64
pixel (within 1/128 px); the same with rows for y. No edge lies on a 1/128 px grid point that a
1/16-pixel position could occupy, so no fill rule is involved.

The device, the vertex stage and the vertex data are :mod:`oracles._vulkan`'s (as
:mod:`oracles.lavapipe`'s). Importing the module makes the device (``LavapipeUnavailable`` when it
cannot be made): reach this module through ``conftest.require``.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from ._vulkan import DEVICE, VERTEX_BUFFER, WGPU, vertex_data, vertex_wgsl

__all__ = ["SAMPLES", "rasterize_samples", "probe_sample_positions"]

SAMPLES = 4
_ID_FORMAT = "r32float"

_FRAGMENT = """
@fragment fn fs(i: VOut) -> @location(0) vec4<f32> {
    return vec4<f32>(f32(i.face), 0.0, 0.0, 0.0);   // exact below 2^24
}
"""

_READ = """
@group(0) @binding(0) var ids: texture_multisampled_2d<f32>;
@group(0) @binding(1) var<storage, read_write> out: array<i32>;
@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) g: vec3<u32>) {
    let size = textureDimensions(ids);
    if (g.x >= size.x || g.y >= size.y) { return; }
    let base = (g.y * size.x + g.x) * 4u;
    for (var s = 0; s < 4; s++) {
        out[base + u32(s)] = i32(textureLoad(ids, vec2<i32>(g.xy), s).r);
    }
}
"""

_PIPELINES: dict = {}


def _pipeline(ndc_y, compare):
    key = (ndc_y, compare)
    if key not in _PIPELINES:
        mod = DEVICE.create_shader_module(code=vertex_wgsl(ndc_y) + _FRAGMENT)
        _PIPELINES[key] = DEVICE.create_render_pipeline(
            layout="auto",
            vertex={"module": mod, "entry_point": "vs", "buffers": [VERTEX_BUFFER]},
            primitive={"topology": "triangle-list", "front_face": "ccw", "cull_mode": "none"},
            depth_stencil={"format": "depth32float", "depth_write_enabled": True,
                           "depth_compare": compare},
            multisample={"count": SAMPLES},
            fragment={"module": mod, "entry_point": "fs", "targets": [{"format": _ID_FORMAT}]})
    return _PIPELINES[key]


def _reader():
    if "read" not in _PIPELINES:
        mod = DEVICE.create_shader_module(code=_READ)
        _PIPELINES["read"] = DEVICE.create_compute_pipeline(
            layout="auto", compute={"module": mod, "entry_point": "main"})
    return _PIPELINES["read"]


def rasterize_samples(draws, width, height, *, ndc_y="up", depth_compare="less",
                      clear_depth=1.0):
    """Per-sample global face indices ``(H, W, 4)`` int32 (−1: no primitive), row 0 at the top of
    the picture, of ``draws`` (a list of ``(clip (V, 4) float32, faces (F, 3))``, drawn in order
    as one draw call) in a ``width × height`` 4× frame with its depth cleared to ``clear_depth``
    and tested with the WebGPU ``depth_compare``."""
    wgpu, dev = WGPU, DEVICE
    width, height = int(width), int(height)
    data, n_faces = vertex_data(draws)
    if n_faces >= 1 << 24:
        raise ValueError(f"draws: {n_faces} faces do not fit the oracle's float ids (< 2^24)")
    tu = wgpu.TextureUsage
    ids = dev.create_texture(size=(width, height, 1), format=_ID_FORMAT, sample_count=SAMPLES,
                             usage=tu.RENDER_ATTACHMENT | tu.TEXTURE_BINDING)
    depth = dev.create_texture(size=(width, height, 1), format="depth32float",
                               sample_count=SAMPLES, usage=tu.RENDER_ATTACHMENT)
    nbytes = width * height * SAMPLES * 4
    out = dev.create_buffer(size=nbytes, usage=wgpu.BufferUsage.STORAGE
                            | wgpu.BufferUsage.COPY_SRC)
    enc = dev.create_command_encoder()
    rp = enc.begin_render_pass(
        color_attachments=[{"view": ids.create_view(), "clear_value": (-1.0, 0.0, 0.0, 0.0),
                            "load_op": "clear", "store_op": "store"}],
        depth_stencil_attachment={"view": depth.create_view(),
                                  "depth_clear_value": float(clear_depth),
                                  "depth_load_op": "clear", "depth_store_op": "store"})
    if n_faces:
        vb = dev.create_buffer_with_data(data=data.tobytes(), usage=wgpu.BufferUsage.VERTEX)
        rp.set_pipeline(_pipeline(ndc_y, depth_compare))
        rp.set_vertex_buffer(0, vb)
        rp.draw(3 * n_faces)
    rp.end()
    reader = _reader()
    group = dev.create_bind_group(layout=reader.get_bind_group_layout(0), entries=[
        {"binding": 0, "resource": ids.create_view()},
        {"binding": 1, "resource": {"buffer": out, "offset": 0, "size": nbytes}}])
    cp = enc.begin_compute_pass()
    cp.set_pipeline(reader)
    cp.set_bind_group(0, group)
    cp.dispatch_workgroups((width + 7) // 8, (height + 7) // 8)
    cp.end()
    dev.queue.submit([enc.finish()])
    a = np.frombuffer(dev.queue.read_buffer(out), np.int32)
    return a.reshape(height, width, SAMPLES).copy()


_PROBE = 64   # columns (rows): positions measured in 1/64 pixel


def _probe_quads(axis):
    """Clip positions (w = 1, exact in float32) and faces of the probe's quads: column (row) ``k``
    covers ``[k, k + (2k + 1)/128)`` px along ``axis`` (0: x, 1: y from the top) and the whole
    frame across it."""
    n = _PROBE
    clip, faces = [], []
    for k in range(n):
        lo, hi = Fraction(k), Fraction(k) + Fraction(2 * k + 1, 2 * n)
        a, b = (float(2 * t / n - 1) for t in (lo, hi))          # x: 2x/W − 1
        if axis == 1:
            a, b = -a, -b                                         # y from the top: 1 − 2y/H
        corners = ([(a, -1.0), (b, -1.0), (b, 1.0), (a, 1.0)] if axis == 0 else
                   [(-1.0, a), (-1.0, b), (1.0, b), (1.0, a)])
        base = len(clip)
        clip += [(x, y, 0.5, 1.0) for x, y in corners]
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(clip, np.float32), np.array(faces, np.int64)


def probe_sample_positions():
    """The positions lavapipe uses at 4×, measured (module docstring): a list of 4 ``(x, y)``
    :class:`~fractions.Fraction` pixels from the pixel's upper-left corner as the picture is seen
    (y down), each the midpoint of the 1/64-pixel interval that holds the sample (a position on
    the 1/16 grid comes out exactly). Raises ``AssertionError`` if a sample's column (row) count
    varies across the frame (the probe then measures nothing)."""
    n = _PROBE
    out = [[None, None] for _ in range(SAMPLES)]
    for axis in (0, 1):
        ids = rasterize_samples([_probe_quads(axis)], n, n)
        uncovered = (ids < 0).sum(axis=1 - axis)   # per row (x) or column (y), per sample
        for s in range(SAMPLES):
            counts = set(uncovered[:, s].tolist())
            assert len(counts) == 1, f"probe axis {axis}, sample {s}: counts {sorted(counts)}"
            out[s][axis] = Fraction(counts.pop(), n)
    return [tuple(p) for p in out]
