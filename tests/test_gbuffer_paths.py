"""The G-buffer pass's shortcuts (issue 28, third pass) give the bytes of the plain path.

* flat normals computed once per face (``gbuffer.per_face_normals``) instead of once per run
  of a face's pixels in a row;
* ``finalize`` writing the background of a reused framebuffer itself (``FILL_IN_KERNEL``);
* every kernel input passed read-only, so ``finalize``/``shade`` compile one specialisation per
  declared face image dtype;
* ``render(out=)`` comparing only inputs it has not checked against the same arrays before.

Each is compared with the plain path forced by its threshold, on scenes that make a wrong
shortcut visible (two draw calls with different models, a stale frame under the new one, the
vertices changed between the frame and the colour's shading)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import framebuffer as fbm
from refraster.mesh import Mesh
from refraster.raster import gbuffer
from refraster.scenes import cube, icosphere


def _bytes(fb):
    return {f: getattr(fb, f).tobytes() for f in FB_FIELDS}


def _model(angle, t):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    m[:3, :3] *= [1.0, 0.6, 1.3]   # non-uniform: the normal matrix is not the model's rotation
    m[:3, 3] = t
    return m


#: Turns the cube's axis-aligned faces (a scaling would not change their normals).
SHEAR = np.array([[1.0, 0.3, -0.2], [0.1, 0.9, 0.4], [0.25, -0.3, 1.1]])


def _scenes():
    box, ico = mesh_of(cube()), mesh_of(icosphere(2))
    kw = camera_kw()
    return [("cube", box, kw),
            ("two draws", [box, ico],
             dict(kw, model=[_model(0.4, (-0.5, 0, 0)), _model(-0.9, (0.6, 0.1, -0.2))])),
            ("three draws, empty middle", [ico, Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64)),
                                          box],
             dict(kw, model=[_model(0.2, (0.4, 0, 0)), np.eye(4), _model(1.1, (-0.6, 0, 0))])),
            ("culled", box, dict(kw, raster=rf.RasterState(cull="back")))]


@pytest.mark.parametrize("name", [s[0] for s in _scenes()])
def test_per_face_normals_give_the_per_pixel_bytes(monkeypatch, name):
    meshes, kw = next((m, k) for n, m, k in _scenes() if n == name)
    monkeypatch.setattr(gbuffer, "FACE_NORMAL_PIXELS", 0)        # every frame per face
    per_face = _bytes(rf.render(meshes, **kw))
    monkeypatch.setattr(gbuffer, "FACE_NORMAL_PIXELS", 10 ** 12)  # every frame per pixel
    per_pixel = _bytes(rf.render(meshes, **kw))
    for f in FB_FIELDS:
        assert per_face[f] == per_pixel[f], f


def test_per_face_normals_match_the_cubes_analytic_normals(monkeypatch):
    """An outside oracle: the flat cube's eye-space normals are ``view``'s rotation of the six
    axis directions (the face's outward normal), whichever path computes them."""
    box = mesh_of(cube())
    kw = camera_kw(w=128, h=96)
    rot = kw["view"][:3, :3]
    for pixels in (0, 10 ** 12):
        monkeypatch.setattr(gbuffer, "FACE_NORMAL_PIXELS", pixels)
        fb = rf.render(box, **kw)
        m = fb.mask
        n = fb.normal[m].astype(np.float64)
        world = n @ rot                     # back to world space (rot is orthonormal)
        axis = np.zeros_like(world)
        j = np.argmax(np.abs(world), axis=1)
        axis[np.arange(len(j)), j] = np.sign(world[np.arange(len(j)), j])
        assert np.abs(world - axis).max() < 1e-6
        # … and the outward one of the visible face: its centroid's dominant axis
        cen = box.vertices[box.faces[fb.prim_id[m]]].mean(axis=1)
        k = np.argmax(np.abs(cen), axis=1)
        outward = np.zeros_like(cen)
        outward[np.arange(len(k)), k] = np.sign(cen[np.arange(len(k)), k])
        assert np.array_equal(axis, outward)


def test_per_face_choice():
    F = gbuffer.FACE_NORMAL_PIXELS
    assert gbuffer.per_face_normals(12, 120, 160, False)
    assert not gbuffer.per_face_normals(12, 120, 160, True)            # smooth: per pixel
    assert gbuffer.per_face_normals(120 * 160 // F, 120, 160, False)
    assert not gbuffer.per_face_normals(120 * 160 // F + 1, 120, 160, False)


def test_pending_colour_uses_the_vertices_as_they_are_when_read(monkeypatch):
    """The colour is shaded when first read, from the mesh as it is then (documented): the
    per-face normals must be computed then too, not taken from the frame's ``finalize``."""
    results = []
    for pixels in (0, 10 ** 12):
        monkeypatch.setattr(gbuffer, "FACE_NORMAL_PIXELS", pixels)
        box = mesh_of(cube())
        kw = camera_kw()
        fb = rf.render(box, **kw)
        box.vertices[:] = box.vertices @ SHEAR + [0.1, 0.0, 0.0]   # in place: new face normals
        results.append(fb.color.tobytes())
        # and the same through a reused framebuffer
        out = rf.render(mesh_of(icosphere(1)), **kw)
        box2 = mesh_of(cube())
        rf.render(box2, **kw, out=out)
        box2.vertices[:] = box2.vertices @ SHEAR.T
        results.append(out.color.tobytes())
    assert results[0] == results[2] and results[1] == results[3]
    # and the change is visible (the check above can fail)
    assert results[0] != rf.render(mesh_of(cube()), **camera_kw()).color.tobytes()


@pytest.mark.parametrize("fill_in_kernel", [0, 1 << 40])
def test_background_written_by_finalize_over_a_stale_frame(monkeypatch, fill_in_kernel):
    """With ``out=``, a frame of at least ``FILL_IN_KERNEL`` pixels has its eye depth, normal
    and ids' background written by ``finalize``: every pixel the last frame covered and this
    one does not must get it (both paths, compared with a fresh frame)."""
    monkeypatch.setattr(fbm, "FILL_IN_KERNEL", fill_in_kernel)
    big, small = mesh_of(icosphere(3)), mesh_of(cube())
    kw = camera_kw(w=160, h=120, eye=(0.9, 0.7, 1.4))    # the sphere fills most of the frame
    kw_far = camera_kw(w=160, h=120, eye=(3.0, 2.2, 4.5))
    out = rf.render(big, **kw)
    out.color
    for _ in range(2):
        got = _bytes(rf.render(small, **kw_far, out=out))
        ref = _bytes(rf.render(small, **kw_far))
        for f in FB_FIELDS:
            assert got[f] == ref[f], f
        rf.render(big, **kw, raster=rf.RasterState(normals="smooth"), out=out)
    assert out.prim_id.size >= fill_in_kernel or fill_in_kernel > 1 << 30


@pytest.mark.parametrize("fill_in_kernel", [0, 1 << 40])
def test_background_written_by_finalize_into_recycled_outputs(monkeypatch, fill_in_kernel):
    """A new frame of at least ``FILL_IN_KERNEL`` pixels takes its eye depth, normal and ids
    from the output pool without a fill (``finalize`` writes the background): recycled arrays
    holding a dropped frame's sphere must come out as NumPy's fills leave them."""
    monkeypatch.setattr(fbm, "FILL_IN_KERNEL", fill_in_kernel)
    big, small = mesh_of(icosphere(3)), mesh_of(cube())
    kw = camera_kw(w=160, h=120, eye=(0.9, 0.7, 1.4))    # the sphere fills most of the frame
    kw_far = camera_kw(w=160, h=120, eye=(3.0, 2.2, 4.5))
    monkeypatch.setattr(fbm, "FILL_IN_KERNEL", 1 << 40)
    ref = _bytes(rf.render(small, **kw_far))             # NumPy's fills
    monkeypatch.setattr(fbm, "FILL_IN_KERNEL", fill_in_kernel)
    fb = rf.render(big, **kw)
    pooled = ("depth", "eye_depth", "normal", "prim_id", "object_id")   # >= POOL_MIN_BYTES
    stale = {getattr(fb, f).ctypes.data for f in pooled}
    del fb
    fb = rf.render(small, **kw_far)
    # the dropped frame's memory, recycled (depth and eye depth may trade places)
    assert {getattr(fb, f).ctypes.data for f in pooled} == stale
    got = _bytes(fb)
    for f in FB_FIELDS:
        assert got[f] == ref[f], f


@pytest.mark.parametrize("fill_in_kernel", [None, 1 << 40])
def test_background_written_by_finalize_into_recycled_sample_outputs(monkeypatch,
                                                                      fill_in_kernel):
    """The 4x G-buffer (``render_samples``) builds its sample image ``(H, W·S)`` as a new
    frame: from ``FILL_IN_KERNEL`` samples (160x120 at 4x is above the default) its eye depth,
    normal and ids come from the output pool unfilled and ``finalize`` writes their
    background; recycled arrays holding a dropped 4x frame's sphere must come out as NumPy's
    fills leave them (the plain path forced by the threshold). The tile pass's per-sample
    depth, facing and barycentrics come from the pool too (filled there): the same."""
    if fill_in_kernel is None:
        assert 160 * 120 * 4 >= fbm.FILL_IN_KERNEL
    else:
        monkeypatch.setattr(fbm, "FILL_IN_KERNEL", fill_in_kernel)
    s4 = rf.RasterState(samples=4)
    big, small = mesh_of(icosphere(3)), mesh_of(cube())
    kw = camera_kw(w=160, h=120, eye=(0.9, 0.7, 1.4))    # the sphere fills most of the frame
    kw_far = camera_kw(w=160, h=120, eye=(3.0, 2.2, 4.5))
    with monkeypatch.context() as m:
        m.setattr(fbm, "FILL_IN_KERNEL", 1 << 40)
        ref = {k: a.tobytes() for k, a in rf.render_samples(small, **kw_far, raster=s4)
               .arrays().items()}                        # NumPy's fills
    built = ("eye_depth", "normal", "prim_id", "object_id", "depth", "front_facing",
             "barycentric")
    sfb = rf.render_samples(big, **kw, raster=s4)
    stale = {getattr(sfb, f).ctypes.data for f in built}
    del sfb
    sfb = rf.render_samples(small, **kw_far, raster=s4)
    # the dropped frame's memory, recycled
    assert {getattr(sfb, f).ctypes.data for f in built} == stale
    got = {k: a.tobytes() for k, a in sfb.arrays().items()}
    for f in ref:
        assert got[f] == ref[f], f


def test_default_threshold_uses_both_background_paths():
    assert 160 * 120 < fbm.FILL_IN_KERNEL <= 512 * 384


def _face_image_specialisations(kernel):
    """``kernel``'s specialisations, checked against the declared set: one per dtype of
    ``gbuffer.FACE_IMAGE_DTYPES`` (the face image, argument 0), the other arguments' types the
    same in each."""
    sigs = kernel.signatures
    got = sorted(str(s[0].dtype) for s in sigs)
    assert got == sorted(np.dtype(d).name for d in gbuffer.FACE_IMAGE_DTYPES), sigs
    assert len({s[1:] for s in sigs}) == 1, sigs
    return sigs


def test_one_specialisation_per_face_image_dtype():
    """Writeable and read-only meshes, normals and matrices, one or several draw calls, the
    fused and the fragment-stream paths, 1x and 4x frames, deep-copied and unpickled frames:
    ``finalize`` and ``shade`` compile once per declared face image dtype (the 1x frame's
    int64, the 4x sample image's int32: ``gbuffer.FACE_IMAGE_DTYPES``) and for nothing else."""
    box = mesh_of(cube())
    ro = Mesh(box.vertices.copy(), box.faces.copy())
    ro.vertices.flags.writeable = False
    ro.faces.flags.writeable = False
    normals = box.vertices / np.linalg.norm(box.vertices, axis=1, keepdims=True)
    normals.flags.writeable = False
    kw = camera_kw(w=32, h=24)
    s4 = rf.RasterState(samples=4)
    for m in (box, ro):
        rf.render(m, **kw).color
        rf.render(m, **kw, raster=rf.RasterState(normals="smooth")).color
        rf.render((m.vertices, m.faces, normals), **kw,
                  raster=rf.RasterState(normals="smooth")).color
        rf.render([m, box], **kw).color
        rf.render(m, **kw, fragment_stage=lambda fr: np.ones(len(fr), bool)).color
        out = rf.render(m, **kw)
        rf.render(m, **kw, out=out).color
        # a pending colour deep-copied or pickled (protocol 4: writeable copies of its inputs)
        copy.deepcopy(rf.render(m, **kw)).color
        pickle.loads(pickle.dumps(rf.render(m, **kw), protocol=4)).color
        rf.render_samples(m, **kw, raster=s4).color
        rf.render_samples((m.vertices, m.faces, normals), **kw,
                          raster=s4.replace(normals="smooth")).color
        rf.render_samples([m, box], **kw, raster=s4).color
    sigs = _face_image_specialisations(gbuffer.finalize)
    _face_image_specialisations(gbuffer.shade)
    assert not any(t.mutable for s in sigs for t in s[:5])


def test_face_image_limit_refused_in_one_line(monkeypatch):
    """``render_samples`` refuses more faces than its int32 sample face image can index
    (``MAX_FACES``, 2³¹; lowered here to the cube's 12 faces) instead of wrapping them, and
    takes exactly that many (the outputs' dtypes those of a 1x frame); so does the tile
    pass's wrapper ``rasterize_samples`` for a caller of its own."""
    from refraster import multisample as ms
    from refraster.raster import rasterizer as rr
    assert rr.MAX_FACES == 2 ** 31 == np.iinfo(np.int32).max + 1
    box = mesh_of(cube())
    kw = camera_kw(w=32, h=24)
    s4 = rf.RasterState(samples=4)
    monkeypatch.setattr(ms, "MAX_FACES", 12)
    fb = rf.render_samples(box, **kw, raster=s4)
    one = rf.render(box, **kw)
    for name, a in fb.arrays().items():
        assert a.dtype == getattr(one, name).dtype, name
    tri = Mesh(box.vertices, box.faces[:1])
    with pytest.raises(ValueError, match=r"^meshes: 13 faces in all; render_samples takes at "
                                         r"most 12 \(its sample face image is int32\)$"):
        rf.render_samples([box, tri], **kw, raster=s4)
    monkeypatch.setattr(rr, "MAX_FACES", 11)      # the tile pass's own guard
    with pytest.raises(ValueError, match=r"^rasterize_samples takes at most 11 faces \(its face "
                                         r"image is int32\), not 12$"):
        rf.render_samples(box, **kw, raster=s4)


def test_one_sample_face_image_limit_refused_in_one_line(monkeypatch):
    """``render``'s face image is int32 too (handed out as ``prim_id`` with one draw call):
    more faces than it indexes (``MAX_FACES``, lowered here to the cube's 12) are refused in
    one line by ``render``, by the tile pass's wrapper ``fused`` and by
    ``Framebuffer.from_fragments``, and exactly that many are taken, ids and all."""
    from refraster import framebuffer as fbm
    from refraster.raster import rasterizer as rr
    assert rr.MAX_FACES == 2 ** 31 == np.iinfo(np.int32).max + 1
    box = mesh_of(cube())
    kw = camera_kw(w=32, h=24)
    want = rf.render(box, **kw)
    monkeypatch.setattr(fbm, "MAX_FACES", 12)
    fb = rf.render(box, **kw)
    assert fb.prim_id.dtype == np.int32 and np.array_equal(fb.prim_id, want.prim_id)
    assert fb.prim_id.max() == 11 and fb.prim_id.min() == -1
    tri = Mesh(box.vertices, box.faces[:1])
    with pytest.raises(ValueError, match=r"^meshes: 13 faces in all; render takes at most 12 "
                                         r"\(its face image is int32\)$"):
        rf.render([box, tri], **kw)
    monkeypatch.setattr(rr, "MAX_FACES", 11)      # the tile pass's own guard
    with pytest.raises(ValueError, match=r"^fused takes at most 11 faces \(its face image is "
                                         r"int32\), not 12$"):
        rf.render(box, **kw)
    frags = rf.draw(box, **kw)                    # and a framebuffer built from a stream
    res = rf.resolve(frags)
    assert np.array_equal(rf.Framebuffer.from_fragments(frags, res).prim_id, want.prim_id)
    monkeypatch.setattr(fbm, "MAX_FACES", 11)
    with pytest.raises(ValueError, match=r"^frags: 12 faces in all; a framebuffer takes at "
                                         r"most 11 \(its face image is int32\)$"):
        rf.Framebuffer.from_fragments(frags, res)


def test_out_input_check_after_good_frames():
    """``render(out=)`` compares only inputs it has not checked against the same arrays: after
    good frames, a new input living in ``out``'s memory is still refused."""
    box = mesh_of(cube())
    kw = camera_kw()
    out = rf.render(box, **kw)
    for _ in range(2):
        rf.render(box, **kw, out=out)          # box, view, proj remembered
    flat = out.barycentric.reshape(-1).view(np.float64)
    flat[:24] = box.vertices.reshape(-1)
    inside = Mesh(flat[:24].reshape(8, 3), box.faces)
    with pytest.raises(ValueError, match="out.barycentric shares memory with an input"):
        rf.render(inside, **kw, out=out)
    rf.render(box, **kw, out=out)
    proj = out.normal.reshape(-1).view(np.float64)[:16].reshape(4, 4)
    proj[:] = kw["proj"]
    with pytest.raises(ValueError, match="out.normal shares memory with an input"):
        rf.render(box, **dict(kw, proj=proj), out=out)
    # the framebuffer's arrays swapped after good frames: the remembered inputs are
    # compared again against the new arrays
    rf.render(box, **kw, out=out)
    view = kw["view"].copy()
    eye = np.empty(out.eye_depth.size, np.float32)
    as64 = eye.view(np.float64)
    as64[:16] = view.reshape(-1)
    kw2 = dict(kw, view=as64[:16].reshape(4, 4))
    rf.render(box, **kw2, out=out)                       # view not in out: fine
    out.eye_depth = eye.reshape(out.eye_depth.shape)     # now it is
    with pytest.raises(ValueError, match="out.eye_depth shares memory with an input"):
        rf.render(box, **kw2, out=out)


def _runs_image(rng, h, w, n_faces):
    """A face image whose rows alternate runs of background (−1) of every length from 0 to
    20 (the last rows: 40 to 400, long enough for streaming stores) with runs of 1 to 3
    covered pixels (face 0 among them), from any column."""
    prim = np.full((h, w), -1, np.int32)
    for r in range(h):
        c = int(rng.integers(0, 3))
        lo, hi = (0, 21) if r < h - 3 else (40, 401)
        while c < w:
            c += int(rng.integers(lo, hi))
            n = int(rng.integers(1, 4))
            prim[r, c:c + n] = rng.integers(0, n_faces, size=len(prim[r, c:c + n]))
            c += n
    prim[0, :9] = 0          # a row starting covered
    prim[1, -9:] = -1        # and one ending in background
    prim[2, :] = -1          # and one with nothing covered
    return prim


@pytest.mark.parametrize("stream", [False, True], ids=["stores", "streaming"])
@pytest.mark.parametrize("seed", range(3))
def test_background_runs_of_every_length(monkeypatch, seed, stream):
    """``finalize`` and ``shade`` find runs of background eight columns a step and fill each
    array's stretch in a loop of its own (with ``stream``, its aligned 32-byte blocks by
    streaming stores): every background pixel gets the clear values, every covered one (next
    to runs of any length and phase) its face's ids and eye depth (NumPy, in the kernel's
    order of operations: the same bits), and the tile pass's depth, facing and barycentrics of
    a covered pixel are left as they were. The output arrays start as garbage, so a pixel the
    fill misses is seen. The colour against the same frame with the background made of a face
    beyond ``n_shaded``, which ``shade`` colours pixel by pixel: the same bytes."""
    monkeypatch.setattr(fbm, "FILL_IN_KERNEL", 0)    # the background written in the kernel
    monkeypatch.setattr(fbm, "STREAM_FROM_BYTES", 0 if stream else 1 << 62)
    monkeypatch.setattr(fbm.OUTPUTS, "empty", lambda shape, dtype: np.full(shape, 7, dtype))
    rng = np.random.default_rng(seed)
    h, w, n_faces = 9, 611, 5
    v = rng.normal(size=(3 * n_faces + 3, 3)) + [0.0, 0.0, -4.0]
    f = np.arange(3 * n_faces + 3, dtype=np.int64).reshape(-1, 3)
    mesh = Mesh(v, f)
    kw = camera_kw(w=w, h=h)
    prim = _runs_image(rng, h, w, n_faces)
    bary = rng.random((h, w, 3)).astype(np.float32)
    depth = rng.random((h, w)).astype(np.float32)
    front = rng.random((h, w)) < 0.5
    bg = (0.2, 0.4, 0.6)

    def build(face_image):
        return fbm._build([mesh], [np.eye(4)], kw["view"], kw["proj"], depth.copy(),
                          face_image, [0, n_faces + 1], front.copy(), bary.copy(), "flat", bg,
                          n_shaded=n_faces, raster_bg=0.75)

    fb = build(prim)
    cov = prim >= 0
    assert np.all(fb.eye_depth[~cov] == np.inf) and np.all(fb.normal[~cov] == 0.0)
    assert np.all(fb.prim_id[~cov] == -1) and np.all(fb.object_id[~cov] == -1)
    assert np.all(fb.depth[~cov] == np.float32(0.75)) and not fb.front_facing[~cov].any()
    assert np.all(fb.barycentric[~cov] == 0.0)
    assert np.array_equal(fb.prim_id[cov], prim[cov]) and np.all(fb.object_id[cov] == 0)
    assert np.array_equal(fb.depth[cov], depth[cov])
    assert np.array_equal(fb.front_facing[cov], front[cov])
    assert np.array_equal(fb.barycentric[cov], bary[cov])
    mv = kw["view"]
    corners = v[f[prim[cov]]]                                        # (n, 3 corners, 3)
    b = bary[cov].astype(np.float64)
    p = [(b[:, 0] * corners[:, 0, j] + b[:, 1] * corners[:, 1, j]) + b[:, 2] * corners[:, 2, j]
         for j in range(3)]
    ez = ((mv[2, 0] * p[0] + mv[2, 1] * p[1]) + mv[2, 2] * p[2]) + mv[2, 3]
    assert np.array_equal(fb.eye_depth[cov], (-ez).astype(np.float32))
    assert np.all(np.linalg.norm(fb.normal[cov], axis=1) > 0.99)
    # the colour: runs of background against pixel-by-pixel background (the face n_faces)
    ref = build(np.where(cov, prim, n_faces).astype(np.int32))
    color = np.asarray(fb.color)
    assert np.all(color[~cov] == np.float32(bg))
    assert color.tobytes() == np.asarray(ref.color).tobytes()
