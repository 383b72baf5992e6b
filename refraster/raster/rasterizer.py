"""The rasterizer: fixed-point edge functions over tiles.

Coverage
    Each screen triangle (counter-clockwise, snapped to ``1/2^b`` pixel, pixel centres on integer
    multiples of ``2^b``; see :mod:`refraster.raster.primitive`) has three integer edge functions
    ``E_k(p) = (X_b − X_a)(p_y − Y_a) − (Y_b − Y_a)(p_x − X_a)`` for the edge a→b opposite
    vertex k. A pixel centre is covered when every ``E_k > 0``, or ``E_k = 0`` on an edge the fill
    rule owns. With ``fill_rule="llvmpipe"`` (alias ``"bottom-left"``) a centre on an edge belongs
    to the triangle for which it is a **left** edge (``dy < 0`` walking counter-clockwise in GL's
    y-up window space) or a **bottom** edge (``dy = 0, dx > 0``), as the picture is seen;
    ``"top-left"`` (Direct3D's rule as the picture is seen) owns left and top edges. The tie
    rule is a bias of 0 or 1 subtracted from ``E_k`` so the test is ``E_k − bias ≥ 0`` in exact
    int64 arithmetic, stepped incrementally across the tile.

Interpolation (identical formulas in the fragment-stream and fused paths)
    ``λ_k = E_k · (1 / area)`` in float64; window depth ``z = λ0 z0 + λ1 z1 + λ2 z2`` (linear in
    screen space, as GL), clamped to [0, 1] and rounded to float32; perspective-correct
    barycentrics in the original face ``b = Σ_k q_k B_k / Σ_k q_k`` with ``q_k = E_k / w_k``,
    rounded to float32.

Tiles
    The viewport is cut into ``TILE × TILE`` pixel tiles; triangles are binned to the tiles their
    bounding box touches, in primitive order. Tiles are processed in parallel; each writes only
    its own output range, so the result is bit-identical for any thread count.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import JIT, PJIT

TILE_SHIFT = 5
TILE = 1 << TILE_SHIFT

DEPTH_FUNCS = {"never": 0, "less": 1, "equal": 2, "lequal": 3, "greater": 4, "notequal": 5,
               "gequal": 6, "always": 7}


@njit(**JIT)
def depth_test(func, z, ref):
    """OpenGL's depth comparison of an incoming ``z`` against the stored ``ref``."""
    if func == 1:
        return z < ref
    if func == 3:
        return z <= ref
    if func == 4:
        return z > ref
    if func == 6:
        return z >= ref
    if func == 2:
        return z == ref
    if func == 5:
        return z != ref
    return func == 7


@njit(**JIT)
def _bin_count(bbox, ntx, counts):
    for t in range(bbox.shape[0]):
        for ty in range(bbox[t, 2] >> TILE_SHIFT, (bbox[t, 3] >> TILE_SHIFT) + 1):
            for tx in range(bbox[t, 0] >> TILE_SHIFT, (bbox[t, 1] >> TILE_SHIFT) + 1):
                counts[ty * ntx + tx] += 1


@njit(**JIT)
def _bin_fill(bbox, ntx, cursor, lists):
    for t in range(bbox.shape[0]):
        for ty in range(bbox[t, 2] >> TILE_SHIFT, (bbox[t, 3] >> TILE_SHIFT) + 1):
            for tx in range(bbox[t, 0] >> TILE_SHIFT, (bbox[t, 1] >> TILE_SHIFT) + 1):
                k = ty * ntx + tx
                lists[cursor[k]] = t
                cursor[k] += 1


def bin_triangles(bbox, width, height):
    """Tile lists: ``starts (ntiles + 1,)`` and ``lists`` of triangle indices in order."""
    ntx = (width + TILE - 1) >> TILE_SHIFT
    nty = (height + TILE - 1) >> TILE_SHIFT
    counts = np.zeros(ntx * nty, np.int64)
    _bin_count(bbox, ntx, counts)
    starts = np.zeros(ntx * nty + 1, np.int64)
    np.cumsum(counts, out=starts[1:])
    cursor = starts[:-1].copy()
    lists = np.zeros(int(starts[-1]), np.int64)
    _bin_fill(bbox, ntx, cursor, lists)
    return ntx, nty, starts, lists


@njit(**JIT)
def _edge_setup(X, Y, t, k, bits, rule, px, py):
    """Edge k of triangle t: (value at pixel (px, py) minus bias, step in x, step in y, bias)."""
    a = (k + 1) % 3
    b = (k + 2) % 3
    xa = np.int64(X[t, a])
    ya = np.int64(Y[t, a])
    dx = np.int64(X[t, b]) - xa
    dy = np.int64(Y[t, b]) - ya
    if rule == 0:
        owns = dy < 0 or (dy == 0 and dx > 0)   # left or bottom edge
    else:
        owns = dy < 0 or (dy == 0 and dx < 0)   # left or top edge
    bias = np.int64(0) if owns else np.int64(1)
    e = dx * ((np.int64(py) << bits) - ya) - dy * ((np.int64(px) << bits) - xa) - bias
    return e, -(dy << bits), dx << bits, bias


@njit(**JIT)
def fragment_depth(Z, t, e0, e1, e2, inv_area):
    l0 = np.float64(e0) * inv_area
    l1 = np.float64(e1) * inv_area
    l2 = np.float64(e2) * inv_area
    z = l0 * np.float64(Z[t, 0]) + l1 * np.float64(Z[t, 1]) + l2 * np.float64(Z[t, 2])
    if z < 0.0:
        z = 0.0
    elif z > 1.0:
        z = 1.0
    return np.float32(z)


@njit(**JIT)
def fragment_bary(IW, BI, B, front, t, e0, e1, e2, out, o):
    q0 = np.float64(e0) * IW[t, 0]
    q1 = np.float64(e1) * IW[t, 1]
    q2 = np.float64(e2) * IW[t, 2]
    s = q0 + q1 + q2
    k = BI[t]
    if k < 0:
        # an unclipped face: its own vertices, in order 0, 1, 2 (front) or 0, 2, 1 (back)
        out[o, 0] = np.float32(q0 / s)
        if front[t]:
            out[o, 1] = np.float32(q1 / s)
            out[o, 2] = np.float32(q2 / s)
        else:
            out[o, 1] = np.float32(q2 / s)
            out[o, 2] = np.float32(q1 / s)
        return
    for j in range(3):
        out[o, j] = np.float32((q0 * B[k, 0, j] + q1 * B[k, 1, j] + q2 * B[k, 2, j]) / s)


@njit(**PJIT)
def _stream_pass(X, Y, Z, IW, BI, B, front, bbox, area, starts, lists, ntx, width, height,
                 bits, rule, write, counts, offsets, o_pixel, o_depth, o_tri, o_bary):
    ntiles = starts.shape[0] - 1
    for tile in prange(ntiles):
        tx0 = (tile % ntx) << TILE_SHIFT
        ty0 = (tile // ntx) << TILE_SHIFT
        tx1 = min(tx0 + TILE, width) - 1
        ty1 = min(ty0 + TILE, height) - 1
        o = offsets[tile]
        for j in range(starts[tile], starts[tile + 1]):
            t = lists[j]
            x0 = max(bbox[t, 0], tx0)
            x1 = min(bbox[t, 1], tx1)
            y0 = max(bbox[t, 2], ty0)
            y1 = min(bbox[t, 3], ty1)
            if x0 > x1 or y0 > y1:
                continue
            r0, sx0, sy0, b0 = _edge_setup(X, Y, t, 0, bits, rule, x0, y0)
            r1, sx1, sy1, b1 = _edge_setup(X, Y, t, 1, bits, rule, x0, y0)
            r2, sx2, sy2, b2 = _edge_setup(X, Y, t, 2, bits, rule, x0, y0)
            inv_area = 1.0 / np.float64(area[t])
            for y in range(y0, y1 + 1):
                e0, e1, e2 = r0, r1, r2
                row = (height - 1 - y) * width
                for x in range(x0, x1 + 1):
                    if e0 >= 0 and e1 >= 0 and e2 >= 0:
                        if write:
                            o_pixel[o] = row + x
                            o_tri[o] = t
                            o_depth[o] = fragment_depth(Z, t, e0 + b0, e1 + b1, e2 + b2,
                                                        inv_area)
                            fragment_bary(IW, BI, B, front, t, e0 + b0, e1 + b1, e2 + b2, o_bary, o)
                        o += 1
                    e0 += sx0
                    e1 += sx1
                    e2 += sx2
                r0 += sy0
                r1 += sy1
                r2 += sy2
        if not write:
            counts[tile] = o - offsets[tile]


def stream(st, *, fill_rule=0):
    """Rasterize set-up triangles into a fragment stream.

    Returns ``(pixel, depth, tri, bary, tile_offsets)``: ``tri`` indexes the screen triangles;
    fragments are grouped by tile, and within a tile ordered by triangle, then row, then column.
    """
    ntx, nty, starts, lists = bin_triangles(st.bbox, st.width, st.height)
    ntiles = ntx * nty
    counts = np.zeros(ntiles, np.int64)
    offsets = np.zeros(ntiles, np.int64)
    args = (st.x, st.y, st.z, st.inv_w, st.bary_index, st.bary, st.front, st.bbox, st.area, starts, lists, ntx,
            st.width, st.height, st.subpixel_bits, fill_rule)
    z = (np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros(0, np.int64),
         np.zeros((0, 3), np.float32))
    _stream_pass(*args, False, counts, offsets, *z)
    tile_offsets = np.zeros(ntiles + 1, np.int64)
    np.cumsum(counts, out=tile_offsets[1:])
    n = int(tile_offsets[-1])
    out = (np.zeros(n, np.int64), np.zeros(n, np.float32), np.zeros(n, np.int64),
           np.zeros((n, 3), np.float32))
    _stream_pass(*args, True, counts, tile_offsets[:-1].copy(), *out)
    return (*out, tile_offsets)


@njit(**PJIT)
def _fused_pass(X, Y, Z, IW, BI, B, front, prim, bbox, area, starts, lists, ntx, width, height,
                bits, rule, func, clear, o_depth, o_prim, o_front, o_bary):
    ntiles = starts.shape[0] - 1
    for tile in prange(ntiles):
        tx0 = (tile % ntx) << TILE_SHIFT
        ty0 = (tile // ntx) << TILE_SHIFT
        tx1 = min(tx0 + TILE, width) - 1
        ty1 = min(ty0 + TILE, height) - 1
        zbuf = np.full((TILE, TILE), clear, np.float32)
        win = np.full((TILE, TILE), -1, np.int64)
        for j in range(starts[tile], starts[tile + 1]):
            t = lists[j]
            x0 = max(bbox[t, 0], tx0)
            x1 = min(bbox[t, 1], tx1)
            y0 = max(bbox[t, 2], ty0)
            y1 = min(bbox[t, 3], ty1)
            if x0 > x1 or y0 > y1:
                continue
            r0, sx0, sy0, b0 = _edge_setup(X, Y, t, 0, bits, rule, x0, y0)
            r1, sx1, sy1, b1 = _edge_setup(X, Y, t, 1, bits, rule, x0, y0)
            r2, sx2, sy2, b2 = _edge_setup(X, Y, t, 2, bits, rule, x0, y0)
            inv_area = 1.0 / np.float64(area[t])
            for y in range(y0, y1 + 1):
                e0, e1, e2 = r0, r1, r2
                ly = y - ty0
                for x in range(x0, x1 + 1):
                    if e0 >= 0 and e1 >= 0 and e2 >= 0:
                        z = fragment_depth(Z, t, e0 + b0, e1 + b1, e2 + b2, inv_area)
                        lx = x - tx0
                        if depth_test(func, z, zbuf[ly, lx]):
                            zbuf[ly, lx] = z
                            win[ly, lx] = t
                    e0 += sx0
                    e1 += sx1
                    e2 += sx2
                r0 += sy0
                r1 += sy1
                r2 += sy2
        for y in range(ty0, ty1 + 1):
            row = height - 1 - y
            for x in range(tx0, tx1 + 1):
                t = win[y - ty0, x - tx0]
                o_depth[row, x] = zbuf[y - ty0, x - tx0]
                o_prim[row, x] = prim[t] if t >= 0 else -1
                if t >= 0:
                    o_front[row, x] = front[t]
                    e0, _, _, b0 = _edge_setup(X, Y, t, 0, bits, rule, x, y)
                    e1, _, _, b1 = _edge_setup(X, Y, t, 1, bits, rule, x, y)
                    e2, _, _, b2 = _edge_setup(X, Y, t, 2, bits, rule, x, y)
                    fragment_bary(IW, BI, B, front, t, e0 + b0, e1 + b1, e2 + b2, o_bary,
                                  row * width + x)


def fused(st, *, fill_rule=0, depth_func=1, clear_depth=1.0):
    """Rasterize and depth-resolve in one pass (no fragment stream, depth writes on).

    Returns ``(depth (H, W) float32, prim (H, W) int64 face index or −1, front (H, W) bool,
    bary (H·W, 3) float32)``; bit-identical to :func:`stream` followed by
    :func:`refraster.raster.resolve.resolve` with the same ``depth_func`` (a test checks it).
    """
    ntx, nty, starts, lists = bin_triangles(st.bbox, st.width, st.height)
    h, w = st.height, st.width
    depth = np.zeros((h, w), np.float32)
    prim = np.zeros((h, w), np.int64)
    front = np.zeros((h, w), np.bool_)
    bary = np.zeros((h * w, 3), np.float32)
    _fused_pass(st.x, st.y, st.z, st.inv_w, st.bary_index, st.bary, st.front, st.prim, st.bbox,
                st.area, starts, lists, ntx, w, h, st.subpixel_bits, fill_rule, depth_func,
                np.float32(clear_depth), depth, prim, front, bary)
    return depth, prim, front, bary
