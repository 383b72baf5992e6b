"""Options of the Fig. 5(d) knot-diagram picture (`fig5d_diagram`): a band of the spun sphere
around one meridian (`spun_trefoil(band=)`), colours by 4D depth (`colored_by_depth`) and the
headlight's ambient part (`render_halos(style=HaloStyle(ambient=))`). Analytic expectations."""

import colorsys

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import surfaces as hs


def test_band_is_the_spun_sphere_between_two_meridians():
    """Every vertex is S(s, φ) with |φ| ≤ b, both edges φ = ±b are reached, and each vertex's
    distance r to the spinning plane's axis is that of an arc point (the arc is only turned)."""
    b = 0.15
    s = h.spun_trefoil(120, 6, band=b)
    x, w = s.vertices[:, 0], s.vertices[:, 3]
    r = np.hypot(hs.SPUN_XP - x, w)
    phi = np.arctan2(w, hs.SPUN_XP - x)
    inner = r > 1e-9
    assert np.abs(phi[inner]).max() == pytest.approx(b, abs=1e-12)
    assert phi[inner].min() == pytest.approx(-b, abs=1e-12)
    arc = hs.trefoil_arc()[0]
    # (y, z, r) of every vertex lies on the arc's (y, z, Xp − x) polyline (to its sampling)
    ref = np.column_stack([arc[:, 1], arc[:, 2], hs.SPUN_XP - arc[:, 0]])
    got = np.column_stack([s.vertices[:, 1], s.vertices[:, 2], r])
    d = np.min(np.linalg.norm(got[:, None, :] - ref[None, ::4, :], axis=2), axis=1)
    assert d.max() < 0.02
    assert s.n_faces == 2 * (120 - 2) * (6 - 1)


@pytest.mark.parametrize("bad", [0.0, -0.1, 2.0, float("nan")])
def test_band_rejects_bad_widths(bad):
    with pytest.raises(ValueError, match="band"):
        h.spun_trefoil(40, 4, band=bad)


def test_band_and_cut_open_exclude_each_other():
    with pytest.raises(ValueError, match="band and cut_open"):
        h.spun_trefoil(40, 4, band=0.1, cut_open=True)


def test_colored_by_depth_runs_from_red_near_to_blue_far():
    """The vertex nearest in 4D (largest rotated w, δ = e − w) is pure red, the farthest the
    hue 0.66 (blue); in between the hue is linear in w (colorsys as the oracle)."""
    rot = h.compose(("zw", np.pi / 2), ("zx", 0.3))
    s = h.colored_by_depth(h.spun_trefoil(60, 8), rot, saturation=0.85)
    w = (s.vertices @ rot.T)[:, 3]
    q = (w - w.min()) / (w.max() - w.min())
    for k in [int(np.argmax(w)), int(np.argmin(w)), 7, 100, 333]:
        want = colorsys.hsv_to_rgb(0.66 * (1 - q[k]), 0.85, 1.0)
        np.testing.assert_allclose(s.colors[k], want, atol=1e-12)
    np.testing.assert_allclose(s.colors[int(np.argmax(w))], [1.0, 0.15, 0.15], atol=1e-12)
    with pytest.raises(ValueError, match="saturation"):
        h.colored_by_depth(s, rot, saturation=1.5)
    with pytest.raises(ValueError, match="rotation"):
        h.colored_by_depth(s, np.eye(3))


def test_ambient_scales_a_tilted_sheet_by_the_headlight_formula():
    """A white square tilted by 60° (|n̂_z| = 0.5), seen along z: its colour with ambient a is
    a + (1 − a)·0.5 times its colour with a = 1 (unlit), pixel for pixel; the default is 0.3."""
    sq = h.uv_surface(lambda u, v: np.stack([u, v, np.sqrt(3.0) * u, 0 * u], axis=-1),
                      (-1, 1), (-1, 1), 4, 4)
    kw = dict(width=40, height=40, slices=32, halos=h.Halos(rho=0.05))
    flat = h.render_halos(sq, style=h.HaloStyle(ambient=1.0), **kw)
    inside = flat.alpha > 0.5
    assert inside.sum() > 200
    for a in (0.0, 0.3, 0.7):
        img = h.render_halos(sq, style=h.HaloStyle(ambient=a), **kw).image
        np.testing.assert_allclose(img[inside], (a + (1 - a) * 0.5) * flat.image[inside],
                                   rtol=1e-4, atol=1e-6)
    default = h.render_halos(sq, **kw).image
    assert default.tobytes() == h.render_halos(sq, style=h.HaloStyle(ambient=0.3),
                                               **kw).image.tobytes()
    with pytest.raises(ValueError, match=r"^style\.ambient must be <= 1\.0"):
        h.HaloStyle(ambient=1.5)
