"""Adaptive cutaways (Burns & Finkelstein 2008): jump flooding of the cutaway surface and its
rendering effects. See ``docs/cutaway.md`` and MATH.md §4.

* :mod:`.flood` — the image-space core: :func:`jump_flood`, :func:`exact`, :func:`chamfer`.
* :mod:`.surface` — rear hulls → slopes (Eq. 3, edge compression, floor constraint) → D in NDC.
* :mod:`.options` — the options of :func:`render_cutaway` as values: :class:`Cutaway` (the
  surface D), :class:`CutSurfaces` (shading, dilation, outlines), :class:`GhostLines`.
* :mod:`.render` — :func:`render_cutaway`: clipping, cut surfaces, outlines, ghost lines.
* :mod:`.multisample` — :func:`render_cutaway_samples`: the cutaway at ``samples > 1``, the
  surface flooded per sample or from the resolved rear hulls (:class:`refraster.GBufferSampling`).
* :mod:`.lines` — the feature-line segments and their ghost-line opacity (Sec. 4.3).
"""

from .flood import VARIANTS, chamfer, exact, jump_flood
from .lines import feature_segments, ghost_alpha, segment_pieces
from .options import GHOST_SOURCES, Cutaway, CutSurfaces, GhostLines
from .render import CutawayFramebuffer, cut_surface_normals, ghost_lines, outline, render_cutaway
from .surface import cutaway_surface, seed_slopes, upsample_bilinear
from .multisample import SampleCutaway, render_cutaway_samples

__all__ = [
    "VARIANTS", "jump_flood", "exact", "chamfer", "cutaway_surface", "seed_slopes",
    "upsample_bilinear", "render_cutaway", "Cutaway", "CutSurfaces", "GhostLines",
    "GHOST_SOURCES", "CutawayFramebuffer", "cut_surface_normals",
    "outline", "ghost_lines", "feature_segments", "segment_pieces", "ghost_alpha",
    "SampleCutaway", "render_cutaway_samples",
]
