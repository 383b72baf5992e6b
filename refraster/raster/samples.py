"""Sample positions inside a pixel (``docs/multisample.md``).

Every pattern is stored as ``(x, y)`` in 1/16 pixel from the pixel's upper-left corner as the
picture is seen (row 0 at the top), x right and y down — Vulkan's framebuffer coordinates, in
which its standard sample locations and ``VK_EXT_sample_locations`` are given. The rasterizer
works in picture-up fixed-point coordinates with pixel centres on multiples of ``2^b``
(:mod:`refraster.raster.rasterizer`); :func:`sample_offsets` turns a pattern into offsets from
the pixel centre there.
"""

from __future__ import annotations

import numpy as np

from ._sample_tables import STANDARD

__all__ = ["STANDARD", "GL_LLVMPIPE_4X", "GL_LLVMPIPE_4X_REPORTED", "pattern", "sample_offsets",
           "sample_points"]

#: What llvmpipe reports through ``glGetMultisamplefv(GL_SAMPLE_POSITION, i)`` at 4×, in GL's
#: window coordinates (x right, y **up** from the pixel's lower-left corner).
GL_LLVMPIPE_4X_REPORTED = ((0.375, 0.125), (0.875, 0.375), (0.125, 0.625), (0.625, 0.875))
#: The same positions as the picture is seen (y down from the upper-left corner, 1/16 pixel):
#: GL's y up turned down, ``y ↦ 16 − 16·y``. ``tests/test_msaa.py`` checks against llvmpipe's
#: per-sample coverage that this is the picture it makes (Vulkan's 4× pattern mirrored top to
#: bottom).
GL_LLVMPIPE_4X = tuple((int(16 * x), 16 - int(16 * y)) for x, y in GL_LLVMPIPE_4X_REPORTED)


def pattern(state):
    """The ``(S, 2)`` int64 positions of a :class:`~refraster.RasterState`, in 1/16 pixel, y down
    from the pixel's upper-left corner."""
    loc = state.sample_locations
    if loc == "standard":
        pts = STANDARD[state.samples]
    elif loc == "gl_llvmpipe":
        pts = GL_LLVMPIPE_4X
    else:
        pts = loc
    return np.array(pts, np.int64).reshape(-1, 2)


def sample_offsets(state):
    """``(ox, oy)``, each ``(S,)`` int64: the samples' offsets from the pixel centre in the
    rasterizer's fixed point (``1/2^subpixel_bits`` pixel, y up); exact, as 1/16 pixel is a
    multiple of the sub-pixel step at 4 and 8 bits."""
    p = pattern(state)
    shift = state.subpixel_bits - 4
    return (p[:, 0] - 8) << shift, (8 - p[:, 1]) << shift


def sample_points(state):
    """``(S, 2)`` float64: the positions in pixels from the pixel's upper-left corner, y down."""
    return pattern(state).astype(np.float64) / 16.0
