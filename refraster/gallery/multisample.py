"""The gallery's multisampled pictures (issue 44): one per technique, beside its single-sample
one — the paper's single-sample picture, then 4× with the image pass per sample and 4× from
the resolved G-buffer (:class:`refraster.GBufferSampling`, ``docs/multisample.md``).

:data:`PICTURES` maps a section to its picture's function ``(out_dir, quick) -> Item``; a
section joins by adding its function here and calling :func:`picture` from its ``render``
(clip surfaces: ``None`` until their 4× frames exist). The 4D halos have none: their slicing
composite refuses ``samples > 1`` (``docs/halos4d.md``, "Multisampling").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item
from .panels import label as _label, side_by_side as _side_by_side

__all__ = ["PICTURES", "picture", "edges_picture", "cutaway_picture"]

#: 4× at llvmpipe's positions with sample-rate interpolation (the goldens' state).
_RASTER = dict(samples=4, sample_locations="gl_llvmpipe", interpolation="sample")


def _zoom(image, factor):
    return np.repeat(np.repeat(image, factor, axis=0), factor, axis=1)


def edges_picture(out_dir, quick, section="edges"):
    """The building's edge map over grey: one sample, 4× per sample, 4× resolved (sample 0)."""
    import refraster
    from ..camera import frame_bounds
    from ..edges import edge_map, edge_map_samples, npr
    from ..io import write_png
    from ..scenes import solid
    w, h = (80, 60) if quick else (240, 180)
    mesh = solid("building")
    cam = frame_bounds(np.stack([mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)]),
                       width=w, height=h)
    box = np.stack([mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)])
    grey = np.full((h, w, 3), 0.5, np.float32)
    one = edge_map(refraster.render(mesh, **cam.kwargs), bounds=box)
    frame = refraster.render_samples(mesh, **cam.kwargs, raster=refraster.RasterState(**_RASTER))
    per = edge_map_samples(frame, bounds=box, view=cam.view).edge_map
    res = edge_map_samples(frame, bounds=box, view=cam.view,
                           sampling=refraster.GBufferSampling("resolved")).edge_map
    z = 2 if quick else 3
    panels = [_label(_zoom(npr.composite(grey, e), z), t) for e, t in (
        (one, "1 sample (the paper)"), (per, "4x, per sample"), (res, "4x, resolved G-buffer"))]
    name = "edges/edges_building_msaa.png"
    write_png(Path(out_dir) / name, _side_by_side(panels))
    diff = float((np.abs(per - res) > 1 / 255).mean())
    return Item(section, name,
                f"building: the paper's edge map over grey (inner edges towards white, profile "
                f"towards black), enlarged ×{z}: one sample; 4 samples with the filters on each "
                f"sample's G-buffer and the four edge maps averaged (edges anti-aliased); 4 "
                f"samples with the filters on the G-buffer resolved first (sample 0's: as "
                f"jagged as one sample, shifted). The two 4× pictures differ on "
                f"{100 * diff:.1f} % of the pixels by more than 1/255.")


def cutaway_picture(out_dir, quick, section="cutaway"):
    """The nested shells' cutaway: one sample, 4× per sample, 4× resolved (sample 0)."""
    import refraster
    from ..camera import look_at, perspective
    from ..cutaway import Cutaway, GhostLines, render_cutaway, render_cutaway_samples
    from ..io import write_png
    from ..scenes import icosphere, nested_shells
    s = 96 if quick else 240
    shells = nested_shells((1.2, 1.05, 0.8, 0.68), subdivisions=2 if quick else 3)
    core = [icosphere(3, radius=0.3)]
    cam = dict(view=look_at((2.6, 1.6, 3.0), (0.0, 0.0, 0.0)),
               proj=perspective(35.0, 1.0, 0.5, 20.0), width=s, height=s)
    opts = dict(cutaway=Cutaway(angle=0.7), ghosts=GhostLines(distance=0.6))
    one = render_cutaway(core, shells, **cam, **opts).image
    st = refraster.RasterState(**_RASTER)
    per = render_cutaway_samples(core, shells, **cam, **opts, raster=st).image
    res = render_cutaway_samples(core, shells, **cam, **opts, raster=st,
                                 sampling=refraster.GBufferSampling("resolved")).image
    panels = [_label(i, t) for i, t in ((one, "1 sample (the paper)"),
                                        (per, "4x, per sample"),
                                        (res, "4x, resolved rear hulls"))]
    name = "cutaway_shells_msaa.png"
    write_png(Path(out_dir) / name, _side_by_side(panels))
    diff = float((np.abs(per - res) > 1 / 255).any(axis=2).mean())
    return Item(section, name,
                f"Nested shells cut away around a sphere (θ = 0.7): one sample; 4 samples, each "
                f"sample's rear hulls flooded to its own cutaway surface and carved by it; 4 "
                f"samples carved by one surface flooded from the resolved rear hulls (sample "
                f"0's). Each sample's discard, cut shading and outline are its own (sample "
                f"shading); the pictures are the box filter of the samples. The two 4× pictures "
                f"differ on {100 * diff:.1f} % of the pixels by more than 1/255.")


#: Section → its multisampled picture (None: none yet, or none by design — see the module).
PICTURES = {"edges": edges_picture, "cutaway": cutaway_picture, "clipsurface": None,
            "halos4d": None}


def picture(key, section, out_dir, quick):
    """Section ``key``'s multisampled picture as a one-item list (empty when it has none),
    its item in ``section`` (the section module's ``SECTION``)."""
    fn = PICTURES.get(key)
    return [] if fn is None else [fn(out_dir, quick, section)]
