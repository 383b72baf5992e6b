"""Multisampling (issue 43): the raster state's sample fields, the standard sample locations
against the Vulkan specification's text, per-sample coverage, depth and attributes against a
float64 brute-force twin, the covered-sample fraction against the area, fill-rule ties at
samples, the resolve, and llvmpipe at 4× as an outside oracle (``docs/multisample.md``).
"""

from __future__ import annotations

import importlib.util
import json
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import refraster
from exact_referee import GL_NEAR_FAR, clip_polygon, covers, gl_window_depth
from naive import sample_coverage, sample_grid, sample_plane_depth
from refraster import RasterState
from refraster.raster import samples as SP
from refraster.raster._sample_tables import STANDARD

ROOT = Path(__file__).resolve().parents[1]
EXCERPT = ROOT / "docs" / "spec" / "vulkan_standard_sample_locations.adoc"
EYE = np.eye(4)


# ---------------------------------------------------------------- the table from the spec text

def _spec_table():
    """The standard sample locations parsed here from the verbatim copy of the spec's table
    (this parser is the test's own, not the extraction script's): ``{count: [(x16, y16)]}``."""
    text = EXCERPT.read_text()
    table, count = {}, None
    for line in text.splitlines():
        m = re.search(r"VK_SAMPLE_COUNT_(\d+)_BIT", line)
        if m:
            count = int(m.group(1))
            table[count] = []
        for x, y in re.findall(r"#\(([^,#]+),([^)#]+)\)#", line):
            table[count].append((Fraction(x.strip()) * 16, Fraction(y.strip()) * 16))
    return {n: [(int(x), int(y)) for x, y in pts] for n, pts in table.items()}


SPEC = _spec_table()


def test_standard_table_is_the_spec_text():
    assert sorted(SPEC) == [1, 2, 4, 8, 16]
    for n, pts in SPEC.items():
        assert len(pts) == n
        assert tuple(pts) == STANDARD[n], n
    # the copy names its source; the generated table names the same commit
    head = EXCERPT.read_text().splitlines()[:2]
    commit = re.search(r"commit ([0-9a-f]{40})", head[0]).group(1)
    assert "chapters/primsrast.adoc" in head[1]
    assert commit in (ROOT / "refraster" / "raster" / "_sample_tables.py").read_text()
    assert commit in (ROOT / "docs" / "multisample.md").read_text()


def test_extraction_script_regenerates_the_table():
    spec = importlib.util.spec_from_file_location(
        "vulkan_sample_locations", ROOT / "docs" / "scripts" / "vulkan_sample_locations.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    body = "\n".join(EXCERPT.read_text().splitlines()[2:]) + "\n"
    commit = re.search(r"commit ([0-9a-f]{40})", EXCERPT.read_text()).group(1)
    assert mod.parse(body) == {n: list(p) for n, p in STANDARD.items()}
    assert mod.table_source(mod.parse(body), commit) == \
        (ROOT / "refraster" / "raster" / "_sample_tables.py").read_text()


def test_gl_llvmpipe_pattern_is_vulkans_mirrored():
    # what llvmpipe reports, y up in GL's window coordinates, is Vulkan's 4x table's numbers;
    # as the picture is seen (y down) that is the table mirrored top to bottom
    assert [(Fraction(x) * 16, Fraction(y) * 16) for x, y in SP.GL_LLVMPIPE_4X_REPORTED] == \
        [tuple(map(Fraction, p)) for p in SPEC[4]]
    assert SP.GL_LLVMPIPE_4X == tuple((x, 16 - y) for x, y in SPEC[4])


# ------------------------------------------------------------------------- the raster state

@pytest.mark.parametrize("fields, message", [
    (dict(samples=3), "raster.samples must be one of 1, 2, 4, 8, 16, got 3"),
    (dict(samples=True), "raster.samples must be an int, got bool"),
    (dict(samples=4.0), "raster.samples must be an int, got float"),
    (dict(samples=2, sample_locations="gl_llvmpipe"), "raster.samples must be 4 for it"),
    (dict(samples=2, sample_locations=[(1, 2)]), "one (x, y) pair per sample (2), got 1"),
    (dict(samples=1, sample_locations=[(16, 0)]), "raster.sample_locations[0] must lie in 0..15"),
    (dict(samples=1, sample_locations=[(1.5, 0)]), "must be a pair of ints"),
    (dict(samples=1, sample_locations="vulkan"), "raster.sample_locations must be one of"),
    (dict(samples=1, sample_locations=7), "raster.sample_locations must be one of"),
    (dict(interpolation="pixel"), "raster.interpolation must be one of center, centroid"),
])
def test_bad_sample_fields_get_one_line(fields, message):
    with pytest.raises((ValueError, TypeError)) as err:
        RasterState(**fields)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_state_fields_and_defaults():
    st = RasterState()
    assert (st.samples, st.sample_locations, st.interpolation) == (1, "standard", "center")
    user = RasterState(samples=2, sample_locations=[[3, 4], [12, 11]])
    assert user.sample_locations == ((3, 4), (12, 11))
    assert user.as_dict()["sample_locations"] == [[3, 4], [12, 11]]
    assert json.loads(json.dumps(user.as_dict())) == user.as_dict()
    assert RasterState.from_dict(user.as_dict()) == user
    assert RasterState(samples=4, sample_locations="GL_LLVMPIPE").sample_locations == \
        "gl_llvmpipe"


def test_single_sample_entry_points_refuse_a_multisample_state():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    f = np.array([[0, 1, 2]])
    for fn in (refraster.render, refraster.draw):
        with pytest.raises(ValueError, match="raster.samples must be 1 .*render_samples"):
            fn((v, f), view=EYE, proj=EYE, width=8, height=8, raster=RasterState(samples=4))


def test_scene_packages_store_the_sample_fields():
    from refraster.golden.io.schema import SCENE_SCHEMA, validate
    from refraster.golden.scenes import as_state, raster_state
    plain = raster_state({})
    assert "samples" not in plain and "sample_locations" not in plain   # bytes as before
    assert as_state(plain) == RasterState()
    ms = raster_state({"samples": 2, "sample_locations": ((2, 3), (13, 12)),
                       "interpolation": "centroid"})
    assert ms["sample_locations"] == [[2, 3], [13, 12]]
    json.dumps(ms)
    assert as_state(ms) == RasterState(samples=2, sample_locations=((2, 3), (13, 12)),
                                       interpolation="centroid")
    props = SCENE_SCHEMA["properties"]["raster"]["properties"]
    for key in ("samples", "sample_locations", "interpolation"):
        assert key in props
    sub = {"type": "object", "properties": props, "additionalProperties": False}
    validate({"samples": 4, "sample_locations": "gl_llvmpipe"}, sub)
    validate({"samples": 2, "sample_locations": [[2, 3], [13, 12]]}, sub)
    with pytest.raises(Exception, match="sample_locations"):
        validate({"sample_locations": [[2, 16]]}, sub)
    with pytest.raises(Exception, match="samples"):
        validate({"samples": 3}, sub)


def test_gl_package_reader_refuses_multisample_packages(tmp_path):
    from refraster.gl.package import PackageError, read_scene
    eye = np.eye(4).tolist()
    doc = {"schema": "refraster.scene", "schema_version": 1,
           "viewport": {"width": 8, "height": 8}, "camera": {"view": eye, "projection": eye},
           "raster": {"cull": "none", "depth_func": "less", "front_face": "ccw",
                      "normals": "flat", "clear_depth": 1.0}, "draws": []}
    (tmp_path / "scene.json").write_text(json.dumps(doc))
    with pytest.raises(PackageError) as err:               # one sample: past the raster
        read_scene(tmp_path)
    assert "shading" in str(err.value)
    for extra in ({"samples": 4}, {"sample_locations": [[8, 8]]}):
        doc["raster"] = {**doc["raster"], **extra}
        (tmp_path / "scene.json").write_text(json.dumps(doc))
        with pytest.raises(PackageError, match="raster.samples must be 1 for this backend"):
            read_scene(tmp_path)


# ------------------------------------------------------------------ the float64 twin

def _window(v, w, h):
    """Window position (float32, as the vertex stage: ``x·(1/w)·W/2 + W/2``), snapped (int,
    8 bits, ``rint((x_w − ½)·256)``), depth; ``v`` (V, 3) (w = 1) or clip (V, 4)."""
    v = np.asarray(v, np.float32)
    hw, hh = np.float32(w * 0.5), np.float32(h * 0.5)
    one = np.float32(1.0) / (v[:, 3] if v.shape[1] == 4 else np.float32(1.0))
    xw = v[:, 0] * one * hw + hw
    yw = v[:, 1] * one * hh + hh
    zw = v[:, 2] * one * np.float32(0.5) + np.float32(0.5)
    sx = np.rint((xw - np.float32(0.5)) * np.float32(256)).astype(np.int64)
    sy = np.rint((yw - np.float32(0.5)) * np.float32(256)).astype(np.int64)
    return xw.astype(np.float64), yw.astype(np.float64), zw.astype(np.float64), sx, sy


def twin(vertices, faces, w, h, positions, rule="llvmpipe"):
    """Per-sample face id and depth, brute force: every sample of every pixel against every
    face in draw order (GL conventions, identity matrices: clip = the vertex). ``positions``
    in 1/16 pixel, y down from the pixel's upper-left corner (the spec's own numbers).
    Returns ``prim (H, W, S)``, ``depth (H, W, S)`` float64 and the second-nearest depth."""
    xw, yw, zw, X, Y = _window(vertices, w, h)
    SX, SY, FX, FY = sample_grid(positions, w, h)
    best = np.full(SX.shape, 1.0)
    second = np.full(SX.shape, np.inf)
    prim = np.full(SX.shape, -1)
    for i, face in enumerate(faces):
        cov = sample_coverage(X, Y, face, SX, SY, rule)
        if cov is None:
            continue
        z = sample_plane_depth(xw, yw, zw, face, FX, FY)
        win = cov & (z.astype(np.float32) < best.astype(np.float32))
        lose = cov & ~win
        second = np.where(win, np.minimum(second, best), np.where(lose, np.minimum(second, z),
                                                                   second))
        best = np.where(win, z, best)
        prim = np.where(win, i, prim)
    flip = (slice(None, None, -1),)
    return prim[flip], best[flip], second[flip]


def _soup(seed, n, w, h, grid=False):
    """Random triangles in front of the camera (identity matrices), some large, some small,
    interpenetrating; ``grid``: vertices on the 1/16 pixel grid (ties at samples)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1.0, 1.0, (n, 1, 2))
    size = np.where(rng.random((n, 1, 1)) < 0.3, 0.08, 0.6)
    xy = c + rng.normal(0.0, 1.0, (n, 3, 2)) * size
    if grid:   # window position k/16 ⇔ clip 2k/(16 W) − 1, exact in float32
        k = np.rint((xy + 1.0) * 0.5 * np.array([w, h]) * 16)
        xy = k / (16 * np.array([w, h])) * 2.0 - 1.0
    z = rng.uniform(-0.9, 0.9, (n, 3, 1))
    v = np.concatenate([xy, z], axis=2).reshape(-1, 3).astype(np.float32)
    return v, np.arange(3 * n).reshape(n, 3)


def _render(v, f, w, h, **state):
    return refraster.render_samples((v, f), view=EYE, proj=EYE, width=w, height=h,
                                    raster=RasterState(**state))


def _agree(sf, tw, what):
    prim, best, second = tw
    ties = np.abs(second - best) < 1e-5          # two faces within float32 rounding
    bad = (sf.prim_id != prim) & ~ties
    assert not bad.any(), (f"{what}: {int(bad.sum())} of {bad.size} samples differ from the "
                           f"float64 twin, first at {np.argwhere(bad)[:3].tolist()}")
    cov = prim >= 0
    same = cov & (sf.prim_id == prim)
    np.testing.assert_allclose(sf.depth[same], best[same], atol=2e-7, rtol=0)
    assert (sf.depth[~(sf.prim_id >= 0)] == 1.0).all()


@pytest.mark.parametrize("samples", [2, 4, 8, 16])
@pytest.mark.parametrize("grid", [False, True])
def test_coverage_and_depth_per_sample_match_the_twin(samples, grid):
    w, h = 37, 23
    v, f = _soup(samples * 7 + grid, 40, w, h, grid=grid)
    sf = _render(v, f, w, h, samples=samples)
    assert sf.prim_id.shape == (h, w, samples) and sf.color.shape == (h, w, samples, 3)
    _agree(sf, twin(v, f, w, h, SPEC[samples]), f"{samples}x grid={grid}")


@pytest.mark.parametrize("seed", range(3))
def test_depths_at_the_ends_of_the_range_match_the_twin(seed):
    """Triangles lying within 0.001 of the far plane (window depth 0.999 … 1, a vertex on it)
    and of the near plane (0 … 0.001, a vertex on it), in front of and behind each other: the
    covered samples' depths agree with the float64 twin's plane clamped to [0, 1] (a far
    sample at 1.0 loses `less` against the clear depth 1.0, as in the twin). Samples deeper
    than 0.999 and nearer than 0.001 must win: a clamp short of either end changes them."""
    w, h = 37, 23
    rng = np.random.default_rng(seed)
    n = 24
    xy = rng.uniform(-1.0, 1.0, (n, 1, 2)) + rng.normal(0.0, 1.0, (n, 3, 2)) * 0.3
    far = rng.random(n) < 0.5
    z = np.where(far[:, None], 1.0 - rng.uniform(0.0, 0.002, (n, 3)),
                 -1.0 + rng.uniform(0.0, 0.002, (n, 3)))
    z[:, 0] = np.where(far, 1.0, -1.0)          # a vertex on the plane
    v = np.concatenate([xy, z[:, :, None]], axis=2).reshape(-1, 3).astype(np.float32)
    f = np.arange(3 * n).reshape(n, 3)
    sf = _render(v, f, w, h, samples=4)
    tw = twin(v, f, w, h, SPEC[4])
    prim, best, _ = tw
    assert (best[prim >= 0] > 0.999).sum() > 0 and (best[prim >= 0] < 0.001).sum() > 0
    _agree(sf, tw, f"ends seed={seed}")


@pytest.mark.parametrize("state", [
    dict(samples=4, sample_locations="gl_llvmpipe"),
    dict(samples=2, sample_locations=((0, 0), (15, 15))),
    dict(samples=4, sample_locations=((1, 14), (3, 3), (15, 8), (8, 0)), fill_rule="top-left"),
])
def test_gl_and_user_patterns_match_the_twin(state):
    w, h = 29, 31
    v, f = _soup(5, 40, w, h, grid=True)
    sf = _render(v, f, w, h, **state)
    pts = SP.GL_LLVMPIPE_4X if state["sample_locations"] == "gl_llvmpipe" \
        else state["sample_locations"]
    _agree(sf, twin(v, f, w, h, pts, rule=state.get("fill_rule", "llvmpipe")), str(state))


def test_one_sample_is_the_single_sample_frame():
    w, h = 41, 27
    v, f = _soup(3, 60, w, h)
    fb = refraster.render((v, f), view=EYE, proj=EYE, width=w, height=h)
    for interp in ("center", "centroid", "sample"):
        sf = _render(v, f, w, h, samples=1, interpolation=interp)
        for name, a in sf.arrays().items():
            assert np.array_equal(a[:, :, 0], getattr(fb, name)), (interp, name)


def test_one_draw_calls_ids_are_its_face_image_and_several_calls_write_theirs():
    """With one draw call ``render_samples`` hands out the sample face image as ``prim_id``
    (not written again): the same bytes as with the ids written (the call and an empty second
    call). With two calls the ids are per call: the second call's faces from 0."""
    w, h = 41, 27
    v, f = _soup(5, 60, w, h)
    kw = dict(view=EYE, proj=EYE, width=w, height=h, raster=RasterState(samples=4))
    one = refraster.render_samples((v, f), **kw)
    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int64))
    written = refraster.render_samples([(v, f), empty], **kw)
    for name, a in one.arrays().items():
        assert a.tobytes() == getattr(written, name).tobytes(), name
    assert (one.prim_id >= 0).sum() > 1000
    two = refraster.render_samples([(v, f[:30]), (v, f[30:])], **kw)
    second = two.object_id == 1
    assert second.any() and (two.prim_id >= 0).any()
    np.testing.assert_array_equal(two.prim_id[second], one.prim_id[second] - 30)
    np.testing.assert_array_equal(two.prim_id[two.object_id == 0],
                                  one.prim_id[two.object_id == 0])


# ------------------------------------------------- triangles hidden behind their whole box

def _behind_a_wall(seed, w, h):
    """A wall over most of the window drawn first (window depth ~0.45), its duplicate (ties:
    ``lequal`` lets the second win), then small triangles behind it, through it and steep
    ones (depth planes with large gradients), some reaching past the wall's edge. At
    150 × 140 the middle tile lies inside the wall, so whole boxes are behind it."""
    rng = np.random.default_rng(seed)
    wall = np.array([[-0.8, -0.9, -0.1], [0.9, -0.9, -0.1], [0.9, 0.95, -0.1],
                     [-0.8, 0.95, -0.1]], np.float32)
    c = rng.uniform(-1.0, 1.0, (600, 1, 2))
    xy = c + rng.normal(0.0, 0.04, (600, 3, 2))
    z = rng.uniform(-0.15, 0.9, (600, 1, 1)) + rng.normal(0.0, 0.02, (600, 3, 1))
    z[::7] = rng.uniform(-0.9, 0.9, (len(z[::7]), 3, 1))          # steep
    soup = np.concatenate([xy, z], axis=2).reshape(-1, 3).astype(np.float32)
    # and 60 small triangles in the wall's plane: ties at every sample of their boxes
    flat = rng.uniform(-0.6, 0.7, (60, 1, 2)) + rng.normal(0.0, 0.03, (60, 3, 2))
    flat = np.concatenate([flat, np.full((60, 3, 1), -0.1)], axis=2).astype(np.float32)
    v = np.concatenate([wall, wall, soup, flat.reshape(-1, 3)])
    f = np.concatenate([[[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]],
                        8 + np.arange(len(soup) + 180).reshape(-1, 3)])
    return v, f


@pytest.mark.parametrize("depth_func", ["less", "lequal", "greater", "gequal"])
@pytest.mark.parametrize("samples", [4, 8])
def test_triangles_hidden_behind_their_box_are_the_streams_bytes(samples, depth_func):
    """The tile pass skips a triangle whose plane, at its box's lowest corner, is already
    behind every stored sample of the box (``raster/multisample.py``, ``_hidden``); the
    per-sample fragment stream resolved by the single-sample depth test skips nothing. Both
    give the same bytes, ties of ``lequal``/``gequal`` (the wall's duplicate and the small
    triangles in its plane win) included; ``greater``/``gequal`` on the scene mirrored in depth."""
    from refraster.framebuffer import Framebuffer
    from refraster.multisample import draw_samples, sample_image
    w, h = 150, 140
    v, f = _behind_a_wall(samples, w, h)
    reverse = depth_func in ("greater", "gequal")
    if reverse:   # mirrored in depth, cleared to 0
        v[:, 2] = -v[:, 2]
    st = RasterState(samples=samples, depth_func=depth_func, clear_depth=0.0 if reverse else 1.0)
    sf = refraster.render_samples((v, f), view=EYE, proj=EYE, width=w, height=h, raster=st)
    frags = draw_samples((v, f), view=EYE, proj=EYE, width=w, height=h, raster=st)
    one = sample_image(st)
    fb = Framebuffer.from_fragments(frags, refraster.resolve(frags, raster=one), raster=one)
    for k in ("depth", "prim_id", "front_facing", "barycentric"):
        np.testing.assert_array_equal(getattr(fb, k).reshape(getattr(sf, k).shape),
                                      getattr(sf, k), err_msg=k)
    ties = depth_func in ("lequal", "gequal")
    wall = np.isin(sf.prim_id, (2, 3) if ties else (0, 1))
    assert wall.mean() > 0.5 and (sf.prim_id > 3).any()
    flat = np.isin(np.arange(604, 664), sf.prim_id).sum()   # drawn only where ties win
    assert flat > 40 if ties else flat == 0


# ------------------------------------------------------------------ the exact span walk

def test_edge_walk_gives_each_rows_exact_span():
    """The multisample pass's spans (each edge walked down the rows without divisions) against
    their definition, enumerated in Python integers: the columns ``i`` of a row of ``n`` where
    every ``v_k + sx_k·i ≥ 0`` — steep, shallow, horizontal and vertical edges, values past
    2^53, steps of either sign."""
    from refraster.raster.multisample import _floor_divmod, _walk_span, _walk_step
    rng = np.random.default_rng(43)
    for case in range(400):
        scale = 1 << int(rng.choice([4, 12, 30, 58]))
        n = int(rng.integers(1, 24))
        sx = [int(rng.integers(-scale, scale + 1)) * int(rng.integers(0, 2) or (k == 0))
              for k in range(3)]
        sy = [int(rng.integers(-scale, scale + 1)) for _ in range(3)]
        v = [int(rng.integers(-scale * n, scale * n + 1)) for _ in range(3)]
        walk = []
        for k in range(3):
            m = abs(sx[k])
            q, u = _floor_divmod(np.int64(sy[k]), np.int64(m))
            F, T = _floor_divmod(np.int64(v[k]), np.int64(m))
            walk.append([F, T, q, u, m])
        for row in range(6):
            a, b = 0, n - 1
            for k in range(3):
                a, b = _walk_span(np.int64(sx[k]), walk[k][0], walk[k][1], a, b)
            want = [i for i in range(n)
                    if all(v[k] + sy[k] * row + sx[k] * i >= 0 for k in range(3))]
            assert list(range(a, b + 1)) == want, (case, row, sx, sy, v)
            for k in range(3):
                walk[k][0], walk[k][1] = _walk_step(*walk[k])


# ------------------------------------------------------------------ analytic: area

def test_covered_fraction_converges_to_the_area():
    """Each sample index's positions form a translate of the pixel lattice; for a convex
    region of area A and perimeter P, a translate of Z² has N points with A − P/2 < N ≤
    A + P/2 + 1 (Nosarzewska 1948). Snapping moves each vertex by at most √2/512 px, which
    changes the area by at most P·√2/512 (+ a second-order term bounded by P·√2/512 again).
    The mean over the S samples (the covered fraction × the pixel count) obeys the same bound,
    |Σ coverage / S − A| ≤ P/2 + 1 + P·√2/256, so the relative error is O(P/A) and falls with
    the polygon's size; over many random polygons the signed errors average out."""
    w, h = 300, 220
    rng = np.random.default_rng(43)
    rel = []
    for t in range(40):
        n = [2, 4, 8, 16][t % 4]
        c = rng.uniform(60, 160, 2)
        p = c + rng.uniform(-55, 55, (3, 2))
        area = 0.5 * abs((p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1])
                         - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1]))
        if area < 500:
            continue
        per = sum(np.hypot(*(p[(k + 1) % 3] - p[k])) for k in range(3))
        clip = np.column_stack([p[:, 0] / w * 2 - 1, p[:, 1] / h * 2 - 1, np.zeros(3)])
        sf = _render(clip.astype(np.float32), np.array([[0, 1, 2]]), w, h, samples=n)
        est = (sf.prim_id >= 0).sum() / n
        assert abs(est - area) <= per / 2 + 1 + per * np.sqrt(2) / 256, (n, est, area, per)
        rel.append((est - area) / area)
    assert len(rel) >= 20
    assert abs(np.mean(rel)) < 0.002, rel


# ------------------------------------------------------------------ fill-rule ties

@pytest.mark.parametrize("rule", ["llvmpipe", "top-left"])
@pytest.mark.parametrize("samples", [4, 16])
def test_shared_edges_through_samples_cover_each_sample_once(rule, samples):
    """A fan of triangles with vertices on the 1/16 grid whose edges pass exactly through
    sample positions (16×: every 1/16 column and row holds a sample): every sample inside the
    fan is covered by exactly one triangle; the fan's outer edges by the rule."""
    w, h = 8, 8   # a power of two: the 1/16 pixel vertices are exact in float32 clip space
    # a 2 × 2 grid of cells (vertices 0..8, row by row from the bottom), the middle vertex
    # moved off the centre so the cells' diagonals have slopes 1/2, 3/2, ...
    # (6 and 86 ≡ 6 mod 16: the outer edges pass through samples at 4x as at 16x)
    k = np.array([[6, 6], [46, 6], [86, 6], [6, 46], [54, 38], [86, 46], [6, 86], [46, 86],
                  [86, 86]])   # 1/16 pixel
    clip = np.column_stack([k[:, 0] / (16 * w) * 2 - 1, k[:, 1] / (16 * h) * 2 - 1,
                            np.zeros(len(k))]).astype(np.float32)
    tris = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6],
                     [4, 5, 8], [4, 8, 7]])
    count = np.zeros((h, w, samples), int)
    for t in tris:
        sf = _render(clip, t[None], w, h, samples=samples, fill_rule=rule)
        count += sf.prim_id >= 0
    pts = np.array(SPEC[samples])
    # each sample's window position in 1/16 pixel, y up
    px, py = np.meshgrid(np.arange(w), np.arange(h)[::-1])
    sx = px[..., None] * 16 + pts[:, 0]
    sy = py[..., None] * 16 + (16 - pts[:, 1])
    inside = (sx > 6) & (sx < 86) & (sy > 6) & (sy < 86)
    on_edge = ((sx == 6) | (sx == 86) | (sy == 6) | (sy == 86)) & \
        (sx >= 6) & (sx <= 86) & (sy >= 6) & (sy <= 86)
    assert (count[inside] == 1).all()
    assert (count <= 1).all()
    # the square's own edges: left always owned; bottom (llvmpipe) or top (top-left)
    owned = (sx == 6) & (sy > 6) & (sy < 86)
    assert (count[owned] == 1).all()
    assert (count[(sx == 86) & (sy > 6) & (sy < 86)] == 0).all()
    bottom = (sy == 6) & (sx > 6) & (sx < 86)
    top = (sy == 86) & (sx > 6) & (sx < 86)
    assert (count[bottom] == (1 if rule == "llvmpipe" else 0)).all()
    assert (count[top] == (0 if rule == "llvmpipe" else 1)).all()
    assert on_edge.any() and (inside & (count == 1)).sum() > 50
    # and samples lie exactly on the fan's inner edges (ties the rule decides)
    on_inner = np.zeros_like(inside)
    for t in tris:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            (xa, ya), (xb, yb) = k[a], k[b]
            cross = (xb - xa) * (sy - ya) - (yb - ya) * (sx - xa)
            within = (np.minimum(xa, xb) <= sx) & (sx <= np.maximum(xa, xb)) & \
                (np.minimum(ya, yb) <= sy) & (sy <= np.maximum(ya, yb))
            on_inner |= (cross == 0) & within & inside
    assert on_inner.sum() >= 2, on_inner.sum()


# ------------------------------------------------------------------ attributes

def _lambdas(v, f, w, h, sf, fx, fy):
    """Screen-space barycentrics of each sample's face at (fx, fy) (identity matrices: the
    perspective-correct ones), from the unsnapped float32 window positions."""
    xw, yw, _, _, _ = _window(v, w, h)
    out = np.zeros(sf.prim_id.shape + (3,))
    cov = sf.prim_id >= 0
    tri = f[sf.prim_id[cov]]
    x, y = xw[tri], yw[tri]
    den = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    X, Y = fx[cov], fy[cov]
    l1 = ((X - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (Y - y[:, 0])) / den
    l2 = ((x[:, 1] - x[:, 0]) * (Y - y[:, 0]) - (X - x[:, 0]) * (y[:, 1] - y[:, 0])) / den
    out[cov] = np.column_stack([1 - l1 - l2, l1, l2])
    return out, cov


def test_interpolation_points():
    w, h, n = 33, 25, 8
    v, f = _soup(11, 30, w, h)
    pts = np.array(SPEC[n])
    px, py = np.meshgrid(np.arange(w), np.arange(h)[::-1])
    fx_c = np.repeat((px + 0.5)[..., None], n, 2)
    fy_c = np.repeat((py + 0.5)[..., None], n, 2)
    fx_s = px[..., None] + pts[:, 0] / 16.0
    fy_s = py[..., None] + 1.0 - pts[:, 1] / 16.0
    centre = _render(v, f, w, h, samples=n)
    ref, cov = _lambdas(v, f, w, h, centre, fx_c, fy_c)
    np.testing.assert_allclose(centre.barycentric[cov], ref[cov], atol=2e-5)
    per_sample = _render(v, f, w, h, samples=n, interpolation="sample")
    assert np.array_equal(per_sample.prim_id, centre.prim_id)
    ref, cov = _lambdas(v, f, w, h, per_sample, fx_s, fy_s)
    np.testing.assert_allclose(per_sample.barycentric[cov], ref[cov], atol=2e-5)
    # centroid: a point inside both the pixel and the primitive (within the 1/512 px of
    # snapping), where the centre extrapolates
    cen = _render(v, f, w, h, samples=n, interpolation="centroid")
    assert np.array_equal(cen.prim_id, centre.prim_id)
    big = np.array([np.ptp(_window(v, w, h)[0][t]) > 3 for t in f])
    keep = (cen.prim_id >= 0) & big[np.maximum(cen.prim_id, 0)]
    assert cen.barycentric[keep].min() > -0.01
    assert centre.barycentric[keep].min() < -0.05



def test_triangles_flattened_by_snapping_interpolate_their_snapped_edges():
    """Slivers whose unsnapped triangle turns the other way (A and B snap onto a sample row,
    C to 1/256 px above it, unsnapped C lies below line AB): the pass interpolates the snapped
    triangle (``_lambdas_at``'s fallback, the edge values at the point over the snapped
    area). Their samples on AB against the snapped triangle's barycentrics by Cramer's rule
    at the pixel centre (extrapolated: λ_C = −32 or +32 at 1/8 px from AB) and at the sample,
    and against the per-sample fragment stream, bit for bit."""
    from refraster.framebuffer import Framebuffer
    from refraster.multisample import draw_samples, sample_image
    w = h = 64
    ys = 10.625 + 6.0 * np.arange(8)[:, None]        # rows of samples with offset ±2/16
    u = 1.0 / 65536
    wx = np.broadcast_to([4.0, 20.0, 36.0], (8, 3))
    wy = ys + np.array([-115, 115, 141]) * u          # snapped: ys, ys, ys + 1/256
    wz = np.broadcast_to(0.1 * np.arange(8)[:, None] - 0.5, (8, 3))
    v = np.stack([wx * 2 / w - 1, wy * 2 / h - 1, wz], -1).reshape(-1, 3).astype(np.float32)
    f = np.arange(24).reshape(-1, 3)
    for interp in ("center", "sample"):
        st = RasterState(samples=4, interpolation=interp)
        sf = refraster.render_samples((v, f), view=EYE, proj=EYE, width=w, height=h, raster=st)
        r, c, s = np.nonzero(sf.prim_id >= 0)
        assert len(r) == 8 * 16 and np.array_equal(np.unique(sf.prim_id), np.arange(-1, 8))
        pts = SP.sample_points(st)
        off = pts[s] if interp == "sample" else np.full((len(s), 2), 0.5)
        px, py = c + off[:, 0], h - (r + off[:, 1])      # window position, y up
        k = sf.prim_id[r, c, s]
        ax, ay, bx, cx = 4.0, ys[k, 0], 20.0, 36.0
        cy = ay + 1.0 / 256
        den = (bx - ax) * (cy - ay)
        lb = ((px - ax) * (cy - ay) - (cx - ax) * (py - ay)) / den
        lc = ((bx - ax) * (py - ay)) / den
        ref = np.column_stack([1 - lb - lc, lb, lc])
        np.testing.assert_allclose(sf.barycentric[r, c, s], ref, rtol=1e-6, atol=1e-7,
                                   err_msg=interp)
        frags = draw_samples((v, f), view=EYE, proj=EYE, width=w, height=h, raster=st)
        one = sample_image(st)
        fb = Framebuffer.from_fragments(frags, refraster.resolve(frags, raster=one), raster=one)
        for name in ("depth", "prim_id", "barycentric"):
            np.testing.assert_array_equal(
                getattr(fb, name).reshape(getattr(sf, name).shape), getattr(sf, name),
                err_msg=f"{interp} {name}")

# ------------------------------------------------------------------ resolve

def test_resolve_modes():
    a = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    assert np.array_equal(refraster.resolve_samples(a, "sample_zero"), a[:, :, 0])
    assert np.array_equal(refraster.resolve_samples(a, "min"), a.min(2))
    assert np.array_equal(refraster.resolve_samples(a, "max"), a.max(2))
    assert np.array_equal(refraster.resolve_samples(a, "average"), a.mean(2))
    with pytest.raises(ValueError, match="mode 'average' needs a float buffer"):
        refraster.resolve_samples(a.astype(np.int32), "average")
    with pytest.raises(ValueError, match="mode must be one of"):
        refraster.resolve_samples(a, "median")
    with pytest.raises(ValueError, match="sample axis"):
        refraster.resolve_samples(a[:, :, 0], "min")
    # half black, half white: linear 0.5; an sRGB target averages light, not code values
    c = np.zeros((1, 1, 4, 3), np.float32)
    c[0, 0, :2] = 1.0
    assert np.allclose(refraster.resolve_color(c), 0.5)
    srgb = refraster.resolve_color(c, "srgb")
    assert np.allclose(srgb, 1.055 * 0.5 ** (1 / 2.4) - 0.055, atol=1e-6)
    with pytest.raises(ValueError, match="encoding must be"):
        refraster.resolve_color(c, "gamma")


def test_resolved_frame_is_the_mean_of_its_samples():
    w, h = 24, 18
    v, f = _soup(2, 20, w, h)
    sf = _render(v, f, w, h, samples=4)
    col = refraster.resolve_color(sf.color)
    assert col.shape == (h, w, 3)
    assert np.allclose(col, sf.color.astype(np.float64).mean(2), atol=1e-7)
    ids = refraster.resolve_samples(sf.prim_id, "max")
    assert ids.dtype == sf.prim_id.dtype and ids.shape == (h, w)


# ------------------------------------------------------------------ llvmpipe at 4x

#: Required agreement of the per-pixel sample sets (issue 43).
MIN_AGREEMENT = 0.9999
_ORACLE = {}


def _oracle_scenes():
    from oracles import scenes as S
    return S.random_scenes(26)


def _oracle_frame(M, sc):
    from oracles import llvmpipe as L
    draws = [(L.clip_positions(v, sc.mvp), np.asarray(f)) for v, f in sc.meshes]
    clip, faces, base = [], [], 0
    for c, f in draws:
        clip.append(c)
        faces.append(f + base)
        base += len(c)
    ids, reported = M.rasterize_samples(np.concatenate(clip), np.concatenate(faces), sc.width,
                                        sc.height)
    return ids, reported, draws


def _global(sf, sc):
    offsets = np.cumsum([0] + [len(f) for _, f in sc.meshes])
    return np.where(sf.prim_id >= 0, sf.prim_id + offsets[np.maximum(sf.object_id, 0)], -1)


def _referee(sc, draws, r, c, s, pattern, ours, gl):
    """The exact referee of ``tests/test_llvmpipe_oracle.py`` (rational clipping, the sample
    tested against each candidate's clip-space cone, exact depth) at sample ``s`` of pixel
    ``(r, c)``. Candidates: the ids either renderer has at any sample of the pixel. Returns
    ``"llvmpipe"`` (the referee sides with refraster), ``"ill-conditioned"`` (a clip polygon
    reaches w = 0), ``"near-edge"`` (the sample within 1/128 px of a candidate's edge: decided
    by the snapping), ``"tie"`` or ``"refraster"``."""
    from test_llvmpipe_oracle import SNAP_MARGIN, _edge_distance
    w, h = sc.width, sc.height
    x16, y16 = (int(t) for t in pattern[s])
    xw = Fraction(int(c)) + Fraction(x16, 16)
    yw = Fraction(h - 1 - int(r)) + 1 - Fraction(y16, 16)
    q = (2 * xw / w - 1, 2 * yw / h - 1, Fraction(1))
    offsets = np.cumsum([0] + [len(f) for _, f in draws])
    cands = {int(g) for g in np.concatenate([ours[r, c], gl[r, c]]) if g >= 0}
    best, near = None, False
    for g in sorted(cands):
        k = int(np.searchsorted(offsets, g, side="right")) - 1
        clip, faces = draws[k]
        tri = clip[faces[g - offsets[k]]]
        poly = clip_polygon(tri, GL_NEAR_FAR)
        if any(p[3] == 0 for p in poly):
            return "ill-conditioned"
        inside = covers(poly, q) if len(poly) >= 3 else False
        if inside is None:
            return "tie"
        if len(poly) >= 3 and _edge_distance(poly, float(xw), float(yw), w, h) < SNAP_MARGIN:
            near = True
        if inside:
            z = gl_window_depth(tri, q)
            if z is not None and (best is None or z < best[0]):
                best = (z, g)
    exact = best[1] if best is not None else -1
    if near:
        return _snapped_referee(draws, offsets, cands, int(c), h - 1 - int(r), (x16, y16), w, h,
                                int(ours[r, c, s]), int(gl[r, c, s]))
    if exact == int(ours[r, c, s]) and exact != int(gl[r, c, s]):
        return "llvmpipe"
    return "refraster"


def _snapped_referee(draws, offsets, cands, px, py, pos, w, h, mine, theirs):
    """A sample within 1/128 px of an edge: both renderers declare 8 sub-pixel bits
    (``GL_SUBPIXEL_BITS``), so the triangle whose coverage counts is the one with snapped
    vertices. Snapped here on its own (:func:`_window`) and tested exactly at the sample with
    llvmpipe's fill rule (integers), the nearest by exact depth wins: ``"snapped"`` when that
    is refraster's answer and not llvmpipe's, else ``"near-edge"`` (counted against
    refraster). Faces crossing a clip plane stay ``"near-edge"``."""
    sx = (px << 8) + (pos[0] - 8) * 16
    sy = (py << 8) + (8 - pos[1]) * 16
    q = (Fraction(2 * px * 16 + 2 * pos[0], 16 * w) - 1,
         Fraction(2 * py * 16 + 32 - 2 * pos[1], 16 * h) - 1, Fraction(1))
    best = None
    for g in sorted(cands):
        k = int(np.searchsorted(offsets, g, side="right")) - 1
        clip, faces = draws[k]
        tri = clip[faces[g - offsets[k]]].astype(np.float64)
        if not ((np.abs(tri[:, 2]) <= tri[:, 3]).all() and (tri[:, 3] > 0).all()
                and (np.abs(tri[:, :2]) <= 4 * tri[:, 3:4]).all()):
            return "near-edge"   # clipped (near/far, or beyond a guard band of 4 viewports)
        _, _, _, X, Y = _window(tri.astype(np.float32), w, h)
        X, Y = [int(t) for t in X], [int(t) for t in Y]
        ids = [0, 1, 2]
        area = (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0])
        if area == 0:
            continue
        if area < 0:
            ids = [0, 2, 1]
        inside = True
        for j in range(3):
            a, b = ids[(j + 1) % 3], ids[(j + 2) % 3]
            dx, dy = X[b] - X[a], Y[b] - Y[a]
            e = dx * (sy - Y[a]) - dy * (sx - X[a])
            inside &= e > 0 or (e == 0 and (dy < 0 or (dy == 0 and dx > 0)))
        if inside:
            z = gl_window_depth(tri, q)
            if z is not None and (best is None or z < best[0]):
                best = (z, g)
    exact = best[1] if best is not None else -1
    return "snapped" if exact == mine and exact != theirs else "near-edge"


def agreement(M, pattern="gl_llvmpipe", referee=True):
    """Per scene: ``(name, pixels either covers, pixels whose sample sets differ, verdicts of
    the differing samples)``, and the positions llvmpipe reports."""
    key = (pattern, referee)
    if key in _ORACLE:
        return _ORACLE[key]
    rows, reported = [], None
    pts = SP.pattern(RasterState(samples=4, sample_locations=pattern))
    for sc in _oracle_scenes():
        ids, reported, draws = _oracle_frame(M, sc)
        sf = refraster.render_samples(sc.meshes, view=sc.view, proj=sc.proj, width=sc.width,
                                      height=sc.height,
                                      raster=RasterState(samples=4, sample_locations=pattern))
        ours = _global(sf, sc)
        either = (ids >= 0).any(2) | (ours >= 0).any(2)
        differ = either & ~(ids == ours).all(2)
        verdicts = {}
        if referee:
            for r, c, s in np.argwhere(ids != ours):
                verdicts[(int(r), int(c), int(s))] = _referee(sc, draws, r, c, s, pts, ours,
                                                              ids)
        rows.append((sc.name, int(either.sum()), int(differ.sum()), verdicts))
    _ORACLE[key] = (rows, reported)
    return rows, reported


def agreement_report():
    """The table of docs/multisample.md (``python -c "import sys; sys.path.insert(0, 'tests');
    import test_msaa as t; t.agreement_report()"``)."""
    from oracles import llvmpipe_msaa as M
    rows, reported = agreement(M)
    print(f"positions reported: {reported}")
    print("| scene | pixels | sample sets differ | refraster right | snapped triangle | "
          "ill-conditioned | against refraster |")
    print("|---|---|---|---|---|---|---|")
    tot = [0] * 6
    for name, n, d, v in rows:
        vals = list(v.values())
        cells = [n, d, vals.count("llvmpipe"), vals.count("snapped"),
                 vals.count("ill-conditioned"), _against(v)]
        tot = [a + b for a, b in zip(tot, cells)]
        print(f"| {name} | " + " | ".join(map(str, cells)) + " |")
    print("| total | " + " | ".join(map(str, tot)) + " |")


def _against(verdicts):
    """Pixels with a differing sample the referee does not decide for refraster (llvmpipe
    wrong) or leave out (ill-conditioned 1e30 clip coordinates, as at one sample)."""
    return len({(r, c) for (r, c, _), v in verdicts.items()
                if v not in ("llvmpipe", "snapped", "ill-conditioned")})


def test_llvmpipe_4x_per_sample_coverage(oracle):
    """≥ 99.99 % of the pixels either renderer covers have the same four sample ids (in
    sample-index order) under ``sample_locations="gl_llvmpipe"``, every difference decided by
    the exact referee as at one sample."""
    oracle("oracles.llvmpipe")
    M = oracle("oracles.llvmpipe_msaa")
    rows, reported = agreement(M)
    assert [tuple(p) for p in reported] == list(SP.GL_LLVMPIPE_4X_REPORTED)
    total = sum(n for _, n, _, _ in rows)
    against = sum(_against(v) for *_, v in rows)
    assert total > 50_000
    assert 1.0 - against / total >= MIN_AGREEMENT, (against, total)
    for name, *_, v in rows:
        if any(x == "ill-conditioned" for x in v.values()):
            assert name.endswith("huge_1e30"), name


def test_llvmpipe_4x_is_not_the_standard_picture(oracle):
    """The same scenes under Vulkan's standard 4x pattern (llvmpipe's mirror image) disagree
    on several per cent of the covered pixels: the test tells a pattern from its mirror."""
    oracle("oracles.llvmpipe")
    M = oracle("oracles.llvmpipe_msaa")
    rows, _ = agreement(M, "standard", referee=False)
    total = sum(n for _, n, _, _ in rows)
    differ = sum(d for _, _, d, _ in rows)
    assert differ / total > 0.01, (differ, total)


def test_techniques_refuse_a_multisample_state():
    # render_clipped and ldi.peel render samples (tests/test_msaa_clipsurface.py)
    from refraster.cutaway import render_cutaway
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    f = np.array([[0, 1, 2]])
    for fn, args in ((render_cutaway, ((v, f), (v, f))),):
        with pytest.raises(ValueError, match="raster.samples must be 1 .*render_samples"):
            fn(*args, view=EYE, proj=EYE, width=8, height=8,
               raster=RasterState(samples=4))


@pytest.mark.parametrize("samples", [4, 8])
def test_vulkan_window_is_the_gl_picture_mirrored(samples):
    """Under ``ndc_y="down"`` with ``origin="upper_left"`` the same clip coordinates make the
    picture mirrored top to bottom with the same window numbers (so the same snapping): the
    frame is the OpenGL frame flipped, rendered with the pattern mirrored and the fill rule that
    owns top edges instead of bottom ones (the rule and the pattern are the picture's): the
    same faces at every sample, the facing turned."""
    w, h = 31, 22
    v, f = _soup(samples, 40, w, h, grid=True)
    pts = SPEC[samples]
    mirrored = [(x, 16 - y) for x, y in pts]
    assert all(0 < y for _, y in pts)   # 4x, 8x: every mirror image is on the 0..15 grid
    vk = _render(v, f, w, h, samples=samples, ndc_y="down", origin="upper_left")
    gl = _render(v, f, w, h, samples=samples, fill_rule="top-left",
                 sample_locations=mirrored)
    assert np.array_equal(vk.prim_id, gl.prim_id[::-1])
    # the depth plane is evaluated in each window's own float32 coordinates: rounding apart
    np.testing.assert_allclose(vk.depth, gl.depth[::-1], atol=3e-7, rtol=0)
    cov = vk.prim_id >= 0
    assert cov.any()
    assert np.array_equal(vk.front_facing[cov], ~gl.front_facing[::-1][cov])


def test_reversed_depth_per_sample():
    """``depth_func="greater"`` with the depth cleared to 0 on the scene with z negated picks
    the same face at every sample as ``"less"`` on the scene (window depth 1 − z there)."""
    w, h = 27, 19
    v, f = _soup(21, 40, w, h)
    near = _render(v, f, w, h, samples=8)
    flip = v * np.array([1, 1, -1], np.float32)
    far = _render(flip, f, w, h, samples=8, depth_func="greater", clear_depth=0.0)
    same = near.prim_id == far.prim_id
    tw = twin(v, f, w, h, SPEC[8])
    assert (same | (np.abs(tw[2] - tw[1]) < 1e-5)).all()
    cov = near.prim_id >= 0
    np.testing.assert_allclose(far.depth[cov], 1.0 - near.depth[cov], atol=2e-7)
    assert (far.depth[~cov] == 0.0).all()
