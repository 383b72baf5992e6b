"""Allowances of technique goldens at ``samples > 1`` (issue 44; ``docs/tolerance.md``,
"Techniques at sample rate"): the single-sample ones, derived per sample.

Under sample-rate interpolation sample ``s`` of every pixel is the pixel centre of the frame
whose window is moved by minus the sample's offset (:func:`.samples.sample_shift`), so the
technique's single-sample allowances — the G-buffer's, the edge map's intervals
(:mod:`.edges`), the cutaway's surface, cut and ghost bounds (:mod:`.cutaway`, :mod:`.clip`,
:mod:`.ghosts`) — are derived once per sample on that moved scene with the sample's own
buffers (``sample<s>_<name>``), stored as ``s<s>_<name>``, and read by the sample's buffers
through ``"sample": s``.

The resolved edge map (``edge_map``):

* ``sampling.mode = "per_sample"``: the float64 mean of the samples' edge maps rounded to
  float32; the mean is increasing in every sample, so its interval is the mean of the
  samples' lower ends and of their upper ends (rounded outwards, plus 1e−6 for a float32
  mean);
* ``"resolved"`` with ``resolve = "sample_zero"``: the edge map of sample 0's G-buffer, so
  sample 0's interval.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .samples import sample_shift

__all__ = ["sampled_allowances", "MEAN_ROUNDING"]

#: A float32 mean of S float32 values differs from the float64 mean by at most this.
MEAN_ROUNDING = 1e-6


def _outward(lo, hi):
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-1)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(2)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def _sample_may(scene, bufs):
    """A sample's technique "may" pixels: the cutaway's (the cut region's changes and the
    ghost lines' pixels, as ``technique_scenes._cutaway_golden``); none for edge maps."""
    if scene.technique != "cutaway":
        return None
    from .core import changes
    edge = changes(np.asarray(bufs["cut_mask"], np.bool_))
    return edge | (np.asarray(bufs["ghost"]) > 0)


def _resolved_surface(scene, plain, overrides, params, positions):
    """The D interval of a cutaway whose rear hulls are resolved by ``sample_zero`` and
    flooded once: sample 0's rear hulls (the scene moved by sample 0's offset) flooded with the
    pixel centre's projection (:func:`.cutaway.cutaway_bounds` with ``flood_camera``)."""
    from ...camera import Camera
    from ...conformance import edge_epsilon
    from .cutaway import cutaway_bounds
    from .precision import candidate_bits
    if scene.parameters["sampling"].get("resolve") != "sample_zero":
        raise ValueError("no allowance for a cutaway surface flooded from rear hulls resolved "
                         f"by {scene.parameters['sampling'].get('resolve')!r} (sample_zero "
                         "only)")
    cam = scene.camera
    moved = Camera(cam.view, sample_shift(positions[0], cam.width, cam.height) @ cam.proj,
                   cam.width, cam.height)
    sub = dataclasses.replace(scene, camera=moved, parameters=params, raster=overrides)
    eps = edge_epsilon(cam.width, cam.height, min_bits=candidate_bits())
    return cutaway_bounds(sub, eps, flood_camera=cam)


def sampled_allowances(scene, raster):
    """Per-sample allowances of a technique scene with ``raster.samples > 1`` (module
    docstring). Returns ``(arrays, info, checks)`` as :func:`.core.gl_allowances`."""
    from ...camera import Camera
    from ..scenes import DEFAULT_RASTER
    from .conventions import is_gl
    from .core import gl_allowances
    from .samples import _plain_raster
    if not is_gl(raster) or raster.get("depth_func", "less") != "less":
        raise ValueError("the per-sample technique allowances are derived in OpenGL's "
                         "conventions with depth_func 'less'; this scene's raster differs")
    if raster.get("interpolation") != "sample":
        raise ValueError("the per-sample technique allowances need raster.interpolation "
                         "'sample' (each sample's G-buffer the frame moved by its offset), got "
                         f"{raster.get('interpolation')!r}")
    params = scene.parameters
    positions = params["sample_pattern"]["positions"]
    sampling = params["sampling"]
    cam = scene.camera
    plain = _plain_raster(raster)
    overrides = {k: v for k, v in plain.items() if v != DEFAULT_RASTER.get(k)}
    technique_params = {k: v for k, v in params.items()
                        if k not in ("sample_pattern", "sampling")}
    arrays, checks, info, per = {}, {}, None, []
    d_bounds = None
    if scene.technique == "cutaway" and sampling["mode"] == "resolved":
        d_bounds = _resolved_surface(scene, plain, overrides, technique_params, positions)
    for s, pos in enumerate(positions):
        moved = Camera(cam.view, sample_shift(pos, cam.width, cam.height) @ cam.proj,
                       cam.width, cam.height)
        q = f"sample{s}_"
        bufs = {k[len(q):]: v for k, v in scene.buffers.items() if k.startswith(q)}
        derive = dict(bufs)
        if "edge_map" in scene.buffers and "edge_map" not in bufs:
            # the resolved mode stores no sample's edge map; its interval is still derived
            derive["edge_map"] = scene.buffers["edge_map"]
        sub = dataclasses.replace(scene, camera=moved, buffers=derive,
                                  parameters=technique_params, raster=overrides,
                                  may=_sample_may(scene, bufs), kinds={}, ids={})
        a, info_s, ch_s = gl_allowances(sub, plain, d_bounds)
        info = info if info is not None else info_s
        per.append(a)
        for k, v in a.items():
            arrays[f"s{s}_{k}"] = v
        for key, spec in ch_s.items():
            if key in bufs:
                checks[f"{q}{key}"] = {**spec, "sample": s}
    arrays["id_may"] = np.logical_or.reduce([a["id_may"] for a in per])
    arrays["may"] = np.logical_or.reduce([a["may"] for a in per])
    if "edge_map" in scene.buffers:
        if "edge_map_lo" not in per[0]:
            raise ValueError("the edge map's operator has no per-sample interval "
                             "(allowances.edges.supported)")
        if sampling["mode"] == "per_sample":
            lo = np.mean([a["edge_map_lo"].astype(np.float64) for a in per], axis=0)
            hi = np.mean([a["edge_map_hi"].astype(np.float64) for a in per], axis=0)
            lo, hi = _outward(np.maximum(lo - MEAN_ROUNDING, 0.0),
                              np.minimum(hi + MEAN_ROUNDING, 1.0))
        elif sampling.get("resolve") == "sample_zero":
            lo, hi = per[0]["edge_map_lo"], per[0]["edge_map_hi"]
        else:
            raise ValueError(f"no allowance for an edge map of the G-buffer resolved by "
                             f"{sampling.get('resolve')!r} (sample_zero only)")
        arrays["edge_map_lo"], arrays["edge_map_hi"] = lo, hi
        checks["edge_map"] = {"checks": ["bounds"], "lo": "edge_map_lo", "hi": "edge_map_hi"}
    return arrays, info, checks
