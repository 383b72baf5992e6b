"""2.5D clip surfaces with caps in WGSL (Trapp & Döllner) for refraster.wgpu, from what the
scene package carries (``docs/golden-schema.md``, "Clip surfaces: what the package carries"):
the solids' PLYs, each surface's offset map and derived normal and occlusion maps (and user
textures), per solid its volumetric depth sprite, per solid and surface the exported cap mesh.

The G-buffer of ``shaders/clip.wgsl`` in the driver's three passes of at most 32 bytes per
sample, each drawing the solids (the clip test's discard), then the caps (the parity-test
discard, shading from the maps) from a cleared depth buffer. Maps are rgba32float textures
filtered bilinearly in the shader under the surface's ``wrap`` (no ``float32-filterable``);
the sprites are an r32float 2D array and an r32sint count texture read with ``textureLoad``.
``cap_mask`` is ``object_id ≥ M`` (M solids).
"""

from __future__ import annotations

import numpy as np

from ..gl.package import (CLIP_MAX_SURFACES, PackageError, clipsurface_supports, matrix,
                          read_map, read_ply)
from .common import float_texture, scene_pipeline, uniform

__all__ = ["supports", "load", "draw", "release", "MAX_SURFACES", "ADDRESS_MODES"]

SHADER = "clip.wgsl"
#: Surfaces one scene may have (``Clip.surfaces`` of clip.wgsl).
MAX_SURFACES = CLIP_MAX_SURFACES
#: The package's ``wrap`` → clip.wgsl's address mode (WebGPU's names: repeat, clamp-to-edge,
#: mirror-repeat).
ADDRESS_MODES = {"repeat": 0, "clamp": 1, "clamp_to_edge": 1, "mirrored_repeat": 2}
#: The G-buffer's passes (as the driver's GBUFFER_PASSES): entry point → target formats.
PASSES = {"fs_clip_ids": ("r32float", "r32float", "rgba32sint"),
          "fs_clip_surface": ("rgba32float", "rgba32float"),
          "fs_clip_shade": ("rgba32float",)}
#: The planted faults of this module → the override constant of clip.wgsl they set.
FAULT_CONSTANTS = {"offset_wrong_address_mode": "WRONG_ADDRESS_MODE",
                   "parity_far_end": "PARITY_FAR_END"}
_UNIFORM_BYTES = 304            # gbuffer.wgsl's Draw (the driver's _UNIFORM_BYTES)


def supports(scene):
    """``None`` if this module can draw the clip-surface scene, else the reason (the shared
    reading of :func:`refraster.gl.package.clipsurface_supports`, and a float32 depth)."""
    fmt = scene.get("raster", {}).get("depth_format", "float32")
    if fmt != "float32":
        return (f"clipsurface with raster.depth_format {fmt!r}: the passes write the float32 "
                "window depth; only 'float32'")
    return clipsurface_supports(scene)


def _layouts(backend):
    if "_clip_layouts" in backend.__dict__:
        return backend._clip_layouts
    dev, s = backend.device, backend.wgpu.ShaderStage
    unf = {"sample_type": "unfilterable-float", "view_dimension": "2d"}
    entries = [{"binding": 20, "visibility": s.FRAGMENT, "buffer": {"type": "uniform"}}]
    entries += [{"binding": b, "visibility": s.FRAGMENT, "texture": unf} for b in (21, 22)]
    entries += [{"binding": 23, "visibility": s.FRAGMENT,
                 "texture": {"sample_type": "unfilterable-float",
                             "view_dimension": "2d-array"}},
                {"binding": 24, "visibility": s.FRAGMENT,
                 "texture": {"sample_type": "sint", "view_dimension": "2d"}}]
    entries += [{"binding": b, "visibility": s.FRAGMENT, "texture": unf}
                for b in (25, 26, 27, 28)]
    group = dev.create_bind_group_layout(entries=entries)
    backend._clip_layouts = {
        "group": group,
        "pipeline": dev.create_pipeline_layout(bind_group_layouts=[backend._group0, group])}
    return backend._clip_layouts


def _draw_uniform(backend, view, proj, model, tmat, base, object_id, smooth, shading, vp):
    """gbuffer.wgsl's ``Draw`` block (the driver's layout) for one draw → uniform buffer."""
    mv = view @ model
    try:
        nmat = np.linalg.inv(mv[:3, :3]).T
    except np.linalg.LinAlgError:
        raise PackageError("a draw's view·model is singular") from None
    n4 = np.eye(4)
    n4[:3, :3] = nmat
    block = np.zeros(_UNIFORM_BYTES // 4, np.float32)
    for k, m in enumerate((proj @ mv, mv, n4, tmat)):
        block[16 * k:16 * (k + 1)] = np.asarray(m, np.float32).T.reshape(-1)
    block[64:67] = base
    block[68:72] = [shading[k] for k in ("ambient", "diffuse", "specular", "shininess")]
    block[72:74] = [vp["width"], vp["height"]]
    ints = block.view(np.int32)
    ints[74] = object_id
    ints[75] = 1 if smooth else 0
    return uniform(backend, block)


def _mesh_draw(backend, vertices, faces, normals, ubo, object_id):
    wgpu, dev = backend.wgpu, backend.device
    data = backend._deindex(vertices, faces, normals)
    vbo = (dev.create_buffer_with_data(data=data.tobytes(), usage=wgpu.BufferUsage.VERTEX)
           if len(data) else None)
    group = dev.create_bind_group(layout=backend._group0, entries=[
        {"binding": 0, "resource": {"buffer": ubo, "offset": 0, "size": _UNIFORM_BYTES}}])
    return {"object_id": object_id, "n_faces": len(faces), "vbo": vbo, "ubo": ubo,
            "group": group}


def load(backend, package_dir, scene):
    """Upload the solids, caps, maps and sprites of a clip-surface package; a malformed
    parameter is a :class:`PackageError` naming it."""
    try:
        return _load(backend, package_dir, scene)
    except PackageError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise PackageError(f"{package_dir}/scene.json: clipsurface parameters: missing or "
                           f"malformed field ({type(exc).__name__}: {exc})") from None


def _load(backend, package_dir, scene):
    p = scene["parameters"]
    dev, usage = backend.device, backend.wgpu.TextureUsage
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    shading, palette, vp = scene["shading"], scene["shading"]["palette"], scene["viewport"]
    smooth = scene["raster"]["normals"] == "smooth"
    out = {"solids": [], "caps": [], "surfaces": [], "sprites": [], "textures": [],
           "buffers": []}
    for i, d in enumerate(scene["draws"]):
        v, f, n = read_ply(package_dir / d["mesh"], d.get("n_vertices"), d.get("n_faces"))
        if smooth and n is None:
            raise PackageError(f"{package_dir / d['mesh']}: the scene is smooth-shaded but the "
                               "PLY has no vertex normals")
        model = matrix(d["model"], f"draws[{i}].model")
        oid = int(d["object_id"])
        ubo = _draw_uniform(backend, view, proj, model, model, palette[oid % len(palette)],
                            oid, smooth, shading, vp)
        out["solids"].append(_mesh_draw(backend, v, f, n, ubo, oid))
    zero = float_texture(backend, [np.zeros((1, 1), np.float32)])
    out["textures"].append(zero)
    for k, s in enumerate(p["surfaces"]):
        wrap = s.get("wrap", "repeat")
        if wrap not in ADDRESS_MODES:
            raise PackageError(f"parameters.surfaces[{k}].wrap must be one of "
                               f"{sorted(ADDRESS_MODES)}, got {wrap!r}")
        entry = {"enabled": bool(s.get("enabled", True)), "s": s, "mode": ADDRESS_MODES[wrap],
                 "offset": float_texture(backend, [read_map(package_dir, scene,
                                                            s["offset_map"])])}
        if p.get("caps"):
            maps = [read_map(package_dir, scene, name) for name in s["normal_map"]]
            maps.append(read_map(package_dir, scene, s["occlusion_map"]))
            entry["shading"] = float_texture(backend, maps)
            for key in ("diffuse", "normal", "light"):
                names = (s.get("textures") or {}).get(key)
                if names:
                    entry[key] = float_texture(backend, [read_map(package_dir, scene, name)
                                                         for name in names])
        out["textures"] += [t for key, t in entry.items()
                            if key in ("offset", "shading", "diffuse", "normal", "light")]
        out["surfaces"].append(entry)
    if p.get("caps"):
        for m, sp in enumerate(p["sprites"]):
            layers = [read_map(package_dir, scene, n) for n in sp["sprite_depth"]]
            count = read_map(package_dir, scene, sp["sprite_count"])
            h, w = count.shape
            if not layers or any(a.shape != (h, w) for a in layers):
                raise PackageError(f"sprites[{m}]: the maps must all be (h, w) = {(h, w)}")
            if len(layers) > 256 or max(h, w) > 8192:
                raise PackageError(f"sprites[{m}] exceeds WebGPU's default texture limits "
                                   "(256 layers, 8192 texels)")
            # the package's maps have row 0 at the top, texture row 0 is t = 0: flipped
            depth = np.ascontiguousarray(np.stack([a[::-1] for a in layers]), np.float32)
            arr = dev.create_texture(size=(w, h, len(layers)), format="r32float",
                                     usage=usage.TEXTURE_BINDING | usage.COPY_DST)
            dev.queue.write_texture({"texture": arr}, depth.tobytes(),
                                    {"bytes_per_row": 4 * w, "rows_per_image": h},
                                    (w, h, len(layers)))
            cnt = dev.create_texture(size=(w, h, 1), format="r32sint",
                                     usage=usage.TEXTURE_BINDING | usage.COPY_DST)
            dev.queue.write_texture({"texture": cnt},
                                    np.ascontiguousarray(count[::-1], np.int32).tobytes(),
                                    {"bytes_per_row": 4 * w, "rows_per_image": h}, (w, h, 1))
            out["sprites"].append((arr, cnt, matrix(sp["sprite_matrix"],
                                                    f"sprites[{m}].sprite_matrix")))
            out["textures"] += [arr, cnt]
        for i, c in enumerate(p["cap_meshes"]):
            v = np.asarray(read_map(package_dir, scene, c["vertices"]), np.float64)
            f = np.asarray(read_map(package_dir, scene, c["faces"]))
            if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 \
                    or (len(f) and (f.min() < 0 or f.max() >= len(v))) \
                    or not np.all(np.isfinite(v)):
                raise PackageError(f"cap_meshes[{i}]: vertices (V, 3) finite and faces (F, 3) "
                                   "in range")
            if not (0 <= c["solid"] < len(out["sprites"])
                    and 0 <= c["surface"] < len(out["surfaces"])):
                raise PackageError(f"cap_meshes[{i}]: solid or surface out of range")
            oid = int(c["object_id"])
            ubo = _draw_uniform(backend, view, proj, np.eye(4), np.eye(4), (0.0, 0.0, 0.0),
                                oid, False, shading, vp)
            draw_ = _mesh_draw(backend, v.astype(np.float32), f.astype(np.int64), None, ubo,
                               oid)
            draw_.update(solid=int(c["solid"]), surface=int(c["surface"]))
            out["caps"].append(draw_)
    out["groups"] = _groups(backend, scene, out, view)
    return out


def _clip_block(scene, surfaces, view, cap=None, smat=None, has=0):
    """clip.wgsl's ``Clip`` uniform (320 bytes)."""
    block = np.zeros(80, np.float32)
    ints = block.view(np.int32)
    for k, e in enumerate(surfaces):
        s = e["s"]
        o, u, v = (np.asarray(s[key], np.float64) for key in ("origin", "u", "v"))
        lu, lv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
        if not lu > 0 or not lv > 0:
            raise PackageError(f"parameters.surfaces[{k}]: u and v must be non-zero")
        uh, vh = u / lu, v / lv
        base = 20 * k
        block[base:base + 4] = [*o, 1.0 if e["enabled"] else 0.0]
        block[base + 4:base + 8] = [*uh, lu]
        block[base + 8:base + 12] = [*vh, lv]
        block[base + 12:base + 15] = np.cross(uh, vh)
        block[base + 16:base + 20] = [*(float(x) for x in s["scale"]), float(e["mode"])]
    n4 = np.eye(4)
    n4[:3, :3] = np.linalg.inv(view[:3, :3]).T
    block[40:56] = np.asarray(n4, np.float32).T.reshape(-1)
    block[56:72] = np.asarray(np.eye(4) if smat is None else smat, np.float32).T.reshape(-1)
    block[72:75] = scene["parameters"].get("cap_color", [0.0, 0.0, 0.0])
    ints[76:80] = [len(surfaces), 0 if cap is None else 1, 0 if cap is None else cap, has]
    return block


def _groups(backend, scene, loaded, view):
    """The bind groups of group 1: the solids' and one per cap."""
    lay = _layouts(backend)
    dev = backend.device
    surfaces, zero = loaded["surfaces"], loaded["textures"][0]
    if "_clip_dummy" not in backend.__dict__:
        usage = backend.wgpu.TextureUsage.TEXTURE_BINDING
        backend._clip_dummy = (
            dev.create_texture(size=(1, 1, 1), format="r32float", usage=usage),
            dev.create_texture(size=(1, 1, 1), format="r32sint", usage=usage))
    arr0, cnt0 = backend._clip_dummy
    offsets = [e["offset"] for e in surfaces] + [zero] * (MAX_SURFACES - len(surfaces))

    def group(block, arr, cnt, maps):
        ubo = uniform(backend, block)
        loaded["buffers"].append(ubo)
        entries = [{"binding": 20, "resource": {"buffer": ubo, "offset": 0,
                                                "size": block.nbytes}}]
        entries += [{"binding": 21 + k, "resource": t.create_view()}
                    for k, t in enumerate(offsets)]
        entries += [{"binding": 23, "resource": arr.create_view(dimension="2d-array")},
                    {"binding": 24, "resource": cnt.create_view()}]
        entries += [{"binding": 25 + k, "resource": t.create_view()} for k, t in enumerate(maps)]
        return dev.create_bind_group(layout=lay["group"], entries=entries)

    out = {"solids": group(_clip_block(scene, surfaces, view), arr0, cnt0, [zero] * 4),
           "caps": []}
    for d in loaded["caps"]:
        e = surfaces[d["surface"]]
        arr, cnt, smat = loaded["sprites"][d["solid"]]
        has = sum(bit for key, bit in (("diffuse", 1), ("normal", 2), ("light", 4)) if key in e)
        maps = [e.get("shading", zero)] + [e.get(key, zero) for key in ("diffuse", "normal",
                                                                         "light")]
        block = _clip_block(scene, surfaces, view, d["surface"], smat, has)
        out["caps"].append(group(block, arr, cnt, maps))
    return out


def release(loaded):
    """Destroy what :func:`load` uploaded (``None``: nothing)."""
    if not loaded:
        return
    for tex in loaded.get("textures", ()):
        tex.destroy()
    for d in loaded.get("solids", []) + loaded.get("caps", []):
        for buf in (d["vbo"], d["ubo"]):
            if buf is not None:
                buf.destroy()
    for buf in loaded.get("buffers", ()):
        buf.destroy()
    loaded.clear()


def draw(backend, loaded):
    """The clip-surface G-buffer → ``{buffer: array}`` as the golden stores it."""
    scene, conv, clip = loaded["scene"], loaded["conv"], loaded["clip"]
    raster, shading = scene["raster"], scene["shading"]
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    state, clear = backend._state(scene, conv)
    faults = tuple((c, True) for f, c in FAULT_CONSTANTS.items() if f in backend.faults)
    lay = _layouts(backend)
    depth = backend._depth(state, size)
    encoder = backend.device.create_command_encoder()
    made = {}
    for entry, formats in PASSES.items():
        targets = backend._targets(formats, size)
        pipe = scene_pipeline(backend, SHADER, entry, formats, state, lay["pipeline"], faults)
        rp = encoder.begin_render_pass(
            color_attachments=[{"view": t.create_view(), "clear_value": (0, 0, 0, 0),
                                "load_op": "clear", "store_op": "store"} for t in targets],
            depth_stencil_attachment={"view": depth.create_view(), "depth_clear_value": clear,
                                      "depth_load_op": "clear", "depth_store_op": "store"})
        rp.set_pipeline(pipe)
        for d, group in [(d, clip["groups"]["solids"]) for d in clip["solids"]] + \
                list(zip(clip["caps"], clip["groups"]["caps"])):
            if not d["n_faces"]:
                continue
            rp.set_bind_group(0, d["group"])
            rp.set_bind_group(1, group)
            rp.set_vertex_buffer(0, d["vbo"])
            rp.draw(3 * d["n_faces"])
        rp.end()
        made[entry] = (targets, formats)
    backend.device.queue.submit([encoder.finish()])
    try:
        got = {entry: [backend._read(t, f, size) for t, f in zip(ts, fs)]
               for entry, (ts, fs) in made.items()}
    finally:
        for ts, _ in made.values():
            for t in ts:
                t.destroy()
        depth.destroy()
    win, eye, ids = got["fs_clip_ids"]
    normal, bary = got["fs_clip_surface"]
    color = got["fs_clip_shade"][0]
    covered = ids[..., 3] == 1
    c3 = covered[..., None]
    bg = np.asarray(shading["background"], np.float32)
    object_id = np.where(covered, ids[..., 1], -1).astype(np.int32)
    return {
        "depth": np.where(covered, win[..., 0],
                          np.float32(raster["clear_depth"])).astype(np.float32),
        "eye_depth": np.where(covered, eye[..., 0], np.float32(np.inf)).astype(np.float32),
        "normal": np.where(c3, normal[..., :3], 0).astype(np.float32),
        "prim_id": np.where(covered, ids[..., 0], -1).astype(np.int32),
        "object_id": object_id,
        "front_facing": covered & (ids[..., 2] == 1),
        "barycentric": np.where(c3, bary[..., :3], 0).astype(np.float32),
        "color": np.where(c3, color[..., :3], bg).astype(np.float32),
        "cap_mask": object_id >= len(clip["solids"]),
    }
