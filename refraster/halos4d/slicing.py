"""Slicing tetrahedra by planes z = c and voxelizing them (Wang et al. Sec. 4.6; MATH.md §5.6).

Slice planes
    N planes perpendicular to screen z at the centres of N equal intervals of ``[z0, z1]``:
    ``c_k = z0 + (k + 0.5)·(z1 − z0)/N`` (:func:`voxel_centres`, the single formula used by every
    kernel and by the tests' brute force).

Cross-section (§5.6)
    ``s_i = z_i − c``; ``s_i = 0`` counts as positive. 1 or 3 positive vertices give the triangle
    ``[e_ab, e_ac, e_ad]`` of the lone vertex a; 2 give the quad ``[e_ac, e_ad, e_bd, e_bc]``,
    split as ``(e_ac, e_ad, e_bd)`` and ``(e_ac, e_bd, e_bc)``. An edge point is always computed
    from the endpoint with the smaller global vertex index, ``λ = s_p/(s_p − s_q)``,
    ``X = X_p + λ(X_q − X_p)``, so two tetrahedra sharing an edge produce bit-identical points and
    the cross-sections of a conforming mesh form a conforming triangle mesh. Every attribute
    (4D depth, t, colour) is interpolated with the same λ (linearly in projected 3D, as the
    paper's GPU pipeline; §5.6 [guess] for perspective).

Voxel tie rule (``voxelize``)
    * ``snap=False``: a voxel centre p is in tetrahedron T when, for each face (vertices i < j < k
      by global index, ``O(p) = ((v_j − v_i) × (v_k − v_i))·(p − v_i)`` in float64), ``O(p)`` has
      the sign of ``O`` at the opposite vertex, or ``O(p) = 0`` and the face's inward normal is
      lexicographically positive (x, then y, then z). This is p perturbed by ``(ε, ε², ε³)``; as
      both tetrahedra sharing a face evaluate the same ``O(p)`` and opposite normals, exactly one
      of them claims a centre on the face. Degenerate tetrahedra (``O = 0`` at a vertex) claim
      nothing.
    * ``snap=True``: the renderer's own coverage: the slice polygon's vertices go through the
      orthographic camera and the foundation rasterizer's float32 viewport transform, are snapped
      to 1/256 pixel, and pixel centres are tested with exact integer edge functions and the
      llvmpipe fill rule (left and bottom edges own their centres). Exact, so every centre inside
      a conforming mesh is claimed once; it differs from ``snap=False`` only within 1/512 pixel of
      a polygon edge.
    Where tetrahedra overlap (twisted prisms) the smallest tetrahedron index wins.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import IJIT, JIT, PJIT
from .._validate import as_float_array, as_index_array

__all__ = ["voxel_centres", "slice_tetrahedra", "SliceTriangles", "voxelize", "ortho_ndc",
           "MAX_SLICES"]

#: Largest slice count accepted (the paper uses at most 512).
MAX_SLICES = 4096
SUBPIXEL_BITS = 8


def _shape3(shape):
    if not isinstance(shape, (tuple, list)) or len(shape) != 3:
        raise TypeError(f"shape must be a tuple (N, H, W), got {shape!r}")
    out = []
    for name, v in zip(("N", "H", "W"), shape):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"shape {name} must be an int, got {type(v).__name__}")
        if not 1 <= v <= (MAX_SLICES if name == "N" else 1 << 15):
            raise ValueError(f"shape {name} = {v} is out of range")
        out.append(int(v))
    if out[0] * out[1] * out[2] > 1 << 30:
        raise ValueError(f"shape {tuple(out)} has more than 2^30 voxels")
    return tuple(out)


def _bounds(bounds):
    b = as_float_array(bounds, "bounds", shape=(2, 3))
    if not np.all(b[1] > b[0]):
        raise ValueError(f"bounds must satisfy min < max on every axis, got {b.tolist()}")
    return b


def voxel_centres(shape, bounds):
    """Voxel-centre coordinates ``(z (N,), y (H,), x (W,))``; row 0 is the top (largest y).

    ``z_k = z0 + (k + 0.5)·dz``, ``y_i = y1 − (i + 0.5)·dy``, ``x_j = x0 + (j + 0.5)·dx``.
    """
    n, h, w = _shape3(shape)
    b = _bounds(bounds)
    dz = (b[1, 2] - b[0, 2]) / n
    dy = (b[1, 1] - b[0, 1]) / h
    dx = (b[1, 0] - b[0, 0]) / w
    return (b[0, 2] + (np.arange(n) + 0.5) * dz, b[1, 1] - (np.arange(h) + 0.5) * dy,
            b[0, 0] + (np.arange(w) + 0.5) * dx)


def ortho_ndc(points, bounds):
    """x, y of ``points`` through ``glOrtho(x0, x1, y0, y1, ·, ·)``: NDC ``(V, 2)`` float64."""
    from ..camera import orthographic
    b = np.asarray(bounds, np.float64)
    p = orthographic(b[0, 0], b[1, 0], b[0, 1], b[1, 1], 1.0, 2.0)
    return np.stack([p[0, 0] * points[:, 0] + p[0, 3], p[1, 1] * points[:, 1] + p[1, 3]], axis=1)


# ----------------------------------------------------------------------------- slicing kernels
@njit(**JIT)
def _section_corners(s0, s1, s2, s3):
    """Cross-section of a tetrahedron whose vertices sit at signed heights s0 … s3 (§5.6).

    Returns the number of triangles (0, 1 or 2) and their corners as 6 local edges
    ``(i0, j0, i1, j1, …)``: corner c lies on the edge between local vertices ``i_c`` and ``j_c``.
    """
    p0 = s0 >= 0.0
    p1 = s1 >= 0.0
    p2 = s2 >= 0.0
    p3 = s3 >= 0.0
    npos = p0 + p1 + p2 + p3
    pos = (p0, p1, p2, p3)
    if npos == 0 or npos == 4:
        return 0, (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    if npos == 2:
        # {a, b} on the positive side, {c, d} on the negative side, each in vertex order
        a = b = c = d = -1
        for i in range(4):
            if pos[i]:
                if a < 0:
                    a = i
                else:
                    b = i
            elif c < 0:
                c = i
            else:
                d = i
        # quad [e_ac, e_ad, e_bd, e_bc] → (e_ac, e_ad, e_bd), (e_ac, e_bd, e_bc)
        return 2, (a, c, a, d, b, d, a, c, b, d, b, c)
    lone = 0
    for i in range(4):
        if pos[i] == (npos == 1):
            lone = i
    o1 = (lone + 1) % 4
    o2 = (lone + 2) % 4
    o3 = (lone + 3) % 4
    return 1, (lone, o1, lone, o2, lone, o3, 0, 0, 0, 0, 0, 0)


@njit(**IJIT)
def section_edge(g, s, e, corner):
    """Corner ``corner`` of a cross-section (:func:`_section_corners`' edges ``e``) of the
    tetrahedron with global vertices ``g`` at signed heights ``s``: ``(v_p, v_q, λ)``, the point
    ``X_p + λ(X_q − X_p)``, from the endpoint with the smaller global index (shared edges agree
    bitwise)."""
    i = e[2 * corner]
    j = e[2 * corner + 1]
    if g[i] > g[j]:
        i, j = j, i
    return g[i], g[j], s[i] / (s[i] - s[j])


@njit(**PJIT)
def _count_pass(tets, z, centres, k0, pair_start, pair_count):
    for t in prange(tets.shape[0]):
        z0 = z[tets[t, 0]]
        z1 = z[tets[t, 1]]
        z2 = z[tets[t, 2]]
        z3 = z[tets[t, 3]]
        for p in range(pair_start[t], pair_start[t + 1]):
            c = centres[k0[t] + p - pair_start[t]]
            pair_count[p] = _section_corners(z0 - c, z1 - c, z2 - c, z3 - c)[0]


@njit(**JIT)
def _place(k0, pair_start, pair_count, n):
    """The slices' start offsets ``(n + 1,)`` in the slice-major output (tetrahedra in index
    order within a slice), and the (tetrahedron, slice) pairs that yield triangles grouped by
    slice: pair ``i`` of slice k (``pstarts[k] <= i < pstarts[k + 1]``) is tetrahedron
    ``ptet[i]``, in index order, so the write pass walks each slice's output in order."""
    starts = np.zeros(n + 1, np.int64)
    pstarts = np.zeros(n + 1, np.int64)
    nt = k0.shape[0]
    for t in range(nt):
        for p in range(pair_start[t], pair_start[t + 1]):
            if pair_count[p] > 0:
                k = k0[t] + p - pair_start[t]
                starts[k + 1] += pair_count[p]
                pstarts[k + 1] += 1
    for k in range(n):
        starts[k + 1] += starts[k]
        pstarts[k + 1] += pstarts[k]
    cursor = pstarts[:-1].copy()
    ptet = np.zeros(pstarts[n], np.int64)
    for t in range(nt):
        for p in range(pair_start[t], pair_start[t + 1]):
            if pair_count[p] > 0:
                k = k0[t] + p - pair_start[t]
                ptet[cursor[k]] = t
                cursor[k] += 1
    return starts, pstarts, ptet


@njit(**PJIT)
def _write_pass(tets, z, xy, attr, centres, starts, pstarts, ptet, oxy, oattr, oslice, otet):
    """Parallel over slices: each writes its triangles in output order (no scattered stores
    across the output, which a tetrahedron-major pass makes: one tetrahedron's slices lie
    ``starts[k + 1] − starts[k]`` triangles apart)."""
    nc = attr.shape[1]
    for k in prange(centres.shape[0]):
        c = centres[k]
        o = starts[k]
        for pi in range(pstarts[k], pstarts[k + 1]):
            t = ptet[pi]
            g = (tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3])
            s = (z[g[0]] - c, z[g[1]] - c, z[g[2]] - c, z[g[3]] - c)
            n, e = _section_corners(s[0], s[1], s[2], s[3])
            for corner in range(3 * n):
                vi, vj, lam = section_edge(g, s, e, corner)
                tri = o + corner // 3
                slot = corner % 3
                for q in range(2):
                    oxy[tri, slot, q] = xy[vi, q] + lam * (xy[vj, q] - xy[vi, q])
                for q in range(nc):
                    oattr[tri, slot, q] = attr[vi, q] + lam * (attr[vj, q] - attr[vi, q])
            for q in range(n):
                oslice[o + q] = k
                otet[o + q] = t
            o += n


class SliceTriangles:
    """Cross-section triangles of all slices, grouped by slice (struct of arrays, K triangles).

    ``xy (K, 3, 2)`` float64 positions; ``attr (K, 3, C)`` float64 interpolated attributes;
    ``tet (K,)`` int64 source tetrahedron; ``slice (K,)`` int64 slice index; ``starts (N + 1,)``:
    slice k holds triangles ``starts[k]:starts[k+1]``, in tetrahedron order (the draw order).
    """

    __slots__ = ("xy", "attr", "tet", "slice", "starts")

    def __len__(self):
        return int(self.tet.shape[0])


def slice_tetrahedra(vertices, tets, centres, attributes=None, *, xy=None):
    """Cross-sections of tetrahedra with the planes ``z = centres[k]`` (MATH.md §5.6).

    Parameters
    ----------
    vertices : (V, 3) float
        Only z is used for slicing (and x, y as positions unless ``xy`` is given).
    tets : (T, 4) int
    centres : (N,) float, increasing
    attributes : (V, C) float, optional
        Interpolated with the edge parameter λ.
    xy : (V, 2) float, optional
        Positions to interpolate instead of vertices' x, y (e.g. already in NDC).

    Returns
    -------
    SliceTriangles
    """
    v = as_float_array(vertices, "vertices", shape=(None, 3))
    tt = as_index_array(tets, "tets", shape=(None, 4), upper=max(len(v), 1))
    c = as_float_array(centres, "centres", shape=(None,))
    if c.size == 0 or c.size > MAX_SLICES:
        raise ValueError(f"centres must hold 1 to {MAX_SLICES} planes, got {c.size}")
    if np.any(np.diff(c) <= 0):
        raise ValueError("centres must be strictly increasing")
    a = (np.zeros((len(v), 0)) if attributes is None
         else as_float_array(attributes, "attributes", shape=(len(v), None)))
    pos = v[:, :2].copy() if xy is None else as_float_array(xy, "xy", shape=(len(v), 2))
    return _slice(v[:, 2].copy(), tt, c, np.ascontiguousarray(a), np.ascontiguousarray(pos))


def slice_ranges(z, tets, centres):
    """Per tetrahedron, the slices ``k0 <= k < k1`` whose plane cuts it: ``min z < c_k <= max
    z`` (s = 0 counts as positive); ``k1 <= k0`` where none does."""
    zt = z[tets].reshape(-1, 4)
    k0 = np.searchsorted(centres, zt.min(axis=1, initial=np.inf), side="right").astype(np.int64)
    k1 = np.searchsorted(centres, zt.max(axis=1, initial=-np.inf), side="right").astype(np.int64)
    return k0, k1


def _slice(z, tets, centres, attr, xy):
    k0, k1 = slice_ranges(z, tets, centres)
    pair_start = np.zeros(len(tets) + 1, np.int64)
    np.cumsum(np.maximum(k1 - k0, 0), out=pair_start[1:])
    pair_count = np.zeros(int(pair_start[-1]), np.int64)
    _count_pass(tets, z, centres, k0, pair_start, pair_count)
    starts, pstarts, ptet = _place(k0, pair_start, pair_count, len(centres))
    k = int(starts[-1])
    st = SliceTriangles()
    st.xy = np.zeros((k, 3, 2))
    st.attr = np.zeros((k, 3, attr.shape[1]))
    st.tet = np.zeros(k, np.int64)
    st.slice = np.zeros(k, np.int64)
    _write_pass(tets, z, xy, attr, centres, starts, pstarts, ptet, st.xy, st.attr, st.slice,
                st.tet)
    st.starts = starts
    return st


# ----------------------------------------------------------------------------- window setup
@njit(**PJIT)
def window_setup(ndc, width, height, bits, X, Y, XF, YF, order, bbox, valid):
    """The foundation's viewport transform, snapping and triangle set-up, for w = 1 triangles.

    Replicates :mod:`refraster.raster.primitive` bit for bit (float32 ``x·W/2 + W/2``, minus the
    half-pixel offset, ``rint`` to ``1/2^bits``; zero-area triangles dropped; clockwise ones
    stored with their last two vertices swapped, ``order`` mapping stored → original vertex).
    ``XF, YF`` keep the unsnapped float32 window positions, from which the foundation
    interpolates.
    """
    hw = np.float32(width * 0.5)
    hh = np.float32(height * 0.5)
    half = np.float32(0.5)
    s = np.float32(1 << bits)
    one = np.int64(1) << bits
    for t in prange(ndc.shape[0]):
        # the three vertices in scalars (no per-triangle arrays: issue 46)
        x0, y0, xf0, yf0 = _window_vertex(ndc[t, 0, 0], ndc[t, 0, 1], hw, hh, half, s)
        x1, y1, xf1, yf1 = _window_vertex(ndc[t, 1, 0], ndc[t, 1, 1], hw, hh, half, s)
        x2, y2, xf2, yf2 = _window_vertex(ndc[t, 2, 0], ndc[t, 2, 1], hw, hh, half, s)
        a = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if a == 0:
            valid[t] = False
            continue
        X[t, 0], Y[t, 0], XF[t, 0], YF[t, 0], order[t, 0] = x0, y0, xf0, yf0, 0
        if a > 0:
            X[t, 1], Y[t, 1], XF[t, 1], YF[t, 1], order[t, 1] = x1, y1, xf1, yf1, 1
            X[t, 2], Y[t, 2], XF[t, 2], YF[t, 2], order[t, 2] = x2, y2, xf2, yf2, 2
        else:
            X[t, 1], Y[t, 1], XF[t, 1], YF[t, 1], order[t, 1] = x2, y2, xf2, yf2, 2
            X[t, 2], Y[t, 2], XF[t, 2], YF[t, 2], order[t, 2] = x1, y1, xf1, yf1, 1
        xmin = min(x0, x1, x2)
        xmax = max(x0, x1, x2)
        ymin = min(y0, y1, y2)
        ymax = max(y0, y1, y2)
        bbox[t, 0] = max((xmin + one - 1) >> bits, 0)
        bbox[t, 1] = min(xmax >> bits, width - 1)
        bbox[t, 2] = max((ymin + one - 1) >> bits, 0)
        bbox[t, 3] = min(ymax >> bits, height - 1)
        valid[t] = bbox[t, 0] <= bbox[t, 1] and bbox[t, 2] <= bbox[t, 3]


@njit(**JIT)
def _window_vertex(nx, ny, hw, hh, half, s):
    """One vertex of :func:`window_setup`: snapped ``(X, Y)`` and float32 window ``(xf, yf)``."""
    x = np.float32(nx)
    y = np.float32(ny)
    rw = np.float32(1.0) / np.float32(1.0)
    xw = x * rw * hw + hw
    yw = y * rw * hh + hh
    return (np.int64(np.rint((xw - half) * s)), np.int64(np.rint((yw - half) * s)),
            np.float64(xw), np.float64(yw))


def setup_window(ndc, width, height, bits=SUBPIXEL_BITS):
    n = ndc.shape[0]
    X = np.zeros((n, 3), np.int64)
    Y = np.zeros((n, 3), np.int64)
    order = np.zeros((n, 3), np.int64)
    XF = np.zeros((n, 3))
    YF = np.zeros((n, 3))
    bbox = np.zeros((n, 4), np.int64)
    valid = np.zeros(n, np.bool_)
    window_setup(np.ascontiguousarray(ndc), width, height, bits, X, Y, XF, YF, order, bbox,
                 valid)
    return X, Y, order, bbox, valid, XF, YF


@njit(**JIT)
def _edge(X, Y, t, k, px, py, bits):
    """Edge function of the edge opposite stored vertex k at pixel (px, py), and its bias
    (0 when the llvmpipe rule gives the edge its centres: a left or bottom edge)."""
    a = (k + 1) % 3
    b = (k + 2) % 3
    dx = X[t, b] - X[t, a]
    dy = Y[t, b] - Y[t, a]
    bias = 0 if (dy < 0 or (dy == 0 and dx > 0)) else 1
    return dx * ((py << bits) - Y[t, a]) - dy * ((px << bits) - X[t, a]), bias


@njit(**JIT)
def covered(X, Y, t, px, py, bits):
    """Coverage of pixel (px, py) by stored triangle t; also the raw edge values (λ·2A)."""
    # k as int64 variables, not literals: one _edge, not three (issue 27)
    e0, b0 = _edge(X, Y, t, np.int64(0), px, py, bits)
    e1, b1 = _edge(X, Y, t, np.int64(1), px, py, bits)
    e2, b2 = _edge(X, Y, t, np.int64(2), px, py, bits)
    return (e0 - b0 >= 0 and e1 - b1 >= 0 and e2 - b2 >= 0), e0, e1, e2


# ----------------------------------------------------------------------------- voxelize
@njit(**PJIT)
def _voxelize_snapped(X, Y, bbox, valid, tet, starts, width, height, bits, out, claims):
    n = starts.shape[0] - 1
    for k in prange(n):
        for j in range(starts[k], starts[k + 1]):
            if not valid[j]:
                continue
            for py in range(bbox[j, 2], bbox[j, 3] + 1):
                row = height - 1 - py
                for px in range(bbox[j, 0], bbox[j, 1] + 1):
                    if covered(X, Y, j, px, py, bits)[0]:
                        claims[k, row, px] += 1
                        if out[k, row, px] < 0:
                            out[k, row, px] = tet[j]


@njit(**JIT)
def face_orientation(v, i, j, k, p0, p1, p2):
    """``((v_j − v_i) × (v_k − v_i))·(p − v_i)`` and the cross product, in one fixed order."""
    ax = v[j, 0] - v[i, 0]
    ay = v[j, 1] - v[i, 1]
    az = v[j, 2] - v[i, 2]
    bx = v[k, 0] - v[i, 0]
    by = v[k, 1] - v[i, 1]
    bz = v[k, 2] - v[i, 2]
    nx = ay * bz - az * by
    ny = az * bx - ax * bz
    nz = ax * by - ay * bx
    o = (nx * (p0 - v[i, 0]) + ny * (p1 - v[i, 1])) + nz * (p2 - v[i, 2])
    return o, nx, ny, nz


@njit(**JIT)
def _sorted3(a, b, c):
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return a, b, c


@njit(**JIT)
def _face(tets, t, m):
    """Global indices, sorted, of the face of tetrahedron t opposite its vertex m."""
    return _sorted3(tets[t, (m + 1) % 4], tets[t, (m + 2) % 4], tets[t, (m + 3) % 4])


@njit(**JIT)
def tet_setup(v, tets, t, sides, owned):
    """Per face m (opposite vertex m): the sign of O at the opposite vertex and whether the face
    owns centres on it (inward normal lexicographically positive). False if degenerate."""
    for m in range(4):
        i0, i1, i2 = _face(tets, t, m)
        vm = tets[t, m]
        o, nx, ny, nz = face_orientation(v, i0, i1, i2, v[vm, 0], v[vm, 1], v[vm, 2])
        if o == 0.0:
            return False
        sg = 1.0 if o > 0.0 else -1.0
        sides[m] = sg
        nx *= sg
        ny *= sg
        nz *= sg
        owned[m] = nx > 0.0 or (nx == 0.0 and (ny > 0.0 or (ny == 0.0 and nz > 0.0)))
    return True


@njit(**JIT)
def inside_tet(v, tets, t, sides, owned, p0, p1, p2):
    for m in range(4):
        i0, i1, i2 = _face(tets, t, m)
        o = face_orientation(v, i0, i1, i2, p0, p1, p2)[0] * sides[m]
        if o < 0.0 or (o == 0.0 and not owned[m]):
            return False
    return True


@njit(**PJIT)
def _voxelize_exact(v, tets, zc, yc, xc, out, claims):
    n = zc.shape[0]
    h = yc.shape[0]
    w = xc.shape[0]
    nt = tets.shape[0]
    lo = np.zeros((nt, 3))
    hi = np.zeros((nt, 3))
    good = np.zeros(nt, np.bool_)
    sides = np.zeros((nt, 4))
    owned = np.zeros((nt, 4), np.bool_)
    for t in range(nt):
        good[t] = tet_setup(v, tets, t, sides[t], owned[t])
        for c in range(3):
            lo[t, c] = min(v[tets[t, 0], c], v[tets[t, 1], c], v[tets[t, 2], c], v[tets[t, 3], c])
            hi[t, c] = max(v[tets[t, 0], c], v[tets[t, 1], c], v[tets[t, 2], c], v[tets[t, 3], c])
    dx = xc[1] - xc[0] if w > 1 else 1.0
    dy = yc[0] - yc[1] if h > 1 else 1.0
    for k in prange(n):
        z = zc[k]
        for t in range(nt):
            if not good[t] or z < lo[t, 2] or z > hi[t, 2]:
                continue
            # candidate ranges from the bounding box, widened by one voxel: the test decides
            j0 = max(int(np.floor((lo[t, 0] - xc[0]) / dx)) - 1, 0)
            j1 = min(int(np.ceil((hi[t, 0] - xc[0]) / dx)) + 1, w - 1)
            i0 = max(int(np.floor((yc[0] - hi[t, 1]) / dy)) - 1, 0)
            i1 = min(int(np.ceil((yc[0] - lo[t, 1]) / dy)) + 1, h - 1)
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    if inside_tet(v, tets, t, sides[t], owned[t], xc[j], yc[i], z):
                        claims[k, i, j] += 1
                        if out[k, i, j] < 0:
                            out[k, i, j] = t


def voxelize(vertices, tets, shape, bounds, snap=True, *, return_claims=False):
    """Tetrahedron index per voxel of the grid ``shape = (N, H, W)`` over ``bounds``.

    Parameters
    ----------
    vertices : (V, 3) float
    tets : (T, 4) int
    shape : (N, H, W) ints
        N slices along z (slice 0 at the smallest z), H rows (row 0 at the largest y), W columns.
    bounds : (2, 3) float
        ``[[x0, y0, z0], [x1, y1, z1]]``; voxel centres from :func:`voxel_centres`.
    snap : bool
        True: the renderer's coverage (slice polygons snapped to 1/256 pixel, integer edge
        functions, llvmpipe fill rule). False: exact floating-point point-in-tetrahedron test of
        the voxel centres. Both tie rules are in the module docstring.
    return_claims : bool
        Also return the ``(N, H, W)`` int32 number of tetrahedra claiming each voxel (1 inside a
        conforming mesh; more where tetrahedra overlap).

    Returns
    -------
    (N, H, W) int32
        Smallest claiming tetrahedron index, −1 where empty (and the claims, on request).

    Notes
    -----
    Wang et al. Sec. 4.6 (multi-slice voxelization); MATH.md §5.6.
    """
    v = as_float_array(vertices, "vertices", shape=(None, 3))
    tt = as_index_array(tets, "tets", shape=(None, 4), upper=max(len(v), 1))
    n, h, w = _shape3(shape)
    b = _bounds(bounds)
    if not isinstance(snap, (bool, np.bool_)):
        raise TypeError(f"snap must be a bool, got {type(snap).__name__}")
    out = np.full((n, h, w), -1, np.int32)
    claims = np.zeros((n, h, w), np.int32)
    zc, yc, xc = voxel_centres((n, h, w), b)
    if snap:
        st = _slice(v[:, 2].copy(), tt, zc, np.zeros((len(v), 0)), ortho_ndc(v, b))
        X, Y, _, bbox, valid, _, _ = setup_window(st.xy, w, h)
        _voxelize_snapped(X, Y, bbox, valid, st.tet, st.starts, w, h, SUBPIXEL_BITS, out, claims)
    else:
        _voxelize_exact(v, tt, zc, yc, xc, out, claims)
    return (out, claims) if return_claims else out

