"""refraster's ``fill_rule="top-left"`` against Direct3D's top-left rule as Direct3D words it.

The oracle (:func:`naive.d3d_top_left_covered`) decides coverage in exact rational arithmetic
from the rule's definitions — a top edge is exactly horizontal and above the other edges, a left
edge is not horizontal and has the triangle on its right — in Direct3D's own render-target
coordinates (y down). refraster's rule is an integer bias on its edge functions in the picture's
y-up coordinates (``refraster/raster/rasterizer.py``, ``_edge``); the two are written
independently. Triangles with every vertex on the quarter-pixel grid put many pixel centres
exactly on edges (horizontal, vertical and slanted, and on vertices), so each of the rule's
cases decides pixels here; the frame is 16×16 (every coordinate exact in float32 and on the
1/16 px grid, so 4 and 8 sub-pixel bits snap nothing). The rule is defined as the picture is
seen, so it must hold under every window origin and NDC y direction.
"""

from __future__ import annotations

import numpy as np
import pytest

import refraster as rf
from naive import d3d_top_left_covered
from refraster import RasterState

W = H = 16
STATES = {
    "d3d12": RasterState(depth_range="zero_to_one", origin="upper_left", ndc_y="up",
                         fill_rule="top-left"),
    "vulkan_4bit": RasterState(depth_range="zero_to_one", origin="upper_left", ndc_y="down",
                               fill_rule="top-left", subpixel_bits=4),
    "gl_origin": RasterState(fill_rule="top-left"),
}


def _mesh(tri, state):
    """Direct3D render-target positions (y down) as NDC for ``state``, identity camera: every
    state draws the same picture."""
    p = np.asarray(tri, np.float64)
    x = 2.0 * p[:, 0] / W - 1.0
    y_up = 1.0 - 2.0 * p[:, 1] / H            # NDC y when it points up the picture
    y = y_up if state.ndc_y == "up" else -y_up
    return np.column_stack([x, y, np.full(3, 0.5)]), np.array([[0, 1, 2]])


def _covered(tri, state):
    fb = rf.render(_mesh(tri, state), view=np.eye(4), proj=np.eye(4), width=W, height=H,
                   raster=state)
    return fb.prim_id >= 0


def test_oracle_gives_direct3d_9s_worked_example():
    """The two triangles of "Rasterization Rules (Direct3D 9)", centres at integers there, so
    moved by +½ here: (0, 0), (5, 0), (5, 5) covers 15 pixels, (0, 5), (0, 0), (5, 5) 10 —
    the shared diagonal is the first one's left edge, its top edge counts, the right and
    bottom edges do not."""
    a = [(0.5, 0.5), (5.5, 0.5), (5.5, 5.5)]
    b = [(0.5, 5.5), (0.5, 0.5), (5.5, 5.5)]
    ca, cb = d3d_top_left_covered(a, W, H), d3d_top_left_covered(b, W, H)
    assert (ca.sum(), cb.sum()) == (15, 10)
    assert not (ca & cb).any()
    assert (ca | cb).sum() == 25
    for name, state in STATES.items():
        assert np.array_equal(_covered(a, state), ca), name
        assert np.array_equal(_covered(b, state), cb), name


def _exact_tie_triangles(n, seed):
    """Random triangles on the quarter-pixel grid, some with a horizontal or vertical edge on
    pixel centres, both windings; with how many centres lie exactly on an edge."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        v = rng.integers(0, 4 * W + 1, (3, 2)) / 4.0
        kind = len(out) % 4
        if kind == 1:                       # a horizontal edge through centres
            v[1, 1] = v[0, 1] = np.floor(v[0, 1]) + 0.5 if v[0, 1] < H else H - 0.5
        elif kind == 2:                     # a vertical edge through centres
            v[1, 0] = v[0, 0] = np.floor(v[0, 0]) + 0.5 if v[0, 0] < W else W - 0.5
        elif kind == 3:                     # every vertex on a pixel centre
            v = np.floor(v) + 0.5
            v = np.minimum(v, W - 0.5)
        if rng.random() < 0.5:
            v = v[::-1]
        out.append([tuple(p) for p in v])
    return out


def _on_edge(tri):
    from fractions import Fraction
    p = [(Fraction(x), Fraction(y)) for x, y in tri]
    count = 0
    for row in range(H):
        for col in range(W):
            q = (Fraction(2 * col + 1, 2), Fraction(2 * row + 1, 2))
            for k in range(3):
                a, b = p[k], p[(k + 1) % 3]
                if (b[0] - a[0]) * (q[1] - a[1]) == (b[1] - a[1]) * (q[0] - a[0]) \
                        and min(a[0], b[0]) <= q[0] <= max(a[0], b[0]) \
                        and min(a[1], b[1]) <= q[1] <= max(a[1], b[1]):
                    count += 1
                    break
    return count


@pytest.mark.parametrize("name", list(STATES))
def test_top_left_rule_is_direct3ds_on_exact_ties(name):
    """Every pixel of 48 triangles on the quarter-pixel grid (horizontal edges at the top and
    at the bottom, vertical edges, vertices on centres; both windings) as the oracle decides
    it, and the ties are many (a centre exactly on an edge in most triangles)."""
    state = STATES[name]
    tris = _exact_tie_triangles(48, 39)
    ties = [_on_edge(t) for t in tris]
    assert sum(t > 0 for t in ties) >= 30 and sum(ties) >= 150, ties
    for tri in tris:
        expect = d3d_top_left_covered(tri, W, H)
        got = _covered(tri, state)
        assert np.array_equal(got, expect), (name, tri, np.argwhere(got != expect)[:5])


def test_shared_edges_cover_each_centre_once():
    """A fan of four triangles around a centre, every edge through centres: under the rule each
    centre of the fan's square belongs to exactly one triangle (no crack, no double cover), in
    refraster and in the oracle alike."""
    c, r = (8.5, 8.5), 4.0
    corners = [(c[0] - r, c[1] - r), (c[0] + r, c[1] - r), (c[0] + r, c[1] + r),
               (c[0] - r, c[1] + r)]
    fan = [[c, corners[k], corners[(k + 1) % 4]] for k in range(4)]
    for name, state in STATES.items():
        got = [_covered(t, state) for t in fan]
        expect = [d3d_top_left_covered(t, W, H) for t in fan]
        assert all(np.array_equal(g, e) for g, e in zip(got, expect)), name
        inside = np.zeros((H, W), np.bool_)
        inside[4:13, 4:13] = True        # the square's centres: rows and columns 4..12
        count = np.sum(got, axis=0)
        assert (count[~inside] == 0).all() and (count[inside] <= 1).all(), name
        # the square's top and left sides are owned, its bottom and right sides are not
        assert count[4:12, 4:12].all() and not count[12, :].any() and not count[:, 12].any()
