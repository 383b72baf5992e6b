"""The prism split of the halos (Wang et al. Sec. 4.4, 5.1, Fig. 4; MATH.md §5.5;
docs/halos4d.md "Prisms → tetrahedra"): the paper's decomposition and mismatch repair
(``Halos.split="paper"``, the default) against the global-index rule (``"global_index"``).

* zero mismatched shared faces on every surface of the gallery and on seeded random prism
  strips, checked from the tetrahedra alone (:func:`mismatched_faces`); a planted fault (one
  flip of the repair skipped) is caught;
* every prism's tetrahedra fill it exactly once: volumes sum to the prism's, and a float64
  brute force of random points finds every point of the prism in exactly one tetrahedron;
* flat side faces: the voxel coverage does not depend on the split;
* twisted side faces: the coverage differs only inside the slivers ``conv(a, b, a⁺, b⁺)`` of the
  side quads split differently, each of volume ``(2/3)·ρ²·|e·(n̂_a × n̂_b)|``, and a prism's
  volume changes by at most the sum of its slivers' (the bound derived in docs/halos4d.md).
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import Halos, View4D
from refraster.halos4d.render import _screen_bounds, prepare
from refraster.halos4d.thicken import paper_diagonals, split_prisms, steiner_values

SEED = 20261203
thicken = importlib.import_module("refraster.halos4d.thicken")


# ----------------------------------------------------------------------------- checkers
def _tet_faces(tets):
    """All 4 faces of every tetrahedron, each sorted: (4T, 3)."""
    t = np.asarray(tets, np.int64)
    f = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
    return np.sort(f, axis=1)


def _lateral(tets, n):
    """The tetrahedron faces that lie on a side quad: ``(edge keys, diagonal start, faces)``.
    A face on the quad of mesh edge {u, w} has its three vertices among u, w, u⁺, w⁺ (its base
    indices mod n are exactly {u, w}); the diagonal it carries joins a lower copy to the upper
    copy of the other vertex, and is named by that lower copy."""
    f = _tet_faces(tets)
    f = f[(f < 2 * n).all(axis=1)]                      # inserted vertices are not on a side
    base = np.sort(f % n, axis=1)
    two = (base[:, 0] == base[:, 1]) != (base[:, 1] == base[:, 2])
    f, base = f[two], base[two]
    key = base[:, 0] * n + base[:, 2]
    lower = f < n
    one_lower = lower.sum(axis=1) == 1
    start = np.where(one_lower, np.where(lower, f, -1).max(axis=1), -1)
    # two lower copies: the one whose base differs from the upper copy's
    up = np.where(~lower, f - n, -1).max(axis=1)
    two_lower = ~one_lower
    cand = np.where(lower & (f != up[:, None]), f, -1).max(axis=1)
    start[two_lower] = cand[two_lower]
    return key, start, f


def mismatched_faces(tets, faces, n):
    """Number of shared side quads (mesh edges of ≥ 2 faces) whose triangles do not match: a
    conforming quad is split by one diagonal and each of its two triangles is a face of one
    tetrahedron of every prism on it."""
    fa = np.asarray(faces, np.int64)
    e = np.sort(np.concatenate([fa[:, [0, 1]], fa[:, [1, 2]], fa[:, [2, 0]]]), axis=1)
    ek, on_edge = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    shared = dict(zip(ek[on_edge >= 2].tolist(), on_edge[on_edge >= 2].tolist()))
    key, start, f = _lateral(tets, n)
    bad = set()
    tri, cnt = np.unique(f, axis=0, return_counts=True)
    tri_count = {tuple(t): c for t, c in zip(tri.tolist(), cnt.tolist())}
    starts = {}
    for k, s, t in zip(key.tolist(), start.tolist(), map(tuple, f.tolist())):
        if k in shared:
            starts.setdefault(k, set()).add(s)
            if tri_count[t] != shared[k]:
                bad.add(k)
    bad.update(k for k, s in starts.items() if len(s) != 1)
    bad.update(k for k in shared if k not in starts)
    return len(bad)


def quad_diagonals(tets, n):
    """``{edge key: diagonal start}`` of every side quad of a split."""
    key, start, _ = _lateral(tets, n)
    return dict(zip(key.tolist(), start.tolist()))


def _faces_ok(s):
    f = s.faces
    return f[~((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2]))]


def _signed_volumes(v, tets):
    a = v[tets[:, 0]]
    return np.einsum("ij,ij->i", np.cross(v[tets[:, 1]] - a, v[tets[:, 2]] - a),
                     v[tets[:, 3]] - a) / 6.0


# ----------------------------------------------------------------------------- surfaces
@pytest.fixture(scope="module")
def gallery_surfaces():
    from refraster.gallery.halos4d import figures
    out, seen = [], set()
    for fig in figures():
        if id(fig.surface) not in seen:
            seen.add(id(fig.surface))
            out.append((fig.name, fig.surface))
    return out


def random_strip(rng, m):
    """A strip of 2m triangles over 2(m + 1) vertices, seeded: random global numbering, each
    face's vertex order rotated at random and, for a third of them, reversed."""
    n = 2 * (m + 1)
    perm = rng.permutation(n)
    faces = []
    for i in range(m):
        a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
        faces += [[a, b, d], [a, d, c]]
    f = perm[np.asarray(faces)]
    f = np.stack([np.roll(row, r) for row, r in zip(f, rng.integers(0, 3, len(f)))])
    rev = rng.random(len(f)) < 1 / 3
    f[rev] = f[rev][:, ::-1]
    return f[rng.permutation(len(f))], n, perm


def _random_triangulation(rng, k=40):
    from scipy.spatial import Delaunay
    pts = rng.random((k, 2))
    return pts, Delaunay(pts).simplices.astype(np.int64)


# ----------------------------------------------------------------------------- mismatches
def test_gallery_surfaces_have_no_mismatched_faces(gallery_surfaces):
    for name, s in gallery_surfaces:
        f, n = _faces_ok(s), s.n_vertices
        paper = split_prisms(f, n, "paper")
        assert mismatched_faces(paper.tets, f, n) == 0, name
        assert mismatched_faces(split_prisms(f, n, "global_index").tets, f, n) == 0, name
        # the paper's decomposition before the repair has mismatches: the repair is needed
        assert paper.flips > 0, name
        # every tetrahedron face is shared by at most two tetrahedra
        assert np.unique(_tet_faces(paper.tets), axis=0, return_counts=True)[1].max() <= 2


def test_random_strips_have_no_mismatched_faces():
    rng = np.random.default_rng(SEED)
    rebuilt = flips = 0
    for _ in range(200):
        f, n, _ = random_strip(rng, int(rng.integers(2, 12)))
        ps = split_prisms(f, n)
        assert mismatched_faces(ps.tets, f, n) == 0
        rebuilt += len(ps.steiner)
        flips += ps.flips
    # both repairs of Fig. 4 happen on the strips
    assert rebuilt > 0 and flips > 0


def test_random_triangulations_have_no_mismatched_faces():
    rng = np.random.default_rng(SEED + 1)
    pts, faces = _random_triangulation(rng, 60)
    rebuilt = 0
    for _ in range(50):
        f = rng.permutation(len(pts))[faces]
        f = np.stack([np.roll(row, r) for row, r in zip(f, rng.integers(0, 3, len(f)))])
        ps = split_prisms(f, len(pts))
        assert mismatched_faces(ps.tets, f, len(pts)) == 0
        rebuilt += len(ps.steiner)
    assert rebuilt > 0


def test_the_checker_sees_the_unrepaired_decomposition(monkeypatch):
    """Without the repair (every prism in its face's order), the checker counts exactly the
    shared faces whose two prisms start their diagonals at different vertices, and the repair
    flips each of them once."""
    rng = np.random.default_rng(SEED + 2)
    f, n, _ = random_strip(rng, 10)
    flips = split_prisms(f, n).flips
    d = paper_diagonals(f)
    start = np.where(d == 0, f, np.roll(f, -1, axis=1))
    by_edge = {}
    for fi in range(len(f)):
        for k in range(3):
            e = tuple(sorted((f[fi, k], f[fi, (k + 1) % 3])))
            by_edge.setdefault(e, set()).add(int(start[fi, k]))
    expected = sum(len(v) > 1 for v in by_edge.values())
    assert expected > 0 and flips == expected
    monkeypatch.setattr(thicken, "repair_mismatches", lambda f, d, skip=(): 0)
    assert mismatched_faces(split_prisms(f, n).tets, f, n) == expected


def test_planted_fault_one_flip_skipped_is_caught(monkeypatch, gallery_surfaces):
    """A repair that skips one flip leaves exactly one mismatched face, on every surface."""
    original = thicken.repair_mismatches
    monkeypatch.setattr(thicken, "repair_mismatches",
                        lambda f, d, skip=(): original(f, d, skip=(0,)))
    for name, s in gallery_surfaces[:3]:
        f, n = _faces_ok(s), s.n_vertices
        assert mismatched_faces(split_prisms(f, n).tets, f, n) == 1, name


# ----------------------------------------------------------------------------- exact cover
def _flat_prisms(rng, kind):
    """A random planar triangulation (faces CCW, numbering and face order random) and its
    prisms with flat sides: ``kind`` "oblique" (upper = lower + d) or "frustum" (the lateral
    edges meet at an apex). Returns (faces, n, vertices (2n, 3), volume of each prism)."""
    pts, faces = _random_triangulation(rng, 30)
    n = len(pts)
    perm = rng.permutation(n)
    f = perm[faces]
    base = np.zeros((n, 3))
    base[perm, :2] = pts
    a, b, c = base[f[:, 0]], base[f[:, 1]], base[f[:, 2]]
    cw = np.cross(b - a, c - a)[:, 2] < 0
    f[cw] = f[cw][:, [0, 2, 1]]
    f = np.stack([np.roll(row, r) for row, r in zip(f, rng.integers(0, 3, len(f)))])
    a, b, c = base[f[:, 0]], base[f[:, 1]], base[f[:, 2]]
    area = 0.5 * np.cross(b - a, c - a)[:, 2]
    if kind == "oblique":
        d = np.array([0.13, -0.07, 0.3])
        top = base + d
        vol = area * d[2]
    else:
        apex, lam = np.array([0.4, 0.6, 1.5]), 0.35
        top = base + lam * (apex - base)
        vol = area * apex[2] / 3.0 * (1.0 - (1.0 - lam) ** 3)
    return f, n, np.concatenate([base, top]), vol


def _in_tets(v, tets, p, tol):
    """Per point: how many tetrahedra contain it, and whether it is within ``tol`` of a face
    plane of any (float64 barycentric coordinates)."""
    inside = np.zeros(len(p), np.int64)
    near = np.zeros(len(p), bool)
    for t in tets:
        m = np.column_stack([v[t[1]] - v[t[0]], v[t[2]] - v[t[0]], v[t[3]] - v[t[0]]])
        lam = np.linalg.solve(m, (p - v[t[0]]).T).T
        bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
        inside += (bary > 0).all(axis=1)
        near |= np.abs(bary).min(axis=1) < tol
    return inside, near


@pytest.mark.parametrize("kind", ["oblique", "frustum"])
def test_every_prism_is_filled_exactly_once(kind):
    rng = np.random.default_rng(SEED + (kind == "frustum"))
    rebuilt = 0
    for _ in range(6):
        f, n, v, vol = _flat_prisms(rng, kind)
        ps = split_prisms(f, n)
        rebuilt += len(ps.steiner)
        vv = steiner_values(v, ps.steiner, n)
        sv = _signed_volumes(vv, ps.tets)
        assert sv.min() > 0.0
        np.testing.assert_allclose(np.bincount(ps.prism, sv, len(f)), vol, rtol=1e-12)
        for fi in rng.choice(len(f), 8, replace=False):
            tets = ps.tets[ps.prism == fi]
            corner = v[np.concatenate([f[fi], f[fi] + n])]
            lo, hi = corner.min(axis=0), corner.max(axis=0)
            p = lo + (hi - lo) * rng.random((400, 3))
            count, near = _in_tets(vv, tets, p, 1e-9)
            # the prism: convex, its 5 planes (the frustum's sides meet at the apex)
            inside = np.ones(len(p), bool)
            bot, top = f[fi], f[fi] + n
            planes = [(v[bot[0]], v[bot[2]], v[bot[1]]), (v[top[0]], v[top[1]], v[top[2]])]
            for k in range(3):
                i, j = bot[k], bot[(k + 1) % 3]
                planes.append((v[i], v[j], v[j + n]))
            for o, q, r in planes:      # outward normals: (q − o) × (r − o)
                inside &= np.einsum("ij,j->i", p - o, np.cross(q - o, r - o)) < 0
            keep = ~near
            assert keep.sum() > 300
            np.testing.assert_array_equal(count[keep], inside[keep].astype(np.int64))
    assert rebuilt > 0


# ----------------------------------------------------------------------------- coverage
def _voxels(geo, bounds, shape, snap):
    return h.voxelize(geo.vertices, geo.tets, shape, bounds, snap=snap) >= 0


FLAT_VIEWS = [h.compose(("zx", 0.5), ("yz", -0.6)), h.compose(("zx", 0.35), ("yz", -0.6)),
              h.compose(("xw", 0.3), ("zx", 0.2), ("yz", 0.9))]


@pytest.mark.parametrize("snap", [False, True])
@pytest.mark.parametrize("view", range(len(FLAT_VIEWS)))
def test_flat_sides_coverage_does_not_depend_on_the_split(view, snap):
    """The Fig. 1 patches are flat in 4D, so every prism is straight and its sides are flat:
    the voxels covered are the same with either split (exact float64 test and the renderer's
    snapped coverage)."""
    s = h.figure1_scene(8)
    v = View4D(rotation=FLAT_VIEWS[view])
    gp, rho = prepare(s, view=v, split="paper")
    gg, _ = prepare(s, view=v, split="global_index")
    assert not np.array_equal(gp.tets, gg.tets)
    # the sides are flat: the twist e·(n̂_a × n̂_b) of every side vanishes
    n = s.n_vertices
    nrm = (gp.vertices[n:2 * n] - gp.vertices[:n]) / (2 * rho)
    f = _faces_ok(s)
    for k in range(3):
        i, j = f[:, k], f[:, (k + 1) % 3]
        e = gp.points[j] - gp.points[i]
        twist = np.abs(np.einsum("ij,ij->i", e, np.cross(nrm[i], nrm[j])))
        assert twist.max() < 1e-9 * np.linalg.norm(e, axis=1).max()
    bounds = _screen_bounds([gp.vertices], 96, 80, 0.05)
    a = _voxels(gp, bounds, (24, 80, 96), snap)
    b = _voxels(gg, bounds, (24, 80, 96), snap)
    assert a.sum() > 1000
    np.testing.assert_array_equal(a, b)


def _sliver_tets(geo, n, quads):
    """The slivers conv(a, b, a⁺, b⁺) of the side quads ``quads`` (edge keys)."""
    q = np.asarray(sorted(quads), np.int64)
    u, w = q // n, q % n
    return np.stack([u, w, u + n, w + n], axis=1)


def _in_closed(v, tets, p, tol):
    """Whether each point lies in some closed tetrahedron (barycentrics ≥ −tol)."""
    hit = np.zeros(len(p), bool)
    for t in tets:
        m = np.column_stack([v[t[1]] - v[t[0]], v[t[2]] - v[t[0]], v[t[3]] - v[t[0]]])
        if abs(np.linalg.det(m)) < 1e-300:
            continue
        lam = np.linalg.solve(m, (p - v[t[0]]).T).T
        bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
        hit |= (bary >= -tol).all(axis=1)
    return hit


FERMAT_VIEW = h.compose(h.hanson_view(0.6), ("zx", 0.35), ("yz", -0.5))
KNOT_VIEW = h.compose(("zw", np.pi / 2), ("yz", 0.75), ("zx", 0.2))
#: (name, surface, rotation, ρ as a multiple of the default) — thickened curved surfaces
TWISTED = [("quadratic_fermat", lambda: h.quadratic_fermat(10, 10), FERMAT_VIEW, 1.0),
           ("quadratic_fermat_3rho", lambda: h.quadratic_fermat(10, 10), FERMAT_VIEW, 3.0),
           ("calabi_yau_quartic", lambda: h.calabi_yau_quartic(6, 6), FERMAT_VIEW, 2.0),
           ("twist_spun_trefoil", lambda: h.twist_spun_trefoil(60, 12), KNOT_VIEW, 2.0)]


@pytest.mark.parametrize("case", range(len(TWISTED)))
def test_twisted_sides_coverage_differs_only_inside_the_slivers(case):
    name, make, rot, scale = TWISTED[case]
    s = make()
    n = s.n_vertices
    view = View4D(rotation=rot)
    rho = scale * prepare(s, view=view, split="global_index")[1]
    gp, _ = prepare(s, view=view, rho=rho, split="paper")
    gg, _ = prepare(s, view=view, rho=rho, split="global_index")
    dp, dg = quad_diagonals(gp.tets, n), quad_diagonals(gg.tets, n)
    differ = {k for k in dp if dp[k] != dg[k]}
    assert differ
    sl = _sliver_tets(gg, n, differ)
    v = gg.vertices
    # the sliver's volume is (2/3)·ρ²·|e·(n̂_a × n̂_b)| (docs/halos4d.md)
    nrm = (v[n:2 * n] - v[:n]) / (2 * rho)
    u, w = sl[:, 0], sl[:, 1]
    twist = np.einsum("ij,ij->i", gg.points[w] - gg.points[u], np.cross(nrm[u], nrm[w]))
    vol_sl = np.abs(_signed_volumes(v, sl))
    elen = np.linalg.norm(gg.points[w] - gg.points[u], axis=1).max()
    np.testing.assert_allclose(vol_sl, 2.0 / 3.0 * rho ** 2 * np.abs(twist), rtol=1e-6,
                               atol=1e-12 * rho ** 2 * elen)
    assert vol_sl.max() > 0.0
    # per prism: |ΔV| ≤ Σ of its slivers' volumes
    f = _faces_ok(s)
    ps = split_prisms(f, n, "paper")
    vp = np.bincount(ps.prism, _signed_volumes(gp.vertices, gp.tets), len(f))
    vg = np.bincount(np.repeat(np.arange(len(f)), 3), _signed_volumes(v, gg.tets), len(f))
    sl_vol = dict(zip(sorted(differ), vol_sl))
    bound = np.zeros(len(f))
    for k in range(3):
        i, j = f[:, k], f[:, (k + 1) % 3]
        key = np.minimum(i, j) * n + np.maximum(i, j)
        bound += np.array([sl_vol.get(int(x), 0.0) for x in key])
    assert np.all(np.abs(vp - vg) <= bound * (1 + 1e-9) + 1e-12 * rho ** 3)
    # the voxels whose coverage differs: inside a sliver of a quad split differently, or in a
    # tetrahedron (of either split) of a prism whose tetrahedra do not all have one sign (there
    # the signed count, which the slivers bound, is not the count)
    sp = np.sign(_signed_volumes(gp.vertices, gp.tets))
    sg = np.sign(_signed_volumes(v, gg.tets))
    mixed = (np.bincount(ps.prism, sp > 0, len(f)) * np.bincount(ps.prism, sp < 0, len(f))
             + np.bincount(np.repeat(np.arange(len(f)), 3), sg > 0, len(f))
             * np.bincount(np.repeat(np.arange(len(f)), 3), sg < 0, len(f))) > 0
    turned = np.flatnonzero(mixed)
    hull_p = gp.tets[np.isin(ps.prism, turned)]
    hull_g = gg.tets[np.isin(np.repeat(np.arange(len(f)), 3), turned)]
    shape = (32, 96, 96)
    bounds = _screen_bounds([gp.vertices], 96, 96, 0.05)
    a = _voxels(gp, bounds, shape, False)
    b = _voxels(gg, bounds, shape, False)
    diff = np.argwhere(a != b)
    zc, yc, xc = h.voxel_centres(shape, bounds)
    p = np.column_stack([xc[diff[:, 2]], yc[diff[:, 1]], zc[diff[:, 0]]])
    in_sliver = _in_closed(v, sl, p, 1e-9)
    ok = in_sliver | _in_closed(gp.vertices, hull_p, p, 1e-9) | _in_closed(v, hull_g, p, 1e-9)
    assert ok.all(), f"{name}: {int((~ok).sum())} of {len(p)} differing voxels outside the bound"
    voxel = np.prod((bounds[1] - bounds[0]) / np.array([shape[2], shape[1], shape[0]]))
    print(f"{name}: {len(diff)} voxels differ of {int(a.sum())} covered; slivers "
          f"{len(sl)}, Σ volume / voxel = {vol_sl.sum() / voxel:.1f}; inverted prisms "
          f"{int(mixed.sum())}; differing voxels in a sliver {int(in_sliver.sum())}")


def test_split_option_and_render():
    """``Halos.split`` reaches the tetrahedra: the default is the paper's; the two renders
    differ; a bad value is refused with one line naming ``halos.split``."""
    assert Halos().split == "paper"
    with pytest.raises(ValueError, match="halos.split"):
        Halos(split="dompierre")
    with pytest.raises(TypeError, match="halos.split"):
        Halos(split=1)
    s = h.figure1_scene(6)
    rot = View4D(rotation=FLAT_VIEWS[0])
    a = h.render_halos(s, view=rot, width=32, height=24, slices=6)
    b = h.render_halos(s, view=rot, width=32, height=24, slices=6,
                       halos=Halos(split="global_index"))
    c = h.render_halos(s, view=rot, width=32, height=24, slices=6, halos=Halos(split="paper"))
    assert np.array_equal(a.image, c.image)
    assert not np.array_equal(a.image, b.image)


def test_gl_backend_port_of_the_paper_split_is_the_same():
    """refraster.gl imports nothing of refraster: its port of the split gives the same
    tetrahedra and rebuilt prisms as :func:`split_prisms`."""
    from refraster.gl.halos import _paper_split
    rng = np.random.default_rng(SEED + 3)
    rebuilt = 0
    for _ in range(100):
        f, n, _ = random_strip(rng, int(rng.integers(2, 12)))
        tets, cyc = _paper_split(f, n)
        ps = split_prisms(f, n)
        np.testing.assert_array_equal(tets, ps.tets)
        np.testing.assert_array_equal(cyc, ps.steiner)
        rebuilt += len(cyc)
    assert rebuilt > 0


# ----------------------------------------------------------------------------- the split cache
def test_prepare_caches_the_split_and_honours_a_patched_repair(monkeypatch):
    """Issue 46: :func:`prepare` reuses a surface's split across views (it does not depend on
    the view), hands out its own copy of the tetrahedra, and a patched repair (the planted
    faults above) is a new cache entry, not the cached repaired split."""
    s = h.spun_trefoil(24, 8)
    a, _ = prepare(s, view=View4D(rotation=h.rotation("zw", 0.3)))
    b, _ = prepare(s, view=View4D(rotation=h.rotation("zx", 0.7)))
    assert np.array_equal(a.tets, b.tets) and a.tets is not b.tets
    a.tets[:] = 0                                        # the caller's copy only
    c, _ = prepare(s, view=View4D(rotation=h.rotation("zw", 0.3)))
    assert np.array_equal(c.tets, b.tets)
    f = s.faces
    assert np.array_equal(c.tets, split_prisms(f, s.n_vertices).tets)
    monkeypatch.setattr(thicken, "repair_mismatches", lambda f, d, skip=(): 0)
    d, _ = prepare(s, view=View4D(rotation=h.rotation("zw", 0.3)))
    assert np.array_equal(d.tets, split_prisms(f, s.n_vertices).tets)
    assert not np.array_equal(d.tets, c.tets)
