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

import math

import numpy as np

from .common import Unsupported, fullscreen, programs
from .package import PackageError, matrix, read_ply

__all__ = ["supports", "step_schedule", "render_cutaway", "feature_segments"]

VARIANTS = ("jfa", "jfa+1", "jfa+2", "1+jfa")
#: Passes dropped by the planted fault ``schedule_truncated`` (the schedule's last ones).
TRUNCATED_PASSES = 3


def step_schedule(height, width, variant):
    """The jump lengths of one run, in order (as refraster.cutaway.flood.step_schedule)."""
    n = 1
    while n < max(height, width):
        n *= 2
    plain, k = [], n // 2
    while k >= 1:
        plain.append(k)
        k //= 2
    plain = plain or [1]
    return {"jfa": plain, "jfa+1": plain + [1], "jfa+2": plain + [2, 1],
            "1+jfa": [1] + plain}[variant]


def _names(scene, key):
    p = scene.get("parameters", {})
    names = p.get(key)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise PackageError(f"parameters.{key} must be a list of draw names")
    by_name = {d.get("name"): i for i, d in enumerate(scene["draws"])}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise PackageError(f"parameters.{key} names draws {missing} the scene does not have")
    return [by_name[n] for n in names]


def options(scene):
    p = scene.get("parameters", {})
    if not isinstance(p, dict):
        raise PackageError("parameters must be an object")
    opt = {}
    variant = p.get("variant", "jfa")      # Cutaway().variant: the paper's schedule
    if variant not in VARIANTS:
        return None, (f"cutaway variant {variant!r}: only the jump-flooding schedules "
                      f"{list(VARIANTS)} are implemented")
    opt["variant"] = variant
    for key in ("stand_ins", "cutaway_size", "cut_color"):
        if p.get(key) is not None:
            return None, f"cutaway parameter {key!r} is not implemented by the gl backend"
    if p.get("ghost", "lines") != "lines":
        return None, "cutaway ghost 'visible' is not implemented (only 'lines')"
    angle = p.get("angle")
    angles = angle if isinstance(angle, list) else [angle]
    if not 1 <= len(angles) <= 8 or not all(
            isinstance(a, (int, float)) and not isinstance(a, bool) and 0 < a < math.pi / 2
            for a in angles):
        raise PackageError("parameters.angle must be a number (or up to 8) in (0, π/2) rad")
    opt["angles"] = [float(a) for a in angles]
    ec = p.get("edge_compression", 0.1)
    if ec is None:
        ec = 0.0
    if isinstance(ec, bool) or not isinstance(ec, (int, float)) or not ec >= 0:
        raise PackageError("parameters.edge_compression must be a number >= 0 or null")
    opt["r"] = float(ec)
    for key, default in (("perspective_compensation", True), ("dilation", True),
                         ("ghost_fade", True), ("outlines", True)):
        v = p.get(key, default)
        if not isinstance(v, bool):
            raise PackageError(f"parameters.{key} must be true or false")
        opt[key] = v
    for key, default in (("ghost_distance", None), ("crease_angle", 30.0)):
        v = p.get(key, default)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                              or not math.isfinite(v) or v < 0):
            raise PackageError(f"parameters.{key} must be a finite number >= 0")
        opt[key] = v
    fn = p.get("floor_normal")
    if fn is not None:
        if not (isinstance(fn, list) and len(fn) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                for c in fn)) or not any(fn):
            raise PackageError("parameters.floor_normal must be 3 finite numbers, not all 0")
        fn = [float(c) for c in fn]
    opt["floor_normal"] = fn
    fm = p.get("floor_margin", math.radians(2.0))
    if isinstance(fm, bool) or not isinstance(fm, (int, float)) or not 0 <= fm <= math.pi / 2:
        raise PackageError("parameters.floor_margin must be a number in [0, π/2] rad")
    opt["floor_margin"] = float(fm)
    opt["interest"] = _names(scene, "interest")
    opt["secondary"] = _names(scene, "secondary")
    return opt, None


def supports(scene):
    try:
        _, reason = options(scene)
    except PackageError as exc:
        return f"cutaway: {exc}"
    if reason is None:
        proj = np.asarray(scene["camera"]["projection"], np.float64)
        if not (np.array_equal(proj[3], [0, 0, -1, 0]) or np.array_equal(proj[3], [0, 0, 0, 1])):
            reason = "cutaway: the projection is neither glFrustum- nor glOrtho-shaped"
    return reason


def _face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def feature_segments(vertices, faces, view, model, ortho, crease_angle):
    """World-space feature lines (N, 2, 3) of one mesh for one view: silhouettes (front and back
    faces meet; front: the CCW normal toward the eye), borders (one face) and creases (dihedral
    angle > crease_angle degrees; for more than two faces the largest), vertices merged by
    exact position first."""
    v = np.asarray(vertices, np.float64)
    uniq, inv = np.unique(v, axis=0, return_inverse=True)
    f = inv.reshape(-1)[np.asarray(faces, np.int64)]
    if len(f) == 0:
        return np.zeros((0, 2, 3))
    mv = view @ model
    fn = _face_normals(uniq, f)
    im = np.linalg.inv(mv)
    towards = (np.broadcast_to(im[:3, :3] @ np.array([0.0, 0.0, 1.0]), fn.shape) if ortho
               else im[:3, 3] - uniq[f[:, 0]])
    front = np.einsum("ij,ij->i", fn, towards) > 0.0
    if np.linalg.det(mv[:3, :3]) < 0:
        front = ~front
    nf = len(f)
    pairs = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    face_of = np.tile(np.arange(nf), 3)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    ne = len(edges)
    count = np.bincount(inverse, minlength=ne)
    n_front = np.bincount(inverse, weights=front[face_of], minlength=ne)
    order = np.lexsort((face_of, inverse))
    start = np.cumsum(count) - count
    sf = face_of[order]
    two = count >= 2
    dihedral = np.full(ne, np.nan)
    dihedral[two] = _angle_deg(fn[sf[start[two]]], fn[sf[start[two] + 1]])
    for e in np.flatnonzero(count > 2):
        adj = fn[sf[start[e]:start[e] + count[e]]]
        i, j = np.triu_indices(len(adj), 1)
        dihedral[e] = _angle_deg(adj[i], adj[j]).max()
    with np.errstate(invalid="ignore"):
        crease = dihedral > crease_angle
    silhouette = two & (n_front > 0) & (n_front < count)
    keep = silhouette | (count == 1) | (two & crease)
    seg = uniq[edges[keep]]                                  # object space
    hom = np.concatenate([seg, np.ones(seg.shape[:2] + (1,))], axis=-1)
    return (hom @ model.T)[..., :3]


#: The programs (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {
    "hull": ("gbuffer.vert", None, "cutaway_hull.frag"),
    "seed": ("fullscreen.vert", None, "cutaway_seed.frag"),
    "flood": ("fullscreen.vert", None, "cutaway_flood.frag"),
    "dilate": ("fullscreen.vert", None, "cutaway_dilate.frag"),
    "gbuffer": ("gbuffer.vert", "gbuffer.geom", "cutaway_gbuffer.frag"),
    "ghost": ("line.vert", None, "cutaway_ghost.frag"),
}


def render_cutaway(gl, loaded, package_dir):
    scene, draws = loaded["scene"], loaded["draws"]
    opt, reason = options(scene)
    if reason is not None:
        raise Unsupported(reason)
    progs = programs(gl, SHADERS)
    mgl, ctx = gl.mgl, gl.ctx
    w, h = size = (scene["viewport"]["width"], scene["viewport"]["height"])
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    persp = bool(np.array_equal(proj[3], [0, 0, -1, 0]))
    owned = []

    def tex(comps, dtype):
        t = ctx.texture(size, comps, dtype=dtype)
        t.filter = (mgl.NEAREST, mgl.NEAREST)
        owned.append(t)
        return t

    def fbo(colors, depth=None):
        f = ctx.framebuffer(color_attachments=colors, depth_attachment=depth)
        owned.insert(0, f)
        return f

    try:
        ctx.viewport = (0, 0, *size)
        # 1. rear hulls
        rear, hull = tex(1, "f4"), tex(1, "i4")
        dep0 = gl._depth_attachment(size)
        owned.append(dep0)
        f = fbo([rear, hull], dep0)
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
        # 2. seeds
        recs = [tex(4, "f4"), tex(4, "f4")]
        flr = [tex(4, "f4"), tex(4, "f4")]         # (m_f, n_x, n_y) with the floor constraint
        fb_rec = [fbo([recs[0], flr[0]]), fbo([recs[1], flr[1]])]
        floor = opt["floor_normal"] is not None
        prog = progs["seed"]
        fb_rec[0].use()
        rear.use(0)
        hull.use(1)
        gl._set(prog, "u_rear", 0)
        gl._set(prog, "u_hull", 1)
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
            gl._write(prog, "u_inv_proj", np.linalg.inv(proj))
        fullscreen(gl, prog)
        # 3. jump flooding
        steps = step_schedule(h, w, opt["variant"])
        if "schedule_truncated" in gl.faults:   # planted fault: the last passes left out
            steps = steps[:max(1, len(steps) - TRUNCATED_PASSES)]
        dtex = tex(1, "f4")
        fb_d = fbo([dtex])
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
        # 4. D_dil and the cut normals
        prog = progs["dilate"]
        gl._set(prog, "u_d", 0)
        gl._write(prog, "u_inv_proj", np.linalg.inv(proj))
        gl._set(prog, "u_perspective", persp)
        if opt["dilation"]:
            ddil = tex(1, "f4")
            fbo([ddil]).use()
            dtex.use(0)
            gl._set(prog, "u_normals", False)
            fullscreen(gl, prog)
        else:
            ddil = dtex
        cutn = tex(4, "f4")
        fbo([cutn]).use()
        ddil.use(0)
        gl._set(prog, "u_normals", True)
        fullscreen(gl, prog)
        # 5. the clipped G-buffer
        targets = [tex(1, "f4"), tex(1, "f4"), tex(4, "f4"), tex(4, "f4"), tex(4, "f4"),
                   tex(4, "i4"), tex(1, "i4")]
        dep = gl._depth_attachment(size)
        owned.append(dep)
        f = fbo(targets, dep)
        f.use()
        f.clear(0.0, 0.0, 0.0, 0.0, depth=float(scene["raster"]["clear_depth"]))
        gl._state(scene)
        prog = progs["gbuffer"]
        shading = scene["shading"]
        gl._set(prog, "u_light", tuple(float(shading[k]) for k in
                                       ("ambient", "diffuse", "specular", "shininess")))
        gl._set(prog, "u_smooth", scene["raster"]["normals"] == "smooth")
        gl._set(prog, "u_viewport", (float(w), float(h)))
        gl._set(prog, "u_dilation", opt["dilation"])
        dtex.use(0)
        ddil.use(1)
        cutn.use(2)
        for name, unit in (("u_D", 0), ("u_D_dil", 1), ("u_cut_normal", 2)):
            gl._set(prog, name, unit)
        palette = shading["palette"]
        sec = set(opt["secondary"])
        for i in opt["secondary"] + opt["interest"]:
            d = draws[i]
            if not d["n_faces"]:
                continue
            gl._write(prog, "u_mvp", d["mvp"])
            gl._write(prog, "u_mv", d["mv"])
            gl._write(prog, "u_nmat", d["nmat"])
            gl._set(prog, "u_object", int(d["object_id"]))
            gl._set(prog, "u_secondary", i in sec)
            gl._set(prog, "u_base", tuple(float(c) for c in
                                          palette[d["object_id"] % len(palette)]))
            gl._vao(d, prog).render(mgl.TRIANGLES)
        ctx.finish()
        out, covered = gl._read_gbuffer(scene, targets, size)
        cut = gl._read(targets[6], "<i4", 1, size)[..., 0]
        d_ndc = gl._read(dtex, "<f4", 1, size)[..., 0]
        # 6. ghost lines
        ghost = np.zeros((h, w), np.float32)
        g_max = opt["ghost_distance"]
        if g_max is None:
            g_max = 0.1 * _diagonal(package_dir, scene, opt["secondary"])
        interest_ids = {int(draws[i]["object_id"]) for i in opt["interest"]}
        carved = bool(opt["secondary"])   # refraster draws lines only if something was carved
        if g_max > 0 and carved:
            segs = []
            for i in opt["secondary"]:
                dd = scene["draws"][i]
                v, fc, _ = read_ply(package_dir / dd["mesh"], dd.get("n_vertices"),
                                    dd.get("n_faces"))
                segs.append(feature_segments(v, fc, view, matrix(dd["model"], "model"),
                                             not persp, float(opt["crease_angle"])))
            seg = np.concatenate(segs) if segs else np.zeros((0, 2, 3))
            if len(seg):
                # where covered, object_id and depth are the ids and window depth read back
                ooi = covered & np.isin(out["object_id"], list(interest_ids))
                occ = np.where(ooi, 2.0 * out["depth"] - 1.0, 2.0).astype(np.float32)
                occ_tex = ctx.texture(size, 1, np.ascontiguousarray(occ[::-1]).tobytes(),
                                      dtype="f4")
                owned.append(occ_tex)
                occ_tex.filter = (mgl.NEAREST, mgl.NEAREST)
                gtex = tex(1, "f4")
                fg = fbo([gtex])
                fg.use()
                fg.clear(0.0, 0.0, 0.0, 0.0)
                ctx.enable_only(mgl.BLEND)
                ctx.blend_equation = mgl.MAX
                ctx.blend_func = mgl.ONE, mgl.ONE
                prog = progs["ghost"]
                gl._write(prog, "u_mvp", (proj @ view).astype(np.float32))
                dtex.use(0)
                occ_tex.use(1)
                gl._set(prog, "u_D", 0)
                gl._set(prog, "u_occluder", 1)
                gl._set(prog, "u_g_max", float(g_max))
                gl._set(prog, "u_fade", opt["ghost_fade"])
                gl._set(prog, "u_p", (float(proj[2, 2]), float(proj[2, 3]), float(proj[3, 2]),
                                      float(proj[3, 3])))
                vbo = ctx.buffer(np.ascontiguousarray(seg.reshape(-1, 3), np.float32).tobytes())
                owned.insert(0, vbo)
                vao = ctx.vertex_array(prog, [(vbo, "3f", "in_pos")])
                owned.insert(0, vao)
                vao.render(mgl.LINES)
                ctx.blend_equation = mgl.FUNC_ADD
                ctx.disable(mgl.BLEND)
                ctx.finish()
                ghost = gl._read(gtex, "<f4", 1, size)[..., 0]
    finally:
        gl._parking.use()
        for obj in owned:
            obj.release()
    out["cutaway_depth"] = (np.float32(0.5) * d_ndc + np.float32(0.5)).astype(np.float32)
    out["cut_mask"] = covered & (cut == 1)
    out["ghost"] = np.ascontiguousarray(ghost, np.float32)
    return out


def _diagonal(package_dir, scene, indices):
    vs = []
    for i in indices:
        d = scene["draws"][i]
        v, _, _ = read_ply(package_dir / d["mesh"], d.get("n_vertices"), d.get("n_faces"))
        vs.append(v.astype(np.float64))
    if not vs:
        return 0.0
    v = np.concatenate(vs)
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
