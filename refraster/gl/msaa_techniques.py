"""Technique scenes at ``samples > 1`` on refraster.gl (issue 44): edge maps and cutaways per
sample, by jittered single-sample passes.

A 4× technique golden declares sample-rate interpolation, so its sample ``s`` is the
single-sample frame whose window is moved by minus the sample's offset
(:func:`refraster.sample_rate.window_shift`). refraster.gl draws exactly that: the technique's
single-sample passes (:mod:`.edges`, :mod:`.cutaway`) once per sample, the projection
premultiplied by the sample's window shift, at this context's own sample positions
(``glGetMultisamplefv``; a scene declaring others is skipped with one line) — the
accumulation-buffer way of multisampling, not GL's multisample rasterization, which
:mod:`.msaa` exercises. The resolved ``edge_map`` is the float64 mean of the samples' maps
(``sampling.mode = "per_sample"``) or sample 0's (``"resolved"``, ``sample_zero``). A cutaway
flooded once from resolved rear hulls is not drawn (skipped with one line).

Planted fault ``msaa_edges_resolved_for_per_sample``: every sample's edge map is sample 0's
(the edge map of the resolved G-buffer where per-sample is declared).
"""

from __future__ import annotations

import copy

import numpy as np

from .common import Unsupported

__all__ = ["supports", "render_sampled", "SAMPLED_TECHNIQUES"]

SAMPLED_TECHNIQUES = ("edges", "cutaway")


def _shift(position, width, height):
    ox = (float(position[0]) - 8.0) / 16.0
    oy = (8.0 - float(position[1])) / 16.0
    t = np.eye(4)
    t[0, 3] = -2.0 * ox / width
    t[1, 3] = -2.0 * oy / height
    return t


def supports(scene):
    """``None`` if the multisampled technique scene can be drawn, else the reason."""
    raster = scene.get("raster", {})
    technique = scene.get("technique")
    if technique not in SAMPLED_TECHNIQUES:
        return (f"technique {technique!r} at samples > 1 is not implemented by the gl backend "
                f"(it draws {', '.join(SAMPLED_TECHNIQUES)} per sample)")
    if raster.get("interpolation", "center") != "sample":
        return (f"{technique} at samples > 1: only sample-rate interpolation (each sample the "
                f"frame moved by its offset) is drawn, the scene declares "
                f"{raster.get('interpolation', 'center')!r}")
    sampling = (scene.get("parameters") or {}).get("sampling") or {}
    if technique == "cutaway" and sampling.get("mode") != "per_sample":
        return ("cutaway at samples > 1: one surface flooded from resolved rear hulls is not "
                "drawn by the gl backend (per-sample flooding only)")
    if technique == "edges" and sampling.get("mode") == "resolved" \
            and sampling.get("resolve") != "sample_zero":
        return f"edges at samples > 1: resolve {sampling.get('resolve')!r} is not drawn"
    return None


def render_sampled(gl, package_dir, scene):
    """The golden's buffers of a multisampled edges or cutaway scene (module docstring)."""
    from .cutaway import render_cutaway
    from .edges import render_edges
    samples = int(scene["raster"]["samples"])
    declared = scene["parameters"]["sample_pattern"]["positions"]
    own = gl.sample_pattern(samples)
    if own is None or own["positions"] != declared:
        mine = "none" if own is None else " ".join(f"({x}, {y})" for x, y in own["positions"])
        raise Unsupported(f"{scene['technique']} at {samples}x: this OpenGL's sample positions "
                          f"are {mine}, the scene declares "
                          + " ".join(f"({x}, {y})" for x, y in declared))
    w, h = scene["viewport"]["width"], scene["viewport"]["height"]
    proj = np.asarray(scene["camera"]["projection"], np.float64)
    draw = render_edges if scene["technique"] == "edges" else render_cutaway
    per = []
    for pos in declared:
        s_scene = copy.deepcopy(scene)
        s_scene["camera"]["projection"] = (_shift(pos, w, h) @ proj).tolist()
        s_scene["raster"].update(samples=1, sample_locations="standard",
                                 interpolation="center")
        loaded = {"scene": s_scene, "draws": gl._upload(package_dir, s_scene), "textures": [],
                  "package_dir": package_dir}
        try:
            per.append(draw(gl, loaded, package_dir))
        finally:
            gl.unload(loaded)
    sampling = scene["parameters"]["sampling"]
    out = {}
    maps = [b.pop("edge_map") for b in per] if scene["technique"] == "edges" else None
    if maps is not None and "msaa_edges_resolved_for_per_sample" in gl.faults:
        maps = [maps[0]] * len(maps)     # planted fault: the resolved G-buffer's edge map
    for s, b in enumerate(per):
        for k, v in b.items():
            out[f"sample{s}_{k}"] = v
        if maps is not None and sampling["mode"] == "per_sample":
            out[f"sample{s}_edge_map"] = maps[s]
    if maps is not None:
        out["edge_map"] = (np.mean([m.astype(np.float64) for m in maps], axis=0).astype(
            np.float32) if sampling["mode"] == "per_sample" else maps[0])
    return out
