"""2.5D clip surfaces and relief clip planes with cap surfaces (Trapp & Döllner). See
``docs/clipsurface.md`` and MATH.md §1–§2.

Modules, each importing only those above it (no circle; tests/test_architecture.py):

* :mod:`.offsetmaps` — offset maps: loading, the ``texture2D`` sampler, generators, blends,
  derived normal and occlusion maps.
* :mod:`.surfaces` — :class:`ClipSurface`, :class:`ReliefClipPlane`, the clip test
  (:func:`clip_function`, :func:`clip_mask`).
* :mod:`.capping` — cap meshes, exact caps, cap lighting and shading.
* :mod:`.fused` — the fused clip-and-cap tile pass.
* :mod:`.render` — :func:`render_clipped`, its cap options :class:`Caps` and
  :class:`ClippedFramebuffer`.
"""

from .render import Caps, ClippedFramebuffer, ClippedSampleFramebuffer, render_clipped
from .surfaces import (ORTHOGONALITY_TOLERANCE, ClipSurface, ReliefClipPlane,  # noqa: F401
                       as_surfaces, clip_function, clip_mask, clipped_at)

__all__ = ["Caps", "ClipSurface", "ReliefClipPlane", "ClippedFramebuffer",
           "ClippedSampleFramebuffer", "as_surfaces",
           "clip_function", "clip_mask", "render_clipped"]
