"""Allowances of clip-surface scenes ("Goldens with teeth (2)", item 1): the clip decision and
the caps bounded by their own arithmetic.

What ``render_clipped`` shows at a pixel is the nearest *kept* fragment of the draw list
``solids + caps`` (cap of solid m and surface k = draw ``M + m·K + k``): a solid fragment is
kept iff ``g(P) ≥ 0`` for every enabled surface (Eq. 1, MATH.md §1.1); a cap fragment iff the
volumetric parity test of its solid's sprite says inside (MATH.md §2.2) and no other surface
clips it. A conformant GPU may differ in

* **which faces cover the centre and their depth** — plain rendering's ε and float32 slack
  (:func:`refraster.golden.allowances.layers.covering_entries`, hidden faces included);
* **the clip decision** — only where ``|g|`` is within
  (a) Eq. 1 in float32: ``δ_a = 16·2⁻²⁴·(|P| + |O| + |Sz|)`` (P interpolated in float32, the dot
  product and the sum rounded),
  (b) the offset-map lookup: ``GL_LINEAR`` with 8-bit fixed-point weights (each weight off by
  ≤ 1/512, so the value by ≤ Δ/256 with Δ the largest difference of two adjacent texels),
  unorm16 or float32 texels (≤ ½/65535) and float32 texture coordinates (``s·W`` off by
  ≤ 4·2⁻²⁴·|s|·W texels, times Δ per texel): ``δ_b = |Sz|·(Δ/256 + ½/65535 + 4·2⁻²⁴·(|s|·W + |t|·H)·Δ)``,
  (c) the sample position: ``g`` at the pixel centre and the corners of the ε-square, its
  spread widened by 1.5 (second-order margin, as plain rendering's values);
* **cap parity** — only where the parity test at the cap point differs from that at a point one
  sprite texel away along an axis or at a corner of the ε-square (within a texel of a sprite
  layer or of where the layer count or depth changes).

Per pixel the golden stores the entries (face, window-depth interval, facing) that *may win*:
those that may be kept and whose least depth is not behind the farthest the nearest surely
covering, surely kept entry can be; and whether the background may show (no entry surely
covers and is surely kept). The check ``clip`` names the candidate's entry by its own
``(object_id, prim_id)`` and holds ``depth``, ``front_facing`` and ``cap_mask`` to it.
"""

from __future__ import annotations

import numpy as np

from .conventions import FACES_FLIPPED

__all__ = ["clip_allowances", "clip_outside", "clip_allowed", "CLIP_ARRAYS", "CLIP_BUFFERS",
           "CLIP_VALUES"]

F32 = 2.0 ** -24
CLIP_ARRAYS = ("cs_offsets", "cs_face", "cs_depth_lo", "cs_depth_hi", "cs_eye_lo", "cs_eye_hi",
               "cs_facing", "cs_flag", "cs_bg", "cs_draw_offsets")
#: the buffers the check covers; the mask buffer (``cap_mask``, ``cut_mask``) must equal the
#: named entry's ``cs_flag`` (1: a cap face, a back face of a secondary object; 0: not; −1:
#: either, a sliver whose facing may flip)
CLIP_BUFFERS = ("prim_id", "object_id", "depth", "eye_depth", "front_facing", "cap_mask",
                "cut_mask")


def _surfaces(scene):
    from ...clipsurface import ClipSurface
    out = []
    for s in scene.parameters["surfaces"]:
        om = scene.maps[s["offset_map"]] if s.get("offset_map") else None
        out.append(ClipSurface(s["origin"], s["u"], s["v"], s["scale"], om,
                               wrap=s.get("wrap", "repeat"), enabled=s.get("enabled", True)))
    return out


def _lookup_error(surface, points):
    """δ_b of the module docstring at ``points``."""
    om = getattr(surface, "offset_map", None)
    sz = abs(float(surface.scale[2]))
    if om is None or sz == 0.0:
        return np.zeros(len(points))
    om = np.asarray(om, np.float64)
    if om.ndim == 1:
        om = om[None, :]
    h, w = om.shape[:2]
    jump = 0.0
    if w > 1:
        jump = max(jump, float(np.abs(np.diff(om, axis=1)).max()))
    if h > 1:
        jump = max(jump, float(np.abs(np.diff(om, axis=0)).max()))
    # wrap seams count as neighbours too
    jump = max(jump, float(np.abs(om[:, 0] - om[:, -1]).max()),
               float(np.abs(om[0, :] - om[-1, :]).max()))
    u = np.asarray(surface.u, np.float64)
    v = np.asarray(surface.v, np.float64)
    d = points - np.asarray(surface.origin, np.float64)
    s = np.abs(d @ (u / np.linalg.norm(u))) / np.linalg.norm(u) * abs(float(surface.scale[0]))
    t = np.abs(d @ (v / np.linalg.norm(v))) / np.linalg.norm(v) * abs(float(surface.scale[1]))
    return sz * (jump / 256.0 + 0.5 / 65535.0 + 4.0 * F32 * (s * w + t * h) * jump)


def clip_allowances(scene, raster, eps, eye_budget):
    """The ``cs_*`` arrays of a clip-surface scene (see the module docstring)."""
    from ...clipsurface import clip_function
    from ...clipsurface.render import _cached_cap, _solid_tests
    from ...ldi import VolumetricDepthSprite
    from ...mesh import Mesh, bounds
    from ...raster.fragments import vertices_in
    from .layers import covering_entries
    p = scene.parameters
    cam = scene.camera
    h, w = cam.height, cam.width
    surfaces = _surfaces(scene)
    solids = [d.mesh for d in scene.draws]
    models = [np.asarray(d.model, np.float64) for d in scene.draws]
    world = [Mesh(v, s.faces) for s, v in zip(solids, vertices_in(solids, models, None,
                                                                   "world"))]
    n_solids, n_surf = len(solids), len(surfaces)
    tests = _solid_tests(world, None, int(p.get("vds_resolution", 1024)))
    draws, draw_models = list(solids), list(models)
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    for m, wm in enumerate(world):
        box = bounds(wm.vertices)
        sprite = tests[m] if isinstance(tests[m], VolumetricDepthSprite) else None
        for s in surfaces:
            cap, _ = _cached_cap(s, box, int(p.get("subdivision", 1)), sprite) \
                if s.enabled else (None, None)
            draws.append(empty if cap is None else cap)
            draw_models.append(np.eye(4))
    prep, pix, faces, sure, fragile, lo, hi, beta = covering_entries(
        draws, draw_models, cam, raster["cull"], eps, with_beta=True)
    offs = np.asarray(prep.face_offsets, np.int64)
    draw = np.searchsorted(offs[1:], faces, side="right")
    # world position of each entry at the centre and the corners of the ε-square
    wv = vertices_in(prep.meshes, prep.models, None, "world")
    verts = np.concatenate([np.asarray(v, np.float64) for v in wv]) if wv else np.zeros((0, 3))
    vbase = np.cumsum([0] + [len(v) for v in wv])
    local = faces - offs[draw]
    tri = np.stack([np.asarray(prep.meshes[d].faces)[f] for d, f in zip(draw, local)]) \
        if len(faces) else np.zeros((0, 3), np.int64)
    tri = tri + vbase[draw][:, None]
    pts = np.einsum("esk,ekc->esc", np.nan_to_num(beta), verts[tri])       # (E, 5, 3)
    region = None
    if p.get("decision_offset") is not None:
        # a multisampled scene at pixel rate, derived on the scene moved to one sample
        # (allowances/samples.py): the decision is taken at the pixel centre, offset from
        # this scene's pixel centre, not where the sample's coverage is
        pts = _points_at(cam, pix, verts[tri], p["decision_offset"], eps)
        if p.get("decision_point") == "centroid":
            # at any point of the pixel (offset) ∩ the triangle, both grown by ε
            from .homogeneous import pixel_triangle
            clip_v = prep.clip[prep.triangles.faces[faces]].astype(np.float64)
            poly, ok = pixel_triangle(clip_v, pix, w, h, eps, p["decision_offset"])
            region = (_window_to_plane(cam, poly, verts[tri]), ok)
            own = _points_at(cam, pix, verts[tri], (0.0, 0.0), 0.0)[:, 0]
    state = np.full(len(faces), 2, np.int8)     # 0 never kept, 1 may be, 2 surely
    is_cap = draw >= n_solids
    # solids: the clip decision of every enabled surface
    sol = np.flatnonzero(~is_cap)
    for s in surfaces:
        if not s.enabled or not len(sol):
            continue
        if region is not None:
            st = _region_state(s, region[0][sol], region[1][sol])
            state[sol] = np.minimum(state[sol], st)
            continue
        q = pts[sol].reshape(-1, 3)
        g = clip_function(q, s).reshape(len(sol), 5)
        c = g[:, 0]
        g_lo = c - 1.5 * (c - g.min(axis=1))
        g_hi = c + 1.5 * (g.max(axis=1) - c)
        centre = pts[sol, 0]
        delta = (16.0 * F32 * (np.linalg.norm(centre, axis=1)
                               + float(np.linalg.norm(s.origin)) + abs(float(s.scale[2])))
                 + _lookup_error(s, centre))
        st = np.where(g_lo > delta, 2, np.where(g_hi < -delta, 0, 1)).astype(np.int8)
        state[sol] = np.minimum(state[sol], st)
    # caps: parity at the cap point, at the ε-square's corners and one sprite texel away
    caps = np.flatnonzero(is_cap)
    if len(caps):
        m_of = (draw[caps] - n_solids) // max(n_surf, 1)
        k_of = (draw[caps] - n_solids) % max(n_surf, 1)
        for m in range(n_solids):
            sel = caps[m_of == m]
            if not len(sel):
                continue
            t = tests[m]
            texel = float(getattr(t, "texel_size", 0.0))
            probes = [pts[sel, j] for j in range(5)]
            for axis in range(3):
                for sign in (-1.0, 1.0):
                    probes.append(pts[sel, 0] + sign * texel * np.eye(3)[axis])
            if region is not None:
                # the polygon's vertices and centre, each and one texel away
                poly, ok = region[0][sel], region[1][sel]
                has = ~np.isnan(poly[:, :, 0])
                centre = np.nansum(poly, axis=1) / np.maximum(has.sum(axis=1), 1)[:, None]
                base = [np.where(has[:, j, None], poly[:, j], centre)
                        for j in range(poly.shape[1])] + [centre]
                # and the sample itself (this scene's centre: inside both when covered),
                # the point refraster and llvmpipe pick where the primitive covers it alone
                base.append(own[sel])
                probes = list(base)
                for q0 in base:
                    for axis in range(3):
                        for sign in (-1.0, 1.0):
                            probes.append(q0 + sign * texel * np.eye(3)[axis])
            inside = np.stack([t.contains(q) for q in probes], axis=1)
            st = np.where(inside.all(axis=1), 2, np.where(~inside.any(axis=1), 0, 1))
            if region is not None:
                st = np.where(region[1][sel], st, 1)
            state[sel] = np.minimum(state[sel], st.astype(np.int8))
        # a cap is clipped by the other surfaces as a solid fragment is
        for k, s in enumerate(surfaces):
            sel = caps[(k_of != k)] if n_surf > 1 else np.zeros(0, np.int64)
            if not s.enabled or not len(sel):
                continue
            g = clip_function(pts[sel, 0], s)
            delta = 16.0 * F32 * (np.linalg.norm(pts[sel, 0], axis=1) + abs(float(s.scale[2]))) \
                + _lookup_error(s, pts[sel, 0])
            st = np.where(g > delta, 2, np.where(g < -delta, 0, 1)).astype(np.int8)
            if region is not None:
                st = _region_state(s, region[0][sel], region[1][sel])
            state[sel] = np.minimum(state[sel], st)
    return _winners(prep, pix, faces, sure, fragile, lo, hi, state, is_cap, h, w, eye_budget)


def _points_at(cam, pix, tri, offset, eps):
    """World points ``(E, 5, 3)`` of each entry's triangle plane (``tri`` ``(E, 3, 3)`` world)
    seen through pixel ``pix`` (flat, row 0 at the top) at the window offset ``offset``
    (pixels, GL window y up) from its centre and at the corners of the ε-square around that
    point: the ray through the window point met with the plane, in float64."""
    h, w = cam.height, cam.width
    inv = np.linalg.inv(np.asarray(cam.proj, np.float64) @ np.asarray(cam.view, np.float64))
    r, c = np.divmod(np.asarray(pix, np.int64), w)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros((len(pix), 5, 3))
    for j, (dx, dy) in enumerate(((0.0, 0.0), (-eps, -eps), (eps, -eps), (-eps, eps),
                                  (eps, eps))):
        x = c + 0.5 + offset[0] + dx
        y = (h - 1 - r) + 0.5 + offset[1] + dy
        ndc = np.stack([2.0 * x / w - 1.0, 2.0 * y / h - 1.0], -1)
        ends = []
        for z in (-1.0, 1.0):
            q = np.concatenate([ndc, np.full((len(pix), 1), z), np.ones((len(pix), 1))], 1) @ inv.T
            ends.append(q[:, :3] / q[:, 3:])
        o, d = ends[0], ends[1] - ends[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ec,ec->e", tri[:, 0] - o, n) / np.einsum("ec,ec->e", d, n)
        out[:, j] = o + np.nan_to_num(t)[:, None] * d
    return out


def _window_to_plane(cam, poly, tri):
    """World points ``(E, K, 3)`` of window points ``poly`` ``(E, K, 2)`` (pixels, GL window y
    up; NaN kept) on each entry's triangle plane (``tri`` ``(E, 3, 3)`` world): the ray through
    the window point met with the plane, in float64. A projective map keeps lines, so a convex
    window polygon maps to the convex world polygon of its vertices' images."""
    h, w = cam.height, cam.width
    inv = np.linalg.inv(np.asarray(cam.proj, np.float64) @ np.asarray(cam.view, np.float64))
    e, k = poly.shape[:2]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ndc = np.stack([2.0 * poly[..., 0] / w - 1.0, 2.0 * poly[..., 1] / h - 1.0], -1)
    ends = []
    for z in (-1.0, 1.0):
        q = np.concatenate([ndc, np.full((e, k, 1), z), np.ones((e, k, 1))], -1) @ inv.T
        ends.append(q[..., :3] / q[..., 3:])
    o, d = ends[0], ends[1] - ends[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ekc,ec->ek", tri[:, None, 0] - o, n) / np.einsum("ekc,ec->ek", d, n)
    return o + t[..., None] * d


def _map_range(surface, s_lo, s_hi, t_lo, t_hi):
    """Per entry, the range ``(lo, hi)`` of ``GL_LINEAR``'s value of ``surface``'s offset map
    over the texture-coordinate box ``[s_lo, s_hi] × [t_lo, t_hi]``: a bilinear blend lies
    between its taps' least and largest, and the taps of every point of the box are the
    texels ``⌊s·W − ½⌋ … ⌊s_hi·W − ½⌋ + 1`` (wrapped) by the rows likewise."""
    from ...clipsurface.offsetmaps import _wrap_texel
    from ...clipsurface.surfaces import WRAP_MODES
    om = np.asarray(surface.offset_map, np.float64)
    if om.ndim == 1:
        om = om[None, :]
    rows, cols = om.shape
    mode = WRAP_MODES[surface.wrap]
    lo = np.empty(len(s_lo))
    hi = np.empty(len(s_lo))
    for e in range(len(s_lo)):
        c0, c1 = int(np.floor(s_lo[e] * cols - 0.5)), int(np.floor(s_hi[e] * cols - 0.5)) + 1
        r0, r1 = int(np.floor(t_lo[e] * rows - 0.5)), int(np.floor(t_hi[e] * rows - 0.5)) + 1
        cs = (range(cols) if c1 - c0 + 1 >= 2 * cols
              else sorted({_wrap_texel(i, cols, mode) for i in range(c0, c1 + 1)}))
        rs = (range(rows) if r1 - r0 + 1 >= 2 * rows
              else sorted({_wrap_texel(i, rows, mode) for i in range(r0, r1 + 1)}))
        block = om[np.ix_(list(rs), list(cs))]
        lo[e], hi[e] = block.min(), block.max()
    return lo, hi


def _region_state(surface, poly, ok):
    """The clip decision of ``surface`` taken at any point of each entry's convex world
    polygon ``poly`` ``(E, K, 3)`` (NaN-padded; a centroid-interpolated fragment): 2 kept
    wherever it is taken, 0 discarded wherever, 1 either. ``g = N·(P − O) + Sz·OM(s, t)``
    with the linear term and ``(s, t)`` affine in P: their ranges over the polygon are at its
    vertices; ``OM``'s range over the ``(s, t)`` box is :func:`_map_range`; plus the float32
    and lookup slack of the module docstring (δ_a, δ_b) at the polygon's vertices."""
    from ...clipsurface.surfaces import _Packed
    prm = _Packed([surface]).params[0]
    has = ~np.isnan(poly[..., 0])
    ok = ok & has.any(axis=1)
    first = np.where(np.isnan(poly[:, :1]), 0.0, poly[:, :1])
    pts = np.where(has[..., None], poly, first)
    dp = pts - prm[0:3]
    lin = dp @ prm[9:12]
    s = (dp @ prm[3:6]) / prm[12] * prm[14]
    t = (dp @ prm[6:9]) / prm[13] * prm[15]
    m_lo, m_hi = _map_range(surface, s.min(axis=1), s.max(axis=1), t.min(axis=1),
                            t.max(axis=1))
    sz = prm[16]
    g_lo = lin.min(axis=1) + np.minimum(sz * m_lo, sz * m_hi)
    g_hi = lin.max(axis=1) + np.maximum(sz * m_lo, sz * m_hi)
    norm = np.linalg.norm(pts, axis=2).max(axis=1)
    delta = (16.0 * F32 * (norm + float(np.linalg.norm(surface.origin)) + abs(float(sz)))
             + _lookup_error(surface, pts.reshape(-1, 3)).reshape(pts.shape[:2]).max(axis=1))
    st = np.where(g_lo > delta, 2, np.where(g_hi < -delta, 0, 1)).astype(np.int8)
    return np.where(ok, st, 1).astype(np.int8)


def _eye_interval(lo, hi, proj, budget):
    """Eye depth (−z_eye) over a window-depth interval: the projection's map is monotone
    (perspective ``P₂₃/(z_ndc + P₂₂)``, orthographic ``(P₂₃ − z_ndc)/P₂₂``), so its bounds are its
    values at the bounds, widened by plain rendering's float32 eye-depth budget ``(abs, rel)``
    (:data:`refraster.golden.allowances.core.EYE_DEPTH_ABS`, ``EYE_DEPTH_REL``)."""
    from ...camera import is_perspective
    eye_abs, eye_rel = budget
    proj = np.asarray(proj, np.float64)
    ends = []
    for d in (lo, hi):
        z = 2.0 * np.clip(d, 0.0, 1.0) - 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            e = (proj[2, 3] / (z + proj[2, 2]) if is_perspective(proj)
                 else (proj[2, 3] - z) / proj[2, 2])
        ends.append(e)
    e_lo = np.minimum(ends[0], ends[1])
    e_hi = np.maximum(ends[0], ends[1])
    free = ~np.isfinite(lo) | ~np.isfinite(hi) | ~np.isfinite(e_lo) | ~np.isfinite(e_hi)
    e_lo = np.where(free, -np.inf, e_lo - eye_abs - eye_rel * np.abs(e_lo))
    e_hi = np.where(free, np.inf, e_hi + eye_abs + eye_rel * np.abs(e_hi))
    lo32, hi32 = e_lo.astype(np.float32), e_hi.astype(np.float32)
    lo32 = np.where(lo32 > e_lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < e_hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def _winners(prep, pix, faces, sure, fragile, lo, hi, state, flag, h, w, eye_budget):
    """The ``cs_*`` arrays from per-entry keep states (0 never, 1 may be, 2 surely kept)."""
    from ...conformance import _face_facing
    offs = np.asarray(prep.face_offsets, np.int64)
    # which entries may win: may be kept, and not behind the nearest sure one
    zsure = np.full(h * w, np.inf)
    sure_win = sure & (state == 2)
    np.minimum.at(zsure, pix[sure_win], hi[sure_win])
    keep = (state >= 1) & (lo <= zsure[pix])
    bg = ~np.isfinite(zsure)
    pix, faces = pix[keep], faces[keep]
    offsets = np.zeros(h * w + 1, np.int64)
    np.add.at(offsets, pix + 1, 1)
    offsets = np.cumsum(offsets)
    facing = _face_facing(prep.triangles)[faces].astype(np.int8)
    facing[fragile[faces]] = -1
    lo32 = lo[keep].astype(np.float32)
    hi32 = hi[keep].astype(np.float32)
    lo32 = np.where(lo32 > lo[keep], np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi[keep], np.nextafter(hi32, np.float32(np.inf)), hi32)
    return {"cs_offsets": offsets.astype(np.int32), "cs_face": faces.astype(np.int32),
            "cs_depth_lo": lo32.astype(np.float32), "cs_depth_hi": hi32.astype(np.float32),
            "cs_facing": facing, "cs_flag": np.asarray(flag, np.int8)[keep],
            "cs_bg": bg.reshape(h, w), "cs_draw_offsets": offs.astype(np.int32),
            **dict(zip(("cs_eye_lo", "cs_eye_hi"), _eye_interval(lo[keep], hi[keep],
                                                                   prep.proj, eye_budget)))}


def cutaway_allowances(scene, raster, eps, d_lo, d_hi, eye_budget):
    """The ``cs_*`` arrays of a cutaway scene: a secondary fragment is cut iff its window depth
    is in front of D (front faces) or of the 3×3 minimum of D (back faces, with dilation);
    with D in ``[d_lo, d_hi]`` (:mod:`refraster.golden.allowances.cutaway`, window depth) and the
    minimum filter monotone, it is surely kept where its least depth is ≥ the largest cut
    depth, surely cut where its largest depth is < the least, else either. Objects of
    interest are always kept. The flag is "a back face of a secondary object" (``cut_mask``)."""
    from ...cutaway.surface import min_filter_3x3
    from .layers import covering_entries
    p = scene.parameters
    cam = scene.camera
    h, w = cam.height, cam.width
    secondary = set(p["secondary"])
    draws = list(scene.draws)
    prep, pix, faces, sure, fragile, lo, hi = covering_entries(
        [d.mesh for d in draws], [d.model for d in draws], cam, raster["cull"], eps)
    offs = np.asarray(prep.face_offsets, np.int64)
    draw = np.searchsorted(offs[1:], faces, side="right")
    is_sec = np.array([d.name in secondary for d in draws])[draw]
    facing = _face_facing_of(prep, faces, fragile)
    if raster.get(FACES_FLIPPED, False):
        # the equivalent OpenGL scene of clockwise fronts (allowances/conventions.py): its
        # front faces are the scene's back faces; the cut and the flag follow the scene's
        facing = np.where(facing >= 0, 1 - facing, facing).astype(np.int8)
    dil = bool(p.get("dilation", True))
    lim_lo = {True: np.asarray(d_lo, np.float64), False: np.asarray(d_lo, np.float64)}
    lim_hi = {True: np.asarray(d_hi, np.float64), False: np.asarray(d_hi, np.float64)}
    if dil:
        lim_lo[False] = min_filter_3x3(d_lo)
        lim_hi[False] = min_filter_3x3(d_hi)
    state = np.full(len(faces), 2, np.int8)
    for front in (True, False):
        # a sliver's facing may flip: the looser of the two limits
        sel = is_sec & ((facing == 1) if front else (facing == 0))
        cut_hi = lim_hi[front].ravel()[pix[sel]]
        cut_lo = lim_lo[front].ravel()[pix[sel]]
        state[sel] = np.where(lo[sel] >= cut_hi, 2, np.where(hi[sel] < cut_lo, 0, 1))
    sel = is_sec & (facing < 0)
    cut_hi = np.maximum(lim_hi[True], lim_hi[False]).ravel()[pix[sel]]
    cut_lo = np.minimum(lim_lo[True], lim_lo[False]).ravel()[pix[sel]]
    state[sel] = np.where(lo[sel] >= cut_hi, 2, np.where(hi[sel] < cut_lo, 0, 1))
    # a secondary back face is a cut surface; a sliver whose facing may flip may be either
    flag = np.where(is_sec & (facing < 0), -1, is_sec & (facing == 0)).astype(np.int8)
    return _winners(prep, pix, faces, sure, fragile, lo, hi, state, flag, h, w, eye_budget)


def _face_facing_of(prep, faces, fragile):
    from ...conformance import _face_facing
    f = _face_facing(prep.triangles)[faces].astype(np.int8)
    f[fragile[faces]] = -1
    return f


#: per-entry value arrays of the clip sets (issue 20, "Clip-surface and cutaway values"):
#: buffer → the arrays that bound what the entry's face shows at its pixel
CLIP_VALUES = {"barycentric": ("cs_barycentric_lo", "cs_barycentric_hi"),
               "color": ("cs_color_lo", "cs_color_hi"),
               "normal": ("cs_normal", "cs_normal_angle")}


def check_clip_arrays(arrays, height, width):
    """Raise ``ValueError`` unless the ``cs_*`` arrays (when present) are consistent."""
    if "cs_offsets" not in arrays:
        return
    missing = [k for k in CLIP_ARRAYS if k not in arrays]
    if missing:
        raise ValueError(f"the clip-surface allowance lacks {missing}")
    off = np.asarray(arrays["cs_offsets"]).astype(np.int64)
    face = np.asarray(arrays["cs_face"]).astype(np.int64)
    n = len(face)
    if off.shape != (height * width + 1,) or off[0] != 0 or off[-1] != n \
            or np.any(np.diff(off) < 0):
        raise ValueError("cs_offsets is not an offset array over the frame's pixels")
    draws = np.asarray(arrays["cs_draw_offsets"]).astype(np.int64)
    if draws.ndim != 1 or len(draws) < 2 or draws[0] != 0 or np.any(np.diff(draws) < 0):
        raise ValueError("cs_draw_offsets is not an offset array over the draw calls")
    if n and (face.min() < 0 or face.max() >= draws[-1]):
        raise ValueError("cs_face holds a face outside the scene's draws")
    for k in ("cs_depth_lo", "cs_depth_hi", "cs_eye_lo", "cs_eye_hi", "cs_facing", "cs_flag"):
        if np.asarray(arrays[k]).shape != (n,):
            raise ValueError(f"{k} does not have one entry per cs_face ({n})")
    if np.asarray(arrays["cs_bg"]).shape != (height, width):
        raise ValueError(f"cs_bg is not (H, W) = ({height}, {width})")
    if np.asarray(arrays["cs_flag"]).shape != (n,):
        raise ValueError(f"cs_flag does not have one entry per cs_face ({n})")
    for k in ("cs_facing", "cs_flag"):
        if n and not np.isin(arrays[k], (-1, 0, 1)).all():
            raise ValueError(f"{k} holds values other than -1, 0, 1")
    for k in (x for pair in CLIP_VALUES.values() for x in pair):
        want = (n,) if k == "cs_normal_angle" else (n, 3)
        if k in arrays and np.asarray(arrays[k]).shape != want:
            raise ValueError(f"{k} is not {want} (one row per cs_face entry)")
    for k in ("golden_face", "golden_object", "face_may", "face_sliver"):
        if k in arrays and np.asarray(arrays[k]).shape != (height, width):
            raise ValueError(f"{k} is not (H, W) = ({height}, {width})")


def _named(arrays, prim, obj):
    """(H, W) int64: the entry the candidate's (object_id, prim_id) names, −1 if none."""
    h, w = prim.shape
    draws = arrays["cs_draw_offsets"].astype(np.int64)
    off = arrays["cs_offsets"].astype(np.int64)
    face = arrays["cs_face"].astype(np.int64)
    prim = np.asarray(prim, np.int64)
    obj = np.asarray(obj, np.int64)
    ok = (prim >= 0) & (obj >= 0) & (obj < len(draws) - 1)
    oc = np.clip(obj, 0, len(draws) - 2)
    ok &= prim < draws[oc + 1] - draws[oc]
    g = np.where(ok, draws[oc] + prim, -1).ravel()
    if not len(face):
        return np.full((h, w), -1, np.int64)
    top = int(draws[-1]) + 1
    pix = np.repeat(np.arange(h * w, dtype=np.int64), np.diff(off))
    keys = pix * top + face
    q = np.arange(h * w, dtype=np.int64) * top + g
    j = np.searchsorted(keys, q)
    jc = np.minimum(j, len(keys) - 1)
    hit = (j < len(keys)) & (keys[jc] == q) & (g >= 0)
    return np.where(hit, jc, -1).reshape(h, w)


def clip_outside(key, cand, arrays, others=None, *, step=0.0, clear=1.0, depth_func="less"):
    """(H, W) bool: pixels whose candidate ``key`` lies outside the clip-surface allowance
    (a depth is a fragment's where it lies before ``clear`` in ``depth_func``'s direction)."""
    h, w = arrays["cs_bg"].shape
    c = np.asarray(cand)
    bg = np.asarray(arrays["cs_bg"], np.bool_)
    others = others or {}
    prim = np.asarray(others.get("prim_id", c if key == "prim_id" else None)) \
        if ("prim_id" in others or key == "prim_id") else None
    obj = np.asarray(others.get("object_id", c if key == "object_id" else None)) \
        if ("object_id" in others or key == "object_id") else None
    if key == "prim_id":
        prim = c
    if key == "object_id":
        obj = c
    named = None
    if prim is not None and obj is not None and prim.shape == (h, w) and obj.shape == (h, w):
        named = _named(arrays, prim, obj)
    off = arrays["cs_offsets"].astype(np.int64)
    n = np.diff(off).reshape(h, w)
    if key in ("prim_id", "object_id"):
        covered = c >= 0
        if named is None:   # one id alone: some entry of the set must carry it
            return covered & (n == 0) | (~covered & ~bg)
        return (covered & (named < 0)) | (~covered & ~bg)
    if key in ("cap_mask", "cut_mask"):
        if named is None:
            return np.zeros((h, w), np.bool_)
        e = np.maximum(named, 0)
        flag = arrays["cs_flag"][e] if len(arrays["cs_flag"]) else np.zeros((h, w), np.int8)
        return ((named >= 0) & (flag >= 0) & (c.astype(np.bool_) != (flag == 1))
                | ((named < 0) & c.astype(np.bool_)))
    if key == "front_facing":
        if named is None:
            return np.zeros((h, w), np.bool_)
        e = np.maximum(named, 0)
        f = arrays["cs_facing"][e] if len(arrays["cs_facing"]) else np.full((h, w), -1)
        return (named >= 0) & (f >= 0) & (c.astype(np.bool_) != (f == 1))
    if key not in ("depth", "eye_depth"):
        raise ValueError(f"no clip-surface check for buffer {key!r}")
    v = c.astype(np.float64)
    if key == "depth":
        from .conventions import depth_covered
        covered = depth_covered(v, clear, depth_func)
    else:
        covered = np.isfinite(v)
    which = "depth" if key == "depth" else "eye"
    lo = arrays[f"cs_{which}_lo"].astype(np.float64)
    hi = arrays[f"cs_{which}_hi"].astype(np.float64)
    if named is not None:
        e = np.maximum(named, 0)
        lo_p = np.where(named >= 0, lo[e] if len(lo) else np.nan, np.nan)
        hi_p = np.where(named >= 0, hi[e] if len(hi) else np.nan, np.nan)
    else:   # the envelope of the pixel's entries
        lo_p = np.full(h * w, np.nan)
        hi_p = np.full(h * w, np.nan)
        runs = np.flatnonzero(n.ravel() > 0)
        if len(runs):
            lo_p[runs] = np.minimum.reduceat(lo, off[runs])
            hi_p[runs] = np.maximum.reduceat(hi, off[runs])
        lo_p, hi_p = lo_p.reshape(h, w), hi_p.reshape(h, w)
    with np.errstate(invalid="ignore"):
        inside = (v >= lo_p - step) & (v <= hi_p + step)
    return (covered & ~inside) | (~covered & ~bg)


def clip_allowed(key, arrays, r, c, step=0.0):
    """What the allowance admits at pixel (r, c), in words."""
    h, w = arrays["cs_bg"].shape
    k = r * w + c
    a, b = int(arrays["cs_offsets"][k]), int(arrays["cs_offsets"][k + 1])
    draws = arrays["cs_draw_offsets"].astype(np.int64)
    parts = []
    for i in range(a, b):
        f = int(arrays["cs_face"][i])
        o = int(np.searchsorted(draws[1:], f, side="right"))
        s = f"({o}, {f - int(draws[o])})"
        if key in ("depth", "eye_depth"):
            which = "depth" if key == "depth" else "eye"
            s += (f" {key} [{float(arrays[f'cs_{which}_lo'][i]) - step:.6g}, "
                  f"{float(arrays[f'cs_{which}_hi'][i]) + step:.6g}]")
        elif key in CLIP_VALUES and CLIP_VALUES[key][0] in arrays:
            a, b = (arrays[x][i] for x in CLIP_VALUES[key])
            if key == "normal":
                s += (f" normal within {float(b) + step * np.sqrt(3.0):.4g} rad of "
                      f"({', '.join(f'{float(x):.6g}' for x in a)})")
            else:
                s += (f" {key} [({', '.join(f'{float(x) - step:.6g}' for x in a)}), "
                      f"({', '.join(f'{float(x) + step:.6g}' for x in b)})]")
        parts.append(s)
    bg = "; or the background" if arrays["cs_bg"][r, c] else ""
    return "(object_id, prim_id) one of {" + "; ".join(parts) + "}" + bg
