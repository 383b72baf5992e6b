"""The clip test of 2.5D clip surfaces and relief clip planes (MATH.md §1.1, D1–D8)."""


import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraster.clipsurface import offsetmaps as om
from refraster.camera import look_at
from refraster.clipsurface import ClipSurface, ReliefClipPlane, clip_function, clip_mask
from determinism import outputs_by_thread_count


def naive_g(p, surface):
    """Slow, obvious MATH.md §1.1, written from the formula with NumPy."""
    u, v = np.asarray(surface.u, float), np.asarray(surface.v, float)
    uh, vh = u / np.linalg.norm(u), v / np.linalg.norm(v)
    n = np.cross(uh, vh)
    n /= np.linalg.norm(n)
    o = np.asarray(surface.origin, float)
    pn = p - ((p - o) @ n)[:, None] * n  # Eq. 3 (redundant for s, t but spelled out)
    s = ((pn - o) @ uh / np.linalg.norm(u)) * surface.scale[0]
    t = ((pn - o) @ vh / np.linalg.norm(v)) * surface.scale[1]
    h = om.sample(surface.offset_map, np.stack([s, t], 1), wrap=surface.wrap)
    return (p - o) @ n + surface.scale[2] * h


def xy_surface(offset_map, sz=1.0, **kw):
    """Plane z = 0, U = 2x̂, V = 4ŷ, N = +z; kept material above."""
    return ClipSurface([0, 0, 0], [2, 0, 0], [0, 4, 0], (1, 1, sz), offset_map, **kw)


def test_hand_computed_points():
    # h = 0.25 everywhere, Sz = 0.4: the surface is z = −0.1; z < −0.1 is clipped
    cs = xy_surface(om.constant(3, 0.25), 0.4)
    p = np.array([[0.5, 0.5, 0.3],     # above
                  [0.5, 0.5, -0.3],    # below
                  [0.5, 0.5, -0.1],    # on the surface: g = 0, not clipped (strict <)
                  [7.0, -9.0, -0.05],  # outside [0,1]² of the map: repeat still applies
                  [7.0, -9.0, -0.15]])
    np.testing.assert_allclose(clip_function(p, cs), [0.4, -0.2, 0.0, 0.05, -0.05], atol=1e-15)
    np.testing.assert_array_equal(clip_mask(p, cs), [False, True, False, False, True])


def test_texcoords_and_clamp_outside_the_map():
    # map with h = 0 for s < ½ and h = 1 for s ≥ ½ (two texels); U = 2x̂ so s = x / 2
    m = np.array([[0.0, 1.0]])
    cs = xy_surface(m, 1.0, wrap="clamp_to_edge")
    np.testing.assert_allclose(cs.texcoords([[1.0, 2.0, 5.0]]), [[0.5, 0.5]])
    p = np.array([[0.5, 0, -0.5],   # s = 0.25: texel 0 centre, h = 0 → g = −0.5
                  [1.5, 0, -0.5],   # s = 0.75: h = 1 → g = 0.5
                  [1.0, 0, -0.5],   # s = 0.5: halfway → h = 0.5 → g = 0
                  [9.0, 0, -0.5],   # s = 4.5 clamps to the last texel: h = 1
                  [-9.0, 0, -0.5]])  # s < 0 clamps to texel 0: h = 0
    np.testing.assert_allclose(clip_function(p, cs), [-0.5, 0.5, 0.0, 0.5, -0.5])
    rep = cs.replace(wrap="repeat")
    # s = 4.5 under repeat is s = 0.5 → h = 0.5
    assert clip_function([[9.0, 0, -0.5]], rep)[0] == pytest.approx(0.0)


def test_several_surfaces_any_clips():
    a = xy_surface(om.constant(2, 0.0))                       # clips z < 0
    b = ClipSurface([0, 0, 0], [0, 1, 0], [0, 0, 1], (1, 1, 0), om.constant(2))  # N = x̂: x < 0
    p = np.array([[1, 0, 1], [-1, 0, 1], [1, 0, -1], [-1, 0, -1]], float)
    np.testing.assert_array_equal(clip_mask(p, [a, b]), [False, True, True, True])
    np.testing.assert_array_equal(clip_mask(p, [a, b.replace(enabled=False)]),
                                  [False, False, True, True])
    np.testing.assert_array_equal(clip_mask(p, [a, b], skip=np.array([0, 0, 1, 1])),
                                  [False, True, True, True])
    np.testing.assert_array_equal(clip_mask(p, []), False)


@settings(deadline=None, max_examples=20)
@given(st.integers(0, 2**31), st.sampled_from(["repeat", "clamp_to_edge", "mirrored_repeat"]))
def test_kernel_matches_naive(seed, wrap):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    cs = ClipSurface(rng.normal(size=3), q[0] * rng.uniform(0.5, 3), q[1] * rng.uniform(0.5, 3),
                     (rng.uniform(0.5, 3), rng.uniform(0.5, 3), rng.uniform(-1, 1)),
                     rng.random((rng.integers(1, 9), rng.integers(1, 9))), wrap=wrap)
    p = rng.normal(size=(300, 3)) * 3
    got = clip_function(p, cs)
    np.testing.assert_allclose(got, naive_g(p, cs), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(clip_mask(p, cs), got < 0)


def test_eye_space_equals_world_space_for_rigid_view():
    rng = np.random.default_rng(5)
    cs = ClipSurface([0.1, 0.2, 0.3], [1.5, 0, 0], [0, 0.5, 0.5], (2, 1, 0.3),
                     om.perlin_noise(16, seed=2))
    view = look_at([3, 2, 5], [0, 0, 0], [0, 1, 0])
    p = rng.uniform(-1, 1, (20000, 3))
    pe = p @ view[:3, :3].T + view[:3, 3]
    gw = clip_function(p, cs)
    ge = clip_function(pe, cs, space="eye", view=view)
    np.testing.assert_allclose(ge, gw, rtol=0, atol=1e-12)
    same = clip_mask(pe, cs, space="eye", view=view) == clip_mask(p, cs)
    # only points within rounding of the surface may differ
    assert np.all(same | (np.abs(gw) < 1e-12))


def test_relief_clip_plane_sign_d8():
    # RCP discards N·(X − P) − s·h > 0: with N = +z, P = 0, s = 0.5, h = 0.5 → z > 0.25
    rcp = ReliefClipPlane([0, 0, 2], [0, 0, 0], om.constant(4, 0.5), 0.5)
    p = np.array([[0.3, 0.1, 0.3], [0.3, 0.1, 0.2], [5, 5, 0.26]])
    np.testing.assert_array_equal(clip_mask(p, rcp), [True, False, True])
    cs = rcp.clip_surface
    np.testing.assert_allclose(cs.normal, [0, 0, -1])
    np.testing.assert_allclose(np.cross(cs.u_hat, cs.v_hat), cs.normal)
    # deterministic in-plane axis: the world axis least aligned with N (x), and a given u
    np.testing.assert_allclose(cs.u_hat, [1, 0, 0])
    given_u = ReliefClipPlane([0, 0, 1], [0, 0, 0], om.constant(4), 1.0, u=[1, 1, 5])
    np.testing.assert_allclose(given_u.clip_surface.u_hat, [2 ** -0.5, 2 ** -0.5, 0])
    a = ReliefClipPlane([1, 2, 3], [0, 0, 0], om.constant(4), 1.0)
    b = ReliefClipPlane([1, 2, 3], [0, 0, 0], om.constant(4), 1.0)
    np.testing.assert_array_equal(a.clip_surface.params, b.clip_surface.params)


@pytest.mark.parametrize("kwargs,exc,match", [
    (dict(u=[0, 0, 0]), ValueError, "u must have non-zero length"),
    (dict(v=[2, 0, 0]), ValueError, "parallel"),
    (dict(v=[1, 1, 0]), ValueError, "orthogonal"),
    (dict(origin=[0, np.nan, 0]), ValueError, "origin"),
    (dict(u=[np.inf, 0, 0]), ValueError, "u"),
    (dict(scale=(0, 1, 1)), ValueError, "Sx"),
    (dict(scale=(1, 1)), ValueError, "scale"),
    (dict(offset_map=np.zeros((0, 4))), ValueError, "empty"),
    (dict(offset_map=np.zeros((2, 2, 2))), ValueError, "2D"),
    (dict(textures=np.zeros((2, 2))), TypeError, "CapTextures"),
    (dict(offset_map=np.zeros((2, 2), np.int64)), TypeError, "dtype"),
    (dict(offset_map=None), TypeError, "offset_map"),
    (dict(wrap="border"), ValueError, "wrap"),
    (dict(enabled=1), TypeError, "enabled"),
])
def test_bad_surface_parameters(kwargs, exc, match):
    args = dict(origin=[0, 0, 0], u=[1, 0, 0], v=[0, 1, 0], scale=(1, 1, 1),
                offset_map=om.constant(2))
    args.update(kwargs)
    with pytest.raises(exc, match=match):
        ClipSurface(**args)


def test_bad_call_inputs():
    cs = xy_surface(om.constant(2))
    with pytest.raises(ValueError, match="points"):
        clip_mask([[0, 0, np.nan]], cs)
    with pytest.raises(ValueError, match="points"):
        clip_mask([0, 0, 0], cs)
    with pytest.raises(ValueError, match="view"):
        clip_mask([[0, 0, 0]], cs, space="eye")
    with pytest.raises(ValueError, match="space"):
        clip_mask([[0, 0, 0]], cs, space="clip")
    with pytest.raises(TypeError, match="surfaces"):
        clip_mask([[0, 0, 0]], [cs, "plane"])
    with pytest.raises(ValueError, match="parallel"):
        ReliefClipPlane([0, 0, 1], [0, 0, 0], om.constant(2), 1.0, u=[0, 0, 3])
    with pytest.raises(ValueError, match="normal"):
        ReliefClipPlane([0, 0, 0], [0, 0, 0], om.constant(2), 1.0)
    with pytest.raises(ValueError, match="height_scale"):
        ReliefClipPlane([0, 0, 1], [0, 0, 0], om.constant(2), np.nan)


_DETERMINISM = """
import numpy as np, sys
from refraster.clipsurface import offsetmaps as om
from refraster.clipsurface import ClipSurface, clip_mask, clip_function
cs = [ClipSurface([0, 0, 0], [1, 0, 0], [0, 1, 0], (3, 2, 0.4), om.perlin_noise(32, seed=k))
      for k in range(3)]
p = np.random.default_rng(0).uniform(-1, 1, (200000, 3))
sys.stdout.write(clip_function(p, cs[0]).tobytes().hex()[:20000])
sys.stdout.write(np.packbits(clip_mask(p, cs)).tobytes().hex())
"""


def test_deterministic_across_thread_counts():
    outs = outputs_by_thread_count(_DETERMINISM)
    assert outs[0] == outs[1] == outs[2] and len(outs[0]) > 1000
