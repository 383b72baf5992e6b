"""The pieces of the resolve and centroid allowances (issue 44, open points c and d;
docs/tolerance.md), each against brute force: the clip decision's range over a polygon
(``allowances.clip._region_state``) against the clip function evaluated inside it, the mean
edge operator's dot-product bound (``allowances.edges._mean_dot_bounds``) against unit normals
drawn inside the cones, and the min/max seed images (``allowances.sampled``) by hand."""

import math

import numpy as np
import pytest

from refraster.clipsurface import ClipSurface, clip_function
from refraster.clipsurface.offsetmaps import perlin_noise
from refraster.golden.allowances.clip import _region_state
from refraster.golden.allowances.edges import _mean_dot_bounds
from refraster.golden.allowances.sampled import resolved_seed_images


def _inside(poly, rng, n):
    """``n`` random points of the convex polygon ``poly (K, 3)`` (convex combinations)."""
    w = rng.dirichlet(np.ones(len(poly)), size=n)
    return w @ poly


@pytest.mark.parametrize("wrap", ["repeat", "mirrored_repeat", "clamp_to_edge"])
def test_the_region_decision_is_sure_only_where_g_keeps_its_sign(wrap):
    rng = np.random.default_rng(44)
    om = perlin_noise((16, 16), seed=3)
    surface = ClipSurface([0.0, 0.0, 0.2], [1.0, 0.0, 0.0], [0.0, 1.5, 0.0], [1.0, 1.0, 0.3],
                          om, wrap=wrap)
    # polygons about the surface (g = 0 at their centres, ± noise), spanning a part of a
    # texel (1/16) to several
    centres = np.column_stack([rng.uniform(-0.5, 1.5, 300), rng.uniform(-0.5, 2.0, 300),
                               np.zeros(300)])
    g0 = clip_function(centres, surface)
    slope = clip_function(centres + [0.0, 0.0, 1.0], surface) - g0      # g is affine in z
    centres[:, 2] = -g0 / slope + rng.normal(0.0, 0.1, 300)
    sizes = rng.uniform(0.01, 0.1, 300)
    k = 5
    poly = centres[:, None, :] + sizes[:, None, None] * rng.normal(size=(300, k, 3))
    poly[::7, 4] = np.nan                               # some NaN-padded polygons
    state = _region_state(surface, poly, np.ones(300, bool))
    seen = {0: 0, 1: 0, 2: 0}
    for e in range(300):
        verts = poly[e][~np.isnan(poly[e, :, 0])]
        g = clip_function(_inside(verts, rng, 400), surface)
        g = np.concatenate([g, clip_function(verts, surface)])
        seen[int(state[e])] += 1
        if state[e] == 2:
            assert g.min() >= 0.0, e
        elif state[e] == 0:
            assert g.max() < 0.0, e
    assert min(seen.values()) > 5, seen     # each answer occurs
    # a polygon that reaches across the surface is never sure
    across = np.array([[[0.0, 0.0, -1.0], [0.01, 0.0, 1.0], [0.0, 0.01, 1.0]]])
    assert _region_state(surface, across, np.ones(1, bool))[0] == 1


def _cone_samples(axis, angle, rng, n):
    """Unit vectors within ``angle`` of the unit ``axis``."""
    axis = np.asarray(axis, float)
    t = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(axis, t)
    th = np.arccos(rng.uniform(np.cos(angle), 1.0, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    return (np.cos(th)[:, None] * axis + np.sin(th)[:, None]
            * (np.cos(ph)[:, None] * t + np.sin(ph)[:, None] * b))


def test_the_mean_dot_bound_holds_for_normals_inside_the_cones():
    """Two pixels (A, H), S = 3 samples, each sample one to two options (a cone or the
    background): every choice of one option and one unit normal in its cone per sample gives
    a dot product of the two means inside the bound; the bound is reached within 5 %."""
    rng = np.random.default_rng(7)
    for trial in range(40):
        s_count, n_pix = 3, 2
        counts = rng.integers(1, 3, s_count * n_pix)
        off = np.zeros(len(counts) + 1, np.int64)
        off[1:] = np.cumsum(counts)
        n = int(off[-1])
        nrm = rng.normal(size=(n, 3))
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        ang = rng.uniform(0.0, 0.4, n)
        bg = rng.random(n) < 0.15
        free = np.zeros(len(counts), np.bool_)
        lo, hi = _mean_dot_bounds(0, 1, n_pix, s_count, off, nrm, ang, bg, free, 0.0)
        got = []
        for _ in range(300):
            means = []
            for p in range(n_pix):
                vs = []
                for s in range(s_count):
                    q = p + s * n_pix
                    i = rng.integers(off[q], off[q + 1])
                    vs.append(np.zeros(3) if bg[i] else _cone_samples(nrm[i], ang[i], rng, 1)[0])
                means.append(np.mean(vs, axis=0))
            got.append(float(means[0] @ means[1]))
        assert lo - 1e-12 <= min(got) and max(got) <= hi + 1e-12, (trial, lo, hi)
    # one option per sample, no spread: the bound is the exact dot product of the means
    off = np.arange(5, dtype=np.int64)
    nrm = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 0, 0]])
    lo, hi = _mean_dot_bounds(0, 1, 2, 2, off, nrm, np.zeros(4), np.zeros(4, np.bool_),
                              np.zeros(4, np.bool_), 0.0)
    # n̄_A = (e_x + e_z)/2, n̄_H = (e_y + e_x)/2: dot = 1/4
    assert lo == pytest.approx(0.25) and hi == pytest.approx(0.25)
    assert math.isclose(lo, hi)


def test_the_min_and_max_seed_images_by_hand():
    one = np.ones((1, 3), bool)
    big0, small0, least0 = np.array([[0.6, 0.5, 0.0]]), np.array([[0.55, 0, 0]]), \
        np.array([[0.5, 0.45, 1.0]])
    sure0 = np.array([[True, False, False]])
    may0 = np.array([[True, True, False]])
    big1, small1 = np.array([[0.7, 0.3, 0.4]]), np.array([[0.65, 0.25, 0]])
    sure1 = np.array([[True, True, False]])
    images = [(big0, may0, small0, sure0, least0), (big1, one, small1, sure1, least0)]
    big, seedable, low, sure, least = resolved_seed_images(images, "max")
    assert big.tolist() == [[0.7, 0.5, 0.4]]
    # pixel 0: both sure → max(0.55, 0.65); pixel 1: sample 0 may seed (least 0.45),
    # sample 1 sure 0.25 → 0.45; pixel 2: sample 0 not seedable
    assert low[0, :2].tolist() == [0.65, 0.45]
    assert (seedable == may0).all() and (sure == sure0).all() and (least == low).all()
    big, _, low, _, _ = resolved_seed_images(images, "min")
    assert big.tolist() == [[0.6, 0.3, 0.0]]
    assert low[0, :2].tolist() == [0.55, 0.25]
    # a sample that may be uncovered (not sure) brings the clear value 0 under min
    images[1] = (big1, one, small1, np.zeros((1, 3), bool), least0)
    assert resolved_seed_images(images, "min")[2][0, 0] == 0.0
    with pytest.raises(ValueError, match="resolve must be 'min' or 'max'"):
        resolved_seed_images(images, "average")
