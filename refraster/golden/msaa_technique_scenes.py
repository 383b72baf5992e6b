"""Technique golden scenes at ``samples > 1`` (issue 44; ``docs/golden.md``, "Multisampled
goldens"): edge maps and cutaways on multisampled G-buffers, each in the two modes of
:class:`refraster.GBufferSampling`.

A scene stores each sample's buffers as ``sample<s>_<name>`` (the technique's single-sample
buffers at that sample: the G-buffer, and ``edge_map`` or ``cutaway_depth``, ``cut_mask``,
``ghost``) and the technique's resolved output (``edge_map``: the box filter of the samples'
edge maps, or the edge map of the resolved G-buffer). It declares its sample pattern
(``sample_pattern``) and its sampling (``sampling``: ``{"mode", "resolve"}``) in its
parameters. The 4× scenes use llvmpipe's positions (``"gl_llvmpipe"``) and sample-rate
interpolation: each sample's G-buffer is then the single-sample G-buffer of the frame moved by
the sample's offset, and its allowances are the single-sample ones derived on that frame
(:mod:`refraster.golden.allowances.sampled`).

Registered with ``samples=4`` (:func:`refraster.golden.scenes.register_scene`), so the
technique pass/fail matrix at 4× (``docs/backends.md``) lists them.
"""

from __future__ import annotations

import numpy as np

from .io.buffers import infer_kind
from .msaa_scenes import pattern_of
from .scenes import Draw, GoldenScene, _framed, as_state, prepare_draws, raster_state, \
    register_scene

__all__ = ["SAMPLED_RASTER", "sampled_scene_names", "edges_buffers", "cutaway_buffers"]

#: The raster fields of the 4× technique scenes.
SAMPLED_RASTER = {"samples": 4, "sample_locations": "gl_llvmpipe", "interpolation": "sample"}
#: The G-buffer channels each sample stores.
_GBUFFER = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
            "barycentric")


def sampled_scene_names(technique=None):
    """The registered technique scenes with more than one sample (optionally of one
    technique), in registration order; the multisampled clip-surface scenes
    (:mod:`.msaa_clip_scenes`, allowances of their own) are not among them."""
    from .scenes import SCENES
    return [n for n, e in SCENES.items() if e.samples > 1
            and e.technique not in ("msaa", "clipsurface")
            and (technique is None or e.technique == technique)]


def _sample_keys(per_sample, kinds, ids, n_draws, n_faces):
    out = {}
    for s, bufs in enumerate(per_sample):
        for k, a in bufs.items():
            key = f"sample{s}_{k}"
            out[key] = a
            kinds[key] = infer_kind(k, a)
            if k == "prim_id":
                ids[key] = (-1, n_faces - 1)
            elif k == "object_id":
                ids[key] = (-1, n_draws - 1)
    return out


def edges_buffers(frame, params, sampling):
    """The buffers of an edge scene from a :class:`refraster.SampleFramebuffer`: each sample's
    G-buffer (and edge map, per sample) and the resolved ``edge_map``."""
    from ..edges import edge_map_samples
    from ..sample_rate import GBufferSampling
    res = edge_map_samples(frame, bounds=np.array(params["bounds"]), view=params["_view"],
                           sampling=GBufferSampling(**sampling),
                           normal_filter=params["normal_filter"],
                           depth_filter=params["depth_filter"], ids=params["ids"],
                           inner_threshold=params["inner_threshold"],
                           profile_threshold=params["profile_threshold"],
                           width=params["width"], k_n=params["k_n"], k_z=params["k_z"])
    per = []
    for s in range(frame.samples):
        b = {ch: np.ascontiguousarray(getattr(frame, ch)[:, :, s]) for ch in _GBUFFER}
        b["prim_id"] = b["prim_id"].astype(np.int32)
        b["object_id"] = b["object_id"].astype(np.int32)
        if res.samples is not None:
            b["edge_map"] = np.ascontiguousarray(res.samples[:, :, s])
        per.append(b)
    return per, res.edge_map


def _sampled_scene(technique, camera, draws, per, n_faces, params, sampling, state,
                   unorm=(), **extra):
    """A 4× technique GoldenScene from each sample's buffers ``per`` (``sample<s>_<name>``;
    the names in ``unorm`` of kind ``"unorm"``) and the technique's parameters, with the
    scene's sample pattern and sampling stored beside them; ``extra``: the resolved buffers
    (``buffers=``) and other GoldenScene fields."""
    kinds, ids = {}, {}
    buffers = _sample_keys(per, kinds, ids, len(draws), n_faces)
    buffers.update(extra.pop("buffers", {}))
    for s in range(len(per)):
        for name in unorm:
            kinds[f"sample{s}_{name}"] = "unorm"
    params.update(sample_pattern=pattern_of(state), sampling=dict(sampling))
    return GoldenScene(technique=technique, camera=camera, draws=draws, buffers=buffers,
                       parameters=params, raster=dict(SAMPLED_RASTER), kinds=kinds, ids=ids,
                       may_radius=2, **extra)


def _edges_scene(sampling):
    from ..multisample import render_samples
    from ..scenes import solid
    state = raster_state(SAMPLED_RASTER)
    draws = prepare_draws([Draw("building", solid("building"))])
    camera = _framed([d.mesh for d in draws], 96, 72, (1.2, 0.9, 1.6))
    frame = render_samples([d.mesh for d in draws], **camera.kwargs,
                           model=[d.model for d in draws], raster=as_state(state))
    lo, hi = draws[0].mesh.vertices.min(axis=0), draws[0].mesh.vertices.max(axis=0)
    params = dict(bounds=[lo.tolist(), hi.tolist()], preset="paper", normal_filter="diagonal",
                  depth_filter="diagonal", ids=False, inner_threshold=0.0,
                  profile_threshold=0.0, width=1, k_n=1.0, k_z=1.0, gbuffer_format="rgba8",
                  output_format="rgba8")
    per, resolved = edges_buffers(frame, {**params, "_view": camera.view}, sampling)
    return _sampled_scene("edges", camera, draws, per, len(draws[0].mesh.faces), params,
                          sampling, state, buffers={"edge_map": resolved})


def cutaway_buffers(result):
    """Each sample's buffers of a :class:`refraster.cutaway.SampleCutaway`: the G-buffer,
    ``cutaway_depth``, ``cut_mask`` and ``ghost`` (the single-sample golden's)."""
    per = []
    for f in result.frames:
        b = {k: np.ascontiguousarray(v) for k, v in f.arrays().items()}
        b.update(cutaway_depth=f.cutaway_depth, cut_mask=f.cut_mask, ghost=f.ghost)
        per.append(b)
    return per


def _cutaway_scene(sampling):
    from ..cutaway import render_cutaway_samples
    from ..sample_rate import GBufferSampling
    from .technique_scenes import _cutaway_variant_scene, cutaway_options
    single = _cutaway_variant_scene("jfa+1")
    named = {d.name: d.mesh for d in single.draws}
    params = dict(single.parameters)
    state = raster_state(SAMPLED_RASTER)
    res = render_cutaway_samples([named[n] for n in params["interest"]],
                                 [named[n] for n in params["secondary"]],
                                 **single.camera.kwargs, **cutaway_options(params),
                                 raster=as_state(state), sampling=GBufferSampling(**sampling))
    return _sampled_scene("cutaway", single.camera, single.draws, cutaway_buffers(res),
                          max(len(d.mesh.faces) for d in single.draws), params, sampling,
                          state, unorm=("cutaway_depth", "ghost"), geometry=False)


#: name → (technique, sampling, description) of the 4× technique scenes.
_SAMPLED = {
    "edges4gl_building_per_sample": (
        "edges", {"mode": "per_sample", "resolve": "sample_zero"},
        "The paper's edge map of the building (edges_building's operator, 96×72) at 4 "
        "samples (llvmpipe's positions, sample-rate interpolation), per sample: each "
        "sample's G-buffer filtered, the four edge maps resolved by the box filter."),
    "edges4gl_building_resolved": (
        "edges", {"mode": "resolved", "resolve": "sample_zero"},
        "edges4gl_building_per_sample's frame with the edge map of the resolved G-buffer "
        "(resolve mode sample_zero: every channel from sample 0), filtered once per pixel."),
    "cutaway4gl_shells_per_sample": (
        "cutaway", {"mode": "per_sample", "resolve": "sample_zero"},
        "cutaway_shells (jfa+1, 96×72) at 4 samples (llvmpipe's positions, sample shading), "
        "per sample: each sample's rear hulls flooded to its own cutaway surface, each "
        "sample carved by its own."),
    "cutaway4gl_shells_resolved": (
        "cutaway", {"mode": "resolved", "resolve": "sample_zero"},
        "cutaway4gl_shells_per_sample's frame with one cutaway surface flooded from the rear "
        "hulls resolved by sample_zero (sample 0's), at the pixel centre's projection: every "
        "sample of a pixel carved by the pixel's."),
    "edges4gl_building_resolved_average": (
        "edges", {"mode": "resolved", "resolve": "average"},
        "edges4gl_building_per_sample's frame with the edge map of the G-buffer resolved by "
        "average (the box filter of the encoded normal and the linear depth; ids from "
        "sample 0), filtered once per pixel."),
    "cutaway4gl_shells_resolved_min": (
        "cutaway", {"mode": "resolved", "resolve": "min"},
        "cutaway4gl_shells_resolved with the rear hulls' depth resolved by min (the nearest "
        "sample, the clear value 0 where a sample is uncovered; ids from sample 0), flooded "
        "once at the pixel centre's projection."),
    "cutaway4gl_shells_resolved_max": (
        "cutaway", {"mode": "resolved", "resolve": "max"},
        "cutaway4gl_shells_resolved with the rear hulls' depth resolved by max (the farthest "
        "sample; ids from sample 0), flooded once at the pixel centre's projection."),
}
_BUILDERS = {"edges": _edges_scene, "cutaway": _cutaway_scene}


def _register(name):
    technique, sampling, description = _SAMPLED[name]

    @register_scene(name, technique=technique, samples=SAMPLED_RASTER["samples"],
                    description=description)
    def _scene():
        return _BUILDERS[technique](dict(sampling))
    return _scene


for _name in _SAMPLED:
    _register(_name)
