"""Edge maps on the GPU (Nienhaus & Döllner, WSCG 2003) for refraster.gl: the paper's passes
from a scene package's ``parameters`` alone (``docs/golden-schema.md``, technique ``edges``).

1. The edge G-buffer ``T_G``: every draw with the scene's raster state into an RGBA8 (the
   paper's; ``gbuffer_format``) or RGBA32F target — encoded normal ``0.5·n + 0.5`` in RGB, linear
   depth between near/far fitted to ``parameters.bounds`` in A — and ``object_id + 1`` into an
   R32I target (``shaders/edge_gbuffer.frag``).
2. One full-screen pass with the chosen operators into the edge map, RGBA8 or RGBA32F
   (``output_format``; ``shaders/edge_map.frag``), then for ``width > 1`` one grey dilation
   pass (``shaders/edge_dilate.frag``).

The scene's ordinary G-buffer buffers (depth, normal, ids, …) come from the driver's G-buffer
pass; this module adds ``edge_map``. Only NumPy and the standard library besides moderngl.
"""

from __future__ import annotations

import numpy as np

from .common import fullscreen, programs
# the package's edges parameters: one reader for both backends (refraster.gl.package)
from .package import DEPTH_FILTERS, NORMAL_FILTERS
from .package import edges_near_far as near_far
from .package import edges_options as options
from .package import edges_supports as supports

__all__ = ["supports", "near_far", "render_edges", "operator_uniforms", "NORMAL_FILTERS",
           "DEPTH_FILTERS"]

FORMATS = {"rgba8": "f1", "rgba32f": "f4", "float32": "f4"}


#: The programs (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {
    "gbuffer": ("gbuffer.vert", "gbuffer.geom", "edge_gbuffer.frag"),
    "edge": ("fullscreen.vert", None, "edge_map.frag"),
    "dilate": ("fullscreen.vert", None, "edge_dilate.frag"),
    "npr": ("gbuffer.vert", "gbuffer.geom", "edge_npr.frag"),
}


def render_edges(gl, loaded, package_dir=None):
    """The scene's G-buffer buffers and ``edge_map (H, W, 4) float32`` (row 0 at the top)."""
    scene, draws = loaded["scene"], loaded["draws"]
    out = gl._gbuffer(scene, draws)
    opt = options(scene.get("parameters", {}))
    near, far = near_far(scene, package_dir)
    progs = programs(gl, SHADERS)
    mgl, ctx = gl.mgl, gl.ctx
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    tg = ctx.texture(size, 4, dtype=FORMATS[opt["gbuffer_format"]])
    ids = ctx.texture(size, 1, dtype="i4")
    fmt = FORMATS[opt["output_format"]]
    edge = [ctx.texture(size, 4, dtype=fmt) for _ in range(2 if opt["width"] > 1 else 1)]
    for t in (tg, ids, *edge):
        t.filter = (mgl.NEAREST, mgl.NEAREST)
    depth = gl._depth_attachment(size)
    fbo = ctx.framebuffer(color_attachments=[tg, ids], depth_attachment=depth)
    fbo_e = [ctx.framebuffer(color_attachments=[t]) for t in edge]
    try:
        # pass 1: T_G
        prog = progs["gbuffer"]
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=float(scene["raster"]["clear_depth"]))
        gl._state(scene)
        gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
        gl._set(prog, "u_viewport", tuple(float(s) for s in size))
        gl._set(prog, "u_near_far", (near, far))
        for d in draws:
            if not d["n_faces"]:
                continue
            gl._draw(prog, d)
        # pass 2: the operators, full screen, no depth test
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
        prog = progs["edge"]
        fbo_e[0].use()
        ctx.viewport = (0, 0, *size)
        tg.use(location=0)
        ids.use(location=1)
        operator_uniforms(gl, prog, opt)
        fullscreen(gl, prog)
        result = edge[0]
        if opt["width"] > 1:
            prog = progs["dilate"]
            fbo_e[1].use()
            edge[0].use(location=0)
            gl._set(prog, "u_edge", 0)
            gl._set(prog, "u_radius", opt["width"] - 1)
            fullscreen(gl, prog)
            result = edge[1]
        npr = None
        if "npr" in opt:
            npr = _npr_pass(gl, scene, draws, opt["npr"], result, size, progs["npr"])
        ctx.finish()
        if fmt == "f1":
            e = gl._read(result, "u1", 4, size).astype(np.float32) / np.float32(255.0)
        else:
            e = gl._read(result, "<f4", 4, size)
    finally:
        gl._parking.use()
        for obj in (*fbo_e, fbo, depth, tg, ids, *edge):
            obj.release()
    out["edge_map"] = np.ascontiguousarray(e, np.float32)
    if npr is not None:
        out["npr_color"] = npr
    return out


def operator_uniforms(gl, prog, opt):
    """Pass 2's uniforms: T_G on unit 0, the ids on unit 1, the operators and thresholds."""
    gl._set(prog, "u_tg", 0)
    gl._set(prog, "u_ids", 1)
    gl._set(prog, "u_nmethod", NORMAL_FILTERS[opt["normal_filter"]])
    gl._set(prog, "u_zmethod", DEPTH_FILTERS[opt["depth_filter"]])
    gl._set(prog, "u_use_ids", bool(opt["ids"]))
    for key in ("k_n", "k_z"):
        gl._set(prog, f"u_{key}", float(opt[key]))
    gl._set(prog, "u_t_inner", float(opt["inner_threshold"]))
    gl._set(prog, "u_t_profile", float(opt["profile_threshold"]))


def _npr_pass(gl, scene, draws, npr, edge_tex, size, prog):
    """Pass 3: the objects again with the Gooch style and the edge map blended over it."""
    mgl, ctx = gl.mgl, gl.ctx
    target = ctx.texture(size, 4, dtype="f4")
    depth = gl._depth_attachment(size)
    fbo = ctx.framebuffer(color_attachments=[target], depth_attachment=depth)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(*npr["background"], 1.0, depth=float(scene["raster"]["clear_depth"]))
        gl._state(scene)
        edge_tex.use(location=0)
        gl._set(prog, "u_edge", 0)
        kd = np.array(npr["base"])
        gl._set(prog, "u_light", tuple(npr["light"]))
        gl._set(prog, "u_cool", tuple(np.array(npr["cool"]) + npr["alpha"] * kd))
        gl._set(prog, "u_warm", tuple(np.array(npr["warm"]) + npr["beta"] * kd))
        gl._set(prog, "u_inner_color", tuple(npr["inner_color"]))
        gl._set(prog, "u_profile_color", tuple(npr["profile_color"]))
        gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
        gl._set(prog, "u_viewport", tuple(float(s) for s in size))
        for d in draws:
            if not d["n_faces"]:
                continue
            gl._write(prog, "u_mvp", d["mvp"])
            gl._write(prog, "u_mv", d["mv"])
            gl._write(prog, "u_nmat", d["nmat"])
            gl._vao(d, prog).render(mgl.TRIANGLES)
        ctx.finish()
        return np.ascontiguousarray(gl._read(target, "<f4", 4, size)[..., :3], np.float32)
    finally:
        gl._parking.use()
        for obj in (fbo, depth, target):
            obj.release()
