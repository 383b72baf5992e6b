"""The halo gallery: every figure of the paper as halos off | on | changed pixels (issue 21)."""

from types import SimpleNamespace

import numpy as np

import refraster.gallery.halos4d as g


def fake(image, alpha):
    return SimpleNamespace(image=np.asarray(image, np.float32), alpha=np.asarray(alpha, np.float32))


def test_change_share_counts_covered_pixels_that_change():
    off = fake(np.zeros((2, 3, 3)), [[0, 1, 1], [1, 1, 0]])
    img = np.zeros((2, 3, 3))
    img[0, 1, 2] = 0.5              # covered, changed
    img[1, 0, 0] = 4.0 / 255.0      # covered, below the threshold
    img[1, 2, 1] = 0.9              # newly covered by the halo picture, changed
    on = fake(img, [[0, 1, 1], [1, 1, 0.5]])
    assert g.change_share(on, off) == (2, 5)
    t = g.triptych(on, off)
    assert t.shape == (2, 3 * 3 + 2 * g.GAP, 3)
    diff = t[:, -3:, 0]
    np.testing.assert_array_equal(diff == 1.0, [[False, True, False], [False, False, True]])
    assert g.triptych(on, off, stacked=True).shape == (3 * 2 + 2 * g.GAP, 3, 3)


def test_every_figure_is_rendered_with_its_twin(tmp_path):
    m = {}
    items = g.render(tmp_path, quick=True, measurements=m)
    names = [f[0] for f in g.figures(quick=True)]
    assert names == ["fig1a", "fig1bc", "fig3e", "fig5ad", "fig5d_dark", "fig5d_open",
                     "fig5d_translucent",
                     "fig5d_diagram",
                     "fig5b", "fig6a",
                     "fig6b", "fig7", "fig8"]
    assert [i.filename for i in items] == [f"halos4d_{n}.png" for n in names]
    for item, n in zip(items, names):
        assert (tmp_path / item.filename).stat().st_size > 1000
        changed, covered, stats = m[n]
        assert covered > 0 and 0 < changed <= covered, n
        assert f"{100 * changed / covered:.1f} %" in item.caption


def test_fig5d_gaps_are_drawn_dark_and_pure_halos_show_none():
    """Fig. 5(d) with dark gaps (`fig5d_dark`, issue 21): with the gaps drawn dark, a good share of the pixels the halos
    change are near-black (the knot diagram's breaks); with the pure halos (the planted
    "wrong" picture, as before) the same gaps only shift the shade and none is dark."""
    import refraster.halos4d as h
    (fig,) = [f for f in g.figures(quick=True) if f.name == "fig5d_dark"]
    assert fig.style.boundary_color == g.GAP_DARK and fig.halos.rho == g.KNOT_RHO
    kw = dict(width=128, height=128, slices=48, view=fig.view)
    off = h.render_halos(fig.surface, halos=fig.halos.replace(enabled=False), **kw)

    def dark_share(style):
        on = h.render_halos(fig.surface, halos=fig.halos, style=style, **kw)
        covered = (on.alpha > g.COVER_THRESHOLD) | (off.alpha > g.COVER_THRESHOLD)
        changed = (np.abs(on.image - off.image).max(axis=2) > g.CHANGE_THRESHOLD) & covered
        return float((on.image.mean(axis=2)[changed] < 0.1).mean()), int(changed.sum())

    dark, n = dark_share(fig.style)
    assert n > 500 and dark > 0.2, (dark, n)
    dark, n = dark_share(fig.style.replace(boundary_color=None, boundary_width=0.15))
    assert n > 300 and dark == 0.0, (dark, n)
