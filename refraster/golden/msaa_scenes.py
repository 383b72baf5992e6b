"""Multisampled golden scenes (issue 43, ``docs/multisample.md``, ``docs/golden.md``).

A scene of technique ``"msaa"`` stores the per-sample G-buffers of
:func:`refraster.render_samples` as one buffer per sample and channel —
``sample<s>_<channel>`` for the channels of :data:`SAMPLE_CHANNELS`, each ``(H, W[, C])``, so
every per-sample buffer is checked, reported and named like a single-sample one — and the
resolved colour ``color`` (the box filter of the samples' colours, in linear space:
:func:`refraster.resolve_color`). The scene declares its sample pattern in its parameters
(``sample_pattern``: the count and the positions in 1/16 pixel, y down from the pixel's
upper-left corner as the picture is seen) beside the raster state's ``samples`` and
``sample_locations``; a candidate states its own (``<scene>/sample_pattern.json``) and the
compare refuses a mismatch. The allowances are per sample
(:mod:`refraster.golden.allowances.samples`).
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera, look_at, orthographic, perspective
from .io.read import PATTERN_FILE
from .scenes import (SCENES, Draw, GoldenScene, _framed, _rotate_x, _translate, as_state,
                     draw_meshes, prepare_draws, raster_state, register_scene)

__all__ = ["SAMPLE_CHANNELS", "sample_buffer", "sample_buffers", "msaa_scene", "pattern_of",
           "PATTERN_FILE"]

#: The per-sample channels a multisampled golden stores (``sample<s>_<channel>``).
SAMPLE_CHANNELS = ("depth", "prim_id", "object_id", "front_facing", "barycentric", "color")


def sample_buffer(s, channel):
    """The buffer name of channel ``channel`` at sample ``s``: ``sample<s>_<channel>``."""
    return f"sample{int(s)}_{channel}"


def sample_buffers(frame):
    """The buffers of a multisampled golden from a :class:`refraster.SampleFramebuffer`:
    ``sample<s>_<channel>`` for each sample and channel of :data:`SAMPLE_CHANNELS`, and the
    resolved colour ``color`` (the linear box filter)."""
    from ..multisample import resolve_color
    out = {}
    arrays = frame.arrays()
    for s in range(frame.samples):
        for ch in SAMPLE_CHANNELS:
            a = np.asarray(arrays[ch])[:, :, s]
            out[sample_buffer(s, ch)] = (a.astype(np.int32) if ch in ("prim_id", "object_id")
                                         else np.ascontiguousarray(a))
    out["color"] = resolve_color(np.asarray(frame.color, np.float32))
    return out


def pattern_of(raster):
    """``{"samples": S, "positions": [[x, y], ...]}`` of a raster dict: the positions in 1/16
    pixel, y down from the pixel's upper-left corner as the picture is seen."""
    from ..raster.samples import pattern
    p = pattern(as_state(raster))
    return {"samples": int(len(p)), "positions": [[int(x), int(y)] for x, y in p]}


def msaa_scene(draws, camera, raster, description=""):
    """A multisampled :class:`GoldenScene` of ``draws`` (``raster``: the fields that differ from
    the default raster state; ``samples`` among them)."""
    from ..multisample import render_samples
    state = raster_state(raster)
    if state.get("samples", 1) < 2:
        raise ValueError("an msaa scene needs raster.samples of 2 or more")
    prepared = prepare_draws(draws, normals=state["normals"])
    frame = render_samples(draw_meshes(prepared, state), **camera.kwargs,
                           model=[d.model for d in prepared], raster=as_state(state))
    ids = {}
    faces = max(len(np.asarray(d.mesh.faces)) for d in prepared)
    for s in range(frame.samples):
        ids[sample_buffer(s, "prim_id")] = (-1, faces - 1)
        ids[sample_buffer(s, "object_id")] = (-1, len(prepared) - 1)
    from .io.buffers import GBUFFER_KINDS
    kinds = {sample_buffer(s, ch): GBUFFER_KINDS[ch] for s in range(frame.samples)
             for ch in SAMPLE_CHANNELS}
    params = {"sample_pattern": pattern_of(state),
              "resolve": {"color": "average", "encoding": "linear"}}
    return GoldenScene(technique="msaa", camera=camera, draws=prepared,
                       buffers=sample_buffers(frame), parameters=params, raster=dict(raster),
                       kinds=kinds, ids=ids, description=description)


def _ms(samples, locations="standard", **raster):
    return {"samples": samples, "sample_locations": locations, **raster}


def _solid(name, raster, *, width=160, height=120, direction=(1.0, 0.8, 1.4)):
    from ..scenes import solid
    mesh = solid(name)
    return msaa_scene([Draw(name, mesh)], _framed([mesh], width, height, direction), raster)


def _multi_draw(raster, width=160, height=120):
    from ..scenes import solid
    draws = [Draw("cube", solid("cube"), _translate(-0.6, 0.0, 0.0)),
             Draw("torus", solid("torus", quick=True), _translate(0.2, 0.0, 0.0) @ _rotate_x(70)),
             Draw("icosphere", solid("icosphere", quick=True), _translate(1.5, 0.3, -0.4))]
    view = look_at((1.0, 2.5, 5.0), (0.4, 0.0, 0.0))
    camera = Camera(view, perspective(35.0, width / height, 2.0, 9.0), width, height)
    return msaa_scene(draws, camera, raster)


#: The plain scenes multisampled: (suffix, builder of a raster dict).
_PLAIN = {
    "cube": ("Cube, flat normals, perspective, no culling",
             lambda r, **k: _solid("cube", r, **k)),
    "icosphere_smooth": ("Icosphere (1 280 faces), smooth vertex normals, back-face culling",
                         lambda r, **k: _solid("icosphere", {"normals": "smooth",
                                                             "cull": "back", **r}, **k)),
    "multi_draw": ("Three draw calls with model matrices (the torus passes through the cube: "
                   "per-sample depth decides along the intersection)",
                   lambda r, **k: _multi_draw(r, **k)),
}
_PATTERNS = {
    "msaa4": (4, "standard", "4 samples at Vulkan's standard positions"),
    "msaa8": (8, "standard", "8 samples at Vulkan's standard positions"),
    "msaa4gl": (4, "gl_llvmpipe", "4 samples at llvmpipe's GL positions (Vulkan's 4x pattern "
                                  "mirrored top to bottom)"),
}


def _register_plain(prefix, suffix):
    samples, locations, how = _PATTERNS[prefix]
    what, build = _PLAIN[suffix]

    @register_scene(f"{prefix}_{suffix}", technique="msaa",
                    description=f"{what}; {how}: per-sample buffers and the resolved colour.")
    def _scene(width=None, height=None, **raster):
        size = {} if width is None else {"width": width, "height": height}
        return build(_ms(samples, locations, **raster), **size)
    return _scene


for _prefix in _PATTERNS:
    for _suffix in _PLAIN:
        _register_plain(_prefix, _suffix)


@register_scene("msaa4_centroid_cube", technique="msaa",
                description="msaa4_cube with centroid interpolation: each sample's "
                            "barycentrics and colour may be those of any point inside both "
                            "the pixel and the primitive.")
def _msaa4_centroid_cube(width=160, height=120):
    return _solid("cube", _ms(4, interpolation="centroid"), width=width, height=height)


#: The fan of tests/test_msaa.py (vertices in 1/16 pixel, y up): its outer edges pass through
#: the 4x samples (6/16 mod 1), its inner edges through samples too.
_FAN = np.array([[6, 6], [46, 6], [86, 6], [6, 46], [54, 38], [86, 46], [6, 86], [46, 86],
                 [86, 86]])
_FAN_FACES = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6],
                       [4, 5, 8], [4, 8, 7]])


@register_scene("msaa4_ties", technique="msaa",
                description="Exact ties at 4 samples: four fans of triangles with vertices on "
                            "the 1/16-pixel grid whose shared and outer edges pass exactly "
                            "through sample positions (the fill rule decides each such sample), "
                            "each fan tilted in depth, orthographic, one window pixel per unit "
                            "(every window coordinate exact in float32).")
def _msaa4_ties(width=16, height=16):
    v, f = [], []
    for k, (tx, ty) in enumerate(((0, 0), (128, 0), (0, 128), (128, 128))):
        # each fan tilted (depth varies along x), one behind the other
        v.append(np.column_stack([(_FAN[:, 0] + tx) / 16.0, (_FAN[:, 1] + ty) / 16.0,
                                  -1.0 - 0.25 * k - _FAN[:, 0] / 512.0]))
        f.append(_FAN_FACES + k * len(_FAN))
    proj = orthographic(0.0, float(width), 0.0, float(height), 0.5, 4.0)
    return msaa_scene([Draw("fans", (np.concatenate(v), np.concatenate(f)))],
                      Camera(np.eye(4), proj, width, height), _ms(4))


@register_scene("msaa4_asymmetric", technique="msaa",
                description="One asymmetric triangle (no mirror symmetry), tilted in depth, over "
                            "a quad at 4 samples, orthographic, one window pixel per unit: its edges cross "
                            "pixels between samples that the standard pattern and its mirror "
                            "image place differently, so a mirrored pattern changes many "
                            "samples' coverage.")
def _msaa4_asymmetric(width=24, height=16):
    tri = np.array([[1.3, 2.45, -1.0], [22.6, 6.3, -1.6], [5.15, 14.2, -1.2]])
    quad = np.array([[12.0, 0.0, -2.0], [24.0, 0.0, -2.0], [24.0, 16.0, -2.0], [12.0, 16.0, -2.0]])
    draws = [Draw("triangle", (tri, np.array([[0, 1, 2]]))),
             Draw("quad", (quad, np.array([[0, 1, 2], [0, 2, 3]])))]
    proj = orthographic(0.0, float(width), 0.0, float(height), 0.5, 4.0)
    return msaa_scene(draws, Camera(np.eye(4), proj, width, height), _ms(4))


def msaa_scene_names(samples=None, locations=None):
    """The registered msaa scenes (optionally of one sample count / location set)."""
    out = []
    for name, entry in SCENES.items():
        if entry.technique != "msaa":
            continue
        if samples is not None and not name.startswith(f"msaa{samples}"):
            continue
        if locations == "gl_llvmpipe" and not name.startswith("msaa4gl_"):
            continue
        if locations == "standard" and name.startswith("msaa4gl_"):
            continue
        out.append(name)
    return out
