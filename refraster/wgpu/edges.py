"""Edge maps and NPR compositing in WGSL (Nienhaus & Döllner, WSCG 2003) for refraster.wgpu:
the paper's passes from a scene package's ``parameters`` alone (``docs/golden-schema.md``,
technique ``edges``), in ``shaders/edges.wgsl``.

1. ``T_G``: every draw with the scene's raster state into ``rgba8unorm`` (``gbuffer_format``
   ``rgba8``, the paper's) or ``rgba32float`` — normal ``0.5·n + 0.5`` in RGB, linear depth
   between near/far fitted to ``parameters.bounds`` in A — and ``object_id + 1`` into
   ``r32sint`` (20 bytes per sample at most).
2. One full-screen pass with the operators into the edge map (``rgba8unorm`` or
   ``rgba32float``, ``output_format``), ``textureLoad`` only (no sampler: no
   ``float32-filterable``), then for ``width > 1`` one dilation pass.
3. With ``parameters.npr``: the draws again with the Gooch style, the edge map of the
   fragment's pixel composited over it, into ``rgba32float`` cleared to the style's background
   (no blending: no ``float32-blendable``).

The scene's ordinary G-buffer comes from the driver's G-buffer passes; this module adds
``edge_map`` (and ``npr_color``). No optional WebGPU feature is needed.
"""

from __future__ import annotations

import numpy as np

# the package's edges parameters: one reader for both backends
from ..gl.package import DEPTH_FILTERS, NORMAL_FILTERS
from ..gl.package import edges_near_far as near_far
from ..gl.package import edges_options as options
from ..gl.package import edges_supports as supports
from .common import fullscreen, fullscreen_pipeline, scene_pipeline, uniform

__all__ = ["supports", "options", "near_far", "render", "NORMAL_FILTERS", "DEPTH_FILTERS"]

SHADER = "edges.wgsl"
FORMATS = {"rgba8": "rgba8unorm", "rgba32f": "rgba32float", "float32": "rgba32float"}
#: The planted faults of this module → the override constant of edges.wgsl they set.
FAULT_CONSTANTS = {"sobel_transposed": "SOBEL_TRANSPOSED", "one_diagonal": "ONE_DIAGONAL"}


def _layouts(backend):
    """The bind group layouts of this module's passes (made once per backend)."""
    if "_edges_layouts" in backend.__dict__:
        return backend._edges_layouts
    dev, s = backend.device, backend.wgpu.ShaderStage
    unf = {"sample_type": "unfilterable-float", "view_dimension": "2d"}
    tg = dev.create_bind_group_layout(entries=[
        {"binding": 10, "visibility": s.FRAGMENT, "buffer": {"type": "uniform"}}])
    edge = dev.create_bind_group_layout(entries=[
        {"binding": 10, "visibility": s.FRAGMENT, "buffer": {"type": "uniform"}},
        {"binding": 11, "visibility": s.FRAGMENT, "texture": unf},
        {"binding": 12, "visibility": s.FRAGMENT,
         "texture": {"sample_type": "sint", "view_dimension": "2d"}}])
    dilate = dev.create_bind_group_layout(entries=[
        {"binding": 10, "visibility": s.FRAGMENT, "buffer": {"type": "uniform"}},
        {"binding": 13, "visibility": s.FRAGMENT, "texture": unf}])
    npr = dev.create_bind_group_layout(entries=[
        {"binding": 11, "visibility": s.FRAGMENT, "buffer": {"type": "uniform"}},
        {"binding": 12, "visibility": s.FRAGMENT, "texture": unf}])
    pl = dev.create_pipeline_layout
    backend._edges_layouts = {
        "tg_group": tg, "edge_group": edge, "dilate_group": dilate, "npr_group": npr,
        "tg": pl(bind_group_layouts=[backend._group0, tg]),
        "edge": pl(bind_group_layouts=[edge]), "dilate": pl(bind_group_layouts=[dilate]),
        "npr": pl(bind_group_layouts=[backend._group0, npr])}
    return backend._edges_layouts


def render(backend, loaded, package_dir):
    """The scene's G-buffer buffers, ``edge_map (H, W, 4) float32`` and, with an ``npr``
    parameter, ``npr_color (H, W, 3) float32`` (row 0 at the top)."""
    scene, draws, conv = loaded["scene"], loaded["draws"], loaded["conv"]
    out = backend._gbuffer(loaded)
    opt = options(scene.get("parameters", {}))
    near, far = near_far(scene, package_dir)
    lay = _layouts(backend)
    dev, usage = backend.device, backend.wgpu.TextureUsage
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    state, clear = backend._state(scene, conv)
    faults = tuple((c, True) for f, c in FAULT_CONSTANTS.items() if f in backend.faults)
    tg_fmt, edge_fmt = FORMATS[opt["gbuffer_format"]], FORMATS[opt["output_format"]]
    made = []

    def texture(fmt):
        t = dev.create_texture(size=(*size, 1), format=fmt,
                               usage=usage.RENDER_ATTACHMENT | usage.TEXTURE_BINDING
                               | usage.COPY_SRC)
        made.append(t)
        return t

    try:
        tg, ids = texture(tg_fmt), texture("r32sint")
        depth = backend._depth(state, size)
        made.append(depth)
        encoder = dev.create_command_encoder()
        # pass 1: T_G
        u_tg = uniform(backend, np.array([near, far, 0, 0], np.float32))
        made.append(u_tg)
        g_tg = dev.create_bind_group(layout=lay["tg_group"], entries=[
            {"binding": 10, "resource": {"buffer": u_tg, "offset": 0, "size": 16}}])
        pipe = scene_pipeline(backend, SHADER, "fs_tg", (tg_fmt, "r32sint"), state, lay["tg"],
                              faults)
        backend._pass(encoder, pipe, [tg, ids], depth, clear, draws, g_tg)
        # pass 2: the operators
        params = np.zeros(8, np.float32)
        params.view(np.int32)[:4] = [NORMAL_FILTERS[opt["normal_filter"]],
                                     DEPTH_FILTERS[opt["depth_filter"]], int(opt["ids"]),
                                     opt["width"] - 1]
        params[4:] = [opt["k_n"], opt["k_z"], opt["inner_threshold"], opt["profile_threshold"]]
        u_edge = uniform(backend, params)
        made.append(u_edge)
        res = {"binding": 10, "resource": {"buffer": u_edge, "offset": 0, "size": 32}}
        edge = texture(edge_fmt)
        group = dev.create_bind_group(layout=lay["edge_group"], entries=[
            res, {"binding": 11, "resource": tg.create_view()},
            {"binding": 12, "resource": ids.create_view()}])
        fullscreen(backend, encoder, fullscreen_pipeline(backend, SHADER, "fs_edge", edge_fmt,
                                                         lay["edge"], faults), edge, group)
        if opt["width"] > 1:
            wide = texture(edge_fmt)
            group = dev.create_bind_group(layout=lay["dilate_group"], entries=[
                res, {"binding": 13, "resource": edge.create_view()}])
            fullscreen(backend, encoder, fullscreen_pipeline(
                backend, SHADER, "fs_dilate", edge_fmt, lay["dilate"], faults), wide, group)
            edge = wide
        color = None
        if "npr" in opt:
            color = texture("rgba32float")
            made.extend(_npr_pass(backend, encoder, opt["npr"], edge, color, state, clear,
                                  draws, faults))
        dev.queue.submit([encoder.finish()])
        e = (backend._read(edge, "rgba32float", size) if edge_fmt == "rgba32float"
             else _read_rgba8(backend, edge, size))
        out["edge_map"] = np.ascontiguousarray(e, np.float32)
        if color is not None:
            out["npr_color"] = np.ascontiguousarray(
                backend._read(color, "rgba32float", size)[..., :3], np.float32)
    finally:
        for t in made:           # textures and buffers
            t.destroy()
    return out


def _read_rgba8(backend, texture, size):
    """An rgba8unorm texture → float32 ``(H, W, 4)`` = byte / 255 (row 0 at the top)."""
    w, h = size
    data = backend.device.queue.read_texture(
        {"texture": texture, "mip_level": 0, "origin": (0, 0, 0)},
        {"offset": 0, "bytes_per_row": 4 * w}, (w, h, 1))
    raw = np.frombuffer(data, np.uint8).reshape(h, w, 4)
    return raw.astype(np.float32) / np.float32(255.0)


def _npr_pass(backend, encoder, npr, edge, target, state, clear, draws, faults):
    """Pass 3: the draws with the Gooch style and the edge map composited over it → the depth
    attachment and the uniform buffer it made (destroyed by the caller after the read-back)."""
    lay = _layouts(backend)
    kd = np.array(npr["base"])
    block = np.zeros((5, 4), np.float32)
    block[0, :3] = npr["light"]
    block[1, :3] = np.array(npr["cool"]) + npr["alpha"] * kd
    block[2, :3] = np.array(npr["warm"]) + npr["beta"] * kd
    block[3, :3] = npr["inner_color"]
    block[4, :3] = npr["profile_color"]
    u_npr = uniform(backend, block)
    group = backend.device.create_bind_group(layout=lay["npr_group"], entries=[
        {"binding": 11, "resource": {"buffer": u_npr, "offset": 0, "size": 80}},
        {"binding": 12, "resource": edge.create_view()}])
    pipe = scene_pipeline(backend, SHADER, "fs_npr", ("rgba32float",), state, lay["npr"],
                          faults)
    depth = backend._depth(state, (target.width, target.height))
    rp = encoder.begin_render_pass(
        color_attachments=[{"view": target.create_view(),
                            "clear_value": (*npr["background"], 1.0),
                            "load_op": "clear", "store_op": "store"}],
        depth_stencil_attachment={"view": depth.create_view(), "depth_clear_value": clear,
                                  "depth_load_op": "clear", "depth_store_op": "store"})
    rp.set_pipeline(pipe)
    rp.set_bind_group(1, group)
    for d in draws:
        if d["n_faces"]:
            rp.set_bind_group(0, d["group"])
            rp.set_vertex_buffer(0, d["vbo"])
            rp.draw(3 * d["n_faces"])
    rp.end()
    return depth, u_npr
