"""Allowances of edge maps ("Goldens with teeth (2)", item 3): intensity intervals propagated
from the G-buffer's allowances through the operator's own footprint by interval arithmetic.

The edge map (:func:`refraster.edges.edge_map`, the paper's operator: diagonal normal filter in
RGB, diagonal depth filter in A, no id edges, no thresholds) at a pixel X reads the G-buffer at
its four diagonal neighbours A, C, F, H (clamp-to-edge) and X's own coverage::

    E_N = 1 − clamp(½ (n_A·n_H + n_C·n_F), 0, 1)        (0 where X is background)
    E_Z = 1 − (1 − ½|z_A − z_H|)² (1 − ½|z_C − z_F|)²

with ``n`` the decoded normal (0 on the background) and ``z`` the linear depth
``clamp((eye − near) / (far − near), 0, 1)`` (1 on the background). Per G-buffer pixel the
golden's allowances say what a conformant GPU may show there
(:mod:`refraster.golden.allowances.core`):
where the visible face must agree, the reference normal within ``normal_angle`` and the eye depth
in ``[eye_depth_lo, eye_depth_hi]``; where it may differ, any entry of the pixel's face set
(its normal cone and eye-depth interval) or, where coverage may differ, the background. Each is
an *option* of the pixel. Then:

* a dot product of two options' normals lies in ``[cos(min(π, θ₀ + α₁ + α₂)),
  cos(max(0, θ₀ − α₁ − α₂))]`` (θ₀ the angle between the cones' axes, α their half-angles), 0
  with the background; ``E_N``'s interval is the image of the sum's interval under the
  monotone ``1 − clamp(·)``, joined with 0 where X may be background;
* ``|z_A − z_H|`` lies in the absolute value of the interval difference, and ``E_Z`` is
  increasing in both ``|Δ|`` (they are ≤ 1), so its bounds are its values at the bounds;
* the texture formats the scene states (``gbuffer_format``, the paper's RGBA8): an 8-bit
  G-buffer stores ``½n + ½`` and z to the nearest of 255 steps — each normal component off by up
  to 1/255, so a dot product by up to ``2·√3/255 + 3/255²``, and z by ½/255; the 8-bit edge map
  rounds its output by ½/255; float32 rounding adds 1e−6;
* ``width > 1``: a grey dilation with the disk of radius ``width − 1`` is monotone, so the
  bounds are the dilated bounds.

The other operators of :func:`refraster.edges.edge_map` read the same options through their
own 3×3 footprint (clamp-to-edge), docs/tolerance.md "Edge maps" has each derivation:

* normal components (Sobel's input): within α of an axis at θ_c from e_c, ``n_c ∈
  [cos(min(π, θ_c + α)), cos(max(0, θ_c − α))]``, 0 on the background, ± the decoding error;
* Sobel (normal ``k_n·√(Σ_c G_y,c² + G_x,c²)/8``, depth ``k_z·√(G_y² + G_x²)/4``): ``G`` is
  linear, so its interval is the weighted sum of the taps' intervals; squares, sums, ``√`` and
  ``min(1, ·)`` are monotone;
* angle ``max_q ½(1 − n_X·n_q)``: the dot-product intervals above, maxima of intervals;
* C1 ``Σ_k w_k |z_k − z_X| / s`` (s = 12 or 8) and ``diagonal2`` (``z_A + z_H − 2 z_X``): sums
  of interval differences, then the monotone maps of the operator;
* thresholds: ``v ↦ v·[v ≥ t]`` is non-decreasing; float32 arithmetic of these operators on a
  GPU: :data:`ARITH`.

Stored: ``edge_map_lo`` / ``edge_map_hi (H, W, 4)`` float32, checked by ``bounds`` (the
interval at every pixel, whatever the visible face). For the Gooch NPR composite
(:func:`npr_color_bounds`): ``npr_color_lo`` / ``npr_color_hi (H, W, 3)`` — t's interval from
each option's normal cone and the light, the clipped linear shade, and the composite's extremes
at the corners of the box of (shade, E_N, E_Z) (it is multilinear in them).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..._config import JIT

__all__ = ["edge_map_bounds", "mean_edge_map_bounds", "npr_color_bounds", "npr_supported",
           "supported"]

Q8 = 1.0 / 255.0


#: :func:`refraster.edges.edge_map`'s operators this module bounds (codes of its kernels)
NORMAL_OPS = {"diagonal": 0, "sobel": 1, "angle": 2}
DEPTH_OPS = {"diagonal": 0, "c1": 1, "c1-paper": 2, "sobel": 3, "diagonal2": 4}
#: float32 arithmetic of the Sobel, C1, angle and second-difference operators on a GPU (a few
#: tens of float32 operations on values ≤ 16, scaled by ≤ ¼; estimated ≤ 3e−6, docs/tolerance.md)
ARITH = 1e-5


def supported(params):
    """Whether :func:`edge_map_bounds` covers the scene's operator: every normal and depth
    filter of :func:`refraster.edges.edge_map`, any thresholds, width and gains; not the id
    edges (``ids=True``)."""
    try:
        t_in = float(params.get("inner_threshold", 0.0))
        t_pr = float(params.get("profile_threshold", 0.0))
        k_n = float(params.get("k_n", 1.0))
        k_z = float(params.get("k_z", 1.0))
        width = int(params.get("width", 1))
    except (TypeError, ValueError):
        return False
    return (params.get("normal_filter") in NORMAL_OPS and params.get("depth_filter") in DEPTH_OPS
            and not params.get("ids") and 0.0 <= t_in <= 1.0 and 0.0 <= t_pr <= 1.0
            and k_n >= 0.0 and k_z >= 0.0 and width >= 1)


@njit(**JIT)
def _dot_bounds(oa, ob, off, nrm, ang, bg, free, ddot, fg_only):
    """Bounds of the dot product of the normals of an option of pixel ``oa`` and one of
    ``ob`` (0 ± ``ddot`` with a background option; [−1, 1] ± ``ddot`` where either pixel is
    free). ``fg_only``: over the foreground options of ``oa`` only (the angle operator: where X
    shows the background its E_N is 0 whatever the dot product), (1, 1) if it has none."""
    if free[oa] or free[ob]:
        return -1.0 - ddot, 1.0 + ddot
    lo = np.inf
    hi = -np.inf
    for i in range(off[oa], off[oa + 1]):
        if fg_only and bg[i]:
            continue
        for j in range(off[ob], off[ob + 1]):
            if bg[i] or bg[j]:
                lo = min(lo, -ddot)
                hi = max(hi, ddot)
                continue
            c = nrm[i, 0] * nrm[j, 0] + nrm[i, 1] * nrm[j, 1] + nrm[i, 2] * nrm[j, 2]
            t0 = math.acos(min(max(c, -1.0), 1.0))
            a = ang[i] + ang[j]
            lo = min(lo, math.cos(min(math.pi, t0 + a)) - ddot)
            hi = max(hi, math.cos(max(0.0, t0 - a)) + ddot)
    if fg_only and lo > hi:     # no foreground option
        return 1.0, 1.0
    return lo, hi


@njit(**JIT)
def _absdiff(alo, ahi, blo, bhi):
    """Bounds of |a − b| for a ∈ [alo, ahi], b ∈ [blo, bhi]."""
    dlo = alo - bhi
    dhi = ahi - blo
    if dlo >= 0.0:
        return dlo, dhi
    if dhi <= 0.0:
        return -dhi, -dlo
    return 0.0, max(-dlo, dhi)


@njit(**JIT)
def _diagonals(y, x, h, w):
    """Flat indices of the diagonal neighbours A, C, F, H of pixel (y, x) (clamp-to-edge) and
    of the pixel itself."""
    ym = max(y - 1, 0)
    yp = min(y + 1, h - 1)
    xm = max(x - 1, 0)
    xp = min(x + 1, w - 1)
    return ym * w + xm, ym * w + xp, yp * w + xm, yp * w + xp, y * w + x


@njit(**JIT)
def _bounds_kernel(off, nrm, ang, bg, zlo, zhi, free, may_bg, may_fg, ddot, dz, dout, lo, hi):
    h, w = lo.shape[:2]
    for y in range(h):
        for x in range(w):
            pa, pc, pf, ph, p = _diagonals(y, x, h, w)
            # inner edges (RGB)
            ah_lo, ah_hi = _dot_bounds(pa, ph, off, nrm, ang, bg, free, ddot, False)
            cf_lo, cf_hi = _dot_bounds(pc, pf, off, nrm, ang, bg, free, ddot, False)
            i_lo = 0.5 * (ah_lo + cf_lo)
            i_hi = 0.5 * (ah_hi + cf_hi)
            en_lo = 1.0 - min(max(i_hi, 0.0), 1.0)
            en_hi = 1.0 - min(max(i_lo, 0.0), 1.0)
            if not may_fg[p] and not free[p]:
                en_lo = 0.0
                en_hi = 0.0
            elif may_bg[p] or free[p]:
                en_lo = 0.0
            # profile edges (A)
            _store(lo, hi, y, x, en_lo, en_hi, zlo[pa], zhi[pa], zlo[ph], zhi[ph], zlo[pc],
                   zhi[pc], zlo[pf], zhi[pf], dz, dout)


@njit(**JIT)
def _store(lo, hi, y, x, en_lo, en_hi, alo, ahi, hlo, hhi, clo, chi, flo, fhi, dz, dout):
    """Pixel (y, x) of the diagonal operators' bounds: ``E_N ∈ [en_lo, en_hi]`` in RGB and
    ``E_Z`` from the depth intervals of A, H, C, F (each ± ``dz``) in A, ± ``dout``."""
    d1lo, d1hi = _absdiff(alo - dz, ahi + dz, hlo - dz, hhi + dz)
    d2lo, d2hi = _absdiff(clo - dz, chi + dz, flo - dz, fhi + dz)
    d1lo, d1hi = min(d1lo, 1.0), min(d1hi, 1.0)
    d2lo, d2hi = min(d2lo, 1.0), min(d2hi, 1.0)
    a_hi, a_lo = 1.0 - 0.5 * d1lo, 1.0 - 0.5 * d1hi
    b_hi, b_lo = 1.0 - 0.5 * d2lo, 1.0 - 0.5 * d2hi
    ez_lo = 1.0 - (a_hi * a_hi) * (b_hi * b_hi)
    ez_hi = 1.0 - (a_lo * a_lo) * (b_lo * b_lo)
    for c in range(3):
        lo[y, x, c] = max(en_lo - dout, 0.0)
        hi[y, x, c] = min(en_hi + dout, 1.0)
    lo[y, x, 3] = max(ez_lo - dout, 0.0)
    hi[y, x, 3] = min(ez_hi + dout, 1.0)


@njit(**JIT)
def _component_bounds(off, nrm, ang, bg, free, dn, clo, chi):
    """Per pixel and channel, the interval of a decoded normal component over the pixel's
    options: a unit vector within α of an axis at θ_c from the channel's axis e_c has
    ``n_c = cos ∠(n, e_c) ∈ [cos(min(π, θ_c + α)), cos(max(0, θ_c − α))]``; 0 on the
    background; ``dn`` the decoding error of the texture format."""
    n_pix = len(off) - 1
    for p in range(n_pix):
        if free[p]:
            for c in range(3):
                clo[p, c] = -1.0 - dn
                chi[p, c] = 1.0 + dn
            continue
        for c in range(3):
            clo[p, c] = np.inf
            chi[p, c] = -np.inf
        for i in range(off[p], off[p + 1]):
            if bg[i]:
                for c in range(3):
                    clo[p, c] = min(clo[p, c], -dn)
                    chi[p, c] = max(chi[p, c], dn)
                continue
            length = math.sqrt(nrm[i, 0] * nrm[i, 0] + nrm[i, 1] * nrm[i, 1]
                               + nrm[i, 2] * nrm[i, 2])
            for c in range(3):
                t = math.acos(min(max(nrm[i, c] / length, -1.0), 1.0)) if length > 0 else 0.5 * math.pi
                a = ang[i] if length > 0 else math.pi
                clo[p, c] = min(clo[p, c], math.cos(min(math.pi, t + a)) - dn)
                chi[p, c] = max(chi[p, c], math.cos(max(0.0, t - a)) + dn)


@njit(**JIT)
def _lin(wlo, whi, plo, phi, q):
    """Add ``w·[plo, phi]`` to ``[wlo, whi]`` (interval arithmetic)."""
    if q >= 0.0:
        return wlo + q * plo, whi + q * phi
    return wlo + q * phi, whi + q * plo


@njit(**JIT)
def _sq(lo, hi):
    """Bounds of x² for x ∈ [lo, hi]."""
    if lo >= 0.0:
        return lo * lo, hi * hi
    if hi <= 0.0:
        return hi * hi, lo * lo
    return 0.0, max(lo * lo, hi * hi)


@njit(**JIT)
def _sobel_bounds(lo3, hi3, y, x, h, w, c):
    """Bounds of (G_y, G_x) of channel c of the 3×3 neighbourhood (clamp-to-edge): the
    operator is linear, so each is the weighted sum of its taps' intervals."""
    ym = max(y - 1, 0)
    yp = min(y + 1, h - 1)
    xm = max(x - 1, 0)
    xp = min(x + 1, w - 1)
    gylo = 0.0
    gyhi = 0.0
    gxlo = 0.0
    gxhi = 0.0
    # G_y = (F + 2G + H) − (A + 2B + C); G_x = (C + 2E + H) − (A + 2D + F)
    for (yy, xx, wy, wx) in ((ym, xm, -1.0, -1.0), (ym, x, -2.0, 0.0), (ym, xp, -1.0, 1.0),
                             (y, xm, 0.0, -2.0), (y, xp, 0.0, 2.0),
                             (yp, xm, 1.0, -1.0), (yp, x, 2.0, 0.0), (yp, xp, 1.0, 1.0)):
        p = yy * w + xx
        gylo, gyhi = _lin(gylo, gyhi, lo3[p, c], hi3[p, c], wy)
        gxlo, gxhi = _lin(gxlo, gxhi, lo3[p, c], hi3[p, c], wx)
    return gylo, gyhi, gxlo, gxhi


@njit(**JIT)
def _normal_op_kernel(method, off, nrm, ang, bg, free, may_bg, may_fg, clo, chi, k_n, ddot,
                      lo, hi):
    """E_N bounds of the Sobel (method 1) and angle (method 2) normal operators."""
    h, w = lo.shape
    for y in range(h):
        for x in range(w):
            p = y * w + x
            if method == 1:
                # E_N = min(1, k_n·sqrt(Σ_c G_y,c² + G_x,c²)/8): monotone in each square
                slo = 0.0
                shi = 0.0
                for c in range(3):
                    gylo, gyhi, gxlo, gxhi = _sobel_bounds(clo, chi, y, x, h, w, c)
                    a, b = _sq(gylo, gyhi)
                    slo += a
                    shi += b
                    a, b = _sq(gxlo, gxhi)
                    slo += a
                    shi += b
                en_lo = min(k_n * math.sqrt(slo) / 8.0, 1.0)
                en_hi = min(k_n * math.sqrt(shi) / 8.0, 1.0)
            else:
                # E_N = min(1, max_q ½(1 − n_X·n_q)): X's foreground options against each
                # neighbour's options
                ym = max(y - 1, 0)
                yp = min(y + 1, h - 1)
                xm = max(x - 1, 0)
                xp = min(x + 1, w - 1)
                en_lo = 0.0
                en_hi = 0.0
                for (yy, xx) in ((ym, xm), (ym, x), (ym, xp), (y, xm), (y, xp), (yp, xm),
                                 (yp, x), (yp, xp)):
                    dlo, dhi = _dot_bounds(p, yy * w + xx, off, nrm, ang, bg, free, ddot, True)
                    en_lo = max(en_lo, 0.5 * (1.0 - dhi))
                    en_hi = max(en_hi, 0.5 * (1.0 - dlo))
                en_lo = min(en_lo, 1.0)
                en_hi = min(en_hi, 1.0)
            if not may_fg[p] and not free[p]:
                en_lo = 0.0
                en_hi = 0.0
            elif may_bg[p] or free[p]:
                en_lo = 0.0
            lo[y, x] = en_lo
            hi[y, x] = en_hi


@njit(**JIT)
def _depth_op_kernel(method, zlo, zhi, k_z, lo, hi):
    """E_Z bounds of the C1 (1: /12, 2: /8), Sobel (3) and second-difference diagonal (4)
    depth operators from the per-pixel depth intervals ``[zlo, zhi]`` (quantisation and
    rounding already added)."""
    h, w = lo.shape
    for y in range(h):
        for x in range(w):
            ym = max(y - 1, 0)
            yp = min(y + 1, h - 1)
            xm = max(x - 1, 0)
            xp = min(x + 1, w - 1)
            p = y * w + x
            if method == 1 or method == 2:
                # E = min(1, Σ_k w_k |z_k − z_X| / s): each term bounded alone (sound; X's
                # interval enters every term)
                slo = 0.0
                shi = 0.0
                for (yy, xx, wk) in ((ym, xm, 1.0), (ym, x, 2.0), (ym, xp, 1.0),
                                     (y, xm, 2.0), (y, xp, 2.0),
                                     (yp, xm, 1.0), (yp, x, 2.0), (yp, xp, 1.0)):
                    q = yy * w + xx
                    dlo, dhi = _absdiff(zlo[q], zhi[q], zlo[p], zhi[p])
                    slo += wk * dlo
                    shi += wk * dhi
                s = 12.0 if method == 1 else 8.0
                lo[y, x] = min(slo / s, 1.0)
                hi[y, x] = min(shi / s, 1.0)
            elif method == 3:
                # E = min(1, k_z·sqrt(G_y² + G_x²)/4)
                gylo = 0.0
                gyhi = 0.0
                gxlo = 0.0
                gxhi = 0.0
                for (yy, xx, wy, wx) in ((ym, xm, -1.0, -1.0), (ym, x, -2.0, 0.0),
                                         (ym, xp, -1.0, 1.0), (y, xm, 0.0, -2.0),
                                         (y, xp, 0.0, 2.0), (yp, xm, 1.0, -1.0),
                                         (yp, x, 2.0, 0.0), (yp, xp, 1.0, 1.0)):
                    q = yy * w + xx
                    gylo, gyhi = _lin(gylo, gyhi, zlo[q], zhi[q], wy)
                    gxlo, gxhi = _lin(gxlo, gxhi, zlo[q], zhi[q], wx)
                a0, a1 = _sq(gylo, gyhi)
                b0, b1 = _sq(gxlo, gxhi)
                lo[y, x] = min(k_z * math.sqrt(a0 + b0) / 4.0, 1.0)
                hi[y, x] = min(k_z * math.sqrt(a1 + b1) / 4.0, 1.0)
            else:
                # d_AH = z_A + z_H − 2 z_X, d_CF = z_C + z_F − 2 z_X (|d| ≤ 2, where
                # 1 − (1 − ½|d_AH|)²(1 − ½|d_CF|)² is increasing in both)
                pa, pc, pf, ph = ym * w + xm, ym * w + xp, yp * w + xm, yp * w + xp
                d1lo, d1hi = _absdiff(zlo[pa] + zlo[ph], zhi[pa] + zhi[ph],
                                      2.0 * zlo[p], 2.0 * zhi[p])
                d2lo, d2hi = _absdiff(zlo[pc] + zlo[pf], zhi[pc] + zhi[pf],
                                      2.0 * zlo[p], 2.0 * zhi[p])
                d1lo, d1hi = min(d1lo, 2.0), min(d1hi, 2.0)
                d2lo, d2hi = min(d2lo, 2.0), min(d2hi, 2.0)
                a_hi, a_lo = 1.0 - 0.5 * d1lo, 1.0 - 0.5 * d1hi
                b_hi, b_lo = 1.0 - 0.5 * d2lo, 1.0 - 0.5 * d2hi
                lo[y, x] = 1.0 - (a_hi * a_hi) * (b_hi * b_hi)
                hi[y, x] = 1.0 - (a_lo * a_lo) * (b_lo * b_lo)


def _options(arrays, buffers, near, far):
    """Per G-buffer pixel, its options as CSR: normal cone, linear-depth interval,
    background; ``free`` where nothing bounds the pixel."""
    from ...conformance import MUST, MUST_NOT
    normal = np.asarray(buffers["normal"], np.float64)
    h, w = normal.shape[:2]
    cov = np.asarray(arrays["coverage"])
    id_may = np.asarray(arrays["id_may"], np.bool_)
    span = far - near

    def lin(e):
        with np.errstate(invalid="ignore"):
            return np.clip((np.asarray(e, np.float64) - near) / span, 0.0, 1.0)

    n_pix = h * w
    sure = ~id_may.ravel()
    fg_sure = sure & (cov.ravel() != MUST_NOT)
    bg_sure = sure & (cov.ravel() == MUST_NOT)
    set_off = arrays["set_offsets"].astype(np.int64)
    n_set = np.where(id_may.ravel(), np.diff(set_off), 0)
    add_bg = id_may.ravel() & (cov.ravel() != MUST)
    count = fg_sure.astype(np.int64) + bg_sure + n_set + add_bg
    off = np.zeros(n_pix + 1, np.int64)
    off[1:] = np.cumsum(count)
    n = int(off[-1])
    nrm = np.zeros((n, 3))
    ang = np.zeros(n)
    bg = np.zeros(n, np.bool_)
    zlo = np.ones(n)
    zhi = np.ones(n)
    cursor = off[:-1].copy()
    # the sure foreground: the reference's normal and eye-depth interval
    k = np.flatnonzero(fg_sure)
    e = cursor[k]
    nrm[e] = normal.reshape(-1, 3)[k]
    ang[e] = np.asarray(arrays["normal_angle"], np.float64).ravel()[k]
    zlo[e] = lin(np.asarray(arrays["eye_depth_lo"]).ravel()[k])
    zhi[e] = lin(np.asarray(arrays["eye_depth_hi"]).ravel()[k])
    cursor[k] += 1
    # the sure background
    k = np.flatnonzero(bg_sure)
    bg[cursor[k]] = True
    cursor[k] += 1
    # face-set entries
    k = np.flatnonzero(n_set > 0)
    if len(k):
        reps = n_set[k]
        src = np.repeat(set_off[k], reps) + (np.arange(reps.sum())
                                             - np.repeat(np.cumsum(reps) - reps, reps))
        dst = np.repeat(cursor[k], reps) + (np.arange(reps.sum())
                                            - np.repeat(np.cumsum(reps) - reps, reps))
        nrm[dst] = arrays["set_normal"][src]
        ang[dst] = np.minimum(arrays["set_normal_angle"][src].astype(np.float64), math.pi)
        zlo[dst] = lin(arrays["set_eye_depth_lo"][src])
        zhi[dst] = lin(arrays["set_eye_depth_hi"][src])
        # an unbounded eye depth (a sliver) spans the whole range
        zlo[dst] = np.where(np.isfinite(arrays["set_eye_depth_lo"][src]), zlo[dst], 0.0)
        zhi[dst] = np.where(np.isfinite(arrays["set_eye_depth_hi"][src]), zhi[dst], 1.0)
        cursor[k] += reps
    k = np.flatnonzero(add_bg)
    bg[cursor[k]] = True
    cursor[k] += 1
    free = count == 0
    may_bg = np.zeros(n_pix, np.bool_)
    may_fg = np.zeros(n_pix, np.bool_)
    pix = np.repeat(np.arange(n_pix), count)
    np.logical_or.at(may_bg, pix, bg)
    np.logical_or.at(may_fg, pix, ~bg)
    # per pixel, the envelope of its options' depths
    zl = np.ones(n_pix)
    zh = np.zeros(n_pix)
    np.minimum.at(zl, pix, zlo)
    np.maximum.at(zh, pix, zhi)
    zl[free] = 0.0
    zh[free] = 1.0
    return off, nrm, ang, bg, zl, zh, free, may_bg, may_fg


def edge_map_bounds(arrays, buffers, params, near, far, *, gbuffer_format="rgba8",
                    output_format="rgba8"):
    """``(lo, hi)``, each ``(H, W, 4)`` float32: what a conformant edge map may hold."""
    off, nrm, ang, bg, zl, zh, free, may_bg, may_fg = _options(arrays, buffers, near, far)
    h, w = np.asarray(buffers["normal"]).shape[:2]
    q_in = Q8 if gbuffer_format == "rgba8" else 0.0
    ddot = 2.0 * math.sqrt(3.0) * q_in + 3.0 * q_in * q_in + 1e-6
    dz = 0.5 * q_in + 1e-6
    dout = (0.5 * Q8 if output_format == "rgba8" else 0.0) + 1e-6
    lo = np.zeros((h, w, 4))
    hi = np.zeros((h, w, 4))
    nmethod = NORMAL_OPS[params.get("normal_filter", "diagonal")]
    zmethod = DEPTH_OPS[params.get("depth_filter", "diagonal")]
    if nmethod == 0 or zmethod == 0:
        # the paper's diagonal operators
        _bounds_kernel(off, nrm, ang, bg, zl, zh, free, may_bg, may_fg, ddot, dz, dout, lo, hi)
    if nmethod != 0:
        clo = np.zeros((h * w, 3))
        chi = np.zeros((h * w, 3))
        # a decoded component is off by ≤ 1/255 in RGBA8 (½/255 encoded, times 2), ≤ 1e−6
        # in float32
        _component_bounds(off, nrm, ang, bg, free, 2.0 * 0.5 * q_in + 1e-6, clo, chi)
        en_lo = np.zeros((h, w))
        en_hi = np.zeros((h, w))
        _normal_op_kernel(nmethod, off, nrm, ang, bg, free, may_bg, may_fg, clo, chi,
                          float(params.get("k_n", 1.0)), ddot, en_lo, en_hi)
        for c in range(3):
            lo[..., c] = np.maximum(en_lo - dout - ARITH, 0.0)
            hi[..., c] = np.minimum(en_hi + dout + ARITH, 1.0)
    if zmethod != 0:
        ez_lo = np.zeros((h, w))
        ez_hi = np.zeros((h, w))
        _depth_op_kernel(zmethod, (zl - dz).ravel(), (zh + dz).ravel(),
                         float(params.get("k_z", 1.0)), ez_lo, ez_hi)
        lo[..., 3] = np.maximum(ez_lo - dout - ARITH, 0.0)
        hi[..., 3] = np.minimum(ez_hi + dout + ARITH, 1.0)
    # thresholds: v ↦ v·[v ≥ t] is non-decreasing, so the bounds map to their images
    for chans, key in (((0, 1, 2), "inner_threshold"), ((3,), "profile_threshold")):
        t = float(params.get(key, 0.0))
        if t > 0.0:
            for c in chans:
                lo[..., c] = np.where(lo[..., c] >= t, lo[..., c], 0.0)
                hi[..., c] = np.where(hi[..., c] >= t, hi[..., c], 0.0)
    width = int(params.get("width", 1))
    if width > 1:
        from skimage.morphology import dilation, disk
        foot = disk(width - 1)
        for c in range(4):
            lo[..., c] = dilation(lo[..., c], foot)
            hi[..., c] = dilation(hi[..., c], foot)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


@njit(**JIT)
def _mean_dot_bounds(pa, ph, n_pix, n_samples, off, nrm, ang, bg, free, ddot):
    """Bounds of the dot product of the box-filtered normals of pixels ``pa`` and ``ph``
    (sample ``s``'s options at ``p + s·n_pix``): ``n̄_A·n̄_H = (1/S²) Σ_{s,t} n_{A,s}·n_{H,t}``,
    so its interval is the mean of the pairs' intervals (:func:`_dot_bounds` without its
    rounding term; ``ddot`` added once, for the resolved texture)."""
    lo = 0.0
    hi = 0.0
    for s in range(n_samples):
        for t in range(n_samples):
            a, b = _dot_bounds(pa + s * n_pix, ph + t * n_pix, off, nrm, ang, bg, free, 0.0,
                               False)
            lo += a
            hi += b
    k = float(n_samples * n_samples)
    return lo / k - ddot, hi / k + ddot


@njit(**JIT)
def _mean_bounds_kernel(off, nrm, ang, bg, zlo, zhi, free, n_samples, ddot, dz, dout, lo, hi):
    """:func:`_bounds_kernel` on the G-buffer resolved by the box filter (normals and linear
    depths averaged over the samples, ids — so the background test at X — from sample 0)."""
    h, w = lo.shape[:2]
    n_pix = h * w
    for y in range(h):
        for x in range(w):
            pa, pc, pf, ph, p = _diagonals(y, x, h, w)
            ah_lo, ah_hi = _mean_dot_bounds(pa, ph, n_pix, n_samples, off, nrm, ang, bg, free,
                                            ddot)
            cf_lo, cf_hi = _mean_dot_bounds(pc, pf, n_pix, n_samples, off, nrm, ang, bg, free,
                                            ddot)
            i_lo = 0.5 * (ah_lo + cf_lo)
            i_hi = 0.5 * (ah_hi + cf_hi)
            en_lo = 1.0 - min(max(i_hi, 0.0), 1.0)
            en_hi = 1.0 - min(max(i_lo, 0.0), 1.0)
            may_bg = free[p]
            may_fg = free[p]
            for i in range(off[p], off[p + 1]):
                if bg[i]:
                    may_bg = True
                else:
                    may_fg = True
            if not may_fg:
                en_lo = 0.0
                en_hi = 0.0
            elif may_bg:
                en_lo = 0.0
            # the mean depth of each diagonal neighbour: the mean of its samples' intervals
            zs = np.zeros((4, 2))
            for k, q in enumerate((pa, ph, pc, pf)):
                for s in range(n_samples):
                    zs[k, 0] += zlo[q + s * n_pix]
                    zs[k, 1] += zhi[q + s * n_pix]
            zs /= n_samples
            _store(lo, hi, y, x, en_lo, en_hi, zs[0, 0], zs[0, 1], zs[1, 0], zs[1, 1],
                   zs[2, 0], zs[2, 1], zs[3, 0], zs[3, 1], dz, dout)


def mean_edge_map_bounds(per_arrays, per_buffers, params, near, far, *,
                         gbuffer_format="rgba8", output_format="rgba8"):
    """``(lo, hi)``, each ``(H, W, 4)`` float32: what a conformant edge map of the G-buffer
    resolved by the box filter (``GBufferSampling("resolved", resolve="average")``) may hold,
    from each sample's allowances ``per_arrays[s]`` and buffers ``per_buffers[s]`` (the
    paper's diagonal operators only).

    Each sample's options (:func:`_options`) bound its normal and depth; the resolved texture
    holds their means, so a dot product of two resolved normals lies in the mean of the S²
    pairs' intervals and a resolved depth in the mean of the samples' intervals (the mean is
    increasing in each term). An RGBA8 G-buffer rounds each sample (½/255) and the resolve
    rounds the mean (≤ 1/255 more: to nearest or toward zero): an encoded value is off by
    ≤ 1.5/255, a decoded component by δ ≤ 3/255, a dot product of two such by ≤ 2·√3·δ + 3·δ²,
    a depth by ≤ 1.5/255."""
    if params.get("normal_filter", "diagonal") != "diagonal" \
            or params.get("depth_filter", "diagonal") != "diagonal" \
            or not supported(params) or float(params.get("inner_threshold", 0.0)) > 0.0 \
            or float(params.get("profile_threshold", 0.0)) > 0.0 \
            or int(params.get("width", 1)) != 1:
        raise ValueError("the edge map of a G-buffer resolved by 'average' has allowances for "
                         "the paper's operator only (diagonal filters, no ids, no thresholds, "
                         "width 1)")
    parts = [_options(a, b, near, far) for a, b in zip(per_arrays, per_buffers)]
    h, w = np.asarray(per_buffers[0]["normal"]).shape[:2]
    n_pix = h * w
    offs = [p[0] for p in parts]
    base = np.cumsum([0] + [int(o[-1]) for o in offs[:-1]])
    off = np.concatenate([o[:-1] + b for o, b in zip(offs, base)] + [[base[-1] + offs[-1][-1]]])
    off = off.astype(np.int64)
    nrm = np.concatenate([p[1] for p in parts])
    ang = np.concatenate([p[2] for p in parts])
    bg = np.concatenate([p[3] for p in parts])
    zl = np.concatenate([p[4] for p in parts])
    zh = np.concatenate([p[5] for p in parts])
    free = np.concatenate([p[6] for p in parts])
    assert len(off) == len(parts) * n_pix + 1
    q_in = 3.0 * Q8 if gbuffer_format == "rgba8" else 0.0    # δ, a decoded component
    ddot = 2.0 * math.sqrt(3.0) * q_in + 3.0 * q_in * q_in + 1e-6
    dz = 0.5 * q_in + 1e-6
    dout = (0.5 * Q8 if output_format == "rgba8" else 0.0) + 1e-6
    lo = np.zeros((h, w, 4))
    hi = np.zeros((h, w, 4))
    _mean_bounds_kernel(off, nrm, ang, bg, zl, zh, free, len(parts), ddot, dz, dout, lo, hi)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def npr_supported(params):
    """Whether :func:`npr_color_bounds` covers the scene's composite (Gooch + edge map)."""
    npr = params.get("npr")
    return (isinstance(npr, dict) and npr.get("style") == "gooch"
            and npr.get("mask") == "objects"
            and all(k in npr for k in ("light", "base", "cool", "warm", "alpha", "beta",
                                       "background", "inner_color", "profile_color")))


@njit(**JIT)
def _npr_kernel(off, nrm, ang, bg, free, light, k_cool, k_warm, background, ci, cp, elo, ehi,
                dcol, lo, hi):
    h, w = lo.shape[:2]
    for y in range(h):
        for x in range(w):
            p = y * w + x
            for c in range(3):
                lo[y, x, c] = np.inf
                hi[y, x, c] = -np.inf
            if free[p]:
                for c in range(3):
                    lo[y, x, c] = 0.0
                    hi[y, x, c] = 1.0
                continue
            # t = ½(1 + n·l) over the pixel's foreground options
            tlo = np.inf
            thi = -np.inf
            for i in range(off[p], off[p + 1]):
                if bg[i]:
                    # composite masked off: the shade there is the background colour
                    for c in range(3):
                        lo[y, x, c] = min(lo[y, x, c], background[c])
                        hi[y, x, c] = max(hi[y, x, c], background[c])
                    continue
                length = math.sqrt(nrm[i, 0] * nrm[i, 0] + nrm[i, 1] * nrm[i, 1]
                                   + nrm[i, 2] * nrm[i, 2])
                cl = (nrm[i, 0] * light[0] + nrm[i, 1] * light[1] + nrm[i, 2] * light[2]) / length
                t0 = math.acos(min(max(cl, -1.0), 1.0))
                tlo = min(tlo, 0.5 * (1.0 + math.cos(min(math.pi, t0 + ang[i]))))
                thi = max(thi, 0.5 * (1.0 + math.cos(max(0.0, t0 - ang[i]))))
            if tlo > thi:
                continue
            en_lo, en_hi = elo[y, x, 0], ehi[y, x, 0]
            ez_lo, ez_hi = elo[y, x, 3], ehi[y, x, 3]
            for c in range(3):
                # shade = clip(t·k_warm + (1 − t)·k_cool): linear in t, then clipped
                s1 = min(max(tlo * k_warm[c] + (1.0 - tlo) * k_cool[c], 0.0), 1.0)
                s2 = min(max(thi * k_warm[c] + (1.0 - thi) * k_cool[c], 0.0), 1.0)
                slo, shi = min(s1, s2), max(s1, s2)
                # out = (1 − E_Z)((1 − E_N)·s + E_N·c_i) + E_Z·c_p: multilinear in
                # (s, E_N, E_Z), so its extremes over the box are at corners
                for s in (slo, shi):
                    for en in (en_lo, en_hi):
                        for ez in (ez_lo, ez_hi):
                            v = (1.0 - ez) * ((1.0 - en) * s + en * ci[c]) + ez * cp[c]
                            lo[y, x, c] = min(lo[y, x, c], v)
                            hi[y, x, c] = max(hi[y, x, c], v)
            for c in range(3):
                lo[y, x, c] = lo[y, x, c] - dcol
                hi[y, x, c] = hi[y, x, c] + dcol


def npr_color_bounds(arrays, buffers, params, near, far, edge_lo, edge_hi):
    """``(lo, hi)``, each ``(H, W, 3)`` float32: what a conformant ``npr_color`` may hold —
    Gooch shading of each option's normal cone composited with the edge map's interval
    (``edge_lo`` / ``edge_hi`` from :func:`edge_map_bounds`), or the background colour where
    the pixel may show the background."""
    npr = params["npr"]
    off, nrm, ang, bg, _zl, _zh, free, _may_bg, _may_fg = _options(arrays, buffers, near, far)
    h, w = np.asarray(buffers["normal"]).shape[:2]
    light = np.asarray(npr["light"], np.float64)
    light = light / np.linalg.norm(light)
    kd = np.asarray(npr["base"], np.float64)
    k_cool = np.asarray(npr["cool"], np.float64) + float(npr["alpha"]) * kd
    k_warm = np.asarray(npr["warm"], np.float64) + float(npr["beta"]) * kd
    # float32 arithmetic (ARITH) and a target that may be RGBA8 (½/255)
    dcol = 0.5 * Q8 + ARITH
    lo = np.zeros((h, w, 3))
    hi = np.zeros((h, w, 3))
    _npr_kernel(off, nrm, ang, bg, free, light, k_cool, k_warm,
                np.asarray(npr["background"], np.float64),
                np.asarray(npr["inner_color"], np.float64),
                np.asarray(npr["profile_color"], np.float64),
                np.asarray(edge_lo, np.float64), np.asarray(edge_hi, np.float64), dcol, lo, hi)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)
