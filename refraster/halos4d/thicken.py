"""View-dependent thickening, prisms → tetrahedra, and the halo depth (Wang et al. Sec. 4.3–4.5).

Thickening (Eq. 1–2, MATH.md §5.3 [fix]): ``n = t1_3D × t2_3D`` is **normalized** (the paper's
unnormalized n would make the halo thickness depend on the parametrization), and where
``|n| < ε·|t1|·|t2|`` (edge-on view, projection folds, singular parametrization such as a
knot's poles) it falls back to the normalized sum of the area-weighted normals of the projected
3D faces around the vertex; if that vanishes too, to +z. The thickened vertex array holds the
lower copy ``v − ρ n̂`` (t = 0) at indices ``0 … n−1`` and the upper copy ``v + ρ n̂`` (t = 1) at
``n … 2n−1``.

Tetrahedra (MATH.md §5.5): :func:`split_prisms` with ``split="paper"`` (the default of
:class:`refraster.halos4d.Halos`) decomposes each prism in its face's vertex order and then
repairs the mismatched shared quads as Wang et al. Sec. 5.1 / Fig. 4 do: a flip of the shared
face's diagonal (Fig. 4(b)), and where a prism's three side diagonals end cyclic (Fig. 4(c)),
two inserted vertices and three smaller prisms (Fig. 4(d)). ``split="global_index"``
(:func:`prism_tetrahedra`) is the global vertex-index rule, which avoids mismatches by
construction.

Halo depth (Eq. 3, MATH.md §5.4): ``d_new = d_orig + max(0, |2t − 1| − δt)·δd``, evaluated per
fragment (|·| is not linear).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .._config import JIT
from .._validate import as_choice, as_float_array, as_index_array, as_real

__all__ = ["thickening_normals", "thicken", "prism_tetrahedra", "split_prisms", "PrismSplit",
           "steiner_values", "SPLITS", "halo_depth", "NORMAL_EPS",
           "default_halo_parameters", "crossing_depth_differences", "RHO_FRACTION",
           "DEPTH_QUANTILE"]

#: Relative threshold of the |t1 × t2| fallback.
NORMAL_EPS = 1e-6


def _face_normal_sum(points, faces, which):
    """Sum of the area-weighted normals of the faces around each vertex of the mask ``which``
    (other rows: partial sums, not to be read). Only the faces at those vertices are summed,
    in the same order (face order, for each corner k in turn), so the bits are the whole sum's."""
    faces = faces[which[faces[:, 0]] | which[faces[:, 1]] | which[faces[:, 2]]]
    a = points[faces[:, 0]]
    fn = np.cross(points[faces[:, 1]] - a, points[faces[:, 2]] - a)   # 2·area·unit normal
    acc = np.zeros_like(points)
    for k in range(3):
        np.add.at(acc, faces[:, k], fn)
    return acc


def thickening_normals(points, tangents, faces):
    """Unit thickening directions n̂ (Eq. 1, normalized; fallback of MATH.md §5.3).

    Parameters
    ----------
    points : (V, 3) float
        Projected vertices (3D screen space).
    tangents : (V, 2, 3) float
        Projected tangents t1, t2.
    faces : (F, 3) int
        Only used by the fallback.

    Returns
    -------
    normals : (V, 3) float64, unit length.
    n_fallback : int
        How many vertices used the face-normal fallback (including the +z last resort).
    """
    p = as_float_array(points, "points", shape=(None, 3))
    t = as_float_array(tangents, "tangents", shape=(p.shape[0], 2, 3))
    f = as_index_array(faces, "faces", shape=(None, 3), upper=max(p.shape[0], 1))
    n = np.cross(t[:, 0], t[:, 1])
    ln = np.linalg.norm(n, axis=1)
    scale = np.linalg.norm(t[:, 0], axis=1) * np.linalg.norm(t[:, 1], axis=1)
    bad = ~(ln > NORMAL_EPS * scale) | (scale == 0.0)
    out = np.zeros_like(n)
    np.divide(n, ln[:, None], out=out, where=~bad[:, None])    # the masked quotients' bits
    if bad.any():
        fb = _face_normal_sum(p, f, bad)[bad]
        lf = np.linalg.norm(fb, axis=1)
        ok = lf > 0.0
        fb[ok] /= lf[ok, None]
        fb[~ok] = (0.0, 0.0, 1.0)
        out[bad] = fb
    return out, int(bad.sum())


def thicken(points, normals, rho):
    """Offset surfaces ``v ± ρ n̂`` (Eq. 2): ``(vertices (2V, 3), t (2V,))``, lower copy first."""
    p = as_float_array(points, "points", shape=(None, 3))
    n = as_float_array(normals, "normals", shape=p.shape)
    rho = as_real(rho, "rho", lo=0.0, lo_open=True)
    verts = np.concatenate([p - rho * n, p + rho * n])
    t = np.concatenate([np.zeros(len(p)), np.ones(len(p))])
    return verts, t


def prism_tetrahedra(faces, n_vertices):
    """Split each prism (face × [lower, upper]) into three tetrahedra by the global vertex-index
    rule (MATH.md §5.5): :func:`split_prisms`' ``split="global_index"``.

    Parameters
    ----------
    faces : (F, 3) int
        Triangles over vertices ``0 … n_vertices−1``; the upper copy of vertex i is
        ``i + n_vertices``. Faces with a repeated vertex are rejected.
    n_vertices : int

    Returns
    -------
    (3F, 4) int64
        Tetrahedra ``3f, 3f+1, 3f+2`` come from face f. With the face's vertices sorted
        ``a < b < c`` (global index) and ``⁺`` the upper copy: ``(a, b, c, c⁺)``,
        ``(a, b, c⁺, b⁺)``, ``(a, a⁺, b⁺, c⁺)``.

    Notes
    -----
    Every quad side is split along the diagonal from its lower-index bottom vertex to the
    higher-index top vertex (a–b⁺, b–c⁺, a–c⁺), which is Dompierre et al.'s rule "diagonal through
    the smallest global index" for the numbering i / i + n; it depends only on the quad's own
    vertices, so two prisms sharing a quad split it the same way, and a prism's minimum vertex
    carries two diagonals, so the pattern is never the cyclic one that needs a Steiner point
    (no repair of Wang et al. Fig. 4 is needed; the paper's split with its repair is
    :func:`split_prisms`' default). Orientation: when the upper copy lies on the side
    of the face normal (right-hand rule of the face as given) of an untwisted prism, all three
    tetrahedra have positive signed volume ``det[v1−v0, v2−v0, v3−v0] > 0``.
    """
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, (int, np.integer)):
        raise TypeError(f"n_vertices must be an int, got {type(n_vertices).__name__}")
    if n_vertices < 3:
        raise ValueError(f"n_vertices must be at least 3, got {n_vertices}")
    f = as_index_array(faces, "faces", shape=(None, 3), upper=int(n_vertices))
    s = np.sort(f, axis=1)
    if np.any((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])):
        bad = int(np.count_nonzero((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])))
        raise ValueError(f"faces has {bad} degenerate triangle(s) with a repeated vertex")
    a, b, c = s[:, 0], s[:, 1], s[:, 2]
    n = int(n_vertices)
    tets = np.stack([
        np.stack([a, b, c, c + n], axis=1),
        np.stack([a, b, c + n, b + n], axis=1),
        np.stack([a, a + n, b + n, c + n], axis=1),
    ], axis=1)
    # sorting by an odd permutation reverses the face's orientation: swap two tet vertices back
    odd = _odd_permutation(f)
    tets[odd] = tets[odd][:, :, [1, 0, 2, 3]]
    return tets.reshape(-1, 4)


#: The prism splits: the paper's decomposition and repair (default), the global-index rule.
SPLITS = ("paper", "global_index")


class PrismSplit(NamedTuple):
    """Result of :func:`split_prisms`.

    ``tets (T, 4)`` int64, prism by prism in face order (3 tetrahedra per prism, 9 per rebuilt
    one); ``prism (T,)`` the face each tetrahedron fills; ``steiner (K, 3)`` the faces of the
    rebuilt prisms, in face order: inserted vertex k is the centroid of face k's lower
    triangle, index ``2·n_vertices + k``, and of its upper triangle, ``2·n_vertices + K + k``
    (:func:`steiner_values`); ``flips`` the number of shared-face diagonals flipped by the
    repair (Fig. 4(b)).
    """

    tets: np.ndarray
    prism: np.ndarray
    steiner: np.ndarray
    flips: int


def _checked_faces(faces, n_vertices):
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, (int, np.integer)):
        raise TypeError(f"n_vertices must be an int, got {type(n_vertices).__name__}")
    if n_vertices < 3:
        raise ValueError(f"n_vertices must be at least 3, got {n_vertices}")
    f = as_index_array(faces, "faces", shape=(None, 3), upper=int(n_vertices))
    s = np.sort(f, axis=1)
    if np.any((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])):
        bad = int(np.count_nonzero((s[:, 0] == s[:, 1]) | (s[:, 1] == s[:, 2])))
        raise ValueError(f"faces has {bad} degenerate triangle(s) with a repeated vertex")
    return f


def paper_diagonals(f):
    """The side diagonals of each prism in the paper's order (Sec. 4.4: one geometry-program
    call per triangle, its vertices in their given order v0, v1, v2), as ``(F, 3)`` int8:
    entry k is 0 when the side over edge ``(v_k, v_k+1)`` is split from ``v_k``'s lower copy
    to ``v_k+1``'s upper copy, 1 for the other diagonal. The order's decomposition is
    ``(v0, v1, v2, v2⁺), (v0, v1, v2⁺, v1⁺), (v0, v0⁺, v1⁺, v2⁺)``: diagonals v0–v1⁺, v1–v2⁺,
    v0–v2⁺, i.e. ``(0, 0, 1)`` for every prism."""
    d = np.zeros((len(f), 3), np.int8)
    d[:, 2] = 1
    return d


def repair_mismatches(f, diag, skip=()):
    """The repair pass of Sec. 5.1 (Fig. 4(b)), in place on ``diag`` (:func:`paper_diagonals`'
    encoding). On every shared face the first prism (smallest face index) keeps its diagonal
    and every later prism whose diagonal differs is flipped there, its other faces keeping
    their pattern (a flip touches one face, so a face repaired stays repaired and the result
    does not depend on the order of the pass). Returns the number of flips. ``skip``: positions
    in the list of flips (ordered by the flipped prism's face index, then side) left undone —
    the tests' planted fault."""
    n_faces = len(f)
    start = np.where(diag == 0, f, np.roll(f, -1, axis=1))      # lower copy the diagonal leaves
    u, w = f, np.roll(f, -1, axis=1)
    nv = np.int64(f.max()) + 1 if n_faces else np.int64(1)
    key = (np.minimum(u, w).astype(np.int64) * nv + np.maximum(u, w)).ravel()
    side = np.arange(3 * n_faces)                               # = 3·face + side, face order
    order = np.lexsort((side, key))
    k = key[order]
    first = np.ones(len(k), bool)
    first[1:] = k[1:] != k[:-1]
    head = order[np.maximum.accumulate(np.where(first, np.arange(len(k)), 0))]
    flat_start = start.ravel()
    wrong = order[flat_start[order] != flat_start[head]]        # later prisms that disagree
    wrong = np.sort(wrong)
    if len(skip):
        wrong = np.delete(wrong, np.asarray(skip, np.int64))
    flat = diag.reshape(-1)
    flat[wrong] ^= 1
    return int(len(wrong))


def _apex_tets(a, b, c, a1, b1, c1, cb):
    """The 3 tetrahedra of prisms whose lower vertex ``a`` carries the diagonals to ``b⁺`` and
    ``c⁺`` (a, b, c in the face's orientation); side (b, c) split b–c⁺ (``cb`` False) or
    c–b⁺ (True). Positive volumes for an untwisted prism with the upper copy on the face
    normal's side."""
    t0 = np.where(cb[:, None], np.stack([a, b, c, b1], 1), np.stack([a, b, c, c1], 1))
    t1 = np.where(cb[:, None], np.stack([a, b1, c, c1], 1), np.stack([a, b, c1, b1], 1))
    t2 = np.stack([a, a1, b1, c1], 1)
    return np.stack([t0, t1, t2], axis=1)


def split_prisms(faces, n_vertices, split="paper"):
    """Split each prism (face × [lower, upper]) into tetrahedra (MATH.md §5.5; Wang et al.
    Sec. 4.4, 5.1, Fig. 4).

    Parameters
    ----------
    faces : (F, 3) int
        Triangles over vertices ``0 … n_vertices−1``; the upper copy of vertex i is
        ``i + n_vertices``. Faces with a repeated vertex are rejected.
    n_vertices : int
    split : {"paper", "global_index"}
        ``"paper"``: every prism decomposed in its face's vertex order
        (:func:`paper_diagonals`), then the mismatched shared faces repaired
        (:func:`repair_mismatches`, Fig. 4(b)); a prism whose three side diagonals end cyclic
        — each of its six vertices on exactly one diagonal, which no 3-tetrahedron
        decomposition admits (Fig. 4(c)) — is rebuilt with two inserted vertices, the
        centroids m, m⁺ of its lower and upper triangles, as three smaller prisms
        ``(m, v_k, v_k+1)`` whose inner sides are split from m (Fig. 4(d)), nine tetrahedra.
        ``"global_index"``: :func:`prism_tetrahedra`, three per prism, no inserted vertex.

    Returns
    -------
    PrismSplit
    """
    f = _checked_faces(faces, n_vertices)
    split = as_choice(split, "split", SPLITS)
    n = int(n_vertices)
    nf = len(f)
    if split == "global_index":
        return PrismSplit(prism_tetrahedra(f, n), np.repeat(np.arange(nf), 3),
                          np.zeros((0, 3), np.int64), 0)
    diag = paper_diagonals(f)
    flips = repair_mismatches(f, diag)
    cyc = (diag[:, 0] == diag[:, 1]) & (diag[:, 1] == diag[:, 2])
    # a valid prism: the lower vertex that starts two diagonals is the apex
    starts = (diag == 0).astype(np.int8) + (np.roll(diag, 1, axis=1) == 1)
    ok = np.flatnonzero(~cyc)
    apex = np.argmax(starts[ok], axis=1)
    rows = ok[:, None]
    loc = (apex[:, None] + np.arange(3)) % 3
    abc = f[rows, loc]
    cb = diag[ok, (apex + 1) % 3] == 1
    valid = _apex_tets(abc[:, 0], abc[:, 1], abc[:, 2], abc[:, 0] + n, abc[:, 1] + n,
                       abc[:, 2] + n, cb)
    # cyclic prisms: three sub-prisms (m, v_k, v_k+1) with apex m (Fig. 4(d))
    cy = np.flatnonzero(cyc)
    kk = len(cy)
    m = 2 * n + np.arange(kk, dtype=np.int64)
    m1 = m + kk
    subs = []
    for side in range(3):
        b, c = f[cy, side], f[cy, (side + 1) % 3]
        subs.append(_apex_tets(m, b, c, m1, b + n, c + n, diag[cy, side] == 1))
    rebuilt = np.concatenate(subs, axis=1) if kk else np.zeros((0, 9, 4), np.int64)
    count = np.where(cyc, 9, 3)
    offset = np.concatenate([[0], np.cumsum(count)])
    tets = np.zeros((int(offset[-1]), 4), np.int64)
    idx = offset[ok][:, None] + np.arange(3)
    tets[idx.ravel()] = valid.reshape(-1, 4)
    idx = offset[cy][:, None] + np.arange(9)
    tets[idx.ravel()] = rebuilt.reshape(-1, 4)
    return PrismSplit(tets, np.repeat(np.arange(nf), count), f[cy].astype(np.int64), flips)


def steiner_values(values, steiner, n_vertices):
    """The per-vertex ``values (2·n_vertices, C)`` of the thickened surface extended by the
    inserted vertices of :func:`split_prisms` (``steiner (K, 3)``): ``(2·n_vertices + 2K, C)``,
    vertex ``2n + k`` the mean ``(x_a + x_b + x_c)/3`` (in that order, float64) of its lower
    triangle's values and ``2n + K + k`` of its upper triangle's — positions on the triangles'
    planes, t = 0 and 1 exactly, the 4D depth and colour of the centroid; computed once, so
    every tetrahedron of the rebuilt prism reads the same bits."""
    v = np.asarray(values, np.float64)
    s = np.asarray(steiner, np.int64)
    if len(s) == 0:
        return v
    n = int(n_vertices)
    lo = (v[s[:, 0]] + v[s[:, 1]] + v[s[:, 2]]) / 3.0
    hi = (v[s[:, 0] + n] + v[s[:, 1] + n] + v[s[:, 2] + n]) / 3.0
    return np.concatenate([v, lo, hi])


def _odd_permutation(f):
    """True where sorting a face's three (distinct) indices is an odd permutation."""
    inversions = ((f[:, 0] > f[:, 1]).astype(int) + (f[:, 0] > f[:, 2]) + (f[:, 1] > f[:, 2]))
    return (inversions % 2) == 1


def halo_depth(d_orig, t, delta_t, delta_d):
    """Eq. 3: ``d_new = d_orig + max(0, |2t − 1| − δt)·δd`` (elementwise, float64)."""
    d = as_float_array(d_orig, "d_orig")
    tt = as_float_array(t, "t")
    delta_t = as_real(delta_t, "delta_t", lo=0.0, hi=1.0)
    delta_d = as_real(delta_d, "delta_d", lo=0.0)
    return d + np.maximum(0.0, np.abs(2.0 * tt - 1.0) - delta_t) * delta_d


#: Default halo radius ρ as a fraction of the projected bounding-box diagonal [guess;
#: docs/halos4d.md, "Defaults"].
RHO_FRACTION = 0.03
#: The default δd keeps Eq. 3 unsaturated for this quantile of the crossing depth differences.
DEPTH_QUANTILE = 0.95
#: Two vertices are on different sheets when their 4D separation is mostly along the view:
#: |Δδ| ≥ OVERLAP_SLOPE·|Δxyz| (xyz: the rotated 4D coordinates orthogonal to the view).
OVERLAP_SLOPE = 1.0


#: Above this many candidate pairs the vertices are thinned (every other one, repeatedly).
MAX_PAIRS = 4_000_000


@njit(**JIT)
def _cell(ukey, q):
    """Index of key ``q`` in the sorted unique cell keys ``ukey``, or −1."""
    lo = 0
    hi = ukey.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if ukey[mid] < q:
            lo = mid + 1
        else:
            hi = mid
    return lo if lo < ukey.shape[0] and ukey[lo] == q else -1


@njit(**JIT)
def _candidate_count(ukey, ucount, offsets):
    """Σ over occupied cells c and the 27 neighbour offsets o of ``n_c · n_(c+o)``: the number
    of (sorted position, neighbour) candidates the grid visits (before ``i < j``)."""
    total = 0
    for c in range(ukey.shape[0]):
        for o in range(offsets.shape[0]):
            k = _cell(ukey, ukey[c] + offsets[o])
            if k >= 0:
                total += ucount[c] * ucount[k]
    return total


#: Relative margin of the grid kernel's distance test: pairs whose squared distance (summed
#: in the kernel's order) lies within it of ``radius²`` are decided by NumPy's ``einsum``.
PAIR_MARGIN = 1e-9


@njit(**JIT)
def _grid_candidates(ps, ukey, ustart, offsets, r2):
    """Sorted positions ``(a, b)``, ``a < b``, of the points in neighbouring cells within the
    radius, in the order (offset, a, b), and per pair 1 when its squared distance is clearly
    below ``r2``, 0 when it lies within :data:`PAIR_MARGIN` of it (the caller decides those
    with the exact test); clearly farther pairs are dropped. A negative offset has no pair
    (its cell's points sort before ``a``). Serial: a few ms, and one order."""
    lo_r2 = r2 * (1.0 - PAIR_MARGIN)
    hi_r2 = r2 * (1.0 + PAIR_MARGIN)
    cap = 1024
    ia = np.empty(cap, np.int64)
    ib = np.empty(cap, np.int64)
    sure = np.empty(cap, np.int8)
    m = 0
    for o in range(offsets.shape[0]):
        if offsets[o] < 0:
            continue
        for c in range(ukey.shape[0]):
            k = _cell(ukey, ukey[c] + offsets[o])
            if k < 0:
                continue
            for a in range(ustart[c], ustart[c + 1]):
                pa0 = ps[a, 0]
                pa1 = ps[a, 1]
                pa2 = ps[a, 2]
                for b in range(max(ustart[k], a + 1), ustart[k + 1]):
                    d0 = pa0 - ps[b, 0]
                    d1 = pa1 - ps[b, 1]
                    d2 = pa2 - ps[b, 2]
                    q = d0 * d0 + d1 * d1 + d2 * d2
                    if q > hi_r2:
                        continue
                    if m == cap:
                        cap *= 2
                        ia2 = np.empty(cap, np.int64)
                        ib2 = np.empty(cap, np.int64)
                        sure2 = np.empty(cap, np.int8)
                        ia2[:m] = ia[:m]
                        ib2[:m] = ib[:m]
                        sure2[:m] = sure[:m]
                        ia, ib, sure = ia2, ib2, sure2
                    ia[m] = a
                    ib[m] = b
                    sure[m] = 1 if q < lo_r2 else 0
                    m += 1
    return ia[:m], ib[:m], sure[:m]


def _close_pairs(points, radius):
    """All pairs ``i < j`` with ``|p_i − p_j| < radius`` (uniform hash grid); when there would
    be more than MAX_PAIRS candidates, the pairs of every other vertex. The grid walk is a
    Numba kernel; a pair within :data:`PAIR_MARGIN` of the radius is decided by the NumPy
    test ``einsum(diff, diff) < radius²``, so the pairs do not depend on the kernel's rounding."""
    cell = np.floor((points - points.min(axis=0)) / radius).astype(np.int64)
    dims = cell.max(axis=0) + 3
    key = ((cell[:, 0] + 1) * dims[1] + (cell[:, 1] + 1)) * dims[2] + (cell[:, 2] + 1)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    ukey, ustart, ucount = np.unique(sk, return_index=True, return_counts=True)
    ustart = np.append(ustart, len(sk)).astype(np.int64)
    offsets = np.array([(dx * dims[1] + dy) * dims[2] + dz for dx in (-1, 0, 1)
                        for dy in (-1, 0, 1) for dz in (-1, 0, 1)], np.int64)
    if (_candidate_count(ukey, ucount.astype(np.int64), offsets) > MAX_PAIRS
            and len(points) > 2):
        sub = np.arange(0, len(points), 2)
        i, j = _close_pairs(points[sub], radius)
        return sub[i], sub[j]
    ps = np.ascontiguousarray(points[order], np.float64)
    i, j, sure = _grid_candidates(ps, ukey, ustart, offsets, float(radius) * float(radius))
    near = sure == 1
    edge = np.flatnonzero(~near)
    if len(edge):
        diff = ps[i[edge]] - ps[j[edge]]
        near[edge] = np.einsum("ij,ij->i", diff, diff) < radius * radius
    i, j = order[i[near]], order[j[near]]
    return np.minimum(i, j), np.maximum(i, j)


def crossing_depth_differences(points, depth, spatial, faces, radius):
    """|Δδ| over pairs of vertices of different sheets that overlap in the 3D projection.

    Pairs: vertices closer than ``radius`` in 3D screen space, not joined by a mesh edge, whose
    4D separation is mostly along the view, ``|Δδ| ≥ OVERLAP_SLOPE·|Δspatial|`` (on one sheet,
    nearby vertices differ in δ by the sheet's slope times their distance; across a crossing
    the 4D-depth difference stays while the spatial distance goes to 0).
    """
    p = as_float_array(points, "points", shape=(None, 3))
    d = as_float_array(depth, "depth", shape=(p.shape[0],))
    x = as_float_array(spatial, "spatial", shape=(p.shape[0], 3))
    f = as_index_array(faces, "faces", shape=(None, 3), upper=max(p.shape[0], 1))
    radius = as_real(radius, "radius", lo=0.0, lo_open=True)
    i, j = _close_pairs(p, radius)
    n = np.int64(p.shape[0])
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    ek = np.unique(np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1]))
    pk = i * n + j
    pos = np.minimum(np.searchsorted(ek, pk), len(ek) - 1)
    edge = ek[pos] == pk
    dd = np.abs(d[i] - d[j])
    sep = np.linalg.norm(x[i] - x[j], axis=1)
    return dd[~edge & (dd >= OVERLAP_SLOPE * sep) & (dd > 0.0)]


def pair_radius(points, faces, rho):
    """Search radius of the overlap pairs: ``max(ρ, 1.5 ×`` the median projected edge)."""
    edges = np.linalg.norm(points[faces[:, [1, 2, 0]]] - points[faces], axis=2).ravel()
    return max(float(rho), 1.5 * float(np.median(edges)) if edges.size else 0.0)


def default_halo_parameters(points, depth, spatial, faces, delta_t, rho=None):
    """Defaults of ρ (Eq. 2) and δd (Eq. 3) that keep Eq. 3 depth-dependent (issue 21).

    ``ρ = RHO_FRACTION ×`` the projected bounding-box diagonal (unless given). ``δd`` is chosen
    so that ``(1 − δt)·δd`` equals the ``DEPTH_QUANTILE`` quantile of the 4D-depth differences
    of sheets that overlap in projection (:func:`crossing_depth_differences`, pairs within
    ``max(ρ, 1.5 ×`` the median projected edge length``)``): up to that quantile the gap next to
    a crossing, ``ρ·min(1, δt + Δδ/δd)``, still grows with the depth difference. Without any
    crossing, ``δd = depth range / (1 − δt)`` (1 if the range is 0).

    Returns ``(rho, delta_d, samples)`` with the number of depth differences used.
    """
    p = as_float_array(points, "points", shape=(None, 3))
    d = as_float_array(depth, "depth", shape=(p.shape[0],))
    f = as_index_array(faces, "faces", shape=(None, 3), upper=max(p.shape[0], 1))
    delta_t = as_real(delta_t, "delta_t", lo=0.0, hi=1.0)
    if rho is None:
        diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
        rho = RHO_FRACTION * diag if diag > 0 else 1.0
    dd = crossing_depth_differences(p, d, spatial, f, pair_radius(p, f, rho))
    keep = max(1.0 - delta_t, 1e-3)
    if dd.size:
        target = float(np.quantile(dd, DEPTH_QUANTILE))
    else:
        target = float(d.max() - d.min()) if d.size else 0.0
    delta_d = target / keep if target > 0 else 1.0
    return float(rho), delta_d, int(dd.size)
