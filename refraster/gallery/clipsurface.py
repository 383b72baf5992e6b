"""Gallery section "clipsurface": 2.5D clip surfaces, relief clip planes and caps.

After Trapp & Döllner: the crank with a ragged surface and a hatched, edge-enhanced cap
(Fig. 1/10), the same with a user's hatch texture image (Fig. 10(a)) and Gooch-shaded
(Fig. 10(c)), edges white inside and black at the profile, the fluted column (Fig. 2), a cube
with procedural and user 3D solid textures (Fig. 11), the
building cut by two surfaces (Fig. 6), offset / normal / occlusion map triplets (Fig. 5), and
the tessellated against the exact cap.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item

__all__ = ["render"]

SECTION = "clipsurface"


def _frame(n):
    """(Û, V̂) with Û × V̂ = n."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0])
    if np.linalg.norm(u) < 1e-6:
        u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return n, u, np.cross(n, u)


def _surface(center, normal, extent, sz, offset_map, **kw):
    from ..clipsurface import ClipSurface
    n, u, v = _frame(normal)
    return ClipSurface(center, extent * u, extent * v, (1.0, 1.0, sz), offset_map, **kw)


#: Said under every edge-enhanced picture: why the "clean" preset is shown beside the paper's.
EDGE_NOTE = ("Left: Nienhaus & Döllner's operator (edge_map() with no options, the default); "
             "right: the \"clean\" preset (ours). The paper's profile strength is the raw "
             "depth step, weak where the step is small (a far side against the far plane), so "
             "the object's rim shows mostly its white inner edge (its normal against the "
             "background's) and not the black outline of Fig. 10; \"clean\" adds the id "
             "edges (strength 1) and thresholds the faint ones.")


def _edges(fb, color, preset="paper"):
    """Image-based edge enhancement composited with the paper's polarity (Fig. 10 (a)–(c),
    Nienhaus & Döllner [22]): white inner edges (normal discontinuities), black profile edges
    (depth discontinuities), :func:`refraster.edges.npr.composite`; ``preset`` of
    :func:`refraster.edges.edge_map` (the paper's operator by default)."""
    from ..edges import edge_map
    from ..edges.npr import composite
    return composite(color, edge_map(fb, preset=preset), inner_color=(1.0, 1.0, 1.0),
                     profile_color=(0.0, 0.0, 0.0))


def _edges_beside(fb, color, box=(slice(None), slice(None))):
    """The paper's edge enhancement (left) beside the "clean" preset (right), 4 white pixels
    apart, both cut to ``box`` (:data:`EDGE_NOTE`)."""
    paper, clean = (_edges(fb, color, preset)[box] for preset in ("paper", "clean"))
    gap = np.ones((paper.shape[0], 4, 3), paper.dtype)
    return np.concatenate([paper, gap, clean], axis=1)


def _object_box(mask, margin=0.04):
    """The rows and columns of the pictures of the crank that hold the object, with a margin
    (a share of the frame's height), so that the object fills the picture; the rendering is
    the same, only the empty border is left out."""
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return slice(None), slice(None)
    h, w = mask.shape
    m = max(int(round(margin * h)), 2)
    return (slice(max(ys.min() - m, 0), min(ys.max() + m + 1, h)),
            slice(max(xs.min() - m, 0), min(xs.max() + m + 1, w)))


def hatch_texture(size=64, *, spacing=8, width=2):
    """A user-style hatch texture image (what Fig. 10 (a) draws its caps with): dark 45° lines
    ``width`` texels wide every ``spacing`` texels on paper white, RGB uint8, tiling."""
    r, c = np.mgrid[0:size, 0:size]
    ink = (r + c) % spacing < width
    img = np.where(ink, 40, 235).astype(np.uint8)
    return np.repeat(img[:, :, None], 3, axis=2)


def strata_volume(n=48):
    """A user-style solid texture: bent sediment layers in sandstone colours, ``(n, n, n, 3)``
    float in [0, 1] (``vol[z, y, x]``)."""
    z, y, x = np.mgrid[0:n, 0:n, 0:n] / max(n - 1, 1)
    phase = 9.0 * y + 1.5 * np.sin(4.0 * x + 2.0 * z) + 0.8 * np.sin(7.0 * z)
    v = 0.5 + 0.5 * np.sin(phase)
    light = np.array([0.93, 0.82, 0.62])
    dark = np.array([0.55, 0.33, 0.2])
    return (1.0 - v)[..., None] * dark + v[..., None] * light


def render(out_dir: Path, *, quick: bool = False) -> list[Item]:
    """Render the section's pictures into ``out_dir``; returns their items."""
    from ..clipsurface import offsetmaps as om
    from .. import scenes
    from ..camera import frame_bounds
    from ..clipsurface import Caps, render_clipped
    from ..io import write_png

    out_dir = Path(out_dir)
    w, h = (160, 120) if quick else (640, 480)
    res = 128 if quick else 512
    items = []

    def save(name, image, caption):
        write_png(out_dir / f"clipsurface_{name}.png", image)
        items.append(Item(SECTION, f"clipsurface_{name}.png", caption))

    # Fig. 5: offset, normal and occlusion maps (columns) for four offset maps.
    size = 64 if quick else 128
    maps = {
        "Perlin noise": om.perlin_noise(size, cells=4, seed=1),
        "ragged cut": om.ragged_cut(size, seed=2),
        "sinusoid": om.sinusoid(size, periods=(6, 0)),
        "max(steps, noise)": om.blend(om.steps(size, levels=4), om.value_noise(size, cells=8),
                                      "lerp", weight=0.3),
    }
    rows = []
    for m in maps.values():
        kw = dict(extent=(1.0, 1.0), scale=(1.0, 1.0, 0.08))
        nrm = om.encode_normal_map(om.normal_map(m, **kw))
        occ = om.occlusion_map(m, **kw)
        # texel row 0 is t = 0: flip for display so t grows upwards
        rows.append(np.concatenate([np.repeat(m[::-1, :, None], 3, 2), nrm[::-1],
                                    np.repeat(occ[::-1, :, None], 3, 2)], axis=1))
    save("maps", np.concatenate(rows, axis=0),
         "Offset maps (left) with their normal maps (middle) and occlusion maps (right), "
         "MATH.md §1.2b; rows: " + ", ".join(maps) + " (after Fig. 5).")

    # Fig. 1/10: the crank, ragged surface along its axis, hatched cap, edge enhancement.
    crank = scenes.solid("crank", quick=quick)
    lo, hi = crank.bounds
    c = (lo + hi) / 2
    n = np.array([0.0, 0.25, -1.0])
    ragged = om.blend(om.ragged_cut(256, teeth=10, seed=4), om.perlin_noise(256, seed=5), "lerp",
                      weight=0.25)
    cs = _surface(c + [0, 0, 0.1], n, float(np.linalg.norm(hi - lo)), 0.9, ragged)
    cam = frame_bounds(crank.bounds, width=w, height=h, direction=(0.3, 0.7, 1.0))
    fb = render_clipped(crank, cs, **cam.kwargs,
                        caps=Caps(style="hatch", color=(0.55, 0.12, 0.1), vds_resolution=res))
    box = _object_box(fb.mask)
    save("crank_hatched", _edges_beside(fb, fb.color, box),
         "Crank cut by a ragged 2.5D clip surface; procedural hatched cap with normal and "
         "occlusion maps, edge-enhanced with white inner and black profile edges (after Fig. 1 "
         "and 10). " + EDGE_NOTE)

    # Fig. 10(a): the cap's diffuse map is a user's hatch texture image, read from its file
    # (CapTextures: mapped with the surface's (s, t), scale and wrap mode, GL_LINEAR).
    from ..clipsurface.textures import CapTextures
    from ..edges.npr import gooch
    hatch_png = out_dir / "clipsurface_hatch_texture.png"
    write_png(hatch_png, hatch_texture(256 if quick else 1024, spacing=16, width=6))
    items.append(Item(SECTION, hatch_png.name, "The user's hatch texture image used as the "
                      "caps' diffuse map below (the Fig. 10 insets)."))
    textured = _surface(c + [0, 0, 0.1], n, float(np.linalg.norm(hi - lo)), 0.9, ragged,
                        textures=CapTextures(diffuse=hatch_png))
    fb = render_clipped(crank, textured, **cam.kwargs,
                        caps=Caps(style="diffuse", vds_resolution=res))
    save("fig10a_texture", _edges_beside(fb, fb.color, box),
         "After Fig. 10(a): the crank's cap textured with the user's hatch image (file above) "
         "as its diffuse map, light through the derived occlusion map, white inner "
         "and black profile edges. " + EDGE_NOTE)

    # Fig. 10(c): Gooch shading of the clipped solid, the textured cap, the same edges.
    solid_px = fb.mask & ~fb.cap_mask
    shaded = np.array(fb.color, np.float64)
    shaded[solid_px] = gooch(fb.normal, mask=solid_px)[solid_px]
    save("fig10c_gooch", _edges_beside(fb, shaded, box),
         "After Fig. 10(c): the clipped crank Gooch-shaded (cool to warm), its cap textured "
         "with the hatch image, white inner and black profile edges. " + EDGE_NOTE)

    # Fig. 2: the fluted column cut across, marble cap.
    col = scenes.solid("fluted_column", quick=quick)
    lo, hi = col.bounds
    c = (lo + hi) / 2 + [0, 0.4, 0]
    cs = _surface(c, [0.35, -1.0, 0.25], 1.5, 0.35,
                  om.perlin_noise(128, cells=4, octaves=5, seed=8))
    cam = frame_bounds([lo, [hi[0], c[1] + 0.4, hi[2]]], width=w, height=h,
                       direction=(-0.05, 1.2, 0.35))
    fb = render_clipped(col, cs, **cam.kwargs,
                        caps=Caps(style="marble", color=(0.45, 0.42, 0.4), texture_frequency=3.0,
                                  vds_resolution=res))
    save("column", fb.color, "Fluted column with a 2.5D clip surface and a marble cap "
         "(after Fig. 2).")

    # Fig. 11: the cube with a solid-textured cap (wood) and the occlusion map.
    cube = scenes.solid("cube", quick=quick)
    lo, hi = cube.bounds
    cs = _surface((lo + hi) / 2 + 0.1, [-0.4, -0.3, -1.0], 1.5 * float(hi[0] - lo[0]), 0.25,
                  om.perlin_noise(64, cells=4, seed=11))
    cam = frame_bounds(cube.bounds, width=w, height=h, direction=(0.8, 0.9, 1.4))
    fb = render_clipped(cube, cs, **cam.kwargs,
                        caps=Caps(style="wood", color=(0.45, 0.25, 0.1), texture_frequency=2.0,
                                  vds_resolution=res))
    save("cube_wood", fb.color, "Cube with a solid-textured (wood) cap lit through its "
         "occlusion map (after Fig. 11).")

    # Fig. 11 with the user's own 3D texture: a volume sampled in the cube's object space.
    vol = strata_volume(16 if quick else 48)
    fb = render_clipped(cube, cs, **cam.kwargs,
                        caps=Caps(style="solid", solid_texture=vol, vds_resolution=res))
    save("cube_solid", fb.color, "Cube with a user 3D texture (a 48³ volume of bent strata, "
         "trilinear, spanning the cube's object-space box) on its cap, lit through the "
         "occlusion map (after Fig. 11).")

    # Fig. 6: the building cut by two surfaces in one pass.
    bld = scenes.solid("building", quick=quick)
    lo, hi = bld.bounds
    front = _surface([5.0, 3.0, 5.2], [0.0, 0.0, -1.0], 4.0, 0.3, om.ragged_cut(128, seed=6))
    roof = _surface([5.0, 4.6, 3.5], [0.0, -1.0, 0.15], 4.0, 0.3,
                    om.ragged_cut(128, seed=7, axis="t"))
    cam = frame_bounds(bld.bounds, width=w, height=h, direction=(0.6, 1.0, 1.4))
    fb = render_clipped(bld, [front, roof], **cam.kwargs,
                        caps=Caps(style="diffuse", color=(0.85, 0.45, 0.3), vds_resolution=res))
    save("building", _edges_beside(fb, fb.color, _object_box(fb.mask)),
         "Building cut by two 2.5D clip surfaces in one pass, revealing rooms and doorways "
         "(after Fig. 6). " + EDGE_NOTE)

    # Tessellated against exact caps, and the rim where a planar cut differs from manifold3d.
    box = scenes.solid("cube", quick=quick)
    lo, hi = box.bounds
    cs = _surface((lo + hi) / 2, [-0.2, -0.1, -1.0], 1.2 * float(hi[0] - lo[0]), 0.3,
                  om.perlin_noise(12, cells=3, seed=3))
    cam = frame_bounds(box.bounds, width=w, height=h, direction=(0.5, 0.6, 1.5))
    mesh_fb = render_clipped(box, cs, **cam.kwargs, caps=Caps(vds_resolution=res))
    exact_fb = render_clipped(box, cs, **cam.kwargs, caps=Caps(mode="exact", vds_resolution=res))
    both = mesh_fb.cap_mask & exact_fb.cap_mask
    diff = np.zeros(both.shape)
    diff[both] = np.abs(mesh_fb.eye_depth[both] - exact_fb.eye_depth[both])
    scale = max(float(diff.max()), 1e-12)
    heat = np.stack([diff / scale, np.zeros_like(diff), 1.0 - diff / scale], -1)
    heat[~both] = 1.0
    save("exact_vs_mesh", np.concatenate([mesh_fb.color, exact_fb.color, heat], axis=1),
         "A coarse 12×12 offset map: tessellated cap (left), exact per-pixel ray–height-field "
         f"cap (middle), and their eye-depth difference (right, red = {scale:.2g}).")
    from .multisample import picture
    items += picture("clipsurface", SECTION, out_dir, quick)
    return items
