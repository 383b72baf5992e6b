"""Issue 28: a reused framebuffer (``render(out=…)``), the smooth-normals cache and the per-frame
thread choice never change a byte, never alias an input and never return stale data."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import _threads
from refraster.mesh import Mesh, smooth_normals, vertex_normals
from refraster.scenes import cube, icosphere, torus


def _same(a, b):
    for f in FB_FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert x.tobytes() == y.tobytes(), f


def test_out_gives_the_bytes_of_a_fresh_render_over_a_stale_frame():
    ico, box = mesh_of(icosphere(3)), mesh_of(cube())
    kw = camera_kw()
    out = rf.render(ico, **kw, raster=rf.RasterState(normals="smooth"))   # another scene's data in every buffer
    out.color                                         # … colour included
    ids = {f: id(getattr(out, f)) for f in FB_FIELDS if f != "color"}
    got = rf.render(box, **camera_kw(eye=(2.0, -1.0, 2.5)), out=out)
    assert got is out
    assert all(id(getattr(out, f)) == ids[f] for f in ids)   # written in place
    _same(got, rf.render(box, **camera_kw(eye=(2.0, -1.0, 2.5))))
    # twice more, alternating scenes and options, colour pending or read
    _same(rf.render(ico, **kw, raster=rf.RasterState(cull="back"), out=out), rf.render(ico, **kw, raster=rf.RasterState(cull="back")))
    _same(rf.render(box, **kw, raster=rf.RasterState(depth_func="greater", clear_depth=0.0), out=out),
          rf.render(box, **kw, raster=rf.RasterState(depth_func="greater", clear_depth=0.0)))


def test_out_colour_read_before_and_after_reuse():
    box, ico = mesh_of(cube()), mesh_of(icosphere(2))
    kw = camera_kw()
    out = rf.render(box, **kw)
    first = out.color.copy()
    rf.render(ico, **kw, out=out)
    assert out.color.tobytes() == rf.render(ico, **kw).color.tobytes()
    assert out.color.tobytes() != first.tobytes()


def test_fresh_frames_never_share_memory():
    """Without out=, every frame's arrays are new: a frame a user holds never changes."""
    box = mesh_of(cube())
    kw = camera_kw()
    a = rf.render(box, **kw)
    keep = {f: getattr(a, f).copy() for f in FB_FIELDS}
    b = rf.render(mesh_of(icosphere(2)), **kw)
    for f in FB_FIELDS:
        for g in FB_FIELDS:
            assert not np.may_share_memory(getattr(a, f), getattr(b, g)), (f, g)
        assert getattr(a, f).tobytes() == keep[f].tobytes(), f


def test_out_is_checked():
    box = mesh_of(cube())
    kw = camera_kw()
    out = rf.render(box, **kw)
    with pytest.raises(TypeError, match="out must be a Framebuffer"):
        rf.render(box, **kw, out=out.depth)
    with pytest.raises(ValueError, match=r"out.depth must be float32 of shape \(60, 80\)"):
        rf.render(box, **camera_kw(80, 60), out=out)
    bad = rf.render(box, **kw)
    bad.prim_id = bad.prim_id.astype(np.int64)
    with pytest.raises(ValueError, match="out.prim_id must be int32"):
        rf.render(box, **kw, out=bad)
    bad = rf.render(box, **kw)
    bad.normal = np.asfortranarray(bad.normal)
    with pytest.raises(ValueError, match="out.normal must be a C-contiguous, writeable"):
        rf.render(box, **kw, out=bad)
    bad = rf.render(box, **kw)
    bad.depth.flags.writeable = False
    with pytest.raises(ValueError, match="out.depth must be a C-contiguous, writeable"):
        rf.render(box, **kw, out=bad)
    bad = rf.render(box, **kw)
    bad.eye_depth = bad.depth
    with pytest.raises(ValueError, match="out.depth and out.eye_depth share memory"):
        rf.render(box, **kw, out=bad)
    with pytest.raises(ValueError, match="fragment_stage"):
        rf.render(box, **kw, out=out, fragment_stage=lambda fr: fr.depth < 1)


def test_out_overlap_is_checked_again_after_a_good_frame():
    """The overlap check of ``out``'s own arrays is skipped only for the very array objects it
    passed last time: an array swapped in after a good frame is checked again."""
    box = mesh_of(cube())
    kw = camera_kw()
    out = rf.render(box, **kw)
    rf.render(box, **kw, out=out)     # a good frame: its arrays are remembered
    rf.render(box, **kw, out=out)
    out.object_id = out.prim_id       # same shape and dtype, same memory
    with pytest.raises(ValueError, match="out.prim_id and out.object_id share memory"):
        rf.render(box, **kw, out=out)
    out.object_id = out.prim_id.copy()
    rf.render(box, **kw, out=out)
    out.color = out.normal            # a colour array aliasing the normals
    with pytest.raises(ValueError, match="out.normal and out.color share memory"):
        rf.render(box, **kw, out=out)


def test_camera_caches_never_give_another_cameras_normals():
    """The normal matrix and the projection check are remembered by the matrices' bytes: a
    loop over cameras, back to the first, gives each camera's own frame (compared with a frame
    rendered with the caches emptied)."""
    from refraster import framebuffer as fbm
    from refraster import raster as rmod
    box = mesh_of(cube())
    eyes = [(1.6, 1.2, 2.4), (-2.0, 0.5, 1.5), (1.6, 1.2, 2.4), (0.3, -2.2, 1.0)]
    out = None
    for eye in eyes:
        kw = camera_kw(eye=eye)
        kw["proj"] = rf.perspective(40 + 5 * eye[0], 96 / 72, 0.5, 10)
        got = rf.render(box, **kw)
        got.color
        out = rf.render(box, **kw, out=out) if out is not None else rf.render(box, **kw)
        fbm._NMAT_CACHE.clear()
        rmod._GOOD_PROJ.clear()
        ref = rf.render(box, **kw)
        _same(got, ref)
        _same(out, ref)
    # a singular projection is still refused after good ones were remembered
    with pytest.raises(ValueError, match="proj is singular"):
        rf.render(box, **dict(camera_kw(), proj=np.zeros((4, 4))))


def test_out_never_overwrites_an_input():
    box = mesh_of(cube())
    kw = camera_kw()
    out = rf.render(box, **kw)
    # a mesh whose vertices live in out's barycentric buffer
    flat = out.barycentric.reshape(-1).view(np.float64)
    flat[:24] = box.vertices.reshape(-1)
    inside = Mesh(flat[:24].reshape(8, 3), box.faces)
    before = inside.vertices.copy()
    with pytest.raises(ValueError, match="out.barycentric shares memory with an input"):
        rf.render(inside, **kw, out=out)
    assert inside.vertices.tobytes() == before.tobytes()
    # given normals that are a view of out.normal
    with pytest.raises(ValueError, match="out.normal shares memory with an input"):
        rf.render((box.vertices, box.faces, out.normal.reshape(-1).view(np.float64)[:24]
                   .reshape(8, 3)), **kw,
                  raster=rf.RasterState(normals="smooth"), out=out)


def test_smooth_normals_cache_follows_the_content():
    t = mesh_of(torus(major_segments=24, minor_segments=10))
    kw = camera_kw(eye=(0.5, 2.2, 2.0))
    n1 = smooth_normals(t)
    assert smooth_normals(t) is n1                             # cached
    assert smooth_normals(Mesh(t.vertices.copy(), t.faces.copy())) is n1   # same content
    assert n1.tobytes() == vertex_normals(t.vertices, t.faces).tobytes()
    first = rf.render(t, **kw, raster=rf.RasterState(normals="smooth"))
    # change the mesh in place: the next frame must not reuse the old normals
    t.vertices[:, 1] *= 1.7
    t.vertices[::3] += 0.05
    again = rf.render(t, **kw, raster=rf.RasterState(normals="smooth"))
    fresh = rf.render(Mesh(t.vertices.copy(), t.faces.copy()), **kw, raster=rf.RasterState(normals="smooth"))
    fresh_uncached = rf.render(Mesh(t.vertices.copy(), t.faces.copy(),
                                    vertex_normals(t.vertices, t.faces)), **kw,
                               raster=rf.RasterState(normals="smooth"))
    _same(again, fresh)
    _same(again, fresh_uncached)
    assert again.normal.tobytes() != first.normal.tobytes()
    # faces changed in place (same vertices): new normals too
    t.faces[:, [1, 2]] = t.faces[:, [2, 1]].copy()
    flipped = smooth_normals(t)
    assert flipped.tobytes() == vertex_normals(t.vertices, t.faces).tobytes()
    np.testing.assert_allclose(flipped, -vertex_normals(t.vertices, t.faces[:, [0, 2, 1]]),
                               atol=1e-12)


def test_normals_cache_is_bounded(monkeypatch):
    from refraster import mesh as mesh_mod
    monkeypatch.setattr(mesh_mod, "_NORMALS_CACHE_ENTRIES", 2)
    ms = [mesh_of(icosphere(1, radius=1.0 + k)) for k in range(4)]
    for m in ms:
        smooth_normals(m)
    assert len(mesh_mod._NORMALS_CACHE) <= 2


def test_runnable_count_read_through_a_kept_descriptor(monkeypatch):
    """The load is read with one pread on a descriptor kept open: it follows the file (two
    busy processes raise it), and without the file there is no load to read (None)."""
    import os
    import subprocess
    import sys
    import time
    if not os.path.exists("/proc/loadavg"):
        pytest.skip("no /proc/loadavg on this system")
    monkeypatch.setattr(_threads, "_LOADAVG", [None])
    idle = _threads._runnable()
    fd = _threads._LOADAVG[0]
    assert isinstance(idle, int) and idle >= 1 and isinstance(fd, int)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        time.sleep(0.5)
        busy = max(_threads._runnable() for _ in range(50))
    finally:
        for p in hogs:
            p.kill()
            p.wait()
    assert busy >= 3   # the two busy loops and this process
    assert _threads._LOADAVG[0] == fd   # the same descriptor, not reopened per frame
    monkeypatch.setattr(_threads, "_LOADAVG", [None])
    real_open = os.open
    monkeypatch.setattr(os, "open", lambda *a, **k: (_ for _ in ()).throw(OSError("no")))
    assert _threads._runnable() is None and _threads._LOADAVG[0] is False
    monkeypatch.setattr(os, "open", real_open)
    assert _threads._runnable() is None   # stays off: not retried every frame


def test_small_frames_run_serially_and_the_override(monkeypatch):
    monkeypatch.delenv("REFRASTER_THREADS", raising=False)
    monkeypatch.setattr(_threads, "_runnable", lambda: 1)   # idle cores
    if numba.get_num_threads() > 1 and _threads._cpus() > 1:
        assert _threads.frame_threads(_threads.frame_work(12, 512, 384)) > 1
    assert _threads.frame_threads(_threads.frame_work(12, 160, 120)) == 1
    monkeypatch.setattr(_threads, "_runnable", lambda: 9)   # busy cores: one thread
    assert _threads.frame_threads(_threads.frame_work(81920, 1024, 768)) == 1
    monkeypatch.setattr(_threads, "_runnable", lambda: 1)   # idle: Numba's count
    assert _threads.frame_threads(10**6) == min(numba.get_num_threads(), _threads._cpus())
    monkeypatch.setattr(_threads, "_runnable", lambda: 9)
    monkeypatch.setattr(_threads, "_PASSIVE", True)   # sleeping workers: busy cores are fine
    assert _threads.frame_threads(10**6) == numba.get_num_threads()
    assert _threads.frame_threads(_threads.frame_work(12, 160, 120)) == 1
    monkeypatch.setattr(_threads, "_PASSIVE", False)
    assert _threads.frame_threads(10**6) == 1
    monkeypatch.setenv("REFRASTER_THREADS", "1")
    assert _threads.frame_threads(10**6) == 1
    monkeypatch.setenv("REFRASTER_THREADS", "64")
    assert _threads.frame_threads(10) == numba.config.NUMBA_NUM_THREADS
    monkeypatch.setenv("REFRASTER_THREADS", "two")
    with pytest.raises(ValueError, match="REFRASTER_THREADS must be 'auto' or a positive"):
        _threads.frame_threads(10)


def test_thread_choice_restores_numba_and_keeps_the_bytes(monkeypatch):
    ico = mesh_of(icosphere(4))
    kw = camera_kw(256, 192)
    before = numba.get_num_threads()
    frames = []
    for n in ("1", str(numba.config.NUMBA_NUM_THREADS), "auto"):
        monkeypatch.setenv("REFRASTER_THREADS", n)
        fb = rf.render(ico, **kw, raster=rf.RasterState(normals="smooth"))
        fb.color
        frames.append(fb)
        assert numba.get_num_threads() == before
    _same(frames[0], frames[1])
    _same(frames[0], frames[2])
    monkeypatch.setenv("REFRASTER_THREADS", "1")
    with pytest.raises(ValueError):
        rf.render(ico, **kw, raster=rf.RasterState(cull="sideways"))
    assert numba.get_num_threads() == before


def test_reused_scratch_never_reaches_a_frame(monkeypatch):
    """The fused path's intermediates come from reused per-thread buffers: no array of a frame
    (nor of its pending colour) may live in them, so a later frame cannot change it."""
    from refraster import framebuffer
    from refraster._scratch import frame_scratch
    monkeypatch.setattr(framebuffer, "SCRATCH_FACES", 0)   # these small meshes use it too
    frame_scratch().clear()
    ico, t = mesh_of(icosphere(3)), mesh_of(torus(major_segments=24, minor_segments=10))
    kw = camera_kw()
    a = rf.render(ico, **kw, raster=rf.RasterState(normals="smooth"))        # colour left pending
    held = {f: getattr(a, f).copy() for f in FB_FIELDS if f != "color"}
    pending = a.__dict__["_color"].args
    rf.render(t, **camera_kw(eye=(0.5, 2.2, 2.0)), raster=rf.RasterState(cull="back"))   # reuses every scratch buffer
    bufs = list(frame_scratch()._bufs.values())
    assert bufs
    for x in [getattr(a, f) for f in held] + [p for p in pending if isinstance(p, np.ndarray)]:
        assert not any(np.may_share_memory(x, b) for b in bufs)
    for f in held:
        assert getattr(a, f).tobytes() == held[f].tobytes(), f
    _same(a, rf.render(ico, **kw, raster=rf.RasterState(normals="smooth")))


def test_public_prepare_never_uses_the_scratch():
    from refraster._scratch import SCRATCH_FACES, frame_scratch
    from refraster.raster import prepare
    ico = mesh_of(icosphere(5))
    assert ico.n_faces >= SCRATCH_FACES
    kw = camera_kw()
    frame_scratch().clear()
    rf.render(ico, **kw)
    assert frame_scratch().nbytes > 0                     # the default path uses the scratch
    p = prepare(ico, **kw)
    bufs = list(frame_scratch()._bufs.values())
    t = p.triangles
    for x in (p.clip, t.vx, t.vy, t.vz, t.status, t.bbox):
        assert not any(np.may_share_memory(x, b) for b in bufs)


def test_prepare_called_alone_chooses_its_threads(monkeypatch):
    """``prepare`` on its own picks the frame's threads as ``render`` does (on busy cores a
    plain 2-thread ``prepare`` of a cube took 32 ms against 0.07 ms on one); inside ``render``
    the frame's one choice is kept (asked once, not again)."""
    from refraster.raster import prepare
    asked = []

    def record(work):
        asked.append(work)
        return 1

    monkeypatch.setattr(_threads, "frame_threads", record)
    box = mesh_of(cube())
    kw = camera_kw(160, 120)
    prepare(box, **kw)
    assert asked == [_threads.frame_work(box.n_faces, 160, 120)]
    asked.clear()
    rf.render(box, **kw)
    assert asked == [_threads.frame_work(box.n_faces, 160, 120)]


POISONS = (0xAB, 0x00, 0xFF)


@pytest.mark.parametrize("case", ["plain", "near_clipped", "culled_float64", "msaa"])
def test_scratch_taken_unfilled_is_written_whole(case):
    """The primitive stage's per-vertex and per-face arrays, the clip coordinates and the tile
    lists come from the scratch unfilled (``Scratch.empty``): their kernels write every element.
    With the buffers poisoned (every byte 0xAB, 0x00 or 0xFF) before each frame, the arrays are
    byte for byte those of a frame without a scratch (``np.empty`` memory, written whole by the
    same kernels) and of the ``np.zeros`` bytes where nothing is visible (clipped vertices, faces
    not set up) — and the frame's buffers are those of a frame with fresh memory."""
    from refraster._scratch import Scratch
    from refraster.raster import prepare
    from refraster.raster.rasterizer import bin_primitives
    mesh = mesh_of(torus(major_segments=40, minor_segments=16))
    kw = camera_kw()
    state = None
    if case == "near_clipped":      # the eye inside the torus's ring: faces cross the near plane
        kw = camera_kw(eye=(0.0, 0.2, 1.25))
    elif case == "culled_float64":
        state = rf.RasterState(cull="back", precision="float64")
    elif case == "msaa":
        state = rf.RasterState(samples=4)
    want = prepare(mesh, **kw, raster=state)
    want_lists = bin_primitives(want.triangles)[3]
    s = Scratch()
    for poison in POISONS:
        prepare(mesh, **kw, raster=state, scratch=s)   # the buffers exist after a first frame
        for b in s._bufs.values():
            b.fill(poison)
        got = prepare(mesh, **kw, raster=state, scratch=s)
        t, u = got.triangles, want.triangles
        assert t.status.tobytes() == u.status.tobytes(), poison
        for name in ("vx", "vy", "vz", "v_inv_w", "vxf", "vyf", "vcode", "bbox"):
            assert getattr(t, name).tobytes() == getattr(u, name).tobytes(), (name, poison)
        assert got.clip.tobytes() == want.clip.tobytes(), poison
        lists = bin_primitives(t, s)[3]
        assert lists.tobytes() == want_lists.tobytes(), poison
    u = want.triangles
    if case == "near_clipped":
        assert (u.status == 2).any() and (u.vcode != 0).any()   # the case clips
    assert not u.vx[u.vcode != 0].any() and not u.bbox[u.status != 1].any()


@pytest.mark.parametrize("poison", [0xAB, 0x01, 0x02])
def test_render_samples_through_a_poisoned_scratch_gives_a_fresh_frames_bytes(monkeypatch,
                                                                              poison):
    """``render_samples`` takes the thread's scratch for its primitive stage and tile lists from
    ``SCRATCH_FACES`` faces (here every mesh): with every scratch byte ``poison`` first (0x01,
    0x02: a face status SIMPLE, CLIPPED), its buffers are those of the frame that allocates
    (the scratch refused)."""
    from refraster import multisample
    from refraster._scratch import frame_scratch
    mesh = mesh_of(torus(major_segments=40, minor_segments=16))
    kw = camera_kw(eye=(0.0, 0.2, 1.25))     # faces cross the near plane too
    s4 = rf.RasterState(samples=4, interpolation="centroid")
    monkeypatch.setattr(multisample, "SCRATCH_FACES", 1 << 40)
    want = rf.render_samples(mesh, **kw, raster=s4)
    monkeypatch.setattr(multisample, "SCRATCH_FACES", 0)
    rf.render_samples(mesh, **kw, raster=s4)
    assert frame_scratch()._bufs
    for b in frame_scratch()._bufs.values():
        b.fill(poison)
    got = rf.render_samples(mesh, **kw, raster=s4)
    for f in ("depth", "prim_id", "object_id", "front_facing", "barycentric", "eye_depth",
              "normal", "color"):
        assert getattr(got, f).tobytes() == getattr(want, f).tobytes(), f
