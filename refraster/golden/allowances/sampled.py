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
  sample 0's interval;
* ``"resolved"`` with ``resolve = "average"``: the edge map of the box-filtered G-buffer, from
  every sample's options (:func:`.edges.mean_edge_map_bounds`).

A cutaway flooded once from rear hulls resolved by ``sample_zero`` floods sample 0's seed
images; by ``min`` or ``max``, the seed images of :func:`resolved_seed_images` (the resolve of
the samples' depth intervals, the seeds sample 0's). Both at the pixel centre's projection.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .samples import sample_shift

__all__ = ["sampled_allowances", "resolved_seed_images", "MEAN_ROUNDING"]

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


def _moved(scene, pos):
    """``scene``'s camera moved so that its pixel centres are the sample at ``pos``."""
    from ...camera import Camera
    cam = scene.camera
    return Camera(cam.view, sample_shift(pos, cam.width, cam.height) @ cam.proj, cam.width,
                  cam.height)


def resolved_seed_images(images, resolve):
    """The seed images (:func:`.cutaway._seed_images` with ``with_least``) of rear hulls
    resolved by ``resolve`` from each sample's ``images[s] = (big, big_seed, small,
    small_seed, least)``.

    The seeds are sample 0's (ids take sample 0), so the seedable and the sure pixels are
    sample 0's. The resolved depth is ``R_s z_s`` (``R`` = min or max, increasing in each
    sample's depth ``z_s``), and ``z_s`` lies in ``[ℓ_s, big_s]``: ``ℓ_s`` is ``small_s``
    where a face surely covers the sample, else the clear value 0 (the rear pass clears to the
    near end) for ``s > 0`` — and for sample 0, which is a seed only where it is covered, the
    least depth a covering face may show (``least_0``); ``big_s`` is the largest depth a face
    may show there, 0 where none may cover it. So the resolved depth lies in
    ``[R_s ℓ_s, R_s big_s]``, returned as the smallest (and least) and the largest image."""
    if resolve not in ("min", "max"):
        raise ValueError(f"resolved_seed_images: resolve must be 'min' or 'max', got "
                         f"{resolve!r}")
    red = np.minimum.reduce if resolve == "min" else np.maximum.reduce
    big = red([im[0] for im in images])
    low = [np.where(images[0][3], images[0][2], images[0][4])]
    low += [np.where(im[3], im[2], 0.0) for im in images[1:]]
    low = red(low)
    return big, images[0][1], low, images[0][3], low


def _resolved_surface(scene, plain, overrides, params, positions):
    """The D interval of a cutaway whose rear hulls are resolved (``sampling.resolve``) and
    flooded once with the pixel centre's projection (:func:`.cutaway.cutaway_bounds` with
    ``flood_camera``): ``sample_zero``, sample 0's rear hulls (the scene moved by sample 0's
    offset); ``min``/``max``, the seed images of :func:`resolved_seed_images`."""
    from ...conformance import edge_epsilon
    from .cutaway import _seed_images, cutaway_bounds
    from .precision import candidate_bits
    resolve = scene.parameters["sampling"].get("resolve")
    if resolve not in ("sample_zero", "min", "max"):
        raise ValueError(f"no allowance for a cutaway surface flooded from rear hulls resolved "
                         f"by {resolve!r} (sample_zero, min, max)")
    cam = scene.camera
    eps = edge_epsilon(cam.width, cam.height, min_bits=candidate_bits())

    def sub(pos):
        return dataclasses.replace(scene, camera=_moved(scene, pos), parameters=params,
                                   raster=overrides)
    if resolve == "sample_zero":
        return cutaway_bounds(sub(positions[0]), eps, flood_camera=cam)
    interest = set(params["interest"])
    images = [_seed_images(sub(pos), interest, eps, with_least=True) for pos in positions]
    return cutaway_bounds(sub(positions[0]), eps, flood_camera=cam,
                          seeds=resolved_seed_images(images, resolve))


def sampled_allowances(scene, raster):
    """Per-sample allowances of a technique scene with ``raster.samples > 1`` (module
    docstring). Returns ``(arrays, info, checks)`` as :func:`.core.gl_allowances`."""
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
    per_bufs = []
    for s, pos in enumerate(positions):
        moved = _moved(scene, pos)
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
        per_bufs.append(bufs)
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
        elif sampling.get("resolve") == "average":
            from ...edges import fit_near_far
            from .edges import mean_edge_map_bounds
            near, far = fit_near_far(cam.view, bounds=np.asarray(params["bounds"], np.float64))
            lo, hi = mean_edge_map_bounds(
                per, per_bufs, technique_params, near, far,
                gbuffer_format=params.get("gbuffer_format", "rgba8"),
                output_format=params.get("output_format", "rgba8"))
        else:
            raise ValueError(f"no allowance for an edge map of the G-buffer resolved by "
                             f"{sampling.get('resolve')!r} (sample_zero, average)")
        arrays["edge_map_lo"], arrays["edge_map_hi"] = lo, hi
        checks["edge_map"] = {"checks": ["bounds"], "lo": "edge_map_lo", "hi": "edge_map_hi"}
    return arrays, info, checks
