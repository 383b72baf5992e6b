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
=============================  =============================================================
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from refraster.golden.scenes import available_scenes, as_state, raster_state

available_scenes()

from refraster.golden.io.package import npz_bytes  # noqa: E402
from refraster.golden.io.read import PATTERN_FILE  # noqa: E402
from refraster.golden.msaa_scenes import pattern_of  # noqa: E402
from refraster.golden.msaa_technique_scenes import cutaway_buffers, edges_buffers  # noqa: E402

FAULTS = ("none", "resolved_for_per_sample", "per_sample_for_resolved")


def _sampling(declared, fault):
    if fault == "resolved_for_per_sample" and declared["mode"] == "per_sample":
        return {"mode": "resolved", "resolve": "sample_zero"}
    if fault == "per_sample_for_resolved" and declared["mode"] == "resolved":
        return {"mode": "per_sample", "resolve": "sample_zero"}
    return declared


def candidate_buffers(name, fault="none"):
    """The candidate's buffers of the technique scene ``name`` with ``fault``."""
    from refraster.cutaway import render_cutaway_samples
    from refraster.golden.technique_scenes import cutaway_options
    from refraster.multisample import render_samples
    from refraster.sample_rate import GBufferSampling
    if fault not in FAULTS:
        raise ValueError(f"fault must be one of {FAULTS}, got {fault!r}")
    scene = available_scenes()[name].build()
    raster = raster_state(scene.raster)
    params = scene.parameters
    declared = params["sampling"]
    sampling = _sampling(declared, fault)
    cam = scene.camera
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


__all__ = ["FAULTS", "candidate_buffers", "write_candidate"]
