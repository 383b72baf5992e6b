"""Edge enhancement (Nienhaus & Döllner, WSCG 2003): the edge G-buffer, discontinuity filters,
the edge map, NPR styles, and object-space edge classification. See ``docs/edges.md`` and
MATH.md §3.

Pipeline (the paper's Sec. 4.4 "Rendering Passes"):

1. :func:`edge_gbuffer` — pass 1: eye-space normals encoded ``0.5·n + 0.5`` (RGB), linear depth
   normalized to near/far planes fitted to the enhanced objects (A), and object ids.
2. The discontinuity filters — pass 2: :func:`diagonal_normal`, :func:`diagonal_depth`,
   :func:`c1_depth`, :func:`sobel`, :func:`sobel_depth`, :func:`sobel_normal`,
   :func:`object_id_edges`; :func:`edge_map` runs the chosen ones in one fused pass.
3. Compositing with an NPR style: :mod:`refraster.edges.npr`.

Modules, each importing only those above it (no circle):

* :mod:`.gbuffer` — :class:`EdgeGBuffer`, :func:`edge_gbuffer`, :func:`fit_near_far` (Sec. 4.1.1).
* :mod:`.operators` — the discontinuity filters and :func:`edge_map` (Sec. 4.1.2).
* :mod:`.npr` — the NPR styles, :func:`~.npr.composite` and the mirror (Sec. 5); its names
  stay in :mod:`refraster.edges.npr` (``refraster.edges.npr.gooch``, …).
* :mod:`.multisample` — :func:`edge_map_samples`: the edge map of a multisampled G-buffer,
  per sample or from the resolved G-buffer (:class:`refraster.GBufferSampling`).
* :mod:`.classify` — :func:`classify_edges` → :class:`EdgeSet`, object-space edge classes
  (Sec. 3).
"""

from . import npr
from .classify import DEFAULT_CREASE_ANGLE, EdgeSet, classify_edges
from .gbuffer import EdgeGBuffer, edge_gbuffer, fit_near_far
from .operators import (DEFAULT_INNER_THRESHOLD, DEFAULT_PROFILE_THRESHOLD, EDGE_PRESETS,
                        c1_depth, diagonal_depth, diagonal_normal, edge_map, object_id_edges,
                        sobel, sobel_depth, sobel_normal)
from .multisample import SampleEdgeMap, edge_map_samples

__all__ = [
    "EdgeGBuffer", "edge_gbuffer", "fit_near_far", "diagonal_normal", "diagonal_depth",
    "c1_depth", "sobel", "sobel_depth", "sobel_normal", "object_id_edges", "edge_map",
    "EdgeSet", "classify_edges", "EDGE_PRESETS", "DEFAULT_INNER_THRESHOLD",
    "DEFAULT_PROFILE_THRESHOLD", "DEFAULT_CREASE_ANGLE", "SampleEdgeMap", "edge_map_samples",
]
