"""The gallery pictures show the papers' methods (issue 46, item 5): the clip-surface pictures'
edges are Nienhaus & Döllner's operator (shown beside the "clean" preset), and the galleon
(Burns & Finkelstein Fig. 1) shows ghost lines."""

import numpy as np

import refraster as rr
from refraster.camera import frame_bounds
from refraster.scenes import solid


def test_the_galleon_shows_ghost_lines_of_its_gun_deck():
    from refraster.gallery.cutaway import galleon_frames
    ghost_px = [int((fb.ghost > 0).sum()) for fb in galleon_frames(96, True)]
    assert min(ghost_px) >= 20, ghost_px
    # the hull alone (the picture before issue 46) gives none: a smooth ellipsoid has no
    # creases, and its silhouettes are not removed (what the caption says)
    assert [int((fb.ghost > 0).sum()) for fb in galleon_frames(96, True, deck=False)] == [0] * 3


def test_clip_surface_edges_are_the_papers_operator_beside_clean():
    from refraster.edges import edge_map
    from refraster.edges.npr import composite
    from refraster.gallery import clipsurface as g
    crank = solid("crank", quick=True)
    fb = rr.render(crank, **frame_bounds(crank.bounds, width=96, height=72).kwargs)
    picture = g._edges_beside(fb, fb.color)
    left, gap, right = picture[:, :96], picture[:, 96:100], picture[:, 100:]
    colours = dict(inner_color=(1.0, 1.0, 1.0), profile_color=(0.0, 0.0, 0.0))
    np.testing.assert_array_equal(left, composite(fb.color, edge_map(fb), **colours))
    np.testing.assert_array_equal(right, composite(fb.color, edge_map(fb, preset="clean"),
                                                   **colours))
    assert np.all(gap == 1.0) and not np.array_equal(left, right)
    # the single pictures default to the paper's operator too
    np.testing.assert_array_equal(g._edges(fb, fb.color), left)
