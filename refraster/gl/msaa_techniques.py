"""Technique scenes at ``samples > 1`` on refraster.gl (issue 44): edge maps and cutaways on
multisampled G-buffers, drawn as a GPU port draws them.

A 4× technique golden declares its sample pattern and sample-rate interpolation. This backend
draws only where the context's own positions (:func:`refraster.gl.msaa.sample_pattern`,
``glGetMultisamplefv``) are the declared ones, and then:

* the geometry passes (the G-buffer, the edge map's ``T_G``, the cutaway's rear hulls and its
  clipped G-buffer) rasterize into multisample textures of ``raster.samples`` samples (a
  ``DEPTH_COMPONENT32F`` multisample depth, the depth test per sample) at sample rate
  (``glEnable(GL_SAMPLE_SHADING)``, ``glMinSampleShading(1.0)``: one invocation per sample,
  its inputs interpolated at the sample);
* the image passes read each sample with ``texelFetch(sampler2DMS, p, i)``. Edge maps, per
  sample: the operators at sample rate into a multisample edge map, each invocation reading
  its neighbours at its own sample (``gl_SampleID``), resolved by a float box-filter pass
  (``shaders/msaa_resolve.frag``); resolved (``sample_zero``): the operators once per pixel on
  sample 0; resolved (``average``): on ``T_G`` box-filtered in the pass, the ids sample 0's. Cutaways, per sample: each sample's rear hulls seeded (``u_sample``) and flooded on
  their own, and sample ``s`` of the clipped G-buffer carved by its own ``D_s``
  (``glSampleMaski(0, 1 << s)``); resolved (``sample_zero``, ``min``, ``max``): sample 0's
  rear hulls (their depth resolved by ``min``/``max`` over the samples in the seed pass) flooded
  once at the pixel centres, every sample carved by that ``D``. The cut normals are unprojected
  at the sample's position (the projection moved by the sample's offset,
  :func:`window_shift`).
* the samples' G-buffers are read back with a fetch pass (``shaders/msaa_gbuffer_fetch.frag``).

Ghost lines are drawn per sample as single-sample lines with the projection moved by the
sample's offset: the golden's ghost at a sample is the single-sample line rasterization of that
sample's lattice, while GL rasterizes lines in a multisample framebuffer as rectangles (a
different rule, GL 4.5 §14.5.4).

Planted faults: ``msaa_edges_resolved_for_per_sample`` (the edge operators read sample 0 at
every sample: the resolved G-buffer's edge map where per-sample is declared) and
``msaa_gbuffer_pixel_rate`` (the geometry passes without sample shading: one invocation per
pixel, its inputs at the pixel centre, where sample-rate interpolation is declared).
"""

from __future__ import annotations

import ctypes

import numpy as np

from . import cutaway as _cut
from .common import Unsupported, fullscreen, gl_function, programs
from .edges import FORMATS
from .edges import near_far as edges_near_far
from .edges import operator_uniforms
from .edges import options as edges_options
from .msaa import _depth_texture, _text, sample_pattern
from .package import CONVENTION_DEFAULTS, conventions, matrix

__all__ = ["supports", "render_sampled", "window_shift", "SAMPLED_TECHNIQUES"]

SAMPLED_TECHNIQUES = ("edges", "cutaway")
#: The resolve modes drawn in the ``"resolved"`` mode: edges, the G-buffer from sample 0 or
#: box-filtered in the operators' pass; cutaways, the rear hulls' depth from sample 0 or
#: resolved by min or max in the seed pass (the seeds sample 0's).
_RESOLVES = {"edges": ("sample_zero", "average"), "cutaway": ("sample_zero", "min", "max")}
_DEPTH_RESOLVE = {"sample_zero": 0, "min": 1, "max": 2}

_GL_SAMPLE_SHADING = 0x8C36
_GL_SAMPLE_MASK = 0x8E51

#: The programs of this module (vertex, geometry, fragment shader, variant defines).
SHADERS = {
    "fetch": ("fullscreen.vert", None, "msaa_gbuffer_fetch.frag"),
    "resolve": ("fullscreen.vert", None, "msaa_resolve.frag"),
    "edge": ("fullscreen.vert", None, "edge_map.frag", ("MSAA",)),
    "seed": ("fullscreen.vert", None, "cutaway_seed.frag", ("MSAA",)),
    # the geometry passes with the interpolation at the sample done in the shader
    "gbuffer": ("gbuffer.vert", "gbuffer.geom", "gbuffer.frag", ("SAMPLE_INTERP",)),
    "tg": ("gbuffer.vert", "gbuffer.geom", "edge_gbuffer.frag", ("SAMPLE_INTERP",)),
    "carve": ("gbuffer.vert", "gbuffer.geom", "cutaway_gbuffer.frag", ("SAMPLE_INTERP",)),
}

_FNS = {}


def _fns():
    if not _FNS:
        u = ctypes.c_uint
        _FNS.update(Enable=gl_function("glEnable", None, u),
                    Disable=gl_function("glDisable", None, u),
                    MinSampleShading=gl_function("glMinSampleShading", None, ctypes.c_float),
                    SampleMaski=gl_function("glSampleMaski", None, u, u))
    return _FNS


def window_shift(position, width, height):
    """The clip-space map that moves the window by minus a sample's offset (``position`` in
    1/16 pixel, y down): its pixel centres are the sample's positions (the package's
    definition of a sample's image, ``docs/multisample.md``)."""
    t = np.eye(4)
    t[0, 3] = -2.0 * ((float(position[0]) - 8.0) / 16.0) / width
    t[1, 3] = -2.0 * ((8.0 - float(position[1])) / 16.0) / height
    return t


def supports(scene):
    """``None`` if the multisampled technique scene can be drawn, else the reason."""
    raster = scene.get("raster", {})
    technique = scene.get("technique")
    if technique not in SAMPLED_TECHNIQUES:
        return (f"technique {technique!r} at samples > 1 is not implemented by the gl backend "
                f"(it draws {', '.join(SAMPLED_TECHNIQUES)} on multisampled G-buffers)")
    conv = conventions(raster)
    if conv != CONVENTION_DEFAULTS:
        # the sample interpolation (shaders/sample_interp.glsl) and the read-back assume GL's
        # lower-left window origin and depth range: another convention would be drawn wrong
        changed = sorted(k for k in conv if conv[k] != CONVENTION_DEFAULTS[k])
        return (f"{technique} at samples > 1 renders OpenGL's conventions only; the scene sets "
                f"raster {', '.join(changed)}")
    if raster.get("interpolation", "center") != "sample":
        return (f"{technique} at samples > 1: only sample-rate interpolation (GL_SAMPLE_SHADING) "
                f"is drawn, the scene declares {raster.get('interpolation', 'center')!r}")
    params = scene.get("parameters") or {}
    sampling = params.get("sampling") or {}
    if sampling.get("mode") == "resolved" \
            and sampling.get("resolve") not in _RESOLVES[technique]:
        return (f"{technique} at samples > 1: resolve {sampling.get('resolve')!r} is not drawn "
                f"({', '.join(_RESOLVES[technique])})")
    if technique == "edges" and (int(params.get("width", 1)) > 1 or "npr" in params):
        return "edges at samples > 1: width > 1 and the NPR pass are not drawn"
    return None


def _sample_rate(gl, on):
    """Sample shading on or off (on: not with the planted ``msaa_gbuffer_pixel_rate``)."""
    f = _fns()
    if on and "msaa_gbuffer_pixel_rate" not in gl.faults:
        f["Enable"](_GL_SAMPLE_SHADING)
        f["MinSampleShading"](1.0)
    else:
        f["Disable"](_GL_SAMPLE_SHADING)


def render_sampled(gl, loaded):
    """The golden's buffers of a multisampled edges or cutaway scene (module docstring):
    ``sample<s>_<buffer>`` for each sample, and the resolved ``edge_map`` of an edge scene."""
    scene = loaded["scene"]
    samples = int(scene["raster"]["samples"])
    declared = scene["parameters"]["sample_pattern"]["positions"]
    own = sample_pattern(gl, samples)
    if own is None or own["positions"] != declared:
        raise Unsupported(f"{scene['technique']} at {samples}x: this OpenGL's sample positions "
                          f"are {_text(own['positions']) if own else 'none'}, the scene "
                          f"declares {_text(declared)} (1/16 pixel, y down)")
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    pool = _cut.Pool(gl, size)
    try:
        gl.ctx.viewport = (0, 0, *size)
        draw = _edges if scene["technique"] == "edges" else _cutaway
        return draw(gl, loaded, pool, declared)
    finally:
        _sample_rate(gl, False)
        _fns()["Disable"](_GL_SAMPLE_MASK)
        gl._default_conventions()
        pool.release()


def _ms_gbuffer(gl, pool, scene, samples, cut=False):
    """The G-buffer's multisample targets (gbuffer.frag's six, and the cut flag) and depth,
    cleared → ``(framebuffer, targets, depth)``."""
    spec = [(1, "f4"), (1, "f4"), (4, "f4"), (4, "f4"), (4, "f4"), (4, "i4")] + \
        ([(1, "i4")] if cut else [])
    targets = [pool.tex(c, d, samples) for c, d in spec]
    depth = pool.keep(_depth_texture(gl, pool.size, samples))
    fbo = pool.fbo(targets, depth)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=float(scene["raster"]["clear_depth"]))
    return fbo, targets, depth


def _fetch(gl, pool, scene, targets, depth, samples):
    """Each sample of the multisampled G-buffer read back → a list of ``({buffer: array},
    covered, cut flag)``."""
    prog = programs(gl, SHADERS)["fetch"]
    single = [pool.tex(c, d) for c, d in
              ((1, "f4"), (1, "f4"), (4, "f4"), (4, "f4"), (4, "f4"), (4, "i4"), (1, "i4"))]
    fbo = pool.fbo(single)
    gl.ctx.disable(gl.mgl.DEPTH_TEST | gl.mgl.CULL_FACE)
    sources = [depth, *targets[1:6], targets[6] if len(targets) > 6 else targets[5]]
    names = ("u_depth", "u_eye", "u_normal", "u_bary", "u_color", "u_ids", "u_cut")
    for unit, (name, tex) in enumerate(zip(names, sources)):
        tex.use(location=unit)
        gl._set(prog, name, unit)
    out = []
    for s in range(samples):
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        gl._set(prog, "u_sample", s)
        fullscreen(gl, prog)
        buffers, covered = gl._read_gbuffer(scene, single, pool.size)
        cut = gl._read(single[6], "<i4", 1, pool.size)[..., 0]
        out.append((buffers, covered, cut))
    return out


def _gbuffer_uniforms(gl, prog, scene, size):
    shading = scene["shading"]
    gl._set(prog, "u_ndc_y_down", False)
    gl._set(prog, "u_light", tuple(float(shading[k]) for k in
                                   ("ambient", "diffuse", "specular", "shininess")))
    gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
    gl._set(prog, "u_viewport_px", tuple(float(s) for s in size))
    gl._set(prog, "u_upper_left", False)


def _edges(gl, loaded, pool, positions):
    scene, draws = loaded["scene"], loaded["draws"]
    samples = len(positions)
    ctx, mgl = gl.ctx, gl.mgl
    params = scene["parameters"]
    opt = edges_options(params)
    near, far = edges_near_far(scene, loaded["package_dir"])
    per_sample = params["sampling"]["mode"] == "per_sample"
    mine = programs(gl, SHADERS)
    # the G-buffer at sample rate, each sample read back
    fbo, targets, depth = _ms_gbuffer(gl, pool, scene, samples)
    gl._state(scene)
    prog = mine["gbuffer"]
    _gbuffer_uniforms(gl, prog, scene, pool.size)
    _sample_rate(gl, True)
    for d in draws:
        if d["n_faces"]:
            gl._draw(prog, d, scene["shading"]["palette"])
    _sample_rate(gl, False)
    out = {}
    for s, (buffers, _, _) in enumerate(_fetch(gl, pool, scene, targets, depth, samples)):
        for k, v in buffers.items():
            if k != "color":
                out[f"sample{s}_{k}"] = v
    # T_G and the ids at sample rate
    fmt = FORMATS[opt["output_format"]]
    tg, ids = pool.tex(4, FORMATS[opt["gbuffer_format"]], samples), pool.tex(1, "i4", samples)
    fbo = pool.fbo([tg, ids], pool.keep(_depth_texture(gl, pool.size, samples)))
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=float(scene["raster"]["clear_depth"]))
    gl._state(scene)
    prog = mine["tg"]
    gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
    gl._set(prog, "u_viewport_px", tuple(float(s) for s in pool.size))
    gl._set(prog, "u_near_far", (near, far))
    _sample_rate(gl, True)
    for d in draws:
        if d["n_faces"]:
            gl._draw(prog, d)
    _sample_rate(gl, False)
    # the operators: per sample at sample rate into a multisample map, or once on sample 0
    ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
    prog = mine["edge"]
    tg.use(location=0)
    ids.use(location=1)
    operator_uniforms(gl, prog, opt)
    gl._set(prog, "u_sample_zero", not per_sample)
    average = not per_sample and params["sampling"].get("resolve") == "average"
    gl._set(prog, "u_average", samples if average else 0)
    single = pool.tex(4, fmt)
    if not per_sample:
        pool.fbo([single]).use()
        fullscreen(gl, prog)
        out["edge_map"] = _read_map(gl, single, fmt, pool.size)
        return out
    edge = pool.tex(4, fmt, samples)
    pool.fbo([edge]).use()
    _fns()["Enable"](_GL_SAMPLE_SHADING)      # the pass itself reads gl_SampleID
    _fns()["MinSampleShading"](1.0)
    fullscreen(gl, prog)
    _sample_rate(gl, False)
    res = mine["resolve"]
    edge.use(location=0)
    gl._set(res, "u_src", 0)
    gl._set(res, "u_samples", samples)
    pool.fbo([single]).use()
    for s in range(samples):
        gl._set(res, "u_sample", s)
        fullscreen(gl, res)
        out[f"sample{s}_edge_map"] = _read_map(gl, single, fmt, pool.size)
    resolved = pool.tex(4, "f4")
    pool.fbo([resolved]).use()
    gl._set(res, "u_sample", -1)
    fullscreen(gl, res)
    out["edge_map"] = _read_map(gl, resolved, "f4", pool.size)
    return out


def _read_map(gl, tex, fmt, size):
    if fmt == "f1":
        return gl._read(tex, "u1", 4, size).astype(np.float32) / np.float32(255.0)
    return np.ascontiguousarray(gl._read(tex, "<f4", 4, size), np.float32)


def _cutaway(gl, loaded, pool, positions):
    scene, draws = loaded["scene"], loaded["draws"]
    samples = len(positions)
    opt, reason = _cut.options(scene)
    if reason is not None:
        raise Unsupported(reason)
    ctx = gl.ctx
    w, h = pool.size
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    projs = [window_shift(p, w, h) @ proj for p in positions]
    per_sample = scene["parameters"]["sampling"]["mode"] == "per_sample"
    progs = programs(gl, _cut.SHADERS)
    # 1. the rear hulls at sample rate (GREATER against a multisample depth cleared to 0)
    rear_depth = pool.keep(_depth_texture(gl, pool.size, samples))
    _sample_rate(gl, True)
    _, hull = _cut.rear_hulls(gl, progs, pool, draws, opt, rear_depth, samples)
    _sample_rate(gl, False)
    # 2.–4. each sample's surface (or sample 0's at the pixel centres, shared)
    seed = programs(gl, SHADERS)["seed"]
    surfaces = []
    for s in range(samples if per_sample else 1):
        rear_depth.use(0)
        hull.use(1)
        gl._set(seed, "u_rear", 0)
        gl._set(seed, "u_hull", 1)
        gl._set(seed, "u_sample", s)
        gl._set(seed, "u_samples", samples)
        gl._set(seed, "u_depth_resolve", 0 if per_sample else _DEPTH_RESOLVE[
            scene["parameters"]["sampling"].get("resolve", "sample_zero")])
        p = projs[s] if per_sample else proj
        _cut.seed_uniforms(gl, seed, opt, p, view, np.linalg.inv(p))
        surfaces.append(_cut.flood_surface(gl, progs, pool, seed, opt, p))
    surfaces = surfaces * (1 if per_sample else samples)
    normals = [_cut.cut_normals(gl, progs, pool, ddil, p)
               for (_, ddil), p in zip(surfaces, projs)]
    # 5. the clipped G-buffer at sample rate, sample s carved by its own surface
    f, targets, depth = _ms_gbuffer(gl, pool, scene, samples, cut=True)
    gl._state(scene)
    prog = programs(gl, SHADERS)["carve"]
    _cut.carve_uniforms(gl, prog, scene, opt)
    gl._set(prog, "u_viewport_px", tuple(float(s) for s in pool.size))
    _sample_rate(gl, True)
    fns = _fns()
    fns["Enable"](_GL_SAMPLE_MASK)
    for s in range(samples):
        fns["SampleMaski"](0, 1 << s)
        for unit, t in enumerate((*surfaces[s], normals[s])):
            t.use(unit)
        _cut.carve_draws(gl, prog, draws, opt, scene["shading"]["palette"])
    fns["Disable"](_GL_SAMPLE_MASK)
    _sample_rate(gl, False)
    ctx.finish()
    out = {}
    for s, (buffers, covered, cut) in enumerate(_fetch(gl, pool, scene, targets, depth,
                                                       samples)):
        dtex = surfaces[s][0]
        d_ndc = gl._read(dtex, "<f4", 1, pool.size)[..., 0]
        # 6. ghost lines: single-sample lines on the sample's lattice (module docstring)
        ghost = _cut.ghost_pass(gl, progs, pool, scene, loaded["package_dir"], opt, draws,
                                buffers, covered, dtex, projs[s] @ view)
        buffers.update(cutaway_depth=(np.float32(0.5) * d_ndc + np.float32(0.5)).astype(
            np.float32), cut_mask=covered & (cut == 1), ghost=np.ascontiguousarray(
                ghost, np.float32))
        for k, v in buffers.items():
            out[f"sample{s}_{k}"] = v
    return out
