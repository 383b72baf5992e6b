"""User cap textures (Trapp & Döllner Sec. 4.1, Fig. 10 insets), solid 3D textures (Fig. 11)
and 1D offset maps (Sec. 4.3), against analytic answers and scipy's interpolator.

The set-up: the box [−1, 1]³ cut by the plane z = 0 (N = +z keeps z > 0), seen head-on from
z = −4 by a camera whose pixel centres land on the plane at x, y = −1.25 + (i + ½)/32. With
U = (2, 0, 0), V = (0, 2, 0), O = (−1, −1, 0) and a 64² texture (one texel = 1/32), every
pixel centre falls on a texel centre: the cap shows whole texels, and the texel a pixel shows
follows from the pixel alone (the analytic (s, t) of the ray–plane intersection).
"""

import numpy as np
import pytest
from scipy import ndimage

from refraster.camera import look_at, perspective
from refraster.clipsurface import Caps, ClipSurface, render_clipped
from refraster.clipsurface import capping
from refraster.clipsurface import offsetmaps as om
from refraster.clipsurface.textures import (CapTextures, SolidTexture, as_texture,
                                            sample_texture, sample_volume)
from refraster.mesh import Mesh

N_PX = 80          # pixels across; the plane z = 0 spans 2.5 world units of them
TEX = 64           # texels across the box's face (2 world units)


def box(lo=-1.0, hi=1.0):
    import trimesh
    b = trimesh.creation.box(extents=[hi - lo] * 3)
    return Mesh(np.asarray(b.vertices, float) + (lo + hi) / 2, np.asarray(b.faces, np.int64))


def camera():
    view = look_at([0.0, 0.0, -4.0], [0.0, 0.0, 0.0])
    fovy = 2.0 * np.degrees(np.arctan(1.25 / 4.0))
    return dict(view=view, proj=perspective(fovy, 1.0, 1.0, 10.0), width=N_PX, height=N_PX)


def plane(textures=None, scale=(1.0, 1.0, 0.0), wrap="repeat", offset_map=None):
    return ClipSurface([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], scale,
                       om.constant(4, 0.0) if offset_map is None else offset_map, wrap=wrap,
                       textures=textures)


def analytic_hits(cam):
    """Per pixel, the world point where its centre's ray meets z = 0 (independent of the
    renderer: the inverse of proj·view applied to the pixel centre's near and far points)."""
    inv = np.linalg.inv(cam["proj"] @ cam["view"])
    rows, cols = np.mgrid[0:N_PX, 0:N_PX]
    x = (cols + 0.5) / N_PX * 2 - 1
    y = 1 - (rows + 0.5) / N_PX * 2          # row 0 at the top
    pts = []
    for z in (-1.0, 1.0):
        h = np.stack([x, y, np.full_like(x, z), np.ones_like(x)], -1) @ inv.T
        pts.append(h[..., :3] / h[..., 3:])
    a, b = pts
    tau = -a[..., 2] / (b[..., 2] - a[..., 2])
    return a + tau[..., None] * (b - a)


def head_on_shade(cam, points):
    """0.25 + 0.75·|n·p̂| of the flat cap (n = −N) at world points: the light term the cap
    lighting uses with light = 1."""
    eye = points @ cam["view"][:3, :3].T + cam["view"][:3, 3]
    n = cam["view"][:3, :3] @ np.array([0.0, 0.0, -1.0])
    return 0.25 + 0.75 * np.abs(eye @ n) / np.linalg.norm(eye, axis=-1)


def coded_texture(h=TEX, w=TEX):
    """Texel (row, col) → (col/(w−1), row/(h−1), ((row·7 + col·3) mod 5)/4): every texel
    tells its row and column, neighbours differ by ≥ 1/63."""
    r, c = np.mgrid[0:h, 0:w]
    return np.stack([c / (w - 1), r / (h - 1), ((r * 7 + c * 3) % 5) / 4.0], -1)


def st_of(points, scale=(1.0, 1.0)):
    return np.stack([(points[..., 0] + 1) / 2 * scale[0], (points[..., 1] + 1) / 2 * scale[1]],
                    -1)


def texel_check(fb, cam, tex):
    """Max |colour − texel(analytic s, t)·shade| over cap pixels."""
    hits = analytic_hits(cam)
    st = st_of(hits)
    col = np.floor(st[..., 0] * TEX).astype(int)
    row = np.floor(st[..., 1] * TEX).astype(int)
    m = fb.cap_mask
    assert m.sum() > 0.6 * TEX * TEX
    assert np.all((col[m] >= 0) & (col[m] < TEX) & (row[m] >= 0) & (row[m] < TEX))
    expected = tex[row[m], col[m]] * head_on_shade(cam, hits[m])[:, None]
    return float(np.abs(fb.color[m] - expected).max())


@pytest.mark.parametrize("mode", ["mesh", "exact"])
def test_pixel_centres_on_texel_centres_show_whole_texels(mode):
    cam = camera()
    hits = analytic_hits(cam)
    st = st_of(hits)
    inside = np.all((st > 0) & (st < 1), -1)
    # the set-up really puts the centres on texel centres
    assert np.abs(st[inside] * TEX - 0.5 - np.round(st[inside] * TEX - 0.5)).max() < 1e-12
    tex = coded_texture()
    fb = render_clipped(box(), plane(CapTextures(diffuse=tex)), **cam,
                        caps=Caps(mode=mode, vds_resolution=64, color=(0.0, 0.0, 0.0)))
    assert texel_check(fb, cam, tex) < 2e-4


def test_planted_faults_in_the_texture_lookup_fail(monkeypatch):
    """Swapped s and t, and a lookup without the half-texel shift, both miss the texels."""
    cam = camera()
    tex = coded_texture()
    orig = capping.sample_texture
    faults = {
        "swapped s/t": lambda t, st, wrap: orig(t, st[:, ::-1], wrap=wrap),
        "off by half a texel": lambda t, st, wrap: orig(t, st + 0.5 / np.array(t.shape[1::-1]),
                                                        wrap=wrap),
    }
    for name, fault in faults.items():
        with monkeypatch.context() as m:
            m.setattr(capping, "sample_texture", fault)
            fb = render_clipped(box(), plane(CapTextures(diffuse=tex)), **cam,
                                caps=Caps(vds_resolution=64))
        assert texel_check(fb, cam, tex) > 5e-3, name


@pytest.mark.parametrize("wrap,mode", [("repeat", "grid-wrap"), ("clamp_to_edge", "nearest"),
                                       ("mirrored_repeat", "reflect")])
def test_wrap_modes_against_scipy(wrap, mode):
    """O = 0, Sx = Sy = 2.5 and a 4×5 texture: s, t run over [−1.25, 1.25], both sides of the
    texture's edges; scipy's order-1 map_coordinates (grid-wrap / nearest / reflect) is the
    oracle."""
    cam = camera()
    tex = np.random.default_rng(3).random((4, 5, 3))
    scale = (2.5, 2.5, 0.0)
    fb = render_clipped(box(), centred_surface(scale, wrap, tex), **cam,
                        caps=Caps(mode="exact", vds_resolution=64))
    m = fb.cap_mask
    assert m.sum() > 0.6 * TEX * TEX
    hits = analytic_hits(cam)[m]
    st = hits[:, :2] / 2.0 * 2.5
    assert st.min() < -1.0 and st.max() > 1.0
    coords = [st[:, 1] * 4 - 0.5, st[:, 0] * 5 - 0.5]
    expected = np.stack([ndimage.map_coordinates(tex[..., c], coords, order=1, mode=mode)
                         for c in range(3)], -1) * head_on_shade(cam, hits)[:, None]
    assert np.abs(fb.color[m] - expected).max() < 1e-6
    # the three modes really differ on this cap: a wrong mode fails the same check
    for other in ("repeat", "clamp_to_edge", "mirrored_repeat"):
        if other != wrap:
            f2 = render_clipped(box(), centred_surface(scale, other, tex), **cam,
                                caps=Caps(mode="exact", vds_resolution=64))
            assert np.abs(f2.color[m] - expected).max() > 0.05


def centred_surface(scale, wrap, tex):
    return ClipSurface([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], scale,
                       om.constant(4, 0.0), wrap=wrap, textures=CapTextures(diffuse=tex))


def test_multichannel_sampler_against_scipy_and_the_offset_map_sampler():
    rng = np.random.default_rng(0)
    tex = rng.random((7, 5, 3))
    st = rng.uniform(-2, 3, (500, 2))
    for wrap, mode in [("repeat", "grid-wrap"), ("clamp_to_edge", "nearest"),
                       ("mirrored_repeat", "reflect")]:
        got = sample_texture(tex, st, wrap=wrap)
        coords = [st[:, 1] * 7 - 0.5, st[:, 0] * 5 - 0.5]
        ref = np.stack([ndimage.map_coordinates(tex[..., c], coords, order=1, mode=mode)
                        for c in range(3)], -1)
        assert np.abs(got - ref).max() < 1e-12
        for c in range(3):   # channel by channel it is the offset map's sampler, bit for bit
            assert np.array_equal(got[:, c], om.sample(tex[..., c], st, wrap=wrap))


def test_volume_sampler_against_scipy():
    rng = np.random.default_rng(1)
    vol = rng.random((4, 6, 5, 3))
    p = rng.uniform(-1.5, 2.5, (400, 3))
    for wrap, mode in [("repeat", "grid-wrap"), ("clamp_to_edge", "nearest"),
                       ("mirrored_repeat", "reflect")]:
        got = sample_volume(vol, p, wrap=wrap)
        coords = [p[:, 2] * 4 - 0.5, p[:, 1] * 6 - 0.5, p[:, 0] * 5 - 0.5]
        ref = np.stack([ndimage.map_coordinates(vol[..., c], coords, order=1, mode=mode)
                        for c in range(3)], -1)
        assert np.abs(got - ref).max() < 1e-12
    # a swapped axis order is caught
    bad = sample_volume(np.ascontiguousarray(np.swapaxes(vol, 0, 2)), p)
    assert np.abs(bad - sample_volume(vol, p)).max() > 0.1


def test_user_normal_and_light_maps_replace_the_derived_ones():
    cam = camera()
    theta = 0.5
    enc = np.array([0.5 + 0.5 * np.sin(theta), 0.5, 0.5 + 0.5 * np.cos(theta)])
    normal = np.broadcast_to(enc, (3, 3, 3)).copy()
    light = np.full((2, 2), 0.5)
    fb = render_clipped(box(), plane(CapTextures(normal=normal, light=light)), **cam,
                        caps=Caps(color=(1.0, 1.0, 1.0), mode="exact", vds_resolution=64))
    m = fb.cap_mask
    # (sin θ, 0, cos θ) along (Û, V̂, −N) = (x, y, −z): world (sin θ, 0, −cos θ)
    n_eye = cam["view"][:3, :3] @ np.array([np.sin(theta), 0.0, -np.cos(theta)])
    assert np.abs(fb.normal[m] - n_eye).max() < 1e-7          # float32 buffer
    hits = analytic_hits(cam)[m]
    eye = hits @ cam["view"][:3, :3].T + cam["view"][:3, 3]
    shade = 0.5 * (0.25 + 0.75 * np.abs(eye @ n_eye) / np.linalg.norm(eye, axis=1))
    assert np.abs(fb.color[m] - shade[:, None]).max() < 1e-6


def wedge_surfaces(textures=None):
    """Two planes: x = 0.2 (N = +x: removes x < 0.2) and y = −0.1 (N = −y: removes
    y > −0.1). What stays, x > 0.2 and y < −0.1, shows both caps meeting in an inner corner
    along x = 0.2, y = −0.1."""
    a = ClipSurface([0.2, -1.0, -1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0], (1.0, 1.0, 0.0),
                    om.constant(4, 0.0), textures=textures)        # N = y × z = +x
    b = ClipSurface([-1.0, -0.1, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0], (1.0, 1.0, 0.0),
                    om.constant(4, 0.0), textures=textures)        # N = x × z = −y
    return [a, b]


def smooth_volume(n=16):
    """A periodic, smooth volume (so its repeat wrap adds no jump)."""
    k, j, i = np.mgrid[0:n, 0:n, 0:n] * (2 * np.pi / n)
    return np.stack([0.5 + 0.5 * np.sin(i + j), 0.5 + 0.5 * np.cos(2 * k - j),
                     0.5 + 0.5 * np.sin(i + j + k)], -1)


def wedge_camera(w=120):
    view = look_at([-2.5, 2.8, -3.2], [0.1, -0.2, 0.0])
    return dict(view=view, proj=perspective(40.0, 1.0, 0.5, 20.0), width=w, height=w)


def seam_jump(fb, base):
    """Largest |Δ base colour| / |Δ position| over 4-neighbour pixel pairs across the seam
    between the caps of surface 0 and surface 1."""
    pos = fb.cap_position
    k = np.where(fb.cap_mask, (fb.object_id - fb.n_solids) % fb.n_surfaces, -1)
    worst = 0.0
    pairs = 0
    for axis in (0, 1):
        a = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        b = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        across = (k[a] >= 0) & (k[b] >= 0) & (k[a] != k[b])
        if across.any():
            d = np.linalg.norm(pos[a][across] - pos[b][across], axis=-1)
            dc = np.abs(base[a][across] - base[b][across]).max(-1)
            worst = max(worst, float((dc / np.maximum(d, 1e-9)).max()))
            pairs += int(across.sum())
    assert pairs > 20
    return worst


def test_solid_texture_in_object_space_and_continuous_across_two_caps():
    cam = wedge_camera()
    vol = smooth_volume()
    shift = np.eye(4)
    shift[:3, 3] = [0.15, -0.05, 0.1]
    inv = np.linalg.inv(shift)
    solid = box()
    surfaces = wedge_surfaces()
    fb = render_clipped(solid, surfaces, **cam, model=shift,
                        caps=Caps(style="solid", solid_texture=vol, vds_resolution=96))
    m = fb.cap_mask
    k = (fb.object_id[m] - 1) % 2
    assert (k == 0).sum() > 200 and (k == 1).sum() > 200
    pts = fb.cap_points
    local = pts @ inv[:3, :3].T + inv[:3, 3]
    # the texture spans the solid's object-space box [−1, 1]³ once
    expected = sample_volume(vol, (local + 1.0) / 2.0)
    shade = wedge_shade(fb, cam)
    assert np.abs(fb.color[m] - expected * shade[:, None]).max() < 1e-6
    # world instead of object space (the planted fault) is caught
    wrong = sample_volume(vol, (pts + 1.0) / 2.0)
    assert np.abs(fb.color[m] - wrong * shade[:, None]).max() > 1e-2
    # continuity: the unshaded colour changes across the seam no faster than the volume does
    texel = 2.0 / vol.shape[0]
    # (neighbours under repeat include the last and first texels)
    bound = sum(np.abs(vol - np.roll(vol, 1, axis=a)).max() for a in range(3)) / texel
    base = np.zeros(m.shape + (3,))
    base[m] = fb.color[m] / shade[:, None]
    assert seam_jump(fb, base) <= bound
    # per-surface 2D texturing (one texture on both caps, each by its own (s, t)) jumps there
    checker = (np.indices((4, 4)).sum(0) % 2).astype(float)
    fb2 = render_clipped(solid, wedge_surfaces(CapTextures(diffuse=checker)), **cam,
                         model=shift, caps=Caps(vds_resolution=96))
    base2 = np.zeros(m.shape + (3,))
    base2[fb2.cap_mask] = fb2.color[fb2.cap_mask] / wedge_shade(fb2, cam)[:, None]
    assert seam_jump(fb2, base2) > bound


def wedge_shade(fb, cam):
    """The flat caps' light term 0.25 + 0.75·|n·p̂| (n = −N of each cap, light = 1)."""
    k = (fb.object_id[fb.cap_mask] - fb.n_solids) % fb.n_surfaces
    normals = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])[k]      # −N of each cap
    pts = fb.cap_points
    eye = pts @ cam["view"][:3, :3].T + cam["view"][:3, 3]
    n_eye = normals @ cam["view"][:3, :3].T
    return 0.25 + 0.75 * np.abs(np.einsum("ij,ij->i", eye, n_eye)) / np.linalg.norm(eye, axis=1)


def test_one_d_offset_maps_equal_the_same_map_as_one_row():
    prof = om.ragged_cut((1, 32), seed=3)[0]
    assert prof.ndim == 1
    a = ClipSurface([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], (1.0, 1.0, 0.3), prof)
    b = ClipSurface([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], (1.0, 1.0, 0.3),
                    prof[None, :])
    col = ClipSurface([-1.0, -1.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0], (1.0, 1.0, 0.3),
                      prof[:, None])
    assert a.offset_map.shape == (1, 32)
    p = np.random.default_rng(0).uniform(-1, 1, (3000, 3))
    from refraster.clipsurface import clip_function
    assert np.array_equal(clip_function(p, a), clip_function(p, b))
    assert not np.allclose(clip_function(p, a), clip_function(p, col))   # a column map differs
    assert np.array_equal(a.normal_map(), b.normal_map())
    cam = camera()
    fa = render_clipped(box(), a, **cam, caps=Caps(vds_resolution=64, style="hatch"))
    fb = render_clipped(box(), b, **cam, caps=Caps(vds_resolution=64, style="hatch"))
    for name in ("depth", "color", "normal", "object_id", "prim_id", "cap_mask"):
        assert np.array_equal(getattr(fa, name), getattr(fb, name)), name
    # a 1D map is texture1D(s): constant along t (to rounding: GL_LINEAR's t weights still
    # multiply the two equal rows)
    st = np.random.default_rng(1).uniform(-2, 2, (200, 2))
    st2 = st.copy()
    st2[:, 1] += np.random.default_rng(2).uniform(-5, 5, 200)
    for wrap in ("repeat", "clamp_to_edge", "mirrored_repeat"):
        assert np.abs(om.sample(prof, st, wrap=wrap) - om.sample(prof, st2, wrap=wrap)).max() \
            < 1e-15


def test_texture_files_are_read_bottom_row_first(tmp_path):
    from refraster.io import write_png
    tex = coded_texture(8, 8)
    path = tmp_path / "tex.png"
    write_png(path, tex[::-1])     # the file lists its top row first
    loaded = as_texture(str(path), "diffuse", (3,))
    assert np.abs(loaded - tex).max() <= 0.5 / 255 + 1e-12


@pytest.mark.parametrize("kwargs,exc,match", [
    (dict(diffuse=np.zeros((2, 2, 2))), ValueError, "channel"),
    (dict(diffuse=np.full((2, 2), 2.0)), ValueError, r"\[0, 1\]"),
    (dict(diffuse=np.zeros((2, 2), np.int32)), TypeError, "dtype"),
    (dict(normal=np.zeros((2, 2))), ValueError, "channel"),
    (dict(light=np.zeros((2, 2, 3))), ValueError, "channel"),
    (dict(diffuse="/nonexistent/tex.png"), ValueError, "cannot read"),
    (dict(), ValueError, "at least one"),
])
def test_bad_textures(kwargs, exc, match):
    with pytest.raises(exc, match=match):
        CapTextures(**kwargs)


def test_bad_solid_textures_and_styles():
    with pytest.raises(ValueError, match="shape"):
        SolidTexture(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="origin and size"):
        SolidTexture(np.zeros((2, 2, 2)), origin=(0, 0, 0))
    cam = camera()
    with pytest.raises(ValueError, match="caps.solid_texture is needed by caps.style='solid'"):
        Caps(style="solid", vds_resolution=32)
    with pytest.raises(ValueError, match="caps.solid_texture is used by caps.style='solid' only"):
        Caps(solid_texture=np.zeros((2, 2, 2)), vds_resolution=32)
    with pytest.raises(ValueError, match=r"caps.style='hatch' draws its own pattern; a surface's "
                                         r"diffuse map"):
        render_clipped(box(), plane(CapTextures(diffuse=np.zeros((2, 2)))), **cam,
                       caps=Caps(style="hatch", vds_resolution=32))
    # without caps the procedural style is not drawn, so nothing to refuse
    render_clipped(box(), plane(CapTextures(diffuse=np.zeros((2, 2)))), **cam, caps=None)


_DETERMINISM = """
import hashlib, sys
import numpy as np
sys.path.insert(0, {tests!r})
import test_clipsurface_textures as T
from refraster.clipsurface import Caps, render_clipped
from refraster.clipsurface.textures import CapTextures
cam = T.camera()
tex = CapTextures(diffuse=T.coded_texture(), light=np.linspace(0.2, 1.0, 12).reshape(3, 4))
h = hashlib.sha256()
for mode in ("mesh", "exact"):
    fb = render_clipped(T.box(), T.plane(tex, offset_map=T.om.perlin_noise(16, seed=2),
                        scale=(1.0, 1.0, 0.2)), **cam, caps=Caps(mode=mode, vds_resolution=64))
    h.update(fb.color.tobytes() + fb.normal.tobytes() + fb.cap_points.tobytes())
fb = render_clipped(T.box(), T.wedge_surfaces(), **T.wedge_camera(64),
                    caps=Caps(style="solid", solid_texture=T.smooth_volume(), vds_resolution=64))
h.update(fb.color.tobytes() + fb.normal.tobytes())
print(h.hexdigest())
"""


def test_textured_caps_are_deterministic_across_thread_counts():
    import os

    from determinism import outputs_by_thread_count
    outs = outputs_by_thread_count(_DETERMINISM.format(tests=os.path.dirname(__file__)))
    assert outs[0] == outs[1] == outs[2] and len(outs[0]) == 64


def test_sampling_kernels_compile_once_for_writable_and_read_only_arrays():
    """The wrapper passes read-only views, so a writable and a read-only texture (or volume)
    use the same specialisation (issue 27: one compile, not two)."""
    from refraster.clipsurface import textures
    tex = np.random.default_rng(0).random((4, 5, 3))
    ro = tex.copy()
    ro.setflags(write=False)
    st = np.random.default_rng(1).random((6, 2))
    assert np.array_equal(textures.sample_texture(tex, st), textures.sample_texture(ro, st))
    vol = np.random.default_rng(2).random((3, 4, 5, 2))
    rv = vol.copy()
    rv.setflags(write=False)
    p = np.random.default_rng(3).random((6, 3))
    assert np.array_equal(textures.sample_volume(vol, p), textures.sample_volume(rv, p))
    for k in (textures._sample2d_kernel, textures._sample3d_kernel):
        assert all(not s[0].mutable for s in k.signatures), k.signatures
