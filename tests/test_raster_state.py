"""The raster state as one value (issue 38): validation, the default, and the two fields that
are new to the pipeline's behaviour (``front_face="cw"``, ``depth_write=False`` in ``render``),
each against an independent construction of the same picture."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

import refraster as rf
from refraster.raster.state import RasterState, as_raster_state

FIELDS = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing", "barycentric")
VIEW = rf.look_at([0.9, 1.3, 3.0], [0, 0, 0])
PROJ = rf.perspective(45, 4 / 3, 0.5, 10)
KW = dict(view=VIEW, proj=PROJ, width=64, height=48)


@pytest.mark.parametrize("field, value, exc", [
    ("depth_func", "lesser", ValueError), ("depth_func", 1, TypeError),
    ("depth_write", 1, TypeError), ("clear_depth", 1.5, ValueError),
    ("clear_depth", float("nan"), ValueError), ("clear_depth", "1", TypeError),
    ("cull", "sideways", ValueError), ("front_face", "left", ValueError),
    ("subpixel_bits", 7, ValueError), ("subpixel_bits", 8.0, TypeError),
    ("subpixel_bits", True, TypeError), ("fill_rule", "top_right", ValueError),
    ("precision", "float16", ValueError), ("normals", "given", ValueError),
    ("depth_range", "zero_to_inf", ValueError), ("depth_range", 0, TypeError),
    ("origin", "center", ValueError), ("ndc_y", "left", ValueError),
    ("depth_clamp", "yes", TypeError), ("depth_clamp", 1, TypeError),
    ("depth_format", "unorm32", ValueError), ("depth_format", None, TypeError),
])
def test_every_field_is_checked_with_one_line_naming_it(field, value, exc):
    with pytest.raises(exc, match=rf"^raster\.{field} ") as info:
        RasterState(**{field: value})
    assert "\n" not in str(info.value)


def test_values_are_canonical_immutable_and_comparable():
    s = RasterState(depth_func="LEQUAL", cull="Back", clear_depth=0, subpixel_bits=np.int64(4),
                    depth_write=np.True_)
    assert (s.depth_func, s.cull, s.clear_depth, s.subpixel_bits) == ("lequal", "back", 0.0, 4)
    assert type(s.clear_depth) is float and type(s.depth_write) is bool
    assert s == RasterState(depth_func="lequal", cull="back", clear_depth=0.0, subpixel_bits=4)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.cull = "none"
    assert s.replace(cull="front").cull == "front" and s.cull == "back"
    with pytest.raises(ValueError, match="raster.cull"):
        s.replace(cull="up")
    assert RasterState.from_dict(s.as_dict()) == s
    with pytest.raises(ValueError, match="unknown field.*'culling'"):
        RasterState.from_dict({"culling": "back"})
    assert as_raster_state(None) == RasterState()
    with pytest.raises(TypeError, match="raster must be a refraster.RasterState"):
        as_raster_state({"cull": "back"})


def test_the_defaults_are_opengls():
    s = RasterState()
    assert s.as_dict() == dict(depth_func="less", depth_write=True, clear_depth=1.0,
                               cull="none", front_face="ccw", subpixel_bits=8,
                               fill_rule="llvmpipe", precision="float32", normals="flat",
                               depth_range="negative_one_to_one", origin="lower_left",
                               ndc_y="up", depth_clamp=False, depth_format="float32",
                               samples=1, sample_locations="standard", interpolation="center")


def _bytes(fb):
    return {k: getattr(fb, k).tobytes() for k in FIELDS}


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(2)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


@pytest.mark.parametrize("cull", ["none", "back", "front"])
def test_front_face_cw_is_ccw_of_the_reversed_winding(sphere, cull):
    """An outside construction of the same picture: reversing every face's winding under the
    default state must give what ``front_face="cw"`` gives of the original mesh — coverage,
    depth, ids, facing and culling (the barycentrics refer to each face's own vertex order,
    so they are compared after the same reordering)."""
    v, f = sphere
    rev = (v, f[:, ::-1].copy())
    for path in ("fused", "stream", "reusable"):
        kw = dict(KW)
        if path == "stream":
            kw["fragment_stage"] = lambda fr: np.ones(len(fr), bool)
        if path == "reusable":
            kw["out"] = rf.Framebuffer.reusable(64, 48)
            rf.render((v, f), **kw)   # a frame with other facing first: cleared right
        a = rf.render((v, f), raster=RasterState(front_face="cw", cull=cull), **kw)
        if path == "reusable":
            a = {k: getattr(a, k).copy() for k in FIELDS}
            kw["out"] = rf.Framebuffer.reusable(64, 48)
        b = rf.render(rev, raster=RasterState(cull=cull), **kw)
        get = (lambda x, k: x[k]) if isinstance(a, dict) else getattr
        for k in ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing"):
            want = getattr(b, k)
            if k == "normal":   # flat normals: the reversed faces' normals point the other way
                want = -want
                want[~b.mask] = getattr(b, k)[~b.mask]
            assert np.array_equal(get(a, k), want), (path, k)
        bary = get(a, "barycentric")
        assert np.array_equal(bary, getattr(b, "barycentric")[..., ::-1]), path
        fa, covered = get(a, "front_facing"), get(a, "prim_id") >= 0
        assert covered.sum() > 100, path
        front = fa[covered]
        # the sphere's outside is counter-clockwise on screen: back-facing under "cw"; culling
        # the back leaves its inside, clockwise on screen: front-facing
        if cull == "back":
            assert front.all(), path
        else:
            assert not front.any(), path
        assert not fa[~covered].any(), path


def test_front_face_cw_turns_facing_in_draw_and_rasterize(sphere):
    v, f = sphere
    ccw = rf.draw((v, f), **KW)
    cw = rf.draw((v, f), raster=RasterState(front_face="cw"), **KW)
    assert np.array_equal(ccw.pixel, cw.pixel) and np.array_equal(ccw.depth, cw.depth)
    assert np.array_equal(ccw.front_facing, ~cw.front_facing)
    assert ccw.front_facing.any() and not ccw.front_facing.all()
    back = rf.draw((v, f), raster=RasterState(front_face="cw", cull="back"), **KW)
    assert back.front_facing.all() and len(back) == int((~ccw.front_facing).sum())
    clip = rf.raster.primitive.transform_vertices(v, PROJ @ VIEW)
    r = rf.rasterize(clip, f, 64, 48, raster=RasterState(front_face="cw"))
    assert np.array_equal(r.front_facing, ~rf.rasterize(clip, f, 64, 48).front_facing)


def test_depth_write_off_lets_the_last_fragment_that_passes_win():
    """Analytic: two quads, the far one drawn last. With depth writes off, ``less`` compares
    every fragment with the clear depth, so the far quad wins where they overlap; with writes
    on, the near one. ``render`` gives what ``draw`` + ``resolve`` give."""
    near = (np.array([[-1, -1, 0.5], [1, -1, 0.5], [1, 1, 0.5], [-1, 1, 0.5]], float),
            np.array([[0, 1, 2], [0, 2, 3]]))
    far = (near[0] - [0.3, 0.0, 1.0], near[1])
    kw = dict(view=rf.look_at([0, 0, 3], [0, 0, 0]), proj=PROJ, width=32, height=24)
    on = rf.render([near, far], **kw)
    off = rf.render([near, far], raster=RasterState(depth_write=False), **kw)
    overlap = rf.render(near, **kw).mask & rf.render(far, **kw).mask
    assert overlap.sum() > 50 and (on.mask == off.mask).all()
    assert (off.object_id[overlap] == 1).all() and (on.object_id[overlap] == 0).all()
    assert (off.depth == 1.0).all()   # the depth buffer is the G-buffer's depth: never written
    frags = rf.draw([near, far], **kw)
    res = rf.resolve(frags, raster=RasterState(depth_write=False))
    ref = rf.Framebuffer.from_fragments(frags, res)
    assert _bytes(off) == _bytes(ref)
    assert (res.depth == 1.0).all()   # nothing was written


def test_the_default_state_is_the_none_state(sphere):
    a = rf.render(sphere, **KW)
    b = rf.render(sphere, raster=RasterState(), **KW)
    assert _bytes(a) == _bytes(b)
