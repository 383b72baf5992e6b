"""2.5D clip surfaces with caps on the GL path (issue 26, item 1; Trapp & Döllner).

Reads only what the scene package carries (``docs/golden-schema.md``, "Clip surfaces: what
the package carries"): the solids' PLYs, each surface's offset map and derived normal and
occlusion maps (and user textures), per solid its volumetric depth sprite, per solid and surface
the exported cap mesh. Draws the G-buffer of ``shaders/clip.*`` in two passes into one set of
targets: the solids (Listing 1's discard), then the caps with ``GL_LESS`` (the parity-test
discard, shading from the maps). ``cap_mask`` is ``object_id ≥ M``.
"""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np

from .common import programs
from .package import CLIP_MAX_SURFACES, PackageError, clipsurface_supports, matrix, read_map

__all__ = ["supports", "load", "draw", "release", "MAX_SURFACES"]

#: Surfaces one scene may have (``clip.frag``'s ``MAX_SURFACES``).
MAX_SURFACES = CLIP_MAX_SURFACES

_GL_TEXTURE_2D = 0x0DE1
_GL_TEXTURE_WRAP_S, _GL_TEXTURE_WRAP_T = 0x2802, 0x2803
_WRAP = {"repeat": 0x2901, "clamp": 0x812F, "clamp_to_edge": 0x812F,
         "mirrored_repeat": 0x8370}


def supports(scene):
    """``None`` if this module can draw the clip-surface scene, else the reason
    (:func:`refraster.gl.package.clipsurface_supports`)."""
    return clipsurface_supports(scene)


def _tex_parameter():
    path = ctypes.util.find_library("EGL") or "libEGL.so.1"
    egl = ctypes.CDLL(path)
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    u, i = ctypes.c_uint, ctypes.c_int
    bind = ctypes.CFUNCTYPE(None, u, u)(egl.eglGetProcAddress(b"glBindTexture"))
    param = ctypes.CFUNCTYPE(None, u, u, i)(egl.eglGetProcAddress(b"glTexParameteri"))
    return bind, param


def _texture(backend, arrays, wrap):
    """One GL_LINEAR float texture from (H, W) arrays (its channels), row 0 at t = 0 (no
    flip), with the wrap mode set by glTexParameteri (moderngl knows no mirrored repeat)."""
    if wrap not in _WRAP:
        raise PackageError(f"wrap {wrap!r} is not one of {sorted(_WRAP)}")
    h, w = arrays[0].shape
    if any(a.shape != (h, w) for a in arrays):
        raise PackageError("the channels of a map differ in shape")
    data = np.ascontiguousarray(np.stack(arrays, -1), np.float32)
    tex = backend.ctx.texture((w, h), len(arrays), data.tobytes(), dtype="f4")
    tex.filter = (backend.mgl.LINEAR, backend.mgl.LINEAR)
    if not hasattr(backend, "_clip_texparam"):
        backend._clip_texparam = _tex_parameter()
    bind, param = backend._clip_texparam
    bind(_GL_TEXTURE_2D, tex.glo)
    param(_GL_TEXTURE_2D, _GL_TEXTURE_WRAP_S, _WRAP[wrap])
    param(_GL_TEXTURE_2D, _GL_TEXTURE_WRAP_T, _WRAP[wrap])
    return tex


#: The program (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {"clip": ("clip.vert", "clip.geom", "clip.frag"),
           # sample rate: the inputs interpolated at the sample in the shader, as the
           # multisampled G-buffers' (shaders/sample_interp.glsl)
           "clip_sample": ("clip.vert", "clip.geom", "clip.frag", ("SAMPLE_INTERP",)),
           # pixel rate at a centroid point: the same, at the fragment's centroid point
           "clip_centroid": ("clip.vert", "clip.geom", "clip.frag",
                             ("SAMPLE_INTERP", "CENTROID_INTERP"))}


def load(backend, package_dir, scene):
    """Upload the solids, caps, maps and sprites of a clip-surface package; a malformed
    parameter is a :class:`PackageError` naming it (nothing in the package is trusted)."""
    try:
        return _load(backend, package_dir, scene)
    except PackageError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise PackageError(f"{package_dir}/scene.json: clipsurface parameters: missing or "
                           f"malformed field ({type(exc).__name__}: {exc})") from None


def _load(backend, package_dir, scene):
    p = scene["parameters"]
    solids = backend._upload(package_dir, scene)
    out = {"solids": solids, "caps": [], "surfaces": [], "sprites": [], "textures": []}
    for k, s in enumerate(p["surfaces"]):
        wrap = s.get("wrap", "repeat")
        entry = {"enabled": bool(s.get("enabled", True)), "s": s}
        om = read_map(package_dir, scene, s["offset_map"])
        if "offset_map_clamped" in backend.faults:   # planted fault: the wrap ignored
            wrap = "clamp_to_edge"
        entry["offset"] = _texture(backend, [om], wrap)
        if "offset_map_nearest" in backend.faults:   # planted fault: no bilinear filtering
            entry["offset"].filter = (backend.mgl.NEAREST, backend.mgl.NEAREST)
        if p.get("caps"):
            maps = [read_map(package_dir, scene, n) for n in s["normal_map"]]
            maps.append(read_map(package_dir, scene, s["occlusion_map"]))
            entry["shading"] = _texture(backend, maps, wrap)
            for key in ("diffuse", "normal", "light"):
                names = (s.get("textures") or {}).get(key)
                if names:
                    entry[key] = _texture(backend, [read_map(package_dir, scene, n)
                                                    for n in names], wrap)
        out["textures"] += [t for key, t in entry.items()
                            if key in ("offset", "shading", "diffuse", "normal", "light")]
        out["surfaces"].append(entry)
    if not p.get("caps"):
        return out
    for m, sp in enumerate(p["sprites"]):
        layers = [read_map(package_dir, scene, n) for n in sp["sprite_depth"]]
        count = read_map(package_dir, scene, sp["sprite_count"])
        h, w = count.shape
        if not layers or any(a.shape != (h, w) for a in layers):
            raise PackageError(f"sprites[{m}]: the maps must all be (h, w) = {(h, w)}")
        depth = np.ascontiguousarray(np.stack([a[::-1] for a in layers]), np.float32)
        arr = backend.ctx.texture_array((w, h, len(layers)), 1, depth.tobytes(), dtype="f4")
        cnt = backend.ctx.texture((w, h), 1,
                                  np.ascontiguousarray(count[::-1], np.int32).tobytes(),
                                  dtype="i4")
        for tex in (arr, cnt):
            tex.filter = (backend.mgl.NEAREST, backend.mgl.NEAREST)
        out["sprites"].append((arr, cnt, matrix(sp["sprite_matrix"],
                                                f"sprites[{m}].sprite_matrix")))
        out["textures"] += [arr, cnt]
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    for i, c in enumerate(p["cap_meshes"]):
        v = np.asarray(read_map(package_dir, scene, c["vertices"]), np.float64)
        f = np.asarray(read_map(package_dir, scene, c["faces"]))
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 \
                or (len(f) and (f.min() < 0 or f.max() >= len(v))) or not np.all(np.isfinite(v)):
            raise PackageError(f"cap_meshes[{i}]: vertices (V, 3) finite and faces (F, 3) in "
                               "range")
        if not (0 <= c["solid"] < len(out["sprites"]) and 0 <= c["surface"] < len(out["surfaces"])):
            raise PackageError(f"cap_meshes[{i}]: solid or surface out of range")
        draw = {"object_id": int(c["object_id"]), "n_faces": len(f), "solid": c["solid"],
                "surface": c["surface"], "mvp": (proj @ view).astype(np.float32),
                "mv": view.astype(np.float32), "model": np.eye(4),
                "nmat": np.linalg.inv(view[:3, :3]).T.astype(np.float32), "vaos": {},
                "release": []}
        if len(f):
            data = np.concatenate([v.astype(np.float32), np.zeros((len(v), 3), np.float32)], 1)
            draw["vbo"] = backend.ctx.buffer(np.ascontiguousarray(data).tobytes())
            draw["ibo"] = backend.ctx.buffer(np.ascontiguousarray(f, np.int32).tobytes())
            draw["release"] = [draw["vbo"], draw["ibo"]]
        out["caps"].append(draw)
    return out


def release(loaded):
    for tex in loaded.get("textures", ()):
        tex.release()
    for d in loaded.get("solids", []) + loaded.get("caps", []):
        for obj in d["release"]:
            obj.release()
    loaded.clear()


def draw(backend, scene, loaded):
    """The clip-surface G-buffer → ``{buffer: array}`` as the golden stores it (a scene of
    ``raster.samples > 1``: :func:`draw_samples`)."""
    if int(scene["raster"].get("samples", 1)) > 1:
        return draw_samples(backend, scene, loaded)
    ctx = backend.ctx
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    raster, shading = scene["raster"], scene["shading"]
    targets = [ctx.texture(size, 1, dtype="f4"), ctx.texture(size, 1, dtype="f4"),
               ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="f4"),
               ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="i4")]
    depth = backend._depth_attachment(size)
    fbo = ctx.framebuffer(color_attachments=targets, depth_attachment=depth)
    try:
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=float(raster["clear_depth"]))
        _passes(backend, scene, loaded)
        ctx.finish()
        win, eye = (backend._read(t, "<f4", 1, size)[..., 0] for t in targets[:2])
        normal, bary, color = (backend._read(t, "<f4", 4, size)[..., :3] for t in targets[2:5])
        ids = backend._read(targets[5], "<i4", 4, size)
    finally:
        backend._parking.use()
        for obj in (fbo, depth, *targets):
            obj.release()
    covered = ids[..., 3] == 1
    c3 = covered[..., None]
    bg = np.asarray(shading["background"], np.float32)
    object_id = np.where(covered, ids[..., 1], -1).astype(np.int32)
    return {
        "depth": np.where(covered, win, np.float32(raster["clear_depth"])).astype(np.float32),
        "eye_depth": np.where(covered, eye, np.float32(np.inf)).astype(np.float32),
        "normal": np.where(c3, normal, 0).astype(np.float32),
        "prim_id": np.where(covered, ids[..., 0], -1).astype(np.int32),
        "object_id": object_id,
        "front_facing": covered & (ids[..., 2] == 1),
        "barycentric": np.where(c3, bary, 0).astype(np.float32),
        "color": np.where(c3, color, bg).astype(np.float32),
        "cap_mask": object_id >= len(loaded["solids"]),
    }


def _passes(backend, scene, loaded, variant="clip"):
    """The two passes (solids, then caps) into the bound targets with the program ``variant``
    of :data:`SHADERS`: ``"clip_sample"`` interpolates its inputs at the sample itself
    (``shaders/sample_interp.glsl``: llvmpipe's own divide at the sample is the pixel
    centre's), ``"clip_centroid"`` the same way at the fragment's centroid point."""
    mgl = backend.mgl
    prog = programs(backend, SHADERS)[variant]
    p = scene["parameters"]
    raster, shading = scene["raster"], scene["shading"]
    view = matrix(scene["camera"]["view"], "camera.view")
    set_, write = backend._set, backend._write
    surfaces = loaded["surfaces"]
    backend._state(scene)
    set_(prog, "u_light", tuple(float(shading[k]) for k in
                                ("ambient", "diffuse", "specular", "shininess")))
    set_(prog, "u_smooth", raster["normals"] == "smooth")
    set_(prog, "u_n_surfaces", len(surfaces))
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    set_(prog, "u_viewport_px", tuple(float(x) for x in size))
    if variant == "clip_centroid":      # the declared pattern (1/16 pixel, y down) in GL's y up
        pos = scene["parameters"]["sample_pattern"]["positions"]
        set_(prog, "u_samples", len(pos))
        set_(prog, "u_sample_xy", [(x / 16.0, 1.0 - y / 16.0) for x, y in pos]
             + [(0.5, 0.5)] * (16 - len(pos)))
    O, Uh, Vh, N, lens, S, enabled = [], [], [], [], [], [], []
    for e in surfaces:
        s = e["s"]
        o, u, v = (np.asarray(s[key], np.float64) for key in ("origin", "u", "v"))
        lu, lv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        uh, vh = u / lu, v / lv
        O.append(tuple(o))
        Uh.append(tuple(uh))
        Vh.append(tuple(vh))
        N.append(tuple(np.cross(uh, vh)))
        lens.append((lu, lv))
        S.append(tuple(float(x) for x in s["scale"]))
        enabled.append(e["enabled"])
    pad = MAX_SURFACES - len(surfaces)
    for name, vals, zero in (("u_O", O, (0.0,) * 3), ("u_Uh", Uh, (0.0,) * 3),
                             ("u_Vh", Vh, (0.0,) * 3), ("u_N", N, (0.0,) * 3),
                             ("u_len", lens, (1.0, 1.0)), ("u_S", S, (0.0,) * 3)):
        if name in prog:
            prog[name].value = [tuple(float(x) for x in t) for t in vals] + [zero] * pad
    if "u_enabled" in prog:
        prog["u_enabled"].value = enabled + [False] * pad
    for k, e in enumerate(surfaces):
        e["offset"].use(location=k)
        set_(prog, f"u_offset{k}", k)
    for k in range(len(surfaces), MAX_SURFACES):
        set_(prog, f"u_offset{k}", 0)
    # units: 0-1 offset maps, 2 sprite layers, 3 counts, 4 shading, 5-7 user maps
    for name, unit in (("u_sprite_depth", 2), ("u_sprite_count", 3), ("u_cap_shading", 4),
                       ("u_cap_diffuse", 5), ("u_cap_normal", 6), ("u_cap_lightmap", 7)):
        set_(prog, name, unit)
    palette = shading["palette"]
    set_(prog, "u_cap", False)
    for d in loaded["solids"]:
        if not d["n_faces"]:
            continue
        write(prog, "u_mvp", d["mvp"])
        write(prog, "u_mv", d["mv"])
        write(prog, "u_model", d["model"].astype(np.float32))
        write(prog, "u_nmat", d["nmat"])
        set_(prog, "u_object", int(d["object_id"]))
        set_(prog, "u_base", tuple(float(c) for c in palette[d["object_id"] % len(palette)]))
        backend._vao(d, prog).render(mgl.TRIANGLES)
    if p.get("caps"):
        set_(prog, "u_cap", True)
        set_(prog, "u_smooth", False)
        write(prog, "u_view_nmat", np.linalg.inv(view[:3, :3]).T.astype(np.float32))
        set_(prog, "u_cap_color", tuple(float(c) for c in p["cap_color"]))
        for d in loaded["caps"]:
            if not d["n_faces"]:
                continue
            arr, cnt, tmat = loaded["sprites"][d["solid"]]
            arr.use(location=2)
            cnt.use(location=3)
            e = surfaces[d["surface"]]
            e["shading"].use(location=4)
            for key, unit, flag in (("diffuse", 5, "u_has_diffuse"),
                                    ("normal", 6, "u_has_normal"),
                                    ("light", 7, "u_has_lightmap")):
                if key in e:
                    e[key].use(location=unit)
                set_(prog, flag, key in e)
            write(prog, "u_tmat", tmat.astype(np.float32))
            set_(prog, "u_cap_k", int(d["surface"]))
            write(prog, "u_mvp", d["mvp"])
            write(prog, "u_mv", d["mv"])
            write(prog, "u_model", np.eye(4, dtype=np.float32))
            write(prog, "u_nmat", d["nmat"])
            set_(prog, "u_object", int(d["object_id"]))
            backend._vao(d, prog).render(mgl.TRIANGLES)


_GL_SAMPLE_SHADING = 0x8C36


def draw_samples(backend, scene, loaded):
    """The clip-surface G-buffer at ``raster.samples`` (issue 44) → ``sample<s>_<channel>``
    of :data:`refraster.golden.msaa_clip_scenes.CLIP_SAMPLE_CHANNELS`: the same two passes into
    multisample targets (a ``DEPTH_COMPONENT32F`` multisample depth, the depth test per
    sample), at sample rate (``raster.interpolation == "sample"``) with
    ``glEnable(GL_SAMPLE_SHADING)`` and ``glMinSampleShading(1.0)`` — one invocation per
    sample, its inputs (the world position of Listing 1's test and the parity test) the
    sample's: interpolated in the shader from the corners (``shaders/sample_interp.glsl``),
    since llvmpipe's own divide of a smooth input at the sample is the pixel centre's ``1/w``
    — else at pixel rate (one invocation per pixel, its discard removing every covered
    sample), its inputs at the centre, or (``"centroid"``) interpolated from the corners at the
    centroid point llvmpipe picks (the centre where all samples are covered, else the first
    covered sample: inside both the pixel and the primitive); then each sample read with
    ``texelFetch`` (:mod:`refraster.gl.msaa`'s fetch pass). Only where the context's own
    positions are the scene's declared ones."""
    import ctypes

    from .common import Unsupported, fullscreen, gl_function
    from .msaa import _SHADERS as FETCH, _depth_texture, _text, sample_pattern
    raster, shading = scene["raster"], scene["shading"]
    samples = int(raster["samples"])
    declared = scene["parameters"]["sample_pattern"]["positions"]
    own = sample_pattern(backend, samples)
    if own is None or own["positions"] != declared:
        raise Unsupported(f"clipsurface: this OpenGL's {samples}x sample positions are "
                          f"{_text(own['positions']) if own else 'none'}, the scene declares "
                          f"{_text(declared)} (1/16 pixel, y down)")
    ctx, mgl = backend.ctx, backend.mgl
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    ms = [ctx.texture(size, c, samples=samples, dtype=d)
          for c, d in ((1, "f4"), (1, "f4"), (4, "f4"), (4, "f4"), (4, "f4"), (4, "i4"))]
    depth = _depth_texture(backend, size, samples)
    fbo = ctx.framebuffer(color_attachments=ms, depth_attachment=depth)
    single = [ctx.texture(size, 1, dtype="f4"), ctx.texture(size, 4, dtype="f4"),
              ctx.texture(size, 4, dtype="f4"), ctx.texture(size, 4, dtype="i4")]
    out_fbo = ctx.framebuffer(color_attachments=single)
    enable = gl_function("glEnable", None, ctypes.c_uint)
    disable = gl_function("glDisable", None, ctypes.c_uint)
    min_shading = gl_function("glMinSampleShading", None, ctypes.c_float)
    interp = raster.get("interpolation", "center")
    per_sample = interp == "sample"
    bg = np.asarray(shading["background"], np.float32)
    clear = np.float32(raster["clear_depth"])
    out = {}
    try:
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=float(clear))
        if per_sample:
            enable(_GL_SAMPLE_SHADING)
            min_shading(1.0)
        _passes(backend, scene, loaded, {"sample": "clip_sample",
                                         "centroid": "clip_centroid"}.get(interp, "clip"))
        disable(_GL_SAMPLE_SHADING)
        ctx.finish()
        fetch = programs(backend, FETCH)["fetch"]
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)
        for unit, tex in enumerate((depth, ms[3], ms[4], ms[5])):
            tex.use(location=unit)
        for name, unit in (("u_depth", 0), ("u_bary", 1), ("u_color", 2), ("u_ids", 3)):
            backend._set(fetch, name, unit)
        m = len(loaded["solids"])
        for s in range(samples):
            out_fbo.use()
            out_fbo.clear(0.0, 0.0, 0.0, 0.0)
            backend._set(fetch, "u_sample", s)
            fullscreen(backend, fetch)
            win = backend._read(single[0], "<f4", 1, size)[..., 0]
            bary = backend._read(single[1], "<f4", 4, size)[..., :3]
            color = backend._read(single[2], "<f4", 4, size)[..., :3]
            ids = backend._read(single[3], "<i4", 4, size)
            covered = ids[..., 3] == 1
            c3 = covered[..., None]
            obj = np.where(covered, ids[..., 1], -1).astype(np.int32)
            out[f"sample{s}_depth"] = np.where(covered, win, clear).astype(np.float32)
            out[f"sample{s}_prim_id"] = np.where(covered, ids[..., 0], -1).astype(np.int32)
            out[f"sample{s}_object_id"] = obj
            out[f"sample{s}_front_facing"] = covered & (ids[..., 2] == 1)
            out[f"sample{s}_barycentric"] = np.where(c3, bary, 0).astype(np.float32)
            out[f"sample{s}_color"] = np.where(c3, color, bg).astype(np.float32)
            out[f"sample{s}_cap_mask"] = obj >= m
    finally:
        disable(_GL_SAMPLE_SHADING)
        backend._default_conventions()
        backend._parking.use()
        for obj in (fbo, out_fbo, depth, *ms, *single):
            obj.release()
    return out


#: The planted faults of this module (test-only ``#define``s of ``shaders/clip.frag``).
FAULT_NAMES = ("clip_sign_flipped", "offset_t_flipped", "cap_no_parity")
