"""render_halos_pair (issue 27): the halos-on and halos-off pictures of a figure from one
slicing are the two render_halos calls' results, bit for bit."""

import numpy as np
import pytest

import refraster.halos4d as h
import refraster.halos4d.render as hr
from refraster.gallery import halos4d as g
from refraster.halos4d import HaloStyle, Halos, render_halos_pair


def _same(a, b):
    assert a.image.dtype == b.image.dtype and a.alpha.dtype == b.alpha.dtype
    return (np.array_equal(a.image, b.image) and np.array_equal(a.alpha, b.alpha)
            and a.stats == b.stats and np.array_equal(a.bounds, b.bounds)
            and np.array_equal(a.centres, b.centres)
            and ((a.volume is None and b.volume is None) or np.array_equal(a.volume, b.volume)))


#: the gallery's kinds of figure: plain, halo volume drawn, boundaries, stereo + boundaries
FIGURES = ["fig1bc", "fig3e", "fig5ad", "fig8"]


@pytest.mark.parametrize("name", FIGURES)
def test_pair_is_the_two_renders_bit_for_bit(name):
    fig = {f.name: f for f in g.figures(quick=True)}[name]
    kw = dict(width=64, height=48, slices=24, view=fig.view, style=fig.style)
    on, off = render_halos_pair(fig.surface, halos=fig.halos, **kw)
    ref_on = h.render_halos(fig.surface, halos=fig.halos, **kw)
    ref_off = h.render_halos(fig.surface, halos=fig.halos.replace(enabled=False), **kw)
    assert _same(on, ref_on) and _same(off, ref_off)
    # the two differ (else the test could not tell them apart), and the swap is caught
    assert not _same(on, ref_off) and not _same(off, ref_on)


def test_pair_with_volume_and_the_reference_engine():
    s = h.figure1_scene(8)
    kw = dict(width=40, height=32, slices=16, style=HaloStyle(halo_opacity=0.3), volume=True)
    for engine in ("fused", "reference"):
        on, off = render_halos_pair(s, engine=engine, **kw)
        assert _same(on, h.render_halos(s, engine=engine, **kw))
        assert _same(off, h.render_halos(s, engine=engine, halos=Halos(enabled=False), **kw))


def test_pair_refuses_halos_off():
    with pytest.raises(ValueError, match=r"halos\.enabled must be True"):
        render_halos_pair(h.figure1_scene(6), halos=Halos(enabled=False))
    with pytest.raises(TypeError, match=r"^halos must be a refraster\.halos4d\.Halos, got bool"):
        h.render_halos(h.figure1_scene(6), halos=False)
    with pytest.raises(TypeError, match=r"^halos\.enabled must be a bool, got str"):
        Halos(enabled="both")


def test_a_wrong_twin_is_caught(monkeypatch):
    """Planted fault: the twin drawn with the halos' fill parameters (the on picture reused)
    is not the halos-off render, and the comparison above says so."""
    real = hr._draw

    def reuse(geo, views, bounds, centres, width, height, variants, *rest):
        return real(geo, views, bounds, centres, width, height, [variants[0]] * len(variants),
                    *rest)
    monkeypatch.setattr(hr, "_draw", reuse)
    s = h.figure1_scene(8)
    kw = dict(width=40, height=32, slices=16)
    _, off = render_halos_pair(s, **kw)
    monkeypatch.undo()
    assert not _same(off, h.render_halos(s, halos=Halos(enabled=False), **kw))
