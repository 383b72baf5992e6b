"""The techniques in every API's conventions (issue 39): ``render_clipped`` and ``render_cutaway``
render the same frame in OpenGL's conventions and in reversed-Z (``greater``/``gequal`` cleared
to 0, a reversed projection, an infinite far plane), zero-to-one depth and Vulkan's (upper-left
origin, NDC y down with the projection flipped, clockwise fronts of the reversed winding).

What must agree: everything decided by coverage and by the techniques' own depth comparisons
(ids, facing, masks) exactly — the x, y and w rows of the clip coordinates are the same bits in
every convention, only the depth row differs, and the scenes keep distinct surfaces far apart
in depth; window depth within the bound :func:`depth_bound` derives (after ``d → 1 − d`` under
a reversing test). A technique that left one of its comparisons in OpenGL's direction (the clip
pass's depth test, the exact caps' depth test, the cut test, the rear hulls) changes ids and
masks here.
"""

import math

import numpy as np
import pytest

import refraster as rr
from refraster import RasterState
from refraster.camera import look_at, perspective
from refraster.clipsurface import Caps, ClipSurface, render_clipped
from refraster.clipsurface import offsetmaps as om
from refraster.cutaway import Cutaway, GhostLines, render_cutaway
from refraster.ldi import peel
from refraster.scenes import cube, icosphere, nested_shells

U = 2.0 ** -24
FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])

REVERSED = dict(depth_func="greater", clear_depth=0.0)
#: name → (state, projection keywords, flip y, reverse the winding, reference convention)
CONVENTIONS = {
    "reversed_gl": (RasterState(**REVERSED), dict(reversed=True), False, False, "gl"),
    "gequal_zero_to_one": (RasterState(depth_func="gequal", clear_depth=0.0,
                                       depth_range="zero_to_one"),
                           dict(reversed=True, depth_range="zero_to_one"), False, False, "gl"),
    "lequal": (RasterState(depth_func="lequal"), {}, False, False, "gl"),
    "zero_to_one": (RasterState(depth_range="zero_to_one"), dict(depth_range="zero_to_one"),
                    False, False, "gl"),
    "reversed_infinite": (RasterState(depth_range="zero_to_one", **REVERSED),
                          dict(reversed=True, depth_range="zero_to_one", far=math.inf), False,
                          False, "gl_infinite"),
    "vulkan_cw": (RasterState(depth_range="zero_to_one", origin="upper_left", ndc_y="down",
                              front_face="cw"),
                  dict(depth_range="zero_to_one"), True, True, "gl"),
    "d3d_reversed": (RasterState(depth_range="zero_to_one", origin="upper_left", **REVERSED),
                     dict(depth_range="zero_to_one", reversed=True), False, False, "gl"),
}
REFERENCES = {"gl": (RasterState(), {}), "gl_infinite": (RasterState(), dict(far=math.inf))}


def _reversing(state):
    return state.depth_func in ("greater", "gequal")


def _winding(meshes, reverse):
    """The meshes as ``(vertices, faces)``, every face's winding reversed when asked."""
    out = []
    for m in ([meshes] if hasattr(meshes, "vertices") else meshes):
        v, f = (np.asarray(m.vertices), np.asarray(m.faces)) if hasattr(m, "vertices") else m
        out.append((v, f[:, ::-1].copy() if reverse else f))
    return out


def depth_bound(lo, hi, view, proj, state):
    """A bound on |window depth − exact| of any fragment of a face whose vertices lie in the box
    ``[lo, hi]`` (world space, in front of the near plane), as refraster computes it.

    The vertex stage rounds ``P·V`` to float32 (u relative per entry) and forms each clip
    coordinate as three float32 multiply–adds: ``|δz_c| ≤ 5u·A_z`` and ``|δw| ≤ 5u·A_w``
    with ``A = Σ_j |m_j·x_j|`` (x_3 = 1). ``z_c·(1/w)`` adds 2u relative, OpenGL's ``½·r + ½``
    halves that and rounds once more (u); so a vertex's window depth is within
    ``s·(5u·A_z + |r|·5u·A_w + 2u·|z_c|)/w + u`` of exact (``s`` = ½ under OpenGL's range, 1
    under zero-to-one). A fragment's depth is a convex combination of its face's vertex depths
    (the plane through them, evaluated in float64) rounded once to float32 (u). ``A`` is convex
    in x, so its maximum over the box is at a corner; ``w`` is linear and positive there, so its
    minimum is at a corner too; ``|r| ≤ max A_z / min w``.
    """
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    m = proj @ view
    a_z = (np.abs(corners * m[2]).sum(axis=1)).max()
    a_w = (np.abs(corners * m[3]).sum(axis=1)).max()
    w_min = (corners @ m[3]).min()
    assert w_min > 0
    s = 1.0 if state.depth_range == "zero_to_one" else 0.5
    r = a_z / w_min
    return s * (5 * U * a_z + r * 5 * U * a_w + 2 * U * a_z) / w_min + 2 * U


def _frame_projection(keywords, flip, aspect, near, far):
    k = dict(keywords)
    p = perspective(35, aspect, near, k.pop("far", far), **k)
    return FLIP_Y @ p if flip else p


def _compare(name, ref, fb, ref_state, state, bound, fields):
    """ids and masks equal, depth within ``bound`` (after d → 1 − d under a reversing test)."""
    for f in fields:
        a, b = getattr(ref, f), getattr(fb, f)
        bad = int(np.count_nonzero(a != b))
        assert bad == 0, f"{name}: {f} differs at {bad} pixels"
    d = fb.depth.astype(np.float64)
    if _reversing(state):
        d = 1.0 - d
    covered = ref.mask
    err = np.abs(d - ref.depth.astype(np.float64))[covered]
    assert covered.any()
    assert err.max() <= bound, f"{name}: depth off by {err.max():.3g} > bound {bound:.3g}"
    # the background keeps the clear depth of each frame
    assert np.all(fb.depth[~fb.mask] == np.float32(state.clear_depth))
    assert np.all(ref.depth[~ref.mask] == np.float32(ref_state.clear_depth))
    return float(err.max() / bound)


# ------------------------------------------------------------------------- clip surfaces

def _box_solid():
    import trimesh
    b = trimesh.creation.box((1.0, 1.0, 1.0))
    return np.asarray(b.vertices, np.float64), np.asarray(b.faces, np.int64)


CLIP_SURFACE = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3),
                           om.perlin_noise(16))
CLIP_VIEW = look_at([1.5, 1.2, 2.2], [0, 0, 0])
CLIP_W, CLIP_H = 80, 60
CLIP_FIELDS = ("prim_id", "object_id", "front_facing", "cap_mask", "mask")


def _clipped(state, keywords, flip, reverse, mode, sprite):
    solid = _winding([_box_solid()], reverse)[0]
    proj = _frame_projection(keywords, flip, CLIP_W / CLIP_H, 0.5, 10.0)
    return render_clipped(solid, CLIP_SURFACE, view=CLIP_VIEW, proj=proj, width=CLIP_W,
                          height=CLIP_H, raster=state, caps=Caps(mode=mode), vds=[sprite]), proj


@pytest.fixture(scope="module")
def box_sprite():
    from refraster.ldi import VolumetricDepthSprite
    return VolumetricDepthSprite.from_mesh(_box_solid(), resolution=128)


@pytest.fixture(scope="module")
def clip_references(box_sprite):
    return {(ref, mode): _clipped(st, kw, False, False, mode, box_sprite)
            for ref, (st, kw) in REFERENCES.items() for mode in ("mesh", "exact")}


@pytest.mark.parametrize("mode", ["mesh", "exact"])
@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_clip_surfaces_agree_across_conventions(name, mode, clip_references, box_sprite):
    """Solids clipped and capped (mesh caps through the fused clip pass, exact caps by rays
    and the technique's own window depth and depth test) give the same ids, facing and cap mask
    in every convention, and window depths within the derived bound."""
    state, kw, flip, reverse, ref_name = CONVENTIONS[name]
    ref, ref_proj = clip_references[(ref_name, mode)]
    fb, proj = _clipped(state, kw, flip, reverse, mode, box_sprite)
    assert ref.cap_mask.sum() > 500
    # the cap mesh reaches past the solid's box (the cells around its projection): twice the box
    lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    bound = depth_bound(lo, hi, CLIP_VIEW, ref_proj, REFERENCES[ref_name][0]) \
        + depth_bound(lo, hi, CLIP_VIEW, proj, state)
    _compare(name, ref, fb, REFERENCES[ref_name][0], state, bound, CLIP_FIELDS)
    # cap positions: interpolated with float32 barycentrics (mesh caps; under an upper-left
    # origin the unsnapped window y is H − y_w, rounded again) on a unit box: ≤ 16 float32
    # roundings of its extent; the exact caps' rays agree to float64 rounding
    atol = 16 * U if mode == "mesh" else 1e-9
    np.testing.assert_allclose(fb.cap_points, ref.cap_points, rtol=0, atol=atol)
    # shading reads positions and normals only: the same up to rounding
    assert np.abs(fb.color - ref.color).max() <= 1e-4


def test_clip_surfaces_without_caps_and_through_the_fragment_stream(box_sprite, monkeypatch):
    """The Python clip stage (the fragment stream + resolve, the path of duck-typed parity
    tests) equals the fused clip pass bit for bit under reversed-Z too."""
    import refraster.clipsurface.render as crender
    state, kw, flip, reverse, _ = CONVENTIONS["reversed_infinite"]
    fused, _ = _clipped(state, kw, flip, reverse, "mesh", box_sprite)
    monkeypatch.setattr(crender, "_USE_FUSED", False)
    streamed, _ = _clipped(state, kw, flip, reverse, "mesh", box_sprite)
    for f in ("depth", "prim_id", "object_id", "front_facing", "barycentric", "cap_mask"):
        assert np.array_equal(getattr(fused, f), getattr(streamed, f)), f


# ------------------------------------------------------------------------------ cutaway

def _cube_box(lo, hi):
    c = cube(1.0)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return (np.asarray(c.vertices) + 0.5) * (hi - lo) + lo, np.asarray(c.faces)


CORE = [icosphere(2, radius=0.3), _cube_box((0.25, -0.15, 0.1), (0.5, 0.15, 0.4))]
CRATE = [_cube_box((-0.8, -0.8, -0.8), (0.8, 0.8, 0.8))]
SHELLS = nested_shells((1.2, 1.0, 0.75, 0.6), subdivisions=2)
CUT_W, CUT_H = 96, 80
CUT_FIELDS = ("prim_id", "object_id", "front_facing", "mask", "cut_mask", "carved", "outline")
CUT_SCENES = {
    "shells": (SHELLS, (2.5, 1.2, 3.0), GhostLines()),
    "crate_lines": (CRATE, (2.5, 2.0, 3.0), GhostLines(distance=2.0)),
    "crate_visible": (CRATE, (2.5, 2.0, 3.0), GhostLines(distance=2.0, source="visible")),
}


def _cutaway(scene, state, keywords, flip, reverse):
    secondary, eye, ghosts = CUT_SCENES[scene]
    view = look_at(eye, (0, 0, 0))
    proj = _frame_projection(keywords, flip, CUT_W / CUT_H, 1.0, 12.0)
    fb = render_cutaway(_winding(CORE, reverse), _winding(secondary, reverse), view=view,
                        proj=proj, width=CUT_W, height=CUT_H, raster=state,
                        cutaway=Cutaway(angle=0.6), ghosts=ghosts)
    return fb, view, proj


@pytest.fixture(scope="module")
def cut_references():
    return {(ref, scene): _cutaway(scene, st, kw, False, False)
            for ref, (st, kw) in REFERENCES.items() for scene in CUT_SCENES}


@pytest.mark.parametrize("scene", sorted(CUT_SCENES))
@pytest.mark.parametrize("name", sorted(CONVENTIONS))
def test_cutaway_agrees_across_conventions(name, scene, cut_references):
    """The cut test (fragment depth against the cutaway surface), the rear hulls (the depth
    test opposite to the frame's), jump flooding's depths and the ghost lines' depth test give
    the same ids, cut and carved masks, outlines and ghost lines in every convention; window
    depths and the cutaway depth within the derived bound."""
    state, kw, flip, reverse, ref_name = CONVENTIONS[name]
    ref, view, ref_proj = cut_references[(ref_name, scene)]
    fb, _, proj = _cutaway(scene, state, kw, flip, reverse)
    assert ref.cut_mask.sum() > 200 and ref.carved.sum() > 500
    if scene.startswith("crate"):
        assert ref.ghost.max() > 0.2
    lo, hi = np.full(3, -1.2), np.full(3, 1.2)
    ref_state = REFERENCES[ref_name][0]
    bound = depth_bound(lo, hi, view, ref_proj, ref_state) + depth_bound(lo, hi, view, proj,
                                                                         state)
    _compare(name, ref, fb, ref_state, state, bound, CUT_FIELDS)
    # ghost opacity: eye-depth gaps from the same surfaces, up to float64 rounding
    assert np.array_equal(fb.ghost > 0, ref.ghost > 0)
    assert np.abs(fb.ghost - ref.ghost).max() <= 1e-6
    cd = fb.cutaway_depth.astype(np.float64)
    if _reversing(state):
        cd = 1.0 - cd
    assert np.abs(cd - ref.cutaway_depth).max() <= 4 * U   # float64 D, rounded once
    assert np.abs(fb.image - ref.image).max() <= 1e-4


# --------------------------------------------------------------------------- peeling

def test_peel_under_greater_is_the_float64_front_to_back_order():
    """Outside the pipeline: tilted planes crossing each other, peeled under reversed-Z with an
    infinite far plane; at every pixel whose planes are apart in depth by more than 1e-4 (eye
    units), the layers' object ids are the planes sorted by their float64 ray distance, nearest
    first."""
    rng = np.random.default_rng(7)
    w = h = 48
    view = look_at((0, 0, 0), (0, 0, -1))
    proj = perspective(50, 1.0, 0.5, math.inf, reversed=True, depth_range="zero_to_one")
    state = RasterState(depth_range="zero_to_one", **REVERSED)
    planes = []
    for k in range(5):
        z0 = -2.0 - 0.7 * k + rng.uniform(-0.3, 0.3)
        sx, sy = rng.uniform(-0.4, 0.4, 2)
        xy = np.array([[-3, -3], [3, -3], [3, 3], [-3, 3]], float)
        v = np.c_[xy, z0 + sx * xy[:, 0] + sy * xy[:, 1]]
        planes.append((v, np.array([[0, 1, 2], [0, 2, 3]]), (z0, sx, sy)))
    order = rng.permutation(len(planes))    # drawn in a random order
    lay = peel([planes[i][:2] for i in order], view=view, proj=proj, width=w, height=h,
               raster=state)
    # the float64 oracle: the ray through each pixel centre meets plane z = z0 + sx·x + sy·y
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    t = 1.0 / proj[1, 1]
    dx, dy = (2 * cols / w - 1) * t, (1 - 2 * rows / h) * t
    dist = np.stack([-z0 / (1 + sx * dx + sy * dy) for _, _, (z0, sx, sy) in planes])
    expect = np.argsort(dist, axis=0)
    gaps = np.diff(np.sort(dist, axis=0), axis=0).min(axis=0)
    clear = gaps > 1e-4
    assert clear.mean() > 0.9 and lay.depth.shape[0] == len(planes)
    got = order[lay.object_id]          # draw call → plane index
    assert np.array_equal(got[:, clear], expect[:, clear])
    assert np.all(np.diff(lay.depth, axis=0)[:, clear] < 0)   # depth descends front to back


# --------------------------------------------------------------------------- refusals

@pytest.mark.parametrize("fields, message", [
    (dict(depth_func="always"), "raster.depth_func must be one of less, lequal, greater, gequal"),
    (dict(depth_func="equal"), "raster.depth_func must be one of less, lequal, greater, gequal"),
    (dict(depth_func="notequal"), "raster.depth_func must be one of less"),
    (dict(depth_func="never"), "raster.depth_func must be one of less"),
    (dict(depth_func="greater"), "raster.clear_depth must be 0.0 under depth_func='greater'"),
    (dict(depth_func="less", clear_depth=0.5), "raster.clear_depth must be 1.0 under "
                                               "depth_func='less'"),
    (dict(depth_write=False), "raster.depth_write must be True"),
])
def test_directionless_states_are_refused_in_one_line(fields, message):
    state = RasterState(**fields)
    kw = dict(view=CLIP_VIEW, proj=perspective(35, 4 / 3, 0.5, 10), width=16, height=12)
    for call in (lambda: render_clipped(_box_solid(), CLIP_SURFACE, **kw, raster=state,
                                        caps=None),
                 lambda: render_cutaway(CORE, SHELLS, **kw, raster=state)):
        with pytest.raises(ValueError) as err:
            call()
        assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_exact_caps_refuse_depth_clamp():
    kw = dict(view=CLIP_VIEW, proj=perspective(35, 4 / 3, 0.5, 10), width=16, height=12)
    with pytest.raises(ValueError, match="^raster.depth_clamp must be False for "
                                         "caps.mode='exact'"):
        render_clipped(_box_solid(), CLIP_SURFACE, **kw, raster=RasterState(depth_clamp=True),
                       caps=Caps(mode="exact"))


# ----------------------------------------------------------------------- planar mirror

MIRROR_W, MIRROR_H = 96, 72


def _mirrored(state, keywords, flip, reverse):
    import trimesh
    from refraster.edges import npr
    torus = trimesh.creation.torus(0.6, 0.22, major_sections=32, minor_sections=12)
    model = np.eye(4)
    model[:3, :3] = trimesh.transformations.rotation_matrix(1.1, [1, 0, 0])[:3, :3]
    model[1, 3] = 0.9
    floor = (np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2.0]]),
             np.array([[0, 2, 1], [0, 3, 2]]))
    # the mirror's winding reversed under cw (its front by the state's front face); the
    # torus keeps its own, whose smooth normals follow its winding
    torus = _winding([torus], False)[0]
    floor = _winding([floor], reverse)[0] + (np.tile([0.0, 1.0, 0.0], (4, 1)),)  # own normals
    view = look_at((2.2, 1.6, 3.0), (0.0, 0.5, 0.0))
    proj = _frame_projection(keywords, flip, MIRROR_W / MIRROR_H, 0.5, 20.0)
    return npr.render_mirrored(torus, floor, view=view, proj=proj, width=MIRROR_W,
                               height=MIRROR_H, models=[model],
                               raster=state.replace(normals="smooth"))


@pytest.mark.parametrize("name", ["reversed_infinite", "vulkan_cw", "d3d_reversed"])
def test_mirror_agrees_across_conventions(name):
    """render_mirrored: both passes in the state's conventions, the mirror's front by the
    state's front face; the mirror mask, both passes' ids and the picture agree (the edge
    maps are found from eye depth, which is interpolated, not window depth). Under ``cw`` the
    torus keeps its winding, so its fragments' facing is the reference's turned."""
    state, kw, flip, reverse, ref_name = CONVENTIONS[name]
    ref = _mirrored(REFERENCES[ref_name][0], REFERENCES[ref_name][1], False, False)
    got = _mirrored(state, kw, flip, reverse)
    assert ref.mirror_mask.sum() > 500 and ref.mirrored.mask.sum() > 300
    assert np.array_equal(got.mirror_mask, ref.mirror_mask)
    for part in ("scene", "mirrored"):
        for f in ("prim_id", "object_id", "front_facing", "mask"):
            want = getattr(getattr(ref, part), f)
            if f == "front_facing" and state.front_face == "cw":
                want = want != (getattr(ref, part).object_id == 0)   # the torus's pixels
            assert np.array_equal(getattr(getattr(got, part), f), want), (part, f)
    assert np.abs(got.image - ref.image).max() <= 1e-3
