"""Multisampled G-buffers on a GL multisample framebuffer (issue 43, item 5; docs/backends.md,
"Multisampling").

A scene of technique ``msaa`` declares its sample pattern (``parameters.sample_pattern``:
``raster.samples`` positions ``[x, y]`` in 1/16 pixel, y down from the pixel's upper-left
corner as the picture is seen). GL's sample positions are the implementation's: this backend
draws only where the context's own positions (``glGetMultisamplefv(GL_SAMPLE_POSITION, i)``,
window coordinates with y **up**, turned into the picture's y down: ``(16·x, 16 − 16·y)``) are
the declared ones, and states them in the candidate (``<scene>/sample_pattern.json``).

The G-buffer shaders of the single-sample pass draw into multisample targets of
``raster.samples`` samples (a ``DEPTH_COMPONENT32F`` multisample depth texture, the depth test
per sample at the sample positions, attributes at the pixel centre: no ``centroid``, no sample
shading); a full-screen pass per sample reads every target with ``texelFetch(…, s)``, the
window depth from the depth attachment itself (the depth GL tested at the sample). The
resolved colour is ``glBlitFramebuffer`` of the float colour target (the box filter of the
stored, linear values); uncovered samples hold the background colour (cleared to it).
"""

from __future__ import annotations

import ctypes

import numpy as np

from .common import GLUnavailable, Unsupported, fullscreen, gl_function, programs
from .package import CONVENTION_DEFAULTS, conventions

__all__ = ["supports", "sample_pattern", "render_msaa"]

_GL_TEXTURE_2D_MULTISAMPLE = 0x9100
_GL_DEPTH_COMPONENT32F = 0x8CAC
_GL_SAMPLE_POSITION = 0x8E50
_GL_MULTISAMPLE = 0x809D
_GL_COLOR = 0x1800

_SHADERS = {"fetch": ("fullscreen.vert", None, "msaa_fetch.frag"),
            "srgb_resolve": ("fullscreen.vert", None, "msaa_srgb_resolve.frag")}

_FNS = {}


def _fns():
    if not _FNS:
        fn = gl_function
        u, i = ctypes.c_uint, ctypes.c_int
        _FNS.update({
            "BindTexture": fn("glBindTexture", None, u, u),
            "TexImage2DMultisample": fn("glTexImage2DMultisample", None, u, i, u, i, i,
                                        ctypes.c_ubyte),
            "GetMultisamplefv": fn("glGetMultisamplefv", None, u, u,
                                   ctypes.POINTER(ctypes.c_float)),
            "GetError": fn("glGetError", u),
            "Enable": fn("glEnable", None, u), "Disable": fn("glDisable", None, u),
            "ClearBufferfv": fn("glClearBufferfv", None, u, i, ctypes.POINTER(ctypes.c_float)),
        })
    return _FNS


def supports(scene):
    """``None`` if this backend can draw the ``msaa`` scene (a ``scene.json`` dict), else the
    reason (the context's own positions are checked when it is drawn)."""
    conv = conventions(scene.get("raster", {}))
    if conv != CONVENTION_DEFAULTS:
        changed = sorted(k for k in conv if conv[k] != CONVENTION_DEFAULTS[k])
        return f"msaa: OpenGL's conventions only; the scene sets raster {', '.join(changed)}"
    if scene["raster"].get("interpolation", "center") != "center":
        return (f"msaa: interpolation {scene['raster']['interpolation']!r}: only 'center' (GL's "
                "default) is implemented")
    return None


def _depth_texture(gl, size, samples):
    """A multisample depth texture re-specified as ``DEPTH_COMPONENT32F``."""
    tex = gl.ctx.depth_texture(size, samples=samples)
    f = _fns()
    while f["GetError"]():
        pass
    f["BindTexture"](_GL_TEXTURE_2D_MULTISAMPLE, tex.glo)
    f["TexImage2DMultisample"](_GL_TEXTURE_2D_MULTISAMPLE, samples, _GL_DEPTH_COMPONENT32F,
                               size[0], size[1], 1)
    err = f["GetError"]()
    if err:
        tex.release()
        raise Unsupported(f"msaa: glTexImage2DMultisample(depth32f, {samples} samples) failed: "
                          f"GL error {err:#x}")
    return tex


def _positions(gl, fbo, samples):
    """The bound multisample framebuffer's sample positions, as the picture is seen: ``[x, y]``
    in 1/16 pixel, y down (GL reports window coordinates in [0, 1), y up)."""
    f = _fns()
    fbo.use()
    out = []
    for i in range(samples):
        v = (ctypes.c_float * 2)()
        f["GetMultisamplefv"](_GL_SAMPLE_POSITION, i, v)
        out.append([int(round(16.0 * v[0])), int(round(16.0 - 16.0 * v[1]))])
    return out


def sample_pattern(gl, samples):
    """``{"samples": S, "positions": [[x, y], ...]}``: this context's pattern at ``samples``
    (what a candidate states), or ``None`` when it has no such multisample framebuffer."""
    cache = gl.__dict__.setdefault("_sample_patterns", {})
    if samples not in cache:
        ctx = gl.ctx
        try:
            tex = ctx.texture((1, 1), 4, samples=samples, dtype="f4")
        except Exception:
            cache[samples] = None
            return None
        fbo = ctx.framebuffer(color_attachments=[tex])
        try:
            cache[samples] = {"samples": samples, "positions": _positions(gl, fbo, samples)}
        finally:
            gl._parking.use()
            fbo.release()
            tex.release()
    return cache[samples]


def _text(pattern):
    return " ".join(f"({x}, {y})" for x, y in pattern)


def render_msaa(gl, loaded):
    """Draw a :meth:`~refraster.gl.driver.Backend.load`-ed ``msaa`` scene → the golden's
    buffers: ``sample<s>_<channel>`` and the resolved ``color`` (module docstring)."""
    scene, draws = loaded["scene"], loaded["draws"]
    raster, shading = scene["raster"], scene["shading"]
    samples = int(raster["samples"])
    declared = scene["parameters"]["sample_pattern"]["positions"]
    own = sample_pattern(gl, samples)
    if own is None:
        raise Unsupported(f"msaa: this OpenGL has no {samples}-sample float framebuffer "
                          f"({gl.renderer})")
    if own["positions"] != declared:
        raise Unsupported(f"msaa: this OpenGL's {samples}x sample positions are "
                          f"{_text(own['positions'])}, the scene declares {_text(declared)} "
                          "(1/16 pixel, y down)")
    ctx, mgl, faults = gl.ctx, gl.mgl, gl.faults
    prog = gl.gbuffer
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    ms = [ctx.texture(size, c, samples=samples, dtype=d)
          for c, d in ((1, "f4"), (1, "f4"), (4, "f4"), (4, "f4"), (4, "f4"), (4, "i4"))]
    depth = _depth_texture(gl, size, samples)
    fbo = ctx.framebuffer(color_attachments=ms, depth_attachment=depth)
    single = [ctx.texture(size, 1, dtype="f4"), ctx.texture(size, 4, dtype="f4"),
              ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="i4")]
    out_fbo = ctx.framebuffer(color_attachments=single)
    resolved = ctx.texture(size, 4, dtype="f4")
    resolved_fbo = ctx.framebuffer(color_attachments=[resolved])
    colour_fbo = ctx.framebuffer(color_attachments=[ms[4]])
    f = _fns()
    mirrored = "msaa_pattern_mirrored" in faults
    bg = np.asarray(shading["background"], np.float32)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=gl._clear_depth(raster))
        # uncovered samples of the colour target hold the background: the resolve averages it
        f["ClearBufferfv"](_GL_COLOR, 4, (ctypes.c_float * 4)(*bg, 1.0))
        gl._state(scene)
        if mirrored:   # planted fault: the picture upside down, so is the pattern
            ctx.front_face = {"ccw": "cw", "cw": "ccw"}[ctx.front_face]
        gl._set(prog, "u_ndc_y_down", mirrored)
        gl._set(prog, "u_light", tuple(float(shading[k]) for k in
                                       ("ambient", "diffuse", "specular", "shininess")))
        gl._set(prog, "u_smooth", raster["normals"] == "smooth")
        gl._set(prog, "u_viewport", tuple(float(s) for s in size))
        gl._set(prog, "u_upper_left", False)
        if "msaa_centre_coverage" in faults:   # planted fault: single-sample rasterization
            f["Disable"](_GL_MULTISAMPLE)
        palette = shading["palette"]
        for d in draws:
            if not d["n_faces"]:
                continue
            gl._draw(prog, d, palette)
        f["Enable"](_GL_MULTISAMPLE)
        ctx.finish()
        fetch = programs(gl, _SHADERS)
        out = {}
        clear = np.float32(raster["clear_depth"])
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
        for unit, tex in enumerate((depth, ms[3], ms[4], ms[5])):
            tex.use(location=unit)
        prog_f = fetch["fetch"]
        for name, unit in (("u_depth", 0), ("u_bary", 1), ("u_color", 2), ("u_ids", 3)):
            gl._set(prog_f, name, unit)
        for s in range(samples):
            out_fbo.use()
            out_fbo.clear(0.0, 0.0, 0.0, 0.0)
            gl._set(prog_f, "u_sample", s)
            fullscreen(gl, prog_f)
            win = gl._read(single[0], "<f4", 1, size, top_first=mirrored)[..., 0]
            bary = gl._read(single[1], "<f4", 4, size, top_first=mirrored)[..., :3]
            color = gl._read(single[2], "<f4", 4, size, top_first=mirrored)[..., :3]
            ids = gl._read(single[3], "<i4", 4, size, top_first=mirrored)
            covered = ids[..., 3] == 1
            c3 = covered[..., None]
            out[f"sample{s}_depth"] = np.where(covered, win, clear).astype(np.float32)
            out[f"sample{s}_prim_id"] = np.where(covered, ids[..., 0], -1).astype(np.int32)
            out[f"sample{s}_object_id"] = np.where(covered, ids[..., 1], -1).astype(np.int32)
            out[f"sample{s}_front_facing"] = covered & (ids[..., 2] == 1)
            out[f"sample{s}_barycentric"] = np.where(c3, bary, 0).astype(np.float32)
            out[f"sample{s}_color"] = np.where(c3, color, bg).astype(np.float32)
        if "msaa_srgb_resolve" in faults:   # planted fault: a resolve in sRGB space
            resolved_fbo.use()
            ms[4].use(location=0)
            res = fetch["srgb_resolve"]
            gl._set(res, "u_color", 0)
            gl._set(res, "u_samples", samples)
            fullscreen(gl, res)
        else:
            ctx.copy_framebuffer(resolved_fbo, colour_fbo)
        out["color"] = gl._read(resolved, "<f4", 4, size, top_first=mirrored)[..., :3].astype(
            np.float32)
    finally:
        f["Enable"](_GL_MULTISAMPLE)
        gl._default_conventions()
        gl._parking.use()
        for obj in (fbo, out_fbo, resolved_fbo, colour_fbo, depth, resolved, *ms, *single):
            obj.release()
    return out
