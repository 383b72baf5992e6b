"""Allowances of edge maps ("Goldens with teeth (2)", item 3): intensity intervals propagated
from the G-buffer's allowances through the operator's own footprint by interval arithmetic.

The edge map (:func:`refraster.edges.edge_map`, the paper's operator: diagonal normal filter in
RGB, diagonal depth filter in A, no id edges, no thresholds) at a pixel X reads the G-buffer at
its four diagonal neighbours A, C, F, H (clamp-to-edge) and X's own coverage::

    E_N = 1 − clamp(½ (n_A·n_H + n_C·n_F), 0, 1)        (0 where X is background)
    E_Z = 1 − (1 − ½|z_A − z_H|)² (1 − ½|z_C − z_F|)²

with ``n`` the decoded normal (0 on the background) and ``z`` the linear depth
``clamp((eye − near) / (far − near), 0, 1)`` (1 on the background). Per G-buffer pixel the
golden's allowances say what a conformant GPU may show there (:mod:`refraster.golden.allowance`):
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

Stored: ``edge_map_lo`` / ``edge_map_hi (H, W, 4)`` float32, checked by ``bounds`` (the
interval at every pixel, whatever the visible face).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._config import JIT

__all__ = ["edge_map_bounds", "supported"]

Q8 = 1.0 / 255.0


def supported(params):
    """Whether :func:`edge_map_bounds` covers the scene's operator."""
    return (params.get("normal_filter") == "diagonal" and params.get("depth_filter") == "diagonal"
            and not params.get("ids") and float(params.get("inner_threshold", 1)) == 0.0
            and float(params.get("profile_threshold", 1)) == 0.0
            and float(params.get("k_n", 1.0)) == 1.0 and float(params.get("k_z", 1.0)) == 1.0)


@njit(**JIT)
def _dot_bounds(oa, ob, off, nrm, ang, bg, free, ddot):
    lo = np.inf
    hi = -np.inf
    for i in range(off[oa], off[oa + 1]):
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
    if free[oa] or free[ob]:
        lo = -1.0 - ddot
        hi = 1.0 + ddot
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
def _bounds_kernel(off, nrm, ang, bg, zlo, zhi, free, may_bg, may_fg, ddot, dz, dout, lo, hi):
    h, w = lo.shape[:2]
    for y in range(h):
        for x in range(w):
            ym = max(y - 1, 0)
            yp = min(y + 1, h - 1)
            xm = max(x - 1, 0)
            xp = min(x + 1, w - 1)
            pa, pc, pf, ph = ym * w + xm, ym * w + xp, yp * w + xm, yp * w + xp
            p = y * w + x
            # inner edges (RGB)
            ah_lo, ah_hi = _dot_bounds(pa, ph, off, nrm, ang, bg, free, ddot)
            cf_lo, cf_hi = _dot_bounds(pc, pf, off, nrm, ang, bg, free, ddot)
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
            d1lo, d1hi = _absdiff(zlo[pa] - dz, zhi[pa] + dz, zlo[ph] - dz, zhi[ph] + dz)
            d2lo, d2hi = _absdiff(zlo[pc] - dz, zhi[pc] + dz, zlo[pf] - dz, zhi[pf] + dz)
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


def _options(arrays, buffers, near, far):
    """Per G-buffer pixel, its options as CSR: normal cone, linear-depth interval,
    background; ``free`` where nothing bounds the pixel."""
    from ..tolerance import MUST, MUST_NOT
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
    _bounds_kernel(off, nrm, ang, bg, zl, zh, free, may_bg, may_fg, ddot, dz, dout, lo, hi)
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
