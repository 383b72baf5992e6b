"""The rasterizer: fixed-point edge functions over tiles.

Coverage
    Each triangle (snapped to ``1/2^b`` pixel, pixel centres on integer multiples of ``2^b``;
    see :mod:`refraster.raster.primitive`) is made counter-clockwise (a clockwise face swaps its
    last two vertices) and gets three integer edge functions
    ``E_k(p) = (X_b − X_a)(p_y − Y_a) − (Y_b − Y_a)(p_x − X_a)`` for the edge a→b opposite
    vertex k. A pixel centre is covered when every ``E_k > 0``, or ``E_k = 0`` on an edge the fill
    rule owns. The coordinates are the picture's, y up (the primitive stage turns an upper-left
    window and Vulkan's NDC y into them), so the rules hold as the picture is seen whatever the
    API's conventions. With ``fill_rule="llvmpipe"`` (alias ``"bottom-left"``) a centre on an
    edge belongs to the triangle for which it is a **left** edge (``dy < 0`` walking
    counter-clockwise) or a **bottom** edge (``dy = 0, dx > 0``); ``"top-left"`` (Direct3D's
    rule, in its upper-left coordinates) owns left and top edges. The tie
    rule is a bias of 0 or 1 subtracted from ``E_k`` so the test is ``E_k − bias ≥ 0`` in exact
    int64 arithmetic. Each row's exact span (where all three are ≥ 0) is solved for first, so
    the scan skips the bounding box's empty corners (long slivers cost their area, not their
    box); values inside the span are stepped incrementally.

Interpolation (identical formulas in the fragment-stream and fused paths)
    Snapping decides coverage only; attributes are interpolated from the **unsnapped** float32
    window positions, as Mesa sets up its attribute planes: window depth from the plane through
    the unsnapped vertices, ``z = z0 + dz/dx·(x + ½ − x0) + dz/dy·(y + ½ − y0)`` in float64
    (linear in screen space, as GL), clamped to [0, 1] and rounded to float32; ``λ_k`` = the
    float64 edge function of the unsnapped triangle at the pixel centre times
    ``1 / its doubled area`` (both fall back to the snapped edge functions when snapping
    flipped or flattened a sliver); perspective-correct barycentrics in the original face
    ``b = Σ_k q_k B_k / Σ_k q_k`` with ``q_k = λ_k / w_k`` (``B`` the identity, up to the
    clockwise swap, for an unclipped face), rounded to float32. A covered centre just outside the
    unsnapped triangle extrapolates, as on a GPU.

Tiles
    The viewport is cut into ``TILE × TILE`` pixel tiles; primitives are binned to the tiles
    their bounding box touches, in primitive order (a clipped face's pieces at its place).
    Unclipped faces are set up inside the tile from the per-vertex window positions. Tiles are
    processed in parallel; each writes only its own output range, so the result is
    bit-identical for any thread count.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from .._tiers import kernel as tiered
from .._scratch import OUTPUTS
from ._prefetch import prefetch_row
from .gbuffer import _object_of
from .primitive import BIN_CHUNK as _BIN_CHUNK
from .primitive import CLIPPED, SIMPLE, TILE_SHIFT, bin_shape

TILE = 1 << TILE_SHIFT

#: "No fragment won this pixel" in a tile's winner buffer. Binned items are faces (≥ 0) and
#: clipped pieces −(k + 1) (≤ −1: piece 0 *is* −1), so the sentinel lies below every piece.
NO_ITEM = -(1 << 62)
#: The most faces (over all draw calls) a face image indexes: it is int32 (global face
#: indices 0 … 2³¹ − 1, −1 the background; OpenGL's ``gl_PrimitiveID`` is an int too), half the
#: bytes of an int64 one written by the tile pass and read by ``finalize`` and ``shade``; with
#: one draw call it is handed out as ``prim_id`` (docs/performance.md). :func:`fused`,
#: ``render``, ``render_samples`` and the clip surfaces' pass refuse more.
MAX_FACES = 1 << 31
#: Boxes at most this many pixels wide skip :func:`row_span` in the fused pass (their rows'
#: pixels tested directly: no division per row, the same bits). The narrow block writes out
#: its four columns one by one: change both together.
NARROW = 4

DEPTH_FUNCS = {"never": 0, "less": 1, "equal": 2, "lequal": 3, "greater": 4, "notequal": 5,
               "gequal": 6, "always": 7}


@njit(**IJIT)
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


# ------------------------------------------------------------------------------------ binning

@njit(**IJIT)
def _pieces(sprim, i):
    """Range of clipped pieces of face ``i`` (``sprim`` ascending)."""
    return np.searchsorted(sprim, i, side="left"), np.searchsorted(sprim, i, side="right")


@njit(**IJIT)
def _add(box, ntx, lists, cursor, item):
    """List ``item`` in each tile its pixel box touches (``cursor``: each tile's next slot)."""
    for ty in range(box[2] >> TILE_SHIFT, (box[3] >> TILE_SHIFT) + 1):
        for tx in range(box[0] >> TILE_SHIFT, (box[1] >> TILE_SHIFT) + 1):
            t = ty * ntx + tx
            lists[cursor[t]] = item
            cursor[t] += 1


@njit(**PJIT)
def _bin_pass(status, fbox, sprim, sbox, ntx, starts, lists):
    """Per chunk of faces, write the tile lists: chunk c of tile t from ``starts[c, t]``
    (``(nchunks, ntiles)``, from the primitive stage's counts), so the lists are in primitive
    order whatever the thread count. ``lists`` holds one slot more per chunk after the lists:
    ``len(lists) − nchunks + c``, chunk c's junk slot."""
    nf = status.shape[0]
    nchunks = (nf + _BIN_CHUNK - 1) // _BIN_CHUNK
    for ch in prange(nchunks):
        cursor = starts[ch].copy()
        junk = lists.shape[0] - nchunks + ch
        for i in range(ch * _BIN_CHUNK, min(nf, (ch + 1) * _BIN_CHUNK)):
            s = status[i]
            if s == CLIPPED:   # rare: a branch
                lo, hi = _pieces(sprim, i)
                for k in range(lo, hi):
                    _add(sbox[k], ntx, lists, cursor, -(k + 1))
                continue
            # simple or skipped without a branch on which (a fine mesh's faces alternate
            # between the two at random): a skipped face (box zeros) is listed in the
            # chunk's junk slot
            simple = s == SIMPLE
            x0, x1 = fbox[i, 0] >> TILE_SHIFT, fbox[i, 1] >> TILE_SHIFT
            y0, y1 = fbox[i, 2] >> TILE_SHIFT, fbox[i, 3] >> TILE_SHIFT
            if simple and (x0 != x1 or y0 != y1):   # a box over several tiles
                _add(fbox[i], ntx, lists, cursor, i)
                continue
            t = y0 * ntx + x0 if simple else 0
            lists[cursor[t] if simple else junk] = i
            cursor[t] += simple


def bin_primitives(prims, scratch=None):
    """Tile lists: ``(ntx, nty, starts (ntiles + 1,), lists)``; an item ``i ≥ 0`` is simple face
    ``i``, an item ``−(k + 1)`` clipped piece ``k``; each list is in primitive order. The
    items per chunk of faces and tile are the primitive stage's (``prims.tile_counts``).
    ``scratch``: a :class:`refraster._scratch.Scratch` for the lists (then valid until it is
    used again)."""
    nchunks, ntx, nty = bin_shape(prims.n_faces, prims.width, prims.height)
    counts = prims.tile_counts
    starts = np.zeros(ntx * nty + 1, np.int64)
    np.cumsum(counts.sum(axis=0), out=starts[1:])
    # chunk c of tile t writes from the tile's start plus the earlier chunks' items there
    starts2 = starts[:-1][None, :] + np.cumsum(counts, axis=0) - counts
    n = int(starts[-1])   # and a junk slot per chunk (_bin_pass)
    lists = (np.zeros(n + nchunks, np.int64) if scratch is None
             else scratch.empty("lists", n + nchunks, np.int64))
    st = prims.clipped
    tiered(_bin_pass)(prims.status, prims.bbox, st.prim, st.bbox, ntx, starts2, lists)
    return ntx, nty, starts, lists[:n]


# ------------------------------------------------------------------- per-triangle set-up

@njit(**IJIT)
def _box(item, fbox, sbox):
    """Pixel bounding box ``(x0, x1, y0, y1)`` of a binned item."""
    if item >= 0:
        u = np.uint64(item)   # unsigned: no negative-index fix-up
        return (np.int64(fbox[u, 0]), np.int64(fbox[u, 1]), np.int64(fbox[u, 2]),
                np.int64(fbox[u, 3]))
    k = -item - 1
    return (np.int64(sbox[k, 0]), np.int64(sbox[k, 1]), np.int64(sbox[k, 2]),
            np.int64(sbox[k, 3]))


@njit(**IJIT)
def _box_in_tile(item, fbox, sbox, tx0, tx1, ty0, ty1):
    """An item's pixel box clipped to the tile ``[tx0, tx1] × [ty0, ty1]`` (empty when
    ``x0 > x1`` or ``y0 > y1``)."""
    bx0, bx1, by0, by1 = _box(item, fbox, sbox)
    return max(bx0, tx0), min(bx1, tx1), max(by0, ty0), min(by1, ty1)


@njit(**IJIT)
def tile_rect(tile, ntx, shift, width, height):
    """Pixel rectangle ``(x0, x1, y0, y1)`` (inclusive) of tile number ``tile`` in a row-major
    grid of ``ntx`` tiles per row, ``2^shift`` pixels square, clipped to the viewport."""
    x0 = (tile % ntx) << shift
    y0 = (tile // ntx) << shift
    return x0, min(x0 + (1 << shift), width) - 1, y0, min(y0 + (1 << shift), height) - 1


#: How many items ahead in a tile's list :func:`_prefetch_items` names the rows the tile
#: loop will read: the face's vertex data at ``ITEM_PREFETCH_NEAR``, its ``faces`` and box
#: rows at ``ITEM_PREFETCH_FAR``. A dense mesh's faces scatter their vertices through memory;
#: at 1.3M faces the 1× tile pass took 14 % less time with them. Not in the per-sample pass
#: (its items do 4× the work: 1.3M faces at 4× 134 → 138 ms with them) nor the clip pass
#: (the crank's clip + cap frame: no change).
ITEM_PREFETCH_NEAR = 8
ITEM_PREFETCH_FAR = 16


@njit(**IJIT)
def _prefetch_items(lists, j, end, f, fbox, vX, vY, vZ, vXf, vYf):
    """Prefetch what :func:`_box` and :func:`_load` read for the unclipped faces
    ``ITEM_PREFETCH_NEAR`` and ``ITEM_PREFETCH_FAR`` items after ``lists[j]`` (before ``end``).
    Not 1/w, which the depth loops do not read (prefetching it too made the pass slower): a
    hint, no output changes."""
    far = lists[np.uint64(min(j + ITEM_PREFETCH_FAR, end - 1))]   # (unsigned indices: no
    if far >= 0:                                                   # negative-index fix-up)
        prefetch_row(f, far)
        prefetch_row(fbox, far)
    near = lists[np.uint64(min(j + ITEM_PREFETCH_NEAR, end - 1))]
    if near >= 0:
        un = np.uint64(near)
        for q in range(3):
            v = np.uint64(f[un, q])
            prefetch_row(vX, v)
            prefetch_row(vY, v)
            prefetch_row(vZ, v)
            prefetch_row(vXf, v)
            prefetch_row(vYf, v)


@njit(**IJIT)
def _load(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea):
    """Set up one binned item as a counter-clockwise triangle: its snapped positions (coverage),
    unsnapped positions (interpolation), depths, 1/w, doubled snapped area, face, facing and
    piece (−1 for an unclipped face)."""
    if item >= 0:
        # unsigned vertex indices (checked non-negative by the primitive stage): no
        # negative-index fix-up per gather
        u = np.uint64(item)
        a, b, d = np.uint64(f[u, 0]), np.uint64(f[u, 1]), np.uint64(f[u, 2])
        x0, y0, x1, y1, x2, y2 = vX[a], vY[a], vX[b], vY[b], vX[d], vY[d]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        front = area > 0
        if not front:
            b, d = d, b
            x1, y1, x2, y2 = x2, y2, x1, y1
            area = -area
        return (x0, y0, x1, y1, x2, y2,
                np.float64(vXf[a]), np.float64(vYf[a]), np.float64(vXf[b]), np.float64(vYf[b]),
                np.float64(vXf[d]), np.float64(vYf[d]),
                vZ[a], vZ[b], vZ[d], vIW[a], vIW[b], vIW[d], area, item, front, -1)
    k = -item - 1
    return (np.int64(sX[k, 0]), np.int64(sY[k, 0]), np.int64(sX[k, 1]), np.int64(sY[k, 1]),
            np.int64(sX[k, 2]), np.int64(sY[k, 2]),
            np.float64(sXf[k, 0]), np.float64(sYf[k, 0]), np.float64(sXf[k, 1]),
            np.float64(sYf[k, 1]), np.float64(sXf[k, 2]), np.float64(sYf[k, 2]),
            sZ[k, 0], sZ[k, 1], sZ[k, 2], sIW[k, 0], sIW[k, 1], sIW[k, 2], sarea[k], sprim[k],
            sfront[k], k)


@njit(**IJIT)
def _inv_float_area(fx0, fy0, fx1, fy1, fx2, fy2):
    """1 / doubled area of the unsnapped triangle, or 0 when snapping flipped or flattened it
    (then the snapped edge functions interpolate)."""
    a = (fx1 - fx0) * (fy2 - fy0) - (fx2 - fx0) * (fy1 - fy0)
    return 1.0 / a if a > 0.0 else 0.0


@njit(**IJIT)
def lambdas(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, x, y, e0, e1, e2, inv_area):
    """Screen-space barycentrics of pixel (x, y): from the **unsnapped** positions at the pixel
    centre, as Mesa sets up its attribute planes (snapping decides coverage only)."""
    if inv_af > 0.0:
        cx = np.float64(x) + 0.5
        cy = np.float64(y) + 0.5
        l0 = ((fx2 - fx1) * (cy - fy1) - (fy2 - fy1) * (cx - fx1)) * inv_af
        l1 = ((fx0 - fx2) * (cy - fy2) - (fy0 - fy2) * (cx - fx2)) * inv_af
        l2 = ((fx1 - fx0) * (cy - fy0) - (fy1 - fy0) * (cx - fx0)) * inv_af
        return l0, l1, l2
    return np.float64(e0) * inv_area, np.float64(e1) * inv_area, np.float64(e2) * inv_area


@njit(**IJIT)
def _edge(xa, ya, xb, yb, bits, rule, px, py):
    """Edge a→b: (value at pixel (px, py) minus bias, step in x, step in y, bias)."""
    dx = xb - xa
    dy = yb - ya
    if rule == 0:
        owns = dy < 0 or (dy == 0 and dx > 0)   # left or bottom edge
    else:
        owns = dy < 0 or (dy == 0 and dx < 0)   # left or top edge
    bias = np.int64(0) if owns else np.int64(1)
    e = dx * ((np.int64(py) << bits) - ya) - dy * ((np.int64(px) << bits) - xa) - bias
    return e, -(dy << bits), dx << bits, bias


@njit(**IJIT)
def _span1(r, sx, lo, hi):
    """Narrow [lo, hi] (offsets from the row's first pixel) to where r + sx·k ≥ 0."""
    if sx > 0:
        if r < 0:
            lo = max(lo, -(r // sx))          # ceil(−r / sx)
    elif sx < 0:
        if r < 0:
            return lo, lo - 1
        hi = min(hi, r // (-sx))              # floor(r / −sx)
    elif r < 0:
        return lo, lo - 1
    return lo, hi


@njit(**IJIT)
def row_span(r0, sx0, r1, sx1, r2, sx2, n):
    """Offsets ``[a, b]`` within a row of ``n`` pixels where all three (biased) edge functions
    are ≥ 0: the row's exact span, so the scan skips the bounding box's empty corners."""
    a, b = _span1(r0, sx0, 0, n - 1)
    a, b = _span1(r1, sx1, a, b)
    return _span1(r2, sx2, a, b)


@njit(**IJIT)
def depth_plane(fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, inv_af):
    """Gradient ``(dz/dx, dz/dy)`` of the window-depth plane through the unsnapped vertices."""
    if inv_af <= 0.0:
        return 0.0, 0.0
    a = np.float64(z1) - np.float64(z0)
    b = np.float64(z2) - np.float64(z0)
    return ((a * (fy2 - fy0) - b * (fy1 - fy0)) * inv_af,
            (b * (fx1 - fx0) - a * (fx2 - fx0)) * inv_af)


@njit(**IJIT)
def fragment_depth(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, x, y, e0, e1, e2, inv_area):
    """Window depth at the centre of pixel (x, y): the plane through the unsnapped vertices,
    ``z0 + dz/dx·(x + ½ − x0) + dz/dy·(y + ½ − y0)`` (the snapped edge functions' barycentrics
    when snapping flattened the triangle), clamped to [0, 1], rounded to float32."""
    if inv_af > 0.0:
        z = np.float64(z0) + dzdx * ((np.float64(x) + 0.5) - fx0) \
            + dzdy * ((np.float64(y) + 0.5) - fy0)
    else:
        z = (np.float64(e0) * inv_area * np.float64(z0) + np.float64(e1) * inv_area
             * np.float64(z1) + np.float64(e2) * inv_area * np.float64(z2))
    if z < 0.0:
        z = 0.0
    elif z > 1.0:
        z = 1.0
    return np.float32(z)


@njit(**IJIT)
def perspective_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2):
    """Perspective-correct barycentrics ``(b0, b1, b2)`` (float32) in the original face from the
    screen-space ``λ`` of a set-up triangle (vertex order restored for a clockwise face)."""
    q0 = l0 * iw0
    q1 = l1 * iw1
    q2 = l2 * iw2
    s = q0 + q1 + q2
    if piece < 0:
        # an unclipped face: its own vertices, in order 0, 1, 2 (front) or 0, 2, 1 (back)
        if front:
            return np.float32(q0 / s), np.float32(q1 / s), np.float32(q2 / s)
        return np.float32(q0 / s), np.float32(q2 / s), np.float32(q1 / s)
    return (np.float32((q0 * B[piece, 0, 0] + q1 * B[piece, 1, 0] + q2 * B[piece, 2, 0]) / s),
            np.float32((q0 * B[piece, 0, 1] + q1 * B[piece, 1, 1] + q2 * B[piece, 2, 1]) / s),
            np.float32((q0 * B[piece, 0, 2] + q1 * B[piece, 1, 2] + q2 * B[piece, 2, 2]) / s))


@njit(**IJIT)
def fragment_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2, out, o):
    b0, b1, b2 = perspective_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2)
    out[o, 0] = b0
    out[o, 1] = b1
    out[o, 2] = b2


@njit(**IJIT)
def write_winner(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront,
                 sarea, B, bits, rule, x, y, row, width, o_prim, o_front, o_bary):
    """The face, facing and barycentrics of the item that won pixel (x, y) (output ``row``),
    recomputed exactly as the fragment stream computes them."""
    (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2, area,
     prim, front, piece, inv_af, inv_area) = _setup_winner(
        item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea)
    o_prim[row, x] = prim
    o_front[row, x] = front
    e0, _, _, b0 = _edge(x1, y1, x2, y2, bits, rule, x, y)
    e1, _, _, b1 = _edge(x2, y2, x0, y0, bits, rule, x, y)
    e2, _, _, b2 = _edge(x0, y0, x1, y1, bits, rule, x, y)
    l0, l1, l2 = lambdas(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, x, y, e0 + b0, e1 + b1, e2 + b2,
                         inv_area)
    fragment_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2, o_bary, row * width + x)


@njit(**IJIT)
def _setup_winner(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront,
                  sarea):
    """:func:`_load`'s values of one binned item and its 1 / unsnapped doubled area
    (:func:`_inv_float_area`) and 1 / snapped doubled area: the set-up a tile's write-out of
    the winners redoes once per run of pixels won by one item (and :func:`_setup` starts
    from)."""
    (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2,
     area, prim, front, piece) = _load(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ,
                                       sIW, sXf, sYf, sprim, sfront, sarea)
    return (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2,
            area, prim, front, piece, _inv_float_area(fx0, fy0, fx1, fy1, fx2, fy2),
            1.0 / np.float64(area))


@njit(**IJIT)
def _setup(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea,
           bits, rule, px, py):
    """Everything the tile loops need of one binned triangle: its three edge functions at pixel
    (px, py) with their steps and biases, unsnapped positions, depths, 1/w, face, facing, piece,
    1/area (snapped and unsnapped) and the depth plane's gradient."""
    (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2,
     area, prim, front, piece, inv_af, inv_area) = _setup_winner(
        item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea)
    r0, sx0, sy0, b0 = _edge(x1, y1, x2, y2, bits, rule, px, py)
    r1, sx1, sy1, b1 = _edge(x2, y2, x0, y0, bits, rule, px, py)
    r2, sx2, sy2, b2 = _edge(x0, y0, x1, y1, bits, rule, px, py)
    dzdx, dzdy = depth_plane(fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, inv_af)
    return (r0, sx0, sy0, b0, r1, sx1, sy1, b1, r2, sx2, sy2, b2, fx0, fy0, fx1, fy1, fx2, fy2,
            z0, z1, z2, iw0, iw1, iw2, prim, front, piece, inv_area, inv_af, dzdx, dzdy)


@njit(**IJIT)
def _narrow_pixel(zbuf, win, ly, lx, zx, zy, item, out, greater):
    """One pixel of a narrow box's row in the fused pass's "less" (``greater`` False) or
    "greater" loop: unless ``out`` (outside an edge), the depth ``zx + zy`` (its column's
    and its row's terms), clamped to [0, 1] (NaN kept), tested against and written into the
    tile's buffers, ``item`` the winner where it passes."""
    if out:
        return
    z = zx + zy
    z = 0.0 if z < 0.0 else (1.0 if z > 1.0 else z)
    zf = np.float32(z)
    if (zf > zbuf[ly, lx]) if greater else (zf < zbuf[ly, lx]):
        zbuf[ly, lx] = zf
        win[ly, lx] = item


# ------------------------------------------------------------------------------ kernels

@njit(**PJIT)
def _stream_pass(f, vX, vY, vZ, vIW, vXf, vYf, fbox, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront,
                 sbox, sarea, B,
                 starts, lists, ntx, width, height, bits, rule, write, counts, offsets,
                 face_offsets, o_pixel, o_depth, o_obj, o_prim, o_front, o_bary):
    ntiles = starts.shape[0] - 1
    with_bary = o_bary.shape[0] != 0
    for tile in prange(ntiles):
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
            # the face's draw call and its index there, once per triangle (not a pass over
            # the stream afterwards: 6 ms of one thread's CPU for the peel's 2.6 M fragments)
            draw = _object_of(face_offsets, prim)
            oid = np.int32(draw)
            local = np.int32(prim - face_offsets[draw])
            for y in range(by0, by1 + 1):
                a, b = row_span(r0, sx0, r1, sx1, r2, sx2, bx1 - bx0 + 1)
                if not write:
                    # the counting pass: row_span's span is exact (every pixel of it passes
                    # the three edge tests below, no other does), so its length is the
                    # row's count (the peel's two passes 36.4 → 29.3 ms of one thread,
                    # 2026-12-05)
                    o += max(b - a + 1, 0)
                    r0 += sy0
                    r1 += sy1
                    r2 += sy2
                    continue
                e0 = r0 + sx0 * a
                e1 = r1 + sx1 * a
                e2 = r2 + sx2 * a
                row = (height - 1 - y) * width
                for x in range(bx0 + a, bx0 + b + 1):
                    if e0 >= 0 and e1 >= 0 and e2 >= 0:
                        if write:
                            o_pixel[o] = row + x
                            o_obj[o] = oid
                            o_prim[o] = local
                            o_front[o] = front
                            o_depth[o] = fragment_depth(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af,
                                                        x, y, e0 + b0, e1 + b1, e2 + b2,
                                                        inv_area)
                            if with_bary:
                                l0, l1, l2 = lambdas(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, x, y,
                                                     e0 + b0, e1 + b1, e2 + b2, inv_area)
                                fragment_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2,
                                              o_bary, o)
                        o += 1
                    e0 += sx0
                    e1 += sx1
                    e2 += sx2
                r0 += sy0
                r1 += sy1
                r2 += sy2
        if not write:
            counts[tile] = o - offsets[tile]


def _geometry(prims):
    st = prims.clipped
    return (prims.faces, prims.vx, prims.vy, prims.vz, prims.v_inv_w, prims.vxf, prims.vyf,
            prims.bbox, st.x, st.y, st.z, st.inv_w, st.xf, st.yf, st.prim, st.front, st.bbox,
            st.area, st.bary)


def stream(prims, *, fill_rule=0, bary=True, face_offsets=None):
    """Rasterize the primitive stage's output into a fragment stream.

    Returns ``(pixel, depth, object_id, prim_id, front, bary, tile_offsets)``: fragments
    grouped by tile, and within a tile ordered by primitive, then row, then column;
    ``object_id`` and ``prim_id`` (int32) the draw call of each fragment's face and the face's
    index there, ``face_offsets`` the draws' first faces (``D + 1`` entries; None: one draw
    call); ``bary`` is empty, ``(0, 3)``, unless ``bary`` (the other outputs are the same
    either way).
    """
    if face_offsets is None:
        face_offsets = np.array([0, prims.n_faces], np.int64)
    face_offsets = np.ascontiguousarray(face_offsets, np.int64)
    ntx, nty, starts, lists = bin_primitives(prims)
    ntiles = ntx * nty
    counts = np.zeros(ntiles, np.int64)
    offsets = np.zeros(ntiles, np.int64)
    args = (*_geometry(prims), starts, lists, ntx, prims.width, prims.height,
            prims.subpixel_bits, fill_rule)
    z = (np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros(0, np.int32),
         np.zeros(0, np.int32), np.zeros(0, np.bool_), np.zeros((0, 3), np.float32))
    _stream_pass(*args, False, counts, offsets, face_offsets, *z)
    tile_offsets = np.zeros(ntiles + 1, np.int64)
    np.cumsum(counts, out=tile_offsets[1:])
    n = int(tile_offsets[-1])
    # the write pass writes every fragment the count pass counted: recycled (or new) arrays
    out = (OUTPUTS.empty((n,), np.int64), OUTPUTS.empty((n,), np.float32),
           OUTPUTS.empty((n,), np.int32), OUTPUTS.empty((n,), np.int32),
           OUTPUTS.empty((n,), np.bool_), OUTPUTS.empty((n if bary else 0, 3), np.float32))
    _stream_pass(*args, True, counts, tile_offsets[:-1].copy(), face_offsets, *out)
    return (*out, tile_offsets)


@njit(**IJIT)
def depth_rows(zbuf, win, item, func, r0, sx0, sy0, r1, sx1, sy1, r2, sx2, sy2, fx0, fy0, z0,
               dzdx, dzdy, inv_af, bx0, bx1, by0, by1, tx0, ty0):
    """The depth-only loops of the fused tile passes over one item's box (``bx0 … bx1``,
    ``by0 … by1``, edge functions ``r`` at its first pixel with steps ``sx``, ``sy``) in a tile
    (``zbuf``, ``win`` from ``tx0``, ``ty0``): ``"less"`` and ``"greater"`` with the unsnapped
    depth plane (``inv_af > 0``), the same pixels in the same order and the same depth
    expression as the general loop, so the same bits. Returns False, touching nothing, for
    any other case (the caller's general loop runs then)."""
    n = bx1 - bx0 + 1
    if (func == 1 or func == 4) and inv_af > 0.0 and n <= NARROW:
        # "less" or "greater" (reversed-Z) with the unsnapped depth plane and a box at
        # most NARROW pixels wide (one copy for both: the comparison is a branch
        # taken the same way for every pixel): its row's pixels tested directly, the
        # three biased edge functions at pixel k being r + sx·k (row_span's span
        # is where all three are >= 0), so no division finds the span; same
        # pixels in the same order, the same depth expression: the same bits.
        # The row's (at most NARROW = 4) pixels are written out one by one
        # (_narrow_pixel), each column's depth term zd0 + dz/dx·(x + ½ − x0)
        # computed once per triangle and each row adding its dz/dy term (the
        # same expression, so the same bits). A pixel outside an edge or losing
        # the test is passed over by a branch. At 82k faces this pass took 7.5 ms
        # (one thread) as a loop over k with selects, 7.1 as that loop with
        # branches (LLVM then recomputed the column term per pixel behind a jump
        # table), 6.3 written out (docs/changelog.md, 2026-12-05)
        zd0 = np.float64(z0)
        greater = func == 4
        zx0 = zd0 + dzdx * ((np.float64(bx0) + 0.5) - fx0)
        zx1 = zd0 + dzdx * ((np.float64(bx0 + 1) + 0.5) - fx0)
        zx2 = zd0 + dzdx * ((np.float64(bx0 + 2) + 0.5) - fx0)
        zx3 = zd0 + dzdx * ((np.float64(bx0 + 3) + 0.5) - fx0)
        lx0 = np.uint64(bx0 - tx0)
        for y in range(by0, by1 + 1):
            zy = dzdy * ((np.float64(y) + 0.5) - fy0)
            ly = np.uint64(y - ty0)
            _narrow_pixel(zbuf, win, ly, lx0, zx0, zy, item,
                          (r0 < 0) | (r1 < 0) | (r2 < 0), greater)
            if n > 1:
                _narrow_pixel(zbuf, win, ly, lx0 + np.uint64(1), zx1, zy, item,
                              (r0 + sx0 < 0) | (r1 + sx1 < 0) | (r2 + sx2 < 0),
                              greater)
            if n > 2:
                _narrow_pixel(zbuf, win, ly, lx0 + np.uint64(2), zx2, zy, item,
                              (r0 + 2 * sx0 < 0) | (r1 + 2 * sx1 < 0)
                              | (r2 + 2 * sx2 < 0), greater)
            if n > 3:
                _narrow_pixel(zbuf, win, ly, lx0 + np.uint64(3), zx3, zy, item,
                              (r0 + 3 * sx0 < 0) | (r1 + 3 * sx1 < 0)
                              | (r2 + 3 * sx2 < 0), greater)
            r0 += sy0
            r1 += sy1
            r2 += sy2
        return True
    if func == 1 and inv_af > 0.0:
        # "less" (the default) with the unsnapped depth plane: a loop of its own that
        # LLVM vectorizes (8 pixels per AVX-512 step here; ~0.7x the pass for the
        # cube). Every pixel of row_span's span is covered (the span is exact: where
        # all three biased edge functions are >= 0, checked exhaustively), so there is
        # no edge test, and the edge functions are not stepped; the depth is
        # fragment_depth's expression in its order, (z0 + dz/dx·(x + ½ − x0)) + the
        # row's dz/dy term, clamped as there (NaN kept), the same bits; the test and
        # the writes are selects (a pixel that loses is written its own values back).
        # The column index is unsigned: no negative-index fix-up per pixel.
        zd0 = np.float64(z0)
        for y in range(by0, by1 + 1):
            a, b = row_span(r0, sx0, r1, sx1, r2, sx2, n)
            zy = dzdy * ((np.float64(y) + 0.5) - fy0)
            ly = np.uint64(y - ty0)
            for x in range(bx0 + a, bx0 + b + 1):
                z = (zd0 + dzdx * ((np.float64(x) + 0.5) - fx0)) + zy
                z = 0.0 if z < 0.0 else (1.0 if z > 1.0 else z)
                zf = np.float32(z)
                lx = np.uint64(x - tx0)
                ref = zbuf[ly, lx]
                less = zf < ref
                zbuf[ly, lx] = zf if less else ref
                win[ly, lx] = item if less else win[ly, lx]
            r0 += sy0
            r1 += sy1
            r2 += sy2
        return True
    if func == 4 and inv_af > 0.0:
        # "greater" (reversed-Z): the loop above with the comparison turned, so the
        # reversed-Z convention costs what the default costs (same bits as the
        # callers' general loop: the depth in fragment_depth's order, ties to the first).
        # A copy, not one loop choosing its comparison per pass: that cost the
        # crank's tile pass 0.7 ms (docs/changelog.md, 2026-12-05)
        zd0 = np.float64(z0)
        for y in range(by0, by1 + 1):
            a, b = row_span(r0, sx0, r1, sx1, r2, sx2, n)
            zy = dzdy * ((np.float64(y) + 0.5) - fy0)
            ly = np.uint64(y - ty0)
            for x in range(bx0 + a, bx0 + b + 1):
                z = (zd0 + dzdx * ((np.float64(x) + 0.5) - fx0)) + zy
                z = 0.0 if z < 0.0 else (1.0 if z > 1.0 else z)
                zf = np.float32(z)
                lx = np.uint64(x - tx0)
                ref = zbuf[ly, lx]
                more = zf > ref
                zbuf[ly, lx] = zf if more else ref
                win[ly, lx] = item if more else win[ly, lx]
            r0 += sy0
            r1 += sy1
            r2 += sy2
        return True
    return False


@njit(**PJIT)
def _fused_pass(f, vX, vY, vZ, vIW, vXf, vYf, fbox, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront,
                sbox, sarea, B,
                starts, lists, ntx, width, height, bits, rule, func, clear, fill_face,
                o_depth, o_prim, o_front, o_bary):
    ntiles = starts.shape[0] - 1
    for tile in prange(ntiles):
        tx0, tx1, ty0, ty1 = tile_rect(tile, ntx, TILE_SHIFT, width, height)
        if starts[tile] == starts[tile + 1]:
            # nothing binned: the tile keeps the clear values (the face image's −1 written
            # here with fill_face, the rest by resolved_buffers or the caller's sweep)
            if fill_face:
                for y in range(ty0, ty1 + 1):
                    row = np.uint64(height - 1 - y)
                    for x in range(tx0, tx1 + 1):
                        o_prim[row, np.uint64(x)] = -1
            continue
        zbuf = np.full((TILE, TILE), clear, np.float32)
        win = np.full((TILE, TILE), NO_ITEM, np.int64)
        for j in range(starts[tile], starts[tile + 1]):
            item = lists[j]
            _prefetch_items(lists, j, starts[tile + 1], f, fbox, vX, vY, vZ, vXf, vYf)
            bx0, bx1, by0, by1 = _box_in_tile(item, fbox, sbox, tx0, tx1, ty0, ty1)
            if bx0 > bx1 or by0 > by1:
                continue
            (r0, sx0, sy0, b0, r1, sx1, sy1, b1, r2, sx2, sy2, b2, fx0, fy0, fx1, fy1, fx2, fy2,
             z0, z1, z2, iw0, iw1, iw2, prim, front, piece, inv_area, inv_af, dzdx,
             dzdy) = _setup(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim,
                            sfront, sarea, bits, rule, bx0, by0)
            if depth_rows(zbuf, win, item, func, r0, sx0, sy0, r1, sx1, sy1, r2, sx2, sy2, fx0,
                          fy0, z0, dzdx, dzdy, inv_af, bx0, bx1, by0, by1, tx0, ty0):
                continue
            for y in range(by0, by1 + 1):
                a, b = row_span(r0, sx0, r1, sx1, r2, sx2, bx1 - bx0 + 1)
                e0 = r0 + sx0 * a
                e1 = r1 + sx1 * a
                e2 = r2 + sx2 * a
                ly = y - ty0
                for x in range(bx0 + a, bx0 + b + 1):
                    if e0 >= 0 and e1 >= 0 and e2 >= 0:
                        z = fragment_depth(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, x, y,
                                           e0 + b0, e1 + b1, e2 + b2, inv_area)
                        lx = x - tx0
                        if depth_test(func, z, zbuf[ly, lx]):
                            zbuf[ly, lx] = z
                            win[ly, lx] = item
                    e0 += sx0
                    e1 += sx1
                    e2 += sx2
                r0 += sy0
                r1 += sy1
                r2 += sy2
        # write the resolved tile where a fragment won (the rest keeps the clear values
        # resolved_buffers filled in; with fill_face the face image's −1 is written here):
        # write_winner's computation, with the triangle's set-up (_load, 1/area,
        # 1/unsnapped area) done once per run of pixels won by the same item
        # instead of once per pixel (the same values, so the same bits). Written out here,
        # not called: a call with its 33 arguments is one CPython makes through
        # CALL_FUNCTION_EX (more than 30), which Numba cannot inline into a prange body
        # ("Calling a closure with *args"), and as a called function the post-pass ran
        # ~20 % slower.
        last = lists[starts[tile]]
        (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1, iw2, area,
         prim, front, piece, inv_af, inv_area) = _setup_winner(
            last, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim, sfront, sarea)
        for y in range(ty0, ty1 + 1):
            row = np.uint64(height - 1 - y)   # unsigned indices: no negative-index fix-up
            ly = np.uint64(y - ty0)
            for x in range(tx0, tx1 + 1):
                ux = np.uint64(x)
                lx = np.uint64(x - tx0)
                item = win[ly, lx]
                if item == NO_ITEM:
                    if fill_face:
                        o_prim[row, ux] = -1
                    continue
                if item != last:
                    last = item
                    (x0, y0, x1, y1, x2, y2, fx0, fy0, fx1, fy1, fx2, fy2, z0, z1, z2, iw0, iw1,
                     iw2, area, prim, front, piece, inv_af, inv_area) = _setup_winner(
                        item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim,
                        sfront, sarea)
                o_depth[row, ux] = zbuf[ly, lx]
                o_prim[row, ux] = prim
                o_front[row, ux] = front
                e0, _, _, b0 = _edge(x1, y1, x2, y2, bits, rule, x, y)
                e1, _, _, b1 = _edge(x2, y2, x0, y0, bits, rule, x, y)
                e2, _, _, b2 = _edge(x0, y0, x1, y1, bits, rule, x, y)
                l0, l1, l2 = lambdas(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, x, y,
                                     e0 + b0, e1 + b1, e2 + b2, inv_area)
                fragment_bary(iw0, iw1, iw2, piece, front, B, l0, l1, l2, o_bary,
                              row * np.uint64(width) + ux)


def face_image_limit(n_faces, who):
    """Refuse more faces than an int32 face image indexes (:data:`MAX_FACES`), in one line
    naming ``who`` takes them."""
    if n_faces > MAX_FACES:
        raise ValueError(f"{who} takes at most {MAX_FACES:,} faces (its face image is int32), "
                         f"not {n_faces:,}")


def resolved_buffers(height, width, clear_depth, fill=True, face=True):
    """The outputs of a fused tile pass, holding what a pixel no fragment won keeps: depth
    ``clear_depth``, face −1 (int32: :data:`MAX_FACES`), facing False, barycentrics 0
    (NumPy's fills are ~10× faster than writing the background pixel by pixel in the tile
    loop). ``fill=False``: only the face image filled (the others' background is the
    caller's: ``finalize``'s sweep). ``face=False``: the face image not filled either (the
    tile pass writes its −1: :func:`fused`)."""
    # from the output pool: recycled once nobody holds them (refraster._scratch.OutputPool)
    prim = (OUTPUTS.full((height, width), -1, np.int32) if face
            else OUTPUTS.empty((height, width), np.int32))
    if not fill:
        return (OUTPUTS.empty((height, width), np.float32), prim,
                OUTPUTS.empty((height, width), np.bool_),
                OUTPUTS.empty((height * width, 3), np.float32))
    return (OUTPUTS.full((height, width), np.float32(clear_depth), np.float32), prim,
            OUTPUTS.full((height, width), False, np.bool_),
            OUTPUTS.full((height * width, 3), 0.0, np.float32))


def fused(prims, *, fill_rule=0, depth_func=1, clear_depth=1.0, buffers=None, scratch=None,
          cleared=False, fill=True):
    """Rasterize and depth-resolve in one pass (no fragment stream, depth writes on).

    Returns ``(depth (H, W) float32, prim (H, W) int32 face index or −1, front (H, W) bool,
    bary (H·W, 3) float32)``; bit-identical to :func:`stream` followed by
    :func:`refraster.raster.resolve.resolve` with the same ``depth_func`` (a test checks it).
    ``buffers``: four such arrays (C-contiguous, checked by the caller) to fill and reuse
    instead of new ones; with ``cleared`` they already hold the clear values (a
    :meth:`~refraster.framebuffer.Framebuffer.reusable`'s, cleared where the previous frame
    drew) and are not filled again. ``scratch``: for the tile lists (:func:`bin_primitives`).
    ``fill=False`` (new buffers only): depth, facing and barycentrics hold only the pixels a
    fragment won (:func:`resolved_buffers`), for a caller that writes the rest. At most
    :data:`MAX_FACES` faces; ``buffers``' face image is int32 too.
    """
    face_image_limit(prims.n_faces, "fused")
    ntx, nty, starts, lists = bin_primitives(prims, scratch)
    h, w = prims.height, prims.width
    # the face image's −1 is written by the tile pass itself, in parallel, where no fragment
    # won (fill_face), not filled first by one thread (0.2 ms of the 82k frame at 2 threads);
    # a cleared reusable framebuffer's already holds it
    if buffers is None:
        depth, prim, front, bary = resolved_buffers(h, w, clear_depth, fill, face=False)
    elif cleared:
        depth, prim, front, bary = buffers
    else:   # the same clear values, written into the caller's arrays
        depth, prim, front, bary = buffers
        depth.fill(np.float32(clear_depth))
        front.fill(False)
        bary.fill(0.0)
    tiered(_fused_pass)(*_geometry(prims), starts, lists, ntx, w, h, prims.subpixel_bits, fill_rule,
                depth_func, np.float32(clear_depth), buffers is None or not cleared, depth, prim,
                front, bary)
    return depth, prim, front, bary
