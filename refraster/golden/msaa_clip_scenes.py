"""Multisampled clip-surface golden scenes (issue 44, ``docs/clipsurface.md``, "Multisampling").

A scene of technique ``"clipsurface"`` with ``raster.samples > 1`` stores
:func:`refraster.clipsurface.render_clipped`'s per-sample buffers as ``sample<s>_<channel>``
(the channels of :data:`CLIP_SAMPLE_CHANNELS`: the multisampled G-buffer's and ``cap_mask``),
declares its sample pattern (``parameters.sample_pattern``, as the ``msaa`` scenes) and its
shading rate (``raster.interpolation``: ``"sample"`` is sample rate, ``"center"`` pixel rate
at the centre; ``docs/multisample.md``, "Fragment stages per sample"). Its allowances are the
single-sample clip-surface allowances derived once per sample
(:func:`refraster.golden.allowances.samples.msaa_allowances`), the clip decision and the parity
test at the point the rate evaluates them.
"""

from __future__ import annotations

import numpy as np

from ..raster.state import RasterState
from .msaa_scenes import SAMPLE_CHANNELS, pattern_of, sample_buffer
from .scenes import GoldenScene, raster_state, register_scene

__all__ = ["CLIP_SAMPLE_CHANNELS", "clip_sample_buffers", "msaa_clip_scene_names"]

#: The per-sample channels a multisampled clip-surface golden stores.
CLIP_SAMPLE_CHANNELS = (*SAMPLE_CHANNELS, "cap_mask")


def clip_sample_buffers(frame):
    """``sample<s>_<channel>`` of a :class:`refraster.clipsurface.ClippedSampleFramebuffer`."""
    out = {}
    arrays = frame.arrays()
    for s in range(frame.samples):
        for ch in CLIP_SAMPLE_CHANNELS:
            a = np.asarray(arrays[ch])[:, :, s]
            out[sample_buffer(s, ch)] = (a.astype(np.int32) if ch in ("prim_id", "object_id")
                                         else np.ascontiguousarray(a))
    return out


def _clip_msaa_scene(raster):
    """The building cut by a Perlin clip surface with diffuse caps (``clipsurface_building``'s
    scene, smaller) at ``raster``'s samples and shading rate."""
    from ..clipsurface import render_clipped
    from .technique_scenes import _clip_ids, clip_caps, clip_export, perlin_building_clip
    state = raster_state(raster)
    draws, camera, surface, caps, clip, offset_map = perlin_building_clip(96, 72)
    fb = render_clipped([d.mesh for d in draws], clip, **camera.kwargs, caps=clip_caps(caps),
                        space=caps["space"], raster=RasterState(**raster))
    surfaces = [{**surface, "offset_map": "offset_map"}]
    backend_params, backend_maps = clip_export(draws, [clip], caps, surfaces)
    rng = _clip_ids(draws, [clip], caps["subdivision"])
    ids = {sample_buffer(s, ch): rng[ch] for s in range(fb.samples)
           for ch in ("prim_id", "object_id")}
    from .io.buffers import GBUFFER_KINDS
    kinds = {sample_buffer(s, ch): GBUFFER_KINDS.get(ch, "bool") for s in range(fb.samples)
             for ch in CLIP_SAMPLE_CHANNELS}
    return GoldenScene(technique="clipsurface", camera=camera, draws=draws,
                       buffers=clip_sample_buffers(fb), ids=ids, kinds=kinds,
                       parameters={"surfaces": surfaces, **caps, **backend_params,
                                   "sample_pattern": pattern_of(state)},
                       maps={"offset_map": offset_map, **backend_maps}, geometry=False,
                       raster=dict(raster))


_RATES = {
    "msaa4_clipsurface_sample": (
        {"samples": 4, "interpolation": "sample"},
        "sample rate: the clip test and the caps' parity test at each sample (Vulkan's "
        "standard positions)"),
    "msaa4_clipsurface_pixel": (
        {"samples": 4},
        "pixel rate: the clip test and the caps' parity test at the pixel centre, each "
        "fragment's decision written to the samples it covers (Vulkan's standard positions)"),
    "msaa4_clipsurface_centroid": (
        {"samples": 4, "interpolation": "centroid"},
        "pixel rate at a centroid point: the clip test and the caps' parity test at a point "
        "inside both the pixel and the primitive, each fragment's decision written to the "
        "samples it covers (Vulkan's standard positions)"),
    "msaa4gl_clipsurface_sample": (
        {"samples": 4, "sample_locations": "gl_llvmpipe", "interpolation": "sample"},
        "sample rate (GL's GL_SAMPLE_SHADING at 1.0), at llvmpipe's GL positions"),
    "msaa4gl_clipsurface_pixel": (
        {"samples": 4, "sample_locations": "gl_llvmpipe"},
        "pixel rate (no sample shading), at llvmpipe's GL positions"),
    "msaa4gl_clipsurface_centroid": (
        {"samples": 4, "sample_locations": "gl_llvmpipe", "interpolation": "centroid"},
        "pixel rate at a centroid point (inside both the pixel and the primitive), at "
        "llvmpipe's GL positions"),
}


def _register(name):
    raster, how = _RATES[name]

    @register_scene(name, technique="clipsurface", samples=raster["samples"],
                    description=f"Building cut by a Perlin 2.5D clip surface with diffuse caps "
                                f"at 4 samples, {how}: per-sample buffers.")
    def _scene():
        return _clip_msaa_scene(raster)
    return _scene


for _name in _RATES:
    _register(_name)


def msaa_clip_scene_names():
    """The registered multisampled clip-surface scenes."""
    return list(_RATES)
