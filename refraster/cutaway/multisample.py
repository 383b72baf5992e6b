"""Cutaways at ``samples > 1`` (``docs/cutaway.md``, "Multisampled G-buffers").

Burns & Finkelstein's cutaway surface D is an image pass — jump flooding over the rear hulls'
depth image (Sec. 5.1) — and its fragment stage compares each fragment's depth with D. At
``samples > 1`` the fragment stage runs per sample (sample shading: the discard, the cut
surface's shading and its outline are decided at each sample), and a
:class:`refraster.GBufferSampling` value says where the image pass runs:

* ``"per_sample"``: each sample's rear-hull image (the pixel lattice moved by the sample's
  offset) is flooded on its own; sample ``s`` is carved by its own ``D_s``;
* ``"resolved"``: the rear hulls' multisampled depth is resolved first (``"sample_zero"``,
  ``"min"`` or ``"max"``: Vulkan's depth resolve modes; ids from sample 0), flooded once, and
  every sample of a pixel is carved by the pixel's ``D``.

Each sample's frame is the single-sample cutaway of the frame whose window is moved by minus
the sample's offset (:func:`refraster.sample_rate.window_shift`; the construction of the
per-sample allowances, ``docs/tolerance.md``), so its coverage is the rasterizer's at the
sample up to the rounding of the moved clip coordinates. The picture is the box filter of the
samples' images.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_option
from ..multisample import resolve_color, resolve_samples
from ..raster.samples import pattern
from ..sample_rate import GBufferSampling, window_shift
from .render import (DEFAULT_CUT_SURFACES, DEFAULT_CUTAWAY, DEFAULT_GHOSTS, _carve, _flood,
                     _rear, _setup)

__all__ = ["SampleCutaway", "render_cutaway_samples", "CUTAWAY_RESOLVES"]

#: The rear-hull depth resolves of the ``"resolved"`` mode (Vulkan's depth resolve modes).
CUTAWAY_RESOLVES = ("sample_zero", "min", "max")


@dataclass(frozen=True, eq=False)
class SampleCutaway:
    """A multisampled cutaway.

    Attributes
    ----------
    frames : tuple of CutawayFramebuffer
        Sample ``s``'s frame (its G-buffer, ``cutaway_depth``, ``cut_mask``, ``ghost``,
        ``image``), each ``(H, W[, C])``.
    image : (H, W, 3) float32
        The samples' images resolved by the box filter (linear, :func:`refraster.resolve_color`).
    sampling : GBufferSampling
    positions : (S, 2) int
        The samples' positions in 1/16 pixel, y down.
    """

    frames: tuple
    image: np.ndarray
    sampling: GBufferSampling
    positions: np.ndarray

    @property
    def samples(self):
        return len(self.frames)

    def stack(self, name):
        """Field ``name`` of every sample's frame stacked on a sample axis: ``(H, W, S[, C])``."""
        return np.stack([np.asarray(getattr(f, name)) for f in self.frames], axis=2)


def render_cutaway_samples(interest, secondary, *, view, proj, width, height, raster,
                           stand_ins=(), cutaway=DEFAULT_CUTAWAY,
                           cut_surfaces=DEFAULT_CUT_SURFACES, ghosts=DEFAULT_GHOSTS,
                           sampling=GBufferSampling(), background=(1.0, 1.0, 1.0)):
    """A cutaway with ``raster.samples`` samples per pixel (module docstring).

    The parameters are :func:`refraster.cutaway.render_cutaway`'s, with ``raster`` a
    multisample :class:`refraster.RasterState` (``samples`` and ``sample_locations``; the
    fragment stage runs per sample, so ``interpolation`` is the sample's) and ``sampling`` a
    :class:`refraster.GBufferSampling` (``resolve`` one of :data:`CUTAWAY_RESOLVES`).

    Returns
    -------
    SampleCutaway
    """
    sampling = as_option(sampling, GBufferSampling, "sampling")
    sampling.require_resolve(CUTAWAY_RESOLVES, "cutaways")
    ctx = _setup(interest, secondary, stand_ins, view, proj, width, height, cutaway,
                 cut_surfaces, ghosts, raster, background, "render_cutaway_samples",
                 multisample=True)
    state = ctx.multisample_state
    positions = np.asarray(pattern(state), np.int64)
    to_gl = ctx.clip_map
    from_gl = None if to_gl is None else np.linalg.inv(to_gl)
    projs = []
    for pos in positions:
        shift = window_shift(pos, ctx.width, ctx.height)
        projs.append(shift @ ctx.proj if to_gl is None else from_gl @ shift @ to_gl @ ctx.proj)
    rears = [_rear(ctx, p) for p in projs]

    def gl(p):
        return p if to_gl is None else to_gl @ p

    if sampling.mode == "per_sample":
        buffers = [_flood(ctx, d, ids, gl(p)) for (d, ids), p in zip(rears, projs)]
    elif rears[0][0] is None:
        buffers = [_flood(ctx, None, None, ctx.proj_gl)] * len(projs)
    else:
        # the rear pass stores OpenGL's window depth with the near end 0 (the far test): its
        # "max" is the farthest sample; the flood runs once, at the pixel centre's projection
        depth = resolve_samples(np.stack([np.asarray(d, np.float64) for d, _ in rears],
                                         axis=2), sampling.resolve)
        ids = rears[0][1]
        buffers = [_flood(ctx, depth, ids, ctx.proj_gl)] * len(projs)
    frames = tuple(_carve(ctx, b, p) for b, p in zip(buffers, projs))
    image = resolve_color(np.stack([f.image for f in frames], axis=2))
    return SampleCutaway(frames=frames, image=image, sampling=sampling, positions=positions)
