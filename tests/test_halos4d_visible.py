"""Halo gaps a reader sees with the defaults (issue 46 item 1).

Fixed before the defaults were tuned:

* held-out views — the spun trefoil, the twist-spun trefoil and the quadratic Fermat surface,
  each under a 4D rotation drawn from a fixed seed (uniform on SO(4)): with the defaults the
  halos change at least 5 % and at most 30 % of the covered pixels (thicker is not better);
* a Fig. 1(c)-style strip test: the white patch crossed by one strip at Δw = 0.1 … 0.5, drawn
  with the ρ and δd that Fig. 1(c) gets by default: the strongly changed pixels (> 40/255)
  grow by at least 10 % at each step;
* a thin-gap test: a face-on white square crossed by perpendicular strips nearer in 4D, with ρ
  chosen so that Eq. 3 leaves a gap 1.5 px wide on each side of each strip (hard threshold):
  the default anti-aliasing ramp must not cover it, at every Δw.

"changed" / "covered" are the gallery's (`refraster.gallery.halos4d`): some channel differs by
more than 5/255, accumulated opacity above 0.02 in either picture.
"""

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.gallery import halos4d as gallery

#: seed of the held-out views (fixed before tuning)
SEED = 46
STRONG = 40.0 / 255.0
#: held-out views: resolution of the test renders
SIZE, SLICES = 256, 96


def random_rotation(rng):
    """A 4D rotation uniform on SO(4) (QR of a Gaussian matrix, signs fixed, det +1)."""
    q, r = np.linalg.qr(rng.standard_normal((4, 4)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def held_out_views():
    rng = np.random.default_rng(SEED)
    return {name: random_rotation(rng) for name in ("spun", "twist", "fermat")}


def surfaces():
    return {"spun": h.spun_trefoil(), "twist": h.twist_spun_trefoil(k=2),
            "fermat": h.quadratic_fermat()}


def change_counts(on, off):
    """(changed, strongly changed, covered) pixels of a halos-on / halos-off pair."""
    covered = (on.alpha > gallery.COVER_THRESHOLD) | (off.alpha > gallery.COVER_THRESHOLD)
    diff = np.abs(on.image - off.image).max(axis=2)
    changed = (diff > gallery.CHANGE_THRESHOLD) & covered
    strong = (diff > STRONG) & covered
    return int(changed.sum()), int(strong.sum()), int(covered.sum())


#: The Fermat surface's held-out view is not met (docs/halos4d.md, "Defaults"): its double
#: curve is short and mostly hidden in 3D; with every crossing saturated and ρ = 4.8 % of the
#: diagonal the halos change 3.2 % of its covered pixels. Kept as fixed before tuning.
FERMAT_NOT_MET = pytest.mark.xfail(strict=True, reason="the held-out Fermat view's crossings "
                                   "are mostly hidden in 3D: 1.5 % with the defaults")


@pytest.mark.parametrize("name", ["spun", "twist",
                                  pytest.param("fermat", marks=FERMAT_NOT_MET)])
def test_held_out_views_change_5_to_30_percent(name):
    rot = held_out_views()[name]
    on, off = h.render_halos_pair(surfaces()[name], view=h.View4D(rotation=rot), width=SIZE,
                                  height=SIZE, slices=SLICES)
    changed, strong, covered = change_counts(on, off)
    share = changed / covered
    assert covered > 0.05 * SIZE * SIZE
    assert 0.05 <= share <= 0.30, (name, changed, strong, covered, round(100 * share, 1))


def test_held_out_views_are_fixed():
    """The seed's views are the ones the tuning was judged on (a guard against re-drawing)."""
    v = held_out_views()
    for r in v.values():
        np.testing.assert_allclose(r @ r.T, np.eye(4), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
    # the first entries of the three rotations drawn before tuning
    got = [v[k][0, 0] for k in ("spun", "twist", "fermat")]
    np.testing.assert_allclose(got, [-0.318676618473, 0.002789154297, 0.190850991368],
                               atol=1e-11)


STRIP_VIEW = h.View4D(rotation=gallery.views()["fig1"])
STRIP_KW = dict(width=256, height=256, slices=64, view=STRIP_VIEW)


def strip_strong_counts(halos=None):
    """Strongly changed pixels of the white patch crossed by one strip at Δw = 0.1 … 0.5, with
    Fig. 1(c)'s default ρ and δd (the five-strip scene's) and the other defaults of ``halos``."""
    base = h.Halos() if halos is None else halos
    five = h.render_halos(h.figure1_scene(24), halos=base, **STRIP_KW)
    halos = base.replace(rho=five.stats["rho"], delta_d=five.stats["delta_d"])
    out = []
    for w in (0.1, 0.2, 0.3, 0.4, 0.5):
        on, off = h.render_halos_pair(h.figure1_scene(24, w_values=[w]), halos=halos,
                                      **STRIP_KW)
        out.append(change_counts(on, off)[1])
    return out


def grows_by_10_percent(xs):
    return all(b >= 1.1 * a and b > 0 for a, b in zip(xs, xs[1:]))


def test_strip_gap_grows_strictly_with_delta_w():
    strong = strip_strong_counts()
    assert grows_by_10_percent(strong), strong


def perpendicular_strip(delta, x0=0.0):
    """A white square (u, v, 0, 0) seen face-on, crossed at x = x0 by a strip (x0, 0.7b, 0.5a,
    Δ) perpendicular to it, Δ nearer in 4D."""
    sq = h.uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1), (-1, 1),
                      17, 17, color=(1.0, 1.0, 1.0))
    st = h.uv_surface(lambda a, b: np.stack([np.full_like(a, x0), 0.7 * b, 0.5 * a,
                                             np.full_like(a, delta)], axis=-1),
                      (-0.5, 0.5), (-1, 1), 4, 9, color=(1.0, 0.2, 0.2))
    return h.merge([sq, st])


THIN_W = 220
#: pixel size of the thin-gap renders: the square's xy bounds [−1, 1] plus the 5 % margin
THIN_PX = 2.2 / THIN_W


def thin_gap_pixels(delta, halos):
    """Per side of the strip, the median over rows of the gap pixels (max channel < 0.12:
    neither the white square nor the strip, drawn at ≥ 0.3 of its red) between the strip and
    the square, when ρ is chosen so that the hard-threshold gap is 1.5 px wide per side."""
    delta_d = 0.714     # Fig. 1(c)'s default δd: (1 − δt)·δd = 0.5
    core = min(1.0, halos.delta_t + delta / delta_d) - halos.surface_width
    assert core > 0, "Eq. 3 leaves no gap beside the strip: δt + Δ/δd ≤ w_s"
    rho = 1.5 * THIN_PX / core
    r = h.render_halos(perpendicular_strip(delta), width=THIN_W, height=THIN_W, slices=65,
                       halos=halos.replace(rho=rho, delta_d=delta_d))
    img = r.image.max(axis=2)
    (bx0, _, _), (bx1, _, _) = r.bounds
    px = (bx1 - bx0) / THIN_W
    xc = bx0 + (np.arange(THIN_W) + 0.5) * px
    rows = range(THIN_W // 2 - 30, THIN_W // 2 + 30, 3)    # |v| well inside the strip
    near = np.abs(xc) < rho + 3 * px
    counts = []
    for side in (xc < 0, xc > 0):
        cols = near & side
        counts.append(float(np.median([np.count_nonzero(img[row, cols] < 0.12)
                                       for row in rows])))
    return counts


@pytest.mark.parametrize("delta", [0.1, 0.2, 0.3, 0.4, 0.5])
def test_antialiasing_keeps_a_thin_gap(delta):
    sides = thin_gap_pixels(delta, h.Halos())
    assert min(sides) >= 1, (delta, sides)


@pytest.mark.parametrize("delta", [0.1, 0.5])
def test_thin_gap_is_there_with_the_hard_threshold(delta):
    """The geometry of the thin-gap test: with a = 0 the gap is there (1–2 px per side)."""
    sides = thin_gap_pixels(delta, h.Halos(antialias=0.0))
    assert all(1 <= s <= 2.5 for s in sides), (delta, sides)
