"""Volumetric halos for surfaces in 4D (Wang et al. 2013) on the GPU for refraster.gl, from a
scene package's maps and ``parameters`` alone (``docs/golden-schema.md``, technique
``halos4d``).

On the CPU (NumPy, as a GPU team's per-frame setup, shared with refraster.wgpu:
:func:`refraster.gl.package.halos_frame`): the 4D rotation and projection of the
vertices and tangents, the thickening directions (Eq. 1 normalized, face-normal fallback), the
offset copies v ± ρn̂ (Eq. 2), the headlight colour, and the prisms split into tetrahedra
(``parameters.split``: ``"paper"``, the default, each prism in its face's vertex order with the
paper's repair of mismatched sides — a diagonal flip, Fig. 4(b), and a prism whose sides end
cyclic rebuilt from its triangles' centroids as three smaller prisms, Fig. 4(d); or
``"global_index"``, the global-index rule; ``docs/halos4d.md``). On the GPU, per slicing plane z = c_k, back (smallest z) to front:

A. every tetrahedron sliced in a geometry shader (``halo_slice.geom``, lines_adjacency = the
   tetrahedron's 4 vertices), Eq. 3's halo depth per fragment into a MIN-blended R32F target;
B. the voxel's surface fragment by a depth test on a (core, δ) key;
C. the occlusion rule δ ≤ minD + ε and the slice composited into the frame with blending
   (colour SRC_ALPHA/ONE_MINUS_SRC_ALPHA, alpha ONE/ONE_MINUS_SRC_ALPHA); a second full-screen
   pass MAX-blends the voxel class into the halo-class target.

Buffers: ``color`` (composited over the background), ``alpha``, ``halo_class`` (2 if a halo
carved some surface voxel of the pixel's column, else 1 if a surface voxel is drawn, else 3 if
only halo voxels, else 0).
"""

from __future__ import annotations

import numpy as np

from .common import Unsupported, fullscreen, programs
from .package import HALO_SPLITS as SPLITS
from .package import PackageError, halos_frame
from .package import halos_options as options
from .package import halos_paper_split as _paper_split  # noqa: F401 (tests use it)
from .package import halos_prepare as prepare
from .package import halos_supports as supports

__all__ = ["supports", "options", "prepare", "render_halos", "SPLITS"]


#: The programs (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {
    "depth": ("halo_slice.vert", "halo_slice.geom", "halo_depth.frag"),
    "surface": ("halo_slice.vert", "halo_slice.geom", "halo_surface.frag"),
    "resolve": ("fullscreen.vert", None, "halo_resolve.frag"),
}


def render_halos(gl, loaded, package_dir):
    scene = loaded["scene"]
    _, reason = options(scene)
    if reason is not None:
        raise Unsupported(reason)
    fr = halos_frame(scene, package_dir)
    opt, data, tets = fr["opt"], fr["data"], fr["tets"]
    w, h = opt["width"], opt["height"]
    n = opt["slices"]
    ws, aa = opt["surface_width"], opt["antialias"]
    alpha, halo_alpha, eps = fr["alpha"], fr["halo_alpha"], fr["eps"]
    progs = programs(gl, SHADERS)
    mgl, ctx = gl.mgl, gl.ctx
    size = (w, h)
    owned = []

    def tex(comps):
        t = ctx.texture(size, comps, dtype="f4")
        t.filter = (mgl.NEAREST, mgl.NEAREST)
        owned.append(t)
        return t

    try:
        vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        ibo = ctx.buffer(np.ascontiguousarray(tets, np.int32).tobytes())
        owned += [vbo, ibo]
        vaos = {}
        for key in ("depth", "surface"):
            # the compiler drops an attribute a program does not use: skip its bytes
            layout = ((vbo, "2f 1f 4f 1f", "in_xy", "in_z", "in_attr", "in_b")
                      if "in_b" in progs[key] else
                      (vbo, "2f 1f 4f 4x", "in_xy", "in_z", "in_attr"))
            vaos[key] = ctx.vertex_array(progs[key], [layout], index_buffer=ibo,
                                         index_element_size=4)
            owned.insert(0, vaos[key])
        min_d, hit, sd, surf, acc, cls = tex(1), tex(1), tex(4), tex(4), tex(4), tex(1)
        dep = gl._depth_attachment(size)
        owned.append(dep)
        fa = ctx.framebuffer(color_attachments=[min_d, hit])
        fb = ctx.framebuffer(color_attachments=[sd, surf], depth_attachment=dep)
        fc = ctx.framebuffer(color_attachments=[acc])
        fk = ctx.framebuffer(color_attachments=[cls])
        owned[:0] = [fa, fb, fc, fk]
        ctx.viewport = (0, 0, w, h)
        fc.use()
        fc.clear(0.0, 0.0, 0.0, 0.0)
        fk.use()
        fk.clear(0.0, 0.0, 0.0, 0.0)
        pa, ps, pr = progs["depth"], progs["surface"], progs["resolve"]
        gl._set(pa, "u_delta_t", opt["delta_t"])
        gl._set(pa, "u_delta_d", opt["delta_d"])
        gl._set(pa, "u_ws_aa", ws + aa)
        gl._set(pa, "u_halos", opt["halos"])
        gl._set(ps, "u_ws", ws)
        gl._set(ps, "u_aa", aa)
        gl._set(ps, "u_d_range", (fr["d_range"][0] - 1e-6, fr["d_range"][1] + 1e-6))
        for name, unit in (("u_min_d", 0), ("u_hit", 1), ("u_d", 2), ("u_surf", 3)):
            gl._set(pr, name, unit)
        gl._set(pr, "u_eps", eps)
        gl._set(pr, "u_alpha", alpha)
        gl._set(pr, "u_halo_alpha", halo_alpha)
        gl._set(pr, "u_halo_rgb", tuple(opt["halo_color"]))
        order = range(n)
        if "slices_front_to_back" in gl.faults:     # planted fault
            order = range(n - 1, -1, -1)
        for k in order:
            c = float(fr["planes"][k])
            # A: halo depth (MIN blending)
            fa.use()
            fa.clear(3.0e38, 0.0, 0.0, 0.0)
            ctx.enable_only(mgl.BLEND)
            ctx.blend_equation = mgl.MIN
            ctx.blend_func = mgl.ONE, mgl.ONE
            gl._set(pa, "u_c", c)
            vaos["depth"].render(mgl.LINES_ADJACENCY)
            # B: the surface fragment (depth test on the key)
            fb.use()
            fb.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable_only(mgl.DEPTH_TEST)
            ctx.depth_func = "<"
            gl._set(ps, "u_c", c)
            vaos["surface"].render(mgl.LINES_ADJACENCY)
            # C: resolve and composite; the class (MAX)
            min_d.use(0)
            hit.use(1)
            sd.use(2)
            surf.use(3)
            fc.use()
            ctx.enable_only(mgl.BLEND)
            ctx.blend_equation = mgl.FUNC_ADD
            ctx.blend_func = (mgl.SRC_ALPHA, mgl.ONE_MINUS_SRC_ALPHA, mgl.ONE,
                              mgl.ONE_MINUS_SRC_ALPHA)
            if "halo_premultiplied" in gl.faults:   # planted fault: straight as premultiplied
                ctx.blend_func = (mgl.ONE, mgl.ONE_MINUS_SRC_ALPHA, mgl.ONE,
                                  mgl.ONE_MINUS_SRC_ALPHA)
            gl._set(pr, "u_class_pass", False)
            fullscreen(gl, pr)
            fk.use()
            ctx.blend_equation = mgl.MAX
            ctx.blend_func = mgl.ONE, mgl.ONE
            gl._set(pr, "u_class_pass", True)
            fullscreen(gl, pr)
        ctx.blend_equation = mgl.FUNC_ADD
        ctx.blend_func = mgl.SRC_ALPHA, mgl.ONE_MINUS_SRC_ALPHA
        ctx.disable(mgl.BLEND)
        ctx.finish()
        out = gl._read(acc, "<f4", 4, size)
        code = gl._read(cls, "<f4", 1, size)[..., 0]
    finally:
        gl._parking.use()
        for obj in owned:
            obj.release()
    a = out[..., 3].astype(np.float64)
    bg = np.asarray(opt["background"], np.float64)
    color = out[..., :3].astype(np.float64) + (1.0 - a)[..., None] * bg
    halo_class = np.select([code > 2.5, code > 1.5, code > 0.5], [2, 1, 3], 0).astype(np.int32)
    return {"color": color.astype(np.float32), "alpha": a.astype(np.float32),
            "halo_class": halo_class}
