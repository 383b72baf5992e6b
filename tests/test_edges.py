"""Edge enhancement: G-buffer, discontinuity filters, edge map, object-space classification."""

from functools import lru_cache

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

import refraster as rf
from refraster import edges
from determinism import outputs_by_thread_count

# ---------------------------------------------------------------- NumPy twins (clamp-to-edge)


def _shifted(a):
    """The eight clamp-to-edge neighbours of every pixel, named as in the paper's Fig. 2."""
    p = np.pad(a, [(1, 1), (1, 1)] + [(0, 0)] * (a.ndim - 2), mode="edge")
    h, w = a.shape[:2]
    s = {}
    for name, (dy, dx) in dict(A=(-1, -1), B=(-1, 0), C=(-1, 1), D=(0, -1), X=(0, 0),
                               E=(0, 1), F=(1, -1), G=(1, 0), H=(1, 1)).items():
        s[name] = p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
    return s


def _dot(p, q):
    return (p[..., 0] * q[..., 0] + p[..., 1] * q[..., 1]) + p[..., 2] * q[..., 2]


def twin_diagonal_normal(n, encoded=False):
    n = n.astype(np.float64)
    if encoded:
        n = 2.0 * n - 1.0
    s = _shifted(n)
    i_n = 0.5 * (_dot(s["A"], s["H"]) + _dot(s["C"], s["F"]))
    return (1.0 - np.minimum(np.maximum(i_n, 0.0), 1.0)).astype(np.float32)


def twin_diagonal_depth(z, order=1):
    s = _shifted(z.astype(np.float64))
    if order == 1:
        d1, d2 = s["A"] - s["H"], s["C"] - s["F"]
    else:
        d1 = (s["A"] + s["H"]) - 2.0 * s["X"]
        d2 = (s["C"] + s["F"]) - 2.0 * s["X"]
    a = 1.0 - 0.5 * np.abs(d1)
    b = 1.0 - 0.5 * np.abs(d2)
    return (1.0 - (a * a) * (b * b)).astype(np.float32)


def twin_c1_depth(z, divisor=12.0):
    s = _shifted(z.astype(np.float64))
    x = s["X"]
    t = np.abs(s["A"] - x) + 2.0 * np.abs(s["B"] - x)
    t = t + np.abs(s["C"] - x) + 2.0 * np.abs(s["D"] - x)
    t = t + 2.0 * np.abs(s["E"] - x) + np.abs(s["F"] - x)
    t = t + 2.0 * np.abs(s["G"] - x) + np.abs(s["H"] - x)
    return np.minimum(t / divisor, 1.0).astype(np.float32)


def twin_sobel_parts(a):
    s = _shifted(a.astype(np.float64))
    gy = (s["F"] + 2.0 * s["G"] + s["H"]) - (s["A"] + 2.0 * s["B"] + s["C"])
    gx = (s["C"] + 2.0 * s["E"] + s["H"]) - (s["A"] + 2.0 * s["D"] + s["F"])
    return gy, gx


def twin_sobel_normal(n, k_n=1.0):
    total = 0.0
    for c in range(3):
        gy, gx = twin_sobel_parts(n[..., c])
        total = total + (gy * gy + gx * gx)
    return np.minimum(k_n * np.sqrt(total) / 8.0, 1.0).astype(np.float32)


def twin_angle_normal(n):
    s = _shifted(n.astype(np.float64))
    best = np.zeros(n.shape[:2])
    for q in "ABCDEFGH":
        best = np.maximum(best, 0.5 * (1.0 - _dot(s["X"], s[q])))
    return np.minimum(best, 1.0).astype(np.float32)


def twin_object_id_edges(ids):
    s = _shifted(ids)
    out = np.zeros(ids.shape, bool)
    for q in "ABCDEFGH":
        out |= s[q] != s["X"]
    return out.astype(np.float32)


def _random_normals(rng, h, w, background=0.2):
    n = rng.normal(size=(h, w, 3))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    n[rng.random((h, w)) < background] = 0.0
    return n.astype(np.float32)


def _bits(a):
    return np.asarray(a).tobytes()


# ---------------------------------------------------------------- twins, bit for bit

@pytest.mark.parametrize("seed", range(3))
def test_filters_match_numpy_twins_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    h, w = 17 + seed, 23
    n = _random_normals(rng, h, w)
    z = rng.random((h, w)).astype(np.float32)
    z64 = rng.random((h, w))
    ids = rng.integers(-1, 3, (h, w))
    enc = (np.float32(0.5) * n + np.float32(0.5)).astype(np.float32)
    assert _bits(edges.diagonal_normal(n)) == _bits(twin_diagonal_normal(n))
    assert _bits(edges.diagonal_normal(enc, encoded=True)) == \
        _bits(twin_diagonal_normal(enc, encoded=True))
    for depth in (z, z64):
        assert _bits(edges.diagonal_depth(depth)) == _bits(twin_diagonal_depth(depth))
        assert _bits(edges.diagonal_depth(depth, order=2)) == \
            _bits(twin_diagonal_depth(depth, order=2))
        assert _bits(edges.c1_depth(depth)) == _bits(twin_c1_depth(depth, 12.0))
        assert _bits(edges.c1_depth(depth, scale="paper")) == _bits(twin_c1_depth(depth, 8.0))
        gy, gx = twin_sobel_parts(depth)
        dt = depth.dtype
        assert edges.sobel(depth).dtype == dt
        assert _bits(edges.sobel(depth, axis=0)) == _bits(gy.astype(dt))
        assert _bits(edges.sobel(depth, axis=1)) == _bits(gx.astype(dt))
        assert _bits(edges.sobel(depth)) == _bits(np.sqrt(gy * gy + gx * gx).astype(dt))
    assert _bits(edges.sobel_normal(n, k_n=1.5)) == _bits(twin_sobel_normal(n, 1.5))
    assert _bits(edges.sobel_normal(n, form="angle")) == _bits(twin_angle_normal(n))
    assert _bits(edges.object_id_edges(ids)) == _bits(twin_object_id_edges(ids))


def test_edge_map_is_the_filters_fused():
    rng = np.random.default_rng(7)
    h, w = 19, 26
    n = _random_normals(rng, h, w, background=0.0)
    ids = rng.integers(0, 2, (h, w)).astype(np.int32)
    ids[:3] = -1
    n[ids < 0] = 0.0
    enc = np.where(ids[..., None] >= 0, np.float32(0.5) * n + np.float32(0.5),
                   np.float32(0.5)).astype(np.float32)
    z = np.where(ids >= 0, rng.random((h, w)), 1.0).astype(np.float32)
    gb = edges.EdgeGBuffer(normal=enc, depth=z, object_id=ids, near=1.0, far=2.0)
    for nf, zf, with_ids in [("diagonal", "diagonal2", True), ("sobel", "c1", False),
                             ("angle", "sobel", True), ("diagonal", "diagonal", False),
                             ("diagonal", "c1-paper", True)]:
        em = edges.edge_map(gb, normal_filter=nf, depth_filter=zf, ids=with_ids,
                            inner_threshold=0.2, profile_threshold=0.1, k_n=1.5, k_z=2.0)
        e_n = {"diagonal": lambda: twin_diagonal_normal(enc, True),
               "sobel": lambda: twin_sobel_normal(2.0 * enc.astype(np.float64) - 1.0, 1.5),
               "angle": lambda: twin_angle_normal(2.0 * enc.astype(np.float64) - 1.0)}[nf]()
        e_z = {"diagonal2": lambda: twin_diagonal_depth(z, 2),
               "diagonal": lambda: twin_diagonal_depth(z, 1),
               "c1": lambda: twin_c1_depth(z, 12.0), "c1-paper": lambda: twin_c1_depth(z, 8.0),
               "sobel": lambda: np.minimum(
                   2.0 * np.hypot(*twin_sobel_parts(z)) / 4.0, 1.0).astype(np.float32)}[zf]()
        e_n = np.where((e_n >= np.float32(0.2)) & (ids >= 0), e_n, 0).astype(np.float32)
        e_z = np.where(e_z >= np.float32(0.1), e_z, 0).astype(np.float32)
        if with_ids:
            e_z = np.maximum(e_z, twin_object_id_edges(ids))
        if zf == "sobel":  # hypot vs sqrt(x² + y²) may differ in the last bit
            np.testing.assert_allclose(em[..., 3], e_z, rtol=0, atol=1e-6)
        else:
            assert _bits(em[..., 3]) == _bits(e_z), (nf, zf)
        for c in range(3):
            assert _bits(em[..., c]) == _bits(e_n), (nf, zf)


# ---------------------------------------------------------------- oracles: scipy, scikit-image

@lru_cache(maxsize=None)
def _torus_fb(width=96, height=72):
    mesh = trimesh.creation.torus(1.0, 0.35, major_sections=48, minor_sections=16)
    cam = rf.camera.frame_bounds(mesh.bounds, width=width, height=height)
    return rf.render(mesh, **cam.kwargs, raster=rf.RasterState(normals="smooth"))


def _test_images():
    rng = np.random.default_rng(3)
    fb = _torus_fb()
    gb = edges.edge_gbuffer(fb)
    return [rng.random((31, 45)), rng.normal(size=(8, 5)) * 10, gb.depth.astype(np.float64),
            gb.normal[..., 2].astype(np.float64), np.ones((1, 7)), rng.random((1, 1))]


def test_sobel_matches_scipy_ndimage_nearest(oracle):
    ndi = oracle("scipy.ndimage")
    for img in _test_images():
        g0 = ndi.sobel(img, 0, mode="nearest")
        g1 = ndi.sobel(img, 1, mode="nearest")
        np.testing.assert_allclose(edges.sobel(img), np.hypot(g0, g1), rtol=0, atol=1e-6)
        np.testing.assert_allclose(edges.sobel(img, axis=0), g0, rtol=0, atol=1e-6)
        np.testing.assert_allclose(edges.sobel(img, axis=1), g1, rtol=0, atol=1e-6)


def test_sobel_matches_skimage_after_normalization(oracle):
    filters = oracle("skimage.filters")
    for img in _test_images():
        if min(img.shape) < 2:
            continue
        # scikit-image scales each derivative by 1/4 and the magnitude by 1/sqrt(ndim); for a
        # 3×3 kernel its default "reflect" border equals clamp-to-edge
        ours = edges.sobel(img) / (4.0 * np.sqrt(2.0))
        np.testing.assert_allclose(ours, filters.sobel(img), rtol=0, atol=1e-6)
        np.testing.assert_allclose(ours, filters.sobel(img, mode="nearest"), rtol=0, atol=1e-6)


def test_sobel_of_rendered_normals_matches_scipy_per_channel(oracle):
    ndi = oracle("scipy.ndimage")
    n = _torus_fb().normal.astype(np.float64)
    total = sum(ndi.sobel(n[..., c], 0, mode="nearest") ** 2
                + ndi.sobel(n[..., c], 1, mode="nearest") ** 2 for c in range(3))
    np.testing.assert_allclose(edges.sobel_normal(n, k_n=0.25),
                               np.minimum(0.25 * np.sqrt(total) / 8.0, 1.0), rtol=0, atol=1e-6)


# ---------------------------------------------------------------- analytic cases

def test_flat_plane_gives_exactly_zero():
    z = np.full((9, 11), 0.375)
    n = np.zeros((9, 11, 3))
    n[..., :] = (0.0, 0.0, 1.0)
    for out in (edges.diagonal_depth(z), edges.diagonal_depth(z, order=2), edges.c1_depth(z),
                edges.sobel(z), edges.sobel_depth(z), edges.diagonal_normal(n),
                edges.sobel_normal(n), edges.sobel_normal(n, form="angle"),
                edges.object_id_edges(np.full((9, 11), 4))):
        assert np.all(out == 0.0)
    # a tilted plane (a depth ramp): 0 for the second-order diagonal away from the border,
    # where clamp-to-edge bends the ramp; the Sobel gradient is the slope everywhere inside
    ramp = (np.arange(11) / 64.0)[None, :] + (np.arange(9) / 32.0)[:, None]
    assert np.all(edges.diagonal_depth(ramp, order=2)[1:-1, 1:-1] == 0.0)
    assert np.all(edges.sobel(ramp, axis=1)[1:-1, 1:-1] == 8 / 64.0)
    assert np.all(edges.sobel(ramp, axis=0)[1:-1, 1:-1] == 8 / 32.0)


@pytest.mark.parametrize("delta", [0.5, 0.25, 0.125, 1.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_depth_step_gives_the_math_value_on_the_two_columns_beside_it(delta, axis):
    z = np.full((8, 10), 0.25)
    z[:, 5:] += delta
    if axis == 0:
        z = z.T.copy()
    expected = 1.0 - (1.0 - delta / 2.0) ** 4   # MATH.md §3.2, E_Z = 1 − I_Z
    band = np.zeros(z.shape, bool)
    if axis == 0:
        band[4:6, :] = True
    else:
        band[:, 4:6] = True
    for order in (1, 2):
        e = edges.diagonal_depth(z, order=order)
        assert np.all(e[band] == np.float32(expected))
        assert np.all(e[~band] == 0.0)
    c1 = edges.c1_depth(z)
    assert np.all(c1[band] == np.float32(4 * delta / 12)) and np.all(c1[~band] == 0.0)
    assert np.all(edges.c1_depth(z, scale="paper")[band] == np.float32(min(4 * delta / 8, 1)))
    s = edges.sobel(z)
    assert np.all(s[band] == np.float32(4 * delta)) and np.all(s[~band] == 0.0)
    # through the edge map (one object, so ids add nothing)
    gb = edges.EdgeGBuffer(normal=np.full(z.shape + (3,), 0.5, np.float32).__add__(
        np.float32([0, 0, 0.5])), depth=z.astype(np.float32),
        object_id=np.zeros(z.shape, np.int32), near=0.0, far=1.0)
    em = edges.edge_map(gb, profile_threshold=0.0)
    assert np.all(em[..., 3][band] == np.float32(expected)) and np.all(em[..., 3][~band] == 0)
    assert np.all(em[..., :3] == 0.0)


def _plane_gbuffer(depth, normal=None, ids=None):
    """An EdgeGBuffer of one object covering the frame (normals facing the viewer)."""
    z = np.asarray(depth, np.float32)
    if normal is None:
        normal = np.zeros(z.shape + (3,))
        normal[..., 2] = 1.0
    enc = (np.float32(0.5) * np.asarray(normal, np.float32) + np.float32(0.5)).astype(np.float32)
    ids = np.zeros(z.shape, np.int32) if ids is None else np.asarray(ids, np.int32)
    return edges.EdgeGBuffer(normal=enc, depth=z, object_id=ids, near=0.0, far=1.0)


@pytest.mark.parametrize("sx, sy", [(0.005, 0.0), (0.01, 0.0), (0.02, 0.0), (0.0, 0.01),
                                    (0.01, 0.004), (-0.03, 0.02), (0.1, 0.0)])
def test_default_edge_map_is_the_papers_depth_operator_on_ramps(sx, sy):
    """A depth ramp of slope (s_x, s_y) per pixel: z_A − z_H = −2(s_x + s_y) and
    z_C − z_F = 2(s_x − s_y) (A, C above, F, H below; Fig. 2), so the printed
    I_Z = (1 − ½|A − H|)²(1 − ½|C − F|)² gives E_Z = 1 − (1 − |s_x + s_y|)²(1 − |s_x − s_y|)²,
    and 1 − (1 − s)⁴ for a ramp along one axis (0.0394 at s = 0.01). No thresholds: the raw
    value survives however small."""
    h, w = 9, 12
    z = 0.3 + sx * np.arange(w)[None, :] + sy * np.arange(h)[:, None]
    em = edges.edge_map(_plane_gbuffer(z))
    expect = 1.0 - (1.0 - abs(sx + sy)) ** 2 * (1.0 - abs(sx - sy)) ** 2
    if sy == 0.0:
        assert expect == pytest.approx(1.0 - (1.0 - abs(sx)) ** 4, rel=1e-12)
    inner = (slice(1, -1), slice(1, -1))     # clamp-to-edge bends the ramp at the border
    np.testing.assert_allclose(em[..., 3][inner], expect, rtol=2e-5, atol=0)
    assert np.all(em[..., :3] == 0.0)        # one plane: no normal discontinuity
    # the "clean" preset (second differences, thresholds) gives ≤ 1e-7 there: a different
    # operator, which this test tells apart
    clean = edges.edge_map(_plane_gbuffer(z), preset="clean")
    assert np.all(clean[..., 3][inner] <= 1e-6)


@pytest.mark.parametrize("alpha_deg", [0.5, 2.0, 5.0, 20.0])
@pytest.mark.parametrize("diagonal", [False, True])
def test_default_edge_map_is_the_papers_normal_operator_on_a_normal_ramp(alpha_deg, diagonal):
    """Normals turning by α per pixel column (a cylinder seen side-on): n_A·n_H and n_C·n_F are
    both cos 2α (two columns apart), so E_N = 1 − cos 2α, unthresholded. Turning by α per
    step of x + y (a cylinder whose axis runs at 45° on screen): A and H are 4 steps apart,
    C and F on one line, so I_N = ½(cos 4α + 1) and E_N = ½(1 − cos 4α)."""
    h, w = 7, 15
    yy, xx = np.mgrid[0:h, 0:w]
    a = np.radians(alpha_deg) * ((xx + yy if diagonal else xx) - w // 2)
    n = np.zeros((h, w, 3))
    n[..., 0] = np.sin(a)
    n[..., 2] = np.cos(a)
    em = edges.edge_map(_plane_gbuffer(np.full((h, w), 0.5), n))
    al = np.radians(alpha_deg)
    expect = 0.5 * (1.0 - np.cos(4.0 * al)) if diagonal else 1.0 - np.cos(2.0 * al)
    np.testing.assert_allclose(em[1:-1, 1:-1, 0], expect, rtol=0, atol=3e-7)
    assert np.all(em[..., 0] == em[..., 1]) and np.all(em[..., 0] == em[..., 2])
    assert np.all(em[..., 3] == 0.0)


def test_default_edge_map_has_no_id_edges_and_no_thresholds():
    h, w = 8, 10
    ids = np.zeros((h, w), np.int32)
    ids[:, 5:] = 1                    # two objects meeting flush: same depth, same normal
    z = np.full((h, w), 0.5)
    z[:, 5:] += 0.01                  # a step of 1 % of the range: E_Z = 1 − 0.995⁴ = 0.0199
    em = edges.edge_map(_plane_gbuffer(z, ids=ids))
    expect = np.float32(1.0 - (1.0 - 0.005) ** 4)
    np.testing.assert_allclose(em[:, 4:6, 3], expect, rtol=2e-5)
    assert np.all(em[:, :4, 3] == 0) and np.all(em[:, 6:, 3] == 0)
    clean = edges.edge_map(_plane_gbuffer(z, ids=ids), preset="clean")
    assert np.all(clean[:, 4:6, 3] == 1.0)          # the preset's hard id edge
    # a 5° crease: E_N = 1 − cos 5° = 0.0038, kept by the paper, zeroed by "clean" (0.1)
    n = np.zeros((h, w, 3))
    n[:, :5] = (0.0, 0.0, 1.0)
    n[:, 5:] = (np.sin(np.radians(5)), 0.0, np.cos(np.radians(5)))
    em = edges.edge_map(_plane_gbuffer(np.full((h, w), 0.5), n))
    np.testing.assert_allclose(em[:, 4:6, 0], 1.0 - np.cos(np.radians(5)), atol=1e-7)
    assert np.all(edges.edge_map(_plane_gbuffer(np.full((h, w), 0.5), n),
                                 preset="clean")[..., 0] == 0)


def test_default_edge_map_equals_the_printed_filters_bit_for_bit():
    rng = np.random.default_rng(12)
    h, w = 21, 17
    n = _random_normals(rng, h, w, background=0.0)
    ids = rng.integers(0, 3, (h, w)).astype(np.int32)
    ids[:2] = -1
    enc = np.where(ids[..., None] >= 0, np.float32(0.5) * n + np.float32(0.5),
                   np.float32(0.5)).astype(np.float32)
    z = np.where(ids >= 0, rng.random((h, w)), 1.0).astype(np.float32)
    gb = edges.EdgeGBuffer(normal=enc, depth=z, object_id=ids, near=1.0, far=2.0)
    em = edges.edge_map(gb)
    e_n = np.where(ids >= 0, twin_diagonal_normal(enc, True), 0).astype(np.float32)
    assert _bits(em[..., 3]) == _bits(twin_diagonal_depth(z, 1))
    for c in range(3):
        assert _bits(em[..., c]) == _bits(e_n)
    assert _bits(edges.edge_map(gb, preset="paper")) == _bits(em)
    # the preset's values can be overridden one by one
    assert _bits(edges.edge_map(gb, preset="clean", depth_filter="diagonal", ids=False,
                                inner_threshold=0.0, profile_threshold=0.0)) == _bits(em)
    assert _bits(edges.edge_map(gb, preset="clean")) == _bits(edges.edge_map(
        gb, depth_filter="diagonal2", ids=True, inner_threshold=0.1, profile_threshold=0.03))


def test_ninety_degree_crease_gives_one_on_the_straddling_pixels():
    h, w = 7, 12
    n = np.zeros((h, w, 3))
    n[:, :6] = (1.0, 0.0, 0.0)
    n[:, 6:] = (0.0, 0.0, 1.0)
    expected = np.zeros((h, w), np.float32)
    expected[:, 5:7] = 1.0   # A/F on one side, H/C on the other
    assert _bits(edges.diagonal_normal(n)) == _bits(expected)
    enc = (0.5 * n + 0.5).astype(np.float32)
    assert _bits(edges.diagonal_normal(enc, encoded=True)) == _bits(expected)
    # a 60° crease gives 1 − cos 60° = 0.5
    n[:, 6:] = (0.5, 0.0, np.sqrt(0.75))
    e = edges.diagonal_normal(n)
    np.testing.assert_allclose(e[:, 5:7], 0.5, atol=1e-7)
    assert np.all(e[:, :5] == 0) and np.all(e[:, 7:] <= 2e-16)   # 0.25 + 0.75 rounds
    # Sobel per channel: each of two channels steps by 1 → sqrt(2·16)/8
    n[:, 6:] = (0.0, 0.0, 1.0)
    np.testing.assert_allclose(edges.sobel_normal(n)[:, 5:7], np.sqrt(32.0) / 8.0, rtol=1e-7)
    assert np.all(edges.sobel_normal(n, form="angle")[:, 5:7] == 0.5)


def test_background_normals_at_the_profile():
    """Background normal 0 (MATH.md §3.2): a pair with a background sample has dot 0. Along an
    axis-aligned profile both diagonal pairs straddle it (E_N = 1); along a 45° profile one
    pair runs inside the object (E_N = 0.5, MATH.md's "I_N = 0.5 at profiles")."""
    n = np.zeros((6, 8, 3))
    n[:, :4] = (0.0, 0.0, 1.0)
    e = edges.diagonal_normal(n)
    assert np.all(e[:, :3] == 0.0) and np.all(e[:, 3:] == 1.0)
    y, x = np.mgrid[0:8, 0:8]
    n = np.zeros((8, 8, 3))
    n[y >= x] = (0.0, 0.0, 1.0)
    e = edges.diagonal_normal(n)
    assert np.all(e[1:-1, 1:-1][np.diag(np.ones(6, bool))] == 0.5)
    assert np.all(e[y > x + 1] == 0.0)


def test_object_id_edges_mark_both_sides_and_islands():
    ids = np.zeros((6, 9), int)
    ids[:, 5:] = 2
    ids[2, 1] = -1
    e = edges.object_id_edges(ids)
    assert np.all(e[:, 4:6] == 1) and np.all(e[1:4, 0:3] == 1)
    assert e[0, 0] == 0 and e[5, 7] == 0 and e.sum() == 12 + 9


# ---------------------------------------------------------------- properties



@settings(max_examples=25, deadline=None)
@given(st.integers(1, 9), st.integers(1, 9), st.integers(0, 2**32 - 1))
def test_filters_stay_in_range_and_commute_with_flips(h, w, seed):
    rng = np.random.default_rng(seed)
    # dyadic values keep every sum exact, so flipping must give the same bits
    z = rng.integers(0, 64, (h, w)) / 64.0
    n = _random_normals(rng, h, w).astype(np.float64)
    for f in (edges.diagonal_depth, lambda a: edges.diagonal_depth(a, order=2), edges.c1_depth,
              lambda a: edges.c1_depth(a, scale="paper"), edges.sobel_depth):
        e = f(z)
        assert e.dtype == np.float32 and np.all((e >= 0) & (e <= 1))
        assert _bits(f(z[:, ::-1])) == _bits(e[:, ::-1])
        assert _bits(f(z[::-1])) == _bits(e[::-1])
        assert _bits(f(z.T)) == _bits(e.T)
    for f in (edges.diagonal_normal, edges.sobel_normal,
              lambda a: edges.sobel_normal(a, form="angle")):
        e = f(n)
        assert np.all((e >= 0) & (e <= 1))
        np.testing.assert_allclose(f(n[::-1, ::-1]), e[::-1, ::-1], atol=1e-6)


@settings(max_examples=20, deadline=None)
@given(st.integers(2, 8), st.integers(2, 8), st.integers(0, 2**32 - 1),
       st.integers(-3, 3), st.integers(-3, 3))
def test_second_order_diagonal_ignores_depth_ramps(h, w, seed, gx, gy):
    rng = np.random.default_rng(seed)
    z = rng.integers(0, 64, (h, w)) / 256.0
    ramp = (np.arange(w)[None, :] * gx + np.arange(h)[:, None] * gy) / 256.0
    inner = np.zeros((h, w), bool)
    inner[1:-1, 1:-1] = True   # clamping bends the ramp at the border
    a = edges.diagonal_depth(z + ramp, order=2)
    b = edges.diagonal_depth(z, order=2)
    assert _bits(a[inner]) == _bits(b[inner])


# ---------------------------------------------------------------- G-buffer

def test_edge_gbuffer_encoding_and_depth():
    fb = _torus_fb()
    gb = edges.edge_gbuffer(fb)
    m = fb.mask
    assert gb.normal.dtype == np.float32 and gb.depth.dtype == np.float32
    assert np.all(gb.normal[~m] == 0.5) and np.all(gb.depth[~m] == 1.0)
    assert _bits(gb.normal[m]) == _bits(np.float32(0.5) * fb.normal[m] + np.float32(0.5))
    assert np.all(gb.object_id == fb.object_id)
    # near/far fitted to the vertices' eye-space depth range
    v = fb.meshes[0].vertices
    z_eye = -(v @ fb.view[2, :3] + fb.view[2, 3])
    assert (gb.near, gb.far) == (z_eye.min(), z_eye.max())
    assert _bits(gb.depth) == _bits(rf.normalized_linear_depth(fb, gb.near, gb.far))
    assert gb.depth[m].min() >= 0.0 and gb.depth[m].max() <= 1.0
    assert gb.rgba.shape == fb.normal.shape[:2] + (4,)
    # bounds: the eight corners of the box
    box = fb.meshes[0].to_trimesh().bounds
    near, far = edges.fit_near_far(fb.view, bounds=box)
    assert near <= gb.near and far >= gb.far
    gb2 = edges.edge_gbuffer(fb, bounds=box)
    assert (gb2.near, gb2.far) == (near, far)
    gb3 = edges.edge_gbuffer(fb, near=2.0, far=12.0)
    assert _bits(gb3.depth) == _bits(rf.normalized_linear_depth(fb, 2.0, 12.0))


def test_width_option_dilates_with_a_disk():
    z = np.full((9, 14), 0.25, np.float32)
    z[:, 7:] = 0.75
    gb = edges.EdgeGBuffer(normal=np.full((9, 14, 3), 0.5, np.float32) + np.float32([0, 0, .5]),
                           depth=z, object_id=np.zeros((9, 14), np.int32), near=0, far=1)
    thin = edges.edge_map(gb)[..., 3]
    assert np.array_equal(np.flatnonzero(thin[4] > 0), [6, 7])
    wide = edges.edge_map(gb, width=3)[..., 3]
    assert np.array_equal(np.flatnonzero(wide[4] > 0), [4, 5, 6, 7, 8, 9])
    assert np.all(wide >= thin) and wide.max() == thin.max()


# ---------------------------------------------------------------- object-space classification

def _brute_force_classes(v, f, eye, angle):
    """Per edge: its faces, facing and dihedral, by plain loops."""
    fn = []
    for a, b, c in f:
        n = np.cross(v[b] - v[a], v[c] - v[a])
        fn.append(n / np.linalg.norm(n))
    adj = {}
    for i, tri in enumerate(f):
        for k in range(3):
            e = tuple(sorted((int(tri[k]), int(tri[(k + 1) % 3]))))
            adj.setdefault(e, []).append(i)
    out = {}
    for e, fs in adj.items():
        front = [float(np.dot(fn[i], eye - v[f[i][0]])) > 0 for i in fs]
        if len(fs) == 1:
            out[e] = "border"
        elif any(front) and not all(front):
            out[e] = "silhouette"
        elif np.degrees(np.arccos(np.clip(np.dot(fn[fs[0]], fn[fs[1]]), -1, 1))) > angle:
            out[e] = "crease"
        else:
            out[e] = None
    return out


def _classes(es):
    out = {}
    for k, e in enumerate(es.edges):
        key = tuple(int(i) for i in e)
        out[key] = ("border" if es.border[k] else "silhouette" if es.silhouette[k]
                    else "crease" if es.crease[k] else None)
    return out


def test_classify_cube_from_a_corner():
    box = trimesh.creation.box()
    view = rf.look_at([3.0, 2.5, 2.0], [0, 0, 0])
    es = edges.classify_edges(box, view=view)
    assert len(es) == 18 and es.silhouette.sum() == 6 and es.crease.sum() == 6
    assert es.border.sum() == 0 and not np.any(es.silhouette & es.crease)
    assert np.all(np.isin(es.dihedral[es.crease | es.silhouette], [90.0]))
    np.testing.assert_allclose(np.sort(es.dihedral)[:6], 0.0, atol=1e-12)
    # orthographic along the same direction: the same classes
    ortho = edges.classify_edges(box, view=view, proj=rf.orthographic(-2, 2, -2, 2, 0.1, 9))
    assert np.array_equal(ortho.silhouette, es.silhouette)
    # an open mesh: drop one face → its three edges become border edges
    open_box = (box.vertices, box.faces[1:])
    es2 = edges.classify_edges(open_box, view=view)
    assert es2.border.sum() == 3 and len(es2) == 18


def test_classify_matches_brute_force_and_trimesh(oracle):
    mesh = trimesh.creation.torus(1.0, 0.4, major_sections=20, minor_sections=9)
    model = rf.look_at([0, 0, 0], [0.3, -1, 0.2], up=[1, 0, 0])   # any rigid motion
    view = rf.look_at([2.5, 1.5, 3.0], [0, 0, 0])
    es = edges.classify_edges(mesh, view=view, model=model, crease_angle=25.0)
    eye = (np.linalg.inv(view @ model) @ [0, 0, 0, 1])[:3]
    assert _classes(es) == _brute_force_classes(mesh.vertices, mesh.faces, eye, 25.0)
    # trimesh's dihedral angles of the same adjacent face pairs
    angles = dict(zip(map(tuple, np.sort(mesh.face_adjacency_edges, axis=1)),
                      np.degrees(mesh.face_adjacency_angles)))
    ours = dict(zip(map(tuple, es.edges), es.dihedral))
    assert angles.keys() == ours.keys()
    # trimesh takes arccos of the cosine, good to about 1e-6° near 0
    np.testing.assert_allclose([ours[k] for k in angles], list(angles.values()), atol=1e-5)


def test_classify_non_manifold_and_empty():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1.0]])
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])      # three faces on the edge (0, 1)
    es = edges.classify_edges((v, f), view=rf.look_at([3.0, 2.0, 2.0], [0, 0, 0]))
    k = int(np.flatnonzero((es.edges == [0, 1]).all(axis=1))[0])
    assert es.n_faces[k] == 3 and np.array_equal(es.faces[k], [0, 1])
    assert es.dihedral[k] == pytest.approx(90.0)    # the largest over the three face pairs
    assert es.border.sum() == 6 and np.all(np.isnan(es.dihedral[es.border]))
    empty = edges.classify_edges((v, np.zeros((0, 3), int)), view=np.eye(4))
    assert len(empty) == 0 and empty.faces.shape == (0, 2)


def test_classify_mirror_model_keeps_screen_facing():
    box = trimesh.creation.box()
    view = rf.look_at([3.0, 2.5, 2.0], [0, 0, 0])
    mirror = np.diag([-1.0, 1, 1, 1])
    a = edges.classify_edges(box, view=view)
    b = edges.classify_edges(box, view=view @ mirror, model=mirror)
    assert np.array_equal(a.silhouette, b.silhouette) and np.array_equal(a.crease, b.crease)


# ---------------------------------------------------------------- image space vs object space

def _projected_profile_pixels(fb, mesh, es, cam):
    """Pixels crossed by visible projected silhouette/border edges.

    Each edge is sampled every ≤ 1/4 pixel (linearly in clip space, which is linear in object
    space). A sample counts as visible when some pixel of its 3×3 neighbourhood shows a surface
    at or behind the sample's eye depth (i.e. it is not hidden everywhere around it)."""
    v = np.asarray(mesh.vertices, np.float64)
    mvp = cam.proj @ cam.view
    inv_proj = np.linalg.inv(cam.proj)
    h, w = fb.height, fb.width
    eye_depth = np.where(np.isfinite(fb.eye_depth), fb.eye_depth, np.inf)
    pad = np.pad(eye_depth, 1, mode="edge")
    around = np.max([pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                     for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    ref = np.zeros((h, w), bool)
    vh = np.c_[v, np.ones(len(v))] @ mvp.T
    for i, j in es.edges[es.profile]:
        p0, p1 = vh[i], vh[j]
        a, b = p0[:2] / p0[3], p1[:2] / p1[3]
        length = np.hypot((a - b)[0] * w / 2, (a - b)[1] * h / 2)
        t = np.linspace(0.0, 1.0, max(2, int(np.ceil(4 * length)) + 1))[:, None]
        c = (1 - t) * p0 + t * p1
        col = np.floor((c[:, 0] / c[:, 3] + 1) * w / 2).astype(np.int64)
        row = h - 1 - np.floor((c[:, 1] / c[:, 3] + 1) * h / 2).astype(np.int64)
        e = c @ inv_proj.T
        depth = -e[:, 2] / e[:, 3]
        ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
        row, col, depth = row[ok], col[ok], depth[ok]
        vis = around[row, col] >= depth * (1 - 1e-4)
        ref[row[vis], col[vis]] = True
    return ref


@pytest.mark.parametrize("name", ["torus", "crank"])
def test_image_space_profile_matches_projected_silhouettes(name, oracle):
    ndi = oracle("scipy.ndimage")
    try:
        from refraster.scenes import solids
        mesh = getattr(solids, name)()
    except (ImportError, AttributeError):
        pytest.skip("refraster.scenes is not available")
    cam = rf.camera.frame_bounds(mesh.bounds, width=640, height=480)
    fb = rf.render(mesh, **cam.kwargs)
    es = edges.classify_edges(mesh, view=cam.view, proj=cam.proj)
    ref = _projected_profile_pixels(fb, mesh, es, cam)
    img = edges.edge_map(fb, preset="clean")[..., 3] > 0      # the preset's threshold
    near = np.ones((3, 3), bool)
    recall = (ref & ndi.binary_dilation(img, near)).sum() / ref.sum()
    precision = (img & ndi.binary_dilation(ref, near)).sum() / img.sum()
    print(f"{name}: {ref.sum()} projected profile px, {img.sum()} image px, "
          f"recall {recall:.4f}, precision {precision:.4f}")
    assert ref.sum() > 500
    assert recall >= 0.95 and precision >= 0.90


# ---------------------------------------------------------------- bad input

@pytest.mark.parametrize("call, exc, words", [
    (lambda: edges.diagonal_depth(np.zeros((4, 4, 1))), ValueError, "depth must have shape"),
    (lambda: edges.diagonal_depth(np.zeros((0, 4))), ValueError, "empty"),
    (lambda: edges.diagonal_depth(np.full((3, 3), np.nan)), ValueError, "non-finite"),
    (lambda: edges.diagonal_depth(np.full((3, 3), np.inf)), ValueError, "non-finite"),
    (lambda: edges.diagonal_depth(np.zeros((3, 3), complex)), TypeError, "real"),
    (lambda: edges.diagonal_depth("abc"), TypeError, "depth"),
    (lambda: edges.diagonal_depth(np.zeros((3, 3)), order=3), ValueError, "order"),
    (lambda: edges.c1_depth(np.zeros((3, 3)), scale="12"), ValueError, "scale"),
    (lambda: edges.diagonal_normal(np.zeros((4, 4))), ValueError, "normal must have shape"),
    (lambda: edges.diagonal_normal(np.zeros((4, 4, 3)), encoded=1), TypeError, "encoded"),
    (lambda: edges.sobel(np.zeros((3, 3)), axis=2), ValueError, "axis"),
    (lambda: edges.sobel(np.zeros((3, 3, 3))), ValueError, "image"),
    (lambda: edges.sobel_normal(np.zeros((3, 3, 3)), form="cos"), ValueError, "form"),
    (lambda: edges.sobel_depth(np.zeros((3, 3)), k_z=-1), ValueError, "k_z"),
    (lambda: edges.object_id_edges(np.zeros((3, 3))), TypeError, "ids"),
    (lambda: edges.object_id_edges(np.zeros(3, int)), ValueError, "ids"),
])
def test_bad_filter_inputs(call, exc, words):
    with pytest.raises(exc, match=words):
        call()


def _gb(h=5, w=6):
    return edges.EdgeGBuffer(normal=np.full((h, w, 3), 0.5, np.float32),
                             depth=np.ones((h, w), np.float32),
                             object_id=np.full((h, w), -1, np.int32), near=0.0, far=1.0)


@pytest.mark.parametrize("kwargs, exc, words", [
    (dict(inner_threshold=1.5), ValueError, "inner_threshold"),
    (dict(profile_threshold=-0.1), ValueError, "profile_threshold"),
    (dict(profile_threshold=float("nan")), ValueError, "profile_threshold"),
    (dict(inner_threshold="0.1"), TypeError, "inner_threshold"),
    (dict(width=0), ValueError, "width"),
    (dict(width=1.5), TypeError, "width"),
    (dict(normal_filter="canny"), ValueError, "normal_filter"),
    (dict(depth_filter="laplace"), ValueError, "depth_filter"),
    (dict(ids="yes"), TypeError, "ids"),
    (dict(preset="gpu"), ValueError, "preset"),
    (dict(preset=None), TypeError, "preset"),
    (dict(near=1.0, far=2.0), ValueError, "EdgeGBuffer"),
])
def test_bad_edge_map_inputs(kwargs, exc, words):
    with pytest.raises(exc, match=words):
        edges.edge_map(_gb(), **kwargs)


def test_bad_gbuffer_inputs():
    fb = _torus_fb()
    with pytest.raises(ValueError, match="both near and far"):
        edges.edge_gbuffer(fb, near=1.0)
    with pytest.raises(ValueError, match="far must be greater"):
        edges.edge_gbuffer(fb, near=2.0, far=1.0)
    with pytest.raises(ValueError, match="not both"):
        edges.edge_gbuffer(fb, near=1.0, far=2.0, bounds=[[0, 0, 0], [1, 1, 1]])
    with pytest.raises(ValueError, match="bounds"):
        edges.edge_gbuffer(fb, bounds=[[1, 1, 1], [0, 0, 0]])
    with pytest.raises(ValueError, match="bounds"):
        edges.edge_gbuffer(fb, bounds=[[0, 0, 0], [1, np.nan, 1]])
    with pytest.raises(TypeError, match="Framebuffer"):
        edges.edge_gbuffer(np.zeros((3, 3)))
    bad = edges.EdgeGBuffer(normal=np.full((4, 4, 3), 0.5, np.float32),
                            depth=np.ones((4, 5), np.float32),
                            object_id=np.zeros((4, 4), np.int32), near=0, far=1)
    with pytest.raises(ValueError, match="shapes differ"):
        edges.edge_map(bad)
    nan = edges.EdgeGBuffer(normal=np.full((4, 4, 3), np.nan, np.float32),
                            depth=np.ones((4, 4), np.float32),
                            object_id=np.zeros((4, 4), np.int32), near=0, far=1)
    with pytest.raises(ValueError, match="non-finite"):
        edges.edge_map(nan)


def test_bad_classify_inputs():
    box = trimesh.creation.box()
    view = rf.look_at([3.0, 2.5, 2.0], [0, 0, 0])
    with pytest.raises(ValueError, match="crease_angle"):
        edges.classify_edges(box, view=view, crease_angle=200)
    with pytest.raises(ValueError, match="view"):
        edges.classify_edges(box, view=np.eye(3))
    with pytest.raises(ValueError, match="singular"):
        edges.classify_edges(box, view=view, model=np.zeros((4, 4)))
    with pytest.raises(ValueError, match="faces"):
        edges.classify_edges((box.vertices, box.faces + 100), view=view)
    with pytest.raises(TypeError, match="mesh"):
        edges.classify_edges("box", view=view)


# ---------------------------------------------------------------- determinism

_SCRIPT = r"""
import hashlib, sys
import numpy as np
from refraster import edges
rng = np.random.default_rng(11)
n = rng.normal(size=(67, 91, 3)).astype(np.float32)
z = rng.random((67, 91)).astype(np.float32)
ids = rng.integers(-1, 4, (67, 91)).astype(np.int32)
gb = edges.EdgeGBuffer(normal=np.float32(0.5) * n + np.float32(0.5), depth=z,
                       object_id=ids, near=0.0, far=1.0)
h = hashlib.sha256()
for nf in ("diagonal", "sobel", "angle"):
    for zf in ("diagonal2", "diagonal", "c1", "c1-paper", "sobel"):
        h.update(edges.edge_map(gb, normal_filter=nf, depth_filter=zf).tobytes())
h.update(edges.sobel(z).tobytes())
h.update(edges.object_id_edges(ids).tobytes())
print(h.hexdigest())
"""


def test_deterministic_across_runs_and_thread_counts():
    digests = set(outputs_by_thread_count(_SCRIPT))
    assert len(digests) == 1


def _twin_signatures(module):
    """Signatures of the module's kernels and helpers that carry a uint64 index or a literal:
    the second specialisations issue 27 removed (each compiles the helper once more)."""
    from numba.core.registry import CPUDispatcher
    bad = []
    for name, f in vars(module).items():
        if isinstance(f, CPUDispatcher):
            bad += [(name, s) for s in f.signatures if "uint64" in str(s) or "Literal" in str(s)]
    return bad


def test_edge_helpers_compile_one_specialisation_per_array_type():
    """Every operator through the fused map and the single filters: no helper is compiled for
    a uint64 row index (the parallel loop body's) or a literal order / channel besides the
    int64 one (docs/performance.md, "The first run"). The cutaway's exact search likewise."""
    from refraster.cutaway import exact, flood
    from refraster.edges import operators
    rng = np.random.default_rng(5)
    n = rng.random((9, 11, 3)).astype(np.float32)
    z = rng.random((9, 11)).astype(np.float32)
    ids = rng.integers(-1, 3, (9, 11)).astype(np.int32)
    gb = edges.EdgeGBuffer(normal=n, depth=z, object_id=ids, near=0.0, far=1.0)
    for nf in ("diagonal", "sobel", "angle"):
        for zf in ("diagonal", "diagonal2", "c1", "c1-paper", "sobel"):
            edges.edge_map(gb, normal_filter=nf, depth_filter=zf, ids=True)
    edges.diagonal_depth(z, order=2)
    edges.sobel_normal(n)
    seed = np.full((9, 11), -np.inf)
    seed[4, 5] = 0.5
    exact(seed, 0.3)
    # a kernel loaded from the cache does not type its helpers: compile fresh, uncached copies
    # of the fused map and the exact search so that every helper they call is typed here
    import numba
    from refraster._config import PJIT
    fresh = dict(PJIT, cache=False)
    out = np.zeros((9, 11, 4), np.float32)
    numba.njit(**fresh)(operators._edge_map_kernel.py_func)(
        n, z, ids, True, 0, 4, False, 1.0, 1.0, np.float32(0.0), np.float32(0.0), out)
    zs, params, sy, sx = flood._prepare(seed, 0.3, 1.0, None, None)
    records, directional = flood._records(params, zs.shape[1])
    numba.njit(**fresh)(flood._exact.py_func)(
        np.flatnonzero(zs > -np.inf).astype(np.int32), np.full(zs.shape, -1, np.int32),
        np.full(zs.shape, -np.inf), records, sy, sx, directional)
    assert _twin_signatures(operators) == []
    assert _twin_signatures(flood) == []
