"""Volumetric halos for surfaces in 4D (Wang et al. 2013) on the GPU for refraster.gl, from a
scene package's maps and ``parameters`` alone (``docs/golden-schema.md``, technique
``halos4d``).

On the CPU (NumPy, as a GPU team's per-frame setup): the 4D rotation and projection of the
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

import math

import numpy as np

from .common import Unsupported, fullscreen, programs
from .package import PackageError, read_map

__all__ = ["supports", "prepare", "render_halos"]

RHO_FRACTION = 0.02
NORMAL_EPS = 1e-6
AMBIENT = 0.3
DELTA_MIN = 1e-3
MAX_SLICES = 4096
SPLITS = ("paper", "global_index")


def _num(p, key, lo=None, hi=None, default=None):
    v = p.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or (lo is not None and v < lo) or (hi is not None and v > hi):
        raise PackageError(f"parameters.{key} must be a finite number"
                           + (f" in [{lo}, {hi}]" if lo is not None and hi is not None else ""))
    return float(v)


def options(scene):
    p = scene.get("parameters", {})
    if not isinstance(p, dict):
        raise PackageError("parameters must be an object")
    for key in ("stereo", "boundary_color"):
        if p.get(key):
            return None, f"halos4d parameter {key!r} is not implemented by the gl backend"
    opt = {}
    if p.get("projection") not in ("orthographic", "perspective"):
        raise PackageError("parameters.projection must be 'orthographic' or 'perspective'")
    opt["projection"] = p["projection"]
    slices = p.get("slices")
    if isinstance(slices, bool) or not isinstance(slices, int) or not 1 <= slices <= MAX_SLICES:
        raise PackageError(f"parameters.slices must be an integer in 1..{MAX_SLICES}")
    opt["slices"] = slices
    for key in ("width", "height"):
        v = p.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 32768:
            raise PackageError(f"parameters.{key} must be an integer in 1..32768")
        opt[key] = v
    opt["delta_t"] = _num(p, "delta_t", 0.0, 1.0)
    opt["surface_width"] = _num(p, "surface_width", 0.0, 1.0)
    opt["opacity"] = _num(p, "opacity", 0.0, 1.0)
    opt["delta_d"] = _num(p, "delta_d", 0.0, None)
    opt["antialias"] = _num(p, "antialias", 0.0, 1.0, default=opt["surface_width"])
    opt["halo_opacity"] = _num(p, "halo_opacity", 0.0, 1.0, default=0.0)
    opt["scale"] = _num(p, "scale", 0.0, None, default=1.0)
    opt["eye"] = None if p.get("eye") is None else _num(p, "eye")
    opt["rho"] = None if p.get("rho") is None else _num(p, "rho", 0.0, None)
    opt["depth_eps"] = None if p.get("depth_eps") is None else _num(p, "depth_eps", 0.0, None)
    halos = p.get("halos", True)
    if not isinstance(halos, bool):
        raise PackageError("parameters.halos must be true or false")
    opt["halos"] = halos
    hc = p.get("halo_color", [0.5, 0.5, 0.5])
    bg = p.get("background", [0.0, 0.0, 0.0])
    for key, v in (("halo_color", hc), ("background", bg)):
        if not (isinstance(v, list) and len(v) == 3
                and all(isinstance(c, (int, float)) and math.isfinite(c) for c in v)):
            raise PackageError(f"parameters.{key} must be 3 finite numbers")
    opt["halo_color"], opt["background"] = [float(c) for c in hc], [float(c) for c in bg]
    try:
        rot = np.array(p.get("rotation", np.eye(4).tolist()), np.float64)
    except (TypeError, ValueError):
        rot = None
    if rot is None or rot.shape != (4, 4) or not np.all(np.isfinite(rot)) \
            or not np.allclose(rot @ rot.T, np.eye(4), atol=1e-9, rtol=0):
        raise PackageError("parameters.rotation must be an orthogonal 4x4 matrix")
    opt["rotation"] = rot
    sb = p.get("screen_bounds")
    if sb is not None:
        try:
            sb = np.array(sb, np.float64)
        except (TypeError, ValueError):
            sb = None
        if sb is None or sb.shape != (2, 3) or not np.all(np.isfinite(sb)) \
                or not np.all(sb[1] > sb[0]):
            raise PackageError("parameters.screen_bounds must be [[x0, y0, z0], [x1, y1, z1]]")
    opt["screen_bounds"] = sb
    split = p.get("split", "paper")
    if split not in SPLITS:
        raise PackageError(f"parameters.split must be one of {list(SPLITS)}")
    opt["split"] = split
    return opt, None


def supports(scene):
    try:
        _, reason = options(scene)
    except PackageError as exc:
        return f"halos4d: {exc}"
    return reason


def prepare(vertices4d, faces, tangents, colors, opt):
    """Project, thicken and tetrahedralize (float64) → ``(points (2V + 2K, 3), attr (2V + 2K, 5)
    = (δ, t, r, g, b), tets (T, 4), projected points (V, 3))``, K the vertices inserted by the
    paper's split."""
    f = np.asarray(faces, np.int64)
    f = f[~((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2]))]
    if len(f) == 0:
        raise PackageError("surface has no non-degenerate faces")
    r = opt["rotation"]
    v = np.asarray(vertices4d, np.float64) @ r.T
    t = np.asarray(tangents, np.float64).reshape(len(v), 2, 4) @ r.T
    radius = float(np.abs(v).max()) if v.size else 1.0
    e = 3.0 * max(radius, 1.0 / 3.0) if opt["eye"] is None else opt["eye"]
    depth = e - v[:, 3]
    s = opt["scale"]
    if opt["projection"] == "orthographic":
        pts, t3 = s * v[:, :3], s * t[..., :3]
    else:
        if e <= 0 or np.any(depth <= DELTA_MIN * e):
            raise PackageError("a vertex is at or behind the 4D eye")
        fl = s * e
        pts = fl * v[:, :3] / depth[:, None]
        t3 = fl * (t[..., :3] * depth[:, None, None] + v[:, None, :3] * t[..., 3:4]) \
            / (depth ** 2)[:, None, None]
    n = np.cross(t3[:, 0], t3[:, 1])
    ln = np.linalg.norm(n, axis=1)
    sc = np.linalg.norm(t3[:, 0], axis=1) * np.linalg.norm(t3[:, 1], axis=1)
    bad = ~(ln > NORMAL_EPS * sc) | (sc == 0.0)
    normals = np.zeros_like(n)
    normals[~bad] = n[~bad] / ln[~bad, None]
    if bad.any():
        a = pts[f[:, 0]]
        fn = np.cross(pts[f[:, 1]] - a, pts[f[:, 2]] - a)
        acc = np.zeros_like(pts)
        for k in range(3):
            np.add.at(acc, f[:, k], fn)
        fb = acc[bad]
        lf = np.linalg.norm(fb, axis=1)
        ok = lf > 0
        fb[ok] /= lf[ok, None]
        fb[~ok] = (0.0, 0.0, 1.0)
        normals[bad] = fb
    rho = opt["rho"]
    if rho is None:
        diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        rho = RHO_FRACTION * diag if diag > 0 else 1.0
    verts = np.concatenate([pts - rho * normals, pts + rho * normals])
    tt = np.concatenate([np.zeros(len(pts)), np.ones(len(pts))])
    shade = AMBIENT + (1.0 - AMBIENT) * np.abs(normals[:, 2])
    rgb = np.asarray(colors, np.float64) * shade[:, None]
    attr = np.column_stack([np.concatenate([depth, depth]), tt, np.concatenate([rgb, rgb])])
    nv = len(pts)
    if opt.get("split", "paper") == "global_index":
        srt = np.sort(f, axis=1)
        a, b, c = srt[:, 0], srt[:, 1], srt[:, 2]
        tets = np.stack([np.stack([a, b, c, c + nv], 1), np.stack([a, b, c + nv, b + nv], 1),
                         np.stack([a, a + nv, b + nv, c + nv], 1)], 1).reshape(-1, 4)
        return verts, attr, tets, pts, rho
    tets, cyc = _paper_split(f, nv)
    if len(cyc):
        def centroids(x):
            lo = (x[cyc[:, 0]] + x[cyc[:, 1]] + x[cyc[:, 2]]) / 3.0
            hi = (x[cyc[:, 0] + nv] + x[cyc[:, 1] + nv] + x[cyc[:, 2] + nv]) / 3.0
            return np.concatenate([x, lo, hi])
        verts, attr = centroids(verts), centroids(attr)
    return verts, attr, tets, pts, rho


def _apex(a, b, c, a1, b1, c1, cb):
    """Prisms whose lower vertex a starts the diagonals to b⁺ and c⁺; side (b, c) split b–c⁺, or
    c–b⁺ where ``cb``: (F, 3, 4)."""
    t0 = np.where(cb[:, None], np.stack([a, b, c, b1], 1), np.stack([a, b, c, c1], 1))
    t1 = np.where(cb[:, None], np.stack([a, b1, c, c1], 1), np.stack([a, b, c1, b1], 1))
    return np.stack([t0, t1, np.stack([a, a1, b1, c1], 1)], 1)


def _paper_split(f, nv):
    """Wang et al. Sec. 4.4/5.1: each prism in its face's order (diagonals v0–v1⁺, v1–v2⁺,
    v0–v2⁺), each later prism's diagonal on a shared side flipped to the first prism's, a
    cyclic prism rebuilt as (m, v_k, v_k+1) with its triangles' centroids m, m⁺ (numbered
    2·nv + k and 2·nv + K + k). Returns (tets, the rebuilt prisms' faces)."""
    d = np.zeros((len(f), 3), np.int64)
    d[:, 2] = 1                                  # 0: side k split v_k → v_k+1⁺; 1: the other
    nxt = np.roll(f, -1, axis=1)
    start = np.where(d == 0, f, nxt).ravel()
    key = (np.minimum(f, nxt) * np.int64(nv) + np.maximum(f, nxt)).ravel()
    order = np.lexsort((np.arange(key.size), key))
    first = np.ones(key.size, bool)
    first[1:] = key[order][1:] != key[order][:-1]
    head = order[np.maximum.accumulate(np.where(first, np.arange(key.size), 0))]
    flip = order[start[order] != start[head]]
    d.reshape(-1)[flip] ^= 1
    cyc = (d[:, 0] == d[:, 1]) & (d[:, 1] == d[:, 2])
    ok, cy = np.flatnonzero(~cyc), np.flatnonzero(cyc)
    apex = np.argmax((d[ok] == 0).astype(np.int64) + (np.roll(d[ok], 1, axis=1) == 1), axis=1)
    abc = f[ok[:, None], (apex[:, None] + np.arange(3)) % 3]
    valid = _apex(*abc.T, *(abc + nv).T, d[ok, (apex + 1) % 3] == 1)
    m = 2 * nv + np.arange(len(cy), dtype=np.int64)
    rebuilt = np.concatenate([_apex(m, f[cy, k], f[cy, (k + 1) % 3], m + len(cy),
                                    f[cy, k] + nv, f[cy, (k + 1) % 3] + nv, d[cy, k] == 1)
                              for k in range(3)], axis=1)
    count = np.where(cyc, 9, 3)
    offset = np.concatenate([[0], np.cumsum(count)])
    tets = np.zeros((int(offset[-1]), 4), np.int64)
    tets[(offset[ok][:, None] + np.arange(3)).ravel()] = valid.reshape(-1, 4)
    tets[(offset[cy][:, None] + np.arange(9)).ravel()] = rebuilt.reshape(-1, 4)
    return tets, f[cy]


def _screen_bounds(points, width, height, margin):
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo[:2] + hi[:2])
    half = 0.5 * (hi[:2] - lo[:2]) * (1.0 + 2.0 * margin)
    half = np.maximum(half, 1e-9 * max(1.0, float(np.abs(hi).max())))
    if half[0] / half[1] < width / height:
        half[0] = half[1] * width / height
    else:
        half[1] = half[0] * height / width
    zlo, zhi = lo[2], hi[2]
    if not zhi > zlo:
        zlo, zhi = zlo - 0.5, zhi + 0.5
    return np.array([[centre[0] - half[0], centre[1] - half[1], zlo],
                     [centre[0] + half[0], centre[1] + half[1], zhi]])


#: The programs (vertex, geometry, fragment shader), compiled by refraster.gl.common.programs.
SHADERS = {
    "depth": ("halo_slice.vert", "halo_slice.geom", "halo_depth.frag"),
    "surface": ("halo_slice.vert", "halo_slice.geom", "halo_surface.frag"),
    "resolve": ("fullscreen.vert", None, "halo_resolve.frag"),
}


def render_halos(gl, loaded, package_dir):
    scene = loaded["scene"]
    opt, reason = options(scene)
    if reason is not None:
        raise Unsupported(reason)
    v4 = read_map(package_dir, scene, "surface_vertices4d")
    faces = read_map(package_dir, scene, "surface_faces")
    tang = read_map(package_dir, scene, "surface_tangents")
    cols = read_map(package_dir, scene, "surface_colors")
    nv = len(v4)
    if v4.ndim != 2 or v4.shape[1] != 4 or faces.ndim != 2 or faces.shape[1] != 3 \
            or tang.shape != (nv, 8) or cols.shape != (nv, 3) \
            or not np.issubdtype(faces.dtype, np.integer) \
            or (faces.size and (faces.min() < 0 or faces.max() >= nv)):
        raise PackageError("halos4d maps: vertices (V, 4), faces (F, 3) in range, tangents "
                           "(V, 8), colours (V, 3)")
    verts, attr, tets, pts, rho = prepare(v4, faces, tang, cols, opt)
    w, h = opt["width"], opt["height"]
    vw, vh = scene["viewport"]["width"], scene["viewport"]["height"]
    if (w, h) != (vw, vh):
        raise PackageError(f"parameters.width/height {(w, h)} differ from the viewport")
    bounds = opt["screen_bounds"]
    if bounds is None:
        bounds = _screen_bounds(verts, w, h, float(scene["parameters"].get("margin", 0.05)))
    n = opt["slices"]
    dz = (bounds[1, 2] - bounds[0, 2]) / n
    centres = bounds[0, 2] + (np.arange(n) + 0.5) * dz
    ws, aa = opt["surface_width"], opt["antialias"]

    def slice_alpha(opacity, width_):
        if opacity >= 1.0:
            return 1.0
        return float(1.0 - (1.0 - opacity) ** (dz / (2.0 * width_ * rho)))
    alpha = slice_alpha(opt["opacity"], ws)
    halo_alpha = (slice_alpha(opt["halo_opacity"], max(1.0 - ws - aa, 1e-6))
                  if opt["halos"] and opt["halo_opacity"] > 0 else 0.0)
    depth = attr[:, 0]
    eps = 1e-6 * float(np.abs(depth).max()) if opt["depth_eps"] is None else opt["depth_eps"]
    d_ref = float(0.5 * (depth.min() + depth.max()))
    rel = attr.copy()
    rel[:, 0] -= d_ref
    # x, y into the NDC of glOrtho(x0, x1, y0, y1)
    sx, sy = 2.0 / (bounds[1, 0] - bounds[0, 0]), 2.0 / (bounds[1, 1] - bounds[0, 1])
    span = bounds[1, :2] - bounds[0, :2]
    mid = (bounds[1, :2] + bounds[0, :2]) / span
    xy = np.stack([sx * verts[:, 0] - mid[0], sy * verts[:, 1] - mid[1]], 1)
    # z relative to the first centre keeps float32 steps fine
    z0 = float(centres[0])
    data = np.concatenate([xy, (verts[:, 2] - z0)[:, None], rel], 1).astype(np.float32)
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
        gl._set(ps, "u_d_range", (float(rel[:, 0].min()) - 1e-6, float(rel[:, 0].max()) + 1e-6))
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
            c = float(centres[k] - z0)
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
