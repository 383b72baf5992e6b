"""Re-entrancy (issue 48 item 1, docs/reliability.md): ``render`` called again on the same
thread while a frame is in progress — from a garbage-collector finalizer (``__del__`` of an
object in a reference cycle) or from a signal handler — must give both frames the bytes they
have when rendered alone. Meshes of ``SCRATCH_FACES`` faces and more take the fused path's
intermediates from the thread's reused buffers (:func:`refraster._scratch.frame_scratch`), and
every frame's outputs come from the shared output pool: a nested frame gets scratch of its own
and never an array the outer frame is about to be handed.

The worst moment is forced deterministically: a wrapper around the fused tile pass (after the
primitive stage filled the scratch, before the tile pass reads it) collects garbage or raises
a signal; a last test lets a real interval timer interrupt many frames."""

from __future__ import annotations

import gc
import signal
import threading
import weakref

import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import _scratch, framebuffer
from refraster._scratch import SCRATCH_FACES
from refraster.scenes import icosphere, torus

KW = camera_kw(96, 72)
NESTED_KW = camera_kw(96, 72, eye=(0.4, 2.5, 1.5))
#: Frames whose outputs (but the facing mask) come from the output pool (POOL_MIN_BYTES).
POOL_KW = camera_kw(256, 192)
POOL_NESTED_KW = camera_kw(256, 192, eye=(0.4, 2.5, 1.5))

pytestmark = pytest.mark.usefixtures("empty_output_pool")


@pytest.fixture(scope="module")
def meshes():
    outer = mesh_of(icosphere(5))
    nested = mesh_of(torus(major_segments=128, minor_segments=40))
    assert outer.n_faces >= SCRATCH_FACES and nested.n_faces >= SCRATCH_FACES
    return outer, nested


def _bytes(fb):
    return {f: getattr(fb, f).tobytes() for f in FB_FIELDS}


def _diff(got, want):
    return [f for f in FB_FIELDS if got[f] != want[f]]


class _Renders:
    """Garbage with a finalizer: an object in a reference cycle (only the collector frees it)
    whose ``__del__`` renders ``mesh`` and keeps the frame in ``kept``."""

    def __init__(self, mesh, kept, kw):
        self.mesh, self.kept, self.kw = mesh, kept, kw
        self.me = self   # the cycle

    def __del__(self):
        self.kept.append(rf.render(self.mesh, **self.kw))


def _fused_calling(before):
    real = framebuffer.fused

    def wrapped(*args, **kw):
        before()
        return real(*args, **kw)
    return wrapped


def test_a_finalizer_that_renders_between_the_primitive_stage_and_the_tile_pass(
        monkeypatch, meshes):
    outer, nested = meshes
    want_outer = _bytes(rf.render(outer, **KW))
    want_nested = _bytes(rf.render(nested, **NESTED_KW))
    kept = []
    fired = []

    def collect():
        if not fired:
            fired.append(1)
            _Renders(nested, kept, NESTED_KW)
            gc.collect()

    monkeypatch.setattr(framebuffer, "fused", _fused_calling(collect))
    fb = rf.render(outer, **KW)
    assert len(kept) == 1, "the finalizer did not run inside the frame"
    assert _diff(_bytes(fb), want_outer) == []
    assert _diff(_bytes(kept[0]), want_nested) == []
    for f in FB_FIELDS:
        assert not np.may_share_memory(getattr(fb, f), getattr(kept[0], f)), f


def test_a_signal_handler_that_renders_inside_a_frame(monkeypatch, meshes):
    outer, nested = meshes
    want_outer = _bytes(rf.render(outer, **KW))
    want_nested = _bytes(rf.render(nested, **NESTED_KW))
    kept = []

    def handler(signum, frame):
        kept.append(rf.render(nested, **NESTED_KW))

    old = signal.signal(signal.SIGUSR1, handler)
    try:
        fired = []

        def once():
            if not fired:
                fired.append(1)
                signal.raise_signal(signal.SIGUSR1)
        monkeypatch.setattr(framebuffer, "fused", _fused_calling(once))
        fb = rf.render(outer, **KW)
    finally:
        signal.signal(signal.SIGUSR1, old)
    assert len(kept) == 1
    assert _diff(_bytes(fb), want_outer) == []
    assert _diff(_bytes(kept[0]), want_nested) == []


def test_a_finalizer_that_renders_while_the_output_pool_scans(monkeypatch, meshes):
    """A nested frame run while the outer frame is inside the output pool's scan (a weak
    reference makes the scan step over one entry: the nested frame must not reorder the entries
    under it) keeps its arrays; the outer frame must not be handed any of them."""
    outer, nested = meshes
    want_outer = _bytes(rf.render(outer, **POOL_KW))
    want_nested = _bytes(rf.render(nested, **POOL_NESTED_KW))
    for _ in range(2):   # free arrays of every kind in the pool, dropped
        rf.render(nested, **POOL_NESTED_KW).color
        rf.render(outer, **POOL_KW).color
    # the most recently kept depth-shaped array held weakly: the scan steps over it
    blocker = rf.render(outer, **POOL_KW)
    blocker.color
    ref = weakref.ref(blocker.eye_depth)
    del blocker
    kept = []
    fired = []
    real = weakref.getweakrefcount

    def getweakrefcount(a):
        if not fired:
            fired.append(1)
            _Renders(nested, kept, POOL_NESTED_KW)
            gc.collect()
        return real(a)

    monkeypatch.setattr(_scratch.weakref, "getweakrefcount", getweakrefcount)
    fb = rf.render(outer, **POOL_KW)
    fb.color
    monkeypatch.undo()
    assert fired and len(kept) == 1
    assert ref() is not None
    assert _diff(_bytes(fb), want_outer) == []
    assert _diff(_bytes(kept[0]), want_nested) == []
    for f in FB_FIELDS:
        for g in FB_FIELDS:
            assert not np.may_share_memory(getattr(fb, f), getattr(kept[0], g)), (f, g)


def test_an_interval_timer_rendering_from_its_handler_during_many_frames(meshes):
    """A real timer (not forced): one shot per outer frame, at delays spread over a frame's
    time (~1–10 ms); the handler renders the nested mesh. Every outer frame and every nested
    one has its bytes (bounded: 40 frames)."""
    outer, nested = meshes
    want_outer = _bytes(rf.render(outer, **KW))
    want_nested = _bytes(rf.render(nested, **NESTED_KW))
    kept = []

    def handler(signum, frame):
        kept.append(rf.render(nested, **NESTED_KW))

    old = signal.signal(signal.SIGALRM, handler)
    bad = []
    try:
        for k in range(40):
            signal.setitimer(signal.ITIMER_REAL, 0.00025 * (1 + k % 40))
            got = _bytes(rf.render(outer, **KW))
            signal.setitimer(signal.ITIMER_REAL, 0)
            bad += _diff(got, want_outer)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    assert kept, "the timer never fired"
    assert bad == []
    assert all(_diff(_bytes(k), want_nested) == [] for k in kept)


def test_a_finalizer_rendering_smooth_normals_inside_the_normals_cache(monkeypatch, meshes):
    """The smooth-normals cache is entered again by a finalizer run by a collection inside
    it (an insertion can trigger one): the nested frame computes its normals without the
    cache instead of waiting for a lock its own thread holds (a deadlock: run in a thread
    with a timeout, so that a regression fails instead of hanging)."""
    from collections import OrderedDict

    from refraster import mesh as mesh_module
    outer, nested = meshes
    smooth = rf.RasterState(normals="smooth")
    want_outer = _bytes(rf.render(outer, **KW, raster=smooth))
    want_nested = _bytes(rf.render(nested, **NESTED_KW, raster=smooth))
    kept, fired = [], []

    class Nested(_Renders):
        def __del__(self):
            self.kept.append(rf.render(self.mesh, **self.kw, raster=smooth))

    class Collecting(OrderedDict):
        def __setitem__(self, key, value):
            if not fired:
                fired.append(1)
                Nested(nested, kept, NESTED_KW)
                gc.collect()
            super().__setitem__(key, value)

    monkeypatch.setattr(mesh_module, "_NORMALS_CACHE", Collecting())
    got = []
    t = threading.Thread(target=lambda: got.append(rf.render(outer, **KW, raster=smooth)),
                         daemon=True)
    t.start()
    t.join(120)
    assert not t.is_alive(), "deadlock: the nested frame waits for the normals cache's lock"
    assert fired and len(kept) == 1 and got
    assert _diff(_bytes(got[0]), want_outer) == []
    assert _diff(_bytes(kept[0]), want_nested) == []
