"""Allowance of the cutaway's ghost lines ("Goldens with teeth (2)", item 4; MATH.md D-C11).

The ghost buffer (:func:`refraster.cutaway.lines.ghost_alpha`) is, per pixel, the largest opacity
over the line fragments of the secondary meshes' feature segments there:

    α(z) = 1 − (e(D) − e(z)) / g_max   where z < min(D, occ) and e(D) − e(z) < g_max, else 0

(``e`` the eye depth of an NDC depth, ``occ`` the NDC depth of a visible object of interest, +∞
elsewhere; without the fade α = 1 there). Two rules are accepted:

* **refraster's**: a segment on every pixel its window projection crosses (supercover), the
  largest α over its chord there — on the golden's own segment (no snapping to vary), float32
  interpolation ``32·2⁻²⁴``;
* **a GPU's** ``GL_LINES``: one fragment per column of an x-major line (row of a y-major one),
  its depth at ONE point of the line (:func:`_evaluation_depths`): GL's foot of the pixel
  centre ``t_F`` or, as llvmpipe does (its line depth plane has no minor-axis slope), the
  point on the column's (row's) centre line ``t_C``, extended linearly beyond the segment's
  ends; any parallelogram line whose sides lie between the perpendicular and the minor axis
  evaluates between them. Window depth is affine along the projected line (GL's linear line
  depth). Vertex moves of ``1.5·ε`` per axis move those points' depths by the first-order terms
  of :func:`_evaluation_depths`, float32 interpolation by ``32·2⁻²⁴``.

Per pixel the golden stores ``ghost_lo ≤ ghost ≤ ghost_hi``, or ``ghost = 0`` where
``ghost_zero``:

* **hi**: the supremum of α over refraster's chords at the pixel and over every fragment a GPU
  may draw there — at every chord pixel and, for a line that passes within ``1.5·ε`` of the
  pixel's square, there too — each over its evaluation range, D in ``[D_lo, D_hi]``
  (:mod:`.cutaway`) and the occluder in the range the cut frame's face sets allow (``cs_*`` of
  :func:`.clip.cutaway_allowances`);
* **lo**: the largest, over the segments that *surely* produce a fragment there, of the
  infimum of α over the GPU's evaluation range (refraster's chord maximum is at least that:
  the centre-line point lies on the chord). A segment surely produces a fragment at pixel
  (r, c) where, for its major axis (certain: ``| |Δx| − |Δy| | > 6ε``, the ends moving by 1.5ε;
  else both rules must agree), the line crosses the column's centre line at ``y_c`` with
  ``frac(y_c)`` more than ``1.5·ε·(1 + |slope|)`` from an integer (the pixel's diamond is
  crossed whatever the vertices' moves), ``1.5·ε`` inside the segment's extent along the major
  axis, and the segment's second vertex lies outside the diamond by ``3ε`` in L1 distance
  (diamond exit: a segment ending inside a diamond does not produce it; one starting inside
  does).
* **zero**: where no segment surely produces a fragment, α is 0 (none drawn) or, drawn, at
  least the least α of the fragments that may be drawn there (refraster's chords, the GPU's
  evaluation ranges): the largest gap, at ``D_hi`` and the range's nearest depth; ``lo`` holds
  that bound there and ``zero`` says 0 is allowed too.

The opacity itself is evaluated in float32 on a GPU: the gap ``e(D) − e(z)`` carries
``32·2⁻²⁴·(e(D) + e(z))``.

Not admitted: GL's licence for line algorithms other than diamond exit to put a fragment one
pixel off the diamond-exit one (its rule 1), which would leave every pixel next to a line free.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ghost_bounds", "GHOST_ARRAYS"]

F32 = 2.0 ** -24
#: Margin on the edge ε, as the other intervals' (``SHIFT_MARGIN``).
MARGIN = 1.5
#: The sub-pixel bits of the edge ε the line placement uses, whatever the candidate declares
#: for its triangles: a GPU draws ``GL_LINES`` with a line algorithm of its own (llvmpipe: a
#: quad per line), not with the triangles' snapping the declaration describes; 4 is GL's
#: minimum sub-pixel precision (llvmpipe's lines pass the 8-bit ε too, on the five cutaway
#: scenes).
LINE_BITS = 4
GHOST_ARRAYS = ("ghost_lo", "ghost_hi", "ghost_zero")


def _occluder_bounds(arrays, interest_draws, h, w):
    """(occ_lo, occ_hi) NDC per pixel from the cut frame's face sets: the least depth an object
    of interest that may be visible may show (+∞: none may be), and +∞ unless only objects of
    interest may be visible (then the largest depth they may show)."""
    off = arrays["cs_offsets"].astype(np.int64)
    face = arrays["cs_face"].astype(np.int64)
    draws = arrays["cs_draw_offsets"].astype(np.int64)
    n = np.diff(off)
    pix = np.repeat(np.arange(h * w), n)
    obj = np.searchsorted(draws[1:], face, side="right")
    ooi = np.isin(obj, list(interest_draws))
    lo = 2.0 * arrays["cs_depth_lo"].astype(np.float64) - 1.0
    hi = 2.0 * arrays["cs_depth_hi"].astype(np.float64) - 1.0
    occ_lo = np.full(h * w, np.inf)
    np.minimum.at(occ_lo, pix[ooi], lo[ooi])
    occ_hi = np.full(h * w, -np.inf)
    np.maximum.at(occ_hi, pix[ooi], hi[ooi])
    other = np.zeros(h * w, np.int64)
    np.add.at(other, pix[~ooi], 1)
    only = (other == 0) & (n > 0) & ~np.asarray(arrays["cs_bg"], np.bool_).ravel()
    occ_hi = np.where(only, occ_hi, np.inf)
    return occ_lo, occ_hi


class _Alpha:
    """The ghost opacity of D-C11 with its float32 gap allowance."""

    def __init__(self, proj, g_max, fade):
        from ...cutaway.surface import ndc_to_eye_depth
        self.e = lambda z: ndc_to_eye_depth(np.clip(z, -1.0, 1.0), proj)
        self.g, self.fade = float(g_max), bool(fade)

    def _of_gap(self, gap):
        a = np.clip(1.0 - gap / self.g, 0.0, 1.0) if self.fade else np.ones(gap.shape)
        return np.where(gap < self.g, a, 0.0)

    def sup(self, zl, zh, d_lo, d_hi, occ_hi):
        """Supremum of α over z ∈ [zl, zh], D ∈ [d_lo, d_hi], occ ≤ occ_hi (α increases with
        occ). For fixed D, α increases with z below L = min(D, occ): z* = min(zh, L); as a
        function of D it is 0 up to zl, 1 up to c = min(zh, occ), then falls: the supremum is at
        d_lo, d_hi or c clamped into the interval."""
        best = np.zeros(zl.shape)
        c = np.minimum(zh, occ_hi)
        for d in (d_lo, d_hi, np.clip(c, d_lo, d_hi)):
            lim = np.minimum(d, occ_hi)
            zs = np.minimum(zh, lim)
            ed, ez = self.e(d), self.e(zs)
            gap = np.maximum(ed - ez - 32.0 * F32 * (np.abs(ed) + np.abs(ez)), 0.0)
            best = np.maximum(best, np.where(zl < lim, self._of_gap(gap), 0.0))
        return best

    def inf(self, zl, zh, d_lo, d_hi, occ_lo):
        """Infimum of α over the same box (occ ≥ occ_lo): 0 if some z may lie at or behind
        min(D, occ); else the largest gap, at zl and d_hi."""
        ed, ez = self.e(d_hi), self.e(zl)
        gap = ed - ez + 32.0 * F32 * (np.abs(ed) + np.abs(ez))
        return np.where(zh < np.minimum(d_lo, occ_lo), self._of_gap(gap), 0.0)


    def drawn_inf(self, zl, zh, d_lo, d_hi, occ_hi):
        """Infimum of α over the same box among the fragments that are drawn (α > 0: some z
        in front of min(D, occ)): the largest gap, at zl and d_hi; +∞ where none may be
        drawn."""
        ed, ez = self.e(d_hi), self.e(zl)
        gap = ed - ez + 32.0 * F32 * (np.abs(ed) + np.abs(ez))
        return np.where(zl < np.minimum(d_hi, occ_hi), self._of_gap(gap), np.inf)


def _sure_fragments(whole, eps, h, w):
    """(segment row, pixel) of the fragments every accepted line rasterizer produces (see the
    module docstring)."""
    ends, _, _ = whole
    xa, ya, xb, yb = ends.T
    dx, dy = xb - xa, yb - ya
    m = MARGIN * eps
    out = {}
    for axis in ("x", "y"):
        # parametrise by the major coordinate u, the minor v
        ua, ub, va, vb = (xa, xb, ya, yb) if axis == "x" else (ya, yb, xa, xb)
        du, dv = ub - ua, vb - va
        # the columns whose centre line the segment crosses, ε to spare
        lo_u = np.ceil(np.minimum(ua, ub) + m - 0.5)
        hi_u = np.floor(np.maximum(ua, ub) - m - 0.5)
        n = np.maximum(hi_u - lo_u + 1.0, 0.0).astype(np.int64)
        n = np.where(np.abs(du) > 0, n, 0)
        seg = np.repeat(np.arange(len(ua)), n)
        k = lo_u[seg] + (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n))
        uc = k + 0.5
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = dv[seg] / du[seg]
        vc = va[seg] + (uc - ua[seg]) * slope
        r = np.floor(vc)
        f = vc - r
        delta = m * (1.0 + np.abs(slope)) + 1e-9 * (1.0 + np.abs(vc))
        ok = (f > delta) & (f < 1.0 - delta)
        # diamond exit: the fragment is lost where the segment's second vertex lies inside the
        # diamond (a start inside it still exits); the vertex moves by ε per axis
        ok &= np.abs(ub[seg] - uc) + np.abs(vb[seg] - (r + 0.5)) >= 0.5 + 2.0 * m
        row, col = (r, k) if axis == "x" else (k, r)
        ok &= (row >= 0) & (row < h) & (col >= 0) & (col < w)
        seg, row, col = seg[ok], row[ok].astype(np.int64), col[ok].astype(np.int64)
        out[axis] = set(zip(seg.tolist(), (row * w + col).tolist()))
    xmaj = np.abs(dx) - np.abs(dy) > 4.0 * m
    ymaj = np.abs(dy) - np.abs(dx) > 4.0 * m
    keep = [(s, p) for s, p in out["x"] if xmaj[s]] + [(s, p) for s, p in out["y"] if ymaj[s]]
    both = out["x"] & out["y"]
    keep += [(s, p) for s, p in both if not xmaj[s] and not ymaj[s]]
    if not keep:
        z = np.zeros(0, np.int64)
        return z, z
    seg, pix = (np.array(v, np.int64) for v in zip(*sorted(keep)))
    return seg, pix


def _evaluation_depths(whole, seg, pix, eps, w):
    """NDC depth range ``(z_lo, z_hi)`` of the fragment a GPU's line rasterizer gives segment
    row ``seg`` (of ``whole``) at flat pixel ``pix`` when it draws one there: the line's depth
    at the point(s) where the accepted line rules evaluate it, widened by the vertex moves of
    ``MARGIN·eps`` per axis and float32 interpolation.

    Window depth is affine along the projected line, ``z(t) = z_a + t·(z_b − z_a)`` (GL's
    linear line depth, equation 14.7 of GL 4.6), ``t`` the fraction of the window segment,
    extended linearly beyond the ends. The evaluation points: GL's foot of the pixel centre
    ``t_F = ((p_r − p_a)·(p_b − p_a))/|p_b − p_a|²``, and where the major axis's centre line
    through the centre crosses the line, ``t_C = (x_c − x_a)/Δx`` (x-major) or
    ``t_R = (y_c − y_a)/Δy`` (y-major): llvmpipe's line depth plane has no minor-axis slope
    (measured at every fragment of the cutaway scenes' lines, ``tests/test_gl_techniques.py``).
    Both where the major axis may go either way (``||Δx| − |Δy|| ≤ 4·MARGIN·eps``).

    Vertex moves (first order): ``z(t_C)`` at the fixed ``x_c`` moves by
    ``m·|Δz/Δx|·(|1 − t_C| + |t_C|)``; ``t_F`` by ``√2·m·((|1 − t_F| + |t_F|) + 2|h|/L)/L``
    (``h`` the centre's distance from the line, ``L`` its length), so ``z(t_F)`` by that times
    ``|Δz|``; plus ``32·2⁻²⁴`` for float32 interpolation."""
    ends, zends, _ = whole
    xa, ya, xb, yb = (ends[seg, k] for k in range(4))
    za, zb = zends[seg, 0], zends[seg, 1]
    dx, dy, dz = xb - xa, yb - ya, zb - za
    m = MARGIN * eps
    ll = dx * dx + dy * dy
    ln = np.sqrt(ll)
    cx, cy = pix % w + 0.5, pix // w + 0.5
    t_f = ((cx - xa) * dx + (cy - ya) * dy) / ll
    h = np.abs((cx - xa) * dy - (cy - ya) * dx) / ln
    reach = lambda t: np.abs(1.0 - t) + np.abs(t)      # noqa: E731
    ts = [t_f]
    moved = [np.sqrt(2.0) * m * (reach(t_f) + 2.0 * h / ln) / ln * np.abs(dz)]
    xmaj = np.abs(dx) - np.abs(dy) > 4.0 * m
    ymaj = np.abs(dy) - np.abs(dx) > 4.0 * m
    with np.errstate(divide="ignore", invalid="ignore"):
        for du, t, use in (((dx, (cx - xa) / dx, ~ymaj)), (dy, (cy - ya) / dy, ~xmaj)):
            t = np.where(use, t, t_f)
            ts.append(t)
            moved.append(np.where(use, m * np.abs(dz / du) * reach(t), 0.0))
    t = np.stack(ts)
    z = za + t * dz
    slack = np.max(np.stack(moved), axis=0) + 32.0 * F32
    return z.min(axis=0) - slack, z.max(axis=0) + slack


def ghost_bounds(scene, arrays, eps):
    """``(lo, hi, zero)`` of the ghost opacity — float32 (H, W) bounds and a bool (H, W), where
    α may also be 0 (no fragment is sure there): α ∈ [lo, hi] or (zero and α = 0) — or ``None``
    when the scene's ghost is not the line variant. ``arrays`` must hold ``cutaway_depth_lo/_hi`` and the ``cs_*`` sets."""
    from ...cutaway.lines import feature_segments, segment_pieces
    p = scene.parameters or {}
    if p.get("ghost", "lines") != "lines":
        return None
    cam = scene.camera
    h, w = cam.height, cam.width
    lo = np.zeros(h * w)
    hi = np.zeros(h * w)
    names = [d.name for d in scene.draws]
    secondary = [d for d in scene.draws if d.name in set(p["secondary"])]
    g_max = p.get("ghost_distance")
    meshes = []
    from ...mesh import Mesh
    for d in secondary:
        v = np.asarray(d.mesh.vertices, np.float64)
        v = (np.c_[v, np.ones(len(v))] @ np.asarray(d.model, np.float64).T)[:, :3]
        meshes.append(Mesh(v, d.mesh.faces))
    if g_max is None:
        v = np.concatenate([m.vertices for m in meshes]) if meshes else np.zeros((0, 3))
        g_max = 0.1 * float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) if len(v) else 0.0
    if not meshes or g_max <= 0:
        return (lo.reshape(h, w).astype(np.float32), hi.reshape(h, w).astype(np.float32),
                np.ones((h, w), np.bool_))
    view, proj = np.asarray(cam.view, np.float64), np.asarray(cam.proj, np.float64)
    segs = feature_segments(meshes, view=view, proj=proj,
                            crease_angle=float(p.get("crease_angle", 30.0)))
    pix, za, zb, sidx, (x0, y0, x1, y1), whole = segment_pieces(
        segs, view=view, proj=proj, width=w, height=h, window=True)
    alpha = _Alpha(proj, g_max, p.get("ghost_fade", True))
    d_lo = 2.0 * np.asarray(arrays["cutaway_depth_lo"], np.float64).ravel() - 1.0
    d_hi = 2.0 * np.asarray(arrays["cutaway_depth_hi"], np.float64).ravel() - 1.0
    interest = {i for i, n in enumerate(names) if n in set(p["interest"])}
    occ_lo, occ_hi = _occluder_bounds(arrays, interest, h, w)
    ends, zends, widx = whole
    row_of = np.full(int(widx.max()) + 1 if len(widx) else 0, -1, np.int64)
    row_of[widx] = np.arange(len(widx))
    m = MARGIN * eps
    # refraster's own rule (supercover, the largest α over the chord): the chord's depth range,
    # the segment's own ends, float32 interpolation
    zl = np.minimum(za, zb) - 32.0 * F32
    zh = np.maximum(za, zb) + 32.0 * F32
    np.maximum.at(hi, pix, alpha.sup(zl, zh, d_lo[pix], d_hi[pix], occ_hi[pix]))
    present = np.full(h * w, np.inf)
    np.minimum.at(present, pix, alpha.drawn_inf(zl, zh, d_lo[pix], d_hi[pix], occ_hi[pix]))
    # a GPU's GL_LINES: a fragment at every pixel of the chord and at the neighbours its line
    # passes within 1.5ε of, its depth at the line's evaluation point(s) there
    seg_rows, pair_pix = [], []
    r, c = pix // w, pix % w
    xmin, xmax = np.minimum(x0, x1), np.maximum(x0, x1)
    ymin, ymax = np.minimum(y0, y1), np.maximum(y0, y1)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            gx = {-1: xmin - c, 0: 0.0 * xmin, 1: (c + 1) - xmax}[dj]
            gy = {-1: ymin - r, 0: 0.0 * ymin, 1: (r + 1) - ymax}[di]
            rr, cc = r + di, c + dj
            reach = (gx <= m) & (gy <= m) & (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
            seg_rows.append(row_of[sidx[reach]])
            pair_pix.append((rr * w + cc)[reach])
    # the fragments every accepted rasterizer produces
    sseg, spix = _sure_fragments(whole, eps, h, w)
    keys = np.unique(np.concatenate(
        [s * (h * w) + q for s, q in zip(seg_rows + [sseg], pair_pix + [spix])]))
    gseg, gpix = keys // (h * w), keys % (h * w)
    gl_, gh_ = _evaluation_depths(whole, gseg, gpix, eps, w)
    np.maximum.at(hi, gpix, alpha.sup(gl_, gh_, d_lo[gpix], d_hi[gpix], occ_hi[gpix]))
    sure = np.isin(keys, sseg * (h * w) + spix)
    q = gpix[sure]
    np.maximum.at(lo, q, alpha.inf(gl_[sure], gh_[sure], d_lo[q], d_hi[q], occ_lo[q]))
    # where no fragment is sure, α is 0 (none drawn) or at least the least a drawn one has
    np.minimum.at(present, gpix, alpha.drawn_inf(gl_, gh_, d_lo[gpix], d_hi[gpix],
                                                 occ_hi[gpix]))
    zero = lo <= 0
    lo = np.where(zero & np.isfinite(present), np.maximum(lo, present), lo)
    pos_lo, pos_hi = lo > 0, hi > 0
    lo = np.where(pos_lo, np.clip(lo - 16.0 * F32, 0.0, 1.0), 0.0)
    hi = np.where(pos_hi, np.clip(np.maximum(hi + 16.0 * F32, lo), 0.0, 1.0), 0.0)
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.reshape(h, w), hi32.reshape(h, w), zero.reshape(h, w)
