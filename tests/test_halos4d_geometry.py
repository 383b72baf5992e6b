"""4D surfaces, rotations, projection, thickening and the prism split (Wang et al.; MATH.md §5)."""

import importlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import refraster.halos4d as h
from refraster.halos4d.surfaces import Surface4D


def as_complex(v):
    return v[:, 0] + 1j * v[:, 1], v[:, 2] + 1j * v[:, 3]


# ----------------------------------------------------------------------------- surfaces
@pytest.mark.parametrize("n", [2, 3, 4])
def test_fermat_satisfies_its_equation(n):
    s = h.fermat_surface(n, 12, 12)
    z1, z2 = as_complex(s.vertices)
    err = np.abs(z1 ** n + z2 ** n - 1.0)
    assert err.max() < 1e-10
    assert s.n_faces == n * n * 2 * 11 * 11


def test_calabi_yau_has_16_patches_and_quadratic_fermat_4():
    assert h.calabi_yau_quartic(4, 4).n_vertices == 16 * 16
    assert h.quadratic_fermat(4, 4).n_vertices == 4 * 16


def test_product_polynomial_equation_and_components():
    s = h.product_polynomial(8, 16)
    z1, z2 = as_complex(s.vertices)
    assert np.abs(z1 ** 2 * z2 ** 2 - 1.0).max() < 1e-10
    prod = z1 * z2
    # the two cylinders z1 z2 = ±1, half the vertices each
    assert np.count_nonzero(np.abs(prod - 1) < 1e-10) == s.n_vertices // 2
    assert np.count_nonzero(np.abs(prod + 1) < 1e-10) == s.n_vertices // 2


def test_fermat_cosh_variant_would_fail():
    """MATH.md §5.7: the cosh/sinh copies satisfy z1ⁿ − z2ⁿ = 1, not the Fermat equation."""
    zeta = 0.3 + 0.7j
    z1, z2 = np.cosh(zeta) ** (2 / 3), np.sinh(zeta) ** (2 / 3)
    assert abs(z1 ** 3 + z2 ** 3 - 1) > 1e-3


def test_tangents_match_analytic_derivative():
    """Fermat n = 2, patch (0, 0): z1 = cos ζ, z2 = sin ζ, so ∂/∂x = (−sin ζ, cos ζ)."""
    s = h.fermat_surface(2, 9, 9)
    k = 40                                             # interior vertex of the first patch
    z1, z2 = as_complex(s.vertices[k:k + 1])
    zeta = np.arccos(z1[0])
    want = np.array([(-np.sin(zeta)).real, (-np.sin(zeta)).imag,
                     np.cos(zeta).real, np.cos(zeta).imag])
    np.testing.assert_allclose(s.tangents[k, 0], want, atol=1e-6)
    # holomorphic: ∂/∂y = i ∂/∂x
    iwant = np.array([-want[1], want[0], -want[3], want[2]])
    np.testing.assert_allclose(s.tangents[k, 1], iwant, atol=1e-6)


# the knots (closed orientable embedded spheres, three crossings): tests/test_halos4d_knots.py


def test_adaptive_sampling_densifies_where_curved():
    def func(u, v):      # a parabola cylinder: curvature concentrated near u = 0
        return np.stack([u, 20 * u * u, v, 0 * u], axis=-1)
    s = h.uv_surface(func, (-1, 1), (0, 1), 21, 3, adaptive=True)
    us = s.vertices[::3, 0]
    du = np.diff(us)
    assert du[len(du) // 2] < 0.6 * du[0]
    assert np.all(du > 0)
    u = h.uv_surface(func, (-1, 1), (0, 1), 21, 3)
    np.testing.assert_allclose(np.diff(u.vertices[::3, 0]), 0.1)


def test_figure1_scene_layout():
    s = h.figure1_scene(6)
    w = np.unique(np.round(s.vertices[:, 3], 12))
    np.testing.assert_allclose(w, [0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    white = np.all(s.colors == 1.0, axis=1)
    assert np.all(s.vertices[white, 3] == 0.0)


def test_surface_bad_inputs():
    with pytest.raises(ValueError, match="non-finite"):
        Surface4D(np.full((3, 4), np.nan), [[0, 1, 2]], np.zeros((3, 2, 4)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="faces"):
        Surface4D(np.zeros((3, 4)), [[0, 1, 3]], np.zeros((3, 2, 4)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="nu"):
        h.spun_trefoil(1, 8)
    with pytest.raises(ValueError, match="n must"):
        h.fermat_surface(1)
    with pytest.raises(ValueError, match="a must"):
        h.quadratic_fermat(4, 4, a=float("nan"))
    with pytest.raises(ValueError, match="w_values"):
        h.figure1_scene(4, w_values=[])


# ----------------------------------------------------------------------------- rotations
@pytest.mark.parametrize("plane", list(h.PLANES))
def test_rotation_orthonormal_and_det_one(plane):
    r = h.rotation(plane, 0.7)
    np.testing.assert_allclose(r @ r.T, np.eye(4), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from(list(h.PLANES)), st.floats(-7, 7), st.floats(-7, 7))
def test_rotations_compose(plane, a, b):
    np.testing.assert_allclose(h.rotation(plane, a) @ h.rotation(plane, b),
                               h.rotation(plane, a + b), atol=1e-12)
    np.testing.assert_allclose(h.compose((plane, a), (plane, b)), h.rotation(plane, a + b),
                               atol=1e-12)


def test_compose_order():
    a, b = h.rotation("xy", 0.3), h.rotation("zw", 1.1)
    np.testing.assert_allclose(h.compose(a, b), b @ a)
    np.testing.assert_allclose(h.compose(("xy", 0.3), ("zw", 1.1)), b @ a)


def test_xw_quarter_turn_swaps_x_and_w():
    r = h.rotation("xw", np.pi / 2)
    np.testing.assert_allclose(r @ [1, 0, 0, 0], [0, 0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(r @ [0, 0, 0, 1], [-1, 0, 0, 0], atol=1e-15)
    # the 4D depth of a point becomes (minus) its former x: x and w trade roles
    v = np.array([[0.3, 0.2, 0.1, 0.0]])
    pr = h.project(v, np.zeros((1, 2, 4)), r, eye=2.0)
    assert pr.depth[0] == pytest.approx(2.0 - 0.3)
    np.testing.assert_allclose(pr.points[0], [0.0, 0.2, 0.1], atol=1e-15)


def test_hanson_view():
    r = h.hanson_view(0.4)
    np.testing.assert_allclose(r @ r.T, np.eye(4), atol=1e-15)
    assert np.linalg.det(r) == pytest.approx(1.0)
    z = np.array([1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose((r @ z)[:3], [1.0, 3.0, np.cos(0.4) * 2 + np.sin(0.4) * 4])


def test_rotation_bad_inputs():
    with pytest.raises(ValueError, match="plane"):
        h.rotation("xq", 1.0)
    with pytest.raises(ValueError, match="angle"):
        h.rotation("xy", float("nan"))
    with pytest.raises(ValueError, match="orthogonal"):
        h.project(np.zeros((1, 4)), np.zeros((1, 2, 4)), 2 * np.eye(4))


# ----------------------------------------------------------------------------- projection
def test_perspective_projection_and_tangents_by_differences():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(20, 4)) * 0.5
    t = rng.normal(size=(20, 2, 4))
    pr = h.project(v, t, projection="perspective", eye=4.0, scale=2.0)
    f = 2.0 * 4.0
    np.testing.assert_allclose(pr.points, f * v[:, :3] / (4.0 - v[:, 3:]), rtol=1e-14)
    np.testing.assert_allclose(pr.depth, 4.0 - v[:, 3])
    eps = 1e-6
    for k in range(2):
        plus = h.project(v + eps * t[:, k], t, projection="perspective", eye=4.0, scale=2.0)
        minus = h.project(v - eps * t[:, k], t, projection="perspective", eye=4.0, scale=2.0)
        np.testing.assert_allclose(pr.tangents[:, k], (plus.points - minus.points) / (2 * eps),
                                   rtol=1e-6, atol=1e-6)
    ortho = h.project(v, t, scale=3.0)
    np.testing.assert_allclose(ortho.tangents, 3.0 * t[..., :3])


def test_perspective_behind_eye_is_an_error():
    with pytest.raises(ValueError, match="behind the 4D eye"):
        h.project(np.array([[0, 0, 0, 2.0]]), np.zeros((1, 2, 4)), projection="perspective",
                  eye=1.5)


# ----------------------------------------------------------------------------- thickening
def test_thickening_normals_unit_and_fallback():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    t = np.array([[[2, 0, 0], [0, 3, 0]], [[1, 0, 0], [0, 1, 0]], [[0, 0, 0], [0, 1, 0.0]]])
    n, fb = h.thickening_normals(p, t, [[0, 1, 2]])
    np.testing.assert_allclose(n, [[0, 0, 1]] * 3)
    assert fb == 1                     # the zero tangent: face-normal fallback
    # parallel tangents (edge-on) fall back as well
    t2 = np.array([[[1, 0, 0], [2, 0, 1e-9]]] * 3)
    n2, fb2 = h.thickening_normals(p, t2, [[0, 2, 1]])
    assert fb2 == 3
    np.testing.assert_allclose(n2, [[0, 0, -1]] * 3)


def test_fallback_normal_sums_only_the_faces_at_its_vertices_with_the_whole_sums_bits():
    # the fallback sums the area-weighted normals of the faces around each vertex that needs
    # it; only those faces are visited, in face order for each corner in turn, as a sum over
    # all faces would add them (np.add.at): compared with that sum written out, bit for bit
    tk = importlib.import_module("refraster.halos4d.thicken")
    rng = np.random.default_rng(3)
    p = rng.normal(size=(60, 3))
    f = np.array([rng.choice(60, 3, replace=False) for _ in range(400)])
    which = np.zeros(60, bool)
    which[rng.choice(60, 9, replace=False)] = True
    full = np.zeros_like(p)
    for k in range(3):
        for face in f:
            full[face[k]] += np.cross(p[face[1]] - p[face[0]], p[face[2]] - p[face[0]])
    got = tk._face_normal_sum(p, f, which)
    assert np.array_equal(got[which], full[which])


def test_thicken_offsets():
    p = np.zeros((2, 3))
    n = np.array([[0, 0, 1.0], [1.0, 0, 0]])
    v, t = h.thicken(p, n, 0.25)
    np.testing.assert_allclose(v, [[0, 0, -0.25], [-0.25, 0, 0], [0, 0, 0.25], [0.25, 0, 0]])
    np.testing.assert_array_equal(t, [0, 0, 1, 1])
    with pytest.raises(ValueError, match="rho"):
        h.thicken(p, n, 0.0)


def test_halo_depth_eq3():
    # d_new = d + max(0, |2t − 1| − δt)·δd
    np.testing.assert_allclose(h.halo_depth([1.0, 1.0, 1.0, 1.0], [0.5, 0.6, 1.0, 0.0], 0.3, 2.0),
                               [1.0, 1.0, 1.0 + 0.7 * 2, 1.0 + 0.7 * 2])
    with pytest.raises(ValueError, match="delta_t"):
        h.halo_depth([1.0], [0.5], 1.5, 1.0)


# ----------------------------------------------------------------------------- prism split
def _random_triangulation(rng, n=40):
    from scipy.spatial import Delaunay
    pts = rng.random((n, 2))
    return pts, Delaunay(pts).simplices.astype(np.int64)


def _quad_diagonals(tets, n):
    """Map each quad side {i, j} (bottom indices) to the diagonal its prism uses."""
    out = {}
    for f in range(len(tets) // 3):
        edges = set()
        for tet in tets[3 * f:3 * f + 3]:
            for a in tet:
                for b in tet:
                    if a < n <= b and b - n != a:
                        edges.add((a, b - n))
        for a, b in edges:
            out.setdefault((f, frozenset((a, b))), (a, b))
    return out


def test_prism_split_is_conforming_for_random_numberings():
    rng = np.random.default_rng(0)
    pts, faces = _random_triangulation(rng)
    n = len(pts)
    for _ in range(100):
        perm = rng.permutation(n)
        f = perm[faces]
        tets = h.prism_tetrahedra(f, n)
        diag = _quad_diagonals(tets, n)
        by_quad = {}
        for (fi, quad), d in diag.items():
            by_quad.setdefault(quad, set()).add(d)
        # every quad gets exactly one diagonal, whichever prism produced it
        assert all(len(v) == 1 for v in by_quad.values())
        # and every prism has 3 diagonals (one per side): never the cyclic pattern
        per_face = {}
        for (fi, quad) in diag:
            per_face[fi] = per_face.get(fi, 0) + 1
        assert set(per_face.values()) == {3}


def _signed_volumes(v, tets):
    a = v[tets[:, 0]]
    return np.einsum("ij,ij->i", np.cross(v[tets[:, 1]] - a, v[tets[:, 2]] - a),
                     v[tets[:, 3]] - a) / 6.0


def test_straight_prisms_positive_volumes_sum_to_prism():
    rng = np.random.default_rng(3)
    pts, faces = _random_triangulation(rng, 30)
    n = len(pts)
    for _ in range(20):
        perm = rng.permutation(n)
        f = perm[faces]
        base = np.zeros((n, 3))
        base[perm, :2] = pts
        # orient faces counter-clockwise so their normal is +z
        a, b, c = base[f[:, 0]], base[f[:, 1]], base[f[:, 2]]
        cw = np.cross(b - a, c - a)[:, 2] < 0
        f[cw] = f[cw][:, [0, 2, 1]]
        h_ = 0.3
        v = np.concatenate([base, base + [0, 0, h_]])
        tets = h.prism_tetrahedra(f, n)
        vol = _signed_volumes(v, tets)
        assert vol.min() > 0
        area = 0.5 * np.abs(np.cross(b - a, c - a)[:, 2])
        np.testing.assert_allclose(vol.reshape(-1, 3).sum(axis=1), area * h_, rtol=1e-12)


def test_prism_tetrahedra_hand_example():
    # face (2, 0, 1): sorted a, b, c = 0, 1, 2; n = 3
    t = h.prism_tetrahedra([[0, 1, 2]], 3)
    np.testing.assert_array_equal(t, [[0, 1, 2, 5], [0, 1, 5, 4], [0, 3, 4, 5]])


def test_prism_bad_inputs():
    with pytest.raises(ValueError, match="degenerate"):
        h.prism_tetrahedra([[0, 0, 1]], 3)
    with pytest.raises(ValueError, match="faces"):
        h.prism_tetrahedra([[0, 1, 5]], 3)
    with pytest.raises(TypeError, match="n_vertices"):
        h.prism_tetrahedra([[0, 1, 2]], 3.0)
