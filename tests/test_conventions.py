"""The API conventions of the raster state (issue 39), on scenes worked by hand: window depth in
each depth range, clipping at z = 0, reversed-Z with an infinite far plane, winding and the fill
rule under each window origin and NDC y, depth clamp, and a triangle through the eye plane.
The outside opinion on the same conventions is tests/test_lavapipe_oracle.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

import refraster as rf
from refraster import camera
from refraster.raster.state import RasterState

GL = RasterState()
Z01 = RasterState(depth_range="zero_to_one")


def _frags(clip, faces, w, h, state):
    return rf.rasterize(np.asarray(clip, np.float64), np.asarray(faces), w, h, raster=state)


def _image(frags, w, h, values, fill):
    out = np.full(h * w, fill, np.asarray(values).dtype)
    out[frags.pixel] = values
    return out.reshape(h, w)


def _quad(z, w=(1.0, 1.0, 1.0, 1.0)):
    """A full-viewport quad, clip z given per vertex (or z/w constant when a scalar), the
    clip coordinates scaled by ``w`` per vertex (the projection is the same)."""
    xy = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    w = np.asarray(w, np.float64)
    zz = np.broadcast_to(np.asarray(z, np.float64), (4,))
    clip = np.column_stack([xy * w[:, None], zz * w, w])
    return clip, np.array([[0, 1, 2], [0, 2, 3]])


# ------------------------------------------------------------------------------ depth range

@pytest.mark.parametrize("w", [(1.0, 1.0, 1.0, 1.0), (1.0, 2.0, 4.0, 2.0)])
def test_window_depth_in_each_depth_range(w):
    """z/w = 0.25 everywhere: window depth 0.5·0.25 + 0.5 = 0.625 (GL), 0.25 (zero_to_one),
    exactly, whatever the w of each vertex; z/w = −0.5 lies in front of the zero-to-one near
    plane (nothing drawn) and at depth 0.25 in GL's range."""
    clip, f = _quad(0.25, w)
    for state, expect in ((GL, 0.625), (Z01, 0.25)):
        fr = _frags(clip, f, 8, 6, state)
        assert len(fr) == 48 and np.all(fr.depth == np.float32(expect)), state.depth_range
    clip, f = _quad(-0.5, w)
    assert np.all(_frags(clip, f, 8, 6, GL).depth == np.float32(0.25))
    assert len(_frags(clip, f, 8, 6, Z01)) == 0


def test_clipping_at_z_zero():
    """z = 0.5·x (w = 1): the zero-to-one near plane z ≥ 0 cuts the quad at x = 0, the
    boundary between columns 3 and 4 of 8 (no centre on it); GL's z ≥ −w keeps all of it.
    Depth at a centre: 0.5·x (zero_to_one), 0.25·x + 0.5 (GL)."""
    w, h = 8, 2
    clip, f = _quad([-0.5, 0.5, 0.5, -0.5])
    xc = (np.arange(w) + 0.5) / w * 2 - 1
    for state, cols, depth in ((Z01, slice(4, 8), 0.5 * xc), (GL, slice(0, 8), 0.25 * xc + 0.5)):
        fr = _frags(clip, f, w, h, state)
        cover = _image(fr, w, h, np.ones(len(fr), bool), False)
        expect = np.zeros((h, w), bool)
        expect[:, cols] = True
        assert np.array_equal(cover, expect), state.depth_range
        z = _image(fr, w, h, fr.depth, np.float32(np.nan))
        assert np.allclose(z[:, cols], depth[cols], atol=1e-7, rtol=0)


# ------------------------------------------------------------------------------ reversed-Z

def test_reversed_infinite_perspective_maps_near_to_one_and_infinity_to_zero():
    n = 0.5
    p = camera.perspective(60, 1.0, n, math.inf, reversed=True, depth_range="zero_to_one")
    assert (p[2, 2], p[2, 3], p[3, 2]) == (0.0, n, -1.0)
    assert math.copysign(1.0, p[2, 2]) == 1.0          # +0, not −0
    for z_eye, expect in ((-n, 1.0), (-2 * n, 0.5), (-1e300, n / 1e300)):
        c = p @ [0.0, 0.0, z_eye, 1.0]
        assert c[2] / c[3] == expect, z_eye
    assert camera.near_far(p, reversed=True, depth_range="zero_to_one") == (n, math.inf)
    # every range and direction: near → d_n, far → d_f
    for rng, d in (("negative_one_to_one", (-1.0, 1.0)), ("zero_to_one", (0.0, 1.0))):
        for rev in (False, True):
            d_n, d_f = d[::-1] if rev else d
            for far in (10.0, math.inf):
                m = camera.perspective(50, 1.3, n, far, reversed=rev, depth_range=rng)
                at = [(m @ [0, 0, z, 1.0]) for z in (-n, -far if far < math.inf else -1e300)]
                assert abs(at[0][2] / at[0][3] - d_n) < 1e-15
                assert abs(at[1][2] / at[1][3] - d_f) < 1e-12
                assert np.allclose(camera.near_far(m, reversed=rev, depth_range=rng), (n, far))
            o = camera.orthographic(-1, 1, -1, 1, n, 10.0, reversed=rev, depth_range=rng)
            assert abs((o @ [0, 0, -n, 1.0])[2] - d_n) < 1e-15
            assert abs((o @ [0, 0, -10.0, 1.0])[2] - d_f) < 1e-15


def test_opengl_matrices_are_unchanged():
    """The default projections are the same bytes as gluPerspective/glFrustum/glOrtho's
    formulas (every existing output depends on them)."""
    n, f, fovy, a = 0.5, 10.0, 45.0, 4 / 3
    t = 1.0 / np.tan(np.radians(fovy) / 2.0)
    expect = np.zeros((4, 4))
    expect[0, 0], expect[1, 1], expect[3, 2] = t / a, t, -1.0
    expect[2, 2], expect[2, 3] = (f + n) / (n - f), 2 * f * n / (n - f)
    assert camera.perspective(fovy, a, n, f).tobytes() == expect.tobytes()
    assert camera.near_far(camera.perspective(fovy, a, n, math.inf))[1] == math.inf


def test_reversed_z_render_keeps_float_precision_far_away():
    """Reversed-Z, zero-to-one, infinite far: quads at z_eye = −1, −4 and −1e20 (near 0.5)
    render at window depth n/d = 0.5, 0.125, 5e-21 to float32's relative precision; drawn
    far first, the nearest wins under ``greater`` with the buffer cleared to 0."""
    n = 0.5
    proj = camera.perspective(90, 1.0, n, math.inf, reversed=True, depth_range="zero_to_one")
    state = RasterState(depth_range="zero_to_one", depth_func="greater", clear_depth=0.0)
    quads = []
    for d in (1e20, 4.0, 1.0):
        s = d * 2.0     # covers the view at that distance
        v = np.array([[-s, -s, -d], [s, -s, -d], [s, s, -d], [-s, s, -d]])
        quads.append((v, np.array([[0, 1, 2], [0, 2, 3]])))
    for k, (v, faces) in enumerate(quads):
        fb = rf.render([(v, faces)], view=np.eye(4), proj=proj, width=4, height=4, raster=state)
        d = -v[0, 2]
        assert np.all(np.abs(fb.depth / (n / d) - 1.0) < 2.0 ** -22), d
    fb = rf.render(quads, view=np.eye(4), proj=proj, width=4, height=4, raster=state)
    assert np.all(fb.object_id == 2) and np.all(fb.depth == np.float32(0.5))
    gl = rf.render(quads, view=np.eye(4), proj=proj, width=4, height=4,
                   raster=state.replace(depth_func="less", clear_depth=1.0))
    assert np.all(gl.object_id == 0)   # 'less' on a reversed projection: the farthest wins


# ----------------------------------------------------------------- winding, origin, NDC y

STATES = {
    "gl": RasterState(),
    "d3d": RasterState(origin="upper_left", ndc_y="up"),
    "vulkan": RasterState(origin="upper_left", ndc_y="down"),
    "gl_ndc_down": RasterState(origin="lower_left", ndc_y="down"),
}


def _ndc_mesh(points, faces, w, h, ndc_y, z=0.5):
    """Vertices given in picture pixels (x right, y up from the bottom of the picture) as NDC
    for ``ndc_y``, so every state draws the same picture; the identity camera."""
    p = np.asarray(points, np.float64)
    x = 2.0 * p[:, 0] / w - 1.0
    y = 2.0 * p[:, 1] / h - 1.0
    return np.column_stack([x, y if ndc_y == "up" else -y, np.full(len(p), z)]), \
        np.asarray(faces, np.int64)


def _render(mesh, w, h, state):
    return rf.render(mesh, view=np.eye(4), proj=np.eye(4), width=w, height=h, raster=state)


@pytest.mark.parametrize("name", list(STATES))
def test_winding_is_judged_as_the_picture_is_seen(name):
    """A triangle counter-clockwise as seen is front-facing under every origin and NDC y; the
    same NDC coordinates under ``ndc_y="down"`` draw the picture upside down, clockwise, so
    back-facing (and culled by ``cull="back"``)."""
    w, h = 12, 8
    state = STATES[name]
    tri = [(1.3, 1.2), (10.7, 2.1), (3.1, 6.8)]          # CCW as seen, no centre on an edge
    same_picture = _render(_ndc_mesh(tri, [[0, 1, 2]], w, h, state.ndc_y), w, h, state)
    gl = _render(_ndc_mesh(tri, [[0, 1, 2]], w, h, "up"), w, h, GL)
    assert gl.mask.sum() > 10 and gl.front_facing[gl.mask].all()
    assert np.array_equal(same_picture.mask, gl.mask)
    assert same_picture.front_facing[same_picture.mask].all()
    # GL's NDC coordinates in this state
    raw = _render(_ndc_mesh(tri, [[0, 1, 2]], w, h, "up"), w, h, state)
    flipped = state.ndc_y == "down"
    assert np.array_equal(raw.mask, np.flipud(gl.mask) if flipped else gl.mask)
    assert raw.front_facing[raw.mask].all() == (not flipped)
    culled = _render(_ndc_mesh(tri, [[0, 1, 2]], w, h, "up"), w, h, state.replace(cull="back"))
    assert culled.mask.any() == (not flipped)


@pytest.mark.parametrize("name", list(STATES))
def test_fill_rule_owns_edges_as_the_picture_is_seen(name):
    """Two triangles share a horizontal edge through the centres of picture row 2 (of 4,
    row 0 at the top) and two share a vertical edge through the centres of column 3:
    ``"llvmpipe"`` gives the horizontal edge's centres to the triangle above (the edge is its
    bottom), ``"top-left"`` to the one below (its top: Direct3D's rule), the same under every
    origin and NDC y; the vertical edge's centres go to the triangle on the right (its left
    edge) under both."""
    w, h = 8, 4
    state = STATES[name]
    above = [(-4.0, 1.5), (12.0, 1.5), (4.0, 9.0)]
    below = [(-4.0, 1.5), (4.0, -6.0), (12.0, 1.5)]
    horizontal = _ndc_mesh(above + below, [[0, 1, 2], [3, 4, 5]], w, h, state.ndc_y)
    left = [(3.5, -4.0), (3.5, 8.0), (-6.0, 2.0)]
    right = [(3.5, -4.0), (12.0, 2.0), (3.5, 8.0)]
    vertical = _ndc_mesh(left + right, [[0, 1, 2], [3, 4, 5]], w, h, state.ndc_y)
    for rule, owner in (("llvmpipe", 0), ("top-left", 1)):
        fb = _render(horizontal, w, h, state.replace(fill_rule=rule))
        expect = np.array([[0] * w, [0] * w, [owner] * w, [1] * w])
        assert np.array_equal(fb.prim_id, expect), (name, rule)
        fb = _render(vertical, w, h, state.replace(fill_rule=rule))
        assert np.array_equal(fb.prim_id, np.tile([0, 0, 0, 1, 1, 1, 1, 1], (h, 1))), (name, rule)


def test_upper_left_snaps_in_its_own_coordinates():
    """Under an upper-left origin window y is computed and snapped where the API computes it,
    ``rint((y_w − ½)·2^8)`` with ``y_w = (±y)·(1/w)·H/2 + H/2`` in float32, then turned into
    the picture-up position ``(H − 1)·2^8`` minus that, exactly. Random y: every vertex matches
    that arithmetic (written here in NumPy float32), and for some the picture-up route (GL's
    formula on the same picture) snaps 1/256 px elsewhere — the two are different roundings."""
    from refraster.raster.primitive import convention_code, setup_triangles
    rng = np.random.default_rng(39)
    w, h = 64, 48
    n = 20000
    y = rng.uniform(-1.0, 1.0, n).astype(np.float32)
    wc = rng.uniform(0.5, 3.0, n).astype(np.float32)
    yc = y * wc                        # clip y (float32)
    clip = np.column_stack([np.zeros(n), yc, 0.5 * wc, wc]).astype(np.float32)
    faces = np.arange(n - n % 3).reshape(-1, 3)
    hh = np.float32(h * 0.5)
    rw = np.float32(1.0) / wc
    for ndc_y, sign in (("up", -1), ("down", 1)):
        p = setup_triangles(clip.astype(np.float64), faces, w, h,
                            conv=convention_code(origin="upper_left", ndc_y=ndc_y))
        yw = (np.float32(sign) * yc) * rw * hh + hh
        api = (h - 1) * 256 - np.rint((yw - np.float32(0.5)) * np.float32(256)).astype(np.int64)
        assert np.array_equal(p.vy[:len(api)], api), ndc_y
        up = np.rint(((np.float32(-sign) * yc) * rw * hh + hh - np.float32(0.5))
                     * np.float32(256)).astype(np.int64)
        assert 0 < np.count_nonzero(up != api) < n // 100, ndc_y


# ------------------------------------------------------------------------ depth clamp, eye

def test_depth_clamp_keeps_what_near_and_far_clipping_remove():
    """z = 2·x (w = 1): GL clips to |x| ≤ ½ (columns 2–5 of 8); with depth clamp every column
    is drawn, depth 0.5·z + 0.5 clamped to [0, 1] (0 on the left, 1 on the right). Under
    zero_to_one (z = x) the left half, in front of the near plane, is drawn at depth 0."""
    w, h = 8, 1
    xc = (np.arange(w) + 0.5) / w * 2 - 1
    clip, f = _quad([-2.0, 2.0, 2.0, -2.0])
    plain = _frags(clip, f, w, h, GL)
    assert np.array_equal(np.sort(plain.pixel % w), [2, 3, 4, 5])
    fr = _frags(clip, f, w, h, GL.replace(depth_clamp=True))
    z = _image(fr, w, h, fr.depth, np.float32(np.nan))[0]
    assert np.allclose(z, np.clip(xc + 0.5, 0.0, 1.0), atol=1e-7, rtol=0)
    clip, f = _quad([-1.0, 1.0, 1.0, -1.0])
    fr = _frags(clip, f, w, h, Z01.replace(depth_clamp=True))
    z = _image(fr, w, h, fr.depth, np.float32(np.nan))[0]
    assert np.allclose(z, np.clip(xc, 0.0, 1.0), atol=1e-7, rtol=0)
    assert len(_frags(clip, f, w, h, Z01)) == 4


def _eye_plane_quad(z_ndc):
    """A quad from w = 1 to w = −1 (through the eye plane): x = w/2 − 0.3, y = ±0.5,
    z = z_ndc·w. In front of the eye it covers the pixel centres with x_ndc ≤ 0.2 and
    |y_ndc| ≤ (0.5 − x_ndc)/0.6; behind the eye it would project to x_ndc > 0.5."""
    w = np.array([1.0, -1.0, -1.0, 1.0])
    y = np.array([-0.5, -0.5, 0.5, 0.5])
    clip = np.column_stack([0.5 * w - 0.3, y, z_ndc * w, w])
    return clip, np.array([[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize("state", [GL.replace(depth_clamp=True), Z01.replace(depth_clamp=True),
                                   GL], ids=["gl_clamp", "zero_to_one_clamp", "gl"])
def test_triangle_through_the_eye_plane(state):
    """Under depth clamp nothing in front of the near plane is clipped (z_ndc = −2 here), but
    what lies at or behind the eye still is: coverage is the exact set of centres in front of
    the eye (none past x_ndc = 0.5, where the part behind the eye would land), at depth 0.
    Without the clamp the whole quad lies in front of the near plane: nothing."""
    w, h = 40, 30
    clip, f = _eye_plane_quad(-2.0)
    fr = _frags(clip, f, w, h, state)
    if not state.depth_clamp:
        assert len(fr) == 0
        return
    xs = (np.arange(w) + 0.5) / w * 2 - 1
    ys = 1 - (np.arange(h) + 0.5) / h * 2           # row 0 at the top
    X, Y = np.meshgrid(xs, ys)
    inside = (X <= 0.2) & (np.abs(Y) <= (0.5 - X) / 0.6)
    margin = (np.abs(X - 0.2) < 1e-3) | (np.abs(np.abs(Y) - (0.5 - X) / 0.6) < 1e-3)
    cover = _image(fr, w, h, np.ones(len(fr), bool), False)
    assert inside.sum() > 100
    assert np.array_equal(cover[~margin], inside[~margin])
    assert np.all(fr.depth == 0.0)
    behind = np.array([[0.2, 0.0, 0.5, -1.0], [0.4, 0.3, 0.5, -1.0], [0.1, 0.4, 0.5, -2.0]])
    assert len(_frags(behind, [[0, 1, 2]], w, h, state)) == 0


# ------------------------------------------------------------ the two paths, every state

CONVENTION_STATES = [
    RasterState(depth_range="zero_to_one", origin="upper_left", fill_rule="top-left"),
    RasterState(depth_range="zero_to_one", origin="upper_left", ndc_y="down",
                fill_rule="top-left", cull="back"),
    RasterState(depth_range="zero_to_one", depth_func="greater", clear_depth=0.0,
                origin="upper_left"),
    RasterState(depth_range="zero_to_one", depth_clamp=True, ndc_y="down"),
    RasterState(depth_clamp=True, depth_func="gequal", clear_depth=0.0),
]


@pytest.mark.parametrize("state", CONVENTION_STATES, ids=range(len(CONVENTION_STATES)))
def test_fused_equals_stream_and_resolve_in_every_convention(state):
    """``render``'s fused tile pass (with its vectorized ``greater`` loop) gives the bits of
    ``draw`` + ``resolve`` in each convention, on scenes crossing the near plane."""
    from oracles import scenes as S
    for sc in S.random_scenes(13, seed=39)[4:8]:
        proj = sc.proj.copy()
        if state.depth_range == "zero_to_one":
            proj = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, .5, .5], [0, 0, 0, 1.]]) @ proj
        if state.depth_func in ("greater", "gequal"):
            proj[2] = proj[3] - proj[2] if state.depth_range == "zero_to_one" else -proj[2]
        kw = dict(view=sc.view, proj=proj, width=sc.width, height=sc.height, raster=state)
        fb = rf.render(sc.meshes, **kw)
        frags = rf.draw(sc.meshes, **kw)
        res = rf.resolve(frags, raster=state)
        win = res.winner
        assert np.array_equal(fb.depth.view(np.uint32), res.depth.view(np.uint32)), sc.name
        assert np.array_equal(fb.prim_id, np.where(win >= 0, frags.prim_id[win], -1)), sc.name
        assert np.array_equal(fb.front_facing,
                              np.where(win >= 0, frags.front_facing[win], False)), sc.name
        assert fb.mask.sum() > 50


# ------------------------------------------------------------------------------ bad input

@pytest.mark.parametrize("call, exc, msg", [
    (lambda: camera.perspective(45, 1, 0.5, 10, depth_range="zero-to-one"), ValueError,
     "^depth_range must be one of"),
    (lambda: camera.perspective(45, 1, 0.5, 10, reversed=1), TypeError, "^reversed must be"),
    (lambda: camera.orthographic(-1, 1, -1, 1, 0.5, math.inf), ValueError, "^far must be"),
    (lambda: camera.perspective(45, 1, 0.5, -math.inf), ValueError, "^far must be"),
    (lambda: camera.frustum(-1, 1, -1, 1, 0.5, 0.4, reversed=True), ValueError,
     "^far must be greater"),
])
def test_bad_camera_input_one_line(call, exc, msg):
    with pytest.raises(exc, match=msg) as info:
        call()
    assert "\n" not in str(info.value)


def test_volumetric_depth_sprite_refuses_other_conventions():
    """A sprite's own orthographic camera maps texture depth into GL's clip space: a state
    with another depth range, origin, NDC y or depth clamp is refused with one line."""
    from refraster.ldi import VolumetricDepthSprite
    from refraster.scenes import cube
    m = cube()
    for field, value in (("depth_range", "zero_to_one"), ("ndc_y", "down"),
                         ("origin", "upper_left"), ("depth_clamp", True)):
        with pytest.raises(ValueError, match="^raster.depth_range, origin, ndc_y") as info:
            VolumetricDepthSprite.from_mesh(m, 16, raster=RasterState(**{field: value}))
        assert "\n" not in str(info.value)
