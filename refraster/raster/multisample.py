"""The multisample tile pass: coverage, depth and the depth test per sample.

The same fixed-point edge functions and fill rule as the single-sample rasterizer
(:mod:`refraster.raster.rasterizer`), evaluated at each sample instead of the pixel centre: a
sample at offset ``(ox, oy)`` from the centre (fixed point, picture-up; :mod:`.samples`) has
``E_k + dx_k·oy − dy_k·ox`` (exact int64) and is covered when every biased value is ≥ 0. The
window depth of a sample is the depth plane through the unsnapped vertices at the sample's
position, in float64, clamped to [0, 1] and rounded to float32, and the depth test runs per
sample (ties to the first fragment drawn, as at one sample). Attributes (the barycentrics) are
interpolated, per winning fragment, at

* ``"center"``: the pixel centre (extrapolated where the centre is outside the triangle, as a
  GPU's non-centroid interpolation);
* ``"centroid"``: the centre when the primitive covers every sample of the pixel, else its
  covered sample nearest the centre (the lowest index among equals) — a point inside both
  the pixel and the primitive, as Vulkan and OpenGL allow;
* ``"sample"``: the sample's own position (sample shading).

Triangle boxes are widened by half a pixel (``setup_triangles(pad=)``), so a triangle that
covers samples but no pixel centre is rasterized.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from .._scratch import OUTPUTS
from .rasterizer import (NO_ITEM, TILE, TILE_SHIFT, _box_in_tile, _edge, _geometry, _setup,
                         _setup_winner, bin_primitives, depth_test, face_image_limit,
                         perspective_bary, tile_rect)

#: The widest box (pixels) whose samples :func:`_msaa_pass` tests pixel by pixel instead of
#: walking each edge's span down the rows.
NARROW = 8

#: ``RasterState.interpolation`` names and the kernel's codes.
INTERPOLATIONS = {"center": 0, "centroid": 1, "sample": 2}


@njit(**IJIT)
def _depth_at(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, cx, cy, l0, l1, l2):
    """Window depth at ``(cx, cy)``: the plane through the unsnapped vertices (the snapped
    barycentrics ``l`` when snapping flattened the triangle), clamped, float32."""
    if inv_af > 0.0:
        z = np.float64(z0) + dzdx * (cx - fx0) + dzdy * (cy - fy0)
    else:
        z = l0 * np.float64(z0) + l1 * np.float64(z1) + l2 * np.float64(z2)
    if z < 0.0:
        z = 0.0
    elif z > 1.0:
        z = 1.0
    return np.float32(z)


@njit(**IJIT)
def _lambdas_at(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, cx, cy, e0, e1, e2, inv_area):
    """Screen-space barycentrics at ``(cx, cy)`` (unbiased snapped edge values ``e`` there for
    the fallback), as :func:`refraster.raster.rasterizer.lambdas` at a pixel centre."""
    if inv_af > 0.0:
        l0 = ((fx2 - fx1) * (cy - fy1) - (fy2 - fy1) * (cx - fx1)) * inv_af
        l1 = ((fx0 - fx2) * (cy - fy2) - (fy0 - fy2) * (cx - fx2)) * inv_af
        l2 = ((fx1 - fx0) * (cy - fy0) - (fy1 - fy0) * (cx - fx0)) * inv_af
        return l0, l1, l2
    return np.float64(e0) * inv_area, np.float64(e1) * inv_area, np.float64(e2) * inv_area


@njit(**IJIT)
def _plane_range(zd0, dzdx, dzdy, cxl, cxh, cyl, cyh):
    """Bounds ``(lo, hi)`` of the window depth the pass computes, ``z0 + dz/dx·cx +
    dz/dy·cy`` before its clamp, at every sample offset ``(cx, cy)`` from the first vertex in
    ``[cxl, cxh] × [cyl, cyh]``: the plane at the rectangle's lowest and highest corners,
    widened by 10⁻⁹·(1 + the largest magnitude of its terms there), far more than the float64
    rounding of the pass's four operations (a few 10⁻¹⁶ of that magnitude). NaN when the
    plane's terms overflow."""
    mag = abs(zd0) + abs(dzdx) * max(abs(cxl), abs(cxh)) + abs(dzdy) * max(abs(cyl), abs(cyh))
    margin = 1e-9 * (1.0 + mag)
    lo = zd0 + dzdx * (cxl if dzdx > 0.0 else cxh) + dzdy * (cyl if dzdy > 0.0 else cyh)
    hi = zd0 + dzdx * (cxh if dzdx > 0.0 else cxl) + dzdy * (cyh if dzdy > 0.0 else cyl)
    return lo - margin, hi + margin


@njit(**IJIT)
def _hidden(func, bounds, zbuf, lx0, lx1, ly0, ly1):
    """Whether a triangle whose every sample depth lies in ``bounds`` (:func:`_plane_range`)
    fails the depth test at every sample of the tile buffer's box ``[lx0, lx1] × [ly0, ly1]``.
    For ``less``/``lequal`` (``func`` 1, 3) every depth is ≥ float32(min(lo, 1)) (the clamp
    to [0, 1] and the rounding to float32 keep the order), which must fail against every
    stored depth; for ``greater``/``gequal`` (4, 6) the mirror with ``hi``. False for the
    other tests and when the bound says nothing (``lo`` ≤ 0, ``hi`` ≥ 1, NaN)."""
    lo, hi = bounds
    gt = func == 4 or func == 6
    if not (func == 1 or func == 3 or gt) or not (hi < 1.0 if gt else lo > 0.0):
        return False
    zf = np.float32(max(hi, 0.0) if gt else min(lo, 1.0))
    ties = func == 3 or func == 6
    for ly in range(ly0, ly1 + 1):
        for lx in range(lx0, lx1 + 1):
            for s in range(zbuf.shape[2]):
                ref = zbuf[ly, lx, s]
                if ((zf > ref) if gt else (zf < ref)) or (ties and zf == ref):   # depth_test
                    return False
    return True


@njit(**IJIT)
def _sample_edge(r, sx, sy, bits, ox, oy):
    """An edge's biased value at the sample of fixed-point offset ``(ox, oy)`` from the
    pixel centre where it is ``r`` (steps ``sx``, ``sy`` per pixel): ``r + dx·oy − dy·ox``."""
    return r + (sy >> bits) * oy + (sx >> bits) * ox


@njit(**IJIT)
def _plane_sample(zbuf, win, item, func, ly, lx, s, z):
    """Sample ``s`` of the tile pixel ``(ly, lx)`` at the depth plane's value ``z``: clamped
    to [0, 1] (NaN kept), rounded to float32, tested against the tile's depth and written there
    with ``item`` as the winner where it passes (ties to the first drawn)."""
    if z < 0.0:
        z = 0.0
    elif z > 1.0:
        z = 1.0
    zf = np.float32(z)
    if depth_test(func, zf, zbuf[ly, lx, s]):
        zbuf[ly, lx, s] = zf
        win[ly, lx, s] = item


@njit(**IJIT)
def _floor_divmod(v, m):
    """``(⌊v / m⌋, v − m·⌊v / m⌋)`` for ``m > 0`` (exact int64); ``(0, v)`` for ``m = 0``."""
    if m == 0:
        return np.int64(0), v
    q = v // m
    return q, v - q * m


@njit(**IJIT)
def _walk_span(sx, F, T, a, b):
    """Narrow the row's span ``[a, b]`` to where one edge ``v + sx·i ≥ 0``, from its walk
    ``F = ⌊v / |sx|⌋``, ``T = v − |sx|·F`` (``T = v`` when ``sx = 0``): ``i ≥ −F`` for
    ``sx > 0``, ``i ≤ F`` for ``sx < 0`` — :func:`refraster.raster.rasterizer.row_span`'s
    span without its divisions."""
    if sx > 0:
        return max(a, -F), b
    if sx < 0:
        return a, min(b, F)
    if T < 0:
        return a, a - 1
    return a, b


@njit(**IJIT)
def _walk_step(F, T, q, u, m):
    """One row down an edge's walk: ``v`` grows by the y step ``q·m + u`` (``0 ≤ u < m``;
    ``q = 0, u`` = the step when ``m = 0``), so ``F`` by ``q`` and the carry of ``T + u``."""
    t = T + u
    if t >= m:
        return F + q + 1, t - m
    return F + q, t


@njit(**PJIT)
def _msaa_pass(f, vX, vY, vZ, vIW, vXf, vYf, fbox, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront,
               sbox, sarea, B, starts, lists, ntx, width, height, bits, rule, func, clear,
               ox, oy, interp, o_depth, o_prim, o_front, o_bary):
    ntiles = starts.shape[0] - 1
    ns = ox.shape[0]
    one = np.float64(1 << bits)
    fox = np.empty(ns)
    foy = np.empty(ns)
    for s in range(ns):
        fox[s] = np.float64(ox[s]) / one
        foy[s] = np.float64(oy[s]) / one
    # the samples' least and greatest offsets, by a loop: an array reduction (fox.min())
    # in this kernel is a parallel loop of its own, 8 s more compile
    foxmin, foxmax, foymin, foymax = fox[0], fox[0], foy[0], foy[0]
    for s in range(1, ns):
        foxmin, foxmax = min(foxmin, fox[s]), max(foxmax, fox[s])
        foymin, foymax = min(foymin, foy[s]), max(foymax, foy[s])
    for tile in prange(ntiles):
        if starts[tile] == starts[tile + 1]:
            continue
        tx0, tx1, ty0, ty1 = tile_rect(tile, ntx, TILE_SHIFT, width, height)
        zbuf = np.full((TILE, TILE, ns), clear, np.float32)
        win = np.full((TILE, TILE, ns), NO_ITEM, np.int64)
        # the union of the drawn items' boxes: the write-out looks only there
        ux0, ux1, uy0, uy1 = tx1 + 1, tx0 - 1, ty1 + 1, ty0 - 1
        for j in range(starts[tile], starts[tile + 1]):
            item = lists[j]
            bx0, bx1, by0, by1 = _box_in_tile(item, fbox, sbox, tx0, tx1, ty0, ty1)
            if bx0 > bx1 or by0 > by1:
                continue
            (r0, sx0, sy0, b0, r1, sx1, sy1, b1, r2, sx2, sy2, b2, fx0, fy0, fx1, fy1, fx2, fy2,
             z0, z1, z2, iw0, iw1, iw2, prim, front, piece, inv_area, inv_af, dzdx,
             dzdy) = _setup(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim,
                            sfront, sarea, bits, rule, bx0, by0)
            nx = bx1 - bx0 + 1
            # each edge's walk down the rows: |step in x| and the step in y divided by it,
            # shared by the samples (a sample only starts elsewhere)
            m0, m1, m2 = abs(sx0), abs(sx1), abs(sx2)
            q0, u0 = _floor_divmod(sy0, m0)
            q1, u1 = _floor_divmod(sy1, m1)
            q2, u2 = _floor_divmod(sy2, m2)
            zd0 = np.float64(z0)
            # a triangle behind everything its box holds already is skipped (_hidden):
            # for the G-buffer's `less` a third of the 82k-face sphere's items (its far side)
            if inv_af > 0.0 and _hidden(
                    func, _plane_range(zd0, dzdx, dzdy,
                                      (np.float64(bx0) + 0.5 + foxmin) - fx0,
                                      (np.float64(bx1) + 0.5 + foxmax) - fx0,
                                      (np.float64(by0) + 0.5 + foymin) - fy0,
                                      (np.float64(by1) + 0.5 + foymax) - fy0),
                    zbuf, bx0 - tx0, bx1 - tx0, by0 - ty0, by1 - ty0):
                continue
            ux0, ux1 = min(ux0, bx0), max(ux1, bx1)
            uy0, uy1 = min(uy0, by0), max(uy1, by1)
            if inv_af > 0.0 and nx <= NARROW:
                # a narrow box: each pixel's three biased edge values tested directly
                # (e + sx·i ≥ 0: the walk's span without its floor division per edge),
                # the same pixels in the same order, the same depth expression
                for s in range(ns):
                    e0 = _sample_edge(r0, sx0, sy0, bits, ox[s], oy[s])
                    e1 = _sample_edge(r1, sx1, sy1, bits, ox[s], oy[s])
                    e2 = _sample_edge(r2, sx2, sy2, bits, ox[s], oy[s])
                    for y in range(by0, by1 + 1):
                        ly = y - ty0
                        zy = dzdy * ((np.float64(y) + 0.5 + foy[s]) - fy0)
                        for i in range(nx):
                            if (e0 + sx0 * i < 0) | (e1 + sx1 * i < 0) | (e2 + sx2 * i < 0):
                                continue
                            x = bx0 + i
                            _plane_sample(zbuf, win, item, func, ly, x - tx0, s,
                                          zd0 + dzdx * ((np.float64(x) + 0.5 + fox[s]) - fx0)
                                          + zy)
                        e0 += sy0
                        e1 += sy1
                        e2 += sy2
                continue
            for s in range(ns):
                # the sample's edge values at the box's first pixel: the centre's plus the
                # constant dx_k·oy − dy_k·ox, then walked exactly row by row (_walk_step)
                e0 = _sample_edge(r0, sx0, sy0, bits, ox[s], oy[s])
                e1 = _sample_edge(r1, sx1, sy1, bits, ox[s], oy[s])
                e2 = _sample_edge(r2, sx2, sy2, bits, ox[s], oy[s])
                F0, T0 = _floor_divmod(e0, m0)
                F1, T1 = _floor_divmod(e1, m1)
                F2, T2 = _floor_divmod(e2, m2)
                if inv_af > 0.0:
                    # the depth plane through the unsnapped vertices: _depth_at's expression
                    # in its order, without its fallback's barycentrics
                    for y in range(by0, by1 + 1):
                        a, b = _walk_span(sx0, F0, T0, 0, nx - 1)
                        a, b = _walk_span(sx1, F1, T1, a, b)
                        a, b = _walk_span(sx2, F2, T2, a, b)
                        ly = y - ty0
                        zy = dzdy * ((np.float64(y) + 0.5 + foy[s]) - fy0)
                        for x in range(bx0 + a, bx0 + b + 1):
                            _plane_sample(zbuf, win, item, func, ly, x - tx0, s,
                                          zd0 + dzdx * ((np.float64(x) + 0.5 + fox[s]) - fx0)
                                          + zy)
                        F0, T0 = _walk_step(F0, T0, q0, u0, m0)
                        F1, T1 = _walk_step(F1, T1, q1, u1, m1)
                        F2, T2 = _walk_step(F2, T2, q2, u2, m2)
                    continue
                for y in range(by0, by1 + 1):
                    a, b = _walk_span(sx0, F0, T0, 0, nx - 1)
                    a, b = _walk_span(sx1, F1, T1, a, b)
                    a, b = _walk_span(sx2, F2, T2, a, b)
                    ly = y - ty0
                    cy = np.float64(y) + 0.5 + foy[s]
                    for i in range(a, b + 1):
                        x = bx0 + i
                        cx = np.float64(x) + 0.5 + fox[s]
                        z = _depth_at(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, cx, cy,
                                      np.float64(e0 + sx0 * i + b0) * inv_area,
                                      np.float64(e1 + sx1 * i + b1) * inv_area,
                                      np.float64(e2 + sx2 * i + b2) * inv_area)
                        lx = x - tx0
                        if depth_test(func, z, zbuf[ly, lx, s]):
                            zbuf[ly, lx, s] = z
                            win[ly, lx, s] = item
                    e0 += sy0
                    e1 += sy1
                    e2 += sy2
                    F0, T0 = _walk_step(F0, T0, q0, u0, m0)
                    F1, T1 = _walk_step(F1, T1, q1, u1, m1)
                    F2, T2 = _walk_step(F2, T2, q2, u2, m2)
        # write the winners: face, facing, depth and the barycentrics at the interpolation
        # point; the set-up (_load, 1/areas) is redone only when the item changes, the edge
        # values at the pixel centre once per pixel and item where they are read
        last = lists[starts[tile]]
        (X0, Y0, X1, Y1, X2, Y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2, area,
         prim, front, piece, inv_af, inv_area) = _setup_winner(
            last, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea)
        e0 = e1 = e2 = c0 = c1 = c2 = np.int64(0)
        q0 = q1 = q2 = np.float32(0.0)
        for y in range(uy0, uy1 + 1):
            row = height - 1 - y
            for x in range(ux0, ux1 + 1):
                fresh = True
                for s in range(ns):
                    item = win[y - ty0, x - tx0, s]
                    if item == NO_ITEM:
                        continue
                    if item != last:
                        last = item
                        fresh = True
                        (X0, Y0, X1, Y1, X2, Y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0,
                         iw1, iw2, area, prim, front, piece, inv_af, inv_area) = _setup_winner(
                            item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf,
                            sprim, sfront, sarea)
                    o_depth[row, x, s] = zbuf[y - ty0, x - tx0, s]
                    o_prim[row, x, s] = prim
                    o_front[row, x, s] = front
                    if not fresh and interp != 2:
                        # the same face at the same point (the centre or the centroid) as the
                        # pixel's previous sample: the same barycentrics
                        o_bary[row, x, s, 0] = q0
                        o_bary[row, x, s, 1] = q1
                        o_bary[row, x, s, 2] = q2
                        continue
                    if fresh and (interp == 1 or inv_af <= 0.0):
                        # the edge values at the centre: read by the centroid's coverage and
                        # the flattened triangle's barycentrics only (≈ 1 ms of a 4× frame)
                        e0, _, _, c0 = _edge(X1, Y1, X2, Y2, bits, rule, x, y)
                        e1, _, _, c1 = _edge(X2, Y2, X0, Y0, bits, rule, x, y)
                        e2, _, _, c2 = _edge(X0, Y0, X1, Y1, bits, rule, x, y)
                    fresh = False
                    # the point: the centre (offset 0) or a sample
                    px = np.int64(0)
                    py = np.int64(0)
                    if interp == 2:
                        px, py = ox[s], oy[s]
                    elif interp == 1:
                        best = -1
                        dbest = np.int64(0)
                        full = True
                        d0x, d0y = Y1 - Y2, X2 - X1   # -dy, dx of each edge
                        d1x, d1y = Y2 - Y0, X0 - X2
                        d2x, d2y = Y0 - Y1, X1 - X0
                        for t in range(ns):
                            if (e0 + d0y * oy[t] + d0x * ox[t] >= 0
                                    and e1 + d1y * oy[t] + d1x * ox[t] >= 0
                                    and e2 + d2y * oy[t] + d2x * ox[t] >= 0):
                                d = ox[t] * ox[t] + oy[t] * oy[t]
                                if best < 0 or d < dbest:
                                    best = t
                                    dbest = d
                            else:
                                full = False
                        if not full and best >= 0:
                            px, py = ox[best], oy[best]
                    cx = np.float64(x) + 0.5 + np.float64(px) / one
                    cy = np.float64(y) + 0.5 + np.float64(py) / one
                    u0 = e0 + c0 + (X2 - X1) * py - (Y2 - Y1) * px
                    u1 = e1 + c1 + (X0 - X2) * py - (Y0 - Y2) * px
                    u2 = e2 + c2 + (X1 - X0) * py - (Y1 - Y0) * px
                    l0, l1, l2 = _lambdas_at(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, cx, cy,
                                             u0, u1, u2, inv_area)
                    q0, q1, q2 = perspective_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2)
                    o_bary[row, x, s, 0] = q0
                    o_bary[row, x, s, 1] = q1
                    o_bary[row, x, s, 2] = q2


def rasterize_samples(prims, ox, oy, *, fill_rule=0, depth_func=1, clear_depth=1.0,
                      interpolation="center", scratch=None, fill=True):
    """Rasterize and depth-resolve every sample (``prims`` set up with ``pad`` of half a pixel).

    ``ox, oy``: the samples' fixed-point offsets (:func:`refraster.raster.samples.sample_offsets`).
    Returns ``(depth (H, W, S) float32, prim (H, W, S) int32 face or −1, front (H, W, S) bool,
    bary (H, W, S, 3) float32)``, row 0 at the top. At most :data:`~refraster.raster.rasterizer.MAX_FACES` faces.
    ``scratch``: a :class:`refraster._scratch.Scratch` for the tile lists. ``fill=False``: the
    depth, facing and barycentrics hold only the samples a fragment won (the face image is −1
    elsewhere), for a caller that writes the rest (``render_samples``: ``finalize``'s sweep)."""
    face_image_limit(prims.n_faces, "rasterize_samples")
    ntx, nty, starts, lists = bin_primitives(prims, scratch)
    h, w = prims.height, prims.width
    ns = len(ox)
    prim = OUTPUTS.full((h, w, ns), -1, np.int32)
    if fill:
        depth = OUTPUTS.full((h, w, ns), np.float32(clear_depth), np.float32)
        front = OUTPUTS.zeros((h, w, ns), np.bool_)
        bary = OUTPUTS.zeros((h, w, ns, 3), np.float32)
    else:
        depth = OUTPUTS.empty((h, w, ns), np.float32)
        front = OUTPUTS.empty((h, w, ns), np.bool_)
        bary = OUTPUTS.empty((h, w, ns, 3), np.float32)
    _msaa_pass(*_geometry(prims), starts, lists, ntx, w, h, prims.subpixel_bits, fill_rule,
               depth_func, np.float32(clear_depth), np.ascontiguousarray(ox, np.int64),
               np.ascontiguousarray(oy, np.int64), INTERPOLATIONS[interpolation], depth, prim,
               front, bary)
    return depth, prim, front, bary


@njit(**PJIT)
def _sample_stream_pass(f, vX, vY, vZ, vIW, vXf, vYf, fbox, sX, sY, sZ, sIW, sXf, sYf, sprim,
                        sfront, sbox, sarea, B, starts, lists, ntx, width, height, bits, rule,
                        ox, oy, interp, write, counts, offsets, o_pixel, o_depth, o_prim,
                        o_front, o_bary):
    ntiles = starts.shape[0] - 1
    ns = ox.shape[0]
    one = np.float64(1 << bits)
    for tile in prange(ntiles):
        covered = np.zeros(ns, np.bool_)
        # each sample's walk of the three edges (_walk_span, _walk_step): F, T per edge
        wF = np.zeros((3, ns), np.int64)
        wT = np.zeros((3, ns), np.int64)
        tx0, tx1, ty0, ty1 = tile_rect(tile, ntx, TILE_SHIFT, width, height)
        o = offsets[tile]
        for j in range(starts[tile], starts[tile + 1]):
            item = lists[j]
            bx0, bx1, by0, by1 = _box_in_tile(item, fbox, sbox, tx0, tx1, ty0, ty1)
            if bx0 > bx1 or by0 > by1:
                continue
            (r0, sx0, sy0, b0, r1, sx1, sy1, b1, r2, sx2, sy2, b2, fx0, fy0, fx1, fy1, fx2, fy2,
             z0, z1, z2, iw0, iw1, iw2, prim, front, piece, inv_area, inv_af, dzdx,
             dzdy) = _setup(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim,
                            sfront, sarea, bits, rule, bx0, by0)
            # the edges' dx, dy (the steps are their multiples of 2^bits)
            dx0, dy0 = sy0 >> bits, -(sx0 >> bits)
            dx1, dy1 = sy1 >> bits, -(sx1 >> bits)
            dx2, dy2 = sy2 >> bits, -(sx2 >> bits)
            nx = bx1 - bx0 + 1
            m0, m1, m2 = abs(sx0), abs(sx1), abs(sx2)
            wq0, wu0 = _floor_divmod(sy0, m0)
            wq1, wu1 = _floor_divmod(sy1, m1)
            wq2, wu2 = _floor_divmod(sy2, m2)
            for s in range(ns):
                wF[0, s], wT[0, s] = _floor_divmod(r0 + dx0 * oy[s] - dy0 * ox[s], m0)
                wF[1, s], wT[1, s] = _floor_divmod(r1 + dx1 * oy[s] - dy1 * ox[s], m1)
                wF[2, s], wT[2, s] = _floor_divmod(r2 + dx2 * oy[s] - dy2 * ox[s], m2)
            for y in range(by0, by1 + 1):
                row = height - 1 - y
                # the samples' exact spans in this row: their lengths are the count pass's
                # fragments, their union bounds the pixels the write pass tests (a pixel
                # outside it has no covered sample)
                lo = nx
                hi = np.int64(-1)
                for s in range(ns):
                    a, b = _walk_span(sx0, wF[0, s], wT[0, s], 0, nx - 1)
                    a, b = _walk_span(sx1, wF[1, s], wT[1, s], a, b)
                    a, b = _walk_span(sx2, wF[2, s], wT[2, s], a, b)
                    if a <= b:
                        lo = min(lo, a)
                        hi = max(hi, b)
                        o += 0 if write else b - a + 1
                    wF[0, s], wT[0, s] = _walk_step(wF[0, s], wT[0, s], wq0, wu0, m0)
                    wF[1, s], wT[1, s] = _walk_step(wF[1, s], wT[1, s], wq1, wu1, m1)
                    wF[2, s], wT[2, s] = _walk_step(wF[2, s], wT[2, s], wq2, wu2, m2)
                if not write:
                    hi = lo - 1
                for i in range(lo, hi + 1):
                    x = bx0 + i
                    # the biased edge values at the pixel centre; a sample adds its offset
                    e0 = r0 + sx0 * i
                    e1 = r1 + sx1 * i
                    e2 = r2 + sx2 * i
                    n_cov = 0
                    best = -1
                    dbest = np.int64(0)
                    for s in range(ns):
                        c = (e0 + dx0 * oy[s] - dy0 * ox[s] >= 0
                             and e1 + dx1 * oy[s] - dy1 * ox[s] >= 0
                             and e2 + dx2 * oy[s] - dy2 * ox[s] >= 0)
                        covered[s] = c
                        if c:
                            n_cov += 1
                            d = ox[s] * ox[s] + oy[s] * oy[s]
                            if best < 0 or d < dbest:
                                best = s
                                dbest = d
                    if n_cov == 0:
                        continue
                    # the pixel-rate point: the centre, or the centroid's sample
                    px = np.int64(0)
                    py = np.int64(0)
                    if interp == 1 and n_cov < ns:
                        px, py = ox[best], oy[best]
                    q0 = q1 = q2 = np.float32(0.0)
                    if interp != 2:
                        l0, l1, l2 = _lambdas_at(
                            fx0, fy0, fx1, fy1, fx2, fy2, inv_af,
                            np.float64(x) + 0.5 + np.float64(px) / one,
                            np.float64(y) + 0.5 + np.float64(py) / one,
                            e0 + b0 + dx0 * py - dy0 * px, e1 + b1 + dx1 * py - dy1 * px,
                            e2 + b2 + dx2 * py - dy2 * px, inv_area)
                        q0, q1, q2 = perspective_bary(iw0, iw1, iw2, piece, front, B, l0, l1,
                                                      l2)
                    for s in range(ns):
                        if not covered[s]:
                            continue
                        u0 = e0 + dx0 * oy[s] - dy0 * ox[s] + b0
                        u1 = e1 + dx1 * oy[s] - dy1 * ox[s] + b1
                        u2 = e2 + dx2 * oy[s] - dy2 * ox[s] + b2
                        cx = np.float64(x) + 0.5 + np.float64(ox[s]) / one
                        cy = np.float64(y) + 0.5 + np.float64(oy[s]) / one
                        o_pixel[o] = (row * width + x) * ns + s
                        o_prim[o] = prim
                        o_front[o] = front
                        o_depth[o] = _depth_at(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, cx, cy,
                                               np.float64(u0) * inv_area,
                                               np.float64(u1) * inv_area,
                                               np.float64(u2) * inv_area)
                        if interp == 2:
                            l0, l1, l2 = _lambdas_at(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, cx,
                                                     cy, u0, u1, u2, inv_area)
                            q0, q1, q2 = perspective_bary(iw0, iw1, iw2, piece, front, B, l0,
                                                          l1, l2)
                        o_bary[o, 0] = q0
                        o_bary[o, 1] = q1
                        o_bary[o, 2] = q2
                        o += 1
                r0 += sy0
                r1 += sy1
                r2 += sy2
        if not write:
            counts[tile] = o - offsets[tile]


def stream_samples(prims, ox, oy, *, fill_rule=0, interpolation="center"):
    """Rasterize into a per-sample fragment stream (``prims`` set up with ``pad`` of half a
    pixel): one fragment per covered sample, with the sample's depth and the barycentrics at
    ``interpolation``'s point (the pixel centre or centroid, shared by the samples one
    triangle covers in one pixel; or the sample's own position).

    Returns ``(pixel, depth, prim, front, bary, tile_offsets)`` as
    :func:`refraster.raster.rasterizer.stream`, with ``pixel`` an index into the ``(H, W·S)``
    *sample image* — ``(row·W + col)·S + s`` for sample ``s`` of pixel ``(row, col)`` — so
    within each sample the fragments are in draw order and the single-sample resolve is the
    per-sample depth test. Coverage, depth and barycentrics are :func:`rasterize_samples`'s,
    bit for bit."""
    ntx, nty, starts, lists = bin_primitives(prims)
    ntiles = ntx * nty
    counts = np.zeros(ntiles, np.int64)
    offsets = np.zeros(ntiles, np.int64)
    args = (*_geometry(prims), starts, lists, ntx, prims.width, prims.height,
            prims.subpixel_bits, fill_rule, np.ascontiguousarray(ox, np.int64),
            np.ascontiguousarray(oy, np.int64), INTERPOLATIONS[interpolation])
    z = (np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros(0, np.int64),
         np.zeros(0, np.bool_), np.zeros((0, 3), np.float32))
    _sample_stream_pass(*args, False, counts, offsets, *z)
    tile_offsets = np.zeros(ntiles + 1, np.int64)
    np.cumsum(counts, out=tile_offsets[1:])
    n = int(tile_offsets[-1])
    out = (np.zeros(n, np.int64), np.zeros(n, np.float32), np.zeros(n, np.int64),
           np.zeros(n, np.bool_), np.zeros((n, 3), np.float32))
    _sample_stream_pass(*args, True, counts, tile_offsets[:-1].copy(), *out)
    return (*out, tile_offsets)
