"""Defaults that keep Eq. 3 depth-dependent (issue 21 item 1; MATH.md §5.4).

With the defaults, (1 − δt)·δd equals the 95th percentile of the 4D-depth differences of sheets
that overlap in projection, so the carved part of Fig. 1's white patch grows with Δw, and the gap
next to a crossing has the half-width ρ·min(1, δt + Δδ/δd) that Eq. 3 predicts. A planted
saturating δd (the former default, 10 % of the depth range) makes the growth test fail.
"""

import sys

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import render as hr

ht = sys.modules["refraster.halos4d.thicken"]

FIG1_VIEW = h.View4D(rotation=h.compose(("zx", 0.5), ("yz", -1.0)))
FIG1_KW = dict(width=96, height=96, slices=48, view=FIG1_VIEW, volume=True)


def fig1_defaults():
    r = h.render_halos(h.figure1_scene(10), width=16, height=16, slices=4, view=FIG1_VIEW)
    return r.stats["rho"], r.stats["delta_d"]


def carved_by_strip(rho, delta_d):
    """Carved voxels of the white patch crossed by one strip at Δw = 0.1 … 0.5 (the Fig. 1
    family), rendered with the given ρ and δd."""
    out = []
    for w in (0.1, 0.2, 0.3, 0.4, 0.5):
        r = h.render_halos(h.figure1_scene(10, w_values=[w]),
                           halos=h.Halos(rho=rho, delta_d=delta_d), **FIG1_KW)
        out.append(int((r.volume == hr.CARVED).sum()))
    return out


def strictly_increasing(xs):
    return all(a < b for a, b in zip(xs, xs[1:]))


def test_default_delta_d_meets_the_quantile_rule():
    s = h.figure1_scene(10)
    geo, rho = hr.prepare(s, view=FIG1_VIEW)
    d = geo.attributes[:len(geo.points), 0]
    rho2, dd, n = ht.default_halo_parameters(geo.points, d, geo.spatial, geo.faces, 0.3)
    assert rho2 == rho == pytest.approx(ht.RHO_FRACTION * np.linalg.norm(np.ptp(geo.points, axis=0)))
    # the crossings of Fig. 1 are the five strips at Δw = 0.1 … 0.5: those are the samples
    diffs = ht.crossing_depth_differences(geo.points, d, geo.spatial, geo.faces,
                                          ht.pair_radius(geo.points, geo.faces, rho))
    assert n == diffs.size > 100
    assert set(np.round(diffs, 9)) <= {0.1, 0.2, 0.3, 0.4, 0.5}
    assert (1 - 0.3) * dd >= np.quantile(diffs, 0.95) - 1e-12
    assert (1 - 0.3) * dd == pytest.approx(0.5)
    # without any crossing: the depth range; the render reports what it used
    flat = h.figure1_scene(10, w_values=[0.0])
    r = h.render_halos(flat, width=16, height=16, slices=4)
    assert r.stats["crossing_pairs"] == 0 and r.stats["delta_d"] == 1.0
    r = h.render_halos(s, width=16, height=16, slices=4, view=FIG1_VIEW,
                       halos=h.Halos(delta_d=0.2))
    assert r.stats["crossing_pairs"] is None and r.stats["delta_d"] == 0.2


def test_close_pairs_equal_brute_force():
    rng = np.random.default_rng(3)
    p = rng.random((300, 3)) * [2.0, 1.0, 0.5]
    i, j = ht._close_pairs(p, 0.13)
    got = set(zip(i.tolist(), j.tolist()))
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    bi, bj = np.nonzero(np.triu(d < 0.13, 1))
    assert got == set(zip(bi.tolist(), bj.tolist()))
    assert len(got) == len(i)


def _brute_pairs(p, radius):
    """Every pair i < j with the exact test of the pair search, ``einsum(diff, diff) < r²``."""
    i, j = np.triu_indices(len(p), 1)
    diff = p[i] - p[j]
    near = np.einsum("ij,ij->i", diff, diff) < radius * radius
    return set(zip(i[near].tolist(), j[near].tolist()))


def test_close_pairs_decide_borderline_distances_exactly():
    """Issue 46: the grid kernel sums the squared distance in its own order and leaves pairs
    within PAIR_MARGIN of the radius to the NumPy test; on a lattice whose spacing is the
    radius (distance² = r² exactly: not a pair) and with points one ulp either side of it, the
    pairs are the exact test's (a kernel that kept borderline pairs on its own sum fails)."""
    r = 0.25
    g = np.arange(6) * r
    p = np.stack(np.meshgrid(g, g, g[:3], indexing="ij"), axis=-1).reshape(-1, 3)
    rng = np.random.default_rng(46)
    nudge = rng.integers(-2, 3, size=p.shape)
    p = p + nudge * np.spacing(np.maximum(np.abs(p), r))
    p = p[rng.permutation(len(p))]
    i, j = ht._close_pairs(p, r)
    got = set(zip(i.tolist(), j.tolist()))
    assert len(got) == len(i)
    want = _brute_pairs(p, r)
    assert 0 < len(want) and got == want


def test_defaults_carving_grows_with_depth_difference_on_fig1_family():
    rho, delta_d = fig1_defaults()
    carved = carved_by_strip(rho, delta_d)
    assert strictly_increasing(carved), carved
    # Eq. 3 unsaturated: the gap, and with it the carving, grows about linearly in Δw
    assert carved[4] > 1.8 * carved[0], carved


def test_planted_saturating_delta_d_fails_the_growth_test():
    """The former default δd = 10 % of the depth range (0.05 here) saturates Eq. 3."""
    rho, _ = fig1_defaults()
    carved = carved_by_strip(rho, 0.05)
    assert not strictly_increasing(carved), carved
    assert len(set(carved)) == 1


def perpendicular_strips(deltas=(0.1, 0.25, 0.4), xs=(-0.5, 0.0, 0.5)):
    """A white square (u, v, 0, 0) seen face-on, crossed at x = x_i by strips (x_i, b, 0.5a, Δ_i)
    perpendicular to it, Δ_i nearer in 4D."""
    parts = [h.uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1),
                          (-1, 1), 17, 17, color=(1.0, 1.0, 1.0))]
    for x0, w in zip(xs, deltas):
        def f(a, b, x0=x0, w=w):
            return np.stack([np.full_like(a, x0), 0.7 * b, 0.5 * a, np.full_like(a, w)], axis=-1)
        parts.append(h.uv_surface(f, (-0.5, 0.5), (-1, 1), 4, 9, color=(1.0, 0.2, 0.2)))
    return h.merge(parts)


def gap_half_widths(r, xs, rows):
    """Measured half-width (px) of the non-white run around each x_i, averaged over rows."""
    img = r.image
    W = img.shape[1]
    (bx0, by0, _), (bx1, by1, _) = r.bounds
    px = (bx1 - bx0) / W
    xc = bx0 + (np.arange(W) + 0.5) * px
    white = img.min(axis=2) > 0.6
    out = []
    for x0 in xs:
        window = np.abs(xc - x0) < 0.25
        widths = [np.count_nonzero(~white[row, window]) / 2.0 for row in rows]
        out.append(float(np.mean(widths)))
    return np.array(out), px


@pytest.mark.parametrize("delta_d", [None, 0.05], ids=["defaults", "planted-saturating"])
def test_gap_half_width_next_to_a_crossing_follows_eq3(delta_d):
    deltas, xs = (0.1, 0.25, 0.4), (-0.5, 0.0, 0.5)
    s = perpendicular_strips(deltas, xs)
    # hard surface threshold: the strips are seen edge-on, and an anti-aliasing fringe would
    # widen their own footprint (not the gap)
    r = h.render_halos(s, width=320, height=320, slices=48,
                       halos=h.Halos(delta_d=delta_d, antialias=0.0))
    rho, dd, dt = r.stats["rho"], r.stats["delta_d"], 0.3
    H = r.image.shape[0]
    rows = range(H // 2 - 20, H // 2 + 20, 4)          # |v| well inside the strips
    measured, px = gap_half_widths(r, xs, rows)
    predicted = np.array([rho * min(1.0, dt + d / dd) for d in deltas]) / px
    # Eq. 3's geometry holds for any δd: measured within ±1 px of ρ·min(1, δt + Δδ/δd)
    np.testing.assert_allclose(measured, predicted, atol=1.0)
    if delta_d is None:
        # with the defaults the three gaps differ (depth-dependent), by more than a pixel
        assert rho / px > 6
        assert np.all(np.diff(measured) > 1.0), measured
    else:
        # the planted saturating δd: all three gaps are ρ wide, the depth is lost
        assert np.ptp(measured) <= 1.0, measured
