"""The fused clip-and-cap tile pass against the fragment stream with the Python clip stage.

``render_clipped`` evaluates the clip test and the volumetric parity test inside the
rasterizer's tile loop when the parity tests are volumetric depth sprites; otherwise (or with
``clipsurface.render._USE_FUSED`` off) it draws a fragment stream and runs the stage in NumPy;
both must give the same bits. Cap culling (``capping.cull_cap``) must not change a pixel either.
"""

import numpy as np
import pytest
import trimesh

import refraster
from refraster.clipsurface import capping, fused
from refraster.clipsurface import render as cs_render
from refraster.clipsurface import offsetmaps as om
from refraster.camera import frame_bounds, look_at, perspective
from refraster import RasterState
from refraster.clipsurface import Caps, ClipSurface, render_clipped
from refraster.ldi import VolumetricDepthSprite
from refraster.mesh import Mesh, bounds
from refraster.scenes import crank

FIELDS = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing", "barycentric",
          "color", "cap_mask", "cap_points")


class Wrapped:
    """A duck-typed parity test: forces the fragment-stream path (and no cap culling)."""

    def __init__(self, sprite):
        self.sprite = sprite

    def contains(self, points):
        return self.sprite.contains(points)


def staged(monkeypatch, *args, **kwargs):
    with monkeypatch.context() as m:
        m.setattr(cs_render, "_USE_FUSED", False)
        return render_clipped(*args, **kwargs)


def assert_same(a, b, fields=FIELDS):
    for f in fields:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f


def _frame(n):
    n = np.asarray(n, float) / np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@pytest.fixture(scope="module")
def crank_scene():
    mesh = crank()
    lo, hi = mesh.bounds
    u, v = _frame([0.0, 0.25, -1.0])
    ext = float(np.linalg.norm(hi - lo))
    ragged = ClipSurface((lo + hi) / 2, ext * u, ext * v, (1.0, 1.0, 0.6),
                         om.perlin_noise(64, seed=1))
    u2, v2 = _frame([1.0, 0.1, 0.2])
    second = ClipSurface((lo + hi) / 2 + [0.3 * (hi - lo)[0], 0, 0], ext * u2, ext * v2,
                         (2.0, 2.0, 0.05), om.sinusoid(32, periods=(3, 1)),
                         wrap="mirrored_repeat")
    cam = frame_bounds(mesh.bounds, width=200, height=150, direction=(0.3, 0.7, 1.0))
    sprite = VolumetricDepthSprite.from_mesh(mesh, resolution=256)
    return mesh, ragged, second, cam, sprite


@pytest.mark.parametrize("space", ["world", "eye"])
@pytest.mark.parametrize("two", [False, True], ids=["one surface", "two surfaces"])
def test_fused_equals_stream_on_the_crank(crank_scene, monkeypatch, space, two):
    mesh, ragged, second, cam, sprite = crank_scene
    surfaces = [ragged, second] if two else ragged
    kw = dict(**cam.kwargs, vds=[sprite], caps=Caps(style="hatch"), space=space)
    fused = render_clipped(mesh, surfaces, **kw)
    ref = staged(monkeypatch, mesh, surfaces, **kw)
    assert fused.cap_mask.sum() > 200
    assert_same(fused, ref)


def test_fused_equals_stream_without_caps(crank_scene, monkeypatch):
    mesh, ragged, second, cam, _ = crank_scene
    kw = dict(**cam.kwargs, caps=None)
    fused = render_clipped(mesh, [ragged, second.replace(enabled=False)], **kw)
    ref = staged(monkeypatch, mesh, [ragged, second.replace(enabled=False)], **kw)
    assert_same(fused, ref)
    plain = refraster.render(mesh, **cam.kwargs)
    assert (fused.mask < plain.mask).any()           # the surface removed something


def test_fused_equals_stream_for_two_solids_with_models_and_three_axes(monkeypatch):
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.6)
    m0 = np.eye(4)
    m1 = np.eye(4)
    m1[:3, 3] = [1.3, 0.2, -0.3]
    m1[:3, :3] = trimesh.transformations.rotation_matrix(0.4, [0, 1, 1])[:3, :3]
    cs = ClipSurface([0.5, 0.0, 0.0], [0, 3.0, 0], [3.0, 0, 0], (2, 2, 0.3),
                     om.perlin_noise(32, seed=3))
    world = [Mesh(np.asarray(box.vertices), np.asarray(box.faces)),
             Mesh(np.asarray(ball.vertices) @ m1[:3, :3].T + m1[:3, 3], np.asarray(ball.faces))]
    sprites = [VolumetricDepthSprite.from_mesh(world[0], resolution=64, axis="xyz"),
               VolumetricDepthSprite.from_mesh(world[1], resolution=64)]
    kw = dict(view=look_at([2.0, 1.5, 3.0], [0.6, 0, 0]), proj=perspective(40, 4 / 3, 0.5, 10),
              width=160, height=120, model=[m0, m1], vds=sprites,
              caps=Caps(style="diffuse"),
              raster=RasterState(normals="smooth"))
    fused = render_clipped([box, ball], cs, **kw)
    ref = staged(monkeypatch, [box, ball], cs, **kw)
    assert set(np.unique(fused.object_id[fused.cap_mask])) == {2, 3}
    assert_same(fused, ref)


def test_cap_culling_changes_no_pixel(crank_scene):
    """Culled caps (sprite given) against the whole cap grid (duck-typed test, no culling):
    every buffer equal except the caps' face indices, which count the kept faces."""
    mesh, ragged, _, cam, sprite = crank_scene
    kw = dict(**cam.kwargs, caps=Caps(style="marble"))
    culled = render_clipped(mesh, ragged, vds=[sprite], **kw)
    whole = render_clipped(mesh, ragged, vds=[Wrapped(sprite)], **kw)
    assert_same(culled, whole, [f for f in FIELDS if f != "prim_id"])
    solid = culled.mask & ~culled.cap_mask
    assert np.array_equal(culled.prim_id[solid], whole.prim_id[solid])
    full = capping.cap_mesh(ragged, bounds(mesh.vertices))
    kept = capping.cull_cap(full, sprite)
    assert 0 < kept.n_faces < 0.6 * full.n_faces


def test_cull_cap_keeps_faces_reaching_the_solid():
    """Brute force on a small case: a face is dropped only if no point sampled on it (with a
    small margin) is inside the solid by the parity test."""
    box = Mesh(*(np.asarray(a) for a in (trimesh.creation.box((1, 1, 1)).vertices,
                                         trimesh.creation.box((1, 1, 1)).faces)))
    sprite = VolumetricDepthSprite.from_mesh(box, resolution=32)
    cs = ClipSurface([0.1, 0, 0], [0, 2.0, 0.4], [0, -0.4, 2.0], (1, 1, 0.4),
                     om.perlin_noise(12, seed=5))
    cap = capping.cap_mesh(cs, bounds(box.vertices))
    kept = capping.cull_cap(cap, sprite)
    kept_keys = {tuple(np.round(kept.vertices[f].mean(axis=0), 12)) for f in kept.faces}
    rng = np.random.default_rng(0)
    w = rng.dirichlet((1, 1, 1), size=64)
    for f in cap.faces:
        key = tuple(np.round(cap.vertices[f].mean(axis=0), 12))
        if key in kept_keys:
            continue
        pts = w @ cap.vertices[f]
        assert not sprite.contains(pts).any()


def test_clipped_framebuffer_cap_position_image(crank_scene):
    mesh, ragged, _, cam, sprite = crank_scene
    fb = render_clipped(mesh, ragged, **cam.kwargs, vds=[sprite])
    img = fb.cap_position
    assert img.shape == fb.depth.shape + (3,)
    assert np.array_equal(img[fb.cap_mask], fb.cap_points)
    assert np.isnan(img[~fb.cap_mask]).all()
    eye = fb.eye_position()[fb.cap_mask]
    np.testing.assert_allclose(-eye[:, 2], fb.eye_depth[fb.cap_mask], rtol=1e-6)


def test_bounds_matches_numpy():
    v = np.random.default_rng(1).normal(size=(1001, 3))
    np.testing.assert_array_equal(bounds(v), np.stack([v.min(axis=0), v.max(axis=0)]))
    with pytest.raises(ValueError, match="vertices"):
        bounds(np.zeros((0, 3)))


def test_watertight_memo_sees_changed_arrays():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = np.array(box.vertices)
    f = np.array(box.faces)
    capping.check_watertight(Mesh(v, f))
    capping.check_watertight(Mesh(v, f))          # remembered
    f[-1] = f[0]                                  # now two faces are the same, one edge open
    with pytest.raises(ValueError, match="watertight"):
        capping.check_watertight(Mesh(v, f))


def test_watertight_check_returns_the_bounds_of_the_arrays_it_was_given():
    # the check keeps each solid's bounds with its copy: a mesh with other vertices (still
    # watertight) must get its own bounds, not the remembered ones (a stale box would place
    # the caps' grid wrongly: a silent wrong picture)
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = np.array(box.vertices)
    f = np.array(box.faces)
    first = capping.check_watertight(Mesh(v, f))
    np.testing.assert_array_equal(first, bounds(v))
    again = capping.check_watertight(Mesh(v.copy(), f.copy()))   # remembered: equal bits
    np.testing.assert_array_equal(again, bounds(v))
    assert not again.flags.writeable
    moved = v * 2.0 + 3.0
    np.testing.assert_array_equal(capping.check_watertight(Mesh(moved, f)), bounds(moved))
    v[0, 0] = 7.0   # the caller's array changed in place: still watertight, other bounds
    np.testing.assert_array_equal(capping.check_watertight(Mesh(v, f)), bounds(v))


@pytest.mark.parametrize("n_solids", [0, 1, 3, 7])
def test_cap_pixels_equals_numpy(n_solids):
    rng = np.random.default_rng(n_solids)
    for shape in ((1, 1), (5, 9), (64, 33), (200, 301)):
        obj = rng.integers(-1, 9, size=shape).astype(np.int32)
        mask, flat = capping.cap_pixels(obj, n_solids)
        np.testing.assert_array_equal(mask, obj >= n_solids)
        np.testing.assert_array_equal(flat, np.flatnonzero(obj >= n_solids))
        assert mask.dtype == np.bool_ and flat.dtype == np.int64
    mask, flat = capping.cap_pixels(np.full((4, 6), -1, np.int32), 1)   # no cap at all
    assert not mask.any() and flat.size == 0


def test_a_kept_cap_mask_is_not_reused_by_the_next_frame(crank_scene):
    # cap_pixels takes the mask from the recycled output pool (a frame of 400×300 is above its
    # smallest size): a frame the caller still holds must keep its mask
    mesh, ragged, _, _, sprite = crank_scene
    cams = [frame_bounds(mesh.bounds, width=400, height=300, direction=d)
            for d in ((0.3, 0.7, 1.0), (-0.6, 0.4, 1.0))]
    first = render_clipped(mesh, ragged, **cams[0].kwargs, vds=[sprite])
    kept = first.cap_mask.copy()
    assert kept.any()
    for _ in range(3):
        other = render_clipped(mesh, ragged, **cams[1].kwargs, vds=[sprite])
        assert not np.array_equal(other.cap_mask, kept)
        del other
    np.testing.assert_array_equal(first.cap_mask, kept)


def test_same_bits_compares_shape_dtype_and_every_word():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3))
    assert capping._same_bits(a, a.copy())
    for i in (0, 777, 1499):   # one word changed anywhere
        b = a.copy()
        b.reshape(-1)[i] = np.nextafter(b.reshape(-1)[i], np.inf)
        assert not capping._same_bits(a, b)
    z = a.copy()
    z[0, 0] = 0.0
    z2 = z.copy()
    z2[0, 0] = -0.0                                  # equal values, other bits
    assert not capping._same_bits(z, z2)
    assert not capping._same_bits(a, a[:-1].copy()) and not capping._same_bits(a, a.reshape(3, 500))
    assert not capping._same_bits(a, a.view(np.int64))
    assert capping._same_bits(a[:, :2], a[:, :2].copy())         # strided: the slow path
    assert capping._same_bits(a.astype(np.float32), a.astype(np.float32))
    assert capping._same_bits(np.zeros((0, 3)), np.zeros((0, 3)))


@pytest.mark.parametrize("cull", ["none", "back"])
def test_fused_equals_stream_with_near_plane_clipping(monkeypatch, cull):
    """A camera inside the box's bounding sphere: the near plane cuts faces into pieces, which
    the fused pass tests fragment by fragment (no box classification for pieces)."""
    box = trimesh.creation.box((2.0, 2.0, 2.0))
    cs = ClipSurface([0.2, 0.0, 0.0], [0, 4.0, 0], [0, 0, 4.0], (1, 1, 0.5),
                     om.perlin_noise(32, seed=7))
    sprite = VolumetricDepthSprite.from_mesh(box, resolution=128)
    kw = dict(view=look_at([1.6, 0.4, 1.3], [0.0, 0.0, -0.5]),
              proj=perspective(70, 4 / 3, 0.9, 10), width=160, height=120, vds=[sprite],
              raster=RasterState(cull=cull), caps=Caps(style="wood"))
    prep = refraster.raster.prepare(box, view=kw["view"], proj=kw["proj"], width=160,
                                    height=120)
    assert len(prep.triangles.clipped) > 0          # the near plane does cut faces
    fused = render_clipped(box, cs, **kw)
    ref = staged(monkeypatch, box, cs, **kw)
    assert fused.cap_mask.any() and fused.mask.any()
    assert_same(fused, ref)


# --------------------------------------------------- cap faces that surely pass the parity test

def test_surely_inside_faces_are_inside_everywhere_near_them():
    """Brute force: every point a fragment of a flagged face can land on — barycentrics down
    to −SURE_EXTRAPOLATION — is inside by the parity test; and the flag is not vacuous."""
    box = Mesh(*(np.asarray(a) for a in (trimesh.creation.box((1, 1, 1)).vertices,
                                         trimesh.creation.box((1, 1, 1)).faces)))
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    rng = np.random.default_rng(1)
    lim = capping.SURE_EXTRAPOLATION
    for solid in (box, Mesh(np.asarray(ball.vertices), np.asarray(ball.faces))):
        sprite = VolumetricDepthSprite.from_mesh(solid, resolution=32)
        cs = ClipSurface([0.05, 0, 0], [0, 2.0, 0.4], [0, -0.4, 2.0], (1, 1, 0.4),
                         om.perlin_noise(40, seed=5))
        cap = capping.cull_cap(capping.cap_mesh(cs, bounds(solid.vertices)), sprite)
        sure = capping.surely_inside(cap, sprite)
        assert sure.dtype == np.bool_ and sure.shape == (cap.n_faces,)
        assert 0.4 * cap.n_faces < sure.sum() < cap.n_faces
        # barycentrics summing to 1 with each ≥ −lim: the corners of that region and random
        # points in it
        corners = np.array([[1 + 2 * lim, -lim, -lim], [-lim, 1 + 2 * lim, -lim],
                            [-lim, -lim, 1 + 2 * lim]])
        w = np.concatenate([corners, rng.dirichlet((1, 1, 1), size=40) @ corners])
        tri = cap.vertices[cap.faces[sure]]                      # (S, 3, 3)
        pts = np.einsum("kc,scj->skj", w, tri).reshape(-1, 3)
        assert sprite.contains(pts).all()


def _snapped_coverage(p, bits=8):
    """Pixel centres covered by the triangle ``p`` (3, 2) after snapping to 2^−bits pixel
    (inclusive of its edges: a superset of any fill rule's)."""
    q = np.rint((p - 0.5) * (1 << bits)) / (1 << bits) + 0.5
    lo = np.floor(q.min(axis=0)).astype(int)
    hi = np.ceil(q.max(axis=0)).astype(int)
    xs, ys = np.meshgrid(np.arange(lo[0], hi[0] + 1) + 0.5, np.arange(lo[1], hi[1] + 1) + 0.5)
    c = np.stack([xs.ravel(), ys.ravel()], 1)

    def edge(a, b, pt):
        return (b[0] - a[0]) * (pt[:, 1] - a[1]) - (b[1] - a[1]) * (pt[:, 0] - a[0])
    e = np.stack([edge(q[1], q[2], c), edge(q[2], q[0], c), edge(q[0], q[1], c)], 1)
    return c[(e >= 0).all(axis=1)]


def test_fragments_stay_near_bounds_the_extrapolation():
    """Random (many of them thin) triangles with random 1/w: wherever the guard says the
    fragments stay near, every covered centre's perspective-correct barycentrics are
    ≥ −limit; and the guard passes ordinary triangles."""
    rng = np.random.default_rng(7)
    lim = capping.SURE_EXTRAPOLATION
    passed = 0
    for trial in range(3000):
        p = rng.uniform(0, 12, size=(3, 2))
        if trial % 2:   # a sliver: the third vertex near the first edge
            t = rng.uniform(0, 1)
            p[2] = p[0] + t * (p[1] - p[0]) + rng.normal(0, 0.05, 2)
        d = p[1:] - p[0]
        area2 = d[0, 0] * d[1, 1] - d[1, 0] * d[0, 1]
        if area2 < 0:
            p = p[[0, 2, 1]]
            area2 = -area2
        if area2 <= 0:
            continue
        iw = rng.uniform(0.2, 1.0, 3)
        ok = fused._fragments_stay_near(*p.ravel(), *iw, 1.0 / area2, 8, lim)
        if not ok:
            continue
        passed += 1
        c = _snapped_coverage(p)
        if len(c) == 0:
            continue
        l0 = ((p[2, 0] - p[1, 0]) * (c[:, 1] - p[1, 1]) - (p[2, 1] - p[1, 1]) * (c[:, 0] - p[1, 0]))
        l1 = ((p[0, 0] - p[2, 0]) * (c[:, 1] - p[2, 1]) - (p[0, 1] - p[2, 1]) * (c[:, 0] - p[2, 0]))
        l2 = ((p[1, 0] - p[0, 0]) * (c[:, 1] - p[0, 1]) - (p[1, 1] - p[0, 1]) * (c[:, 0] - p[0, 0]))
        q = np.stack([l0, l1, l2], 1) / area2 * iw
        bary = q / q.sum(axis=1, keepdims=True)
        assert bary.min() >= -lim, (p, iw)
    assert passed > 1000


def test_surely_inside_flags_change_no_pixel(crank_scene, monkeypatch):
    """The fused pass with the flags against the fused pass with every flag cleared."""
    mesh, ragged, second, cam, sprite = crank_scene
    kw = dict(**cam.kwargs, vds=[sprite], caps=Caps(style="hatch"))
    for surfaces in (ragged, [ragged, second]):
        flagged = render_clipped(mesh, surfaces, **kw)
        orig = cs_render._cached_cap

        def cleared(*a, **k):
            m, sure = orig(*a, **k)
            return m, (None if sure is None else np.zeros_like(sure))
        with monkeypatch.context() as m:
            m.setattr(cs_render, "_cached_cap", cleared)
            plain = render_clipped(mesh, surfaces, **kw)
        assert flagged.cap_mask.sum() > 200
        assert_same(flagged, plain)


@pytest.mark.parametrize("caps", [Caps(style="hatch"), None], ids=["caps", "no caps"])
def test_fused_pass_writes_the_face_images_background(crank_scene, monkeypatch, caps):
    """The fused clip pass writes the face image's −1 itself (in tiles nothing was binned to,
    and in a binned tile's pixels no fragment won): with the output pool handing out garbage
    the frame still equals the fragment stream's, and the frame has both kinds of pixel."""
    from refraster._scratch import OUTPUTS

    mesh, ragged, _, _, sprite = crank_scene
    # wide enough for tiles with nothing binned beside the crank
    cam = frame_bounds(mesh.bounds, width=420, height=150, direction=(0.3, 0.7, 1.0))
    kw = dict(**cam.kwargs, vds=[sprite], caps=caps)
    ref = staged(monkeypatch, mesh, ragged, **kw)
    with monkeypatch.context() as m:
        m.setattr(OUTPUTS, "empty", lambda shape, dtype: np.full(shape, 7, dtype))
        got = render_clipped(mesh, ragged, **kw)
    assert_same(got, ref)
    bg = ref.prim_id < 0
    assert bg[:, :64].all() and bg[:, -64:].all()        # whole empty tiles on either side
    assert bg[:, 64:-64].any() and (~bg).any()
