"""Vertex and primitive stages: object → clip space, homogeneous clipping, culling, setup.

The vertex stage computes clip coordinates the way a GPU's vertex shader does by default: one
``float32`` matrix ``P·V·M`` (product taken in float64, then rounded) applied to ``float32``
positions with a fixed multiply–add order. ``precision="float64"`` keeps everything in float64.

The primitive stage turns each face into zero or more *screen triangles*:

1. trivial reject when all three vertices are outside one clip plane;
2. homogeneous clipping (Sutherland–Hodgman, float64) against the near plane ``z ≥ −w`` (``z ≥ 0``
   under ``depth_range="zero_to_one"``), the far plane ``z ≤ w`` (neither under ``depth_clamp``),
   ``w ≥ W_EPS`` and a guard band ``|x|, |y| ≤ g·w`` that keeps window
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
   module), window depth ``0.5·z_ndc + 0.5`` (``z_ndc`` under ``"zero_to_one"``); window y is
   ``(±y)·(1/w)·H/2 + H/2`` in the API's window coordinates (the sign: see :data:`NEGATE_Y`),
   and an upper-left window is snapped there and then turned into the picture-up coordinates
   the rasterizer works in (:data:`UPPER_LEFT`);
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

from .._config import IJIT, JIT, PJIT
from .._tiers import kernel as tiered

#: Window coordinates are kept within this many pixels of the viewport centre by clipping.
GUARD_PIXELS = float(1 << 20)
#: Smallest clip-space w kept (a plane w ≥ W_EPS is clipped against, so 1/w stays finite).
W_EPS = 1e-30

CULL = {"none": 0, "back": 1, "front": 2}
FILL_RULES = {"llvmpipe": 0, "bottom-left": 0, "top-left": 1}

# The API conventions of a RasterState, as bits of one integer ``conv`` the kernels branch on;
# 0 is OpenGL's (lower-left origin, NDC y up, −w ≤ z ≤ w, no clamp), whose arithmetic is the
# same operations in the same order as before the conventions existed.
#: Clip volume 0 ≤ z ≤ w (near plane z ≥ 0) and window depth ``z·(1/w)``.
ZERO_TO_ONE = 1
#: No clipping against the near and far planes (fragment depth is clamped to [0, 1] anyway).
DEPTH_CLAMP = 2
#: Window y from −y: NDC +y and the window's +y point opposite ways in the picture (Direct3D,
#: Metal, WebGPU and ``GL_UPPER_LEFT``: NDC up, window y down; NDC down with a lower-left origin).
NEGATE_Y = 4
#: Window y counts down from the top of the picture: snapped there (``rint((y_w − ½)·2^b)``, so
#: ties round in the API's coordinates), then turned exactly into the rasterizer's picture-up
#: coordinates ``(H − 1)·2^b − Y``; the unsnapped position becomes ``H − y_w`` (float32).
UPPER_LEFT = 8


def convention_code(depth_range="negative_one_to_one", depth_clamp=False, origin="lower_left",
                    ndc_y="up"):
    """The kernels' ``conv`` integer of a state's convention fields (validated names)."""
    upper = origin == "upper_left"
    return ((ZERO_TO_ONE if depth_range == "zero_to_one" else 0)
            | (DEPTH_CLAMP if depth_clamp else 0)
            | (NEGATE_Y if upper != (ndc_y == "down") else 0)
            | (UPPER_LEFT if upper else 0))

# one scratch polygon holds 3 + 7 clip planes vertices: x y z w b0 b1 b2
_MAXV = 10


@njit(**PJIT)
def _transform32(vertices, m, out):
    bad = 0   # clip coordinates that are not finite (an int sum: the same on any threads)
    for i in prange(vertices.shape[0]):
        x = np.float32(vertices[i, 0])
        y = np.float32(vertices[i, 1])
        z = np.float32(vertices[i, 2])
        for r in range(4):
            v = ((m[r, 0] * x + m[r, 1] * y) + m[r, 2] * z) + m[r, 3]
            out[i, r] = v
            if not np.isfinite(v):
                bad += 1
    return bad


@njit(**JIT)
def _transform64(vertices, m, out):
    bad = 0
    for i in range(vertices.shape[0]):
        x = vertices[i, 0]
        y = vertices[i, 1]
        z = vertices[i, 2]
        for r in range(4):
            v = ((m[r, 0] * x + m[r, 1] * y) + m[r, 2] * z) + m[r, 3]
            out[i, r] = v
            if not np.isfinite(v):
                bad += 1
    return bad


def transform_vertices(vertices, mvp, precision="float32", out=None):
    """Clip coordinates ``(V, 4)`` of ``vertices (V, 3)`` under ``mvp (4, 4)``.

    ``precision="float32"`` (default) rounds the matrix and the positions to float32 and
    evaluates ``((m0·x + m1·y) + m2·z) + m3`` in float32, as a vertex shader would;
    ``"float64"`` does the same in float64. Inputs are assumed validated. ``out``: a
    ``(V, 4)`` C-contiguous array to write (every element), of the precision's dtype or
    float64 (the float32 stage's values stored exactly: what the primitive stage reads).
    """
    return transform_counted(vertices, mvp, precision, out)[0]


def transform_counted(vertices, mvp, precision="float32", out=None):
    """:func:`transform_vertices`, and how many of the clip coordinates are not finite (None
    when unknown: the kernel replaced by a warm-up's no-op)."""
    if precision == "float32":
        out = np.zeros((len(vertices), 4), np.float32) if out is None else out
        bad = tiered(_transform32)(vertices, mvp.astype(np.float32), out)
    else:
        out = np.zeros((len(vertices), 4), np.float64) if out is None else out
        bad = _transform64(vertices, mvp.astype(np.float64), out)
    return out, bad


@njit(**IJIT)
def _plane_dist(k, x, y, z, w, gx, gy, conv):
    # signed distance to clip plane k; inside when >= 0
    if k == 0:
        if conv & ZERO_TO_ONE:
            return z          # near, 0 ≤ z
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


@njit(**IJIT)
def _outcode(x, y, z, w, gx, gy, conv):
    code = 0
    for k in range(7):
        if _plane_dist(k, x, y, z, w, gx, gy, conv) < 0.0:
            code |= 1 << k
    if conv & DEPTH_CLAMP:
        code &= ~3            # no near (bit 0) or far (bit 1) plane
    return code


@njit(**IJIT)
def _onto_plane(k, p, m, gx, gy, conv):
    # the new vertex lies on plane k exactly: set the coordinate the plane constrains
    w = p[m, 3]
    if k == 0:
        p[m, 2] = 0.0 if conv & ZERO_TO_ONE else -w
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
def _clip_polygon(poly, tmp, n, planes, gx, gy, conv):
    """Clip the polygon ``poly[:n]`` against every plane whose bit is set in ``planes``."""
    for k in range(7):
        if not (planes >> k) & 1:
            continue
        m = 0
        for i in range(n):
            j = i + 1 if i + 1 < n else 0
            di = _plane_dist(k, poly[i, 0], poly[i, 1], poly[i, 2], poly[i, 3], gx, gy, conv)
            dj = _plane_dist(k, poly[j, 0], poly[j, 1], poly[j, 2], poly[j, 3], gx, gy, conv)
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
                _onto_plane(k, tmp, m, gx, gy, conv)
                m += 1
        n = m
        for i in range(n):
            for c in range(7):
                poly[i, c] = tmp[i, c]
        if n < 3:
            return 0
    return n


@njit(**IJIT)
def _window(x, y, z, w, hw, hh, scale, conv, top):
    """Divide, viewport and snap one vertex (float32, as Mesa's draw module). ``conv``: the
    convention bits; ``top``: ``(H − 1)·2^b``, the snapped y of the top row's centre in the
    rasterizer's picture-up coordinates (used under :data:`UPPER_LEFT`)."""
    half = np.float32(0.5)
    x = np.float32(x)
    y = np.float32(y)
    z = np.float32(z)
    w = np.float32(w)
    rw = np.float32(1.0) / w
    xw = x * rw * hw + hw
    if conv == 0:   # OpenGL's
        yw = y * rw * hh + hh
        zw = z * rw * half + half
        return (np.int64(np.rint((xw - half) * scale)), np.int64(np.rint((yw - half) * scale)),
                zw, 1.0 / np.float64(w), xw, yw)
    if conv & NEGATE_Y:
        y = -y
    yw = y * rw * hh + hh
    if conv & ZERO_TO_ONE:
        zw = z * rw
    else:
        zw = z * rw * half + half
    ys = np.int64(np.rint((yw - half) * scale))
    if conv & UPPER_LEFT:
        ys = top - ys
        yw = np.float32(2.0) * hh - yw
    return (np.int64(np.rint((xw - half) * scale)), ys, zw, 1.0 / np.float64(w), xw, yw)


@njit(**PJIT)
def _vertex_pass(c, width, height, bits, gx, gy, conv, vX, vY, vZ, vIW, vXf, vYf, vcode):
    hw = np.float32(width * 0.5)
    hh = np.float32(height * 0.5)
    scale = np.float32(1 << bits)
    top = np.int64(height - 1) << bits
    for i in prange(c.shape[0]):
        code = _outcode(c[i, 0], c[i, 1], c[i, 2], c[i, 3], gx, gy, conv)
        vcode[i] = code
        if code == 0:
            (vX[i], vY[i], vZ[i], vIW[i], vXf[i],
             vYf[i]) = _window(c[i, 0], c[i, 1], c[i, 2], c[i, 3], hw, hh, scale, conv, top)
        else:   # never read; written so that the arrays need no zero fill first
            vX[i], vY[i], vZ[i], vIW[i], vXf[i], vYf[i] = 0, 0, 0.0, 0.0, 0.0, 0.0


@njit(**IJIT)
def _area(X, Y, i, j, k):
    return (X[j] - X[i]) * (Y[k] - Y[i]) - (X[k] - X[i]) * (Y[j] - Y[i])


@njit(**IJIT)
def _bbox(X, Y, i, j, k, bits, width, height, pad):
    one = np.int64(1) << bits
    xmin = min(X[i], X[j], X[k]) - pad
    xmax = max(X[i], X[j], X[k]) + pad
    ymin = min(Y[i], Y[j], Y[k]) - pad
    ymax = max(Y[i], Y[j], Y[k]) + pad
    # pixel centres sit at integer multiples of 2^bits (the half-pixel offset is in X, Y)
    return (max((xmin + one - 1) >> bits, 0), min(xmax >> bits, width - 1),
            max((ymin + one - 1) >> bits, 0), min(ymax >> bits, height - 1))


@njit(**IJIT)
def _store(t, X, Y, Z, IW, XF, YF, i, j, k, prim, front, box, area, bslot,
           oX, oY, oZ, oIW, oXf, oYf, oprim, ofront, obox, oarea, obidx):
    """Write one counter-clockwise screen triangle (vertices i, j, k of the scratch arrays)."""
    for s, v in enumerate((i, j, k)):
        oX[t, s] = X[v]
        oY[t, s] = Y[v]
        oZ[t, s] = Z[v]
        oIW[t, s] = IW[v]
        oXf[t, s] = XF[v]
        oYf[t, s] = YF[v]
    oprim[t] = prim
    ofront[t] = front
    for s in range(4):
        obox[t, s] = box[s]
    oarea[t] = area
    obidx[t] = bslot


@njit(**JIT)
def _clipped_face(c, f, i, codes, poly, tmp, X, Y, Z, IW, XF, YF, width, height, bits, gx,
                  gy, conv):
    """Clip face ``i`` and project the polygon; returns its vertex count and doubled area."""
    for k in range(3):
        v = f[i, k]
        for j in range(4):
            poly[k, j] = c[v, j]
        for j in range(3):
            poly[k, 4 + j] = 1.0 if j == k else 0.0
    n = _clip_polygon(poly, tmp, np.int64(3), codes, gx, gy, conv)   # int64: one compile
    if n < 3:
        return 0, np.int64(0)
    hw = np.float32(width * 0.5)
    hh = np.float32(height * 0.5)
    scale = np.float32(1 << bits)
    top = np.int64(height - 1) << bits
    for k in range(n):
        X[k], Y[k], Z[k], IW[k], XF[k], YF[k] = _window(poly[k, 0], poly[k, 1], poly[k, 2],
                                                        poly[k, 3], hw, hh, scale, conv, top)
    total = np.int64(0)
    for k in range(1, n - 1):
        total += _area(X, Y, 0, k, k + 1)
    return n, total


_CHUNK = 4096

#: Per-face status after the primitive stage.
SKIP, SIMPLE, CLIPPED = 0, 1, 2

#: The rasterizer's square tiles (``1 << TILE_SHIFT`` pixels a side) and the faces per chunk
#: of its binning (:func:`refraster.raster.rasterizer.bin_primitives`), here because the
#: primitive stage counts its simple faces per chunk and tile (:func:`_classify`).
TILE_SHIFT = 6
BIN_CHUNK = 8192


def bin_shape(n_faces, width, height):
    """``(nchunks, ntx, nty)`` of the binning: chunks of :data:`BIN_CHUNK` faces (at least
    one), tiles across and down."""
    tile = 1 << TILE_SHIFT
    return (max((int(n_faces) + BIN_CHUNK - 1) // BIN_CHUNK, 1),
            (int(width) + tile - 1) >> TILE_SHIFT, (int(height) + tile - 1) >> TILE_SHIFT)


@njit(**PJIT)
def _classify(f, vX, vY, vcode, width, height, bits, cull, pad, ntx, status, fbox, counts):
    """Faces that need no clipping are set up in the rasterizer from the vertex pass's window
    positions (status SIMPLE, with their pixel bounding box); faces crossing a clip plane get
    status CLIPPED; culled, degenerate, rejected or centre-less faces SKIP, as are faces whose
    box is one pixel (no pad) with its centre strictly outside an edge. ``pad`` (fixed
    point) widens the box: the pixels whose centre lies within ``pad`` of the triangle's box
    (0: pixel centres; half a pixel under multisampling, whose samples leave the centre).
    ``counts (nchunks, ntiles)``, zeros: each chunk of :data:`BIN_CHUNK` faces adds its simple
    faces to the tiles their boxes touch (``ntx`` tiles across), the binning's count of them
    taken here while the box is at hand (:func:`count_pieces` adds the clipped pieces)."""
    nf = f.shape[0]
    nchunks = (nf + BIN_CHUNK - 1) // BIN_CHUNK
    for ch in prange(nchunks):
        # unsigned face indices: no negative-index fix-up (signed ones made a microbenchmark
        # of this loop 1.7× slower)
        i0, i1 = np.uint64(ch * BIN_CHUNK), np.uint64(min(nf, (ch + 1) * BIN_CHUNK))
        for i in range(i0, i1):
            # unsigned vertex indices too (validated where the faces came in)
            a, b, d = np.uint64(f[i, 0]), np.uint64(f[i, 1]), np.uint64(f[i, 2])
            ca, cb, cd = vcode[a], vcode[b], vcode[d]
            # every face's box written (zeros unless SIMPLE): the array needs no zero fill
            if ca | cb | cd:
                status[i] = CLIPPED if (ca & cb & cd) == 0 else SKIP
                fbox[i, 0] = 0
                fbox[i, 1] = 0
                fbox[i, 2] = 0
                fbox[i, 3] = 0
                continue
            x0, x1, x2 = vX[a], vX[b], vX[d]
            y0, y1, y2 = vY[a], vY[b], vY[d]
            area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
            one = np.int64(1) << bits
            bx0 = max((min(x0, x1, x2) - pad + one - 1) >> bits, 0)
            bx1 = min((max(x0, x1, x2) + pad) >> bits, width - 1)
            by0 = max((min(y0, y1, y2) - pad + one - 1) >> bits, 0)
            by1 = min((max(y0, y1, y2) + pad) >> bits, height - 1)
            # a box of one pixel (no pad): the face covers at most that pixel's centre, and
            # none when the centre is strictly outside an edge (the raw edge function of
            # rasterizer._edge < 0), whatever the fill rule: its bias only decides a centre
            # on an edge, and such a face is kept. 390,000 of the 695,000 faces a 1.3M-face
            # sphere set up in the tile pass covered nothing; now they are skipped here.
            # No branch on whether the box holds a pixel centre (about half the faces of a
            # dense mesh do not, unpredictably) or on the test: status and box are selected
            px = bx0 << bits
            py = by0 << bits
            e12 = (x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)
            e20 = (x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)
            e01 = (x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)
            may = ((e12 >= 0) & (e20 >= 0) & (e01 >= 0)) if area > 0 else (
                (e12 <= 0) & (e20 <= 0) & (e01 <= 0))
            ok = ((area != 0) & ((cull != 1) | (area > 0)) & ((cull != 2) | (area < 0))
                  & (bx0 <= bx1) & (by0 <= by1)
                  & (may | (pad != 0) | (bx0 != bx1) | (by0 != by1)))
            status[i] = SIMPLE if ok else SKIP
            fbox[i, 0] = bx0 if ok else 0
            fbox[i, 1] = bx1 if ok else 0
            fbox[i, 2] = by0 if ok else 0
            fbox[i, 3] = by1 if ok else 0
        # the chunk's simple faces counted per tile from its status and boxes (still in
        # cache), a loop of its own (counting in the loop above cost more); a run of faces in
        # one tile is counted in a register, added when the tile changes
        cnt = counts[ch]
        run_t = np.int64(-1)
        run_n = np.int64(0)
        for i in range(i0, i1):
            simple = status[i] == SIMPLE
            tx0, tx1 = np.int64(fbox[i, 0]) >> TILE_SHIFT, np.int64(fbox[i, 1]) >> TILE_SHIFT
            ty0, ty1 = np.int64(fbox[i, 2]) >> TILE_SHIFT, np.int64(fbox[i, 3]) >> TILE_SHIFT
            if simple and (tx0 != tx1 or ty0 != ty1):
                add_to_tiles(cnt, ntx, tx0, tx1, ty0, ty1)
                continue
            # not simple: the run goes on, uncounted (no branch on the status)
            t = ty0 * ntx + tx0 if simple else run_t
            if t != run_t:
                if run_t >= 0:
                    cnt[run_t] += run_n
                run_t = t
                run_n = 0
            run_n += simple
        if run_t >= 0:
            cnt[run_t] += run_n


@njit(**IJIT)
def add_to_tiles(cnt, ntx, tx0, tx1, ty0, ty1):
    """Count one item in each tile of ``[tx0, tx1] × [ty0, ty1]`` (tile indices)."""
    for ty in range(ty0, ty1 + 1):
        for tx in range(tx0, tx1 + 1):
            cnt[ty * ntx + tx] += 1


@njit(**JIT)
def count_pieces(sprim, sbox, ntx, counts):
    """Add the clipped pieces (face ``sprim[k]``, box ``sbox[k]``) to the binning's counts per
    chunk of faces and tile (:func:`_classify`)."""
    for k in range(sprim.shape[0]):
        add_to_tiles(counts[sprim[k] // BIN_CHUNK], ntx, np.int64(sbox[k, 0]) >> TILE_SHIFT,
                     np.int64(sbox[k, 1]) >> TILE_SHIFT, np.int64(sbox[k, 2]) >> TILE_SHIFT,
                     np.int64(sbox[k, 3]) >> TILE_SHIFT)


@njit(**PJIT)
def _clip_pass(c, f, idx, width, height, bits, gx, gy, conv, cull, pad, counts, offsets, write,
               oX, oY, oZ, oIW, oXf, oYf, oprim, ofront, obox, oarea, obidx, oB):
    n_idx = idx.shape[0]
    nchunks = (n_idx + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunks):
        poly = np.zeros((_MAXV, 7))
        tmp = np.zeros((_MAXV, 7))
        X = np.zeros(_MAXV, np.int64)
        Y = np.zeros(_MAXV, np.int64)
        Z = np.zeros(_MAXV, np.float32)
        IW = np.zeros(_MAXV)
        XF = np.zeros(_MAXV, np.float32)
        YF = np.zeros(_MAXV, np.float32)
        box = np.zeros(4, np.int64)
        o = offsets[ch]
        for r in range(ch * _CHUNK, min(n_idx, (ch + 1) * _CHUNK)):
            i = idx[r]
            codes = np.int64(0)   # not the literal 0: _clipped_face compiles once
            for k in range(3):
                v = f[i, k]
                codes |= _outcode(c[v, 0], c[v, 1], c[v, 2], c[v, 3], gx, gy, conv)
            n, total = _clipped_face(c, f, i, codes, poly, tmp, X, Y, Z, IW, XF, YF, width,
                                     height, bits, gx, gy, conv)
            if n == 0 or total == 0 or (cull == 1 and total < 0) or (cull == 2 and total > 0):
                continue
            for k in range(1, n - 1):
                area = _area(X, Y, 0, k, k + 1)
                if area == 0 or (area > 0) != (total > 0):
                    continue  # snapped to a sliver that flipped or vanished
                box[0], box[1], box[2], box[3] = _bbox(X, Y, 0, k, k + 1, bits, width, height,
                                                       pad)
                if box[0] > box[1] or box[2] > box[3]:
                    continue
                if write:
                    j1, j2 = (k, k + 1) if area > 0 else (k + 1, k)
                    _store(o, X, Y, Z, IW, XF, YF, 0, j1, j2, i, total > 0, box, abs(area), o,
                           oX, oY, oZ, oIW, oXf, oYf, oprim, ofront, obox, oarea, obidx)
                    for s, v in enumerate((0, j1, j2)):
                        for j in range(3):
                            oB[o, s, j] = poly[v, 4 + j]
                o += 1
        if not write:
            counts[ch] = o - offsets[ch]


class ScreenTriangles:
    """Set-up pieces of clipped faces (struct of arrays, ``T`` triangles).

    ``x, y (T, 3) int32`` snapped window coordinates (GL y-up, half-pixel offset removed, pixel
    centres on multiples of ``2^subpixel_bits``), counter-clockwise; ``z (T, 3) float32`` window
    depth; ``inv_w (T, 3)`` 1/w; ``xf, yf (T, 3) float32`` the unsnapped window coordinates
    (interpolation uses these); ``prim (T,) int64`` the original face index (ascending: draw
    order); ``front (T,) bool``; ``bbox (T, 4) int32`` inclusive pixel ranges ``x0, x1, y0,
    y1``; ``area (T,) int64`` doubled area in fixed point; ``bary (T, 3, 3)`` each vertex's
    barycentrics in the original face (``bary_index`` is the row, kept for the kernels).
    """

    __slots__ = ("x", "y", "z", "inv_w", "xf", "yf", "prim", "front", "bbox", "area",
                 "bary_index", "bary")

    def __len__(self):
        return int(self.prim.shape[0])


class Primitives:
    """Output of the primitive stage, input of the rasterizer.

    ``faces (F, 3)``; per vertex the snapped window position ``vx, vy`` (int64), window depth
    ``vz`` (float32), ``v_inv_w`` and the unsnapped window position ``vxf, vyf`` (float32; valid
    where the vertex's clip outcode ``vcode`` is 0);
    per face ``status`` (``SKIP``, ``SIMPLE``, ``CLIPPED``) and ``bbox (F, 4) int32`` for simple
    faces; ``clipped``, the :class:`ScreenTriangles` of the clipped faces' pieces;
    ``tile_counts (nchunks, ntiles)``, the binning's items per chunk of faces and tile
    (:func:`bin_shape`; simple faces and clipped pieces). A simple face
    is set up inside the rasterizer, per tile, from the per-vertex arrays — the same integer and
    float operations as a stored triangle, so nothing about the result depends on where it was
    set up.
    """

    __slots__ = ("faces", "vx", "vy", "vz", "v_inv_w", "vxf", "vyf", "vcode", "status", "bbox",
                 "clipped", "tile_counts", "width", "height", "subpixel_bits")

    @property
    def n_faces(self):
        return int(self.faces.shape[0])


def _array(scratch, key, shape, dtype):
    """An array the primitive stage's kernels write whole: reused from ``scratch`` unfilled
    (``render``), else ``np.zeros`` (``prepare``: also when warm-up replaces the kernels by
    no-ops, every face stays ``SKIP``)."""
    return np.zeros(shape, dtype) if scratch is None else scratch.empty(key, shape, dtype)


def setup_triangles(clip, faces, width, height, *, cull=0, subpixel_bits=8, conv=0,
                    scratch=None, pad=0):
    """Run the primitive stage on validated arrays; returns :class:`Primitives`.
    ``conv``: the convention bits (:func:`convention_code`; 0: OpenGL's). ``pad``: how far (in
    ``1/2^subpixel_bits`` pixel) outside a triangle's box a pixel centre may lie and the pixel
    still be in its box (0; half a pixel for multisampling).
    ``scratch``: a :class:`refraster._scratch.Scratch` for the per-vertex and per-face arrays
    (the result is then valid until that scratch is used again)."""
    conv = int(conv)
    c = np.ascontiguousarray(clip, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    gx = 2.0 * GUARD_PIXELS / width
    gy = 2.0 * GUARD_PIXELS / height
    nv = len(c)
    vX = _array(scratch, "vX", nv, np.int64)
    vY = _array(scratch, "vY", nv, np.int64)
    vZ = _array(scratch, "vZ", nv, np.float32)
    vIW = _array(scratch, "vIW", nv, np.float64)
    vXf = _array(scratch, "vXf", nv, np.float32)
    vYf = _array(scratch, "vYf", nv, np.float32)
    vcode = _array(scratch, "vcode", nv, np.int64)
    tiered(_vertex_pass)(c, width, height, subpixel_bits, gx, gy, conv, vX, vY, vZ, vIW, vXf, vYf,
                 vcode)
    status = _array(scratch, "status", len(f), np.int8)
    fbox = _array(scratch, "fbox", (len(f), 4), np.int32)
    pad = np.int64(pad)
    nchunks, ntx, nty = bin_shape(len(f), width, height)
    tile_counts = np.zeros((nchunks, ntx * nty), np.int64)
    tiered(_classify)(f, vX, vY, vcode, width, height, subpixel_bits, cull, pad, ntx, status,
                      fbox, tile_counts)
    idx = np.flatnonzero(status == CLIPPED)
    nchunks = max((len(idx) + _CHUNK - 1) // _CHUNK, 1)
    counts = np.zeros(nchunks, np.int64)
    offsets = np.zeros(nchunks, np.int64)
    args = (c, f, idx, width, height, subpixel_bits, gx, gy, conv, cull, pad, counts, offsets)
    if len(idx):
        _clip_pass(*args, False, *_alloc(0))
        offsets[1:] = np.cumsum(counts)[:-1]
    out = _alloc(int(counts.sum()))
    if len(idx):
        _clip_pass(*args, True, *out)
    st = ScreenTriangles()
    (st.x, st.y, st.z, st.inv_w, st.xf, st.yf, st.prim, st.front, st.bbox, st.area,
     st.bary_index, st.bary) = out
    if len(st.prim):
        tiered(count_pieces)(st.prim, st.bbox, ntx, tile_counts)
    p = Primitives()
    p.faces, p.vx, p.vy, p.vz, p.v_inv_w, p.vcode = f, vX, vY, vZ, vIW, vcode
    p.vxf, p.vyf = vXf, vYf
    p.status, p.bbox, p.clipped, p.tile_counts = status, fbox, st, tile_counts
    p.width, p.height, p.subpixel_bits = width, height, subpixel_bits
    return p


def _alloc(t):
    return (np.zeros((t, 3), np.int32), np.zeros((t, 3), np.int32), np.zeros((t, 3), np.float32),
            np.zeros((t, 3)), np.zeros((t, 3), np.float32), np.zeros((t, 3), np.float32),
            np.zeros(t, np.int64), np.zeros(t, np.bool_),
            np.zeros((t, 4), np.int32), np.zeros(t, np.int64), np.zeros(t, np.int32),
            np.zeros((t, 3, 3)))
