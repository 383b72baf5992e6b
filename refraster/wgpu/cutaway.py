"""Adaptive cutaways in WGSL (Burns & Finkelstein 2008) for refraster.wgpu, from a scene
package's ``parameters`` alone (``docs/golden-schema.md``, technique ``cutaway``), in
``shaders/cutaway.wgsl``. Render passes only, every texture read with ``textureLoad``; no
optional WebGPU feature, WebGPU's default limits.

1. rear hulls of the objects of interest (``parameters.interest``): depth test ``greater``
   against a ``depth32float`` attachment cleared to 0, no culling → r32float window depth and
   r32sint hull index + 1;
2. seeds (full screen): two rgba32float targets (seed record, floor record; 32 bytes);
3. jump flooding: one full-screen pass per jump length of ``parameters.variant``'s schedule
   (:func:`refraster.gl.package.cutaway_step_schedule`), ping-pong between two pairs of
   rgba32float textures, the last pass writing D (OpenGL NDC depth) to r32float;
4. D_dil (3×3 minimum) and the cut surfaces' normals from it;
5. the G-buffer of the secondary draws then the objects of interest in the driver's three
   passes (28, 32, 16 bytes per sample), each with the cutaway's discard, so each pass keeps
   the same fragments; the first adds the cut flag;
6. ghost lines: the secondary meshes' feature lines (found on the CPU by the package reader,
   :func:`refraster.gl.package.cutaway_ghost_lines`) as a line list whose opacity is written as
   the fragment depth into a ``depth32float`` attachment under ``greater``: the maximum over
   the lines without blending (float32 is not blendable in core WebGPU).

Buffers: the G-buffer, ``cutaway_depth`` (window depth ½D + ½), ``cut_mask`` and ``ghost``.
"""

from __future__ import annotations

import numpy as np

from ..gl.package import PackageError, cutaway_ghost_lines, cutaway_options, matrix
from ..gl.package import cutaway_step_schedule as step_schedule
from ..gl.package import cutaway_supports
from .common import fullscreen, fullscreen_pipeline, gbuffer_arrays, scene_pipeline, uniform

__all__ = ["supports", "render", "step_schedule", "schedule"]

SHADER = "cutaway.wgsl"
#: The planted faults of this module that set an override constant of cutaway.wgsl.
FAULT_CONSTANTS = {"ndc_y_from_row": "NDC_Y_FROM_ROW",
                   "ghost_not_depth_tested": "GHOST_NOT_DEPTH_TESTED"}
#: The clipped G-buffer's passes: entry point → target formats (bytes per sample 28, 32, 16).
PASSES = {"fs_cut_ids": ("r32float", "r32float", "rgba32sint", "r32sint"),
          "fs_cut_surface": ("rgba32float", "rgba32float"),
          "fs_cut_shade": ("rgba32float",)}
_RGBA = "rgba32float"


def supports(scene):
    """``None`` if this module can draw the cutaway scene, else the reason."""
    reason = cutaway_supports(scene)
    fmt = scene.get("raster", {}).get("depth_format", "float32")
    if reason is None and fmt != "float32":
        reason = (f"cutaway with raster.depth_format {fmt!r}: the passes compare the float32 "
                  "window depth with D; only 'float32'")
    return reason


def schedule(height, width, variant, faults=()):
    """The jump lengths this backend runs: the package's schedule, or with the planted fault
    ``jfa_halved_once_more`` the one whose jump is halved once too often from pass to pass
    (n/2, n/8, n/32, …: every other length of the plain part left out)."""
    steps = step_schedule(height, width, variant)
    if "jfa_halved_once_more" in faults:                   # planted fault
        plain = step_schedule(height, width, "jfa")
        halved = plain[::2]                                # k → k/4 from pass to pass
        steps = [1] + halved if variant == "1+jfa" else halved + steps[len(plain):]
    return steps


def _layouts(backend):
    if "_cutaway_layouts" in backend.__dict__:
        return backend._cutaway_layouts
    dev, s = backend.device, backend.wgpu.ShaderStage
    unf = {"sample_type": "unfilterable-float", "view_dimension": "2d"}
    sint = {"sample_type": "sint", "view_dimension": "2d"}

    def group(ubo, textures, vis=s.FRAGMENT):
        entries = [{"binding": ubo, "visibility": vis, "buffer": {"type": "uniform"}}]
        entries += [{"binding": b, "visibility": s.FRAGMENT, "texture": kind}
                    for b, kind in textures]
        return dev.create_bind_group_layout(entries=entries)

    g = {"hull": group(30, []), "seed": group(31, [(32, unf), (33, sint)]),
         "flood": group(34, [(35, unf), (36, unf)]), "dilate": group(37, [(38, unf)]),
         "cut": group(40, [(41, unf), (42, unf), (43, unf)]),
         "ghost": group(44, [(45, unf), (46, unf)], s.VERTEX | s.FRAGMENT)}
    pl = dev.create_pipeline_layout
    lay = {f"{k}_group": v for k, v in g.items()}
    lay.update(hull=pl(bind_group_layouts=[backend._group0, g["hull"]]),
               cut=pl(bind_group_layouts=[backend._group0, g["cut"]]),
               **{k: pl(bind_group_layouts=[g[k]]) for k in ("seed", "flood", "dilate",
                                                             "ghost")})
    backend._cutaway_layouts = lay
    return lay


def _mat(m):
    """A row-major 4×4 matrix as WGSL's column-major float32."""
    return np.asarray(m, np.float32).T.reshape(-1)


def render(backend, loaded, package_dir):
    """The cutaway scene's buffers as the golden stores them (row 0 at the top)."""
    scene, draws, conv = loaded["scene"], loaded["draws"], loaded["conv"]
    opt, reason = cutaway_options(scene)
    if reason is not None:          # supports() said so already; a package edited since
        raise PackageError(reason)
    lay = _layouts(backend)
    dev, usage = backend.device, backend.wgpu.TextureUsage
    w, h = size = (scene["viewport"]["width"], scene["viewport"]["height"])
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    persp = bool(np.array_equal(proj[3], [0, 0, -1, 0]))
    state, clear = backend._state(scene, conv)
    faults = tuple((c, True) for f, c in FAULT_CONSTANTS.items() if f in backend.faults)
    made = []

    def texture(fmt, depth=False):
        use = usage.RENDER_ATTACHMENT | usage.TEXTURE_BINDING
        if not depth:
            use |= usage.COPY_SRC
        t = dev.create_texture(size=(w, h, 1), format=fmt, usage=use)
        made.append(t)
        return t

    def buffer(data):
        b = uniform(backend, data)
        made.append(b)
        return b

    def bind(layout, ubo, views):
        entries = [{"binding": ubo[0], "resource": {"buffer": ubo[1], "offset": 0,
                                                    "size": ubo[1].size}}]
        entries += [{"binding": b, "resource": t.create_view()} for b, t in views]
        return dev.create_bind_group(layout=layout, entries=entries)

    try:
        encoder = dev.create_command_encoder()
        # 1. rear hulls
        rear, hull = texture("r32float"), texture("r32sint")
        hull_depth = texture("depth32float", depth=True)
        compare, cull, front, write, fmt, clamp, base = state
        hull_state = ("greater", "none", front, True, "depth32float", clamp, base)
        pipe = scene_pipeline(backend, SHADER, "fs_hull", ("r32float", "r32sint"), hull_state,
                              lay["hull"], faults)
        rp = encoder.begin_render_pass(
            color_attachments=[{"view": t.create_view(), "clear_value": (0, 0, 0, 0),
                                "load_op": "clear", "store_op": "store"} for t in (rear, hull)],
            depth_stencil_attachment={"view": hull_depth.create_view(),
                                      "depth_clear_value": 0.0, "depth_load_op": "clear",
                                      "depth_store_op": "store"})
        rp.set_pipeline(pipe)
        for k, i in enumerate(opt["interest"]):
            d = draws[i]
            if not d["n_faces"]:
                continue
            rp.set_bind_group(0, d["group"])
            rp.set_bind_group(1, bind(lay["hull_group"],
                                      (30, buffer(np.array([k, 0, 0, 0], np.int32))), []))
            rp.set_vertex_buffer(0, d["vbo"])
            rp.draw(3 * d["n_faces"])
        rp.end()
        # 2. seeds
        floor = opt["floor_normal"] is not None
        block = np.zeros(36, np.float32)
        block[:len(opt["angles"])] = opt["angles"]
        block.view(np.int32)[8:12] = [len(opt["angles"]),
                                      0 if not persp else
                                      (1 if opt["perspective_compensation"] else 2),
                                      int(floor), 0]
        block[12:16] = [proj[2, 2], proj[0, 0], opt["r"], opt["floor_margin"]]
        if floor:
            n = np.linalg.inv(view[:3, :3]).T @ np.array(opt["floor_normal"])
            block[16:19] = n / np.linalg.norm(n)
        block[20:36] = _mat(np.linalg.inv(proj))
        recs = [(texture(_RGBA), texture(_RGBA)) for _ in range(2)]
        group = bind(lay["seed_group"], (31, buffer(block)), [(32, rear), (33, hull)])
        fullscreen(backend, encoder, fullscreen_pipeline(
            backend, SHADER, "fs_seed", (_RGBA, _RGBA), lay["seed"], faults),
            list(recs[0]), group)
        # 3. jump flooding
        steps = schedule(h, w, opt["variant"], backend.faults)
        dtex = texture("r32float")
        sampling = (2.0 / (w * proj[0, 0]), 2.0 / (h * proj[1, 1]))
        cur = 0
        for n_, k in enumerate(steps):
            last = n_ == len(steps) - 1
            fb = np.zeros(8, np.float32)
            fb.view(np.int32)[:2] = [int(k), int(floor)]
            fb[4:6] = sampling
            group = bind(lay["flood_group"], (34, buffer(fb)),
                         [(35, recs[cur][0]), (36, recs[cur][1])])
            if last:
                pipe = fullscreen_pipeline(backend, SHADER, "fs_flood_final", "r32float",
                                           lay["flood"], faults)
                fullscreen(backend, encoder, pipe, dtex, group)
            else:
                pipe = fullscreen_pipeline(backend, SHADER, "fs_flood", (_RGBA, _RGBA),
                                           lay["flood"], faults)
                fullscreen(backend, encoder, pipe, list(recs[1 - cur]), group)
            cur = 1 - cur
        # 4. D_dil and the cut normals
        block = np.zeros(20, np.float32)
        block[:16] = _mat(np.linalg.inv(proj))
        block.view(np.int32)[16] = int(persp)
        ubo = buffer(block)
        if opt["dilation"]:
            ddil = texture("r32float")
            fullscreen(backend, encoder, fullscreen_pipeline(
                backend, SHADER, "fs_dilate", "r32float", lay["dilate"], faults), ddil,
                bind(lay["dilate_group"], (37, ubo), [(38, dtex)]))
        else:
            ddil = dtex
        cutn = texture(_RGBA)
        fullscreen(backend, encoder, fullscreen_pipeline(
            backend, SHADER, "fs_normals", _RGBA, lay["dilate"], faults), cutn,
            bind(lay["dilate_group"], (37, ubo), [(38, ddil)]))
        # 5. the clipped G-buffer: the secondary draws, then the objects of interest
        sec = set(opt["secondary"])
        order = [(draws[i], bind(lay["cut_group"], (40, buffer(np.array(
            [int(i in sec), int(opt["dilation"]), 0, 0], np.int32))),
            [(41, dtex), (42, ddil), (43, cutn)]))
            for i in opt["secondary"] + opt["interest"] if draws[i]["n_faces"]]
        depth = backend._depth(state, size)
        made.append(depth)
        targets = {}
        for entry, formats in PASSES.items():
            ts = [texture(f) for f in formats]
            targets[entry] = ts
            pipe = scene_pipeline(backend, SHADER, entry, formats, state, lay["cut"], faults)
            rp = encoder.begin_render_pass(
                color_attachments=[{"view": t.create_view(), "clear_value": (0, 0, 0, 0),
                                    "load_op": "clear", "store_op": "store"} for t in ts],
                depth_stencil_attachment={"view": depth.create_view(),
                                          "depth_clear_value": clear, "depth_load_op": "clear",
                                          "depth_store_op": "store"})
            rp.set_pipeline(pipe)
            for d, g in order:
                rp.set_bind_group(0, d["group"])
                rp.set_bind_group(1, g)
                rp.set_vertex_buffer(0, d["vbo"])
                rp.draw(3 * d["n_faces"])
            rp.end()
        dev.queue.submit([encoder.finish()])
        got = {entry: [backend._read(t, f, size) for t, f in zip(targets[entry], formats)]
               for entry, formats in PASSES.items()}
        d_ndc = backend._read(dtex, "r32float", size)[..., 0]
        out, covered = _gbuffer(scene, got)
        # 6. ghost lines
        ghost = np.zeros((h, w), np.float32)
        seg, g_max = cutaway_ghost_lines(scene, package_dir, opt)
        if len(seg):
            interest_ids = [int(draws[i]["object_id"]) for i in opt["interest"]]
            ooi = covered & np.isin(out["object_id"], interest_ids)
            occ = np.where(ooi, 2.0 * out["depth"] - 1.0, 2.0).astype(np.float32)
            ghost = _ghost(backend, lay, seg, occ, dtex, view, proj, g_max, opt, state,
                           faults, made)
    finally:
        for t in made:
            t.destroy()
    out["cutaway_depth"] = (np.float32(0.5) * d_ndc + np.float32(0.5)).astype(np.float32)
    out["cut_mask"] = covered & (got["fs_cut_ids"][3][..., 0] == 1)
    out["ghost"] = np.ascontiguousarray(ghost, np.float32)
    return out


def _gbuffer(scene, got):
    """The G-buffer's buffers from the three passes' read-backs → ``(out, covered)``."""
    win, eye, ids, _ = got["fs_cut_ids"]
    normal, bary = got["fs_cut_surface"]
    return gbuffer_arrays(scene, win[..., 0], eye, ids, normal, bary, got["fs_cut_shade"][0])


def _ghost(backend, lay, seg, occ, dtex, view, proj, g_max, opt, state, faults, made):
    """Pass 6 → the ghost opacity (H, W) float32: the lines' maximum kept by the depth test."""
    dev, wgpu = backend.device, backend.wgpu
    h, w = occ.shape
    occ_tex = dev.create_texture(size=(w, h, 1), format="r32float",
                                 usage=wgpu.TextureUsage.TEXTURE_BINDING
                                 | wgpu.TextureUsage.COPY_DST)
    made.append(occ_tex)
    dev.queue.write_texture({"texture": occ_tex}, np.ascontiguousarray(occ).tobytes(),
                            {"bytes_per_row": 4 * w, "rows_per_image": h}, (w, h, 1))
    block = np.zeros(24, np.float32)
    block[:16] = _mat(proj @ view)
    block[16:20] = [proj[2, 2], proj[2, 3], proj[3, 2], proj[3, 3]]
    block[20:22] = [g_max, 1.0 if opt["ghost_fade"] else 0.0]
    ubo = uniform(backend, block)
    made.append(ubo)
    group = dev.create_bind_group(layout=lay["ghost_group"], entries=[
        {"binding": 44, "resource": {"buffer": ubo, "offset": 0, "size": ubo.size}},
        {"binding": 45, "resource": dtex.create_view()},
        {"binding": 46, "resource": occ_tex.create_view()}])
    vbo = dev.create_buffer_with_data(
        data=np.ascontiguousarray(seg.reshape(-1, 3), np.float32).tobytes(),
        usage=wgpu.BufferUsage.VERTEX)
    made.append(vbo)
    alpha = dev.create_texture(size=(w, h, 1), format="depth32float",
                               usage=wgpu.TextureUsage.RENDER_ATTACHMENT
                               | wgpu.TextureUsage.TEXTURE_BINDING)
    made.append(alpha)
    constants = dict(state[6])
    constants.update(faults)
    key = ("ghost", tuple(sorted(constants.items())))
    cache = backend.__dict__.setdefault("_technique_pipelines", {})
    if key not in cache:
        from .common import module
        mod = module(backend, SHADER)
        cache[key] = dev.create_render_pipeline(
            layout=lay["ghost"],
            vertex={"module": mod, "entry_point": "vs_line", "constants": constants,
                    "buffers": [{"array_stride": 12, "attributes": [
                        {"format": "float32x3", "offset": 0, "shader_location": 0}]}]},
            primitive={"topology": "line-list"},
            depth_stencil={"format": "depth32float", "depth_write_enabled": True,
                           "depth_compare": "greater"},
            multisample={"count": 1},
            fragment={"module": mod, "entry_point": "fs_ghost", "constants": constants,
                      "targets": []})
    encoder = dev.create_command_encoder()
    rp = encoder.begin_render_pass(
        color_attachments=[],
        depth_stencil_attachment={"view": alpha.create_view(), "depth_clear_value": 0.0,
                                  "depth_load_op": "clear", "depth_store_op": "store"})
    rp.set_pipeline(cache[key])
    rp.set_bind_group(0, group)
    rp.set_vertex_buffer(0, vbo)
    rp.draw(2 * len(seg))
    rp.end()
    dev.queue.submit([encoder.finish()])
    return backend._read_depth_buffer(alpha, (w, h))
