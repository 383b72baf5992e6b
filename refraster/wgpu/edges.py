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

import math

import numpy as np

from ..gl.package import PackageError, matrix, read_ply
from .common import fullscreen, fullscreen_pipeline, scene_pipeline, uniform

__all__ = ["supports", "options", "near_far", "render", "NORMAL_FILTERS", "DEPTH_FILTERS"]

SHADER = "edges.wgsl"
NORMAL_FILTERS = {"diagonal": 0, "sobel": 1, "angle": 2}
DEPTH_FILTERS = {"diagonal": 0, "c1": 1, "c1-paper": 2, "sobel": 3, "diagonal2": 4}
#: The presets' option defaults (docs/edges.md); a scene may name a preset and override.
PRESETS = {
    "paper": dict(normal_filter="diagonal", depth_filter="diagonal", ids=False,
                  inner_threshold=0.0, profile_threshold=0.0),
    "clean": dict(normal_filter="diagonal", depth_filter="diagonal2", ids=True,
                  inner_threshold=0.1, profile_threshold=0.03),
}
#: ``gbuffer_format`` / ``output_format`` → the WebGPU texture format.
FORMATS = {"rgba8": "rgba8unorm", "rgba32f": "rgba32float", "float32": "rgba32float"}
#: The planted faults of this module → the override constant of edges.wgsl they set.
FAULT_CONSTANTS = {"sobel_transposed": "SOBEL_TRANSPOSED", "one_diagonal": "ONE_DIAGONAL"}


def _number(v, lo, hi):
    return (not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
            and lo <= v <= hi)


def options(params, where="parameters"):
    """The operator options of a scene's parameters, checked → dict (raises PackageError)."""
    if not isinstance(params, dict):
        raise PackageError(f"{where} must be an object")
    preset = params.get("preset", "paper")
    if preset not in PRESETS:
        raise PackageError(f"{where}.preset must be one of {sorted(PRESETS)}, got {preset!r}")
    opt = dict(PRESETS[preset])
    opt.update({k: params[k] for k in opt if params.get(k) is not None})
    if opt["normal_filter"] not in NORMAL_FILTERS:
        raise PackageError(f"{where}.normal_filter must be one of {sorted(NORMAL_FILTERS)}")
    if opt["depth_filter"] not in DEPTH_FILTERS:
        raise PackageError(f"{where}.depth_filter must be one of {sorted(DEPTH_FILTERS)}")
    if not isinstance(opt["ids"], bool):
        raise PackageError(f"{where}.ids must be true or false")
    for key in ("inner_threshold", "profile_threshold"):
        if not _number(opt[key], 0.0, 1.0):
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
    for key in ("k_n", "k_z"):
        v = params.get(key, 1.0)
        if not _number(v, 0.0, math.inf):
            raise PackageError(f"{where}.{key} must be a finite number >= 0")
        opt[key] = float(v)
    width = params.get("width", 1)
    if isinstance(width, bool) or not isinstance(width, int) or not 1 <= width <= 64:
        raise PackageError(f"{where}.width must be an integer in 1..64")
    opt["width"] = width
    for key in ("gbuffer_format", "output_format"):
        v = params.get(key, "float32")
        if v not in FORMATS:
            raise PackageError(f"{where}.{key} must be one of {sorted(FORMATS)}, got {v!r}")
        opt[key] = v
    if params.get("npr") is not None:
        opt["npr"] = npr_options(params["npr"], f"{where}.npr")
    return opt


def npr_options(npr, where):
    """The NPR pass's options (style ``gooch``; ``mask`` ``objects``) → dict."""
    if not isinstance(npr, dict) or npr.get("style") != "gooch":
        raise PackageError(f"{where}.style must be 'gooch' (the only style the wgpu backend "
                           "has)")
    if npr.get("mask", "objects") != "objects":
        raise PackageError(f"{where}.mask must be 'objects'")
    light = npr.get("light")
    if not (isinstance(light, list) and len(light) == 3
            and all(_number(c, -math.inf, math.inf) for c in light)) or not any(light):
        raise PackageError(f"{where}.light must be a non-zero direction of 3 numbers")
    out = {"light": (np.array(light, np.float64) / np.linalg.norm(light)).tolist()}
    for key in ("base", "cool", "warm", "background", "inner_color", "profile_color"):
        v = npr.get(key)
        if not (isinstance(v, list) and len(v) == 3 and all(_number(c, 0.0, 1.0) for c in v)):
            raise PackageError(f"{where}.{key} must be 3 numbers in [0, 1]")
        out[key] = [float(c) for c in v]
    for key in ("alpha", "beta"):
        if not _number(npr.get(key), 0.0, 1.0):
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
        out[key] = float(npr[key])
    return out


def supports(scene):
    """``None`` if the edges scene can be rendered, else the reason."""
    try:
        options(scene.get("parameters", {}))
    except PackageError as exc:
        return f"edges: {exc}"
    return None


def near_far(scene, package_dir=None):
    """Near and far (float64) fitted to ``parameters.bounds`` (the eight corners of the world
    box in eye space; Sec. 4.1.1), or without bounds to the eye-space depth of every vertex of
    the draws; a flat range is widened by a relative 1e-6."""
    view = matrix(scene["camera"]["view"], "camera.view")
    bounds = scene.get("parameters", {}).get("bounds")
    if bounds is not None:
        try:
            b = np.array(bounds, np.float64)
        except (TypeError, ValueError):
            b = None
        if b is None or b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
            raise PackageError("parameters.bounds must be [[xmin, ymin, zmin], [xmax, ymax, "
                               "zmax]] of finite numbers")
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        z = -(corners @ view[2, :3] + view[2, 3])
    else:
        zs = []
        for i, d in enumerate(scene["draws"]):
            v, _, _ = read_ply(package_dir / d["mesh"], d.get("n_vertices"), d.get("n_faces"))
            mv = view @ matrix(d["model"], f"draws[{i}].model")
            zs.append(-(v.astype(np.float64) @ mv[2, :3] + mv[2, 3]))
        z = np.concatenate(zs) if zs else np.zeros(0)
        if z.size == 0:
            raise PackageError("edges: no bounds and no vertices to fit near and far to")
    near, far = float(z.min()), float(z.max())
    if not far > near:
        far = near + max(abs(near), 1.0) * 1e-6
    return near, far


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
