"""Gallery section "edges": edge maps and the NPR styles of Nienhaus & Döllner (Fig. 4–9).

For the crank and the building: Gooch shading, toon shading (nearest 1D texture and the
anti-aliased cartoon map) and hatching, each with the edge map composited; and the intermediate
buffers side by side (encoded normals, normalized depth, inner strength, profile strength, the
edge map over grey). Pictures are cropped to the object with a small margin.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item

__all__ = ["render"]

SECTION = "edges"
FULL_SIZE = (640, 480)
QUICK_SIZE = (160, 120)
MARGIN = 6


def _crop_box(mask, margin):
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return slice(None), slice(None)
    h, w = mask.shape
    return (slice(max(ys.min() - margin, 0), min(ys.max() + margin + 1, h)),
            slice(max(xs.min() - margin, 0), min(xs.max() + margin + 1, w)))


def _grey(a):
    return np.repeat(np.asarray(a, np.float32)[..., None], 3, axis=2)


def _side_by_side(images, gap=4):
    h = images[0].shape[0]
    sep = np.ones((h, gap, 3), np.float32)
    parts = []
    for k, im in enumerate(images):
        if k:
            parts.append(sep)
        parts.append(im)
    return np.concatenate(parts, axis=1)


def _scene(name, quick):
    """The canonical solid, or a torus from trimesh while refraster.scenes is missing."""
    try:
        from ..scenes import solid
        return solid(name, quick=quick)
    except ImportError:
        import trimesh
        return trimesh.creation.torus(1.0, 0.35)


def render(out_dir, *, quick=False):
    """Render the section into ``out_dir``; return its :class:`~refraster.gallery.Item` list."""
    import refraster
    from .. import edges, npr
    from ..camera import frame_bounds
    from ..io import write_png

    width, height = QUICK_SIZE if quick else FULL_SIZE
    items = []
    for name in ("crank", "building"):
        mesh = _scene(name, quick)
        cam = frame_bounds(mesh.bounds, width=width, height=height)
        fb = refraster.render(mesh, **cam.kwargs)
        gb = edges.edge_gbuffer(fb)
        em = edges.edge_map(gb, width=1 if quick else 2)
        crop = _crop_box(fb.mask, MARGIN)
        m = fb.mask

        toon = npr.toon(fb.normal, mask=m)
        pictures = [
            ("gooch", npr.composite(npr.gooch(fb.normal, mask=m), em),
             "Gooch cool-to-warm shading; inner edges blended to white, profile edges to "
             "black (paper Fig. 7)"),
            ("toon", npr.composite(toon, em),
             "toon shading, 1D texture with nearest filtering, plus edges (paper Fig. 9 left)"),
            ("cartoon_map", npr.composite(npr.cartoon_map(toon, mask=m), em),
             "the anti-aliased cartoon map (3×3 binomial over covered texels) plus edges "
             "(paper Fig. 9 right)"),
            ("hatching", npr.composite(npr.hatching(fb.normal, mask=m), em,
                                       inner_color=(0.35, 0.35, 0.35)),
             "hatching: prioritized strokes with Freudenberg's smooth threshold; inner edges "
             "in grey (white vanishes on paper), profile edges black (paper Fig. 8)"),
        ]
        for key, image, caption in pictures:
            filename = f"{SECTION}/edges_{name}_{key}.png"
            write_png(Path(out_dir) / filename, image[crop])
            items.append(Item(SECTION, filename, f"{name}: {caption}"))

        e_n = edges.diagonal_normal(gb.normal, encoded=True) * m
        e_z = np.maximum(edges.diagonal_depth(gb.depth, order=2),
                         edges.object_id_edges(gb.object_id))
        buffers = [gb.normal, _grey(gb.depth), _grey(1.0 - e_n), _grey(1.0 - e_z),
                   npr.composite(np.full(em.shape[:2] + (3,), 0.5, np.float32), em)]
        filename = f"{SECTION}/edges_{name}_buffers.png"
        write_png(Path(out_dir) / filename, _side_by_side([b[crop] for b in buffers]))
        items.append(Item(
            SECTION, filename,
            f"{name}: G-buffer and edge intensities, left to right: normals 0.5·n + 0.5, "
            f"linear depth fitted to the object (near = black), inner strength E_N and profile "
            f"strength E_Z (unthresholded, dark = edge), the thresholded edge map over grey "
            f"(inner white, profile black; paper Fig. 4 and 6)"))
    return items
