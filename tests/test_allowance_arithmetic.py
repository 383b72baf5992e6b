"""The allowance arithmetic of ``refraster/golden/`` tested as arithmetic (issue 42, item 3).

End-to-end passes and fails say little about a constant or an interval rule: a budget twice too
wide still passes the correct candidate, and a planted fault of 0.25 still fails. Here every
number is derived by hand in the test — from a tiny scene's geometry, or from the definition of
the interval operation — and compared with what the allowance modules compute. Each test is the
killer of mutants of ``tests/mutation/mutants.py`` (module ``allowance``); the table of those
mutants is in ``docs/testing.md``.

The tiny scenes: an orthographic camera whose extent is the viewport in pixels (one world unit
per pixel, window x = world x + W/2), looking down −z from the origin, and triangles far larger
than the viewport, so that every pixel sees one plane whose eye depth, barycentrics and depth
are affine functions of the pixel centre with slopes read off the vertices.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from refraster.camera import Camera, look_at, orthographic
from refraster.conformance import MAY, MUST, MUST_NOT
from refraster.golden.allowances import core
from refraster.golden.allowances.core import scene_allowances, tolerant_metrics
from refraster.golden.allowances.edges import _absdiff, _dot_bounds, _lin, _sq
from refraster.golden.allowances.ghosts import _evaluation_depths
from refraster.golden.allowances.layers import _count_bounds
from refraster.golden.compare.run import GoldenError, _check_nothing_compared
from refraster.golden.scenes import Draw, raster_state, render_scene

W, H = 16, 8


def _camera():
    view = look_at((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))
    return Camera(view, orthographic(-W / 2, W / 2, -H / 2, H / 2, 0.5, 20.0), W, H)


def _eps_by_hand(width, height):
    """docs/tolerance.md: ε = √2 (2⁻⁵ + 2⁻⁹) + 4 ulp_f32(max(W, H)) + 8·2⁻²⁴·max(W, H) (a
    candidate declared at 4 sub-pixel bits: the allowances here are derived with ``bits=4``)."""
    m = max(width, height)
    ulp = float(np.spacing(np.float32(m)))
    return math.sqrt(2.0) * (2.0 ** -5 + 2.0 ** -9) + 4.0 * ulp + 8.0 * 2.0 ** -24 * m


# --- a tilted plane: eye depth 2 + 0.01·x, one triangle covering the viewport -----------------

@pytest.fixture(scope="module")
def tilted():
    v = np.array([[-100.0, -100.0, -1.0], [100.0, -100.0, -3.0], [0.0, 100.0, -2.0]])
    # eye depth −z = 2 + 0.01·x (x in world units = pixels): z = −(2 + 0.01 x) at every vertex
    v[:, 2] = -(2.0 + 0.01 * v[:, 0])
    f = np.array([[0, 1, 2]], np.int32)
    scene = render_scene([Draw("plane", (v, f))], _camera())
    arrays, info, checks = scene_allowances(scene, raster_state(scene.raster), bits=4)
    return scene, arrays, info, checks


def test_eps_is_the_documented_sum(tilted):
    _, _, info, _ = tilted
    assert info["eps"] == pytest.approx(_eps_by_hand(W, H), rel=1e-12)


def _half_widths(arrays, buffers, key):
    ref = np.asarray(buffers[key], np.float64)
    lo = arrays[f"{key}_lo"].astype(np.float64)
    hi = arrays[f"{key}_hi"].astype(np.float64)
    return ref, ref - lo, hi - ref


def test_eye_depth_interval_by_hand(tilted):
    """half-width = 1e−5 + 4e−6·|z| + 1.5·ε·0.01 (the plane's step per pixel is 0.01)."""
    scene, arrays, info, _ = tilted
    ref, below, above = _half_widths(arrays, scene.buffers, "eye_depth")
    np.testing.assert_allclose(ref[:, 1:] - ref[:, :-1], 0.01, atol=2e-6)   # the plane, as built
    want = 1e-5 + 4e-6 * np.abs(ref) + 1.5 * _eps_by_hand(W, H) * 0.01
    ulp = np.spacing(np.float32(ref.max()))
    assert np.all(below >= want - 4e-6 * 0.05) and np.all(above >= want - 4e-6 * 0.05)
    # the float32 outward rounding adds at most one ulp; the step is measured on float32
    # values, off 0.01 by a few ulp, which moves the slack by 1.5 ε · that
    assert np.all(below <= want + 2 * ulp + 1e-6) and np.all(above <= want + 2 * ulp + 1e-6)


def test_barycentric_interval_by_hand(tilted):
    """half-width = 1e−3 + 1.5·ε·0.005: over the 200-pixel triangle the barycentrics change by
    1/200 per pixel in x (β₀, β₁) and in y (β₂) — the largest channel step is 0.005."""
    scene, arrays, _, _ = tilted
    ref, below, above = _half_widths(arrays, scene.buffers, "barycentric")
    want = 1e-3 + 1.5 * _eps_by_hand(W, H) * 0.005
    for side in (below, above):
        np.testing.assert_allclose(side, want, atol=2e-6)


def test_interval_rounds_outwards():
    """float32 bounds contain the float64 interval: lo₃₂ ≤ lo₆₄ and hi₃₂ ≥ hi₆₄."""
    rng = np.random.default_rng(7)
    ref = rng.uniform(-3.0, 3.0, (8, 8))
    surface = np.zeros((8, 8), np.int64)
    base = 1e-7 * rng.uniform(0.1, 1.0, (8, 8))      # slack below one float32 ulp at 3
    lo, hi = core._interval(ref, surface, 0.0, base)
    assert np.all(lo.astype(np.float64) <= ref - base)
    assert np.all(hi.astype(np.float64) >= ref + base)
    # and by at most one ulp
    assert np.all(ref - base - lo <= np.spacing(np.float32(3.0)))


# --- a step: a plane at eye depth 3, in front of it a plane at 2 whose edge runs through the
# centres of column 8 (window x = 8.5, world x = 0.5) ----------------------------------------

@pytest.fixture(scope="module")
def step():
    back = (np.array([[-100.0, -100.0, -3.0], [100.0, -100.0, -3.0], [0.0, 100.0, -3.0]]),
            np.array([[0, 1, 2]], np.int32))
    front = (np.array([[0.5, -100.0, -2.0], [100.0, -100.0, -2.0], [0.5, 100.0, -2.0]]),
             np.array([[0, 1, 2]], np.int32))
    scene = render_scene([Draw("back", back), Draw("front", front)], _camera())
    arrays, info, checks = scene_allowances(scene, raster_state(scene.raster), bits=4)
    return scene, arrays, info, checks


def test_id_may_exactly_on_the_edge_column(step):
    """Pixel centres of column 8 lie on the front plane's edge (distance 0 < ε): either plane
    may win there; columns 7 and 9 are a whole pixel away (> ε): the id is sure."""
    _, arrays, _, _ = step
    want = np.zeros((H, W), bool)
    want[:, 8] = True
    np.testing.assert_array_equal(arrays["id_may"], want)
    # coverage is "may" near border edges (docs/tolerance.md), whatever lies behind them: the
    # front plane's edge makes column 8 "may" although the back plane covers every pixel
    np.testing.assert_array_equal(arrays["coverage"], np.where(want, MAY, MUST))


def test_depth_free_where_the_id_may_differ(step):
    """Where another face may win, the window depth is that face's: the interval is [0, 1]."""
    scene, arrays, _, _ = step
    lo, hi = arrays["depth_lo"], arrays["depth_hi"]
    assert np.all(lo[:, 8] == 0.0) and np.all(hi[:, 8] == 1.0)
    d = np.asarray(scene.buffers["depth"], np.float64)
    rest = np.ones((H, W), bool)
    rest[:, 8] = False
    assert np.all((lo[rest] <= d[rest]) & (d[rest] <= hi[rest]))
    # both planes have constant depth (∇z = 0): the slack is depth_eps = 4e−5 alone
    # (docs/tolerance.md), rounded to float32
    ulp = float(np.spacing(np.float32(0.25)))
    np.testing.assert_allclose(d[rest] - lo[rest], 4e-5, atol=ulp)
    np.testing.assert_allclose(hi[rest] - d[rest], 4e-5, atol=ulp)


# --- the tolerant checks on hand-made allowances ------------------------------------------------

def _spec(check, **names):
    return {"checks": [check], **names}


def test_interval_check_widened_by_the_quantisation_step():
    """A PNG candidate's value may lie one half step outside; the check widens by one step."""
    step = 1.0 / 255.0
    ref = np.full((1, 3), 0.5, np.float32)
    arrays = {"v_lo": np.full((1, 3), 0.4, np.float32), "v_hi": np.full((1, 3), 0.6, np.float32),
              "coverage": np.full((1, 3), MUST, np.int8), "id_may": np.zeros((1, 3), bool)}
    cand = np.array([[0.4 - 0.5 * step, 0.6 + 0.9 * step, 0.6 + 2.0 * step]], np.float32)
    _, checks, _ = tolerant_metrics("v", ref, cand, "unorm", _spec("interval", lo="v_lo",
                                                                     hi="v_hi"),
                                    arrays, step=step)
    (c,) = checks
    assert c["metric"] == "interval" and c["value"] == 1, c          # only the third pixel
    assert "[0, 2]" in c["detail"]


def test_angle_check_widened_by_root_three_steps():
    """A normal sent as 8-bit snorm is off by up to √3·step/… per channel: the angle limit grows
    by step·√3 — a normal turned by limit + 1.6·step passes, by limit + 1.8·step fails."""
    step = 2.0 / 255.0
    limit = 0.01
    ref = np.zeros((1, 2, 3), np.float32)
    ref[..., 2] = 1.0
    turn = np.array([limit + 1.6 * step, limit + 1.8 * step])
    cand = np.stack([np.sin(turn), np.zeros(2), np.cos(turn)], axis=-1)[None].astype(np.float32)
    arrays = {"normal_angle": np.full((1, 2), limit, np.float32),
              "id_may": np.zeros((1, 2), bool), "coverage": np.full((1, 2), MUST, np.int8)}
    _, checks, _ = tolerant_metrics("normal", ref, cand, "snorm",
                                    _spec("angle", angle="normal_angle"), arrays, step=step)
    (c,) = checks
    assert c["value"] == 1 and "[0, 1]" in c["detail"], c


def test_depth_interval_only_where_coverage_is_must():
    """A "may" pixel's depth is whatever face covers it there: no interval applies."""
    ref = np.array([[0.5, 0.5]], np.float32)
    arrays = {"depth_lo": np.full((1, 2), 0.49, np.float32),
              "depth_hi": np.full((1, 2), 0.51, np.float32),
              "coverage": np.array([[MAY, MUST]], np.int8), "id_may": np.zeros((1, 2), bool)}
    cand = np.array([[0.7, 0.7]], np.float32)
    _, checks, _ = tolerant_metrics("depth", ref, cand, "unorm",
                                    _spec("interval", lo="depth_lo", hi="depth_hi"), arrays)
    (c,) = checks
    assert c["value"] == 1 and "[0, 1]" in c["detail"], c


def test_coverage_check_by_hand():
    ref = np.array([[0, -1, 0]], np.int32)
    arrays = {"coverage": np.array([[MUST, MUST_NOT, MAY]], np.int8),
              "id_may": np.zeros((1, 3), bool)}
    for cand, bad in (([[0, -1, -1]], 0), ([[-1, -1, 0]], 1), ([[0, 0, 0]], 1)):
        _, checks, _ = tolerant_metrics("prim_id", ref, np.array(cand, np.int32), "id",
                                        _spec("coverage"), arrays)
        (c,) = checks
        assert c["value"] == bad, (cand, c)


def test_face_check_leaves_background_to_the_coverage_check():
    """Where the id may differ, a candidate showing background names no face: the face check
    does not count it (coverage decides whether background is allowed there)."""
    from refraster.golden.allowances.core import _face_outside
    arrays = {"id_may": np.array([[True, True]]), "set_offsets": np.array([0, 1, 2]),
              "set_face": np.array([0, 0], np.int32), "set_facing": np.array([1, 1], np.int8)}
    named = np.array([[-1, -1]])                      # neither pixel names a face of its set
    cand = np.array([[-1, 3]], np.int32)              # background, and a face outside the set
    out = _face_outside("prim_id", "id", cand, arrays, named, 0.0, 1.0)
    np.testing.assert_array_equal(out, [[False, True]])


# --- the nothing-compared guards ----------------------------------------------------------------

def test_nothing_compared_is_refused():
    manifest = {"scenes": {"a": {"buffers": {"depth": {}}}, "b": {"buffers": {}}}}
    with pytest.raises(GoldenError, match="no scene was selected"):
        _check_nothing_compared(manifest, [], [], None)
    with pytest.raises(GoldenError, match=r"scene\(s\) \['b'\]"):
        _check_nothing_compared(manifest, ["a", "b"], None, ["normal"])
    _check_nothing_compared(manifest, ["a"], None, None)          # something to compare


# --- interval operations of the edge-map bounds (golden/allowances/edges.py) -------------------

def _brute(f, a, b, n=201):
    x = np.linspace(a[0], a[1], n)[:, None]
    y = np.linspace(b[0], b[1], n)[None, :]
    v = f(x, y)
    return float(v.min()), float(v.max())


@pytest.mark.parametrize("a, b", [((0.2, 0.5), (0.6, 0.9)), ((0.6, 0.9), (0.2, 0.5)),
                                  ((0.2, 0.7), (0.4, 0.9)), ((-1.0, 1.0), (0.0, 0.0))])
def test_absdiff_bounds(a, b):
    lo, hi = _absdiff(a[0], a[1], b[0], b[1])
    blo, bhi = _brute(lambda x, y: np.abs(x - y), a, b)
    assert lo == pytest.approx(blo, abs=1e-12) and hi == pytest.approx(bhi, abs=1e-12)


@pytest.mark.parametrize("a", [(0.2, 0.5), (-0.5, -0.2), (-0.3, 0.5), (-0.5, 0.3)])
def test_square_bounds(a):
    lo, hi = _sq(*a)
    blo, bhi = _brute(lambda x, y: x * x + 0 * y, a, (0.0, 0.0), n=2001)
    assert lo == pytest.approx(blo, abs=1e-12) and hi == pytest.approx(bhi, abs=1e-12)


@pytest.mark.parametrize("q", [0.5, -0.5, 0.0])
def test_weighted_sum_bounds(q):
    lo, hi = _lin(1.0, 2.0, -0.2, 0.6, q)
    blo, bhi = _brute(lambda w, p: w + q * p, (1.0, 2.0), (-0.2, 0.6))
    assert lo == pytest.approx(blo, abs=1e-12) and hi == pytest.approx(bhi, abs=1e-12)


def _dots(t0, a, n=4001):
    """Brute force: dot products of unit vectors at angle t0 when each may turn by up to
    a_i (total a) — the angle between them ranges over [max(0, t0 − a), min(π, t0 + a)]."""
    t = np.linspace(max(0.0, t0 - a), min(math.pi, t0 + a), n)
    return float(np.cos(t).min()), float(np.cos(t).max())


@pytest.mark.parametrize("t0, a", [(0.5, 0.1), (3.0, 0.3), (0.05, 0.2)])
def test_dot_bounds_of_turned_normals(t0, a):
    n = np.array([[0.0, 0.0, 1.0], [math.sin(t0), 0.0, math.cos(t0)]])
    off = np.array([0, 1, 2])
    ang = np.array([a / 2, a / 2])
    bg = np.zeros(2, np.bool_)
    free = np.zeros(2, np.bool_)
    lo, hi = _dot_bounds(0, 1, off, n, ang, bg, free, 1e-6, False)
    blo, bhi = _dots(t0, a)
    assert lo == pytest.approx(blo - 1e-6, abs=1e-9) and hi == pytest.approx(bhi + 1e-6, abs=1e-9)


def test_dot_bounds_of_a_free_pixel_cover_every_dot_and_the_slack():
    off = np.array([0, 1, 2])
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    lo, hi = _dot_bounds(0, 1, off, n, np.zeros(2), np.zeros(2, np.bool_),
                         np.array([True, False]), 0.25, False)
    assert (lo, hi) == (-1.25, 1.25)


# --- layer counts of a layered depth image (golden/allowances/layers.py) -----------------------

def _counts(lo, hi, sure, clear=1.0, k_max=8):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    offsets = np.array([0, len(lo)])
    count_lo, count_hi = np.zeros(1, np.int64), np.zeros(1, np.int64)
    must = np.zeros(len(lo), np.bool_)
    _count_bounds(offsets, lo, hi, np.asarray(sure, np.bool_), clear, k_max, count_lo, count_hi,
                  must)
    return int(count_lo[0]), int(count_hi[0]), must.tolist()


def test_layer_count_touching_intervals_may_merge():
    """Two sure entries whose depth intervals touch at 0.2 may be one depth (one layer): the
    least count is 1, the largest 2, and neither entry must show on its own."""
    assert _counts([0.1, 0.2], [0.2, 0.3], [True, True]) == (1, 2, [False, False])


def test_layer_count_disjoint_intervals_by_hand():
    assert _counts([0.1, 0.25, 0.5], [0.2, 0.3, 0.6], [True, True, True]) == (3, 3,
                                                                                [True] * 3)
    # an unsure entry counts only toward the largest count; one whose interval reaches the
    # clear depth may be there (lo < clear) or not
    assert _counts([0.1, 0.5, 0.9], [0.2, 0.6, 1.2], [True, False, True]) == (1, 3,
                                                                                [True, False, False])


# --- the depth a GPU's line fragment takes (golden/allowances/ghosts.py) ----------------------

def _line_depths(a, b, row, col, eps=0.1, width=16):
    ends = np.array([[a[0], a[1], b[0], b[1]]])
    zends = np.array([[-0.5, 0.5]])          # Δz = 1: z(t) = t − 1/2
    lo, hi = _evaluation_depths((ends, zends, np.array([0])), np.array([0]),
                                np.array([row * width + col]), eps, width)
    return float(lo[0]), float(hi[0])


def test_line_fragment_depth_at_the_foot_and_the_column_centre_line():
    """An x-major line (0.5, 0.5) → (10.5, 3.5), pixel (1, 3), centre (3.5, 1.5): GL's foot
    t_F = (3·10 + 1·3)/109 = 33/109, the column's centre line t_C = 3/10; the depth range
    [t_C, t_F] − 1/2, widened by the moves of m = 1.5ε per axis: the foot's
    √2·m·(1 + 2h/L)/L·|Δz| with h = |3·3 − 1·10|/√109 = 1/√109, L = √109 (larger than the
    centre line's m·|Δz/Δx| = m/10), and 32·2⁻²⁴."""
    m, L = 0.15, math.sqrt(109.0)
    slack = math.sqrt(2.0) * m * (1.0 + 2.0 / 109.0) / L + 32.0 * 2.0 ** -24
    lo, hi = _line_depths((0.5, 0.5), (10.5, 3.5), 1, 3)
    assert lo == pytest.approx(0.3 - 0.5 - slack, rel=1e-12, abs=1e-15)
    assert hi == pytest.approx(33.0 / 109.0 - 0.5 + slack, rel=1e-12, abs=1e-15)


def test_line_fragment_depth_of_a_nearly_diagonal_line_takes_both_centre_lines():
    """(0.5, 0.5) → (8.5, 8.6): ||Δx| − |Δy|| = 0.1 ≤ 4m, either axis may be the major one.
    Pixel (4, 4), centre (4.5, 4.5): t_C = 4/8, t_R = 4/8.1, t_F = 64.4/129.61 between them;
    the largest move term the column line's m·|Δz/Δx|·1 = m/8."""
    m = 0.15
    slack = m / 8.0 + 32.0 * 2.0 ** -24
    lo, hi = _line_depths((0.5, 0.5), (8.5, 8.6), 4, 4)
    assert lo == pytest.approx(4.0 / 8.1 - 0.5 - slack, rel=1e-12, abs=1e-15)
    assert hi == pytest.approx(0.5 - 0.5 + slack, rel=1e-12, abs=1e-15)
