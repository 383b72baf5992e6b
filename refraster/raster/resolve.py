"""Resolve: the depth test in draw order over a fragment stream.

Fragments are visited in stream order, which within each pixel is draw order (draw call, then
primitive index). A fragment whose ``keep`` entry is False was discarded by a fragment stage
*before* the depth test, as GLSL ``discard`` does. A fragment passing the test becomes the
pixel's winner (its colour would be written) and, with ``depth_write``, updates the stored depth.
With ``less`` of two fragments at equal depth the first drawn wins, as in OpenGL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .._config import JIT
from .rasterizer import DEPTH_FUNCS, depth_test
from .state import as_raster_state, require_single_sample

__all__ = ["Resolved", "resolve"]


@dataclass(frozen=True, eq=False)
class Resolved:
    """``winner (H, W) int64``: index into the fragment stream of the visible fragment, −1 where
    none; ``depth (H, W) float32``: the depth buffer after all fragments."""

    winner: np.ndarray
    depth: np.ndarray


@njit(**JIT)
def _resolve(pixel, depth, keep, func, write, zbuf, win):
    for i in range(pixel.shape[0]):
        if not keep[i]:
            continue
        p = pixel[i]
        if depth_test(func, depth[i], zbuf[p]):
            win[p] = i
            if write:
                zbuf[p] = depth[i]


def resolve(frags, *, raster=None, keep=None):
    """Depth-test a fragment stream in draw order.

    Parameters
    ----------
    frags : Fragments
        The stream (see :class:`refraster.raster.fragments.Fragments`).
    raster : RasterState, optional
        Its ``depth_func`` (OpenGL's depth function, comparing the incoming fragment against
        the stored depth), ``depth_write`` (whether passing fragments update the depth buffer,
        ``glDepthMask``) and ``clear_depth`` (the depth buffer's initial value) apply here.
        None: ``less``, writes on, cleared to 1.
    keep : (N,) bool, optional
        False for fragments discarded by a fragment stage (applied before the depth test).

    Returns
    -------
    Resolved
    """
    state = require_single_sample(as_raster_state(raster), "resolve")
    func = DEPTH_FUNCS[state.depth_func]
    clear = state.clear_depth
    n = len(frags)
    if keep is None:
        keep = np.ones(n, np.bool_)
    else:
        keep = np.asarray(keep)
        if keep.dtype != np.bool_:
            raise TypeError(f"keep must be a bool array, got dtype {keep.dtype}")
        if keep.shape != (n,):
            raise ValueError(f"keep must have shape ({n},), got {keep.shape}")
        keep = np.ascontiguousarray(keep)
    h, w = frags.height, frags.width
    zbuf = np.full(h * w, np.float32(clear), np.float32)
    win = np.full(h * w, -1, np.int64)
    _resolve(frags.pixel, frags.depth, keep, func, state.depth_write, zbuf, win)
    return Resolved(win.reshape(h, w), zbuf.reshape(h, w))
