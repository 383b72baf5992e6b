"""NPR styles and the edge-map compositing (Nienhaus & Döllner Sec. 5)."""


import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraster import npr
from determinism import outputs_by_thread_count


def _normals(*rows):
    n = np.array(rows, np.float64).reshape(1, -1, 3)
    return n / np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-300)


# ---------------------------------------------------------------- Gooch

def test_gooch_hand_values():
    light = (0.0, 0.0, 1.0)
    n = _normals((0, 0, 1), (0, 0, -1), (1, 0, 0))
    base, cool, warm = (0.4, 0.4, 0.4), (0.0, 0.0, 0.6), (0.4, 0.4, 0.0)
    out = npr.gooch(n, light=light, base=base, cool=cool, warm=warm, alpha=0.25, beta=0.5)
    k_cool = np.array(cool) + 0.25 * np.array(base)
    k_warm = np.array(warm) + 0.5 * np.array(base)
    np.testing.assert_allclose(out[0, 0], k_warm, atol=1e-7)        # facing the light: warm
    np.testing.assert_allclose(out[0, 1], k_cool, atol=1e-7)        # facing away: cool
    np.testing.assert_allclose(out[0, 2], 0.5 * (k_cool + k_warm), atol=1e-7)
    assert out.dtype == np.float32


def test_styles_leave_the_background_alone():
    n = _normals((0, 0, 1), (0, 0, 0))
    for out in (npr.gooch(n, background=(0.2, 0.3, 0.4)),
                npr.toon(n, background=(0.2, 0.3, 0.4))):
        np.testing.assert_allclose(out[0, 1], (0.2, 0.3, 0.4), atol=1e-7)
    np.testing.assert_array_equal(npr.hatching(n, paper=(0.9, 0.9, 0.8))[0, 1],
                                  np.float32([0.9, 0.9, 0.8]))
    mask = np.array([[False, True]])
    out = npr.gooch(n, mask=mask, background=(0, 0, 0))
    assert np.all(out[0, 0] == 0.0)


# ---------------------------------------------------------------- toon

def test_toon_nearest_texel_boundaries():
    # u = n·l exactly at the texel boundaries 0, 1/4, 1/2, 3/4, 1 (and below 0)
    us = np.array([-0.5, 0.0, 0.2499, 0.25, 0.5, 0.7499, 0.75, 1.0])
    n = np.stack([np.sqrt(1 - us ** 2), np.zeros_like(us), us], axis=1)[None]
    tex = np.array([0.1, 0.3, 0.6, 0.9])
    out = npr.toon(n, light=(0, 0, 1), texture=tex, color=(1.0, 0.5, 1.0))
    expect = tex[[0, 0, 0, 1, 2, 2, 3, 3]]
    np.testing.assert_allclose(out[0, :, 0], expect, atol=1e-7)
    np.testing.assert_allclose(out[0, :, 1], 0.5 * expect, atol=1e-7)
    rgb = np.array([[1, 0, 0], [0, 1, 0]], float)
    out = npr.toon(n, light=(0, 0, 1), texture=rgb)
    assert np.all(out[0, :3] == np.float32([0.9, 0.0, 0.0]))


def test_cartoon_map_is_a_normalized_binomial_filter(oracle):
    ndi = oracle("scipy.ndimage")
    rng = np.random.default_rng(2)
    img = rng.random((13, 17, 3))
    k = np.outer([1, 2, 1], [1, 2, 1]) / 16.0
    full = np.stack([ndi.correlate(img[..., c], k, mode="nearest") for c in range(3)], 2)
    np.testing.assert_allclose(npr.cartoon_map(img), full, atol=1e-6)
    mask = rng.random((13, 17)) < 0.6
    num = np.stack([ndi.correlate(img[..., c] * mask, k, mode="nearest") for c in range(3)], 2)
    den = ndi.correlate(mask.astype(float), k, mode="nearest")[..., None]
    expect = np.where(mask[..., None], num / np.where(den > 0, den, 1), img)
    np.testing.assert_allclose(npr.cartoon_map(img, mask=mask), expect, atol=1e-6)


def test_cartoon_map_keeps_flat_patches():
    img = np.zeros((6, 8, 3))
    img[:, 4:] = 1.0
    out = npr.cartoon_map(img)
    assert np.all(out[:, :3] == 0) and np.all(out[:, 5:] == 1)
    np.testing.assert_allclose(out[:, 3], 0.25) and np.testing.assert_allclose(out[:, 4], 0.75)


# ---------------------------------------------------------------- hatching

def test_smooth_threshold_hand_values():
    t = np.array([0.5, 0.5, 0.5, 0.5, 0.5])
    i = np.array([0.3, 0.45, 0.5, 0.55, 0.7])
    np.testing.assert_allclose(npr.smooth_threshold(i, t, softness=0.2),
                               [0.0, 0.25, 0.5, 0.75, 1.0], atol=1e-7)
    np.testing.assert_array_equal(npr.smooth_threshold(i, t, softness=0.0), [0, 0, 0, 1, 1])


def test_stroke_texture_coverage_follows_the_tone():
    st_ = npr.stroke_texture(240, 240, spacing=8.0, first=0.9, cross=0.5)
    assert st_.dtype == np.float32 and st_.min() >= 0 and st_.max() <= 0.9
    # first family only (tone above `cross`): inked fraction 1 − tone/first
    for tone in (0.55, 0.7, 0.85):
        ink = np.mean(st_ > tone)
        assert abs(ink - (1 - tone / 0.9)) < 0.03, (tone, ink)
    assert np.mean(st_ > 0.999) == 0.0


@settings(max_examples=15, deadline=None)
@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 0.3))
def test_hatching_is_monotone_in_the_tone(a, b, soft):
    lo, hi = min(a, b), max(a, b)
    strokes = npr.stroke_texture(24, 24)
    paper_lo = npr.smooth_threshold(np.full((24, 24), lo), strokes, softness=soft)
    paper_hi = npr.smooth_threshold(np.full((24, 24), hi), strokes, softness=soft)
    assert np.all(paper_hi >= paper_lo)


def test_hatching_lit_is_paper_unlit_is_inked():
    n = np.zeros((16, 16, 3))
    n[:, :8] = (0, 0, 1)
    n[:, 8:] = (0, 0, -1)
    out = npr.hatching(n, light=(0, 0, 1), ambient=0.0, softness=0.05)
    assert np.all(out[:, :8] == 1.0)
    assert out[:, 8:].mean() < 0.1


# ---------------------------------------------------------------- compositing

def test_composite_hand_values():
    shade = np.full((1, 4, 3), 0.5)
    em = np.zeros((1, 4, 4))
    em[0, 1, :3] = 1.0            # inner edge → inner colour
    em[0, 2, 3] = 1.0             # profile edge → profile colour
    em[0, 3] = (0.5, 0.5, 0.5, 0.5)
    out = npr.composite(shade, em, inner_color=(1, 1, 1), profile_color=(0, 0, 0))
    np.testing.assert_allclose(out[0], [[0.5] * 3, [1] * 3, [0] * 3, [0.375] * 3])
    out = npr.composite(shade, em, mask=np.array([[True, True, False, True]]))
    np.testing.assert_allclose(out[0, 2], 0.5)


# ---------------------------------------------------------------- bad input

@pytest.mark.parametrize("call, exc, words", [
    (lambda: npr.gooch(np.zeros((3, 3))), ValueError, "normal"),
    (lambda: npr.gooch(np.zeros((3, 3, 3)), light=(0, 0, 0)), ValueError, "light"),
    (lambda: npr.gooch(np.zeros((3, 3, 3)), base=(2, 0, 0)), ValueError, "base"),
    (lambda: npr.gooch(np.zeros((3, 3, 3)), alpha=1.5), ValueError, "alpha"),
    (lambda: npr.gooch(np.full((3, 3, 3), np.nan)), ValueError, "non-finite"),
    (lambda: npr.gooch(np.zeros((3, 3, 3)), mask=np.ones((3, 3))), TypeError, "mask"),
    (lambda: npr.gooch(np.zeros((3, 3, 3)), mask=np.ones((2, 3), bool)), ValueError, "mask"),
    (lambda: npr.toon(np.zeros((3, 3, 3)), texture=[]), ValueError, "texture"),
    (lambda: npr.toon(np.zeros((3, 3, 3)), texture=[0.5, 1.5]), ValueError, "texture"),
    (lambda: npr.toon(np.zeros((3, 3, 3)), texture=np.ones((2, 2))), ValueError, "texture"),
    (lambda: npr.cartoon_map(np.zeros((3, 3))), ValueError, "image"),
    (lambda: npr.stroke_texture(0, 5), ValueError, "height"),
    (lambda: npr.stroke_texture(5, 5, spacing=0), ValueError, "spacing"),
    (lambda: npr.smooth_threshold(np.ones(3), np.ones(4)), ValueError, "broadcast"),
    (lambda: npr.smooth_threshold(np.ones(3), np.ones(3), softness=-1), ValueError, "softness"),
    (lambda: npr.hatching(np.zeros((3, 3, 3)), strokes=np.ones((2, 2))), ValueError, "strokes"),
    (lambda: npr.composite(np.zeros((3, 3, 3)), np.zeros((3, 3, 3))), ValueError, "edge_map"),
    (lambda: npr.composite(np.zeros((3, 3, 3)), np.full((3, 3, 4), 2.0)), ValueError, "[0, 1]"),
    (lambda: npr.composite(np.zeros((3, 3, 3)), np.zeros((3, 3, 4)), inner_color="w"),
     TypeError, "inner_color"),
])
def test_bad_inputs(call, exc, words):
    with pytest.raises(exc, match=words):
        call()


# ---------------------------------------------------------------- determinism

_SCRIPT = r"""
import hashlib
import numpy as np
from refraster import npr
rng = np.random.default_rng(5)
img = rng.random((53, 71, 3))
mask = rng.random((53, 71)) < 0.7
print(hashlib.sha256(npr.cartoon_map(img, mask=mask).tobytes()).hexdigest())
"""


def test_cartoon_map_deterministic_across_thread_counts():
    digests = set(outputs_by_thread_count(_SCRIPT))
    assert len(digests) == 1
