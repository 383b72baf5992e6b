"""Slicing, voxelization and the halo render (Wang et al. Sec. 4.6; MATH.md §5.4–5.6)."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import refraster
import refraster.halos4d as h
from refraster.halos4d import render as hr
from refraster.halos4d import slicing as hs


# ----------------------------------------------------------------------------- brute force
def brute_force_voxelize(v, tets, shape, bounds):
    """Point-in-tetrahedron test of every voxel centre against every tetrahedron (NumPy), with
    the documented tie rule; returns (smallest claiming index, claim count)."""
    zc, yc, xc = h.voxel_centres(shape, bounds)
    Z, Y, X = np.meshgrid(zc, yc, xc, indexing="ij")
    out = np.full(shape, -1, np.int32)
    claims = np.zeros(shape, np.int32)
    for t in range(len(tets)):
        inside = np.ones(shape, bool)
        ok = True
        for m in range(4):
            i, j, k = sorted(int(tets[t, q]) for q in range(4) if q != m)
            a, b = v[j] - v[i], v[k] - v[i]
            n = np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                          a[0] * b[1] - a[1] * b[0]])
            vm = v[tets[t, m]]
            om = (n[0] * (vm[0] - v[i, 0]) + n[1] * (vm[1] - v[i, 1])) + n[2] * (vm[2] - v[i, 2])
            if om == 0.0:
                ok = False
                break
            sg = 1.0 if om > 0 else -1.0
            nin = sg * n
            owned = nin[0] > 0 or (nin[0] == 0 and (nin[1] > 0 or (nin[1] == 0 and nin[2] > 0)))
            o = ((n[0] * (X - v[i, 0]) + n[1] * (Y - v[i, 1])) + n[2] * (Z - v[i, 2])) * sg
            inside &= (o > 0) | ((o == 0) & owned)
        if not ok:
            continue
        claims += inside
        out[inside & (out < 0)] = t
    return out, claims


def slab_mesh(seed=0, n=30, rho=0.08):
    """A conforming tetrahedral slab: a random Delaunay triangulation of a tilted square,
    thickened by ± rho along its normal and split with prism_tetrahedra."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    uv = np.concatenate([rng.random((n - 4, 2)), [[0, 0], [1, 0], [0, 1], [1, 1]]])
    faces = Delaunay(uv).simplices.astype(np.int64)
    e1 = np.array([1.0, 0.0, 0.35])
    e2 = np.array([0.0, 1.0, -0.2])
    nrm = np.cross(e1, e2)
    nrm /= np.linalg.norm(nrm)
    base = uv[:, :1] * e1 + uv[:, 1:] * e2
    verts, _ = h.thicken(base, np.tile(nrm, (len(base), 1)), rho)
    return verts, h.prism_tetrahedra(faces, len(base)), (e1, e2, nrm)


def cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def random_tets(rng, k=12):
    v = rng.random((4 * k, 3))
    return v, np.arange(4 * k).reshape(k, 4)


# ----------------------------------------------------------------------------- voxelize
def test_voxelize_exact_equals_brute_force_on_random_tets():
    rng = np.random.default_rng(5)
    v, t = random_tets(rng)
    shape, bounds = (9, 13, 11), [[0, 0, 0], [1, 1, 1]]
    got, claims = h.voxelize(v, t, shape, bounds, snap=False, return_claims=True)
    want, wclaims = brute_force_voxelize(v, t, shape, bounds)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(claims, wclaims)
    assert (got >= 0).sum() > 50


def test_voxelize_exact_equals_brute_force_on_prism_mesh_with_ties():
    v, t, _ = slab_mesh()
    # bounds chosen so that voxel centres fall on vertex coordinates: ties do occur
    v = np.round(v * 16) / 16
    shape, bounds = (16, 16, 16), [[-0.03125, -0.03125, -0.53125], [0.96875, 0.96875, 0.46875]]
    got, claims = h.voxelize(v, t, shape, bounds, snap=False, return_claims=True)
    want, wclaims = brute_force_voxelize(v, t, shape, bounds)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(claims, wclaims)


def test_voxelize_independent_oracle_scipy_barycentric(oracle):
    """Away from faces (|barycentric| > 1e-9) the classification agrees with barycentric
    coordinates solved by LAPACK."""
    oracle("scipy")
    rng = np.random.default_rng(11)
    v, t = random_tets(rng, 8)
    shape, bounds = (10, 10, 10), [[0, 0, 0], [1, 1, 1]]
    got = h.voxelize(v, t, shape, bounds, snap=False)
    zc, yc, xc = h.voxel_centres(shape, bounds)
    Z, Y, X = np.meshgrid(zc, yc, xc, indexing="ij")
    p = np.stack([X, Y, Z], axis=-1).reshape(-1, 3)
    first = np.full(len(p), -1)
    clear = np.ones(len(p), bool)
    for k in range(len(t)):
        a = v[t[k]]
        m = np.column_stack([a[1] - a[0], a[2] - a[0], a[3] - a[0]])
        lam = np.linalg.solve(m, (p - a[0]).T).T
        bary = np.column_stack([1 - lam.sum(axis=1), lam])
        clear &= np.abs(bary).min(axis=1) > 1e-9
        inside = bary.min(axis=1) > 0
        first[inside & (first < 0)] = k
    np.testing.assert_array_equal(got.reshape(-1)[clear], first[clear])


@pytest.mark.parametrize("snap", [False, True])
def test_conforming_slab_each_voxel_claimed_once(snap):
    v, t, (e1, e2, nrm) = slab_mesh(seed=2)
    shape, bounds = (40, 40, 40), [[-0.1, -0.1, -0.5], [1.1, 1.1, 0.5]]
    got, claims = h.voxelize(v, t, shape, bounds, snap=snap, return_claims=True)
    assert claims.max() == 1
    # centres strictly inside the slab (off its boundary by a margin) are claimed
    zc, yc, xc = h.voxel_centres(shape, bounds)
    Z, Y, X = np.meshgrid(zc, yc, xc, indexing="ij")
    p = np.stack([X, Y, Z], axis=-1)
    m = np.column_stack([e1, e2, nrm])
    a, b, c = np.moveaxis(np.linalg.solve(m, p.reshape(-1, 3).T).reshape(3, *shape), 0, 0)
    interior = (a > 0.02) & (a < 0.98) & (b > 0.02) & (b < 0.98) & (np.abs(c) < 0.08 - 0.01)
    assert interior.sum() > 500
    assert np.all(claims[interior] == 1)


def test_voxelize_snapped_agrees_with_exact():
    v, t, _ = slab_mesh(seed=4)
    shape, bounds = (32, 48, 48), [[-0.1, -0.1, -0.5], [1.1, 1.1, 0.5]]
    a = h.voxelize(v, t, shape, bounds, snap=False)
    b = h.voxelize(v, t, shape, bounds, snap=True)
    agree = np.mean(a == b)
    assert agree >= 0.999, agree
    # occupancy differs only at the slab's boundary, by a sliver
    assert abs(int((a >= 0).sum()) - int((b >= 0).sum())) < 0.01 * (a >= 0).sum()


def test_voxelize_bad_inputs():
    v, t = random_tets(np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match="shape N"):
        h.voxelize(v, t, (0, 4, 4), [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(ValueError, match="shape N"):
        h.voxelize(v, t, (10**6, 4, 4), [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(ValueError, match="bounds"):
        h.voxelize(v, t, (2, 4, 4), [[0, 0, 0], [1, 0, 1]])
    with pytest.raises(ValueError, match="tets"):
        h.voxelize(v, t + 100, (2, 4, 4), [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(ValueError, match="non-finite"):
        h.voxelize(np.full_like(v, np.nan), t, (2, 4, 4), [[0, 0, 0], [1, 1, 1]])
    with pytest.raises(TypeError, match="snap"):
        h.voxelize(v, t, (2, 4, 4), [[0, 0, 0], [1, 1, 1]], snap="yes")


# ----------------------------------------------------------------------------- slicing
def test_slice_hand_values():
    """Unit tetrahedron cut at z = 0.5: the triangle of the lone top vertex, λ = 0.5."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    att = np.array([[0.0], [0.0], [0.0], [2.0]])
    s = h.slice_tetrahedra(v, [[0, 1, 2, 3]], [0.5], att)
    assert len(s) == 1
    np.testing.assert_allclose(s.xy[0], [[0, 0], [0.5, 0], [0, 0.5]])
    np.testing.assert_allclose(s.attr[0, :, 0], [1.0, 1.0, 1.0])
    # a plane through a vertex: s = 0 counts as positive, so z = 1 still cuts (a point, area 0)
    # and z = 0 gives the base triangle
    assert len(h.slice_tetrahedra(v, [[0, 1, 2, 3]], [0.0])) == 0
    assert len(h.slice_tetrahedra(v, [[0, 1, 2, 3]], [1.0])) == 1


def test_slice_quad_is_split_in_two_and_area_matches():
    # a tetrahedron with two vertices on each side of z = 0.5
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 1], [0, 0, 1.0]])
    s = h.slice_tetrahedra(v, [[0, 1, 2, 3]], [0.5])
    assert len(s) == 2
    area = 0.5 * np.abs(cross2(s.xy[:, 1] - s.xy[:, 0], s.xy[:, 2] - s.xy[:, 0])).sum()
    # the section is the square with corners (0, 0), (0.5, 0), (0.5, 0.5), (0, 0.5)
    assert area == pytest.approx(0.25)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10**6))
def test_slice_area_integrates_to_volume(seed):
    """Σ slice areas · Δz → tetrahedron volume (midpoint rule, exact for quadratics)."""
    rng = np.random.default_rng(seed)
    v = rng.random((4, 3))
    vol = abs(np.linalg.det(v[1:] - v[0])) / 6
    n = 400
    c = (np.arange(n) + 0.5) / n
    s = h.slice_tetrahedra(v, [[0, 1, 2, 3]], c)
    area = 0.5 * np.abs(cross2(s.xy[:, 1] - s.xy[:, 0], s.xy[:, 2] - s.xy[:, 0]))
    assert area.sum() / n == pytest.approx(vol, rel=2e-3, abs=1e-6)


def test_slices_grouped_in_draw_order():
    v, t, _ = slab_mesh()
    c = np.linspace(-0.3, 0.3, 17)
    s = h.slice_tetrahedra(v, t, c)
    for k in range(len(c)):
        seg = s.tet[s.starts[k]:s.starts[k + 1]]
        assert np.all(np.diff(seg) >= 0)
        assert np.all(s.slice[s.starts[k]:s.starts[k + 1]] == k)


# ----------------------------------------------------------------------------- the fill kernel
def test_fused_fill_equals_foundation_rasterizer():
    """Coverage and barycentrics of the fused per-slice fill equal refraster.rasterize."""
    v, t, _ = slab_mesh(seed=7)
    bounds = np.array([[-0.1, -0.1, -0.5], [1.1, 1.1, 0.5]])
    st_ = hs._slice(v[:, 2].copy(), t, np.array([-0.05, 0.0, 0.07]), np.zeros((len(v), 0)),
                    hs.ortho_ndc(v, bounds))
    w, hgt = 53, 47
    X, Y, order, bbox, valid, _, _ = hs.setup_window(st_.xy, w, hgt)
    xy = st_.xy.reshape(-1, 2)
    clip = np.column_stack([xy, np.zeros(len(xy)), np.ones(len(xy))])
    fr = refraster.rasterize(clip, np.arange(len(xy)).reshape(-1, 3), w, hgt)
    mine = []
    for j in np.flatnonzero(valid):
        for py in range(bbox[j, 2], bbox[j, 3] + 1):
            for px in range(bbox[j, 0], bbox[j, 1] + 1):
                cov, e0, e1, e2 = hs.covered(X, Y, j, px, py, 8)
                if cov:
                    mine.append((j, (hgt - 1 - py) * w + px))
    mine = sorted(mine)
    theirs = sorted(zip(fr.prim_id.tolist(), fr.pixel.tolist()))
    assert len(mine) > 100
    assert mine == theirs


def fig1(w_values=None):
    return h.figure1_scene(10) if w_values is None else h.figure1_scene(10, w_values=w_values)


HALOS = h.Halos(rho=0.08, delta_d=1.0, delta_t=0.2)
VIEW = h.View4D(rotation=h.compose(("zx", 0.5), ("yz", -0.6)))
KW = dict(width=48, height=40, slices=20, halos=HALOS, view=VIEW)


def test_engines_bit_identical():
    s = fig1()
    for enabled in (True, False):
        kw = {**KW, "halos": HALOS.replace(enabled=enabled)}
        a = h.render_halos(s, volume=True, **kw)
        b = h.render_halos(s, volume=True, engine="reference", **kw)
        assert a.image.tobytes() == b.image.tobytes()
        np.testing.assert_array_equal(a.volume, b.volume)


def test_engines_bit_identical_across_the_hit_masks_words():
    """The fused resolve visits the voxels hit in a slice through a bit mask, 64 columns a word
    (``_resolve_slice``): at 140 × 140 px (three words, the last one partial; five bands, the
    last one partial), with and without a volume (without one the off-core fragments are
    deferred), halos on and off, alone and as a pair, it gives the reference engine's bits."""
    s = fig1()
    kw = {**KW, "width": 140, "height": 140}
    for volume in (True, False):
        on, off = h.render_halos_pair(s, volume=volume, **kw)
        ref_on, ref_off = h.render_halos_pair(s, volume=volume, engine="reference", **kw)
        for a, b in ((on, ref_on), (off, ref_off)):
            assert a.image.tobytes() == b.image.tobytes()
            assert a.alpha.tobytes() == b.alpha.tobytes()
            if volume:
                np.testing.assert_array_equal(a.volume, b.volume)
    # every word of the mask holds drawn voxels, and the halos change the picture
    assert all(on.alpha[:, c].any() for c in (slice(0, 64), slice(64, 128), slice(128, 140)))
    assert on.image.tobytes() != off.image.tobytes()


def test_halo_grows_with_4d_depth_difference():
    """Fig. 1: the carved part of the white patch grows monotonically with Δw."""
    # carved where the white core meets the strip's halo at w_s <= u < δt + Δw/δd
    kw = {**KW, "width": 64, "height": 56, "slices": 32,
          "halos": HALOS.replace(rho=0.1, surface_width=0.2, delta_t=0.3)}
    carved = []
    for w in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5):
        r = h.render_halos(fig1([w]), volume=True, **kw)
        carved.append(int((r.volume == hr.CARVED).sum()))
    assert carved[0] == 0
    assert all(a < b for a, b in zip(carved, carved[1:])), carved
    assert carved[5] > 2 * carved[1]


def test_halo_carves_only_the_farther_surface():
    kw = {**KW, "width": 96, "height": 80, "slices": 32}

    def counts(w, enabled):
        kw["halos"] = HALOS.replace(rho=0.1, enabled=enabled)
        img = h.render_halos(fig1([w]), **kw).image
        red = (img[..., 0] > 0.2) & (img[..., 1] < 0.5 * img[..., 0])
        white = (img.min(axis=2) > 0.2) & (img.max(axis=2) - img.min(axis=2) < 0.05)
        return int(red.sum()), int(white.sum())

    # strip 0.5 behind the white patch in 4D: halos take red pixels, white ones are not lost
    red_h, white_h = counts(-0.5, True)
    red_0, white_0 = counts(-0.5, False)
    assert red_h < red_0 - 10 and white_h >= white_0
    # strip 0.5 in front: halos take white pixels, red ones are not lost
    red_h, white_h = counts(0.5, True)
    red_0, white_0 = counts(0.5, False)
    assert white_h < white_0 - 10 and red_h >= red_0


def test_opacity_independent_of_slice_count():
    """A face-on square: accumulated alpha ≈ opacity for any N (within slice sampling)."""
    sq = h.uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1), (-1, 1), 4, 4)
    alphas = []
    for n in (8, 16, 64):
        r = h.render_halos(sq, width=24, height=24, slices=n, view=h.View4D(margin=0.2),
                           halos=h.Halos(rho=0.2, surface_width=0.5),
                           style=h.HaloStyle(opacity=0.8))
        alphas.append(float(r.alpha[12, 12]))
    np.testing.assert_allclose(alphas, 0.8, atol=0.08)


def test_render_stereo_and_volume_shapes():
    r = h.render_halos(fig1(), **{**KW, "view": VIEW.replace(stereo=h.STEREO_ANGLE)})
    gap = max(2, 48 // 32)
    assert r.image.shape == (40, 2 * 48 + gap, 3)
    assert not np.array_equal(r.image[:, :48], r.image[:, 48 + gap:])
    v = h.render_halos(fig1(), volume=True, **KW)
    assert v.volume.shape == (20, 40, 48) and v.volume.dtype == np.int8
    assert np.all(np.isin(v.volume, [0, 1, 2, 3]))
    # perspective works too
    p = h.render_halos(fig1(), **{**KW, "view": VIEW.replace(projection="perspective")})
    assert p.alpha.max() > 0


def test_render_bad_inputs():
    s = fig1()
    for bad in (0, -3, 10**6):
        with pytest.raises(ValueError, match="slices"):
            h.render_halos(s, width=8, height=8, slices=bad)
    with pytest.raises(TypeError, match="slices"):
        h.render_halos(s, width=8, height=8, slices=2.5)
    for name in ("rho", "delta_d", "delta_t", "surface_width"):
        with pytest.raises(ValueError, match=rf"^halos\.{name} must be finite"):
            h.Halos(**{name: float("nan")})
    with pytest.raises(ValueError, match=r"^style\.opacity must be finite"):
        h.HaloStyle(opacity=float("nan"))
    with pytest.raises(TypeError, match="surface"):
        h.render_halos(np.zeros((3, 4)), width=8, height=8)
    with pytest.raises(ValueError, match="engine"):
        h.render_halos(s, width=8, height=8, engine="gpu")
    with pytest.raises(ValueError, match="volume"):
        h.render_halos(s, width=8, height=8, view=h.View4D(stereo=6.0), volume=True)
    for name, value in (("view", None), ("halos", True), ("style", {"opacity": 0.5})):
        with pytest.raises(TypeError, match=rf"^{name} must be a refraster\.halos4d\."):
            h.render_halos(s, width=8, height=8, **{name: value})
    with pytest.raises(ValueError, match="width"):
        h.render_halos(s, width=0, height=8)


def test_degenerate_faces_are_skipped_with_a_count():
    s = fig1()
    f = np.concatenate([s.faces, [[0, 0, 1], [2, 3, 3]]])
    s2 = h.Surface4D(s.vertices, f, s.tangents, s.colors)
    r = h.render_halos(s2, **KW)
    assert r.stats["degenerate_faces"] == 2
    assert r.image.tobytes() == h.render_halos(s, **KW).image.tobytes()


def test_render_deterministic_across_runs_and_threads(tmp_path):
    code = textwrap.dedent("""
        import sys, numpy as np
        import refraster.halos4d as h
        s = h.spun_trefoil(40, 16)
        r = h.render_halos(s, view=h.View4D(rotation=h.compose(("zw", 0.6), ("yz", 0.4))),
                           width=64, height=64, slices=32, volume=True)
        np.save(sys.argv[1], np.concatenate([r.image.ravel(), r.volume.ravel()]))
    """)
    outs = []
    for threads in ("1", "2", "2"):
        p = tmp_path / f"out{len(outs)}.npy"
        env = {**os.environ, "NUMBA_NUM_THREADS": threads, "REFRASTER_THREADS": threads}
        subprocess.run([sys.executable, "-c", code, str(p)], check=True, env=env)
        outs.append(np.load(p, allow_pickle=False).tobytes())
    assert outs[0] == outs[1] == outs[2]


def _tets_of_triangles(st, centres):
    """Tetrahedra whose slices are exactly the slice triangles ``st`` (the fused engine slices
    tetrahedra): triangle i of slice k becomes the three vertices of its corners at z = c_k
    and an apex half a slice below with a larger global index, so its only slice is k and
    every corner is ``X_corner + 0·(X_apex − X_corner)``, the corner's own bits."""
    k = len(st)
    z = np.concatenate([np.repeat(centres[st.slice], 3), centres[st.slice] - 0.5])
    ndc = np.concatenate([st.xy.reshape(-1, 2), np.zeros((k, 2))])
    attr = np.concatenate([st.attr.reshape(3 * k, -1), np.zeros((k, st.attr.shape[2]))])
    tets = np.column_stack([3 * np.arange(k), 3 * np.arange(k) + 1, 3 * np.arange(k) + 2,
                            3 * k + np.arange(k)]).astype(np.int64)
    k0, k1 = hs.slice_ranges(z, tets, centres)
    assert np.array_equal(k0, st.slice) and np.array_equal(k1, st.slice + 1)
    return hr._TetSlices(z, ndc, attr, tets, centres)


def test_fill_pass_matches_reference_on_snapping_flipped_slivers():
    """The fused fill pass scans each row's exact span and starts the edge functions at the
    span's first pixel (issue 27); they interpolate the attributes of slice triangles that
    1/256-px snapping flipped or flattened (unsnapped area ≤ 0, Mesa's fallback). Real scenes
    rarely have such a triangle cover a pixel centre, so here are slivers along rows of pixel
    centres, one per slice, some of them flipped and covering: the fused pass (alone and as a
    pair) gives the reference engine's bits (refraster.rasterize per slice + NumPy)."""
    W = H = 16
    rng = np.random.default_rng(5)
    n = 4000
    y = rng.integers(2, H - 2, n) + 0.5
    ends = (rng.uniform(0.5, 3.0, n), rng.uniform(W - 4.0, W - 0.5, n), rng.uniform(4.0, W - 5.0, n))
    win = np.stack([np.stack([x, y + rng.uniform(-0.006, 0.006, n)], 1) for x in ends], 1)
    ndc = win / np.array([W, H]) * 2.0 - 1.0
    X, Y, order, bbox, valid, XF, YF = hs.setup_window(ndc.reshape(-1, 3, 2), W, H)
    fa = ((XF[:, 1] - XF[:, 0]) * (YF[:, 2] - YF[:, 0])
          - (XF[:, 2] - XF[:, 0]) * (YF[:, 1] - YF[:, 0]))
    covering = [j for j in np.flatnonzero(valid & (fa <= 0.0))
                if any(hs.covered(X, Y, j, px, py, hs.SUBPIXEL_BITS)[0]
                       for py in range(bbox[j, 2], bbox[j, 3] + 1)
                       for px in range(bbox[j, 0], bbox[j, 1] + 1))]
    assert len(covering) > 20
    keep = np.array(covering[:120])
    k = len(keep)
    st = hs.SliceTriangles()
    st.xy = np.ascontiguousarray(ndc[keep])
    attr = np.empty((k, 3, 5))
    attr[:, :, 0] = rng.uniform(-1.0, 1.0, (k, 3))     # δ
    attr[:, :, 1] = rng.uniform(0.2, 0.8, (k, 3))      # t: core, fringe and halo
    attr[:, :, 2:] = rng.uniform(0.0, 1.0, (k, 3, 3))
    st.attr = attr
    st.tet = np.arange(k, dtype=np.int64)
    st.slice = np.arange(k, dtype=np.int64) // 2       # two slivers per slice
    st.starts = np.append(np.arange(0, k, 2), k).astype(np.int64)
    on = (0.3, 2.0, 0.3, 1e-6, 0.6, True, 0.3, 0.0, np.zeros(3), False, 0.15, np.zeros(3))
    off = on[:5] + (False, 0.3, 0.0, np.zeros(3), False) + on[10:]
    ts = _tets_of_triangles(st, np.arange(k // 2, dtype=np.float64))
    pair = hr._fused(ts, W, H, on, False, pair=True)
    assert pair[3] == k and pair[4] == 0
    for params, (rgb2, a2) in ((on, pair[:2]), (off, pair[5:7])):
        rgb, a, vol = hr._fused(ts, W, H, params, True)[:3]
        ref_rgb, ref_a, ref_vol, _ = hr._reference(st, W, H, params, True)
        assert ref_a.max() > 0.0
        # the same voxel classes, opacities and colours, to the bit (both engines take the
        # opacity of a fractional coverage, 1 − (1 − α)^c, through libm's pow)
        np.testing.assert_array_equal(vol, ref_vol)
        assert a.tobytes() == ref_a.tobytes()
        assert rgb.tobytes() == ref_rgb.tobytes()
        assert rgb2.tobytes() == rgb.tobytes() and a2.tobytes() == a.tobytes()


def test_reference_opacity_is_libm_pow_per_value():
    """The reference engine's surface opacity 1 − (1 − α)^c of a fractional coverage c is
    libm's pow one value at a time (math.pow, the oracle here), the pow of the fused kernel's
    scalar ``**``; α itself at full coverage. NumPy's array power differs from libm's by an ulp
    on about 6 % of arguments where the CPU has AVX-512: it made the engines differ in the last
    bit of opacity and colour (the sliver test above)."""
    import math
    rng = np.random.default_rng(11)
    cov = rng.uniform(0.0, 1.0, 5000)
    cov[::7] = 1.0
    cov[3] = 0.0
    for alpha in (0.6, 0.05, 1.0):
        want = np.array([alpha if c == 1.0 else 1.0 - math.pow(1.0 - alpha, c) for c in cov])
        assert hr._opacity(alpha, cov).tobytes() == want.tobytes()


def test_slices_below_is_numpys_searchsorted_right():
    # the binning's slice ranges walk from the index equal spacing predicts: the count of
    # planes at or below z must be np.searchsorted(centres, z, "right") for any planes in
    # increasing order (uneven, repeated, one, none) and z on, beside and beyond them
    rng = np.random.default_rng(11)
    for centres in (np.linspace(-1.0, 3.0, 256), np.sort(rng.uniform(-2, 2, 40)) ** 3,
                    np.repeat([0.5, 0.75, 2.0], [3, 1, 4]), np.array([0.25]), np.zeros(0)):
        zs = np.concatenate([centres, np.nextafter(centres, np.inf),
                             np.nextafter(centres, -np.inf), rng.uniform(-5, 5, 200),
                             [-1e300, 1e300, 0.0]])
        c0 = centres[0] if len(centres) else 0.0
        span = centres[-1] - c0 if len(centres) > 1 else 0.0
        inv_step = (len(centres) - 1) / span if span > 0 else 0.0
        got = [hr._slices_below(centres, zv, c0, inv_step) for zv in zs]
        assert np.array_equal(got, np.searchsorted(centres, zs, "right"))


def test_band_binning_and_slicing_equal_their_serial_definitions():
    """The fused engine's parallel pieces against the plain definitions, on a frame with
    several binning chunks (hr.BIN_CHUNK) and slices: the slice triangles are those of a
    tetrahedron-major walk (per slice, tetrahedra in index order, each tetrahedron's
    section corners), and each band lists every tetrahedron whose valid slice triangles touch
    it, in index order, with every slice of such a triangle in the entry's slice range (planted
    faults caught: one vertex left out of a tetrahedron's rows; the band's slab not widened by
    a pixel in ``_band_slices``)."""
    s = h.spun_trefoil(n_s=100, n_phi=24)
    geo, _ = hr.prepare(s, view=h.View4D(rotation=h.compose(("zw", 0.6), ("zx", 0.3))))
    v = geo.vertices
    w, hgt, n = 96, 80, 48
    bounds = hr._screen_bounds([v], w, hgt, 0.05)
    centres = bounds[0, 2] + (np.arange(n) + 0.5) * (bounds[1, 2] - bounds[0, 2]) / n
    st_ = hs._slice(v[:, 2].copy(), geo.tets, centres, geo.attributes, hs.ortho_ndc(v, bounds))
    assert len(st_) > 2 * hr.BIN_CHUNK
    # slicing: per slice, the tetrahedra in index order
    z = v[:, 2][geo.tets]
    expect = [t for k, c in enumerate(centres)
              for t in np.flatnonzero((z.min(axis=1) < c) & (c <= z.max(axis=1)))
              for _ in range(hs._section_corners(*(z[t] - c))[0])]
    assert np.array_equal(st_.tet, expect)
    assert np.array_equal(st_.slice, np.repeat(np.arange(n), np.diff(st_.starts)))
    # band binning of the tetrahedra: each band lists, in index order, every tetrahedron with a
    # valid slice triangle touching its rows (the window set-up being ``setup_window``'s)
    X, Y, order, bbox, valid, _, _ = hs.setup_window(st_.xy, w, hgt)
    ts = hr._tet_slices(v, geo.tets, centres, geo.attributes, bounds)
    assert len(geo.tets) > 2 * hr.BIN_CHUNK
    for band_rows in (1, hr.BAND_ROWS):     # one row per band: the tightest check
        clipped = pairs = 0
        nb = (hgt + band_rows - 1) // band_rows
        starts, lists, first, last, k0, k1, _ = hr._bin_tets(ts.z, ts.ndc, ts.tets,
                                                             ts.centres, w, hgt,
                                                             hs.SUBPIXEL_BITS, band_rows, nb)
        # the slice ranges, computed with the binning: slice_ranges' bits
        assert all(np.array_equal(a, b) for a, b in zip((k0, k1),
                                                         hs.slice_ranges(ts.z, ts.tets, centres)))
        # each entry's slices: all of its tetrahedron's, cut to the band's slab where it
        # spans several bands (as the fill does)
        ks = np.column_stack([k0[lists], k1[lists]])
        for band in range(nb):
            r0, r1 = band * band_rows, min(hgt, (band + 1) * band_rows)
            for q in range(starts[band], starts[band + 1]):
                t = lists[q]
                if first[t] < last[t]:
                    ks[q] = hr._band_slices(ts.z, ts.ndc, ts.tets, t, hgt, r0, r1,
                                            ts.centres, k0[t], k1[t])
        assert np.all((k0[lists] <= ks[:, 0]) & (ks[:, 1] <= np.maximum(k1, k0)[lists]))
        rows = (hgt - 1 - bbox[:, 3]) // band_rows, (hgt - 1 - bbox[:, 2]) // band_rows
        for band in range(nb):
            listed = lists[starts[band]:starts[band + 1]]
            assert np.all(np.diff(listed) > 0), band
            touch = valid & (rows[0] <= band) & (band <= rows[1])
            need = np.unique(st_.tet[touch])
            assert np.isin(need, listed).all(), (band, np.setdiff1d(need, listed)[:5])
            assert np.all(first[listed] <= band)
            # each touching triangle's slice lies in its tetrahedron's entry's slice range
            at = np.searchsorted(listed, st_.tet[touch]) + starts[band]
            k = st_.slice[touch]
            assert np.all((ks[at, 0] <= k) & (k < ks[at, 1])), band
            clipped += int((ks[starts[band]:starts[band + 1], 1]
                            - ks[starts[band]:starts[band + 1], 0]).sum())
            pairs += int((k1 - k0)[listed].sum())
        assert clipped < pairs    # the ranges are cut where a tetrahedron spans bands
    # the fused pass counts the slice triangles and the invalid ones as the slicing does
    params = (0.3, 2.0, 0.3, 1e-6, 0.6, True, 0.3, 0.0, np.zeros(3), False, 0.15, np.zeros(3))
    _, _, _, n_tri, n_bad = hr._fused(ts, w, hgt, params, False)
    assert (n_tri, n_bad) == (len(st_), np.count_nonzero(~valid))


def test_column_extrema_are_the_axis_0_reductions_bit_for_bit():
    """``_column_extrema`` (each column's 1D minimum and maximum) against ``min(axis=0)`` and
    ``max(axis=0)``, bit for bit, on columns of ±0, ±1, ±2 where the two reduction orders
    return zeros of different signs (on about a fifth of them), on columns with a NaN or
    an infinity, and on random data (planted fault caught: the fallback for zero results
    removed)."""
    rng = np.random.default_rng(5)
    differ = 0
    for trial in range(600):
        n = int(rng.integers(1, 200))
        p = rng.choice([0.0, -0.0, 1.0, 2.0], size=(n, 3))
        p[:, 1] = -p[:, 1]     # zero maxima there
        if trial % 50 == 0:
            p[rng.integers(n), rng.integers(3)] = [np.nan, np.inf, -np.inf][trial // 50 % 3]
        if trial % 7 == 0:
            p = rng.normal(size=(n, 3))
        lo, hi = hr._column_extrema(p)
        ref_lo, ref_hi = p.min(axis=0), p.max(axis=0)
        assert lo.tobytes() == ref_lo.tobytes() and hi.tobytes() == ref_hi.tobytes()
        cols = (np.array([p[:, j].min() for j in range(3)]),
                np.array([p[:, j].max() for j in range(3)]))
        differ += cols[0].tobytes() != ref_lo.tobytes() or cols[1].tobytes() != ref_hi.tobytes()
    assert differ > 50


def test_fused_float32_pictures_are_the_float64_ones_rounded():
    """``_fused(…, f32=True)`` (the kernel rounds its pictures to float32, render_halos' path)
    gives NumPy's ``astype(float32)`` of the float64 pictures, for one picture and for the
    pair, over a non-black background (planted fault caught: the float32 alpha written before
    the background's term, i.e. the float32 colour without it)."""
    s = fig1()
    geo, _ = hr.prepare(s, view=h.View4D(rotation=h.compose(("zx", 0.5), ("yz", -1.0))))
    v = geo.vertices
    w, hgt, n = 64, 56, 32
    bounds = hr._screen_bounds([v], w, hgt, 0.05)
    centres = bounds[0, 2] + (np.arange(n) + 0.5) * (bounds[1, 2] - bounds[0, 2]) / n
    ts = hr._tet_slices(v, geo.tets, centres, geo.attributes, bounds)
    params = (0.3, 1.0, 0.2, 1e-6, 0.6, True, 0.05, 0.0, np.zeros(3), False, 0.15, np.zeros(3))
    bg = np.array([0.2, 0.5, 0.9])
    for pair in (False, True):
        a = hr._fused(ts, w, hgt, params, False, pair=pair, background=bg)
        b = hr._fused(ts, w, hgt, params, False, pair=pair, background=bg, f32=True)
        pics = (0, 1, 5, 6) if pair else (0, 1)
        for i in pics:
            assert b[i].dtype == np.float32
            assert b[i].tobytes() == a[i].astype(np.float32).tobytes()
        assert a[3:5] == b[3:5]
        assert np.count_nonzero(a[1]) > 100
