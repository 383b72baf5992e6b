"""A fault harness for the technique goldens at 4× (issue 44): refraster's own multisampled
technique frame of a golden scene, written as a candidate directory, right or with one planted
sampling bug. Every candidate states the golden's sample pattern.

=============================  =============================================================
fault                          what the candidate computes
=============================  =============================================================
``none``                       the scene's declared sampling
``resolved_for_per_sample``    edges: the edge map of the resolved G-buffer (sample 0's) where
                               per-sample is declared, written for every sample and resolved;
                               cutaways: one cutaway surface flooded from the resolved rear
                               hulls (sample 0's), shared by every sample
``per_sample_for_resolved``    the edge map per sample where the resolved G-buffer's is
                               declared; cutaways: each sample flooded to its own surface
                               where one surface from the resolved rear hulls is declared
``other_resolve``              a resolved scene with another resolve mode than declared:
                               edges ``average`` ↔ ``sample_zero``; cutaways ``min`` ↔
                               ``max``, ``sample_zero`` → ``min``
``average_depth_resolve``      cutaways: the rear hulls' depth resolved by the average of the
                               samples (no API's depth resolve) where ``min``, ``max`` or
                               ``sample_zero`` is declared
``wrong_sample``               the resolved G-buffer (edges) or rear hulls (cutaways) taken
                               from sample 1 where ``sample_zero`` is declared
=============================  =============================================================

``RESOLVE_FAULTS`` apply to the ``"resolved"`` scenes only (a per-sample scene's candidate is
its right frame).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from refraster.golden.scenes import available_scenes, as_state, raster_state

available_scenes()

from refraster.golden.io.package import npz_bytes  # noqa: E402
from refraster.golden.io.read import PATTERN_FILE  # noqa: E402
from refraster.golden.msaa_scenes import pattern_of  # noqa: E402
from refraster.golden.msaa_technique_scenes import cutaway_buffers, edges_buffers  # noqa: E402

FAULTS = ("none", "resolved_for_per_sample", "per_sample_for_resolved", "other_resolve",
          "average_depth_resolve", "wrong_sample")
RESOLVE_FAULTS = ("other_resolve", "average_depth_resolve", "wrong_sample")
_OTHER = {"edges": {"average": "sample_zero", "sample_zero": "average"},
          "cutaway": {"min": "max", "max": "min", "sample_zero": "min"}}


def _sampling(declared, fault, technique):
    if fault == "other_resolve" and declared["mode"] == "resolved":
        return {**declared, "resolve": _OTHER[technique][declared["resolve"]]}
    if fault == "resolved_for_per_sample" and declared["mode"] == "per_sample":
        return {"mode": "resolved", "resolve": "sample_zero"}
    if fault == "per_sample_for_resolved" and declared["mode"] == "resolved":
        return {"mode": "per_sample", "resolve": "sample_zero"}
    return declared


def candidate_buffers(name, fault="none"):
    """The candidate's buffers of the technique scene ``name`` with ``fault``."""
    if fault not in FAULTS:
        raise ValueError(f"fault must be one of {FAULTS}, got {fault!r}")
    scene = available_scenes()[name].build()
    raster = raster_state(scene.raster)
    params = scene.parameters
    declared = params["sampling"]
    sampling = _sampling(declared, fault, scene.technique)
    cam = scene.camera
    with _planted(fault, declared):
        return _buffers(scene, raster, params, declared, sampling, cam)


@contextlib.contextmanager
def _planted(fault, declared):
    """The resolve faults planted in refraster's own resolve functions for one candidate."""
    import refraster.cutaway.multisample as cm
    import refraster.edges.multisample as em
    saved = cm.resolve_samples, em.resolve_gbuffer
    if fault == "average_depth_resolve" and declared["mode"] == "resolved":
        cm.resolve_samples = lambda depth, mode: depth.mean(axis=2)
    if fault == "wrong_sample" and declared["mode"] == "resolved" \
            and declared["resolve"] == "sample_zero":
        cm.resolve_samples = lambda depth, mode: depth[:, :, 1]
        em.resolve_gbuffer = lambda gbuffers, mode: gbuffers[1]
    try:
        yield
    finally:
        cm.resolve_samples, em.resolve_gbuffer = saved


def _buffers(scene, raster, params, declared, sampling, cam):
    from refraster.cutaway import render_cutaway_samples
    from refraster.golden.technique_scenes import cutaway_options
    from refraster.multisample import render_samples
    from refraster.sample_rate import GBufferSampling
    if scene.technique == "edges":
        frame = render_samples([d.mesh for d in scene.draws], **cam.kwargs,
                               model=[d.model for d in scene.draws], raster=as_state(raster))
        per, resolved = edges_buffers(frame, {**params, "_view": cam.view}, sampling)
        if declared["mode"] == "per_sample" and sampling["mode"] == "resolved":
            # a backend that filters the resolved G-buffer writes its map for every sample
            for b in per:
                b["edge_map"] = resolved
        if declared["mode"] == "resolved":
            for b in per:
                b.pop("edge_map", None)
    else:
        named = {d.name: d.mesh for d in scene.draws}
        res = render_cutaway_samples([named[n] for n in params["interest"]],
                                     [named[n] for n in params["secondary"]], **cam.kwargs,
                                     **cutaway_options(params), raster=as_state(raster),
                                     sampling=GBufferSampling(**sampling))
        per, resolved = cutaway_buffers(res), None
    out = {f"sample{s}_{k}": v for s, b in enumerate(per) for k, v in b.items()}
    if resolved is not None:
        out["edge_map"] = resolved
    return out, pattern_of(raster)


def write_candidate(out, names, fault="none"):
    """Write a candidate directory ``out`` for the scenes ``names`` with ``fault``."""
    out = Path(out)
    for name in names:
        buffers, declared = candidate_buffers(name, fault)
        d = out / name
        d.mkdir(parents=True, exist_ok=True)
        (d / "buffers.npz").write_bytes(npz_bytes(buffers))
        (d / PATTERN_FILE).write_text(json.dumps(declared))
    return out


__all__ = ["FAULTS", "RESOLVE_FAULTS", "candidate_buffers", "write_candidate"]
