"""The cutaway surface and cutaway rendering (refraster.cutaway.surface / .render): MATH.md §4."""

import numpy as np
import pytest

import refraster as rr
from refraster.cutaway import (CutSurfaces, Cutaway, GhostLines, cut_surface_normals,
                               cutaway_surface, ghost_lines, outline, render_cutaway,
                               upsample_bilinear)
from refraster.cutaway.surface import ndc_to_eye_depth, pixel_ndc, unproject
from refraster.scenes import cube, icosphere, nested_shells


def box(lo, hi):
    c = cube(1.0)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return (np.asarray(c.vertices) + 0.5) * (hi - lo) + lo, np.asarray(c.faces)


def single_seed(depth, size=65):
    rear = np.zeros((size, size))
    oid = np.full((size, size), -1)
    rear[size // 2, size // 2] = depth
    oid[size // 2, size // 2] = 0
    return rear, oid


def cone_angles(d, proj):
    """Half-angle of the cone through each pixel of D, apex at the centre pixel (eye space)."""
    h, w = d.shape
    x, y = pixel_ndc(h, w)
    pos = unproject(x, y, d, proj)
    apex = pos[h // 2, w // 2]
    r = np.hypot(pos[..., 0] - apex[0], pos[..., 1] - apex[1])
    on = (d > -1 + 1e-9) & (r > 0)
    return np.arctan2(r[on], pos[..., 2][on] - apex[2]), on


# ----------------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("theta", [0.2, 0.6, 1.2])
def test_orthographic_cone_half_angle(theta):
    proj = rr.orthographic(-2, 2, -1.5, 1.5, 1, 10)  # non-square pixels on a 65² buffer
    d = cutaway_surface(*single_seed(0.7), proj=proj, angle=theta, edge_compression=None)
    angles, on = cone_angles(d, proj)
    assert on.sum() > 100
    assert np.abs(angles - theta).max() < 1e-3


@pytest.mark.parametrize("theta", [0.3, 0.8])
def test_perspective_on_axis_seed_with_compensation(theta):
    proj = rr.perspective(50, 1.0, 1.0, 10.0)
    rear, oid = single_seed(0.95)
    d = cutaway_surface(rear, oid, proj=proj, angle=theta, edge_compression=None)
    angles, on = cone_angles(d, proj)
    assert on.sum() > 100
    assert np.abs(angles - theta).max() < 1e-3
    d = cutaway_surface(rear, oid, proj=proj, angle=theta, edge_compression=None,
                        perspective_compensation=False)
    angles, _ = cone_angles(d, proj)
    assert np.abs(angles - theta).max() > 0.05  # the uncompensated surface is off


@pytest.mark.parametrize("theta", [0.3, 0.8, 1.2])
def test_uncompensated_surface_is_the_papers_ndc_cone(theta):
    """The paper's basic surface (Sec. 3.2; ``perspective_compensation=False``), checked from
    its definition rather than from the slope formula: a cone of half-angle θ about the view
    axis in NDC, z_ndc against (x_ndc, y_ndc). With one seed at NDC (x_s, y_s, z_s) and a square
    viewport, D = z_s − cot θ·‖(x, y) − (x_s, y_s)‖, i.e. the angle between the cone and the
    axis, atan2(‖Δxy‖, z_s − D), is θ at every pixel the cone reaches above the near plane.
    (A tan-based slope gives π/2 − θ; the existing check only says that the cone is off θ in
    eye space, which both are.)"""
    proj = rr.perspective(50, 1.0, 1.0, 10.0)
    rear, oid = single_seed(0.95)
    d = cutaway_surface(rear, oid, proj=proj, angle=theta, edge_compression=None,
                        perspective_compensation=False)
    h, w = d.shape
    x, y = np.broadcast_arrays(*pixel_ndc(h, w))
    r = np.hypot(x - x[h // 2, w // 2], y - y[h // 2, w // 2])
    z_s = 2.0 * 0.95 - 1.0
    on = (d > -1.0 + 1e-9) & (r > 0)
    assert on.sum() > 50
    assert d[h // 2, w // 2] == pytest.approx(z_s, abs=1e-12)
    angles = np.arctan2(r[on], z_s - d[on])
    np.testing.assert_allclose(angles, theta, rtol=0, atol=1e-9)


def test_no_object_gives_near_plane():
    rear = np.zeros((8, 9))
    d = cutaway_surface(rear, np.full((8, 9), -1), proj=rr.perspective(40, 1, 1, 5))
    assert np.all(d == -1.0)


def test_edge_compression_narrows_near_the_border():
    proj = rr.orthographic(-1, 1, -1, 1, 1, 10)
    rear = np.zeros((40, 40))
    oid = np.full((40, 40), -1)
    rear[20, 1], oid[20, 1] = 0.6, 0   # near the left edge
    wide = cutaway_surface(rear, oid, proj=proj, angle=0.8, edge_compression=None)
    narrow = cutaway_surface(rear, oid, proj=proj, angle=0.8, edge_compression=0.1)
    assert narrow[20, 1] == wide[20, 1]
    assert np.all(narrow <= wide) and (narrow < wide).sum() > 10


def test_per_object_angles():
    proj = rr.orthographic(-1, 1, -1, 1, 1, 10)
    rear = np.zeros((33, 66))
    oid = np.full((33, 66), -1)
    rear[16, 16], oid[16, 16] = 0.5, 0
    rear[16, 49], oid[16, 49] = 0.5, 1
    d = cutaway_surface(rear, oid, proj=proj, angle=[0.3, 1.0], edge_compression=None)
    # at equal distance from its own seed, the wider angle's surface is higher (less negative)
    assert d[16, 49 + 6] > d[16, 16 + 6]


def test_upsample_bilinear_matches_skimage(oracle):
    transform = oracle("skimage.transform")
    rng = np.random.default_rng(0)
    a = rng.random((7, 9))
    ours = upsample_bilinear(a, 20, 31)
    ref = transform.resize(a, (20, 31), order=1, mode="edge", anti_aliasing=False)
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_array_equal(upsample_bilinear(a, 7, 9), a)


def test_ndc_eye_depth_round_trip():
    for proj in (rr.perspective(40, 1.3, 0.5, 20), rr.orthographic(-1, 1, -1, 1, 0.5, 20)):
        z = np.linspace(-1, 1, 11)
        d = ndc_to_eye_depth(z, proj)
        assert d[0] == pytest.approx(0.5) and d[-1] == pytest.approx(20)
        clip = proj @ np.stack([np.zeros_like(d), np.zeros_like(d), -d, np.ones_like(d)])
        np.testing.assert_allclose(clip[2] / clip[3], z, atol=1e-12)


# --------------------------------------------------------------------------- image-space effects


def test_outline_of_a_square():
    m = np.zeros((7, 7), bool)
    m[1:6, 1:6] = True
    ring = m.copy()
    ring[2:5, 2:5] = False
    np.testing.assert_array_equal(outline(m), ring)


def test_cut_normals_of_a_plane():
    proj = rr.orthographic(-1, 1, -1, 1, 1, 10)
    n = cut_surface_normals(np.full((5, 6), 0.3), proj)
    np.testing.assert_allclose(n, np.broadcast_to([0, 0, 1], n.shape), atol=1e-12)
    # a ramp rising to the right (depth decreasing with x) tilts the normal to −x… toward +x eye
    x, _ = pixel_ndc(5, 6)
    n = cut_surface_normals(-0.2 * x, proj)
    assert np.all(n[..., 0] < 0) and np.all(n[..., 2] > 0)


def test_ghost_lines_by_hand():
    proj = rr.orthographic(-1, 1, -1, 1, 0.0, 2.0)  # eye depth = z_ndc + 1
    edges = np.ones((1, 4))
    line_depth = np.full((1, 4), 0.25)               # z_ndc = −0.5, eye depth 0.5
    cut = np.array([[-0.5, -0.3, -0.1, 0.9]])        # eye depths 0.5, 0.7, 0.9, 1.9
    alpha = ghost_lines(edges, line_depth, cut, np.ones((1, 4)), proj, g_max=0.4)
    np.testing.assert_allclose(alpha, [[0.0, 0.5, 0.0, 0.0]], atol=1e-6)


# ------------------------------------------------------------------------------- rendering


SHELLS = nested_shells((1.2, 1.0, 0.75, 0.6), subdivisions=2)
CORE = [icosphere(2, radius=0.3), box((0.25, -0.15, 0.1), (0.5, 0.15, 0.4))]


def _camera(eye, size=(96, 80)):
    w, h = size
    return dict(view=rr.look_at(eye, (0, 0, 0)), proj=rr.perspective(40, w / h, 1.0, 12.0),
                width=w, height=h)


@pytest.mark.parametrize("eye", [(2.5, 1.2, 3.0), (-3.2, 0.4, 1.5)])
def test_visibility_of_the_objects_of_interest(eye):
    cam = _camera(eye)
    alone = rr.render(CORE, **cam).mask
    undilated = CutSurfaces(dilation=False)
    full = render_cutaway(CORE, SHELLS, **cam, cutaway=Cutaway(angle=0.5),
                          cut_surfaces=undilated)
    shown = full.object_id >= 1
    assert np.all(shown[alone])
    half = render_cutaway(CORE, SHELLS, **cam, cut_surfaces=undilated, cutaway=Cutaway(
        angle=0.5, buffer_size=(cam["width"] // 2, cam["height"] // 2)))
    assert np.mean((half.object_id >= 1)[alone]) >= 0.99
    assert full.cut_mask.sum() > 50 and full.outline.sum() > 20


def test_no_object_of_interest_cuts_nothing():
    cam = _camera((2.5, 1.2, 3.0))
    r = render_cutaway([], SHELLS, **cam)
    plain = rr.render(SHELLS, **cam)
    assert not r.carved.any() and not r.cut_mask.any() and np.all(r.cutaway_depth == 0)
    np.testing.assert_array_equal(r.color, plain.color)
    np.testing.assert_array_equal(r.depth, plain.depth)


def test_stand_in_is_not_drawn_but_cuts():
    cam = _camera((2.5, 1.2, 3.0))
    r = render_cutaway([], SHELLS, **cam, stand_ins=[icosphere(1, radius=0.3)])
    assert r.carved.sum() > 100
    assert np.all(r.object_id <= 0)  # only the shells are drawn


def test_floor_constraint():
    floor = box((-4, -0.2, -4), (4, 0, 4))
    obj = box((-0.5, 0, -0.5), (0.5, 1, 0.5))
    cam = dict(view=rr.look_at((0, 4, 5), (0, 0.3, 0)), proj=rr.perspective(45, 1, 1, 20),
               width=96, height=96)
    without = render_cutaway(obj, floor, **cam, cutaway=Cutaway(angle=1.0))
    with_floor = render_cutaway(obj, floor, **cam,
                                cutaway=Cutaway(angle=1.0, floor_normal=(0, 1, 0)))
    rows = np.nonzero(rr.render(obj, **cam).mask.any(axis=1))[0]
    front = np.zeros((96, 96), bool)
    front[rows.max() + 1:] = True     # below the box on screen: the floor in front of it
    assert (without.carved & front).sum() > 100
    assert not (with_floor.carved & front).any()


def test_ghost_lines_appear_in_the_carved_region():
    cam = _camera((2.5, 2.0, 3.0))
    crate = box((-0.8, -0.8, -0.8), (0.8, 0.8, 0.8))  # its front corner's edges get carved
    r = render_cutaway(CORE, crate, **cam, cutaway=Cutaway(angle=0.6),
                       ghosts=GhostLines(distance=2.0))
    assert r.ghost.max() > 0.2
    # a line's pixel chord may reach in front of D off the pixel centre: within 1 px of carving
    near = r.carved.copy()
    near[1:] |= r.carved[:-1]
    near[:-1] |= r.carved[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    assert np.all(r.ghost[~near] == 0)
    off = render_cutaway(CORE, crate, **cam, cutaway=Cutaway(angle=0.6), ghosts=None)
    assert not off.ghost.any()


def test_render_is_deterministic():
    cam = _camera((2.5, 1.2, 3.0))
    a = render_cutaway(CORE, SHELLS, **cam, cutaway=Cutaway(floor_normal=(0, 1, 0)))
    b = render_cutaway(CORE, SHELLS, **cam, cutaway=Cutaway(floor_normal=(0, 1, 0)))
    for name in ("image", "cutaway_depth", "cut_mask", "ghost", "normal", "depth"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


# ------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("angle", [-0.1, 0.0, np.pi / 2, np.inf, np.nan, [0.3, -1.0]])
def test_bad_angles(angle):
    with pytest.raises(ValueError, match=r"^cutaway\.angle must"):
        Cutaway(angle=angle)


def test_bad_render_arguments():
    cam = _camera((2, 1, 3), (16, 16))
    with pytest.raises(ValueError, match=r"^cutaway\.angle has 3 entries"):
        render_cutaway(CORE, SHELLS, **cam, cutaway=Cutaway(angle=[0.3, 0.4, 0.5]))
    with pytest.raises(TypeError, match=r"^cutaway must be a refraster\.cutaway\.Cutaway"):
        render_cutaway(CORE, SHELLS, **cam, cutaway=dict(angle=0.5))
    with pytest.raises(TypeError, match=r"^cut_surfaces must be"):
        render_cutaway(CORE, SHELLS, **cam, cut_surfaces=True)
    with pytest.raises(TypeError, match=r"^ghosts must be a refraster\.cutaway\.GhostLines "
                                        r"\(or None\)"):
        render_cutaway(CORE, SHELLS, **cam, ghosts=0.5)
    with pytest.raises(ValueError, match="nothing to draw"):
        render_cutaway([], [], **cam)
    bad = dict(cam, proj=np.eye(4) * 2)
    with pytest.raises(ValueError, match="proj"):
        render_cutaway(CORE, SHELLS, **bad)
    with pytest.raises(ValueError, match="vertices"):
        render_cutaway((np.full((3, 3), np.nan), [[0, 1, 2]]), SHELLS, **cam)


def test_bad_surface_arguments():
    proj = rr.perspective(40, 1, 1, 5)
    rear, oid = single_seed(0.5, 9)
    with pytest.raises(ValueError, match="rear_depth"):
        cutaway_surface(np.full((9, 9), np.nan), oid, proj=proj)
    with pytest.raises(ValueError, match="object_id"):
        cutaway_surface(rear, oid[:-1], proj=proj)
    with pytest.raises(TypeError, match="object_id"):
        cutaway_surface(rear, oid.astype(float), proj=proj)
    with pytest.raises(ValueError, match="rear_depth"):
        cutaway_surface(rear * 3, oid, proj=proj)
    with pytest.raises(ValueError, match="view"):
        cutaway_surface(rear, oid, proj=proj, floor_normal=(0, 1, 0))
    with pytest.raises(ValueError, match="floor_normal"):
        cutaway_surface(rear, oid, proj=proj, view=np.eye(4), floor_normal=(0, 0, 0))
    with pytest.raises(ValueError, match="edge_compression"):
        cutaway_surface(rear, oid, proj=proj, edge_compression=-0.1)


def test_gallery_quick(tmp_path):
    from refraster.gallery import cutaway
    items = cutaway.render(tmp_path, quick=True)
    assert len(items) == 13          # the last: the 4x picture (refraster.gallery.multisample)
    for item in items:
        assert item.section == "Adaptive cutaways" and (tmp_path / item.filename).stat().st_size
