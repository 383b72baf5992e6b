"""Allowances of the cutaway depth D ("Goldens with teeth (2)", item 4).

D (MATH.md §4.1) is ``max(−1, max_s [z(s) − m(s)·‖x − s‖])`` over the seeds s — the pixels of the
rear hulls of the objects of interest (rendered with depth test ``greater``, clear 0) — with
``m(s)`` from θ, perspective compensation (``m = −(P₂₂ + z)/tan θ_e``) and edge compression
(θ_e from the pixel's position only). Every flooding variant computes the maximum over a subset
of the seeds it visits, so no variant exceeds the exact maximum; the exact D is increasing in each
seed's depth (``∂/∂z [z − m(z)·d] = 1 + d/tan θ_e > 0``; orthographic: m constant) and in the set
of seeds.

What a conformant GPU may change in the seeds is plain rendering's: which faces cover a pixel
centre (the edge ε) and each face's depth there (the ε-square and the float32 slack). The
golden takes the per-pixel faces whose ε-dilated footprint covers the centre with their depth
intervals (:func:`refraster.golden.allowances.layers.covering_entries`, hidden faces included)
and forms two seed images at the cutaway resolution:

* **largest**: every pixel some face may cover, at the largest depth any of them may show;
* **smallest**: only pixels some face surely covers (ε to spare, not a sliver), at the least
  depth the farthest surely-covering face may show (the rear hull is at least that far).

Then ``D_hi = exact(largest) + slack`` (no variant, no seed set exceeds it) and
``D_lo = min over the accepted variants v of LB_v − slack``, where ``LB_v``
(:func:`interval_flood`) follows the flood of v over every seed image between the smallest and
the largest at once, as per-pixel sets of the seeds a pixel may hold: jump flooding is not
monotone in its seeds (a new seed can displace a better one on the way), so flooding a few seed
images would prove nothing about the others. Float ties between seeds and seeds of uncertain
depth or presence keep every possible winner; the bound is their least (docs/tolerance.md,
"Cutaways"), with the floor constraint too (the directional slope blends m_e and m_f by the
direction only). With one angle per cutaway object ``D_lo`` keeps the measured floods of the
smallest, the largest and refraster's own rear hull.
``slack`` covers float32 evaluation of
``z − m·‖x − s‖`` (``16·2⁻²⁴·(1 + |z| + m·‖x − s‖)`` ≤ 16·2⁻²⁴·(2 + m_max·diag)) and of the
conversion to window depth. The scene states the variants it accepts (``accepted_variants``:
its own and the exact maximum, and those at least as good as its own).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cutaway_bounds", "interval_flood"]

F32 = 2.0 ** -24
_BIG = np.iinfo(np.int64).max


def _seed_images(scene, interest, eps, with_least=False):
    from .layers import covering_entries
    cam = scene.camera
    draws = [d for d in scene.draws if d.name in interest]
    h, w = cam.height, cam.width
    prep, pix, faces, sure, _, lo, hi = covering_entries([d.mesh for d in draws],
                                                         [d.model for d in draws], cam, "none",
                                                         eps)
    # a sliver's or degenerate face's depth interval is unbounded (±inf), but where a GPU
    # covers a pixel with it, the depth it shows interpolates the face's vertices: at most
    # their largest window depth (the far plane if a vertex is behind the eye), plus the
    # float32 slack
    free = ~np.isfinite(hi)
    if free.any():
        clip = prep.clip[prep.triangles.faces[faces[free]]]
        wv = clip[:, :, 3]
        with np.errstate(invalid="ignore", divide="ignore"):
            zv = 0.5 * clip[:, :, 2] / wv + 0.5
        zmax = np.where((wv > 0).all(axis=1), zv.max(axis=1), 1.0)
        hi = hi.copy()
        hi[free] = np.minimum(zmax + 16.0 * F32, 1.0)
    big = np.full(h * w, -np.inf)
    np.maximum.at(big, pix, hi)
    small = np.full(h * w, -np.inf)
    np.maximum.at(small, pix[sure], lo[sure])
    least = np.full(h * w, np.inf)
    np.minimum.at(least, pix, np.where(np.isfinite(lo), lo, 0.0))
    if with_least:
        return (np.clip(big, 0.0, 1.0).reshape(h, w), np.isfinite(big).reshape(h, w),
                np.clip(small, 0.0, 1.0).reshape(h, w), np.isfinite(small).reshape(h, w),
                np.clip(least, 0.0, 1.0).reshape(h, w))
    return (np.clip(big, 0.0, 1.0).reshape(h, w), np.isfinite(big).reshape(h, w),
            np.clip(small, 0.0, 1.0).reshape(h, w), np.isfinite(small).reshape(h, w))


def interval_flood(z_lo, z_hi, sure, maybe, m_lo, m_hi, m_max, sy, sx, schedule, tau, cap=16,
                   floor=None):
    """A lower bound of every jump flood with ``schedule`` over every seed image a conformant
    GPU may render, evaluated with an error of at most ``tau`` per cutaway-function value.

    The seeds include the pixels ``sure`` and lie in ``sure | maybe``, a seed's NDC depth in
    ``[z_lo, z_hi]`` with slopes ``m_lo``/``m_hi`` there (m affine in z: perspective
    compensation, or constant). Per pixel and pass the flood is followed as a *set* of seeds
    the pixel may hold, each with a least depth it may have given that it is held there:

    * ``T(x)``, a lower bound of the winner's value: for every candidate that surely holds a
      seed, the least its value at x may be (the least over its set); the winner's is ≥ each;
    * the pixel may hold every candidate seed whose largest value at x reaches ``T(x)`` (so
      ties within ``tau``, and seeds whose depth is uncertain, keep both possibilities);
    * a seed s held at x has value ≥ T(x) − tau there; C is affine and increasing in z, so its
      depth is ≥ the z* solving C_s(x; z*) = T(x) − tau (that is what keeps the sets small);
    * a set larger than ``cap`` is no longer followed: the pixel's seed then has value ≥ T(x)
      and, at a pixel at distance δ, ≥ T(x) − m_max·δ (triangle inequality of the cone).

    ``floor``: ``(m_f at z_lo, m_f at z_hi, n_x, n_y)`` of the directional constraint (D-C7): the
    slope toward x blends m_e and m_f by the direction only, so C stays affine and increasing in
    z; the cone's triangle inequality does not hold, so an untracked pixel then bounds nothing.

    Returns ``(T, untracked, several)``: ``T`` after the last pass (the flood's D ≥ T, −inf where
    no seed need reach), the pixels not followed at the end, and those where more than one seed
    may win (a tie within float rounding or an uncertain seed)."""
    h, w = z_lo.shape
    n = h * w
    seedable = sure | maybe
    zl, zh, ml, mh = (np.where(seedable, a, 0.0).ravel() for a in (z_lo, z_hi, m_lo, m_hi))
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(zh > zl, (mh - ml) / (zh - zl), 0.0)
    if floor is not None:
        mfl, mfh, nxs, nys = (np.where(seedable, a, 0.0).ravel() for a in floor)
    rows, cols = np.mgrid[0:h, 0:w].astype(float)
    srow, scol = rows.ravel() * sy, cols.ravel() * sx
    rows, cols = rows * sy, cols * sx
    ids = np.full((h, w, cap), -1, np.int64)
    ids[..., 0] = np.where(seedable, np.arange(n).reshape(h, w), -1)
    zr = np.zeros((h, w, cap))
    zr[..., 0] = np.where(seedable, z_lo, 0.0)
    none = ~sure
    over = np.zeros((h, w), bool)
    olo = np.full((h, w), -np.inf)
    ohi = np.full((h, w), -np.inf)
    T = None
    for k in schedule:
        C_lo, C_hi, C_id, C_z, C_d, C_m, C_g = [], [], [], [], [], [], []
        T = np.full((h, w), -np.inf)
        for oy in (-1, 0, 1):
            for ox in (-1, 0, 1):
                i0, i1 = max(0, -k * oy), min(h, h - k * oy)
                j0, j1 = max(0, -k * ox), min(w, w - k * ox)
                qid = np.full((h, w, ids.shape[2]), -1, np.int64)
                qz = np.zeros((h, w, ids.shape[2]))
                qnone = np.ones((h, w), bool)
                qover = np.zeros((h, w), bool)
                qolo = np.full((h, w), -np.inf)
                qohi = np.full((h, w), -np.inf)
                if i0 < i1 and j0 < j1:
                    src = (slice(i0 + k * oy, i1 + k * oy), slice(j0 + k * ox, j1 + k * ox))
                    dst = (slice(i0, i1), slice(j0, j1))
                    qid[dst], qz[dst] = ids[src], zr[src]
                    qnone[dst], qover[dst] = none[src], over[src]
                    qolo[dst], qohi[dst] = olo[src], ohi[src]
                s = np.maximum(qid, 0)
                dy, dx = rows[..., None] - srow[s], cols[..., None] - scol[s]
                d = np.hypot(dy, dx)
                if floor is None:
                    m0, m1, gs = ml[s], mh[s], g[s]
                else:   # the direction's blend (refraster.cutaway.flood._value_directional)
                    a = -(dx * nxs[s] - dy * nys[s]) / np.where(d != 0, d, 1.0)
                    a = np.clip(a, 0.0, 1.0)
                    m0 = (1.0 - a) * ml[s] + a * mfl[s]
                    m1 = (1.0 - a) * mh[s] + a * mfh[s]
                    with np.errstate(divide="ignore", invalid="ignore"):
                        gs = np.where(zh[s] > zl[s], (m1 - m0) / (zh[s] - zl[s]), 0.0)
                m_at = m0 + (qz - zl[s]) * gs
                lo = np.where(d == 0, qz, qz - m_at * d) - tau
                hi = np.where(d == 0, zh[s], zh[s] - m1 * d) + tau
                valid = qid >= 0
                lo = np.where(valid, lo, np.inf)
                hi = np.where(valid, hi, -np.inf)
                dist = np.hypot(oy * k * sy, ox * k * sx)
                o_lo = qolo - m_max * dist - 2.0 * tau
                o_hi = qohi + m_max * dist + 2.0 * tau
                if floor is not None:   # no triangle inequality: nothing known
                    o_lo = np.where(qover, -np.inf, o_lo)
                    o_hi = np.where(qover, np.inf, o_hi)
                least = np.where(qover, o_lo, lo.min(axis=2))
                T = np.maximum(T, np.where(qnone, -np.inf, least))
                C_lo.append(np.concatenate([lo, np.where(qover, o_lo, np.inf)[..., None]], 2))
                C_hi.append(np.concatenate([hi, np.where(qover, o_hi, -np.inf)[..., None]], 2))
                C_id.append(np.concatenate([qid, np.where(qover, -2, -1)[..., None]], 2))
                C_z.append(np.concatenate([qz, np.zeros((h, w, 1))], 2))
                C_d.append(np.concatenate([d, np.zeros((h, w, 1))], 2))
                C_m.append(np.concatenate([m0 + 0.0 * d, np.zeros((h, w, 1))], 2))
                C_g.append(np.concatenate([gs + 0.0 * d, np.zeros((h, w, 1))], 2))
        Hi, Id, Z, D, ML, G = (np.concatenate(a, axis=2)
                               for a in (C_hi, C_id, C_z, C_d, C_m, C_g))
        may = (Id != -1) & (Hi >= T[..., None])
        # a seed held here has C ≥ T − τ: its depth is at least z* (C affine in z, slope > 0)
        s = np.maximum(Id, 0)
        Tm = np.where(np.isfinite(T), T, -1e300)[..., None] - tau
        den = 1.0 - D * G
        zstar = (Tm + D * ML - D * G * zl[s]) / den
        zstar = np.where(D == 0, Tm, zstar) - 1e-12
        Z = np.minimum(np.maximum(Z, zstar), zh[s])
        key = np.where(may & (Id >= 0), Id, _BIG)
        order = np.lexsort((Z, key), axis=-1)
        ks = np.take_along_axis(key, order, 2)
        zs = np.take_along_axis(Z, order, 2)
        first = np.concatenate([np.ones((h, w, 1), bool), ks[..., 1:] != ks[..., :-1]], 2)
        uniq = first & (ks != _BIG)
        count = uniq.sum(axis=2)
        new_over = (may & (Id == -2)).any(axis=2) | (count > cap)
        new_ids = np.full((h, w, cap), -1, np.int64)
        new_z = np.zeros((h, w, cap))
        pos = np.cumsum(uniq, axis=2) - 1
        r_, c_, k_ = np.nonzero(uniq & (pos < cap))
        new_ids[r_, c_, pos[r_, c_, k_]] = ks[r_, c_, k_]
        new_z[r_, c_, pos[r_, c_, k_]] = zs[r_, c_, k_]
        new_ids[new_over] = -1
        # keep only as many slots as some pixel uses (the sets are small)
        width = max(int(np.minimum(count, cap).max()), 1)
        new_ids, new_z = new_ids[..., :width], new_z[..., :width]
        ohi = np.where(new_over, np.where(may, Hi, -np.inf).max(axis=2), -np.inf)
        olo = np.where(new_over, T, -np.inf)
        ids, zr, none, over = new_ids, new_z, ~np.isfinite(T), new_over
    several = over | (count > 1)
    return T, over, several


def _floor_slope_max(seeded, cam, p, kw):
    """The largest floor-side slope m_f any seed may have: θ_f depends on the pixel only (φ is
    the angle of the pixel's ray to the floor), and m_f = −(P₂₂ + z)/tan θ_f is linear in z, so
    its largest value over the pixels that may be seeds is at z = −1 or z = +1."""
    from ...cutaway.surface import as_angles, seed_slopes
    theta = np.full(seeded.shape, float(np.min(as_angles(p["angle"]))))
    out = 0.0
    for z in (-1.0, 1.0):
        zz = np.where(seeded, z, -np.inf)
        slope, (slope_f, _) = seed_slopes(
            zz, theta, proj=cam.proj, view=cam.view,
            perspective_compensation=kw["perspective_compensation"],
            edge_compression=kw["edge_compression"], floor_normal=kw["floor_normal"],
            floor_margin=kw["floor_margin"])
        out = max(out, float(np.max(np.abs(slope))), float(np.max(np.abs(slope_f))))
    return out


def cutaway_bounds(scene, eps, flood_camera=None, seeds=None):
    """``(lo, hi)`` float32 (H, W): the window-depth interval of the cutaway depth D.
    ``flood_camera``: the camera whose projection the flood uses when it is not the one the
    rear hulls are drawn with (a multisampled cutaway's D flooded from sample 0's rear hulls
    at the pixel centre's projection, :mod:`.sampled`); the seeds are ``scene.camera``'s, or
    ``seeds``: the five images of :func:`_seed_images` (``with_least``) given by the caller
    (rear hulls resolved by min or max, :func:`.sampled.resolved_seed_images`; the proven
    bound only)."""
    from ...cutaway.surface import cutaway_surface, pixel_ndc
    p = scene.parameters
    if seeds is None:
        seeds = _seed_images(scene, set(p["interest"]), eps, with_least=True)
    elif np.size(p["angle"]) != 1:
        raise ValueError("cutaway_bounds: given seed images need one angle per cutaway (the "
                         "proven bound)")
    big, big_seed, small, small_seed, least = seeds
    cam = scene.camera if flood_camera is None else flood_camera
    kw = dict(proj=cam.proj, view=cam.view, angle=p["angle"],
              perspective_compensation=p["perspective_compensation"],
              edge_compression=p["edge_compression"])
    floor = p.get("floor_normal")
    if floor is not None:
        # the directional constraint: the same floor-constrained flood the scene's D used
        kw.update(floor_normal=np.asarray(floor, np.float64),
                  floor_margin=float(p.get("floor_margin", np.radians(2.0))))

    def flood(rear, seeded, variant):
        oid = np.where(seeded, 0, -1).astype(np.int32)
        return cutaway_surface(np.where(seeded, rear, 0.0), oid, variant=variant, **kw)

    # float32 evaluation of z − m·‖x − s‖: the largest m times the diagonal in tangent units
    x, y = pixel_ndc(*big.shape)
    diag = float(np.hypot(np.ptp(x), np.ptp(y))) / min(abs(cam.proj[0, 0]), abs(cam.proj[1, 1]))
    m_max = (abs(cam.proj[2, 2]) + 1.0) / np.tan(max(float(np.min(p["angle"])), 1e-3))
    if floor is not None:
        m_max = max(m_max, _floor_slope_max(big_seed, cam, p, kw))
    slack = 16.0 * F32 * (2.0 + m_max * diag)
    d_hi = flood(big, big_seed, "exact")
    d_lo = np.full(d_hi.shape, np.inf)
    may = np.zeros(d_hi.shape, np.bool_)
    proven = np.size(p["angle"]) == 1
    if proven:
        # proven: the interval flood follows every seed image between the smallest and the
        # largest, and every float evaluation within the slack (interval_flood)
        from ...cutaway.flood import step_schedule
        from ...cutaway.surface import seed_slopes, tangent_sampling
        z_lo = np.where(small_seed, 2.0 * small - 1.0, 2.0 * least - 1.0)
        z_hi = 2.0 * big - 1.0
        theta = np.full(big.shape, float(np.min(p["angle"])))

        def slopes(z):
            extra = {k: kw[k] for k in ("floor_normal", "floor_margin") if k in kw}
            return seed_slopes(np.where(big_seed, z, -np.inf), theta, proj=cam.proj,
                               view=cam.view, perspective_compensation=kw[
                                   "perspective_compensation"],
                               edge_compression=kw["edge_compression"], **extra)
        (m_lo, f_lo), (m_hi, f_hi) = slopes(z_lo), slopes(z_hi)
        m_seed = float(np.max(m_lo[big_seed])) if big_seed.any() else 0.0
        floor_args = None
        if f_lo is not None:
            # the projected floor normal depends on the pixel's ray only, not on the depth
            assert np.allclose(f_lo[1][big_seed], f_hi[1][big_seed], atol=1e-9)
            floor_args = (f_lo[0], f_hi[0], f_lo[1][..., 0], f_lo[1][..., 1])
            m_seed = max(m_seed, float(np.max(f_lo[0][big_seed])) if big_seed.any() else 0.0)
        sy, sx = tangent_sampling(cam.proj, *big.shape)
        tau = 16.0 * F32 * (2.0 + max(m_max, m_seed) * diag)
        for v in p["accepted_variants"]:
            if v == "exact":    # monotone in the seeds and their depths
                d_lo = np.minimum(d_lo, flood(small, small_seed, "exact"))
                continue
            t, _, several = interval_flood(z_lo, z_hi, small_seed, big_seed & ~small_seed,
                                           m_lo, m_hi, m_seed, sy, sx,
                                           step_schedule(*big.shape, v), tau,
                                           floor=floor_args)
            d_lo = np.minimum(d_lo, np.maximum(t, -1.0))
            may |= several
    else:
        # measured, not proven (local angles per object: not followed by interval_flood): the
        # floods of the smallest, the largest and refraster's own rear hull
        from refraster import RasterState, render
        draws = [d for d in scene.draws if d.name in set(p["interest"])]
        rear = render([d.mesh for d in draws], **cam.kwargs, model=[d.model for d in draws],
                      raster=RasterState(depth_func="greater", clear_depth=0.0))
        own = np.asarray(rear.depth, np.float64), np.asarray(rear.object_id) >= 0
        for v in p["accepted_variants"]:
            for seeds in ((small, small_seed), (big, big_seed), own):
                d_lo = np.minimum(d_lo, flood(*seeds, v))
    lo = 0.5 * (np.maximum(d_lo, -1.0) - slack) + 0.5
    hi = 0.5 * (d_hi + slack) + 0.5
    lo = np.clip(lo, 0.0, 1.0)
    hi = np.clip(hi, 0.0, 1.0)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32), float(slack)
