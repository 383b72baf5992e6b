"""Volumetric halos for surfaces in 4D (Wang et al. 2013) in WGSL for refraster.wgpu, from a
scene package's maps and ``parameters`` alone (``docs/golden-schema.md``, technique
``halos4d``), in ``shaders/halos.wgsl``. No optional WebGPU feature, WebGPU's default limits.

On the CPU, the per-frame setup both GPU backends share
(:func:`refraster.gl.package.halos_frame`: the 4D rotation and projection, the thickening, the
prisms split into tetrahedra, the slab planes, opacities and ε). On the GPU, per slicing plane
z = c_k, back (smallest z) to front, in one command encoder:

S. a compute pass (``cs_slice``, one invocation per tetrahedron) cuts every tetrahedron into
   0, 1 or 2 triangles written to fixed slots (6 vertices per tetrahedron, degenerate where
   unused) of a storage buffer — core WebGPU has no geometry shader;
A. that buffer drawn as a vertex buffer: Eq. 3's halo depth as the fragment depth into a
   ``depth32float`` attachment under ``less`` (the per-pixel minimum; refraster.gl MIN-blends
   into R32F, which core WebGPU cannot blend), the hit flag into r32float;
B. drawn again: the voxel's surface fragment by ``less`` on the (core, δ) key (rg32float δ,
   rgba32float colour and coverage);
C. a full-screen pass: the occlusion rule δ ≤ minD + ε and the straight-alpha composite
   ``acc·(1 − a) + a·(colour, 1)`` and the class maximum, written to the other texture pair of
   a ping-pong (rgba32float + r32sint, 20 bytes), the previous pair read with ``textureLoad``
   (no blending).

Buffers: ``color`` (composited over the background), ``alpha``, ``halo_class``.
"""

from __future__ import annotations

import numpy as np

from ..gl.package import PackageError, halos_frame
from ..gl.package import halos_supports as supports
from .common import SHADER_DIR, uniform
from .device import DEFAULT_LIMITS

__all__ = ["supports", "render", "SHADER"]

SHADER = "halos.wgsl"
#: The planted faults of this module: name → the override constant of halos.wgsl it sets (None:
#: a host switch).
FAULT_CONSTANTS = {"plane_half_slab": "PLANE_HALF_SLAB", "halo_depth_max": None}
#: Invocations per workgroup of ``cs_slice``.
WORKGROUP = 64
_SLICE_VERTEX = {"array_stride": 32, "attributes": [
    {"format": "float32x4", "offset": 0, "shader_location": 0},
    {"format": "float32x4", "offset": 16, "shader_location": 1}]}


def _setup(backend):
    """The shader module, bind group layouts and pipelines (once per backend and fault set)."""
    key = ("halos", backend.faults)
    cache = backend.__dict__.setdefault("_technique_pipelines", {})
    if key in cache:
        return cache[key]
    dev, wgpu = backend.device, backend.wgpu
    s = wgpu.ShaderStage
    mod = dev.create_shader_module(code=(SHADER_DIR / SHADER).read_text(encoding="utf-8"))
    const = {c: True for f, c in FAULT_CONSTANTS.items() if c and f in backend.faults}
    g0 = dev.create_bind_group_layout(entries=[
        {"binding": 0, "visibility": s.VERTEX | s.FRAGMENT | s.COMPUTE,
         "buffer": {"type": "uniform"}}])
    gs = dev.create_bind_group_layout(entries=[
        {"binding": 1, "visibility": s.COMPUTE, "buffer": {"type": "uniform"}},
        {"binding": 2, "visibility": s.COMPUTE, "buffer": {"type": "read-only-storage"}},
        {"binding": 3, "visibility": s.COMPUTE, "buffer": {"type": "read-only-storage"}},
        {"binding": 4, "visibility": s.COMPUTE, "buffer": {"type": "storage"}}])
    unf = {"sample_type": "unfilterable-float", "view_dimension": "2d"}
    gc = dev.create_bind_group_layout(entries=[
        {"binding": 5, "visibility": s.FRAGMENT, "texture": unf},
        {"binding": 6, "visibility": s.FRAGMENT,
         "texture": {"sample_type": "depth", "view_dimension": "2d"}},
        {"binding": 7, "visibility": s.FRAGMENT, "texture": unf},
        {"binding": 8, "visibility": s.FRAGMENT, "texture": unf},
        {"binding": 9, "visibility": s.FRAGMENT, "texture": unf},
        {"binding": 10, "visibility": s.FRAGMENT,
         "texture": {"sample_type": "sint", "view_dimension": "2d"}}])
    pl = dev.create_pipeline_layout
    slice_pipe = dev.create_compute_pipeline(
        layout=pl(bind_group_layouts=[g0, gs]),
        compute={"module": mod, "entry_point": "cs_slice", "constants": const})
    draw_layout = pl(bind_group_layouts=[g0])

    def draw(entry, targets, compare):
        return dev.create_render_pipeline(
            layout=draw_layout,
            vertex={"module": mod, "entry_point": "vs_slice", "buffers": [_SLICE_VERTEX]},
            primitive={"topology": "triangle-list", "cull_mode": "none"},
            depth_stencil={"format": "depth32float", "depth_write_enabled": True,
                           "depth_compare": compare},
            multisample={"count": 1},
            fragment={"module": mod, "entry_point": entry,
                      "targets": [{"format": f} for f in targets]})
    # planted fault halo_depth_max: the depth trick kept the maximum (greater, cleared to 0)
    compare_a = "greater" if "halo_depth_max" in backend.faults else "less"
    resolve = dev.create_render_pipeline(
        layout=pl(bind_group_layouts=[g0, gc]),
        vertex={"module": mod, "entry_point": "vs_full"},
        primitive={"topology": "triangle-list"},
        fragment={"module": mod, "entry_point": "fs_resolve",
                  "targets": [{"format": "rgba32float"}, {"format": "r32sint"}]})
    cache[key] = {"g0": g0, "slice_group": gs, "resolve_group": gc, "slice": slice_pipe,
                  "depth": draw("fs_halo_depth", ("r32float",), compare_a),
                  "surface": draw("fs_surface", ("rg32float", "rgba32float"), "less"),
                  "resolve": resolve, "clear_a": 0.0 if compare_a == "greater" else 1.0}
    return cache[key]


def _params(fr):
    """The ``Params`` block of halos.wgsl (64 bytes)."""
    opt = fr["opt"]
    d_lo, d_hi = fr["d_range"][0] - 1e-6, fr["d_range"][1] + 1e-6
    lo, hi = d_lo, d_hi + opt["delta_d"]
    block = np.zeros(16, np.float32)
    block[:11] = [lo, hi, opt["delta_t"], opt["delta_d"], opt["surface_width"],
                  opt["antialias"], d_lo, d_hi, 0.5 * fr["eps"] / (hi - lo), fr["alpha"],
                  fr["halo_alpha"]]
    block.view(np.uint32)[11] = int(opt["halos"])
    block[12:15] = opt["halo_color"]
    block[15] = fr["dz"]
    return block


def render(backend, loaded, package_dir):
    """The halos4d scene's buffers as the golden stores them (row 0 at the top)."""
    scene = loaded["scene"]
    fr = halos_frame(scene, package_dir)
    opt, data, tets = fr["opt"], fr["data"], fr["tets"]
    n_tets = len(tets)
    if n_tets == 0:
        raise PackageError("halos4d: the surface has no tetrahedra")
    limit = DEFAULT_LIMITS["max-storage-buffer-binding-size"]
    if 6 * n_tets * 32 > limit:
        raise PackageError(f"halos4d: {n_tets} tetrahedra need {6 * n_tets * 32} bytes of slice "
                           f"vertices, more than WebGPU's default storage binding ({limit})")
    lay = _setup(backend)
    dev, wgpu = backend.device, backend.wgpu
    usage, busage = wgpu.TextureUsage, wgpu.BufferUsage
    w, h = opt["width"], opt["height"]
    made = []

    def texture(fmt, copy=False):
        use = usage.RENDER_ATTACHMENT | usage.TEXTURE_BINDING
        if copy:
            use |= usage.COPY_SRC
        t = dev.create_texture(size=(w, h, 1), format=fmt, usage=use)
        made.append(t)
        return t

    def storage(arr):
        b = dev.create_buffer_with_data(data=np.ascontiguousarray(arr).tobytes(),
                                        usage=busage.STORAGE)
        made.append(b)
        return b

    def whole(buf):
        return {"buffer": buf, "offset": 0, "size": buf.size}

    try:
        params = uniform(backend, _params(fr))
        made.append(params)
        verts, tet_buf = storage(data), storage(tets)
        tris = dev.create_buffer(size=6 * n_tets * 32, usage=busage.STORAGE | busage.VERTEX)
        made.append(tris)
        g0 = dev.create_bind_group(layout=lay["g0"],
                                   entries=[{"binding": 0, "resource": whole(params)}])
        hit, min_d = texture("r32float"), texture("depth32float")
        sd, surf, dep_b = texture("rg32float"), texture("rgba32float"), texture("depth32float")
        pairs = [(texture("rgba32float", True), texture("r32sint", True)) for _ in range(2)]
        resolve_groups = [dev.create_bind_group(layout=lay["resolve_group"], entries=[
            {"binding": b, "resource": t.create_view()} for b, t in
            ((5, hit), (6, min_d), (7, sd), (8, surf), (9, acc), (10, cls))])
            for acc, cls in pairs]
        encoder = dev.create_command_encoder()
        rp = encoder.begin_render_pass(color_attachments=[
            {"view": t.create_view(), "clear_value": (0, 0, 0, 0), "load_op": "clear",
             "store_op": "store"} for t in pairs[0]])
        rp.end()

        def colour(ts):
            return [{"view": t.create_view(), "clear_value": (0, 0, 0, 0), "load_op": "clear",
                     "store_op": "store"} for t in ts]

        def depth(t, clear):
            return {"view": t.create_view(), "depth_clear_value": clear,
                    "depth_load_op": "clear", "depth_store_op": "store"}

        groups = (n_tets + WORKGROUP - 1) // WORKGROUP
        cur = 0
        for k in range(opt["slices"]):
            block = np.zeros(4, np.float32)
            block[0] = fr["planes"][k]
            block.view(np.uint32)[1] = n_tets
            ubo = uniform(backend, block)
            made.append(ubo)
            gs = dev.create_bind_group(layout=lay["slice_group"], entries=[
                {"binding": 1, "resource": whole(ubo)}, {"binding": 2, "resource": whole(verts)},
                {"binding": 3, "resource": whole(tet_buf)},
                {"binding": 4, "resource": whole(tris)}])
            # S: slicing
            cp = encoder.begin_compute_pass()
            cp.set_pipeline(lay["slice"])
            cp.set_bind_group(0, g0)
            cp.set_bind_group(1, gs)
            cp.dispatch_workgroups(groups)
            cp.end()
            # A: halo depth (the minimum by the depth test) and the hit flag
            for pipe, targets, dtex, clear in ((lay["depth"], [hit], min_d, lay["clear_a"]),
                                               (lay["surface"], [sd, surf], dep_b, 1.0)):
                rp = encoder.begin_render_pass(color_attachments=colour(targets),
                                               depth_stencil_attachment=depth(dtex, clear))
                rp.set_pipeline(pipe)
                rp.set_bind_group(0, g0)
                rp.set_vertex_buffer(0, tris)
                rp.draw(6 * n_tets)
                rp.end()
            # C: resolve into the other pair
            rp = encoder.begin_render_pass(color_attachments=colour(pairs[1 - cur]))
            rp.set_pipeline(lay["resolve"])
            rp.set_bind_group(0, g0)
            rp.set_bind_group(1, resolve_groups[cur])
            rp.draw(3)
            rp.end()
            cur = 1 - cur
        dev.queue.submit([encoder.finish()])
        out = backend._read(pairs[cur][0], "rgba32float", (w, h))
        code = backend._read(pairs[cur][1], "r32sint", (w, h))[..., 0]
    finally:
        for obj in made:
            obj.destroy()
    a = out[..., 3].astype(np.float64)
    bg = np.asarray(opt["background"], np.float64)
    color = out[..., :3].astype(np.float64) + (1.0 - a)[..., None] * bg
    halo_class = np.select([code == 3, code == 2, code == 1], [2, 1, 3], 0).astype(np.int32)
    return {"color": color.astype(np.float32), "alpha": a.astype(np.float32),
            "halo_class": halo_class}
