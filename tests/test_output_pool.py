"""Issue 28 item 3: a new frame's output arrays come from a pool that recycles the memory of
frames nobody holds any more (:class:`refraster._scratch.OutputPool`). The pool must never
hand out memory a user can still reach, and a recycled array must give the bytes of a new one."""

from __future__ import annotations

import gc
import threading
import weakref

import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import _scratch
from refraster._scratch import OUTPUTS, OutputPool
from refraster.scenes import cube, icosphere, torus

#: Large enough that every output but the facing mask is at least POOL_MIN_BYTES.
KW = camera_kw(256, 192)


def _bytes(fb):
    return {f: getattr(fb, f).tobytes() for f in FB_FIELDS}


def _addr(a):
    return a.__array_interface__["data"][0]


def _addresses(fb):
    return {_addr(getattr(fb, f)) for f in FB_FIELDS}


def _fresh(monkeypatch, *args, **kw):
    """The frame rendered with the pool turned off (new arrays from NumPy)."""
    with monkeypatch.context() as m:
        m.setenv("REFRASTER_POOL_MB", "0")
        fb = rf.render(*args, **kw)
        return _bytes(fb)


pytestmark = pytest.mark.usefixtures("empty_output_pool")


def test_a_dropped_frame_is_recycled_and_gives_the_bytes_of_a_new_one(monkeypatch):
    ico, box = mesh_of(icosphere(3)), mesh_of(cube())
    want = _fresh(monkeypatch, box, **KW, raster=rf.RasterState(cull="back"))
    a = rf.render(ico, **KW, raster=rf.RasterState(normals="smooth"))   # another scene in every buffer
    a.color
    old = _addresses(a)
    del a
    b = rf.render(box, **KW, raster=rf.RasterState(cull="back"))
    assert len(old & _addresses(b)) >= 6   # recycled (all but the small facing mask)
    assert _bytes(b) == want
    del b
    # and again with the colour left pending, then other options
    c = rf.render(ico, **KW)
    del c
    want = _fresh(monkeypatch, box, **KW, raster=rf.RasterState(depth_func="greater", clear_depth=0.0))
    assert _bytes(rf.render(box, **KW, raster=rf.RasterState(depth_func="greater", clear_depth=0.0))) == want


def test_a_frame_the_user_holds_is_never_reused():
    box, ico = mesh_of(cube()), mesh_of(icosphere(2))
    a = rf.render(box, **KW)
    a.color
    keep = _bytes(a)
    frames = [rf.render(ico, **KW, raster=rf.RasterState(cull=c)) for c in ("none", "back", "front")]
    for b in frames:
        for f in FB_FIELDS:
            for g in FB_FIELDS:
                assert not np.may_share_memory(getattr(a, f), getattr(b, g)), (f, g)
    assert _bytes(a) == keep


@pytest.mark.parametrize("hold", ["slice", "ravel", "memoryview", "frombuffer", "list",
                                  "transpose", "weakref", "astype-copy-is-free"])
def test_whatever_still_reaches_a_dropped_frame_keeps_it(hold):
    """A view, a memoryview, an ndarray over its buffer, or the array in a container keeps the
    memory out of the pool; only a copy lets it go."""
    box, ico = mesh_of(cube()), mesh_of(icosphere(3))
    a = rf.render(box, **KW)
    src = {"slice": a.depth[10:150, 20:], "ravel": a.normal.ravel(),
           "memoryview": memoryview(a.eye_depth), "frombuffer": np.frombuffer(a.barycentric,
                                                                               np.uint8),
           "list": [a.prim_id], "transpose": a.object_id.T, "weakref": weakref.ref(a.depth),
           "astype-copy-is-free": a.depth.astype(np.float32)}[hold]
    if hold == "weakref":   # a weak reference does not keep the array, but it reaches it
        src = [src]
        reach = lambda s: s[0]()   # noqa: E731
    else:
        reach = lambda s: s[0] if isinstance(s, list) else np.asarray(s)   # noqa: E731
    snapshot = bytes(src) if isinstance(src, memoryview) else (
        reach(src).tobytes() if isinstance(src, list) else src.tobytes())
    held = _addresses(a)
    del a
    gc.collect()
    for _ in range(3):
        b = rf.render(ico, **KW, raster=rf.RasterState(normals="smooth"))
        b.color
        now = bytes(src) if isinstance(src, memoryview) else (
            reach(src).tobytes() if isinstance(src, list) else src.tobytes())
        assert now == snapshot
        if hold != "astype-copy-is-free":
            for f in FB_FIELDS:
                assert not np.may_share_memory(reach(src), getattr(b, f)), f
        else:
            assert held & _addresses(b)   # nothing reaches it: recycled


def test_a_pending_colour_keeps_its_inputs():
    """The colour is shaded when read, from the face image and barycentrics the framebuffer
    keeps: frames rendered in between must not recycle them."""
    box, ico, tor = mesh_of(cube()), mesh_of(icosphere(3)), mesh_of(torus())
    a = rf.render(box, **KW)   # colour not read
    for m in (ico, tor, ico):
        b = rf.render(m, **KW, raster=rf.RasterState(normals="smooth"))
        b.color
        del b
    assert a.color.tobytes() == rf.render(box, **KW).color.tobytes()


def test_the_pool_off_and_bounded(monkeypatch):
    box = mesh_of(cube())
    monkeypatch.setenv("REFRASTER_POOL_MB", "0")
    a = rf.render(box, **KW)
    a.color
    assert len(OUTPUTS) == 0
    old = _addresses(a)
    del a
    b = rf.render(box, **KW)
    b.color
    assert len(OUTPUTS) == 0 and OUTPUTS.nbytes == 0
    del b
    monkeypatch.setenv("REFRASTER_POOL_MB", "0.5")   # 512 KiB: a few arrays of this frame
    frames = [rf.render(box, **KW) for _ in range(3)]
    assert 0 < OUTPUTS.nbytes <= 1 << 19
    del frames, old
    monkeypatch.setenv("REFRASTER_POOL_MB", "not a number")   # the default, not an error
    rf.render(box, **KW)


def test_pool_unit():
    pool = OutputPool()
    a = pool.full((256, 256), 7, np.int32)
    assert a.shape == (256, 256) and (a == 7).all() and len(pool) == 1
    b = pool.empty((256, 256), np.int32)   # a is held: a new array
    assert not np.may_share_memory(a, b) and len(pool) == 2
    pa = _addr(a)
    del a
    c = pool.full((256, 256), -1, np.int32)
    assert _addr(c) == pa and (c == -1).all()   # recycled, every element written
    d = pool.empty((256, 128), np.int32)         # another shape: never a recycled (256, 256)
    assert d.shape == (256, 128)
    small = pool.empty((8, 8), np.float64)       # below POOL_MIN_BYTES: not kept
    assert len(pool) == 3 and small.shape == (8, 8)
    # at most POOL_PER_KIND of one kind are kept, the oldest dropped first
    held = [pool.empty((256, 256), np.int32) for _ in range(_scratch.POOL_PER_KIND + 2)]
    assert sum(e.shape == (256, 256) for e in pool._entries) == _scratch.POOL_PER_KIND
    assert held[-1] is pool._entries[-1]
    pool.clear()
    assert len(pool) == 0 and pool.nbytes == 0


def test_pool_zeros_recycled_or_new_are_zeros():
    """``OutputPool.zeros``: a new array (``np.zeros``) and a recycled one that held junk both
    come out all zeros, kept and recycled as ``empty``'s."""
    pool = OutputPool()
    a = pool.zeros((256, 256, 3), np.float32)
    assert not a.any() and len(pool) == 1
    a[...] = np.nan
    pa = _addr(a)
    del a
    b = pool.zeros((256, 256, 3), np.float32)
    assert _addr(b) == pa and not b.any() and b.dtype == np.float32
    small = pool.zeros((4, 4), np.bool_)                  # below POOL_MIN_BYTES: not kept
    assert small.shape == (4, 4) and not small.any() and len(pool) == 1


def test_threads_rendering_at_once(monkeypatch):
    """Several Python threads rendering at once (a threaded Dask scheduler): each frame has
    the bytes of the same scene rendered alone."""
    scenes = [(mesh_of(cube()), {}),
              (mesh_of(icosphere(3)), {"raster": rf.RasterState(normals="smooth")}),
              (mesh_of(torus()), {"raster": rf.RasterState(cull="back")})]
    want = [_fresh(monkeypatch, m, **KW, **o) for m, o in scenes]
    bad = []

    def run(k):
        m, o = scenes[k % 3]
        for i in range(6):
            fb = rf.render(m, **KW, **o)
            if i % 2:
                fb.color
            if _bytes(fb) != want[k % 3]:
                bad.append(k)

    ts = [threading.Thread(target=run, args=(k,)) for k in range(3)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert not bad


@pytest.mark.parametrize("tracer", ["python", "none"])
def test_held_and_free_told_apart_under_a_tracer(tracer):
    """A Python trace function that reads ``frame.f_locals`` (a debugger) gives every local an
    extra reference through the locals' dict: the sentinel's count, taken the same way, moves
    with them (a count measured once, without the tracer, would call every array held)."""
    import sys
    pool = OutputPool()

    def trace(frame, event, arg):
        frame.f_locals   # as a debugger does: the locals copied into a dict (one more ref)
        return trace

    old = sys.gettrace()
    if tracer == "python":
        sys.settrace(trace)
    try:
        a = pool.full((256, 256), 1.0, np.float32)
        b = pool.full((256, 256), 2.0, np.float32)   # a is held: not recycled
        assert not np.may_share_memory(a, b) and (a == 1.0).all()
        pa = _addr(a)
        del a
        c = pool.full((256, 256), 3.0, np.float32)   # a was dropped: recycled
        assert _addr(c) == pa and (b == 2.0).all()
    finally:
        sys.settrace(old)


def test_the_default_pool_holds_an_8_layer_peel_at_1024():
    """The default limit (``_scratch.POOL_MB``) keeps every layer array of an 8-layer peel at
    1024² (168 MiB), so a loop of peels recycles them instead of page-faulting fresh memory in
    (docs/ldi.md, "Benchmark"); under the former 128 MiB the oldest were dropped."""
    from refraster.ldi import peel
    # nested cubes: 8 layers where they all overlap
    boxes = [cube(size=r) for r in (1.6, 1.2, 0.8, 0.4)]
    cam = dict(view=rf.look_at((0.4, 0.3, 3.0), (0, 0, 0)), proj=rf.perspective(50, 1.0, 0.5, 10.0),
               width=1024, height=1024)
    fields = ("depth", "prim_id", "object_id", "front_facing", "index")
    lay = peel(boxes, max_layers=8, **cam)
    assert len(lay) == 8
    want = {f: getattr(lay, f).tobytes() for f in fields}
    old = {_addr(getattr(lay, f)) for f in fields}
    assert sum(getattr(lay, f).nbytes for f in fields) == 168 << 20
    del lay
    again = peel(boxes, max_layers=8, **cam)
    assert {_addr(getattr(again, f)) for f in fields} == old   # every layer array recycled
    assert {f: getattr(again, f).tobytes() for f in fields} == want


def test_a_recycled_fragment_stream_gives_the_bytes_of_a_new_one(monkeypatch):
    """``draw``'s stream (pixel, depth, ids, facing, barycentrics) and its split ids come from
    the pool unfilled: the kernels must write every element, or a recycled array shows the
    previous stream's fragments. The pool recycles an array of the same shape: the same two
    meshes drawn in the other order give as many fragments, in another order, other ids."""
    fields = ("pixel", "depth", "prim_id", "object_id", "front_facing", "bary")
    a, b = mesh_of(icosphere(3)), mesh_of(torus())
    with monkeypatch.context() as m:
        m.setenv("REFRASTER_POOL_MB", "0")
        fresh = rf.draw([b, a], **KW)
        want = {f: getattr(fresh, f).tobytes() for f in fields}
        del fresh
    first = rf.draw([a, b], **KW)
    old = {_addr(getattr(first, f)) for f in fields}
    del first
    again = rf.draw([b, a], **KW)
    assert len(old & {_addr(getattr(again, f)) for f in fields}) >= 5   # recycled
    assert {f: getattr(again, f).tobytes() for f in fields} == want


def test_the_default_pool_holds_the_1x_4x_and_8x_frames_in_turn():
    """1×, 4× and 8× G-buffers of 1024×768 rendered in turn, colour not read (as
    ``benchmarks.msaa`` does; 442 MiB of outputs):
    under the default limit each frame's arrays are recycled on the next round; under 256 MiB
    the 8× frame evicted the 4× one's, so every round took new memory."""
    box = mesh_of(icosphere(2))
    kw = camera_kw(1024, 768)
    states = [None, rf.RasterState(samples=4), rf.RasterState(samples=8)]

    def frame(state):
        fb = rf.render(box, **kw) if state is None else rf.render_samples(box, **kw,
                                                                            raster=state)
        return {_addr(getattr(fb, f)) for f in ("depth", "eye_depth", "normal", "prim_id",
                                                 "object_id", "barycentric")}

    first = [frame(s) for s in states]
    again = [frame(s) for s in states]
    for a, b in zip(first, again):
        assert a and a == b


FILL_CASES = [(np.float32, 0.0), (np.float32, -0.0), (np.float32, 1.0), (np.float32, np.inf),
              (np.float32, np.nan), (np.float32, 0.5), (np.int32, -1), (np.int32, 7),
              (np.uint32, 0xDEADBEEF), (np.int64, -1), (np.int64, 3), (np.float64, 1.0),
              (np.bool_, True), (np.bool_, False), (np.int8, -3), (np.uint16, 0x0101),
              (np.complex64, 1 + 2j), (np.dtype(">f4"), 1.0), (np.dtype(">i4"), -2)]


@pytest.mark.parametrize("dtype, value", FILL_CASES)
@pytest.mark.parametrize("shape", [(768, 1024, 3), (1024 + 3,), (5, 7)])
def test_fill_gives_numpys_bytes(dtype, value, shape):
    """The pool's fill (the C library's memset / wmemset where the element's bytes allow) writes
    exactly NumPy's bytes, large or small, into memory holding other bytes; a strided view
    is left to NumPy and its gaps untouched."""
    want = np.empty(shape, dtype)
    want.fill(value)
    got = np.frombuffer(np.random.default_rng(1).bytes(want.nbytes), np.uint8).copy()
    got = got.view(want.dtype).reshape(shape)
    _scratch.fill(got, value)
    assert got.tobytes() == want.tobytes()
    wide = np.full(shape[:-1] + (2 * shape[-1],), 9, dtype)
    _scratch.fill(wide[..., ::2], value)
    assert wide[..., ::2].tobytes() == want.tobytes()
    assert wide[..., 1::2].tobytes() == np.full(shape, 9, dtype).tobytes()


def test_fill_leaves_unaligned_arrays_to_numpy(monkeypatch):
    """``wmemset`` wants its elements aligned (C's rule; x86 forgives it): an unaligned view
    (a byte buffer's) is filled by NumPy."""
    def refuse(*args):
        raise AssertionError("the C library called on an unaligned array")
    monkeypatch.setattr(_scratch, "_WMEMSET", refuse)
    raw = np.zeros((1 << 16) * 4 + 1, np.uint8)
    a = raw[1:].view(np.float32)
    assert not a.flags.aligned and a.nbytes >= _scratch.FILL_MIN_BYTES
    _scratch.fill(a, 1.0)
    assert (a == 1.0).all() and raw[0] == 0


def test_fill_leaves_object_arrays_to_numpy():
    a = np.empty(1 << 14, object)
    _scratch.fill(a, "x")
    assert a.nbytes >= _scratch.FILL_MIN_BYTES and all(v == "x" for v in a)


def test_fill_takes_the_c_library_for_a_4x_frames_outputs(monkeypatch):
    """The 4× frame's one per-sample fill before the tile pass (the face image, −1) goes
    through memset, not NumPy's slower fill (docs/performance.md); its depth (clear 1.0,
    wmemset's pattern), facing and barycentrics are not filled (``finalize``'s sweep writes
    their background)."""
    calls = []
    memset, wmemset = _scratch.ctypes.memset, _scratch._WMEMSET
    if wmemset is None:
        pytest.skip("this C library's wchar_t is not 4 bytes: no wmemset path")
    monkeypatch.setattr(_scratch.ctypes, "memset", lambda *a: calls.append("memset") or memset(*a))
    monkeypatch.setattr(_scratch, "_WMEMSET", lambda *a: calls.append("wmemset") or wmemset(*a))
    kw = camera_kw(256, 192)
    s4 = rf.RasterState(samples=4)
    rf.render_samples(mesh_of(icosphere(2)), **kw, raster=s4)
    fb = rf.render_samples(mesh_of(icosphere(2)), **kw, raster=s4)
    assert calls.count("wmemset") == 0 and calls.count("memset") >= 1, calls
    assert (fb.depth[0, 0] == 1.0).all() and (fb.prim_id[0, 0] == -1).all()


@pytest.mark.parametrize("poison", [0xAB, 0x00, 0xFF])
@pytest.mark.parametrize("size", [(320, 240), (120, 90)])
def test_recycled_outputs_poisoned_give_a_fresh_frames_bytes(monkeypatch, poison, size):
    """The tile passes write only the pixels (samples) a fragment won into recycled depth,
    facing and barycentrics; ``finalize``'s sweep writes the rest (from ``FILL_IN_KERNEL``
    pixels; NumPy's fills below, the 120 × 90 frame). With every byte of the pool's free
    arrays ``poison``, ``render`` and ``render_samples`` (centre and sample interpolation,
    reversed-Z's clear depth 0) give the bytes of frames made with the pool off."""
    mesh = mesh_of(torus(major_segments=40, minor_segments=16))
    kw = camera_kw(*size)
    cases = [(rf.render, rf.RasterState()),
             (rf.render, rf.RasterState(depth_func="greater", clear_depth=0.0)),
             (rf.render_samples, rf.RasterState(samples=4)),
             (rf.render_samples, rf.RasterState(samples=8, interpolation="sample",
                                                depth_func="greater", clear_depth=0.0))]
    for fn, state in cases:
        with monkeypatch.context() as m:
            m.setenv("REFRASTER_POOL_MB", "0")
            want = fn(mesh, **kw, raster=state)
            want = {f: getattr(want, f).tobytes() for f in FB_FIELDS}
        for _ in range(2):   # a frame dropped: its arrays in the pool
            fn(mesh_of(icosphere(2)), **kw, raster=state)
        poisoned = set()
        for a in OUTPUTS._entries[1:]:
            a.view(np.uint8).fill(poison)
            poisoned.add(_addr(a))
        del a   # held here, an array would not be handed out again
        got = fn(mesh, **kw, raster=state)
        reused = poisoned & {_addr(getattr(got, f)) for f in FB_FIELDS}
        assert len(reused) >= (5 if size[0] > 200 else 2), (fn.__name__, len(reused))
        for f in FB_FIELDS:
            assert getattr(got, f).tobytes() == want[f], (fn.__name__, state, f)
