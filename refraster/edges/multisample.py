"""Edge maps of a multisampled G-buffer (``docs/edges.md``, "Multisampled G-buffers").

Nienhaus & Döllner's filters (Sec. 4.1.2) read one G-buffer value per pixel; the paper predates
multisampling and its pipeline stays :func:`refraster.edges.edge_map` on a single-sample frame.
On a :class:`refraster.SampleFramebuffer` a :class:`refraster.GBufferSampling` value says where
the filters run:

* ``"per_sample"``: each sample's G-buffer (the picture of sample ``s`` of every pixel: the
  pixel lattice moved by the sample's offset) is encoded and filtered on its own, and the
  ``S`` edge maps are resolved afterwards by the box filter — an edge crossing a pixel between
  its samples gives a fractional strength;
* ``"resolved"``: the G-buffer is resolved first — ``"average"``: the texture ``T_G`` (encoded
  normal and linear depth, a colour attachment) box-filtered, ids from sample 0;
  ``"sample_zero"``: every channel from sample 0 — and the filters run once per pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_option
from ..sample_rate import GBufferSampling
from .gbuffer import EdgeGBuffer, fit_near_far, gbuffer_of
from .operators import edge_map

__all__ = ["SampleEdgeMap", "edge_map_samples", "sample_gbuffers", "resolve_gbuffer",
           "EDGE_RESOLVES"]

#: The G-buffer resolve modes of the ``"resolved"`` mode: the box filter of ``T_G`` (a colour
#: attachment) or sample 0 (``min``/``max`` of encoded normals are not normals).
EDGE_RESOLVES = ("average", "sample_zero")


@dataclass(frozen=True, eq=False)
class SampleEdgeMap:
    """The edge map of a multisampled frame.

    Attributes
    ----------
    edge_map : (H, W, 4) float32
        The resolved edge map (inner strength in RGB, profile in A), as
        :func:`refraster.edges.edge_map`'s.
    samples : (H, W, S, 4) float32 or None
        ``"per_sample"``: each sample's edge map (resolved by the float64 mean of the samples,
        rounded to float32); None in the ``"resolved"`` mode.
    gbuffer : EdgeGBuffer or None
        ``"resolved"``: the resolved G-buffer the filters read; None per sample.
    sampling : GBufferSampling
    """

    edge_map: np.ndarray
    samples: np.ndarray | None
    gbuffer: EdgeGBuffer | None
    sampling: GBufferSampling


def _frame(frame):
    for attr in ("normal", "eye_depth", "object_id", "samples"):
        if not hasattr(frame, attr):
            raise TypeError(f"frame must be a refraster.SampleFramebuffer, got "
                            f"{type(frame).__name__}")
    return frame


def sample_gbuffers(frame, near, far):
    """Sample ``s``'s :class:`EdgeGBuffer` for each sample of ``frame``: its normal, eye depth
    and ids encoded as :func:`refraster.edges.edge_gbuffer` encodes a frame."""
    frame = _frame(frame)
    return [gbuffer_of(frame.normal[:, :, s], frame.eye_depth[:, :, s],
                       frame.object_id[:, :, s], near, far) for s in range(frame.samples)]


def resolve_gbuffer(gbuffers, mode):
    """One :class:`EdgeGBuffer` per pixel from the samples' (:data:`EDGE_RESOLVES`):
    ``"average"`` box-filters the encoded normal and the linear depth (float64 mean, rounded to
    float32) and takes the ids of sample 0; ``"sample_zero"`` is sample 0's G-buffer."""
    if mode not in EDGE_RESOLVES:
        raise ValueError(f"sampling.resolve must be one of {', '.join(EDGE_RESOLVES)} for "
                         f"edge maps, got {mode!r}")
    first = gbuffers[0]
    if mode == "sample_zero":
        return first
    normal = np.mean([g.normal.astype(np.float64) for g in gbuffers], axis=0)
    depth = np.mean([g.depth.astype(np.float64) for g in gbuffers], axis=0)
    return EdgeGBuffer(normal=normal.astype(np.float32), depth=depth.astype(np.float32),
                       object_id=first.object_id, near=first.near, far=first.far)


def edge_map_samples(frame, *, sampling=GBufferSampling(), near=None, far=None, bounds=None,
                     view=None, preset="paper", normal_filter=None, depth_filter=None,
                     ids=None, inner_threshold=None, profile_threshold=None, width=1, k_n=1.0,
                     k_z=1.0):
    """The edge map of a multisampled frame (module docstring).

    Parameters
    ----------
    frame : refraster.SampleFramebuffer
        From :func:`refraster.render_samples`.
    sampling : refraster.GBufferSampling
        ``mode="per_sample"`` (default) or ``"resolved"`` with ``resolve`` one of
        :data:`EDGE_RESOLVES`.
    near, far : float, optional
        The planes of the linear depth; or ``bounds`` (a world box) with the frame's ``view``
        to fit them (:func:`refraster.edges.fit_near_far`).
    preset, normal_filter, depth_filter, ids, inner_threshold, profile_threshold, width, k_n, k_z
        :func:`refraster.edges.edge_map`'s filter options, the same for every sample.

    Returns
    -------
    SampleEdgeMap
    """
    frame = _frame(frame)
    sampling = as_option(sampling, GBufferSampling, "sampling")
    sampling.require_resolve(EDGE_RESOLVES, "edge maps")
    if (near is None) != (far is None):
        raise ValueError("give both near and far, or neither")
    if near is None:
        if bounds is None or view is None:
            raise ValueError("give near and far, or bounds and view (a SampleFramebuffer "
                             "carries no meshes to fit near and far to)")
        near, far = fit_near_far(view, bounds=bounds)
    elif bounds is not None:
        raise ValueError("give bounds or near/far, not both")
    elif not far > near:
        raise ValueError(f"far must be greater than near, got near={near}, far={far}")
    options = dict(preset=preset, normal_filter=normal_filter, depth_filter=depth_filter,
                   ids=ids, inner_threshold=inner_threshold,
                   profile_threshold=profile_threshold, width=width, k_n=k_n, k_z=k_z)
    gbuffers = sample_gbuffers(frame, float(near), float(far))
    if sampling.mode == "resolved":
        gb = resolve_gbuffer(gbuffers, sampling.resolve)
        return SampleEdgeMap(edge_map=edge_map(gb, **options), samples=None, gbuffer=gb,
                             sampling=sampling)
    maps = np.stack([edge_map(g, **options) for g in gbuffers], axis=2)
    resolved = maps.astype(np.float64).mean(axis=2).astype(np.float32)
    return SampleEdgeMap(edge_map=resolved, samples=maps, gbuffer=None, sampling=sampling)
