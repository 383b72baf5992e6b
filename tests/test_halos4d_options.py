"""Halo colour and opacity (Fig. 3e), halo boundaries (Fig. 8's green), anti-aliasing from t
(Sec. 4.6): issue 21 item 3. Analytic expectations on face-on scenes; both engines agree."""

import sys

import numpy as np
import pytest

import refraster.halos4d as h
from refraster.halos4d import HaloStyle, Halos, View4D
from refraster.halos4d import render as hr

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from test_halos4d_defaults import gap_half_widths, perpendicular_strips  # noqa: E402


def square(tilt=0.0):
    return h.uv_surface(lambda u, v: np.stack([u, v, tilt * u, 0 * u], axis=-1), (-1, 1),
                        (-1, 1), 4, 4)


HALOS = Halos(rho=0.08, delta_d=1.0, delta_t=0.2)
KW = dict(width=48, height=40, slices=20, view=View4D(rotation=h.compose(("zx", 0.5),
                                                                         ("yz", -0.6))))


@pytest.mark.parametrize("halos, style", [
    (HALOS, HaloStyle(halo_opacity=0.4)), (HALOS, HaloStyle(boundary_color=(0, 1, 0))),
    (HALOS.replace(antialias=0.1), HaloStyle()),
    (HALOS.replace(antialias=0.15), HaloStyle(halo_opacity=0.3, boundary_color=(0, 1, 0)))])
def test_options_engines_bit_identical(halos, style):
    s = h.figure1_scene(10)
    a = h.render_halos(s, volume=True, halos=halos, style=style, **KW)
    b = h.render_halos(s, volume=True, engine="reference", halos=halos, style=style, **KW)
    assert a.image.tobytes() == b.image.tobytes()
    np.testing.assert_array_equal(a.volume, b.volume)


def test_default_draws_no_halo_and_halo_opacity_colours_exactly_the_halo_voxels():
    s = h.figure1_scene(10)
    off = h.render_halos(s, volume=True, halos=HALOS, **KW)
    assert off.image.tobytes() == h.render_halos(s, halos=HALOS, style=HaloStyle(
        halo_opacity=0.0), **KW).image.tobytes()
    on = h.render_halos(s, volume=True, halos=HALOS,
                        style=HaloStyle(halo_opacity=0.5, halo_color=(0.5, 0.5, 0.5)), **KW)
    np.testing.assert_array_equal(on.volume, off.volume)
    halo_px = np.isin(off.volume, (hr.HALO, hr.CARVED)).any(axis=0)
    changed = np.abs(on.image - off.image).max(axis=2) > 0
    assert halo_px.sum() > 50
    np.testing.assert_array_equal(changed, halo_px)
    # halos off: no halo drawn, whatever halo_opacity says
    no_halos = HALOS.replace(enabled=False)
    a = h.render_halos(s, halos=no_halos, style=HaloStyle(halo_opacity=0.5), **KW)
    assert a.image.tobytes() == h.render_halos(s, halos=no_halos, **KW).image.tobytes()


def test_face_on_halo_shell_accumulates_its_opacity():
    """Column through a face-on square: back halo, surface, front halo. Accumulated alpha
    1 − (1 − h)(1 − o) for halo opacity h and surface opacity o, for any slice count."""
    got = []
    for n in (16, 64):
        r = h.render_halos(square(), width=24, height=24, slices=n, view=View4D(margin=0.2),
                           halos=Halos(rho=0.2, surface_width=0.3),
                           style=HaloStyle(opacity=0.8, halo_opacity=0.5))
        got.append(float(r.alpha[12, 12]))
    np.testing.assert_allclose(got, 1 - 0.5 * 0.2, atol=0.06)


def test_boundary_is_a_rim_of_width_b_rho_inside_each_hole():
    deltas, xs = (0.1, 0.25, 0.4), (-0.5, 0.0, 0.5)
    s = perpendicular_strips(deltas, xs)
    b = 0.25
    kw = dict(width=320, height=320, slices=48, halos=Halos(antialias=0.0))
    plain = h.render_halos(s, **kw)
    rim = h.render_halos(s, style=HaloStyle(boundary_color=(0.0, 1.0, 0.0), boundary_width=b),
                         **kw)
    H = plain.image.shape[0]
    rows = range(H // 2 - 20, H // 2 + 20, 4)
    g0, px = gap_half_widths(plain, xs, rows)
    g1, _ = gap_half_widths(rim, xs, rows)
    # the rim is drawn inside the hole: the hole (non-white run) keeps its size
    np.testing.assert_allclose(g1, g0, atol=0.5)
    img = rim.image
    green = (img[..., 1] > 0.5) & (img[..., 0] < 0.2) & (img[..., 2] < 0.2)
    assert not ((plain.image[..., 1] > 0.5) & (plain.image[..., 0] < 0.2)).any()
    (bx0, _, _), (bx1, _, _) = rim.bounds
    xc = bx0 + (np.arange(img.shape[1]) + 0.5) * px
    rho = rim.stats["rho"]
    for x0, half in zip(xs, g0 * px):
        win = np.abs(xc - x0) < 0.25
        for row in rows:
            gx = np.abs(xc[win][green[row, win]] - x0)
            # two bands (one each side), each b·ρ wide, ending at the hole's edge
            assert abs(len(gx) / 2 - b * rho / px) <= 1.0, (x0, len(gx))
            assert np.all(gx <= half + px) and np.all(gx >= half - b * rho - px)


def test_antialias_keeps_opacity_and_smooths_slice_moire():
    """A tilted square, core about one slice thick: the hard threshold |2t − 1| < w_s bands
    (and at steeper tilt misses voxels entirely); coverage from t keeps the mean opacity."""
    kw = dict(width=64, height=64, view=View4D(margin=0.2), style=HaloStyle(opacity=0.8))
    soft_halos = Halos(rho=0.1, surface_width=0.3)                          # default a = w_s
    hard_halos = soft_halos.replace(antialias=0.0)
    inner = (slice(16, 48), slice(16, 48))
    hard = h.render_halos(square(0.37), slices=16, halos=hard_halos, **kw).alpha[inner]
    soft = h.render_halos(square(0.37), slices=16, halos=soft_halos, **kw).alpha[inner]
    assert abs(soft.mean() - hard.mean()) < 0.05 * hard.mean()
    assert soft.std() < 0.5 * hard.std(), (soft.std(), hard.std())
    hard = h.render_halos(square(0.8), slices=20, halos=hard_halos, **kw).alpha[inner]
    soft = h.render_halos(square(0.8), slices=20, halos=soft_halos, **kw).alpha[inner]
    assert hard.min() == 0.0 and soft.min() > 0.7
    assert soft.std() < 0.1 * hard.std()


def test_option_bad_inputs():
    for name, bad in (("halo_opacity", 1.0), ("halo_opacity", -0.1), ("boundary_width", 0.0),
                      ("boundary_width", 1.0), ("halo_color", (1, 1)),
                      ("boundary_color", (1, 1))):
        with pytest.raises(ValueError, match=rf"^style\.{name} "):
            HaloStyle(**{name: bad})
    for bad in (0.5, float("nan")):
        with pytest.raises(ValueError, match=r"^halos\.antialias must"):
            Halos(antialias=bad)
