"""Hand-worked cases that kill the mutants the rest of the suite let through (issue 30).

Each expected value here is derived by hand from the paper's definition or from MATH.md, not
from the implementation or a twin of it; docs/testing.md lists which mutant each test kills.
"""

import numpy as np
import pytest

import refraster as rr
from refraster.clipsurface import offsetmaps
from refraster.clipsurface.capping import light_caps
from refraster.clipsurface import ClipSurface
from refraster.cutaway.flood import exact, jump_flood, step_schedule

# ------------------------------------------------------------------ jump flooding (MATH.md D-C5)


@pytest.mark.parametrize("h, w, expected", [
    (100, 60, [64, 32, 16, 8, 4, 2, 1]),   # n = 128: the first jump is n/2
    (64, 64, [32, 16, 8, 4, 2, 1]),        # n = 64 exactly
    (65, 3, [64, 32, 16, 8, 4, 2, 1]),
    (2, 1, [1]),
])
def test_jump_schedule_is_half_the_next_power_of_two_down_to_one(h, w, expected):
    """Rong & Tan's schedule: n/2, n/4, …, 1 with n the next power of two ≥ max(H, W)."""
    assert step_schedule(h, w, "jfa") == expected
    assert step_schedule(h, w, "jfa+1") == expected + [1]
    assert step_schedule(h, w, "jfa+2") == expected + [2, 1]
    assert step_schedule(h, w, "1+jfa") == [1] + expected


def test_far_seed_reached_only_through_the_longest_jump():
    """One seed in the corner of a 1×64 strip, slope 0: D = z everywhere. The jumps 32, 16, …, 1
    reach every pixel; starting at 16 the far end (63 = 32 + 16 + 8 + 4 + 2 + 1 from 0, more
    than 16 + 8 + 4 + 2 + 1 = 31) stays without a seed."""
    z = np.full((1, 64), -np.inf)
    z[0, 0] = 0.25
    d, seeds = jump_flood(z, 0.0, return_seeds=True)
    assert np.all(d == 0.25)
    assert np.all(seeds[0, :, 1] == 0)


@pytest.mark.parametrize("method", ["jump_flood", "exact"])
def test_equidistant_seeds_tie_to_the_smaller_index(method):
    """Two seeds of equal depth and slope at (2, 0) and (2, 4) of a 5×5 image: the middle
    column is equidistant from both, so C is equal and the documented tie rule (the smaller
    row-major index) picks (2, 0) there; elsewhere the nearer seed wins."""
    z = np.full((5, 5), -np.inf)
    z[2, 0] = z[2, 4] = 0.0
    f = jump_flood if method == "jump_flood" else exact
    d, seeds = f(z, 1.0, return_seeds=True)
    assert np.all(seeds[:, 2] == [2, 0])
    assert np.all(seeds[:, :2] == [2, 0]) and np.all(seeds[:, 3:] == [2, 4])
    # C at the tie: z − m·‖x − s‖ with ‖(r, 2) − (2, 0)‖ = hypot(r − 2, 2)
    np.testing.assert_allclose(d[:, 2], -np.hypot(np.arange(5) - 2, 2.0), rtol=0, atol=0)


@pytest.mark.parametrize("method", ["jump_flood", "exact"])
def test_floor_constraint_applies_below_the_seed(method):
    """D-C7 by hand: the floor slope m_f applies toward the floor side, i.e. against the
    projected floor normal n̂ (a screen direction, y up). One seed at the centre of a 7×7 image,
    z = 0, m_e = 1, m_f = 0, n̂ = (0, 1) (up): a = −(d_screen · n̂)/‖d‖. Three rows *below* the
    seed (screen direction (0, −1)) a = 1, m = m_f = 0, so D = 0; three rows above a = −1 < 0,
    m = m_e, D = −3; three columns right a = 0, D = −3; diagonal below-right a = 1/√2,
    m = (1 − a)·1, D = −(1 − 1/√2)·3√2 = −(3√2 − 3)."""
    z = np.full((7, 7), -np.inf)
    z[3, 3] = 0.0
    floor_slope = np.zeros((7, 7))
    normal = np.zeros((7, 7, 2))
    normal[..., 1] = 1.0
    f = jump_flood if method == "jump_flood" else exact
    d = f(z, 1.0, floor_slope=floor_slope, floor_normal=normal)
    assert d[6, 3] == 0.0          # below
    assert d[0, 3] == -3.0         # above
    assert d[3, 6] == -3.0 and d[3, 0] == -3.0
    assert d[6, 6] == pytest.approx(-(3.0 * np.sqrt(2.0) - 3.0), abs=1e-12)
    assert d[0, 0] == pytest.approx(-3.0 * np.sqrt(2.0), abs=1e-12)


# ------------------------------------------------------------------ cap lighting (Sec. 4.2)

def _plane_x0():
    """The plane x = 0 with Û = +y, V̂ = +z, so N = Û × V̂ = +x, and a flat (constant) offset
    map."""
    return ClipSurface((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0),
                       offset_map=offsetmaps.constant((8, 8), 0.5))


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_cap_normal_and_shade_of_a_flat_cap_face_on(side):
    """A flat cap seen face on, from either side. Its normal is oriented towards −N, the side
    from which the cut is seen (MATH.md §1.2b: a flat map gives (0, 0, −1) in (Û, V̂, N)), so
    in world space it is −x; a camera at (3·side, 0, 0) looking at the origin sees it as
    (0, 0, −side) in eye space (eye space looks down −Z), and the shade
    occlusion·(0.25 + 0.75·|n·v|) is 1 (no occlusion on a flat map, |n·v| = 1 from both
    sides)."""
    view = rr.look_at((3.0 * side, 0.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0))
    normal, shade = light_caps(np.zeros((1, 3)), np.zeros(1, np.int64), [_plane_x0()], view=view)
    np.testing.assert_allclose(normal[0], [0.0, 0.0, -side], atol=1e-12)
    assert shade[0] == pytest.approx(1.0, abs=1e-12)


def test_cap_shade_at_grazing_angle():
    """From (1, 0, 1)·3/√2 the view direction makes 45° with N = +x: |n·v| = 1/√2 and the shade
    is 0.25 + 0.75/√2."""
    eye = np.array([1.0, 0.0, 1.0]) * 3.0 / np.sqrt(2.0)
    view = rr.look_at(eye, (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
    _, shade = light_caps(np.zeros((1, 3)), np.zeros(1, np.int64), [_plane_x0()], view=view)
    assert shade[0] == pytest.approx(0.25 + 0.75 / np.sqrt(2.0), abs=1e-12)


# ------------------------------------------------------------------ 4D halos: slice opacity

def test_slice_alpha_accumulates_to_the_opacity_across_the_core():
    """The core |2t − 1| < w_s spans w_s of t ∈ [0, 1], i.e. 2·w_s·ρ of the 2ρ-thick halo. With
    slices Δz apart, n = 2·w_s·ρ/Δz slices cross it and 1 − (1 − α)^n must equal the opacity:
    one slice per core thickness gives α = opacity, two give α = 1 − √(1 − opacity)."""
    from refraster.halos4d.render import slice_alpha
    rho, ws = 0.1, 0.3
    assert slice_alpha(0.5, 2 * ws * rho, rho, ws) == pytest.approx(0.5, abs=1e-15)
    assert slice_alpha(0.5, ws * rho, rho, ws) == pytest.approx(1 - np.sqrt(0.5), abs=1e-15)
    assert slice_alpha(1.0, ws * rho, rho, ws) == 1.0


# ------------------------------------------------------------------ golden allowances

def test_surface_step_ignores_steps_across_surfaces():
    """surface_step is the largest change to a 4-neighbour *on the same surface*: a jump of 10
    between two surfaces is a silhouette, not a slope, and must not widen the allowance."""
    from refraster.golden.allowance import surface_step
    values = np.array([[0.0, 10.0, 11.0]])
    assert surface_step(values, np.array([[0, 1, 1]])).tolist() == [[0.0, 1.0, 1.0]]
    assert surface_step(values, np.array([[0, 0, 0]])).tolist() == [[10.0, 10.0, 1.0]]
    assert surface_step(values, np.array([[-1, 1, 1]])).tolist() == [[0.0, 1.0, 1.0]]


# ------------------------------------------------------------------ raster: vertex snapping

def test_vertex_snapping_rounds_to_the_nearest_subpixel():
    """docs/architecture.md: X = rint((x_w − ½)·2^bits). On an 8×8 viewport (x_w = 4·x_ndc + 4,
    w = 1, all values dyadic, so float32 is exact): x_ndc = −509/4096 gives x_w = 3.5 + 0.75/256,
    X = rint(768.75) = 769; x_ndc = −0.875 − 1.25/1024 gives x_w = 0.5 − 1.25/256, X = rint(−1.25)
    = −1; y_ndc = 0.25/1024 gives y_w = 4 + 0.25/256, Y = rint(896.25) = 896. Truncating or
    flooring (768, −2, 896) moves the vertex by up to a whole sub-pixel step, always the same
    way."""
    from refraster.raster.primitive import setup_triangles
    clip = np.array([[-509 / 4096, 0.25 / 1024, 0.0, 1.0],
                     [-0.875 - 1.25 / 1024, 0.5, 0.0, 1.0],
                     [0.5, -0.5, 0.0, 1.0]])
    p = setup_triangles(clip, np.array([[0, 1, 2]]), 8, 8)
    assert p.vx[:2].tolist() == [769, -1]
    assert p.vy[0] == 896
    # x_w = 6, y_w = 2: exactly on pixel-centre multiples
    assert (p.vx[2], p.vy[2]) == ((6 * 256) - 128, (2 * 256) - 128)


# ------------------------------------------------------------------ raster: clipping

def test_clipped_vertex_exactly_on_a_later_plane_is_kept():
    """Sutherland–Hodgman keeps a vertex lying exactly on the plane (d = 0 is inside). Worked by
    hand on an 8×8 viewport, w = 1 everywhere (so clip space is NDC and the triangle is affine),
    guard band G = 2·2^20/8 = 2^18 NDC units: A = (2G + 0.875, 0, −2) is outside the near plane
    and the right guard plane; B = (−0.875, 0, 0) and C = (−1, G/2, 0) are inside. The near
    plane cuts AB at its midpoint P = (G, 0, −1), which lies exactly on the right guard plane
    (x = G), and CA at Q = (G − 1/16, G/4, −1), inside it. After the near plane the polygon is
    P, B, C, Q, entirely inside the guard plane; dropping P (a `>` test) loses the wedge P, B, Q,
    which covers most of the viewport's upper right. The expected coverage is the triangle's
    own: pixel centres with all barycentrics ≥ 0 and z_ndc ≥ −1 (pixels within 0.01 px of an
    edge are not compared)."""
    from refraster.raster.primitive import setup_triangles
    from refraster.raster.rasterizer import fused
    g = 2.0 ** 18
    tri = np.array([[2 * g + 0.875, 0.0, -2.0, 1.0], [-0.875, 0.0, 0.0, 1.0],
                    [-1.0, g / 2, 0.0, 1.0]])
    _, prim, _, _ = fused(setup_triangles(tri, np.array([[0, 1, 2]]), 8, 8))
    a, b, c = tri[:, :2]
    compared = 0
    for row in range(8):
        for col in range(8):
            p = np.array([(col + 0.5) / 4 - 1, 1 - (row + 0.5) / 4])
            dist = []   # signed distance in pixels to each edge (one sign inside: ABC is CW)
            for u, v in ((a, b), (b, c), (c, a)):
                e = v - u
                dist.append(4 * (e[0] * (p[1] - u[1]) - e[1] * (p[0] - u[0])) / np.hypot(*e))
            if min(abs(x) for x in dist) < 0.01:
                continue
            lam_a = dist[1] / (4 * (((c - b)[0] * (a - b)[1] - (c - b)[1] * (a - b)[0]))
                               / np.hypot(*(c - b)))
            inside = max(dist) < 0 and -2.0 * lam_a >= -1.0
            assert (prim[row, col] == 0) == inside, (row, col)
            compared += 1
    assert compared >= 56
    assert prim[3, 6] == 0 and prim[0, 7] == 0 and prim[7, 7] == -1


# ------------------------------------------------------------------ offset maps: GL_LINEAR

_ROW = np.array([[0.1, 0.2, 0.3, 0.4]])   # a 1×4 map, in [0, 1]


def _at(s, wrap):
    return offsetmaps.sample(_ROW, np.column_stack([s, np.full(len(s), 0.5)]), wrap=wrap)


@pytest.mark.parametrize("wrap, table", [
    ("repeat", [0, 1, 2, 3, 0, 1, 2, 3]),
    ("mirrored_repeat", [0, 1, 2, 3, 3, 2, 1, 0]),   # mirrored about the texels' edges
    ("clamp_to_edge", None),
])
def test_texel_centres_return_the_texel_under_each_wrap_mode(wrap, table):
    """OpenGL 4.6 §8.14.2 and Table 8.20 by hand: at the centre of texel i, s = (i + ½)/W, the
    filter weight α = frac(s·W − ½) is 0, so GL_LINEAR returns texel wrap(i) exactly; over
    i = −8 … 11 that is i mod 4 (repeat), the period-8 table 0 1 2 3 3 2 1 0 (mirrored repeat)
    and min(max(i, 0), 3) (clamp)."""
    i = np.arange(-8, 12)
    got = _at((i + 0.5) / 4, wrap)
    idx = (np.array(table)[i % 8] if table is not None else np.clip(i, 0, 3))
    np.testing.assert_array_equal(got, _ROW[0, idx])


def test_halfway_between_texels_and_across_the_repeat_seam():
    """At a texel edge, s = i/W, α = ½: the mean of texels i − 1 and i; at s = 0 and s = 1
    under repeat those are the last and the first texel (the seam wraps, it does not clamp);
    under clamp_to_edge s = 1 gives the last texel."""
    np.testing.assert_allclose(_at(np.array([0.25, 0.5, 0.75]), "repeat"), [0.15, 0.25, 0.35],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(_at(np.array([0.0, 1.0, 2.0]), "repeat"), [0.25, 0.25, 0.25],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(_at(np.array([1.0, 0.0]), "clamp_to_edge"), [0.4, 0.1],
                               rtol=0, atol=1e-15)


def test_clipping_an_edge_to_a_vertex_at_1e30_is_exact():
    """A triangle with one vertex 10^30 away behind the near plane, worked by hand: w = 1
    everywhere, B = (−½, −½, 0), C = (−½, ½, 0), A = B + s·(1, 0, −1) with s = 10^30. z is
    affine in x (z = −(x + ½)), so the part in front of the near plane (z ≥ −1) is x ≤ ½: up
    to a sliver of 10^−30 the visible polygon is the square [−½, ½]², which on an 8×8 viewport
    covers exactly the pixels whose centres are ±1/8, ±3/8: rows and columns 2 … 5 (no centre
    is within half a pixel of an edge). Interpolating the new vertices from the 10^30 endpoint
    instead of the near one leaves them nowhere near x = ½."""
    from refraster.raster.primitive import setup_triangles
    from refraster.raster.rasterizer import fused
    s = 1e30
    tri = np.array([[-0.5 + s, -0.5, -s, 1.0], [-0.5, -0.5, 0.0, 1.0], [-0.5, 0.5, 0.0, 1.0]])
    _, prim, _, _ = fused(setup_triangles(tri, np.array([[0, 1, 2]]), 8, 8))
    expected = np.full((8, 8), -1)
    expected[2:6, 2:6] = 0
    np.testing.assert_array_equal(prim, expected)


# ------------------------------------------------------------------ clip surfaces: g(P) < 0

def test_clip_mask_of_two_surfaces_by_hand():
    """MATH.md §1.1, clipped ⇔ some enabled surface has g(P) = N·(P − O) + Sz·OM(s, t) < 0,
    each surface with its own Sz. Surface 0: the plane z = 0 (Û = x, V̂ = y, N = +z), Sz = 0;
    surface 1: the plane x = 0 (Û = y, V̂ = z, N = +x), Sz = 1, a constant map of ½, so
    g1 = x + ½. (−¼, 0, 1): g0 = 1, g1 = ¼, kept; (−¾, 0, 1): g1 = −¼, clipped; (0.1, 0, −0.1):
    g0 = −0.1, clipped; (−½, 0, 1): g1 = 0 exactly, kept (only g < 0 discards)."""
    from refraster.clipsurface import clip_function, clip_mask
    half = offsetmaps.constant((4, 4), 0.5)
    s0 = ClipSurface((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.0), half)
    s1 = ClipSurface((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 1.0), half)
    pts = np.array([[-0.25, 0.0, 1.0], [-0.75, 0.0, 1.0], [0.1, 0.0, -0.1], [-0.5, 0.0, 1.0]])
    np.testing.assert_allclose(clip_function(pts, s1), pts[:, 0] + 0.5, rtol=0, atol=1e-15)
    assert clip_mask(pts, [s0, s1]).tolist() == [False, True, True, False]
    assert clip_mask(pts, [s1, s0]).tolist() == [False, True, True, False]


# ------------------------------------------------------------------ volumetric depth sprites

@pytest.mark.parametrize("rule", ["parity", "nonzero"])
def test_sprite_of_two_cubes_diagonal_from_each_other(rule):
    """Two unit cubes, [0, 1]×[0, 1]×[0, 1] and [2, 3]×[2, 3]×[0, 1], in one sprite along z: the
    texture's s runs with x and t with y (row 0 of the LDI at the top, t = 1). Their centres are
    inside; the other two corners of the diagonal, (½, 2½, ½) and (2½, ½, ½), are outside. A
    lookup that mirrors t (or s) swaps the two answers."""
    from refraster.ldi import VolumetricDepthSprite
    from refraster.scenes import cube
    c = cube(1.0)
    v0 = np.asarray(c.vertices) + 0.5
    verts = np.concatenate([v0, v0 + [2.0, 2.0, 0.0]])
    faces = np.concatenate([np.asarray(c.faces), np.asarray(c.faces) + len(v0)])
    sprite = VolumetricDepthSprite.from_mesh((verts, faces), resolution=32, axis="z")
    pts = np.array([[0.5, 0.5, 0.5], [2.5, 2.5, 0.5], [0.5, 2.5, 0.5], [2.5, 0.5, 0.5]])
    assert sprite.contains(pts, rule=rule).tolist() == [True, True, False, False]
