"""Vertex and primitive stages: object → clip space, homogeneous clipping, culling, setup.

The vertex stage computes clip coordinates the way a GPU's vertex shader does by default: one
``float32`` matrix ``P·V·M`` (product taken in float64, then rounded) applied to ``float32``
positions with a fixed multiply–add order. ``precision="float64"`` keeps everything in float64.

The primitive stage turns each face into zero or more *screen triangles*:

1. trivial reject when all three vertices are outside one clip plane;
2. homogeneous clipping (Sutherland–Hodgman, float64) against the near plane ``z ≥ −w``, the far
   plane ``z ≤ w``, ``w ≥ W_EPS`` and a guard band ``|x|, |y| ≤ g·w`` that keeps window
   coordinates within ``GUARD_PIXELS`` of the viewport centre, so that fixed-point edge functions
   cannot overflow int64 however far away a vertex is (1e30 included). An intersection point is
   computed from the edge's endpoint nearer the plane (a property of the edge, so the two
   triangles sharing an edge get bit-identical new vertices), and the coordinate the plane
   constrains is then set exactly onto the plane. The remaining coordinates carry float64
   rounding at the scale of the larger of the new point and the near endpoint: an edge whose
   both endpoints lie ~1e30 away is placed only to ~1e14 (as on any float GPU, or worse).
   Every output vertex carries its barycentric
   coordinates **in the original triangle**, so pieces keep the original primitive id and
   barycentrics;
3. perspective divide and viewport transform in float32 (``x·(1/w)·W/2 + W/2``, as Mesa's draw
   module), window depth ``0.5·z_ndc + 0.5``;
4. snapping to ``1/2^subpixel_bits`` pixel (round half to even) after shifting by the half-pixel
   offset, so pixel centres sit on integer multiples of ``2^subpixel_bits``;
5. facing from the sign of the snapped polygon's area (CCW in GL window space — as the picture is
   seen — is front), culling, fan triangulation; every stored triangle is re-ordered CCW so that
   the rasterizer sees a positive area;
6. the pixel bounding box, clamped to the viewport.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import JIT, PJIT

#: Window coordinates are kept within this many pixels of the viewport centre by clipping.
GUARD_PIXELS = float(1 << 20)
#: Smallest clip-space w kept (a plane w ≥ W_EPS is clipped against, so 1/w stays finite).
W_EPS = 1e-30

CULL = {"none": 0, "back": 1, "front": 2}
FILL_RULES = {"llvmpipe": 0, "bottom-left": 0, "top-left": 1}

# one scratch polygon holds 3 + 7 clip planes vertices: x y z w b0 b1 b2
_MAXV = 10


@njit(**JIT)
def _transform32(vertices, m, out):
    for i in range(vertices.shape[0]):
        x = np.float32(vertices[i, 0])
        y = np.float32(vertices[i, 1])
        z = np.float32(vertices[i, 2])
        for r in range(4):
            out[i, r] = ((m[r, 0] * x + m[r, 1] * y) + m[r, 2] * z) + m[r, 3]


@njit(**JIT)
def _transform64(vertices, m, out):
    for i in range(vertices.shape[0]):
        x = vertices[i, 0]
        y = vertices[i, 1]
        z = vertices[i, 2]
        for r in range(4):
            out[i, r] = ((m[r, 0] * x + m[r, 1] * y) + m[r, 2] * z) + m[r, 3]


def transform_vertices(vertices, mvp, precision="float32"):
    """Clip coordinates ``(V, 4)`` of ``vertices (V, 3)`` under ``mvp (4, 4)``.

    ``precision="float32"`` (default) rounds the matrix and the positions to float32 and
    evaluates ``((m0·x + m1·y) + m2·z) + m3`` in float32, as a vertex shader would;
    ``"float64"`` does the same in float64. Inputs are assumed validated.
    """
    if precision == "float32":
        out = np.zeros((len(vertices), 4), np.float32)
        _transform32(vertices, mvp.astype(np.float32), out)
    else:
        out = np.zeros((len(vertices), 4), np.float64)
        _transform64(vertices, mvp.astype(np.float64), out)
    return out


@njit(**JIT)
def _plane_dist(k, x, y, z, w, gx, gy):
    # signed distance to clip plane k; inside when >= 0
    if k == 0:
        return z + w          # near
    if k == 1:
        return w - z          # far
    if k == 2:
        return w - W_EPS      # w > 0
    if k == 3:
        return gx * w - x     # guard band right
    if k == 4:
        return gx * w + x     # guard band left
    if k == 5:
        return gy * w - y     # guard band top
    return gy * w + y         # guard band bottom


@njit(**JIT)
def _outcode(x, y, z, w, gx, gy):
    code = 0
    for k in range(7):
        if _plane_dist(k, x, y, z, w, gx, gy) < 0.0:
            code |= 1 << k
    return code


@njit(**JIT)
def _onto_plane(k, p, m, gx, gy):
    # the new vertex lies on plane k exactly: set the coordinate the plane constrains
    w = p[m, 3]
    if k == 0:
        p[m, 2] = -w
    elif k == 1:
        p[m, 2] = w
    elif k == 2:
        p[m, 3] = W_EPS
    elif k == 3:
        p[m, 0] = gx * w
    elif k == 4:
        p[m, 0] = -gx * w
    elif k == 5:
        p[m, 1] = gy * w
    else:
        p[m, 1] = -gy * w


@njit(**JIT)
def _clip_polygon(poly, tmp, n, planes, gx, gy):
    """Clip the polygon ``poly[:n]`` against every plane whose bit is set in ``planes``."""
    for k in range(7):
        if not (planes >> k) & 1:
            continue
        m = 0
        for i in range(n):
            j = i + 1 if i + 1 < n else 0
            di = _plane_dist(k, poly[i, 0], poly[i, 1], poly[i, 2], poly[i, 3], gx, gy)
            dj = _plane_dist(k, poly[j, 0], poly[j, 1], poly[j, 2], poly[j, 3], gx, gy)
            if di >= 0.0:
                for c in range(7):
                    tmp[m, c] = poly[i, c]
                m += 1
            if (di >= 0.0) != (dj >= 0.0):
                # Interpolate from the endpoint nearer the plane (ties: the inside one), a
                # property of the edge, not of the triangle: both triangles sharing an edge get
                # the same bits. Starting from the near end keeps the error at the scale of the
                # new point rather than of a far-away (1e30) endpoint.
                ai, aj = abs(di), abs(dj)
                if ai < aj or (ai == aj and di >= 0.0):
                    a, b, da, db = i, j, di, dj
                else:
                    a, b, da, db = j, i, dj, di
                t = da / (da - db)
                for c in range(7):
                    tmp[m, c] = poly[a, c] + t * (poly[b, c] - poly[a, c])
                _onto_plane(k, tmp, m, gx, gy)
                m += 1
        n = m
        for i in range(n):
            for c in range(7):
                poly[i, c] = tmp[i, c]
        if n < 3:
            return 0
    return n


@njit(**JIT)
def _to_window(poly, n, width, height, scale, X, Y, Z, IW):
    hw = np.float32(width * 0.5)
    hh = np.float32(height * 0.5)
    half = np.float32(0.5)
    s = np.float32(scale)
    for i in range(n):
        x = np.float32(poly[i, 0])
        y = np.float32(poly[i, 1])
        z = np.float32(poly[i, 2])
        w = np.float32(poly[i, 3])
        rw = np.float32(1.0) / w
        xw = x * rw * hw + hw
        yw = y * rw * hh + hh
        zw = z * rw * half + half
        X[i] = np.int64(np.rint((xw - half) * s))
        Y[i] = np.int64(np.rint((yw - half) * s))
        Z[i] = zw
        IW[i] = 1.0 / np.float64(w)


@njit(**JIT)
def _face(c, f, i, poly, tmp, X, Y, Z, IW, width, height, bits, gx, gy, cull):
    """Clip face ``i`` and project it; returns the polygon's vertex count and its doubled area."""
    ia, ib, ic = f[i, 0], f[i, 1], f[i, 2]
    code_and = 127
    code_or = 0
    for k, v in enumerate((ia, ib, ic)):
        poly[k, 0] = c[v, 0]
        poly[k, 1] = c[v, 1]
        poly[k, 2] = c[v, 2]
        poly[k, 3] = c[v, 3]
        for j in range(3):
            poly[k, 4 + j] = 1.0 if j == k else 0.0
        oc = _outcode(c[v, 0], c[v, 1], c[v, 2], c[v, 3], gx, gy)
        code_and &= oc
        code_or |= oc
    if code_and != 0:
        return 0, 0
    n = 3
    if code_or != 0:
        n = _clip_polygon(poly, tmp, 3, code_or, gx, gy)
        if n < 3:
            return 0, 0
    _to_window(poly, n, width, height, float(1 << bits), X, Y, Z, IW)
    area = np.int64(0)
    for k in range(1, n - 1):
        area += (X[k] - X[0]) * (Y[k + 1] - Y[0]) - (X[k + 1] - X[0]) * (Y[k] - Y[0])
    if area == 0:
        return 0, 0
    if (cull == 1 and area < 0) or (cull == 2 and area > 0):
        return 0, 0
    return n, area


@njit(**JIT)
def _emit(n, total, X, Y, Z, IW, poly, prim, bits, width, height, o, write,
          oX, oY, oZ, oIW, oB, oprim, ofront, obox, oarea):
    """Fan-triangulate one projected polygon; returns the number of screen triangles."""
    cnt = 0
    one = np.int64(1) << bits
    for k in range(1, n - 1):
        idx = (0, k, k + 1)
        a = (X[k] - X[0]) * (Y[k + 1] - Y[0]) - (X[k + 1] - X[0]) * (Y[k] - Y[0])
        if a == 0 or (a > 0) != (total > 0):
            continue  # snapped to a sliver that flipped or vanished
        xmin = min(X[0], X[k], X[k + 1])
        xmax = max(X[0], X[k], X[k + 1])
        ymin = min(Y[0], Y[k], Y[k + 1])
        ymax = max(Y[0], Y[k], Y[k + 1])
        # pixel centres sit at integer multiples of 2^bits (the half-pixel offset is in X, Y)
        px0 = max((xmin + one - 1) >> bits, 0)
        px1 = min(xmax >> bits, width - 1)
        py0 = max((ymin + one - 1) >> bits, 0)
        py1 = min(ymax >> bits, height - 1)
        if px0 > px1 or py0 > py1:
            continue
        if write:
            t = o + cnt
            for s in range(3):
                # stored counter-clockwise: swap the last two vertices of a clockwise triangle
                src = idx[s] if a > 0 or s == 0 else idx[3 - s]
                oX[t, s] = X[src]
                oY[t, s] = Y[src]
                oZ[t, s] = Z[src]
                oIW[t, s] = IW[src]
                for j in range(3):
                    oB[t, s, j] = poly[src, 4 + j]
            oprim[t] = prim
            ofront[t] = total > 0
            obox[t, 0] = px0
            obox[t, 1] = px1
            obox[t, 2] = py0
            obox[t, 3] = py1
            oarea[t] = a if a > 0 else -a
        cnt += 1
    return cnt


_CHUNK = 4096


@njit(**PJIT)
def _setup_pass(c, f, width, height, bits, gx, gy, cull, counts, offsets, write,
                oX, oY, oZ, oIW, oB, oprim, ofront, obox, oarea):
    nf = f.shape[0]
    nchunks = (nf + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunks):
        poly = np.zeros((_MAXV, 7))
        tmp = np.zeros((_MAXV, 7))
        X = np.zeros(_MAXV, np.int64)
        Y = np.zeros(_MAXV, np.int64)
        Z = np.zeros(_MAXV)
        IW = np.zeros(_MAXV)
        o = offsets[ch]
        for i in range(ch * _CHUNK, min(nf, (ch + 1) * _CHUNK)):
            n, total = _face(c, f, i, poly, tmp, X, Y, Z, IW, width, height, bits, gx, gy, cull)
            if n == 0:
                continue
            o += _emit(n, total, X, Y, Z, IW, poly, i, bits, width, height, o, write,
                       oX, oY, oZ, oIW, oB, oprim, ofront, obox, oarea)
        if not write:
            counts[ch] = o - offsets[ch]


class ScreenTriangles:
    """Set-up triangles ready for rasterization (struct of arrays, ``T`` triangles).

    ``x, y (T, 3) int64`` snapped window coordinates (GL y-up, half-pixel offset removed, pixel
    centres on multiples of ``2^subpixel_bits``), counter-clockwise; ``z (T, 3)`` window depth;
    ``inv_w (T, 3)`` 1/w; ``bary (T, 3, 3)`` each vertex's barycentrics in the original face;
    ``prim (T,) int64`` the original face index (in input order, so sorting by it is draw order);
    ``front (T,) bool``; ``bbox (T, 4) int64`` inclusive pixel ranges ``x0, x1, y0, y1``;
    ``area (T,) int64`` doubled area in fixed point.
    """

    __slots__ = ("x", "y", "z", "inv_w", "bary", "prim", "front", "bbox", "area",
                 "width", "height", "subpixel_bits")

    def __len__(self):
        return int(self.prim.shape[0])


def setup_triangles(clip, faces, width, height, *, cull=0, subpixel_bits=8):
    """Run the primitive stage on validated arrays; returns :class:`ScreenTriangles`."""
    c = np.ascontiguousarray(clip, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    gx = 2.0 * GUARD_PIXELS / width
    gy = 2.0 * GUARD_PIXELS / height
    nchunks = (len(f) + _CHUNK - 1) // _CHUNK
    counts = np.zeros(max(nchunks, 1), np.int64)
    offsets = np.zeros(max(nchunks, 1), np.int64)
    dummy = _alloc(0)
    _setup_pass(c, f, width, height, subpixel_bits, gx, gy, cull, counts, offsets, False, *dummy)
    offsets[1:] = np.cumsum(counts)[:-1]
    total = int(counts.sum())
    out = _alloc(total)
    _setup_pass(c, f, width, height, subpixel_bits, gx, gy, cull, counts, offsets, True, *out)
    st = ScreenTriangles()
    (st.x, st.y, st.z, st.inv_w, st.bary, st.prim, st.front, st.bbox, st.area) = out
    st.width, st.height, st.subpixel_bits = width, height, subpixel_bits
    return st


def _alloc(t):
    return (np.zeros((t, 3), np.int64), np.zeros((t, 3), np.int64), np.zeros((t, 3)),
            np.zeros((t, 3)), np.zeros((t, 3, 3)), np.zeros(t, np.int64), np.zeros(t, np.bool_),
            np.zeros((t, 4), np.int64), np.zeros(t, np.int64))
