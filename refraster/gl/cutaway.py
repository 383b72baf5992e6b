"""Adaptive cutaways on the GPU (Burns & Finkelstein 2008) for refraster.gl, from a scene
package's ``parameters`` alone (``docs/golden-schema.md``, technique ``cutaway``).

Passes (``shaders/cutaway_*.frag``):

1. rear hulls of the objects of interest (``parameters.interest``), depth test GREATER against a
   32-bit float depth buffer cleared to 0;
2. seeds: NDC depth and slope per rear-hull pixel (Eq. 3 as corrected, edge compression);
3. jump flooding, ping-pong between two RGBA32F textures, with the step schedule of
   ``parameters.variant`` (``jfa``: n/2 … 1 with n the power of two ≥ max(W, H); ``jfa+1``,
   ``jfa+2`` append 1 or 2, 1; ``1+jfa`` prepends 1), the last pass writing D (NDC);
4. D_dil (3×3 minimum) and the cut-surface normals from it;
5. the G-buffer of the secondary objects then the objects of interest with the discard test
   (front faces against D, back faces against D_dil) and the cut surfaces shaded with the
   cutaway's normals, plus the cut flag;
6. ghost lines: the secondary meshes' feature lines (found here with NumPy, as a GPU team's
   preprocessing would) as GL_LINES, MAX-blended opacity.

Buffers: the G-buffer, ``cutaway_depth`` (window depth ½D + ½), ``cut_mask`` and ``ghost``.
"""

from __future__ import annotations

import numpy as np

from .common import Unsupported, fullscreen, programs
# the package's cutaway parameters and ghost-line preprocessing: one reader for both backends
from .package import CUTAWAY_VARIANTS as VARIANTS  # noqa: F401  (re-exported)
from .package import cutaway_feature_segments as feature_segments
from .package import cutaway_ghost_lines, matrix
from .package import cutaway_options as options
from .package import cutaway_step_schedule as step_schedule
from .package import cutaway_supports as supports

__all__ = ["supports", "step_schedule", "render_cutaway", "feature_segments", "Pool",
           "rear_hulls", "seed_uniforms", "flood_surface", "cut_normals", "carve_uniforms",
           "carve_draws", "ghost_pass"]

#: Passes dropped by the planted fault ``schedule_truncated`` (the schedule's last ones).
TRUNCATED_PASSES = 3


#: The programs (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {
    "hull": ("gbuffer.vert", None, "cutaway_hull.frag"),
    "seed": ("fullscreen.vert", None, "cutaway_seed.frag"),
    "flood": ("fullscreen.vert", None, "cutaway_flood.frag"),
    "dilate": ("fullscreen.vert", None, "cutaway_dilate.frag"),
    "gbuffer": ("gbuffer.vert", "gbuffer.geom", "cutaway_gbuffer.frag"),
    "ghost": ("line.vert", None, "cutaway_ghost.frag"),
}


class Pool:
    """The textures and framebuffers of one frame, released together (:meth:`release`)."""

    def __init__(self, gl, size):
        self.gl, self.size, self.owned = gl, size, []

    def tex(self, comps, dtype, samples=0):
        t = self.gl.ctx.texture(self.size, comps, dtype=dtype, samples=samples)
        if not samples:
            t.filter = (self.gl.mgl.NEAREST, self.gl.mgl.NEAREST)
        self.owned.append(t)
        return t

    def fbo(self, colors, depth=None):
        f = self.gl.ctx.framebuffer(color_attachments=colors, depth_attachment=depth)
        self.owned.insert(0, f)
        return f

    def keep(self, obj, first=False):
        """Own ``obj`` (``first``: release it before the textures, as a framebuffer or VAO)."""
        if first:
            self.owned.insert(0, obj)
        else:
            self.owned.append(obj)
        return obj

    def release(self):
        self.gl._parking.use()
        for obj in self.owned:
            obj.release()
        self.owned = []


def rear_hulls(gl, progs, pool, draws, opt, depth, samples=0):
    """Pass 1 into new targets of ``samples`` samples (0: single-sample) with the depth
    attachment ``depth``, GREATER against 0 → ``(rear window depth R32F, hull + 1 R32I)``."""
    mgl, ctx = gl.mgl, gl.ctx
    rear, hull = pool.tex(1, "f4", samples), pool.tex(1, "i4", samples)
    f = pool.fbo([rear, hull], depth)
    f.use()
    f.clear(0.0, 0.0, 0.0, 0.0, depth=0.0)
    ctx.enable_only(mgl.DEPTH_TEST)
    ctx.depth_func = ">"
    prog = progs["hull"]
    for k, i in enumerate(opt["interest"]):
        d = draws[i]
        if not d["n_faces"]:
            continue
        gl._write(prog, "u_mvp", d["mvp"])
        gl._set(prog, "u_hull", k)
        gl._vao(d, prog).render(mgl.TRIANGLES)
    ctx.disable(mgl.DEPTH_TEST)
    return rear, hull


def seed_uniforms(gl, prog, opt, proj, view, inv_proj):
    """Pass 2's uniforms: the angles, edge compression, slope kind and floor constraint;
    ``inv_proj`` unprojects the seed's pixel centre (the frame's, or a sample's lattice's)."""
    persp = bool(np.array_equal(proj[3], [0, 0, -1, 0]))
    floor = opt["floor_normal"] is not None
    thetas = opt["angles"] + [0.0] * (8 - len(opt["angles"]))
    prog["u_theta"].value = tuple(thetas)
    gl._set(prog, "u_n_theta", len(opt["angles"]))
    gl._set(prog, "u_r", opt["r"])
    gl._set(prog, "u_kind", 0 if not persp else (1 if opt["perspective_compensation"] else 2))
    gl._set(prog, "u_p", (float(proj[2, 2]), float(proj[0, 0])))
    gl._set(prog, "u_floor", floor)
    if floor:
        n = np.linalg.inv(view[:3, :3]).T @ np.array(opt["floor_normal"])
        gl._set(prog, "u_floor_n", tuple(float(c) for c in n / np.linalg.norm(n)))
        gl._set(prog, "u_floor_margin", opt["floor_margin"])
        gl._write(prog, "u_inv_proj", inv_proj)


def flood_surface(gl, progs, pool, seed, opt, proj):
    """Passes 2–4 after the seed program's inputs and uniforms are set: the seeds (``seed``
    drawn full screen), jump flooding and ``D_dil`` → ``(D, D_dil)`` R32F textures (NDC)."""
    w, h = pool.size
    floor = opt["floor_normal"] is not None
    recs = [pool.tex(4, "f4"), pool.tex(4, "f4")]
    flr = [pool.tex(4, "f4"), pool.tex(4, "f4")]     # (m_f, n_x, n_y) with the floor constraint
    fb_rec = [pool.fbo([recs[0], flr[0]]), pool.fbo([recs[1], flr[1]])]
    fb_rec[0].use()
    fullscreen(gl, seed)
    # 3. jump flooding
    steps = step_schedule(h, w, opt["variant"])
    if "schedule_truncated" in gl.faults:   # planted fault: the last passes left out
        steps = steps[:max(1, len(steps) - TRUNCATED_PASSES)]
    dtex = pool.tex(1, "f4")
    fb_d = pool.fbo([dtex])
    prog = progs["flood"]
    gl._set(prog, "u_src", 0)
    gl._set(prog, "u_src_floor", 1)
    gl._set(prog, "u_floor", floor)
    gl._set(prog, "u_sampling", (2.0 / (w * proj[0, 0]), 2.0 / (h * proj[1, 1])))
    cur = 0
    for n, k in enumerate(steps):
        last = n == len(steps) - 1
        (fb_d if last else fb_rec[1 - cur]).use()
        recs[cur].use(0)
        flr[cur].use(1)
        gl._set(prog, "u_k", int(k))
        gl._set(prog, "u_final", last)
        fullscreen(gl, prog)
        cur = 1 - cur
    # 4. D_dil
    if not opt["dilation"]:
        return dtex, dtex
    prog = progs["dilate"]
    ddil = pool.tex(1, "f4")
    pool.fbo([ddil]).use()
    dtex.use(0)
    gl._set(prog, "u_d", 0)
    gl._set(prog, "u_normals", False)
    fullscreen(gl, prog)
    return dtex, ddil


def cut_normals(gl, progs, pool, ddil, proj):
    """Pass 4's cut-surface normals from ``D_dil`` unprojected by ``proj`` → RGBA32F."""
    prog = progs["dilate"]
    cutn = pool.tex(4, "f4")
    pool.fbo([cutn]).use()
    ddil.use(0)
    gl._set(prog, "u_d", 0)
    gl._write(prog, "u_inv_proj", np.linalg.inv(proj))
    gl._set(prog, "u_perspective", bool(np.array_equal(proj[3], [0, 0, -1, 0])))
    gl._set(prog, "u_normals", True)
    fullscreen(gl, prog)
    return cutn


def carve_uniforms(gl, prog, scene, opt):
    """Pass 5's uniforms besides the cutaway textures (units 0, 1, 2: D, D_dil, normals)."""
    shading = scene["shading"]
    gl._set(prog, "u_light", tuple(float(shading[k]) for k in
                                   ("ambient", "diffuse", "specular", "shininess")))
    gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
    gl._set(prog, "u_viewport", tuple(float(s) for s in
                                      (scene["viewport"]["width"], scene["viewport"]["height"])))
    gl._set(prog, "u_dilation", opt["dilation"])
    for name, unit in (("u_D", 0), ("u_D_dil", 1), ("u_cut_normal", 2)):
        gl._set(prog, name, unit)


def carve_draws(gl, prog, draws, opt, palette):
    """Pass 5's draws: the secondary objects, then the objects of interest."""
    sec = set(opt["secondary"])
    for i in opt["secondary"] + opt["interest"]:
        d = draws[i]
        if not d["n_faces"]:
            continue
        gl._set(prog, "u_secondary", i in sec)
        gl._draw(prog, d, palette)


def ghost_pass(gl, progs, pool, scene, package_dir, opt, draws, buffers, covered, dtex, pv):
    """Pass 6: ghost lines under the matrix ``pv`` (projection · view) against ``D``
    (``dtex``) and the visible objects of interest of the read-back G-buffer ``buffers``
    → ``(H, W) float32``."""
    mgl, ctx = gl.mgl, gl.ctx
    w, h = pool.size
    seg, g_max = cutaway_ghost_lines(scene, package_dir, opt)
    if not len(seg):
        return np.zeros((h, w), np.float32)
    interest_ids = {int(draws[i]["object_id"]) for i in opt["interest"]}
    # where covered, object_id and depth are the ids and window depth read back
    ooi = covered & np.isin(buffers["object_id"], list(interest_ids))
    occ = np.where(ooi, 2.0 * buffers["depth"] - 1.0, 2.0).astype(np.float32)
    occ_tex = pool.keep(ctx.texture(pool.size, 1, np.ascontiguousarray(occ[::-1]).tobytes(),
                                    dtype="f4"))
    occ_tex.filter = (mgl.NEAREST, mgl.NEAREST)
    gtex = pool.tex(1, "f4")
    fg = pool.fbo([gtex])
    fg.use()
    fg.clear(0.0, 0.0, 0.0, 0.0)
    ctx.enable_only(mgl.BLEND)
    ctx.blend_equation = mgl.MAX
    ctx.blend_func = mgl.ONE, mgl.ONE
    prog = progs["ghost"]
    gl._write(prog, "u_mvp", pv.astype(np.float32))
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    dtex.use(0)
    occ_tex.use(1)
    gl._set(prog, "u_D", 0)
    gl._set(prog, "u_occluder", 1)
    gl._set(prog, "u_g_max", float(g_max))
    gl._set(prog, "u_fade", opt["ghost_fade"])
    gl._set(prog, "u_p", (float(proj[2, 2]), float(proj[2, 3]), float(proj[3, 2]),
                          float(proj[3, 3])))
    vbo = pool.keep(ctx.buffer(np.ascontiguousarray(seg.reshape(-1, 3), np.float32).tobytes()),
                    first=True)
    vao = pool.keep(ctx.vertex_array(prog, [(vbo, "3f", "in_pos")]), first=True)
    vao.render(mgl.LINES)
    ctx.blend_equation = mgl.FUNC_ADD
    ctx.disable(mgl.BLEND)
    ctx.finish()
    return gl._read(gtex, "<f4", 1, pool.size)[..., 0]


def render_cutaway(gl, loaded, package_dir):
    scene, draws = loaded["scene"], loaded["draws"]
    opt, reason = options(scene)
    if reason is not None:
        raise Unsupported(reason)
    progs = programs(gl, SHADERS)
    ctx = gl.ctx
    size = (scene["viewport"]["width"], scene["viewport"]["height"])
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    pool = Pool(gl, size)
    try:
        ctx.viewport = (0, 0, *size)
        # 1. rear hulls
        rear, hull = rear_hulls(gl, progs, pool, draws, opt, pool.keep(
            gl._depth_attachment(size)))
        # 2.–4. seeds, jump flooding, D_dil and the cut normals
        prog = progs["seed"]
        rear.use(0)
        hull.use(1)
        gl._set(prog, "u_rear", 0)
        gl._set(prog, "u_hull", 1)
        seed_uniforms(gl, prog, opt, proj, view, np.linalg.inv(proj))
        dtex, ddil = flood_surface(gl, progs, pool, prog, opt, proj)
        cutn = cut_normals(gl, progs, pool, ddil, proj)
        # 5. the clipped G-buffer
        targets = [pool.tex(1, "f4"), pool.tex(1, "f4"), pool.tex(4, "f4"), pool.tex(4, "f4"),
                   pool.tex(4, "f4"), pool.tex(4, "i4"), pool.tex(1, "i4")]
        dep = pool.keep(gl._depth_attachment(size))
        f = pool.fbo(targets, dep)
        f.use()
        f.clear(0.0, 0.0, 0.0, 0.0, depth=float(scene["raster"]["clear_depth"]))
        gl._state(scene)
        prog = progs["gbuffer"]
        carve_uniforms(gl, prog, scene, opt)
        for unit, t in enumerate((dtex, ddil, cutn)):
            t.use(unit)
        carve_draws(gl, prog, draws, opt, scene["shading"]["palette"])
        ctx.finish()
        out, covered = gl._read_gbuffer(scene, targets, size)
        cut = gl._read(targets[6], "<i4", 1, size)[..., 0]
        d_ndc = gl._read(dtex, "<f4", 1, size)[..., 0]
        # 6. ghost lines
        ghost = ghost_pass(gl, progs, pool, scene, package_dir, opt, draws, out, covered, dtex,
                           proj @ view)
    finally:
        pool.release()
    out["cutaway_depth"] = (np.float32(0.5) * d_ndc + np.float32(0.5)).astype(np.float32)
    out["cut_mask"] = covered & (cut == 1)
    out["ghost"] = np.ascontiguousarray(ghost, np.float32)
    return out
