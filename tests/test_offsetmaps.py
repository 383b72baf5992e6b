"""Offset maps: the texture2D sampler against a NumPy twin of GL's rules, loading, generators,
blends, normal and occlusion maps (MATH.md §1.2b)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraster.clipsurface import offsetmaps as om
from refraster.io import write_png

WRAPS = ["repeat", "clamp_to_edge", "mirrored_repeat"]


def gl_wrap(i, size, mode):
    """OpenGL 4.6, Table 8.20, on integer texel coordinates."""
    if mode == "repeat":
        return np.mod(i, size)
    if mode == "clamp_to_edge":
        return np.clip(i, 0, size - 1)
    a = np.mod(i, 2 * size) - size
    mirror = np.where(a >= 0, a, -(1 + a))
    return (size - 1) - mirror


def gl_texture2d_linear(tex, s, t, mode):
    """Plain NumPy twin of GL_LINEAR (OpenGL 4.6 §8.14.2): u = s·W, i0 = ⌊u − ½⌋, α = frac."""
    h, w = tex.shape
    u = s * w - 0.5
    v = t * h - 0.5
    i0 = np.floor(u).astype(np.int64)
    j0 = np.floor(v).astype(np.int64)
    a = u - np.floor(u)
    b = v - np.floor(v)
    i1, j1 = gl_wrap(i0 + 1, w, mode), gl_wrap(j0 + 1, h, mode)
    i0, j0 = gl_wrap(i0, w, mode), gl_wrap(j0, h, mode)
    return ((1 - a) * (1 - b) * tex[j0, i0] + a * (1 - b) * tex[j0, i1]
            + (1 - a) * b * tex[j1, i0] + a * b * tex[j1, i1])


@pytest.mark.parametrize("wrap", WRAPS)
@pytest.mark.parametrize("shape", [(1, 1), (2, 3), (5, 7), (16, 16)])
def test_sampler_matches_gl_twin(wrap, shape):
    rng = np.random.default_rng(1)
    tex = rng.random(shape)
    st_ = np.concatenate([rng.uniform(-3, 4, (2000, 2)),
                          # texel centres, texel edges and the domain's borders
                          np.stack(np.meshgrid(np.arange(-2 * shape[1], 3 * shape[1] + 1) / (2 * shape[1]),
                                               [0.0, 1.0, 0.5 / shape[0], -0.5 / shape[0]]), -1).reshape(-1, 2)])
    got = om.sample(tex, st_, wrap=wrap)
    want = gl_texture2d_linear(tex, st_[:, 0], st_[:, 1], wrap)
    np.testing.assert_array_equal(got, want)


def test_sampler_hand_values():
    tex = np.array([[0.0, 1.0], [0.5, 0.25]])  # row 0 at t = 0
    centres = np.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])
    np.testing.assert_array_equal(om.sample(tex, centres), [0.0, 1.0, 0.5, 0.25])
    # midway between all four texel centres
    assert om.sample(tex, [[0.5, 0.5]])[0] == pytest.approx((0 + 1 + 0.5 + 0.25) / 4)
    # s = 0 lies between texel 1 (wrapped) and texel 0 under repeat, on texel 0 under clamp
    assert om.sample(tex, [[0.0, 0.25]], wrap="repeat")[0] == pytest.approx(0.5)
    assert om.sample(tex, [[0.0, 0.25]], wrap="clamp_to_edge")[0] == 0.0
    assert om.sample(tex, [[0.0, 0.25]], wrap="mirrored_repeat")[0] == 0.0
    # one tile to the right: repeat is periodic, mirrored repeat is reflected
    assert om.sample(tex, [[1.25, 0.25]], wrap="repeat")[0] == 0.0
    assert om.sample(tex, [[1.25, 0.25]], wrap="mirrored_repeat")[0] == 1.0
    assert om.sample(tex, [[1.25, 0.25]], wrap="clamp_to_edge")[0] == 1.0


@settings(deadline=None, max_examples=25)
@given(st.integers(1, 9), st.integers(1, 9), st.sampled_from(WRAPS),
       st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=1, max_size=40))
def test_sampler_property(h, w, wrap, coords):
    tex = np.random.default_rng(h * 10 + w).random((h, w))
    st_ = np.array(coords)
    got = om.sample(tex, st_, wrap=wrap)
    np.testing.assert_array_equal(got, gl_texture2d_linear(tex, st_[:, 0], st_[:, 1], wrap))
    assert np.all(got >= tex.min() - 1e-12) and np.all(got <= tex.max() + 1e-12)


def test_sampler_huge_coordinates_do_not_overflow():
    tex = np.random.default_rng(0).random((4, 4))
    out = om.sample(tex, [[1e300, -1e300], [1e17, 3.0]], wrap="repeat")
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("dtype,scale", [(np.uint8, 255), (np.uint16, 65535)])
def test_load_integer_images_flipped(tmp_path, dtype, scale):
    img = np.zeros((3, 4), dtype)
    img[0, :] = scale  # top row of the file
    img[2, 1] = scale // 3
    path = tmp_path / "om.png"
    write_png(path, img)
    m = om.load_offset_map(path)
    assert m.shape == (3, 4) and m.dtype == np.float64
    np.testing.assert_array_equal(m[2], 1.0)       # top row of the file → highest t
    assert m[0, 1] == (scale // 3) / scale          # bottom row of the file → t = 0
    assert not m.flags.writeable


def test_load_float_tiff_and_colour(tmp_path):
    import imageio.v3 as iio
    img = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    iio.imwrite(tmp_path / "f.tiff", img)
    np.testing.assert_array_equal(om.load_offset_map(tmp_path / "f.tiff"), img[::-1])
    rgb = np.zeros((3, 4, 3), np.uint8)
    rgb[..., 1] = 255
    write_png(tmp_path / "c.png", rgb)
    with pytest.raises(ValueError, match="channel"):
        om.load_offset_map(tmp_path / "c.png")
    np.testing.assert_array_equal(om.load_offset_map(tmp_path / "c.png", channel=1), 1.0)


@pytest.mark.parametrize("bad,exc", [
    (np.zeros((0, 3)), ValueError), (np.zeros(0), ValueError), (np.zeros((2, 2, 2)), ValueError),
    (np.float64(0.5), ValueError),
    (np.zeros((2, 2), np.int32), TypeError), (np.zeros((2, 2), bool), TypeError),
    (np.full((2, 2), 1.5), ValueError), (np.full((2, 2), np.nan), ValueError),
    ("map.png", TypeError), (None, TypeError), (np.zeros((2, 2), complex), TypeError),
])
def test_bad_offset_maps(bad, exc):
    with pytest.raises(exc):
        om.as_offset_map(bad)


def test_bad_sampler_inputs():
    tex = np.zeros((2, 2))
    with pytest.raises(ValueError, match="wrap"):
        om.sample(tex, [[0, 0]], wrap="clamp")
    with pytest.raises(ValueError, match="st"):
        om.sample(tex, [[0, np.inf]])
    with pytest.raises(ValueError, match="st"):
        om.sample(tex, [0, 0])


GENERATORS = [
    lambda: om.value_noise((20, 30), cells=4, octaves=2, seed=3),
    lambda: om.perlin_noise((20, 30), cells=4, seed=3),
    lambda: om.ragged_cut((20, 30), seed=3),
    lambda: om.ragged_cut((20, 30), seed=3, axis="t"),
    lambda: om.sinusoid((20, 30), periods=(3, 1)),
    lambda: om.steps((20, 30), levels=3),
    lambda: om.constant((20, 30), 0.25),
]


@pytest.mark.parametrize("gen", GENERATORS)
def test_generators_valid_and_deterministic(gen):
    a, b = gen(), gen()
    assert a.shape == (20, 30) and a.dtype == np.float64
    assert a.min() >= 0.0 and a.max() <= 1.0
    np.testing.assert_array_equal(a, b)
    om.as_offset_map(a)


def test_noise_is_periodic():
    # One texel beyond the right border continues the left border smoothly: the difference
    # across the seam is of the size of an interior step.
    m = om.perlin_noise(64, cells=4, octaves=1)
    seam = np.abs(m[:, 0] - m[:, -1]).max()
    interior = np.abs(np.diff(m, axis=1)).max()
    assert seam <= interior * 1.01


def test_steps_and_sinusoid_values():
    np.testing.assert_array_equal(om.steps((1, 8), levels=4)[0], [0, 0, 1 / 3, 1 / 3, 2 / 3, 2 / 3, 1, 1])
    s = om.sinusoid((1, 4), periods=(1, 0))[0]
    np.testing.assert_allclose(s, 0.5 + 0.5 * np.sin(2 * np.pi * (np.arange(4) + 0.5) / 4))


def test_blends():
    a = np.array([[0.2, 0.8]])
    b = np.array([[0.5, 0.5]])
    np.testing.assert_allclose(om.blend(a, b, "add"), [[0.7, 1.0]])
    np.testing.assert_allclose(om.blend(a, b, "max"), [[0.5, 0.8]])
    np.testing.assert_allclose(om.blend(a, b, "min"), [[0.2, 0.5]])
    np.testing.assert_allclose(om.blend(a, b, "multiply"), [[0.1, 0.4]])
    np.testing.assert_allclose(om.blend(a, b, "lerp", weight=0.25), [[0.275, 0.725]])
    np.testing.assert_allclose(om.blend(a, b, "lerp", weight=np.array([[0.0, 1.0]])), [[0.2, 0.5]])
    with pytest.raises(ValueError, match="shape"):
        om.blend(a, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="mode"):
        om.blend(a, b, "screen")
    with pytest.raises(ValueError, match="weight"):
        om.blend(a, b, weight=2.0)


def test_normal_map_flat_and_ramp():
    flat = om.normal_map(om.constant((4, 5), 0.3))
    np.testing.assert_array_equal(flat, np.broadcast_to([0.0, 0.0, -1.0], (4, 5, 3)))
    # h = s across one tile of a clamped map: ∂h/∂s = 1 in the interior.
    w = 8
    ramp = np.tile((np.arange(w) + 0.5) / w, (3, 1))
    n = om.normal_map(ramp, extent=(2.0, 3.0), scale=(1.0, 1.0, 0.5), wrap="clamp_to_edge")
    # X(a, b) = O + a·2Û + b·3V̂ − 0.5·a·N → normal ∝ −(0.5·3, 0, 2·3)
    want = -np.array([1.5, 0.0, 6.0]) / np.linalg.norm([1.5, 0.0, 6.0])
    np.testing.assert_allclose(n[:, 1:-1], np.broadcast_to(want, (3, w - 2, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0)
    # at the clamped border the sampled surface is flat beyond the texel centre: half the slope
    assert n[0, 0, 0] == pytest.approx(-0.75 / np.linalg.norm([0.75, 0, 6.0]))


def test_normal_map_matches_finite_difference_of_sampler():
    m = om.perlin_noise((16, 12), cells=2, seed=4)
    n = om.normal_map(m, extent=(1.5, 1.0), scale=(2.0, 1.0, 0.3))
    rows, cols = m.shape
    j, i = 5, 7
    s0, t0 = (i + 0.5) / cols, (j + 0.5) / rows
    hs = (om.sample(m, [[s0 + 1 / cols, t0]]) - om.sample(m, [[s0 - 1 / cols, t0]]))[0] * cols / 2
    ht = (om.sample(m, [[s0, t0 + 1 / rows]]) - om.sample(m, [[s0, t0 - 1 / rows]]))[0] * rows / 2
    da = np.array([1.5, 0.0, -0.3 * 2.0 * hs])  # ∂X/∂a in (Û, V̂, N)
    db = np.array([0.0, 1.0, -0.3 * 1.0 * ht])
    want = -np.cross(da, db)
    np.testing.assert_allclose(n[j, i], want / np.linalg.norm(want), atol=1e-12)


def test_occlusion_map():
    # bilinear weights sum to 1 only up to rounding, so a flat map is unoccluded to 1e-12
    np.testing.assert_allclose(om.occlusion_map(om.constant(8, 0.7)), 1.0, rtol=0, atol=1e-12)
    # a pit: the centre texel of a well surrounded by high walls is occluded; walls are not
    pit = np.ones((9, 9))
    pit[4, 4] = 0.0
    ao = om.occlusion_map(pit, scale=(1, 1, 1), radius=1 / 9, directions=4, steps=1)
    # each of 4 directions sees a rise of 1 at distance 1/9: sin θ = 1/√(1 + 1/81)
    assert ao[4, 4] == pytest.approx(1.0 - 1.0 / np.sqrt(1 + 1 / 81))
    assert ao[0, 0] == 1.0
    a = om.occlusion_map(om.perlin_noise(16), scale=(1, 1, 0.2))
    np.testing.assert_array_equal(a, om.occlusion_map(om.perlin_noise(16), scale=(1, 1, 0.2)))
    assert a.min() >= 0.0 and a.max() <= 1.0 and a.min() < 1.0


def test_derived_map_bad_inputs():
    m = om.constant(4)
    with pytest.raises(ValueError, match="extent"):
        om.normal_map(m, extent=(0.0, 1.0))
    with pytest.raises(ValueError, match="scale"):
        om.normal_map(m, scale=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError, match="radius"):
        om.occlusion_map(m, radius=-1.0)
    with pytest.raises(TypeError, match="directions"):
        om.occlusion_map(m, directions=2.5)
    with pytest.raises(ValueError, match="shape"):
        om.perlin_noise((0, 4))
