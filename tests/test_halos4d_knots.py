"""Spun and twist-spun trefoils as knotted 2-spheres (issue 21 item 2; MATH.md §5.7 revised).

Oracles: combinatorics of the mesh (Euler characteristic, oriented edges), an exact
triangle–triangle distance in 4D (minimum over the 49 face pairs of the two triangles, each an
affine least-squares problem: a convex quadratic attains its minimum over a polytope in the
relative interior of one face), and the crossing count of a half-slice projected to a plane.
Each check is also shown to fail on a planted fault.
"""

import itertools

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import surfaces as hs


# ----------------------------------------------------------------------------- oracles
def oriented_closed(faces):
    """Every undirected edge in exactly two faces, traversed once in each direction."""
    d = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = {tuple(e) for e in d.tolist()}
    if len(directed) != len(d):
        return False                          # a directed edge used twice: not oriented
    return all((b, a) in directed for a, b in directed)


def euler(faces, n_vertices):
    e = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]],
                                          faces[:, [2, 0]]]), axis=1), axis=0)
    return n_vertices - len(e) + len(faces)


_SUBSETS = [s for k in (1, 2, 3) for s in itertools.combinations(range(3), k)]


def triangle_distance(A, B):
    """Exact distance between triangles A[i] and B[i] in R^n, (P, 3, n) each."""
    best = np.full(len(A), np.inf)
    for sa, sb in itertools.product(_SUBSETS, _SUBSETS):
        a0, b0 = A[:, sa[0]], B[:, sb[0]]
        cols = [A[:, i] - a0 for i in sa[1:]] + [-(B[:, j] - b0) for j in sb[1:]]
        if cols:
            M = np.stack(cols, axis=2)                       # (P, n, m)
            x = np.einsum("pmn,pn->pm", np.linalg.pinv(M), b0 - a0)
            res = np.einsum("pnm,pm->pn", M, x) - (b0 - a0)
            na = len(sa) - 1
            ba = np.concatenate([1 - x[:, :na].sum(1, keepdims=True), x[:, :na]], axis=1)
            bb = np.concatenate([1 - x[:, na:].sum(1, keepdims=True), x[:, na:]], axis=1)
            ok = (ba.min(axis=1) >= -1e-12) & (bb.min(axis=1) >= -1e-12)
        else:
            res = a0 - b0
            ok = np.ones(len(A), bool)
        d = np.linalg.norm(res, axis=1)
        best = np.where(ok, np.minimum(best, d), best)
    return best


def min_nonadjacent_distance(surface, n_pairs=3000):
    """Smallest exact 4D distance between triangles sharing no vertex, over the n_pairs
    closest such pairs by centroid distance."""
    from scipy.spatial import cKDTree
    v, f = surface.vertices, surface.faces
    c = v[f].mean(axis=1)
    edge = max(np.linalg.norm(v[f[:, i]] - v[f[:, (i + 1) % 3]], axis=1).max() for i in range(3))
    pairs = cKDTree(c).query_pairs(3 * edge, output_type="ndarray")
    share = (f[pairs[:, 0], :, None] == f[pairs[:, 1], None, :]).any(axis=(1, 2))
    pairs = pairs[~share]
    dc = np.linalg.norm(c[pairs[:, 0]] - c[pairs[:, 1]], axis=1)
    pairs = pairs[np.argsort(dc, kind="stable")[:n_pairs]]
    return float(triangle_distance(v[f[pairs[:, 0]]], v[f[pairs[:, 1]]]).min()), len(pairs)


def crossings(xy):
    """Number of proper crossings of the closed 2D polyline xy (non-adjacent segments)."""
    p = np.asarray(xy, np.float64)
    q = np.roll(p, -1, axis=0)
    n = len(p)
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))                   # first and last segments are adjacent
    i, j = i[keep], j[keep]

    def orient(a, b, c):
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    d1 = orient(p[i], q[i], p[j])
    d2 = orient(p[i], q[i], q[j])
    d3 = orient(p[j], q[j], p[i])
    d4 = orient(p[j], q[j], q[i])
    return int(np.count_nonzero((d1 * d2 < 0) & (d3 * d4 < 0)))


def half_slice(surface, n_s, n_phi, j, xp):
    """The mesh's meridian φ = 2πj/n_phi, pole to pole, mapped back to its 3D half-space
    (Xp − r, y, z) with r = |(x − Xp, w)|."""
    v = surface.vertices
    rows = (np.arange(n_s - 2) * n_phi + j)
    idx = np.concatenate([[len(v) - 2], rows, [len(v) - 1]])
    p = v[idx]
    r = np.hypot(p[:, 0] - xp, p[:, 3])
    return np.column_stack([xp - r, p[:, 1], p[:, 2]])


# ----------------------------------------------------------------------------- the oracles work
def test_oracles_detect_planted_faults():
    # a flipped face breaks orientation; an unglued edge breaks closure
    s = h.spun_trefoil(20, 8)
    assert oriented_closed(s.faces)
    bad = s.faces.copy()
    bad[5] = bad[5, ::-1]
    assert not oriented_closed(bad)
    assert not oriented_closed(s.faces[1:])
    # two triangles crossing in 4D (planes x-y and z-w meet at the origin) are at distance 0,
    # a hand case at distance 1
    A = np.array([[[-1, -1, 0, 0], [2, -1, 0, 0], [-1, 2, 0, 0]]], float)
    B = np.array([[[0, 0, -1, -1], [0, 0, 2, -1], [0, 0, -1, 2]]], float)
    assert triangle_distance(A, B)[0] == pytest.approx(0.0, abs=1e-12)
    C = B + np.array([0, 0, 0, 3.0])                  # w from 2 to 5: nearest w = 2 vs 0
    np.testing.assert_allclose(triangle_distance(A, C), [2.0])
    # a brute-force sample of both triangles is never closer than the exact distance
    rng = np.random.default_rng(1)
    A, B = rng.normal(size=(200, 3, 4)), rng.normal(size=(200, 3, 4)) + 0.5
    w = rng.dirichlet(np.ones(3), size=400)
    pa = np.einsum("kv,pvn->pkn", w, A)
    pb = np.einsum("kv,pvn->pkn", w, B)
    brute = np.linalg.norm(pa[:, :, None] - pb[:, None], axis=3).min(axis=(1, 2))
    exact = triangle_distance(A, B)
    assert np.all(exact <= brute + 1e-12)
    assert np.all(brute - exact < 0.2)
    # crossing counter: trefoil 3, (2,5) torus knot 5, circle 0
    u = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    assert crossings(hs._trefoil(u)[:, :2]) == 3
    t25 = np.stack([(2 + np.cos(5 * u)) * np.cos(2 * u), (2 + np.cos(5 * u)) * np.sin(2 * u)], 1)
    assert crossings(t25) == 5
    assert crossings(np.stack([np.cos(u), np.sin(u)], 1)) == 0


# ----------------------------------------------------------------------------- the knots
KNOTS = [("spun", lambda a, b: h.spun_trefoil(a, b), hs.SPUN_XP),
         ("twist2", lambda a, b: h.twist_spun_trefoil(a, b, k=2), hs.TWIST_XP)]


@pytest.mark.parametrize("name,make,xp", KNOTS, ids=[k[0] for k in KNOTS])
def test_knot_is_a_closed_orientable_embedded_sphere(name, make, xp):
    s = make(80, 24)
    assert euler(s.faces, s.n_vertices) == 2
    assert oriented_closed(s.faces)
    diam = float(np.linalg.norm(s.vertices.max(0) - s.vertices.min(0)))
    dmin, n = min_nonadjacent_distance(s)
    assert n == 3000
    assert dmin >= 1e-4 * diam, (dmin, diam)


@pytest.mark.parametrize("name,make,xp", KNOTS, ids=[k[0] for k in KNOTS])
def test_half_slice_is_the_knotted_arc_with_three_crossings(name, make, xp):
    n_s, n_phi = 160, 16
    s = make(n_s, n_phi)
    # φ = 0, π/2, π, 3π/2: the twist by 2φ about y is the identity or a half turn, which
    # mirrors the diagram seen along z; either way three crossings
    for j in (0, 4, 8, 12):
        arc = half_slice(s, n_s, n_phi, j, xp)
        assert crossings(arc[:, :2]) == 3, (name, j)


def test_planted_unknotted_arc_fails_the_crossing_count(monkeypatch):
    """Replace the knot body by an unknotted loop: the half-slice shows no crossing."""
    def circle(u):
        u = np.asarray(u, np.float64)
        return np.stack([3 * np.cos(u), 3 * np.sin(u), 0.4 * np.sin(u)], axis=-1)

    def circle_d(u):
        u = np.asarray(u, np.float64)
        return np.stack([-3 * np.sin(u), 3 * np.cos(u), 0.4 * np.cos(u)], axis=-1)

    monkeypatch.setattr(hs, "_trefoil", circle)
    monkeypatch.setattr(hs, "_trefoil_d", circle_d)
    monkeypatch.setattr(hs, "_ARCS", {})
    s = h.spun_trefoil(160, 16)
    assert crossings(half_slice(s, 160, 16, 0, hs.SPUN_XP)[:, :2]) != 3


def test_spun_trefoil_meets_the_plane_at_its_cut():
    p, s = hs.trefoil_arc(False)
    xp = hs.SPUN_XP
    total = s[-1]
    # connectors: from the plane to the cut ends K(δ), K(2π − δ) of the trefoil
    ia = int(np.argmin(np.linalg.norm(p - hs._trefoil(hs._DELTA), axis=1)))
    ib = int(np.argmin(np.linalg.norm(p - hs._trefoil(2 * np.pi - hs._DELTA), axis=1)))
    assert np.linalg.norm(p[ia] - hs._trefoil(hs._DELTA)) < 1e-12
    connectors = s[ia] + (total - s[ib])
    assert 0 < connectors <= 0.05 * total, (connectors, total)
    # endpoints on the plane, arriving along +x; everything else strictly inside the half-space
    np.testing.assert_allclose(p[[0, -1], 0], xp)
    assert np.all(p[1:-1, 0] < xp)
    for a, b in ((1, 0), (-2, -1)):
        t = p[b] - p[a]
        assert t[0] / np.linalg.norm(t) > 0.999
    # the knotted part is within one arc diameter of the plane
    from scipy.spatial.distance import pdist
    diam = pdist(p[::20]).max()
    assert (xp - p[:, 0]).max() <= diam


def leg_lengths(p, rb):
    """Lengths of the two pieces of the arc outside the ball |p| ≤ rb (from the arc's points,
    not from the construction's constants)."""
    outside = np.linalg.norm(p, axis=1) > rb + 1e-9
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1) * (outside[1:] | outside[:-1])
    half = len(seg) // 2
    return float(seg[:half].sum()), float(seg[half:].sum())


def test_twist_spun_legs_at_most_3_2_and_the_ball_clears_the_plane():
    """Issue 21 item 2: legs ≤ 3.2 (a leg runs from an exit point on the turning axis to the
    plane, so it is at least the ball's radius plus the clearance: "no longer than the radius"
    cannot hold exactly for a ball that clears the plane; 3.2 is the issue's number)."""
    p, s = hs.trefoil_arc(True)
    rb, xp = hs.TWIST_RB, hs.TWIST_XP
    legs = leg_lengths(p, rb)
    assert all(0 < g <= 3.2 for g in legs), legs
    assert sum(legs) == pytest.approx(2 * xp, rel=1e-6)
    assert xp - rb <= 0.25 and xp > rb                 # the ball clears the plane
    # the ball holds the knot body: every arc point with |y| < rb is inside it
    inner = np.abs(p[:, 1]) < rb - 1e-9
    assert np.linalg.norm(p[inner], axis=1).max() <= rb + 1e-12
    # the twisted surface: the turned ball never reaches the plane (r ≥ Xp − RB > 0)
    t = h.twist_spun_trefoil(60, 24, k=2)
    r = np.hypot(t.vertices[:, 0] - xp, t.vertices[:, 3])
    assert np.count_nonzero(r < 1e-12) == 2             # only the two poles lie on the plane
    ball = np.abs(t.vertices[:, 1]) < rb - 1e-9         # off the legs: inside the turned ball
    assert r[ball].min() >= xp - rb - 1e-9
    # the knotted part within one arc diameter of the plane
    from scipy.spatial.distance import pdist
    assert r.max() <= pdist(p[::20]).max()


def test_twist_spun_k0_equals_spin_of_the_ball_arc_and_k2_differs():
    a = h.twist_spun_trefoil(40, 16, k=0)
    b = h.twist_spun_trefoil(40, 16, k=2)
    assert np.abs(a.vertices - b.vertices).max() > 0.5
    # the legs (outside the ball) and the turning axis are not moved by the twist
    legs = (np.abs(a.vertices[:, 1]) >= hs.TWIST_RB - 1e-9) & (a.vertices[:, 2] == 0.0)
    assert legs.sum() > 16
    np.testing.assert_array_equal(a.vertices[legs], b.vertices[legs])
    with pytest.raises(TypeError, match="k"):
        h.twist_spun_trefoil(10, 8, k=1.5)
