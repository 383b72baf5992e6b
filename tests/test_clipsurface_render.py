"""render_clipped and caps against manifold3d (MATH.md §1.2, §2.2; Trapp & Döllner Sec. 5)."""

import os
import subprocess
import sys

import numpy as np
import pytest

import refraster
from refraster.clipsurface import offsetmaps as om
from refraster import scenes
from refraster.camera import frame_bounds, look_at, perspective
from refraster.clipsurface.capping import cap_mesh
from refraster.clipsurface import Caps, ClipSurface, render_clipped


def parity_tests(*meshes):
    """The volumetric parity test of refraster.ldi when it is there (``None`` lets
    render_clipped build it); trimesh's ray-based ``contains`` as a stand-in otherwise."""
    try:
        import refraster.ldi  # noqa: F401
        return None
    except ImportError:
        import trimesh

        class Contains:
            def __init__(self, m):
                self.mesh = trimesh.Trimesh(np.asarray(m.vertices), np.asarray(m.faces))

            def contains(self, p):
                return self.mesh.contains(p)
        return [Contains(m) for m in meshes]


def to_manifold(mesh):
    import manifold3d
    return manifold3d.Manifold(manifold3d.Mesh(
        vert_properties=np.asarray(mesh.vertices, np.float32),
        tri_verts=np.asarray(mesh.faces, np.uint32)))


def from_manifold(solid):
    import trimesh
    m = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts),
                           process=False)


def frame(n, c):
    """(Û, V̂) with Û × V̂ = n."""
    u = np.cross(n, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def convex_solid():
    import trimesh
    return trimesh.convex.convex_hull(np.random.default_rng(0).normal(size=(40, 3)))


def nonconvex_solid():
    import manifold3d
    rng = np.random.default_rng(3)
    parts = [manifold3d.Manifold.cube(list(rng.uniform(0.4, 1.2, 3))).translate(
        list(rng.uniform(-0.8, 0.4, 3))) for _ in range(5)]
    return from_manifold(manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add))


CASES = {
    # across the first web and its counterweight, seen from the nose
    "crank": (lambda: scenes.solid("crank", quick=True), [1.0, 0.15, 0.2], [0.3, 0.4, 0.0]),
    "column": (lambda: scenes.solid("fluted_column", quick=True), [0.3, -1.0, 0.4], [0.3, 0, 0.4]),
    "convex": (convex_solid, [0.3, -0.2, -1.0], [0.3, 0.4, 0.0]),
    "nonconvex": (nonconvex_solid, [0.4, -0.3, -1.0], [0.3, 0.4, 0.0]),
}


@pytest.mark.parametrize("name", ["crank", "column", "convex", "nonconvex"])
def test_planar_cut_matches_manifold3d(oracle, name):
    oracle("manifold3d")
    make, normal, tilt = CASES[name]
    mesh = make()
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    lo, hi = mesh.bounds
    c = np.array([1.2, 0.0, 0.0]) if name == "crank" else (lo + hi) / 2
    u, v = frame(n, c)
    cs = ClipSurface(c, 2 * u, 2 * v, (1, 1, 0.2), om.constant(4, 0.5))
    # kept: N·P ≥ N·O − Sz·h; manifold3d keeps the side the normal points to
    trimmed = from_manifold(to_manifold(mesh).trim_by_plane(list(n), float(n @ c - 0.1)))
    # frame the cut: the bounds of the trimmed solid's vertices on the plane
    on_plane = trimmed.vertices[np.abs(trimmed.vertices @ n - (n @ c - 0.1)) < 1e-5]
    cam = frame_bounds(np.stack([on_plane.min(0), on_plane.max(0)]), width=480, height=360,
                       direction=-n + tilt)
    fb = render_clipped(mesh, cs, **cam.kwargs, vds=parity_tests(mesh))
    ref = refraster.render(trimmed, **cam.kwargs)
    covered = fb.mask | ref.mask
    ok = np.abs(fb.depth.astype(np.float64) - ref.depth) <= 1e-5
    frac = np.count_nonzero(ok & covered) / np.count_nonzero(covered)
    assert fb.cap_mask.sum() > 0.05 * covered.sum()
    assert frac >= 0.995, f"{name}: {frac:.4%} of covered pixels within 1e-5"


def heightfield_solid(surface, bounds, heights_at, subdivision):
    """A closed solid between the displaced surface and a flat floor beyond the box on −N,
    with the same lattice (and diagonal) as refraster.clipsurface.capping.cap_mesh."""
    import trimesh
    cap = cap_mesh(surface, bounds, subdivision=subdivision)
    top = cap.vertices.copy()
    d = top - surface.origin
    a = d @ surface.u_hat / surface.u_length
    b = d @ surface.v_hat / surface.v_length
    plane = surface.origin + a[:, None] * surface.u + b[:, None] * surface.v
    h = heights_at(a * surface.scale[0], b * surface.scale[1])
    top = plane - (surface.scale[2] * h)[:, None] * surface.normal
    depth = 2.0 * np.linalg.norm(bounds[1] - bounds[0]) + abs(surface.scale[2])
    bottom = plane - depth * surface.normal
    nv = len(top)
    faces = [cap.faces[:, ::-1], cap.faces + nv]     # top faces +N outward, bottom faces −N
    # boundary loop of the grid: walls
    nb = len(np.unique(np.round(b, 12)))
    na = nv // nb
    idx = np.arange(nv).reshape(nb, na)
    ring = np.concatenate([idx[0, :], idx[1:, -1], idx[-1, -2::-1], idx[-2:0:-1, 0]])
    for p, q in zip(ring, np.roll(ring, -1)):
        faces.append(np.array([[p, q, q + nv], [p, q + nv, p + nv]]))
    mesh = trimesh.Trimesh(np.concatenate([top, bottom]), np.concatenate(faces), process=False)
    trimesh.repair.fix_normals(mesh)  # consistent, outward winding for manifold3d
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    return mesh


def relief_setup():
    mesh = scenes.solid("fluted_column", quick=True)
    n = np.array([0.35, -0.25, -1.0])
    n /= np.linalg.norm(n)
    lo, hi = mesh.bounds
    c = (lo + hi) / 2
    u, v = frame(n, c)
    om_ = om.perlin_noise(24, cells=3, octaves=2, seed=7)
    cs = ClipSurface(c, 1.6 * u, 1.6 * v, (1, 1, 0.3), om_)
    cam = frame_bounds(mesh.bounds, width=320, height=240, direction=-n + [0.3, 0.4, 0])
    return mesh, cs, cam


def test_relief_cut_matches_manifold3d_and_exact_is_closer(oracle):
    oracle("manifold3d")
    ndimage = oracle("scipy.ndimage")
    mesh, cs, cam = relief_setup()
    tests = parity_tests(mesh)
    bounds = np.asarray(mesh.bounds)
    rows, cols = cs.offset_map.shape

    def sampled(s, t):  # independent bilinear sampler: scipy with GL's texel centres
        return ndimage.map_coordinates(np.asarray(cs.offset_map), [t * rows - 0.5, s * cols - 0.5],
                                       order=1, mode="grid-wrap")

    def oracle_depth(sub):
        hf = heightfield_solid(cs, bounds, sampled, sub)
        return refraster.render(from_manifold(to_manifold(mesh) - to_manifold(hf)), **cam.kwargs)

    same = oracle_depth(1)
    fine = oracle_depth(6)
    tess = render_clipped(mesh, cs, **cam.kwargs, vds=tests)
    exact = render_clipped(mesh, cs, **cam.kwargs, vds=tests, caps=Caps(mode="exact"))
    covered = tess.mask | same.mask
    ok = np.abs(tess.depth.astype(np.float64) - same.depth) <= 1e-4
    frac = np.count_nonzero(ok & covered) / np.count_nonzero(covered)
    assert frac >= 0.99, f"tessellated cap vs manifold3d: {frac:.4%} within 1e-4"
    # against the finely tessellated bilinear surface the exact cap is closer
    caps = tess.cap_mask & exact.cap_mask & fine.mask
    err_tess = np.abs(tess.depth[caps].astype(np.float64) - fine.depth[caps]).mean()
    err_exact = np.abs(exact.depth[caps].astype(np.float64) - fine.depth[caps]).mean()
    assert caps.sum() > 2000
    assert err_exact < err_tess, (err_exact, err_tess)


def test_exact_and_mesh_caps_agree_on_a_plane():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.2), om.constant(4, 0.5))
    kw = dict(view=look_at([1.5, 1.2, 2.2], [0, 0, 0]), proj=perspective(35, 4 / 3, 0.5, 10),
              width=160, height=120, vds=parity_tests(box))
    a = render_clipped(box, cs, **kw)
    b = render_clipped(box, cs, **kw, caps=Caps(mode="exact"))
    both = a.cap_mask & b.cap_mask
    assert both.sum() > 0.97 * max(a.cap_mask.sum(), b.cap_mask.sum())
    np.testing.assert_allclose(a.depth[both], b.depth[both], atol=2e-6)
    assert np.all(a.object_id[a.cap_mask] == 1) and np.all(b.object_id[b.cap_mask] == 1)
    assert np.all(a.front_facing[a.cap_mask]) and np.all(b.front_facing[b.cap_mask])
    # cap normals: the plane's −N (= +z world) in eye space
    n_eye = kw["view"][:3, :3] @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(b.normal[b.cap_mask], np.broadcast_to(n_eye, (both.size and b.cap_mask.sum(), 3)), atol=1e-6)
    pos = b.eye_position()[b.cap_mask]
    world = pos @ np.linalg.inv(kw["view"])[:3, :3].T + np.linalg.inv(kw["view"])[:3, 3]
    np.testing.assert_allclose(world[:, 2], 0.2, atol=1e-9)   # z = 0.1 + 0.2·0.5 along −N = +z


def test_eye_space_render_equals_world_space():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.perlin_noise(16))
    kw = dict(view=look_at([1.5, 1.2, 2.2], [0, 0, 0]), proj=perspective(35, 4 / 3, 0.5, 10),
              width=120, height=90, caps=None)
    a = render_clipped(box, cs, **kw)
    b = render_clipped(box, cs, **kw, space="eye")
    assert np.count_nonzero(a.depth != b.depth) <= 0.001 * a.depth.size


@pytest.mark.parametrize("style", ["diffuse", "hatch", "marble", "wood", "noise"])
def test_cap_styles_and_disabled_surface(style):
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.perlin_noise(16))
    kw = dict(view=look_at([1.5, 1.2, 2.2], [0, 0, 0]), proj=perspective(35, 4 / 3, 0.5, 10),
              width=64, height=48, vds=parity_tests(box))
    fb = render_clipped(box, cs, **kw, caps=Caps(style=style))
    assert fb.cap_mask.any()
    assert np.all((fb.color >= 0) & (fb.color <= 1))
    off = render_clipped(box, cs.replace(enabled=False), **kw, caps=Caps(style=style))
    plain = refraster.render(box, **{k: kw[k] for k in ("view", "proj", "width", "height")})
    np.testing.assert_array_equal(off.depth, plain.depth)
    assert not off.cap_mask.any()


def test_bad_inputs():
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    cs = ClipSurface([0, 0, 0], [0, 1, 0], [1, 0, 0], (1, 1, 0.2), om.constant(4))
    kw = dict(view=look_at([1.5, 1.2, 2.2], [0, 0, 0]), proj=perspective(35, 4 / 3, 0.5, 10),
              width=32, height=24)
    open_box = (box.vertices, box.faces[:-1])
    with pytest.raises(ValueError, match="watertight"):
        render_clipped(open_box, cs, **kw)
    render_clipped(open_box, cs, **kw, caps=None)  # clipping alone needs no closed solid
    with pytest.raises(TypeError, match="caps must be a Caps or None, got bool"):
        render_clipped(box, cs, **kw, caps=True)
    with pytest.raises(ValueError, match="vds"):
        render_clipped(box, cs, **kw, vds=[object(), object()])
    with pytest.raises(TypeError, match="contains"):
        render_clipped(box, cs, **kw, vds=[object()])
    with pytest.raises(TypeError, match="surfaces"):
        render_clipped(box, [cs, None], **kw)
    with pytest.raises(TypeError, match="raster must be a refraster.RasterState"):
        render_clipped(box, cs, **kw, raster={"normals": "smooth"}, caps=None)
    with pytest.raises(ValueError, match=r"raster.clear_depth must be 0.0 under "
                                         r"depth_func='greater' for render_clipped"):
        render_clipped(box, cs, **kw, raster=refraster.RasterState(depth_func="greater"))
    with pytest.raises(ValueError, match=r"raster.depth_func must be one of less, lequal, "
                                         r"greater, gequal for render_clipped"):
        render_clipped(box, cs, **kw, raster=refraster.RasterState(depth_func="always"))



# ------------------------------------------------------------------------- the Caps value

_VOLUME = np.zeros((2, 2, 2))


@pytest.mark.parametrize("field, value, exc, message", [
    ("style", "stipple", ValueError, "caps.style must be one of ['diffuse', 'hatch', 'marble', "
                                     "'noise', 'solid', 'wood'], got 'stipple'"),
    ("style", 3, TypeError, "caps.style must be a str"),
    ("mode", "parallax", ValueError, "caps.mode must be one of ['exact', 'mesh']"),
    ("color", (1.0, 0.0), ValueError, "caps.color must have shape (3), got (2,)"),
    ("color", (np.nan, 0.0, 0.0), ValueError, "caps.color contains 1 non-finite value"),
    ("color", "red", TypeError, "caps.color must be a numeric array"),
    ("hatch_spacing", 0.0, ValueError, "caps.hatch_spacing must be > 0.0, got 0.0"),
    ("hatch_spacing", "1", TypeError, "caps.hatch_spacing must be a real number"),
    ("texture_frequency", -1.0, ValueError, "caps.texture_frequency must be > 0.0"),
    ("texture_frequency", None, TypeError, "caps.texture_frequency must be a real number"),
    ("subdivision", 0, ValueError, "caps.subdivision must be an int in [1, 64], got 0"),
    ("subdivision", 65, ValueError, "caps.subdivision must be an int in [1, 64], got 65"),
    ("subdivision", 1.0, TypeError, "caps.subdivision must be an int, got float"),
    ("subdivision", True, TypeError, "caps.subdivision must be an int, got bool"),
    ("occlusion_radius", 0.0, ValueError, "caps.occlusion_radius must be > 0.0"),
    ("occlusion_radius", np.inf, ValueError, "caps.occlusion_radius must be finite"),
    ("solid_texture", _VOLUME, ValueError, "caps.solid_texture is used by caps.style='solid' "
                                           "only, not 'diffuse'"),
    ("vds_resolution", 4, ValueError, "caps.vds_resolution must be at least 8, got 4"),
    ("vds_resolution", 5000, ValueError, "caps.vds_resolution = 5000 exceeds"),
    ("vds_resolution", 64.0, TypeError, "caps.vds_resolution must be an int, got float"),
])
def test_caps_refuses_a_bad_field_in_one_line_naming_it(field, value, exc, message):
    with pytest.raises(exc) as info:
        Caps(**{field: value})
    text = str(info.value)
    assert text.startswith(message) and "\n" not in text, text


@pytest.mark.parametrize("fields, message", [
    (dict(style="solid"), "caps.solid_texture is needed by caps.style='solid'"),
    (dict(style="solid", solid_texture=np.zeros((2, 2))),
     "caps.solid_texture: volume must be (D, H, W) or (D, H, W, C), got shape (2, 2)"),
])
def test_caps_solid_style_and_its_texture(fields, message):
    with pytest.raises(ValueError) as info:
        Caps(**fields)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_caps_defaults_normal_forms_and_immutability():
    import dataclasses
    import inspect

    from refraster.clipsurface.textures import SolidTexture
    c = Caps()
    assert (c.style, c.mode, c.color, c.hatch_spacing, c.texture_frequency, c.subdivision,
            c.occlusion_radius, c.solid_texture, c.vds_resolution) == \
        ("diffuse", "mesh", (0.80, 0.30, 0.25), None, 4.0, 1, None, None, 1024)
    assert inspect.signature(render_clipped).parameters["caps"].default == c
    assert len(inspect.signature(render_clipped).parameters) <= 15
    d = Caps(style="HATCH", mode="Exact", color=np.array([1, 0, 0]), subdivision=np.int64(2),
             hatch_spacing=1, occlusion_radius=2)
    assert (d.style, d.mode, d.color, d.subdivision, d.hatch_spacing, d.occlusion_radius) == \
        ("hatch", "exact", (1.0, 0.0, 0.0), 2, 1.0, 2.0)
    assert type(d.subdivision) is int and all(type(x) is float for x in d.color)
    assert d == Caps(style="hatch", mode="exact", color=(1.0, 0.0, 0.0), subdivision=2,
                     hatch_spacing=1.0, occlusion_radius=2.0)
    assert hash(d) == hash(dataclasses.replace(d))
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.style = "diffuse"
    with pytest.raises(ValueError, match="caps.subdivision"):
        dataclasses.replace(d, subdivision=0)           # a variant is validated again
    solid = Caps(style="solid", solid_texture=np.zeros((2, 2, 2)))
    assert isinstance(solid.solid_texture, SolidTexture)
    assert Caps(style="solid", solid_texture=solid.solid_texture).solid_texture \
        is solid.solid_texture

_DETERMINISM = """
import sys, numpy as np, trimesh
from refraster.clipsurface import offsetmaps as om
from refraster.camera import look_at, perspective
from refraster.clipsurface import Caps, ClipSurface, render_clipped
box = trimesh.creation.box((1.0, 1.0, 1.0))
class C:
    def contains(self, p):
        return np.all(np.abs(p) <= 0.5, axis=1)
cs = ClipSurface([0, 0, 0.1], [0, 1.5, 0], [1.5, 0, 0], (1, 1, 0.3), om.perlin_noise(16))
kw = dict(view=look_at([1.5, 1.2, 2.2], [0, 0, 0]), proj=perspective(35, 4 / 3, 0.5, 10),
          width=96, height=72, vds=[C()])
for mode in ("mesh", "exact"):
    fb = render_clipped(box, cs, caps=Caps(style="hatch", mode=mode), **kw)
    sys.stdout.write(fb.depth.tobytes().hex() + fb.color.tobytes().hex())
# the fused tile pass (a volumetric depth sprite as the parity test)
from refraster.ldi import VolumetricDepthSprite
kw["vds"] = [VolumetricDepthSprite.from_mesh(box, resolution=64)]
fb = render_clipped(box, cs, caps=Caps(style="hatch"), **kw)
assert fb.cap_mask.any()
sys.stdout.write(fb.depth.tobytes().hex() + fb.color.tobytes().hex() + fb.prim_id.tobytes().hex())
"""


def test_deterministic_across_thread_counts():
    outs = [subprocess.run([sys.executable, "-c", _DETERMINISM], check=True, capture_output=True,
                           text=True, env=dict(os.environ, NUMBA_NUM_THREADS=t,
                                                  REFRASTER_THREADS=t)).stdout
            for t in ("1", "2")]
    assert outs[0] == outs[1] and len(outs[0]) > 10000
