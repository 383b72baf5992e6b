"""The foundation: vertex/primitive stages, rasterizer, fragment stream, resolve, G-buffer."""


import numpy as np
import pytest
import trimesh
from hypothesis import given, settings, strategies as st

import refraster as rf
from refraster.raster.primitive import transform_vertices
from refraster.raster.rasterizer import DEPTH_FUNCS, NARROW, fused, stream

import naive
from determinism import outputs_by_thread_count

VIEW = rf.look_at([0.3, 0.4, 3.0], [0, 0, 0])
PROJ = rf.perspective(50, 4 / 3, 0.5, 10.0)


def _random_soup(rng, n, spread=1.0):
    v = rng.uniform(-spread, spread, (3 * n, 3))
    return v, np.arange(3 * n).reshape(n, 3)


# ---------------------------------------------------------------- NumPy twin, bit for bit

@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("rule", ["bottom-left", "top-left"])
def test_stream_matches_naive_twin(seed, rule):
    rng = np.random.default_rng(seed)
    v, f = _random_soup(rng, 12, 0.9)
    # snap some vertices to pixel centres so the fill rule's ties are exercised
    w, h = 24, 20
    mvp = PROJ @ VIEW
    clip = transform_vertices(v, mvp)
    frags = rf.rasterize(clip, f, w, h, raster=rf.RasterState(fill_rule=rule))
    ref = naive.raster_unclipped(clip, f, w, h, rule=rule)
    got = sorted(zip(frags.prim_id.tolist(), frags.row.tolist(), frags.col.tolist(),
                     frags.depth.tolist(), map(tuple, frags.bary.tolist()),
                     frags.front_facing.tolist()))
    want = sorted((a, b, c, float(d), tuple(e.tolist()), bool(g)) for a, b, c, d, e, g in ref)
    assert got == want


def _one_pixel_faces(rng, w, h, n):
    """Clip coordinates and faces of ``n`` triangles smaller than a pixel, each near a pixel
    centre (so most boxes hold one centre), both windings; every third has an edge through
    its pixel's centre exactly (horizontal, vertical or diagonal), where the fill rule
    decides. Window positions are multiples of 1/256 pixel and w = h are powers of two, so
    the snapped positions are exactly these."""
    pts = []
    for i in range(n):
        cx, cy = rng.integers(0, w) + 0.5, rng.integers(0, h) + 0.5
        if i % 3 == 0:
            a = rng.integers(20, 120) / 256
            kind = i % 9
            if kind == 0:      # horizontal edge through the centre
                tri = [(cx - a, cy), (cx + a, cy), (cx, cy + rng.choice([-1, 1]) * a)]
            elif kind == 3:    # vertical
                tri = [(cx, cy - a), (cx, cy + a), (cx + rng.choice([-1, 1]) * a, cy)]
            else:              # diagonal
                tri = [(cx - a, cy - a), (cx + a, cy + a), (cx + rng.choice([-1, 1]) * a, cy)]
        else:
            tri = [(cx + dx, cy + dy) for dx, dy in rng.integers(-200, 201, (3, 2)) / 256]
        if rng.random() < 0.5:
            tri = tri[::-1]
        pts += tri
    xy = np.asarray(pts)
    clip = np.zeros((len(xy), 4), np.float32)
    clip[:, 0] = 2 * xy[:, 0] / w - 1
    clip[:, 1] = 2 * xy[:, 1] / h - 1
    clip[:, 2] = rng.uniform(-0.9, 0.9, len(xy))
    clip[:, 3] = 1
    return clip, np.arange(len(xy)).reshape(-1, 3)


@pytest.mark.parametrize("rule", ["bottom-left", "top-left"])
def test_one_pixel_boxes_match_naive_twin(rule):
    """Faces whose box holds one pixel centre: the primitive stage drops those whose centre
    lies strictly outside an edge (they were set up in the tile pass for nothing), keeps those
    with the centre on an edge for the fill rule. Against the twin, which tests every pixel
    of every face; the scene has each kind (covered, not covered, covered only by the rule)."""
    from refraster.raster import primitive as P
    w = h = 16
    clip, f = _one_pixel_faces(np.random.default_rng(5), w, h, 360)
    ref = naive.raster_unclipped(clip, f, w, h, rule=rule)
    frags = rf.rasterize(clip, f, w, h, raster=rf.RasterState(fill_rule=rule))
    got = sorted(zip(frags.prim_id.tolist(), frags.row.tolist(), frags.col.tolist(),
                     frags.depth.tolist(), map(tuple, frags.bary.tolist()),
                     frags.front_facing.tolist()))
    want = sorted((a, b, c, float(d), tuple(e.tolist()), bool(g)) for a, b, c, d, e, g in ref)
    assert got == want
    st = P.setup_triangles(clip.astype(np.float64), f, w, h)
    box = st.bbox.astype(np.int64)
    one = (box[:, 0] == box[:, 1]) & (box[:, 2] == box[:, 3]) & (st.status == P.SIMPLE)
    drawn = np.zeros(len(f), bool)
    drawn[[a for a, *_ in ref]] = True
    on_edge = one & ~drawn   # kept for the rule, which gave the centre to a neighbour
    assert one.sum() > 100 and (one & drawn).sum() > 50 and on_edge.sum() > 5
    assert drawn[~one & (st.status == P.SIMPLE)].all()   # larger boxes here hold fragments
    assert (st.status == P.SKIP).sum() > 100              # and most centre-less ones dropped
    # with a pad (multisampling: samples off the centre) no face is dropped for its centre
    padded = P.setup_triangles(clip.astype(np.float64), f, w, h, pad=128)
    assert (padded.status == P.SIMPLE).sum() == len(f)


def test_vertex_stage_matches_twin():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(500, 3)) * 10
    mvp = PROJ @ VIEW
    assert transform_vertices(v, mvp).tobytes() == naive.vertex_stage32(v, mvp).tobytes()


def test_fill_rule_on_shared_pixel_centres():
    # two triangles sharing a diagonal that passes exactly through pixel centres:
    # each centre on it is drawn exactly once
    w = h = 8
    # window coords: a square (0,0)-(8,8); the diagonal passes through (k+.5, k+.5)
    def ndc(x, y):
        return [2 * x / w - 1, 2 * y / h - 1, 0.0, 1.0]
    clip = np.array([ndc(0.5, 0.5), ndc(7.5, 0.5), ndc(7.5, 7.5), ndc(0.5, 7.5)], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    fr = rf.rasterize(clip, faces, w, h)
    counts = np.bincount(fr.pixel, minlength=w * h)
    assert counts.max() == 1
    # pixel centres on the diagonal belong to the upper-left triangle (the diagonal is its
    # ... bottom-right edge? no: for face 1 (0,2,3) the diagonal runs 0->2 upward = right edge;
    # for face 0 it is the edge 2->0 going down = left edge) -> face 0 owns them
    diag = [(h - 1 - k) * w + k for k in range(1, 7)]
    owner = {p: pr for p, pr in zip(fr.pixel.tolist(), fr.prim_id.tolist())}
    assert all(owner[p] == 0 for p in diag)
    # bottom edge y=0.5 (row 7 from top) owned by face 0, left edge x=0.5 by face 1
    assert owner[(h - 1) * w + 3] == 0
    assert owner[3 * w + 0] == 1
    # top edge y=7.5 and right edge x=7.5 are not owned
    assert 0 * w + 3 not in owner or owner.get(0 * w + 3) is None
    assert (3 * w + 7) not in owner


# ---------------------------------------------------------------- fused path == stream + resolve

def _assert_fused_equals_resolve(prep, func, clear):
    """The fused pass's depth, face, facing and barycentrics equal the fragment stream of the
    same triangles resolved with ``func``; returns ``(prim, number of fragments)``."""
    w, h = prep.width, prep.height
    depth, prim, front, bary = fused(prep.triangles, depth_func=DEPTH_FUNCS[func],
                                     clear_depth=clear)
    pixel, fd, _, fprim, ffront, fbary, _ = stream(prep.triangles)
    frags = rf.Fragments(pixel, fd, fprim, np.zeros_like(fprim), fbary, ffront, w, h)
    res = rf.resolve(frags, raster=rf.RasterState(depth_func=func, clear_depth=clear))
    assert res.depth.tobytes() == depth.tobytes()
    assert np.array_equal(np.where(res.winner >= 0, fprim[res.winner], -1), prim)
    assert np.array_equal(np.where(res.winner >= 0, ffront[res.winner], False), front)
    m = res.winner.ravel() >= 0
    assert fbary[res.winner.ravel()[m]].tobytes() == bary[m].tobytes()
    return prim, len(pixel)


@pytest.mark.parametrize("func", sorted(DEPTH_FUNCS))
def test_fused_equals_stream_and_resolve(func):
    rng = np.random.default_rng(7)
    v, f = _random_soup(rng, 60, 1.5)
    # plus large triangles crossing the near plane and the guard band (clipped pieces)
    v2, f2 = _random_soup(rng, 8, 40.0)
    v = np.concatenate([v, v2 + [0, 0, 3.0]])
    f = np.concatenate([f, f2 + len(f) * 3])
    clear = 0.0 if func in ("greater", "gequal") else 1.0
    prep = rf.raster.prepare((v, f), view=VIEW, proj=PROJ, width=40, height=30)
    assert len(prep.triangles.clipped) > 0
    _assert_fused_equals_resolve(prep, func, clear)


@pytest.mark.parametrize("func", sorted(DEPTH_FUNCS))
def test_fused_ties_equal_stream_and_resolve(func):
    """Depth ties, through both loops of the tile pass (its own loop for "less" with the
    unsnapped depth plane, the general one for the other functions): every triangle is drawn
    twice, the second time with its corners in the other order (a back face with the same
    depth at every pixel), so at each covered pixel the depth function alone decides whether
    the later copy replaces the earlier."""
    rng = np.random.default_rng(11)
    v, f = _random_soup(rng, 40, 1.2)
    f = np.stack([f, f[:, ::-1]], axis=1).reshape(-1, 3)   # each face, then its mirror
    clear = 0.0 if func in ("greater", "gequal") else 1.0
    prep = rf.raster.prepare((v, f), view=VIEW, proj=PROJ, width=64, height=48)
    prim, _ = _assert_fused_equals_resolve(prep, func, clear)
    if func in ("less", "lequal", "gequal", "always"):
        assert ((prim % 2 == 1) == (func != "less")).sum() > 100   # ties decided both ways


@pytest.mark.parametrize("func", sorted(DEPTH_FUNCS))
def test_fused_pixel_centres_on_shared_edges(func):
    """Shared edges through pixel centres, in both loops of the tile pass: a square viewport
    tiled by two triangles split along its diagonal (which passes through every centre
    (k + ½, k + ½)) and by two rectangles sharing the vertical line x = 16.5 px. A tiling covers
    every pixel centre exactly once (the fill rule gives each edge centre to one side): every
    pixel is covered, and the fused pass equals the fragment stream + resolve. The same with
    a grid of small triangles whose edges (all three directions) pass through centres."""
    n = 32
    xm = 16.5 / n * 2 - 1   # the vertical edge at x = 16.5 px, exact in binary
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0],
                  [xm, -1, 0], [xm, 1, 0]], np.float64)
    scenes = {"diagonal": np.array([[0, 1, 2], [0, 2, 3]]),
              "vertical": np.array([[0, 4, 5], [0, 5, 3], [4, 1, 2], [4, 2, 5]])}
    # small triangles (boxes at most NARROW pixels wide: the vectorized loops' narrow form):
    # 3-pixel cells with corners on pixel centres, split along alternating diagonals, so
    # their horizontal, vertical and diagonal edges all pass through pixel centres
    k = 12
    g = (0.5 + 3.0 * np.arange(k)) / n * 2 - 1
    gx, gy = np.meshgrid(g, g)
    gv = np.stack([gx.ravel(), gy.ravel(), np.zeros(k * k)], axis=1)
    cells = []
    for i in range(k - 1):
        for j in range(k - 1):
            a, b, c, d = i * k + j, i * k + j + 1, (i + 1) * k + j + 1, (i + 1) * k + j
            cells += ([[a, b, c], [a, c, d]] if (i + j) % 2 else [[a, b, d], [b, c, d]])
    v = np.concatenate([v, gv])
    scenes["small grid"] = np.array(cells) + 6
    assert NARROW >= 4   # the grid's boxes (4 pixels a side) take the narrow form
    # each face's corners in its three rotations: the shared edge is edge 0, 1 and 2 in turn
    scenes = {f"{name} {r}": np.roll(f, r, axis=1) for name, f in scenes.items()
              for r in range(3)}
    clear = {"greater": 0.0, "gequal": 0.0, "equal": 0.5}.get(func, 1.0)
    for name, f in scenes.items():
        prep = rf.raster.prepare((v, f), view=np.eye(4), proj=np.eye(4), width=n, height=n)
        prim, n_frags = _assert_fused_equals_resolve(prep, func, clear)
        assert n_frags == n * n, name   # each centre once: the tiling, by the fill rule
        assert ((prim >= 0).all() if func != "never" else (prim < 0).all()), name


def test_fused_keeps_the_first_clipped_piece():
    """Regression: the fused pass once marked "no winner" with −1, which is also the binned
    item of clipped piece 0, so that piece's pixels came out as background (ids, normal,
    colour) under a written depth. A camera inside a box's bounding sphere: the near plane cuts
    faces, and piece 0 is visible."""
    import trimesh
    box = trimesh.creation.box((2.0, 2.0, 2.0))
    view = rf.look_at([1.6, 0.4, 1.3], [0.0, 0.0, -0.5])
    proj = rf.perspective(70, 4 / 3, 0.9, 10)
    prep = rf.raster.prepare(box, view=view, proj=proj, width=160, height=120)
    st = prep.triangles
    depth, prim, front, bary = fused(st)
    pixel, fd, _, fprim, ffront, fbary, _ = stream(st)
    frags = rf.Fragments(pixel, fd, fprim, np.zeros_like(fprim), fbary, ffront, 160, 120)
    res = rf.resolve(frags)
    want = np.where(res.winner >= 0, fprim[res.winner], -1)
    assert np.count_nonzero(want == st.clipped.prim[0]) > 100   # piece 0's face is visible
    assert np.array_equal(want, prim)
    assert np.array_equal(prim >= 0, depth < 1.0)
    fb = rf.render(box, view=view, proj=proj, width=160, height=120)
    assert np.array_equal(fb.mask, fb.depth < 1.0)


def test_fused_background_keeps_the_clear_values():
    """The fused pass writes only the pixels a fragment won; the rest (tiles with nothing
    binned included) hold the clear depth, face −1, facing False and zero barycentrics."""
    rng = np.random.default_rng(3)
    v, f = _random_soup(rng, 12, 0.4)
    prep = rf.raster.prepare((v, f), view=VIEW, proj=PROJ, width=300, height=200)
    depth, prim, front, bary = fused(prep.triangles, depth_func=DEPTH_FUNCS["always"],
                                     clear_depth=0.625)
    bg = prim < 0
    assert 0 < bg.sum() < bg.size - 100
    # some tiles have nothing binned at all
    from refraster.raster.rasterizer import bin_primitives
    _, _, starts, _ = bin_primitives(prep.triangles)
    assert (np.diff(starts) == 0).any()
    assert np.all(depth[bg] == np.float32(0.625)) and not front[bg].any()
    assert not bary[bg.ravel()].any()
    pixel, fd, _, fprim, ffront, fbary, _ = stream(prep.triangles)
    frags = rf.Fragments(pixel, fd, fprim, np.zeros_like(fprim), fbary, ffront, 300, 200)
    res = rf.resolve(frags, raster=rf.RasterState(depth_func="always", clear_depth=0.625))
    assert res.depth.tobytes() == depth.tobytes()


def test_color_is_shaded_when_first_read():
    """render() leaves the default colour pending until it is read; once read it is a plain
    array, and the fused and the fragment-stream paths shade the same bytes."""
    from refraster.framebuffer import _PendingShade
    m = trimesh.creation.torus(1.0, 0.35)
    kw = dict(view=VIEW, proj=PROJ, width=64, height=48, background=(0.1, 0.2, 0.3))
    fb = rf.render(m, **kw)
    assert isinstance(fb.__dict__["_color"], _PendingShade)
    assert isinstance(fb.field_values()["color"], _PendingShade)   # copying fields does not shade
    color = fb.color
    assert color.dtype == np.float32 and color.shape == (48, 64, 3)
    assert fb.color is color and isinstance(fb.__dict__["_color"], np.ndarray)
    assert np.all(color[~fb.mask] == np.float32([0.1, 0.2, 0.3]))
    assert np.all(color[fb.mask] > 0.0)
    fb.color[0, 0] = 5.0
    assert fb.color[0, 0, 0] == 5.0 and fb.arrays()["color"][0, 0, 0] == 5.0
    streamed = rf.render(m, fragment_stage=lambda fr: np.ones(len(fr), bool), **kw)
    assert rf.render(m, **kw).color.tobytes() == streamed.color.tobytes()


def test_render_paths_agree():
    m = trimesh.creation.torus(1.0, 0.35)
    kw = dict(view=VIEW, proj=PROJ, width=64, height=48)
    a = rf.render(m, **kw)
    b = rf.render(m, fragment_stage=lambda fr: np.ones(len(fr), bool), **kw)
    for k, x in a.arrays().items():
        assert x.tobytes() == b.arrays()[k].tobytes(), k


# ---------------------------------------------------------------- resolve semantics

def test_draw_order_ties():
    quad = (np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], float),
            np.array([[0, 1, 2], [0, 2, 3]]))
    view = rf.look_at([0, 0, 2], [0, 0, 0])
    kw = dict(view=view, proj=PROJ, width=16, height=12)
    a = rf.render([quad, quad], raster=rf.RasterState(depth_func="less"), **kw)
    assert set(np.unique(a.object_id)) == {0}
    b = rf.render([quad, quad], raster=rf.RasterState(depth_func="lequal"), **kw)
    assert set(np.unique(b.object_id)) == {1}
    fr = rf.draw([quad, quad], **kw)
    r = rf.resolve(fr, raster=rf.RasterState(depth_func="less"), keep=fr.object_id == 1)
    assert set(fr.object_id[r.winner[r.winner >= 0]]) == {1}
    r = rf.resolve(fr, raster=rf.RasterState(depth_func="always", depth_write=False))
    assert set(fr.object_id[r.winner[r.winner >= 0]]) == {1}
    assert np.all(r.depth == 1.0)
    r = rf.resolve(fr, raster=rf.RasterState(depth_func="never"))
    assert np.all(r.winner == -1)


def test_closer_object_wins_regardless_of_order():
    s1 = trimesh.creation.icosphere(2, radius=0.5)
    s2 = trimesh.creation.icosphere(2, radius=0.5)
    s2.apply_translation([0, 0, -1.5])
    kw = dict(view=rf.look_at([0, 0, 3], [0, 0, 0]), proj=PROJ, width=32, height=24)
    a = rf.render([s1, s2], **kw)
    b = rf.render([s2, s1], **kw)
    assert np.array_equal(a.depth, b.depth)
    assert np.all(a.object_id[a.mask] == 0) and np.all(b.object_id[b.mask] == 1)


# ---------------------------------------------------------------- watertightness

@st.composite
def closed_meshes(draw):
    kind = draw(st.sampled_from(["sphere", "box", "torus", "capsule"]))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    if kind == "sphere":
        m = trimesh.creation.icosphere(int(rng.integers(0, 3)), radius=rng.uniform(0.3, 1.0))
    elif kind == "box":
        m = trimesh.creation.box(rng.uniform(0.2, 1.5, 3))
    elif kind == "torus":
        m = trimesh.creation.torus(0.7, rng.uniform(0.1, 0.3), major_sections=int(rng.integers(6, 24)),
                                   minor_sections=int(rng.integers(4, 12)))
    else:
        m = trimesh.creation.capsule(rng.uniform(0.2, 1.0), rng.uniform(0.1, 0.5))
    rot = trimesh.transformations.random_rotation_matrix(rng.uniform(size=3))
    m.apply_transform(rot)
    eye = rng.normal(size=3)
    eye = eye / np.linalg.norm(eye) * rng.uniform(3.0, 6.0)
    w, h = int(rng.integers(8, 70)), int(rng.integers(8, 70))
    persp = bool(rng.integers(0, 2))
    proj = rf.perspective(rng.uniform(30, 70), w / h, 0.5, 20) if persp else \
        rf.orthographic(-1.3, 1.3, -1.3, 1.3, 0.5, 20)
    up = [0, 1, 0] if abs(eye[1]) < 0.99 * np.linalg.norm(eye) else [1, 0, 0]
    return kind, m, rf.look_at(eye, [0, 0, 0], up), proj, w, h


@settings(max_examples=40, deadline=None)
@given(closed_meshes())
def test_watertight_closed_meshes(case):
    kind, m, view, proj, w, h = case
    fr = rf.draw(m, view=view, proj=proj, width=w, height=h)
    front = np.bincount(fr.pixel[fr.front_facing], minlength=w * h)
    back = np.bincount(fr.pixel[~fr.front_facing], minlength=w * h)
    assert np.array_equal(front, back)
    if kind in ("sphere", "box"):
        assert front.max(initial=0) <= 1


# ---------------------------------------------------------------- clipping

def test_near_plane_crossing_keeps_original_barycentrics():
    # a big floor crossing the near plane under a perspective camera
    floor = (np.array([[-5, -1, -8], [5, -1, -8], [5, -1, 4], [-5, -1, 4]], float),
             np.array([[0, 1, 2], [0, 2, 3]]))
    view = np.eye(4)
    proj = rf.perspective(60, 1.0, 0.5, 20)
    fr = rf.draw(floor, view=view, proj=proj, width=40, height=40)
    assert len(fr) > 0 and fr.bary.min() >= -1e-6
    p = fr.eye_position()
    assert np.all(-p[:, 2] >= 0.5 - 1e-4)       # nothing in front of the near plane
    # re-project each fragment's eye position: it must land on its pixel centre
    c = np.c_[p, np.ones(len(p))] @ proj.T
    xw = (c[:, 0] / c[:, 3] + 1) * 20
    yw = (c[:, 1] / c[:, 3] + 1) * 20
    assert np.abs(xw - (fr.col + 0.5)).max() < 2e-3
    assert np.abs(yw - (40 - fr.row - 0.5)).max() < 2e-3
    zw = 0.5 * c[:, 2] / c[:, 3] + 0.5
    assert np.abs(zw - fr.depth).max() < 2e-5


@pytest.mark.parametrize("far", [1e6, 1e30])
def test_huge_triangles(far):
    # one triangle covering the whole viewport with vertices far away, and a half-plane
    w, h = 20, 16
    clip = np.array([[-far, -far, 0, 1], [far, -far, 0, 1], [0, far, 0, 1]], np.float32)
    fr = rf.rasterize(clip, [[0, 1, 2]], w, h)
    assert np.array_equal(np.sort(fr.pixel), np.arange(w * h))
    half = np.array([[-far, -far, 0, 1], [0.0, -far, 0, 1], [0.0, far, 0, 1]], np.float32)
    fr = rf.rasterize(half, [[0, 1, 2]], w, h)
    # left half of the screen (x_ndc < 0 ⇒ columns 0..9) and nothing else, up to the diagonal
    # edge's slope, which at this distance is vertical within the viewport
    assert fr.col.max() == w // 2 - 1
    assert len(np.unique(fr.pixel)) == len(fr)


def test_behind_camera_and_degenerate_give_nothing():
    view = rf.look_at([0, 0, 3], [0, 0, 0])
    behind = (np.array([[0, 0, 5], [1, 0, 5], [0, 1, 5]], float), np.array([[0, 1, 2]]))
    assert len(rf.draw(behind, view=view, proj=PROJ, width=8, height=8)) == 0
    degen = (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float), np.array([[0, 1, 2], [0, 0, 0]]))
    assert len(rf.draw(degen, view=view, proj=PROJ, width=8, height=8)) == 0
    empty = (np.zeros((0, 3)), np.zeros((0, 3), int))
    fb = rf.render(empty, view=view, proj=PROJ, width=8, height=6)
    assert fb.depth.shape == (6, 8) and np.all(fb.depth == 1) and np.all(fb.prim_id == -1)
    assert np.all(np.isinf(fb.eye_depth))


def test_culling():
    m = trimesh.creation.icosphere(2)
    kw = dict(view=rf.look_at([0, 0, 3], [0, 0, 0]), proj=PROJ, width=32, height=24)
    fb = rf.draw(m, raster=rf.RasterState(cull="back"), **kw)
    assert fb.front_facing.all() and len(fb) > 0
    fb = rf.draw(m, raster=rf.RasterState(cull="front"), **kw)
    assert not fb.front_facing.any() and len(fb) > 0


# ---------------------------------------------------------------- G-buffer

def test_gbuffer_sphere_analytic():
    r = 1.0
    m = trimesh.creation.icosphere(5, radius=r)
    view = rf.look_at([0, 0, 4], [0, 0, 0])
    fb = rf.render(m, view=view, proj=PROJ, width=64, height=48, raster=rf.RasterState(normals="smooth"))
    pos = fb.eye_position()[fb.mask]
    centre = np.array([0, 0, -4.0])
    d = np.linalg.norm(pos - centre, axis=1)
    assert np.abs(d - r).max() < 2e-3
    n = fb.normal[fb.mask]
    assert np.abs(np.linalg.norm(n, axis=1) - 1).max() < 1e-5
    radial = (pos - centre) / d[:, None]
    assert np.min(np.sum(radial * n, axis=1)) > 0.999
    assert np.all(fb.front_facing[fb.mask])
    assert np.allclose(fb.eye_depth[fb.mask], -pos[:, 2], atol=1e-5)
    lin = rf.normalized_linear_depth(fb, 3.0, 5.0)
    assert lin[~fb.mask].min() == 1.0 and 0.0 <= lin[fb.mask].min() < 0.01
    uv = fb.interpolate(m.vertices[:, :2])
    assert np.allclose(uv[fb.mask], pos[:, :2], atol=2e-3)


def test_orthographic_depth_linear():
    quad = (np.array([[-1, -1, -2], [1, -1, -4], [1, 1, -4], [-1, 1, -2]], float),
            np.array([[0, 1, 2], [0, 2, 3]]))
    proj = rf.orthographic(-1, 1, -1, 1, 1, 5)
    fb = rf.render(quad, view=np.eye(4), proj=proj, width=16, height=16)
    pos = fb.eye_position()
    want = 0.5 * ((-2 * (-pos[..., 2]) + 6) / -4) + 0.5   # glOrtho: z_ndc = (-2 z_e - (f+n))/(f-n)
    want = 0.5 * ((2 * (-pos[..., 2]) - 6) / 4) + 0.5
    assert np.abs(fb.depth - want).max() < 2e-6


# ---------------------------------------------------------------- determinism

_DET_SCRIPT = r"""
import hashlib, numpy as np, trimesh, refraster as rf
m = trimesh.creation.torus(1.0, 0.3, major_sections=96, minor_sections=48)
rng = np.random.default_rng(3)
v = rng.uniform(-2, 2, (3000, 3)); f = np.arange(3000).reshape(1000, 3)
view = rf.look_at([0.5, 1.0, 4.0], [0, 0, 0]); proj = rf.perspective(50, 1.5, 0.3, 20)
h = hashlib.sha256()
fb = rf.render([m, (v, f)], view=view, proj=proj, width=333, height=222,
               raster=rf.RasterState(normals="smooth"))
for a in fb.arrays().values():
    h.update(a.tobytes())
fr = rf.draw([m, (v, f)], view=view, proj=proj, width=333, height=222)
for a in (fr.pixel, fr.depth, fr.bary, fr.prim_id, fr.object_id, fr.front_facing):
    h.update(a.tobytes())
print(h.hexdigest())
"""


def test_deterministic_across_thread_counts():
    out = outputs_by_thread_count(_DET_SCRIPT)
    assert out[0] == out[1] == out[2]


# ---------------------------------------------------------------- bad input

GOOD = dict(view=VIEW, proj=PROJ, width=8, height=8)
TRI = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))


@pytest.mark.parametrize("kwargs, exc, word", [
    (dict(view=np.full((4, 4), np.nan)), ValueError, "view"),
    (dict(proj=np.eye(3)), ValueError, "proj"),
    (dict(width=0), ValueError, "width"),
    (dict(height=-3), ValueError, "height"),
    (dict(width=10**9), ValueError, "width"),
    (dict(width=2.5), TypeError, "width"),
    (dict(model=np.full((4, 4), np.inf)), ValueError, "model"),
    (dict(raster=dict(cull="back")), TypeError, "raster must be a refraster.RasterState"),
])
def test_bad_render_arguments(kwargs, exc, word):
    with pytest.raises(exc, match=word):
        rf.render(TRI, **{**GOOD, **kwargs})


@pytest.mark.parametrize("mesh, exc, word", [
    ((np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]]), ValueError, "vertices"),
    ((np.array([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]]), ValueError, "vertices"),
    ((TRI[0], [[0, 1, 3]]), ValueError, "faces"),
    ((TRI[0], [[0, 1, -1]]), ValueError, "faces"),
    ((TRI[0], [[0.0, 1.0, 2.0]]), TypeError, "faces"),
    ((TRI[0], [[0, 1]]), ValueError, "faces"),
    ((TRI[0][:, :2], [[0, 1, 2]]), ValueError, "vertices"),
    ("mesh.obj", TypeError, "mesh"),
    (((np.array([["a", "b", "c"]]), [[0, 0, 0]])), TypeError, "vertices"),
])
def test_bad_meshes(mesh, exc, word):
    with pytest.raises(exc, match=word):
        rf.render(mesh, **GOOD)


def test_bad_rasterize_and_resolve_arguments():
    with pytest.raises(ValueError, match="clip_positions"):
        rf.rasterize(np.zeros((3, 3)), [[0, 1, 2]], 4, 4)
    with pytest.raises(ValueError, match="clip_positions"):
        rf.rasterize(np.full((3, 4), np.nan), [[0, 1, 2]], 4, 4)
    fr = rf.draw(TRI, **GOOD)
    with pytest.raises(ValueError, match="keep"):
        rf.resolve(fr, keep=np.ones(len(fr) + 1, bool))
    with pytest.raises(TypeError, match="keep"):
        rf.resolve(fr, keep=np.ones(len(fr)))
    with pytest.raises(ValueError, match="clear_depth"):
        rf.resolve(fr, raster=rf.RasterState(clear_depth=2.0))
    with pytest.raises(ValueError, match="fragment_stage"):
        rf.render(TRI, fragment_stage=lambda f: np.ones(3), **GOOD)


def test_fused_post_pass_reloads_each_winning_triangle():
    """The fused pass's post-pass loads a triangle's set-up (vertices, facing, piece, 1/area
    and 1/unsnapped area) once per run of pixels won by the same item: a scene whose winners
    change within rows, mix front and back faces and clipped pieces, and include slivers that
    snapping flipped (interpolated with the snapped edge functions and 1/snapped area), gives
    the bytes of the fragment stream + resolve (the oracle: every fragment computed alone)."""
    from refraster.raster.primitive import setup_triangles
    rng = np.random.default_rng(11)
    w, h, bits = 48, 40, 4
    n = 400
    # thin random triangles (many flip or flatten when snapped to 1/16 pixel) at random
    # depths, both orientations (window = (ndc + 1) / 2 · size)
    c = rng.uniform(-1.0, 1.0, (n, 2))
    d = rng.normal(0.0, 1.0, (n, 2))
    d /= np.linalg.norm(d, axis=1)[:, None]
    length = rng.uniform(0.1, 0.8, n)[:, None]
    thin = rng.uniform(-0.004, 0.004, n)[:, None]
    p0 = c
    p1 = c + d * length
    p2 = c + d * length * rng.uniform(0.2, 0.8, n)[:, None] + d[:, ::-1] * [1, -1] * thin
    xy = np.stack([p0, p1, p2], axis=1).reshape(-1, 2)
    z = np.repeat(rng.uniform(-0.9, 0.9, n), 3) + rng.uniform(-0.05, 0.05, 3 * n)
    # and a few large triangles reaching past the near plane (clipped pieces)
    big = rng.uniform(-3.0, 3.0, (6 * 3, 2))
    zb = rng.uniform(-1.6, 0.9, 6 * 3)
    ndc = np.concatenate([np.column_stack([xy, z]), np.column_stack([big, zb])])
    ww = rng.uniform(1.0, 4.0, len(ndc))   # perspective: 1/w differs per vertex
    clip = np.column_stack([ndc * ww[:, None], ww])
    faces = np.arange(len(clip)).reshape(-1, 3)
    st = setup_triangles(clip, faces, w, h, subpixel_bits=bits)
    assert len(st.clipped) > 0
    depth, prim, front, bary = fused(st)
    pixel, fd, _, fprim, ffront, fbary, _ = stream(st)
    frags = rf.Fragments(pixel, fd, fprim, np.zeros_like(fprim), fbary, ffront, w, h)
    res = rf.resolve(frags)
    want = np.where(res.winner >= 0, fprim[res.winner], -1)
    # the scene exercises what the set-up reuse must get right
    won = np.unique(want[want >= 0])
    won = won[won < n]   # unclipped slivers
    sx = st.vx[faces[won]].astype(np.float64)
    sy = st.vy[faces[won]].astype(np.float64)
    snapped = ((sx[:, 1] - sx[:, 0]) * (sy[:, 2] - sy[:, 0])
               - (sx[:, 2] - sx[:, 0]) * (sy[:, 1] - sy[:, 0]))
    fx = st.vxf[faces[won]].astype(np.float64)
    fy = st.vyf[faces[won]].astype(np.float64)
    unsnapped = ((fx[:, 1] - fx[:, 0]) * (fy[:, 2] - fy[:, 0])
                 - (fx[:, 2] - fx[:, 0]) * (fy[:, 1] - fy[:, 0]))
    assert np.count_nonzero(np.sign(snapped) * unsnapped <= 0) >= 2   # flipped by snapping
    assert np.any(want[:, 1:] != want[:, :-1])        # winners change within rows
    assert front.any() and (~front & (prim >= 0)).any()
    assert np.isin(st.clipped.prim, want).any()
    assert res.depth.tobytes() == depth.tobytes()
    assert np.array_equal(want, prim)
    assert np.array_equal(np.where(res.winner >= 0, ffront[res.winner], False), front)
    m = res.winner.ravel() >= 0
    assert fbary[res.winner.ravel()[m]].tobytes() == bary[m].tobytes()


def test_split_ids_is_numpys_searchsorted():
    """``Prepared.split``'s kernel (``fragments.split_ids``) gives what the NumPy expression it
    replaced gives: ``searchsorted(face_offsets[1:], g, "right")`` and ``g − face_offsets[obj]``,
    as int32, for empty draws, one draw, indices past the last face and −1 (background)."""
    from refraster.raster.fragments import split_ids
    rng = np.random.default_rng(5)
    cases = [np.array([0, 12]), np.array([0, 0, 5, 5, 9, 20]), np.array([0]),
             np.concatenate([[0], np.cumsum(rng.integers(0, 50, 40))])]
    for offs in cases:
        for g in (rng.integers(-1, int(offs[-1]) + 3, 5000), np.array([], np.int64),
                  rng.integers(-1, int(offs[-1]) + 1, (7, 9, 4))):
            obj = np.searchsorted(offs[1:], g, side="right")
            want = (obj.astype(np.int32), (g - offs[obj]).astype(np.int32))
            got = split_ids(g, offs)
            for a, b in zip(got, want):
                assert a.dtype == np.int32 and a.shape == b.shape and np.array_equal(a, b)
