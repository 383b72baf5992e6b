"""Gallery section "edges": edge maps and the NPR styles of Nienhaus & Döllner (Fig. 4–9).

Every picture uses the paper's operator (``edge_map()`` with no options: diagonal normal and
depth operators, raw intensities as blend weights) on a G-buffer rendered with per-vertex
normals split at 30° creases (``Mesh.with_smooth_normals``), as the paper requires, and
composites the edge map onto the objects only (``mask=fb.mask``), as its projective texturing
does. For the crank and the building: Gooch shading (Fig. 7), hatching with strokes attached
to the surface (Fig. 8), the nearest-filtered toon shading beside the anti-aliased cartoon map
(Fig. 9, both halves), the C1 operator beside the diagonal one (Fig. 5) and the intermediate
buffers (Fig. 4 and 6). Then a mirror (Fig. 8, Sec. 5.3). Pictures are cropped to the object
with a small margin; labels name what each panel shows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item
from .panels import label as _label, side_by_side as _side_by_side

__all__ = ["render"]

SECTION = "edges"
FULL_SIZE = (640, 480)
QUICK_SIZE = (160, 120)
MARGIN = 6
CREASE_ANGLE = 30.0


def _crop_box(mask, margin):
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return slice(None), slice(None)
    h, w = mask.shape
    return (slice(max(ys.min() - margin, 0), min(ys.max() + margin + 1, h)),
            slice(max(xs.min() - margin, 0), min(xs.max() + margin + 1, w)))


def _grey(a):
    return np.repeat(np.asarray(a, np.float32)[..., None], 3, axis=2)


def _zoom(image, box, factor):
    """A nearest-neighbour enlargement of ``image[box]`` (pixels stay visible)."""
    part = np.asarray(image)[box]
    return np.repeat(np.repeat(part, factor, axis=0), factor, axis=1)


def _scene(name, quick):
    """The canonical solid, or a torus from trimesh while refraster.scenes is missing."""
    try:
        from ..scenes import solid
        return solid(name, quick=quick)
    except ImportError:
        import trimesh
        return trimesh.creation.torus(1.0, 0.35)


def _edge_rich_box(e, size):
    """The ``size``-pixel square window with the most profile-edge mass (for zoomed crops)."""
    h, w = e.shape
    size = min(size, h, w)
    c = np.cumsum(np.cumsum(np.pad(e, ((1, 0), (1, 0))), axis=0), axis=1)
    s = c[size:, size:] - c[:-size, size:] - c[size:, :-size] + c[:-size, :-size]
    y, x = np.unravel_index(int(np.argmax(s)), s.shape)
    return slice(y, y + size), slice(x, x + size)


def render(out_dir, *, quick=False):
    """Render the section into ``out_dir``; return its :class:`~refraster.gallery.Item` list."""
    import refraster
    from .. import edges
    from ..edges import npr
    from ..camera import frame_bounds
    from ..io import write_png
    from ..mesh import as_mesh

    width, height = QUICK_SIZE if quick else FULL_SIZE
    out_dir = Path(out_dir)
    items = []

    def save(key, image, caption):
        filename = f"{SECTION}/edges_{key}.png"
        write_png(out_dir / filename, image)
        items.append(Item(SECTION, filename, caption))

    for name in ("crank", "building"):
        raw = _scene(name, quick)
        mesh = as_mesh(raw).with_smooth_normals(crease_angle=CREASE_ANGLE)
        cam = frame_bounds(raw.bounds, width=width, height=height)
        fb = refraster.render(mesh, **cam.kwargs, raster=refraster.RasterState(normals="smooth"))
        gb = edges.edge_gbuffer(fb)
        em = edges.edge_map(gb)                       # the paper's operator
        crop = _crop_box(fb.mask, MARGIN)
        m = fb.mask

        def comp(shade, inner_color=(1.0, 1.0, 1.0)):
            return npr.composite(shade, em, inner_color=inner_color, mask=m)

        toon = npr.toon(fb.normal, mask=m)
        diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
        strokes = npr.surface_strokes(fb, spacing=diag / 40.0)
        save(f"{name}_gooch", comp(npr.gooch(fb.normal, mask=m))[crop],
             f"{name}: Gooch cool-to-warm shading; inner edges blended to white by E_N, profile "
             f"edges to black by E_Z, the paper's operator with raw intensities (Fig. 7)")
        save(f"{name}_hatching",
             comp(npr.hatching(fb.normal, mask=m, strokes=strokes),
                  inner_color=(0.35, 0.35, 0.35))[crop],
             f"{name}: hatching; prioritized strokes attached to the surface (triplanar "
             f"projection of object-space positions) with Freudenberg's smooth threshold; inner "
             f"edges grey (white vanishes on paper), profile edges black (Fig. 8)")
        save(f"{name}_fig9",
             _side_by_side([_label(comp(toon)[crop], "nearest 1D texture (Fig. 9 left)"),
                            _label(comp(npr.cartoon_map(toon, mask=m))[crop],
                                   "cartoon map, 3x3 resampled (Fig. 9 right)")]),
             f"{name}: toon shading with edges; left the 1D shade texture with nearest "
             f"filtering (jagged band borders), right the anti-aliased cartoon map (Fig. 9)")

        # Fig. 5: the C1 operator (printed 1/8 scale, clamped) against the diagonal operator,
        # on float32 depth and on depth quantized to 8 bits as in the paper's alpha texture
        grey = np.full(em.shape[:2] + (3,), 0.85, np.float32)
        profile_only = np.arange(4) == 3
        box = _edge_rich_box(em[..., 3] * m, 32 if quick else 64)
        z = 3 if quick else 4
        rows = []
        for tag, g in (("float depth", gb),
                       ("8-bit depth", edges.EdgeGBuffer(
                           normal=gb.normal, depth=(np.round(gb.depth * 255.0) / 255.0).astype(
                               np.float32), object_id=gb.object_id, near=gb.near, far=gb.far))):
            img_c1 = npr.composite(grey, np.where(profile_only, edges.edge_map(
                g, depth_filter="c1-paper"), 0.0))
            img_dg = npr.composite(grey, np.where(profile_only, edges.edge_map(g), 0.0))
            rows.append(_side_by_side([_label(img_c1[crop], f"C1 operator (1/8), {tag}"),
                                       _label(img_dg[crop], f"diagonal operator, {tag}"),
                                       _label(_zoom(img_c1, box, z), f"C1, x{z}"),
                                       _label(_zoom(img_dg, box, z), f"diagonal, x{z}")]))
        save(f"{name}_fig5", np.concatenate([rows[0], np.ones((6,) + rows[0].shape[1:],
                                                                np.float32), rows[1]], axis=0),
             f"{name}: the profile strength E_Z as black over grey, the C1 operator "
             f"(Saito-Takahashi, Decaudin; printed 1/8 scale, clamped at 1) beside the paper's "
             f"diagonal operator, and both enlarged at the window with the most edges; top "
             f"float32 depth, bottom depth quantized to 8 bits like the paper's alpha texture "
             f"(Fig. 5)")

        e_n = edges.diagonal_normal(gb.normal, encoded=True) * m
        e_z = edges.diagonal_depth(gb.depth)
        panels = [_label(gb.normal[crop], "normals 0.5n+0.5"),
                  _label(_grey(gb.depth)[crop], "linear depth (fitted)"),
                  _label(_grey(1.0 - e_n)[crop], "1 - E_N (normal op.)"),
                  _label(_grey(1.0 - e_z)[crop], "1 - E_Z (diagonal depth op.)"),
                  _label(npr.composite(np.full(em.shape[:2] + (3,), 0.5, np.float32),
                                       em)[crop], "edge map over grey")]
        save(f"{name}_buffers", _side_by_side(panels),
             f"{name}: G-buffer and edge intensities, left to right: encoded normals, linear "
             f"depth fitted to the object (near = black), inner strength E_N = 1 − I_N and "
             f"profile strength E_Z = 1 − I_Z of the paper's diagonal operators (raw, dark = "
             f"edge), and the edge map composited over grey: inner toward white, profile "
             f"toward black (Fig. 4 and 6)")

    # Fig. 8 / Sec. 5.3: a mirror, the mirrored scene with its own edge map
    raw = _scene("crank", quick)
    mesh = as_mesh(raw).with_smooth_normals(crease_angle=CREASE_ANGLE)
    lo, hi = raw.bounds
    centre, size = 0.5 * (lo + hi), float(np.max(hi - lo))
    lift = np.eye(4)
    gap = 0.12 * size
    lift[1, 3] = gap - lo[1]                          # the crank floats above the mirror
    top = hi[1] - lo[1] + gap
    half = 2.0 * size
    floor = (np.array([[centre[0] - half, 0.0, centre[2] - half],
                       [centre[0] + half, 0.0, centre[2] - half],
                       [centre[0] + half, 0.0, centre[2] + half],
                       [centre[0] - half, 0.0, centre[2] + half]]),
             np.array([[0, 2, 1], [0, 3, 2]]))
    # frame the crank and its reflection; the mirror runs out of the picture
    box = np.array([[lo[0], -top, lo[2]], [hi[0], top, hi[2]]])
    cam = frame_bounds(box, width=width, height=height, direction=(0.5, 0.75, 1.4),
                       margin=1.0)
    spacing = size / 70.0

    def style(fb, light):
        return npr.hatching(fb.normal, light=light,
                            strokes=npr.surface_strokes(fb, spacing=spacing), mask=fb.mask)

    r = npr.render_mirrored(mesh, floor, **cam.kwargs, models=[lift], style=style,
                            mirror_style=npr.MirrorStyle(reflectance=0.8,
                                                         inner_color=(0.35, 0.35, 0.35)))
    save("mirror_hatching", r.image,
         "crank above a mirror: edge-enhanced hatching; the mirrored crank is rendered with its "
         "own G-buffer and edge map (the objects reflected through the mirror plane, clipped at "
         "it, lit by the reflected light) and composited inside the mirror's pixels (Sec. 5.3, "
         "Fig. 8)")
    from .multisample import picture
    return items + picture("edges", SECTION, out_dir, quick)
