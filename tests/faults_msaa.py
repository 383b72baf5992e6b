"""A fault harness for multisampled goldens (issue 43, item 3): refraster's own multisampled
frame of a golden scene, written as a candidate directory, right or with one planted MSAA bug.

Every candidate states the golden's sample pattern (``<scene>/sample_pattern.json``) — a
faulty backend believes it uses it — so the compare checks the buffers, not the statement:

====================  ==========================================================================
fault                 what the candidate's frame is
====================  ==========================================================================
``none``              refraster's frame (:func:`refraster.render_samples` of the scene)
``pattern_mirrored``  rendered with the pattern mirrored top to bottom (``(x, y) → (x, 16 − y)``:
                      llvmpipe's GL picture for Vulkan's 4× positions, and vice versa)
``depth_per_pixel``   each sample's window depth is its face's depth at the pixel centre (the
                      depth a GPU that tests depth per pixel instead of per sample writes)
``srgb_resolve``      the colour resolved in sRGB space (decoded, averaged, encoded:
                      :func:`refraster.resolve_color` with ``"srgb"``) instead of linear
``centre_coverage``   coverage (and depth) taken at the pixel centre only: every sample at
                      (8, 8)
====================  ==========================================================================
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from refraster.golden.scenes import as_state, available_scenes, draw_meshes, raster_state

# every scene module registers in its own order first (the registry's order is the docs' scene
# table's): naming msaa_scenes before the others would register its scenes ahead of theirs
available_scenes()

from refraster.golden.io.package import npz_bytes  # noqa: E402
from refraster.golden.io.read import PATTERN_FILE  # noqa: E402
from refraster.golden.msaa_scenes import pattern_of, sample_buffer, sample_buffers  # noqa: E402

FAULTS = ("none", "pattern_mirrored", "depth_per_pixel", "srgb_resolve", "centre_coverage")
#: The buffer a fault's failure names first (every sample's, or the resolve).
NAMES = {"pattern_mirrored": "prim_id", "depth_per_pixel": "depth",
         "srgb_resolve": "color", "centre_coverage": "prim_id"}


def _frame(scene, state):
    from refraster.multisample import render_samples
    cam = scene.camera
    raster = raster_state(scene.raster)
    return render_samples(draw_meshes(scene.draws, raster), **cam.kwargs,
                          model=[d.model for d in scene.draws], raster=state)


def _centre_depth(scene, state, frame):
    """Each covered sample's window depth at the pixel centre, of the face it shows: window
    depth is affine in the window, the perspective-correct barycentrics at the centre (the
    ``"center"`` interpolation of the sample's own winner) give the screen-space ones as
    ``λ_i ∝ β_i·w_i``."""
    from refraster.raster import prepare
    cam = scene.camera
    prep = prepare(draw_meshes(scene.draws, raster_state(scene.raster)), **cam.kwargs,
                   model=[d.model for d in scene.draws],
                   raster=dataclasses.replace(state, samples=1, sample_locations="standard",
                                              interpolation="center"))
    prim = frame.prim_id.astype(np.int64)
    obj = frame.object_id.astype(np.int64)
    cov = prim >= 0
    g = np.asarray(prep.face_offsets, np.int64)[np.maximum(obj, 0)] + np.maximum(prim, 0)
    clip = prep.clip[prep.triangles.faces[g[cov]]].astype(np.float64)        # (n, 3, 4)
    beta = frame.barycentric[cov].astype(np.float64)
    lam = beta * clip[:, :, 3]
    lam /= lam.sum(axis=1, keepdims=True)
    zw = 0.5 * clip[:, :, 2] / clip[:, :, 3] + 0.5
    depth = frame.depth.copy()
    depth[cov] = np.clip((lam * zw).sum(axis=1), 0.0, 1.0).astype(np.float32)
    return depth


def candidate_buffers(name, fault="none", **changes):
    """The candidate's buffers of golden scene ``name`` with ``fault`` (module docstring) and
    the pattern it states; ``changes``: raster fields the candidate renders with instead
    (``interpolation="center"``, say)."""
    if fault not in FAULTS:
        raise ValueError(f"fault must be one of {FAULTS}, got {fault!r}")
    scene = available_scenes()[name].build()
    raster = raster_state(scene.raster)
    state = dataclasses.replace(as_state(raster), **changes)
    positions = pattern_of(raster)["positions"]
    if fault == "pattern_mirrored":
        state = dataclasses.replace(state, sample_locations=tuple(
            (x, 16 - y) for x, y in positions))
    elif fault == "centre_coverage":
        state = dataclasses.replace(state, sample_locations=tuple((8, 8) for _ in positions))
    frame = _frame(scene, state)
    buffers = sample_buffers(frame)
    if fault == "depth_per_pixel":
        depth = _centre_depth(scene, state, frame)
        for s in range(frame.samples):
            buffers[sample_buffer(s, "depth")] = np.ascontiguousarray(depth[:, :, s])
    elif fault == "srgb_resolve":
        from refraster.multisample import resolve_color
        buffers["color"] = resolve_color(np.asarray(frame.color, np.float32), "srgb")
    return buffers, pattern_of(raster)


def write_candidate(out, names, fault="none", *, pattern=None, **changes):
    """Write a candidate directory ``out`` for the golden scenes ``names`` with ``fault``;
    ``pattern`` (``{"samples", "positions"}``) overrides the pattern it states, ``changes``
    the raster fields it renders with (:func:`candidate_buffers`)."""
    out = Path(out)
    for name in names:
        buffers, declared = candidate_buffers(name, fault, **changes)
        d = out / name
        d.mkdir(parents=True, exist_ok=True)
        (d / "buffers.npz").write_bytes(npz_bytes(buffers))
        (d / PATTERN_FILE).write_text(json.dumps(declared if pattern is None else pattern))
    return out


__all__ = ["FAULTS", "NAMES", "candidate_buffers", "write_candidate"]
