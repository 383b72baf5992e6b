"""Issue 28, fifth pass: ``render(out=Framebuffer.reusable(w, h))`` clears only what the previous
frame covered (its rows' spans, recorded by ``finalize``) — and is never stale.

The rule these tests attack: the record is trusted only while every array of the framebuffer is
the read-only view ``reusable`` handed out and the private memory behind them was never made
writeable; a frame that fails midway leaves no record. Each frame is compared byte for byte
(every buffer, the colour included) with a fresh ``render`` of the same scene.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import framebuffer as fbm
from refraster.scenes import cube, icosphere, torus

ARRAYS = [f for f in FB_FIELDS if f != "color"]


def _same(a, b):
    for f in FB_FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert x.tobytes() == y.tobytes(), f


def _check(fb, meshes, **kw):
    """Render into ``fb``, compare with a fresh frame; returns ``fb``."""
    got = rf.render(meshes, **kw, out=fb)
    assert got is fb
    _same(got, rf.render(meshes, **kw))
    return got


def _moved(x, y, z=0.0, s=1.0):
    m = np.diag([s, s, s, 1.0])
    m[:3, 3] = (x, y, z)
    return m


@pytest.fixture(scope="module")
def scene():
    return dict(ico=mesh_of(icosphere(3)), box=mesh_of(cube()),
                torus=mesh_of(torus(major_segments=24, minor_segments=10)))


def test_reusable_arrays_are_read_only_and_stay_so(scene):
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _same(fb, fb)   # a new one is the background
    assert (fb.depth == 1).all() and (fb.prim_id == -1).all() and np.isinf(fb.eye_depth).all()
    _check(fb, scene["box"], **kw)
    for f in ARRAYS:
        a = getattr(fb, f)
        assert not a.flags.writeable, f
        with pytest.raises(ValueError):
            a[0, 0] = 1
        with pytest.raises(ValueError):   # numpy refuses: the memory behind is read-only
            a.flags.writeable = True
        with pytest.raises(ValueError):
            a.reshape(-1)[:5].flags.writeable = True
    assert fb.color.flags.writeable      # written whole by the shade: an ordinary array
    empty = rf.Framebuffer.reusable(8, 6)
    for method in (empty.eye_position, lambda: empty.interpolate(np.zeros(3))):
        with pytest.raises(ValueError, match="carries no meshes"):
            method()
    # a view taken now stays read-only across frames
    keep = fb.normal[..., 2]
    _check(fb, scene["ico"], **kw)
    with pytest.raises(ValueError):
        keep.flags.writeable = True


def test_frames_covering_fewer_more_and_other_pixels(scene):
    """Each frame after another that covered more, fewer, other or no pixels, with draw calls
    and culling changing: every byte equals a fresh frame's (the spans of the previous frame
    must be cleared where this one left them uncovered, and nothing else is)."""
    ico, box, tor = scene["ico"], scene["box"], scene["torus"]
    for w, h in ((96, 72), (256, 256)):    # 256×256: the size where out= fills in finalize
        kw = camera_kw(w, h)
        fb = rf.Framebuffer.reusable(w, h)
        _check(fb, ico, **kw)                                      # large
        _check(fb, box, **kw, model=_moved(0.3, -0.2, s=0.4))       # fewer, inside it
        _check(fb, box, **kw, model=_moved(-0.9, 0.7, s=0.5))       # elsewhere, partly outside
        _check(fb, [ico, box], **kw, model=[_moved(0.5, 0.0, s=0.6), _moved(-0.6, 0, s=0.5)])
        _check(fb, box, **kw, model=_moved(0, 0, 30.0))             # nothing visible
        _check(fb, tor, **kw, raster=rf.RasterState(cull="back"))                          # a hole in the middle
        _check(fb, tor, **kw, raster=rf.RasterState(cull="back"))                          # the same again
        _check(fb, ico, **kw, raster=rf.RasterState(normals="smooth"))                     # more again
        _check(fb, box, **kw)


def test_one_mesh_moving_and_shrinking(scene):
    """One mesh whose frames cover fewer, other and more pixels: a stale face id left behind
    is a valid face here (with another mesh it would be read out of range), so a missed clear
    shows as wrong bytes."""
    ico = scene["ico"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    for model in (None, _moved(0.2, 0.1, s=0.5), _moved(-0.6, 0.4, s=0.4), _moved(0, 0, 30.0),
                  _moved(0.1, -0.3, s=0.8), None, _moved(0.5, 0.5, s=0.2), None):
        _check(fb, ico, **kw, model=model)


def test_clear_depth_and_depth_func_change_between_frames(scene):
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _check(fb, ico, **kw)
    _check(fb, box, **kw, raster=rf.RasterState(depth_func="greater", clear_depth=0.0))
    _check(fb, box, **kw, model=_moved(0.4, 0.3, s=0.5), raster=rf.RasterState(depth_func="greater", clear_depth=0.0))
    _check(fb, box, **kw, raster=rf.RasterState(clear_depth=0.5))
    _check(fb, ico, **kw, raster=rf.RasterState(clear_depth=0.5), model=_moved(0, 0, s=0.3))
    _check(fb, box, **kw)


def test_another_array_put_into_the_framebuffer_is_cleared_whole(scene):
    """A writeable array of the user's in place of a view (the record cannot know what was
    written into it): full clears, written in place; the record is trusted again only after a
    frame with every view back."""
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _check(fb, ico, **kw)
    views = {f: getattr(fb, f) for f in ARRAYS}
    mine = {f: np.ones_like(v) if f != "prim_id" else np.full_like(v, 5) for f, v in views.items()}
    for f in ARRAYS:
        setattr(fb, f, mine[f])
    _check(fb, box, **kw, model=_moved(0.2, 0.1, s=0.3))
    assert all(getattr(fb, f) is mine[f] for f in ARRAYS)          # written in place
    mine["depth"][:] = 0.25                                         # the user writes again
    mine["eye_depth"][3:9, 4:40] = 7.0
    _check(fb, box, **kw, model=_moved(-0.2, 0.1, s=0.3))
    # the views back, one of the user's arrays left: still a full clear of that one
    for f in ARRAYS:
        setattr(fb, f, views[f])
    fb.normal = mine["normal"]
    mine["normal"][:] = 9.0
    _check(fb, box, **kw)
    fb.normal = views["normal"]
    _check(fb, ico, **kw)
    _check(fb, box, **kw, model=_moved(0.5, 0.5, s=0.2))


def test_private_memory_made_writeable_taints_for_good(scene):
    """The memory behind a view reached through ``.base`` and made writeable: whatever is
    written there, and later through a view taken while it was writeable (the flag, put back
    by the frame, does not reach that view), never shows in a frame — the record is never
    trusted again. (Made writeable, written and made read-only again by the user before the
    next frame is not detectable: documented as unsupported in ``Framebuffer.reusable``.)"""
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _check(fb, ico, **kw)
    back_door = fb.depth.base
    back_door.flags.writeable = True
    back_door[:] = 0.0625
    v = back_door[10:20]                     # a writeable view
    _check(fb, box, **kw, model=_moved(0.3, 0.3, s=0.3))
    assert not back_door.flags.writeable     # locked again by the frame …
    v[:] = 0.5                               # … but not the view taken while it was not
    _check(fb, box, **kw, model=_moved(-0.3, 0.3, s=0.3))
    v[:] = 0.75
    _check(fb, box, **kw, model=_moved(-0.3, -0.3, s=0.3))
    own = fb.prim_id.base                    # likewise another array's memory
    own.flags.writeable = True
    own[:] = 3
    _check(fb, box, **kw, model=_moved(0.3, -0.3, s=0.3))


def test_sizes_are_checked_and_framebuffers_keep_their_own_record(scene):
    ico, box = scene["ico"], scene["box"]
    small, big = camera_kw(96, 72), camera_kw(128, 100)
    a = rf.Framebuffer.reusable(96, 72)
    b = rf.Framebuffer.reusable(128, 100)
    _check(a, ico, **small)
    with pytest.raises(ValueError, match=r"out.depth must be float32 of shape \(100, 128\)"):
        rf.render(box, **big, out=a)
    _check(a, box, **small)                  # the refused call changed nothing
    _check(b, ico, **big)
    for k in range(3):   # alternating: each framebuffer clears from its own last frame
        _check(a, ico if k % 2 else box, **small, model=_moved(0.2 * k, 0, s=0.5 + 0.2 * k))
        _check(b, box if k % 2 else ico, **big, model=_moved(-0.2 * k, 0, s=0.4 + 0.3 * k))
    c = rf.Framebuffer.reusable(96, 72)     # the same size as a: its own record still
    for k in range(3):
        _check(a, ico, **small, model=_moved(0.3 * k - 0.3, 0.1, s=0.3 + 0.2 * k))
        _check(c, ico, **small, model=_moved(0.3 - 0.3 * k, -0.1, s=0.9 - 0.2 * k))
    for bad in ((0, 72), (96, -1)):
        with pytest.raises(ValueError):
            rf.Framebuffer.reusable(*bad)


def test_a_frame_that_fails_midway_leaves_no_record(scene, monkeypatch):
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _check(fb, ico, **kw, model=_moved(0, 0, s=0.3))
    real = fbm.finalize

    def failing(*args):
        real(*args)
        raise RuntimeError("planted")

    monkeypatch.setattr(fbm, "finalize", failing)
    with pytest.raises(RuntimeError, match="planted"):
        rf.render(ico, **kw, out=fb)         # the tile pass wrote the sphere, finalize too
    monkeypatch.setattr(fbm, "finalize", real)
    assert all(not getattr(fb, f).flags.writeable for f in ARRAYS)
    assert not any(own.flags.writeable for _, own in fb.__dict__["_owners"].values())
    _check(fb, ico, **kw, model=_moved(0, 0, s=0.3))    # a valid face id where it is stale
    _check(fb, box, **kw, model=_moved(0.5, 0, s=0.3))


def test_copies_are_refused_and_the_original_stays_right(scene):
    """A shallow copy shares the private memory with a record of its own (stale once the
    original draws); a deep copy's views are no longer backed by the memory it would write:
    both are refused as ``out``, and the original keeps giving fresh frames' bytes."""
    import copy
    import pickle
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.Framebuffer.reusable(kw["width"], kw["height"])
    _check(fb, ico, **kw)
    twins = (copy.copy(fb), copy.deepcopy(fb), pickle.loads(pickle.dumps(fb)))
    _check(fb, box, **kw, model=_moved(0.3, 0, s=0.4))
    for twin in twins:
        with pytest.raises(ValueError, match="copy of a Framebuffer.reusable"):
            rf.render(ico, **kw, model=_moved(-0.3, 0, s=0.5), out=twin)
    _check(fb, ico, **kw, model=_moved(-0.3, 0, s=0.5))


def test_two_threads_same_bytes(scene, monkeypatch):
    """The record and the two clears run per row in parallel: the same bytes on 2 threads."""
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs NUMBA_NUM_THREADS >= 2")
    monkeypatch.setenv("REFRASTER_THREADS", "2")
    kw = camera_kw(256, 256)
    fb = rf.Framebuffer.reusable(256, 256)
    _check(fb, scene["ico"], **kw)
    _check(fb, scene["box"], **kw, model=_moved(0.3, 0.2, s=0.5))
    _check(fb, scene["torus"], **kw)


def test_render_framebuffer_written_by_the_user_is_cleared_whole(scene):
    """A framebuffer from ``render`` (writeable arrays, the user's) reused with ``out=``: no
    record, every byte written each frame, whatever the user wrote in between."""
    ico, box = scene["ico"], scene["box"]
    kw = camera_kw()
    fb = rf.render(ico, **kw)
    fb.depth[:] = 0.5
    fb.prim_id[::2] = 7
    _check(fb, box, **kw, model=_moved(0.2, 0, s=0.3))
    fb.normal[...] = 2.0
    fb.barycentric[5:9] = 1.0
    _check(fb, box, **kw, model=_moved(-0.2, 0, s=0.3))
    assert "_record" not in fb.__dict__
