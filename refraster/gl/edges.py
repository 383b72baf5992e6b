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

import math

import numpy as np

from .common import fullscreen, programs
from .package import PackageError, matrix, read_ply

__all__ = ["supports", "near_far", "render_edges", "NORMAL_FILTERS", "DEPTH_FILTERS"]

NORMAL_FILTERS = {"diagonal": 0, "sobel": 1, "angle": 2}
DEPTH_FILTERS = {"diagonal": 0, "c1": 1, "c1-paper": 2, "sobel": 3, "diagonal2": 4}
#: The presets' option defaults (as the scene may name a preset and override options).
PRESETS = {
    "paper": dict(normal_filter="diagonal", depth_filter="diagonal", ids=False,
                  inner_threshold=0.0, profile_threshold=0.0),
    "clean": dict(normal_filter="diagonal", depth_filter="diagonal2", ids=True,
                  inner_threshold=0.1, profile_threshold=0.03),
}
FORMATS = {"rgba8": "f1", "rgba32f": "f4", "float32": "f4"}


def options(params, where="parameters"):
    """The operator options of a scene's parameters, checked → dict (raises PackageError)."""
    if not isinstance(params, dict):
        raise PackageError(f"{where} must be an object")
    preset = params.get("preset", "paper")
    if preset not in PRESETS:
        raise PackageError(f"{where}.preset must be one of {sorted(PRESETS)}, got {preset!r}")
    opt = dict(PRESETS[preset])
    for key in opt:
        if params.get(key) is not None:
            opt[key] = params[key]
    if opt["normal_filter"] not in NORMAL_FILTERS:
        raise PackageError(f"{where}.normal_filter must be one of {sorted(NORMAL_FILTERS)}")
    if opt["depth_filter"] not in DEPTH_FILTERS:
        raise PackageError(f"{where}.depth_filter must be one of {sorted(DEPTH_FILTERS)}")
    if not isinstance(opt["ids"], bool):
        raise PackageError(f"{where}.ids must be true or false")
    for key in ("inner_threshold", "profile_threshold"):
        v = opt[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
    for key in ("k_n", "k_z"):
        v = params.get(key, 1.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                or v < 0:
            raise PackageError(f"{where}.{key} must be a finite number >= 0")
        opt[key] = float(v)
    width = params.get("width", 1)
    if isinstance(width, bool) or not isinstance(width, int) or not 1 <= width <= 64:
        raise PackageError(f"{where}.width must be an integer in 1..64")
    opt["width"] = width
    npr = params.get("npr")
    if npr is not None:
        opt["npr"] = npr_options(npr, f"{where}.npr")
    for key in ("gbuffer_format", "output_format"):
        v = params.get(key, "float32")
        if v not in FORMATS:
            raise PackageError(f"{where}.{key} must be one of {sorted(FORMATS)}, got {v!r}")
        opt[key] = v
    return opt


def _rgb(v, where):
    if not (isinstance(v, list) and len(v) == 3 and all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and 0.0 <= c <= 1.0
            for c in v)):
        raise PackageError(f"{where} must be 3 numbers in [0, 1]")
    return [float(c) for c in v]


def npr_options(npr, where):
    """The NPR compositing pass's options (style ``gooch`` only) → dict."""
    if not isinstance(npr, dict) or npr.get("style") != "gooch":
        raise PackageError(f"{where}.style must be 'gooch' (the only style the gl backend has)")
    out = {}
    light = npr.get("light")
    if not (isinstance(light, list) and len(light) == 3
            and all(isinstance(c, (int, float)) and math.isfinite(c) for c in light)) \
            or not any(light):
        raise PackageError(f"{where}.light must be a non-zero direction of 3 numbers")
    out["light"] = (np.array(light, np.float64) / np.linalg.norm(light)).tolist()
    for key in ("base", "cool", "warm", "background", "inner_color", "profile_color"):
        out[key] = _rgb(npr.get(key), f"{where}.{key}")
    for key in ("alpha", "beta"):
        v = npr.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
        out[key] = float(v)
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
    the draws; a flat range is widened by a relative 1e-6 (as refraster's ``fit_near_far``)."""
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
            gl._write(prog, "u_mvp", d["mvp"])
            gl._write(prog, "u_mv", d["mv"])
            gl._write(prog, "u_nmat", d["nmat"])
            gl._set(prog, "u_object", int(d["object_id"]))
            gl._vao(d, prog).render(mgl.TRIANGLES)
        # pass 2: the operators, full screen, no depth test
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
        prog = progs["edge"]
        fbo_e[0].use()
        ctx.viewport = (0, 0, *size)
        tg.use(location=0)
        ids.use(location=1)
        gl._set(prog, "u_tg", 0)
        gl._set(prog, "u_ids", 1)
        gl._set(prog, "u_nmethod", NORMAL_FILTERS[opt["normal_filter"]])
        gl._set(prog, "u_zmethod", DEPTH_FILTERS[opt["depth_filter"]])
        gl._set(prog, "u_use_ids", bool(opt["ids"]))
        for key in ("k_n", "k_z"):
            gl._set(prog, f"u_{key}", float(opt[key]))
        gl._set(prog, "u_t_inner", float(opt["inner_threshold"]))
        gl._set(prog, "u_t_profile", float(opt["profile_threshold"]))
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
