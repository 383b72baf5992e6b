"""D's lower bound is a proof, not a measurement (issue 20, item 4; docs/tolerance.md, "Cutaways"):
``refraster.golden.allowances.cutaway.interval_flood`` bounds from below every jump flood over every
seed image between the smallest and the largest. Brute force: hundreds of random seed images
(sure seeds always, uncertain seeds at random, every depth drawn from its interval, the slope
affine in the depth as perspective compensation makes it) flooded by refraster's own
``jump_flood`` with every schedule; none may fall below the bound at any pixel. Exact ties and
seeds that displace one another are frequent at this size (a 24×20 image, seeds in two blobs).
"""

import numpy as np
import pytest

from refraster.cutaway.flood import VARIANTS, jump_flood, step_schedule
from refraster.golden.allowances.cutaway import interval_flood

H, W = 20, 24
S = (0.1, 0.08)              # row, column spacing (tangent units)
A, B = 1.3, 0.6              # m(z) = A − B·z: affine and decreasing, as −(P22 + z)/tan θ


def _problem(seed):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    blob = ((yy - 6) ** 2 + (xx - 7) ** 2 <= 9) | ((yy - 13) ** 2 + (xx - 16) ** 2 <= 12)
    rim = blob & ~(((yy - 6) ** 2 + (xx - 7) ** 2 <= 4) | ((yy - 13) ** 2 + (xx - 16) ** 2 <= 6))
    sure = blob & ~(rim & (rng.random((H, W)) < 0.5))
    maybe = blob & ~sure
    z_lo = np.where(blob, rng.uniform(-0.2, 0.6, (H, W)), 0.0)
    # a few wide intervals, as at a silhouette; ties: equal depths along a row
    width = np.where(rng.random((H, W)) < 0.1, 0.3, rng.uniform(0.0, 0.02, (H, W)))
    z_lo[8] = 0.25
    width[8] = 0.0
    z_hi = z_lo + width
    return rng, sure, maybe, z_lo, z_hi


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("seed", [1, 2])
def test_no_seed_image_floods_below_the_bound(variant, seed):
    rng, sure, maybe, z_lo, z_hi = _problem(seed)
    m_lo, m_hi = A - B * z_lo, A - B * z_hi
    bound, untracked, several = interval_flood(
        z_lo, z_hi, sure, maybe, m_lo, m_hi, float(m_lo.max()), S[0], S[1],
        step_schedule(H, W, variant), 1e-12)
    assert np.isfinite(bound).all()
    worst = np.inf
    gaps = []
    for _ in range(150):
        seeds = sure | (maybe & (rng.random((H, W)) < 0.5))
        t = rng.random((H, W))
        # depths at the ends of their intervals half of the time (the extremes matter)
        t = np.where(rng.random((H, W)) < 0.5, np.round(t), t)
        z = np.where(seeds, z_lo + t * (z_hi - z_lo), -np.inf)
        d = jump_flood(z, np.where(seeds, A - B * np.where(seeds, z, 0.0), 0.0), variant=variant,
                       sampling=S)
        worst = min(worst, float((d - bound).min()))
        gaps.append(float(np.median(d - bound)))
    assert worst >= 0.0, worst
    # not vacuous: the bound is close to the floods (median gap below the depth uncertainty)
    assert np.median(gaps) < 0.05, np.median(gaps)
    assert several.any()    # ties and uncertain seeds do occur here


def test_the_bound_is_the_flood_itself_without_uncertainty():
    """One seed image, no uncertainty, no float slack: the bound is the flood, bit for bit."""
    _, sure, _, z_lo, _ = _problem(3)
    for variant in VARIANTS:
        bound, untracked, _ = interval_flood(
            z_lo, z_lo, sure, np.zeros_like(sure), A - B * z_lo, A - B * z_lo, A + B,
            S[0], S[1], step_schedule(H, W, variant), 0.0)
        d = jump_flood(np.where(sure, z_lo, -np.inf), A - B * z_lo, variant=variant, sampling=S)
        assert not untracked.any()
        np.testing.assert_allclose(bound, d, rtol=0, atol=1e-15)


@pytest.mark.parametrize("variant", VARIANTS)
def test_no_directional_flood_falls_below_the_bound(variant):
    """The same with the floor constraint (D-C7): a second, steeper slope toward each seed's
    floor side, blended by the direction only (C stays affine and increasing in z)."""
    rng, sure, maybe, z_lo, z_hi = _problem(4)
    ang = rng.uniform(0, 2 * np.pi, (H, W))
    n = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    af, bf = 3.5, 1.2
    m_lo, m_hi = A - B * z_lo, A - B * z_hi
    f_lo, f_hi = af - bf * z_lo, af - bf * z_hi
    bound, untracked, _ = interval_flood(
        z_lo, z_hi, sure, maybe, m_lo, m_hi, float(f_lo.max()), S[0], S[1],
        step_schedule(H, W, variant), 1e-12, floor=(f_lo, f_hi, n[..., 0], n[..., 1]))
    assert np.isfinite(bound).all() and not untracked.any()
    worst = np.inf
    for _ in range(100):
        seeds = sure | (maybe & (rng.random((H, W)) < 0.5))
        t = rng.random((H, W))
        t = np.where(rng.random((H, W)) < 0.5, np.round(t), t)
        z = np.where(seeds, z_lo + t * (z_hi - z_lo), -np.inf)
        zz = np.where(seeds, z, 0.0)
        d = jump_flood(z, A - B * zz, variant=variant, sampling=S, floor_slope=af - bf * zz,
                       floor_normal=n)
        worst = min(worst, float((d - bound).min()))
    assert worst >= 0.0, worst
