"""Allowances of multisampled goldens: per sample, and the resolve's from the samples'
(``docs/tolerance.md``, "Multisampling").

A sample at offset ``o`` from its pixel's centre is the pixel centre of the same scene with the
window moved by ``−o``: the clip coordinates mapped by ``x' = x − (2·o_x/W)·w``,
``y' = y − (2·o_y/H)·w`` (o in pixels, GL window y up). So the single-sample allowances —
the fixed-point edge functions' ε, the must / may / must-not coverage, the id "may" region,
the depth intervals, the face sets and their values (:func:`.core.gl_allowances`) — are
derived once per sample on that moved scene with the sample's own buffers, and stored with the
prefix ``s<s>_`` (``s0_coverage``, ``s0_set_offsets``, …). A per-sample buffer
``sample<s>_<channel>`` reads them through its manifest entry's ``"sample": s``.

Values are interpolated where the scene's ``raster.interpolation`` says:

* ``"sample"``: at the sample, as derived on the moved scene;
* ``"center"``: at the pixel centre (window depth still at the sample): the face sets' values
  other than depth are re-derived on the scene itself at the centre
  (:func:`.core.entry_values`);
* ``"centroid"``: at any point inside both the pixel and the primitive (Vulkan's and OpenGL's
  rule): barycentrics and colour of every covered sample and every face-set entry widen to
  their range over the pixel square ∩ the triangle, each grown by ε
  (:func:`centroid_ranges`).

The resolved colour (the box filter) gets a ``bounds`` interval: per sample the interval of
whatever may show there — the background where coverage is "must not", the golden face's
colour interval where coverage is "must" and the id may not differ, else the envelope of the
pixel's face set at that sample (and the background where coverage is "may"), clamped to
[0, 1] — and the mean of the samples' lower and upper ends (the mean is increasing in every
sample).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...conformance import COLOR_TOL, MAY, MUST, MUST_NOT
from .core import BARY_TOL, entry_values, gl_allowances

__all__ = ["msaa_allowances", "sample_shift", "centroid_ranges", "headlight_bounds",
           "resolve_bounds"]

#: The entry values taken at the interpolation point (not at the sample) under ``"center"``.
_AT_CENTRE = ("set_eye_depth_lo", "set_eye_depth_hi", "set_barycentric_lo",
              "set_barycentric_hi", "set_color_lo", "set_color_hi", "set_normal",
              "set_normal_angle")


def sample_shift(position, width, height):
    """The 4×4 clip-space map that moves the window by minus the sample's offset from the
    pixel centre: ``position`` ``(x, y)`` in 1/16 pixel, y down from the upper-left corner."""
    ox = (float(position[0]) - 8.0) / 16.0
    oy = (8.0 - float(position[1])) / 16.0           # GL window y up
    t = np.eye(4)
    t[0, 3] = -2.0 * ox / width
    t[1, 3] = -2.0 * oy / height
    return t


def _plain_raster(raster):
    from ..scenes import MULTISAMPLE_DEFAULTS
    return {k: v for k, v in raster.items() if k not in MULTISAMPLE_DEFAULTS}


def msaa_allowances(scene, raster):
    """Per-sample allowances of an ``msaa`` scene (module docstring). Returns ``(arrays, info,
    checks)`` as :func:`refraster.golden.allowances.core.gl_allowances`."""
    from ...camera import Camera
    from ..msaa_scenes import SAMPLE_CHANNELS, sample_buffer
    from ..scenes import DEFAULT_RASTER
    from .conventions import is_gl
    if not is_gl(raster) or raster.get("depth_func", "less") != "less" \
            or float(raster.get("clear_depth", 1.0)) != 1.0 \
            or raster.get("depth_format", "float32") != "float32":
        raise ValueError("the multisample allowances are derived in OpenGL's conventions with "
                         "depth_func 'less', a float32 depth buffer cleared to 1; this scene's "
                         "raster differs")
    positions = scene.parameters["sample_pattern"]["positions"]
    interp = raster.get("interpolation", "center")
    clip = scene.technique == "clipsurface"
    cam = scene.camera
    plain = _plain_raster(raster)
    overrides = {k: v for k, v in plain.items() if v != DEFAULT_RASTER.get(k)}
    arrays, checks, info = {}, {}, None
    per_sample = []
    centre = None
    for s, pos in enumerate(positions):
        moved = Camera(cam.view, sample_shift(pos, cam.width, cam.height) @ cam.proj,
                       cam.width, cam.height)
        bufs = {ch: scene.buffers[sample_buffer(s, ch)] for ch in SAMPLE_CHANNELS
                if sample_buffer(s, ch) in scene.buffers}
        if clip:
            sub = _clip_sample_scene(scene, s, moved, overrides, interp, pos)
        else:
            sub = dataclasses.replace(scene, technique="render", camera=moved, buffers=bufs,
                                      parameters={}, raster=overrides, geometry=True, may=None,
                                      kinds={}, ids={})
        a, info_s, ch_s = gl_allowances(sub, plain)
        if info is None:
            info = info_s
        if interp != "sample" and "set_offsets" in a and not clip:
            if centre is None:
                centre = _Centre(scene, plain)
            centre.values(a, info_s["eps"])
        if interp == "centroid":
            centroid_ranges(scene, plain, a, sub.buffers if clip else bufs, info_s["eps"],
                            "cs" if clip else "set")
        per_sample.append(a)
        for k, v in a.items():
            arrays[f"s{s}_{k}"] = v
        for key, spec in ch_s.items():
            checks[sample_buffer(s, key)] = {**spec, "sample": s}
    bg = np.asarray(scene.parameters.get("background", (1.0, 1.0, 1.0)), np.float64)
    arrays["id_may"] = np.logical_or.reduce([a["id_may"] for a in per_sample])
    arrays["may"] = np.logical_or.reduce([a["may"] for a in per_sample])
    if "color" in scene.buffers:
        arrays["resolve_color_lo"], arrays["resolve_color_hi"] = resolve_bounds(per_sample, bg)
        checks["color"] = {"checks": ["bounds"], "lo": "resolve_color_lo",
                           "hi": "resolve_color_hi"}
    return arrays, info, checks


def _clip_sample_scene(scene, s, moved, overrides, interp, position):
    """Sample ``s`` of a multisampled clip-surface scene as a single-sample clip-surface scene
    on the camera moved to the sample (its buffers, its own clip-decision "may" pixels); at
    pixel rate (``interp`` not ``"sample"``) the clip decision and parity test are taken at
    the pixel centre, offset by minus the sample's offset from the moved scene's centre
    (``parameters.decision_offset``, pixels, GL window y up; :mod:`.clip`)."""
    from ..msaa_clip_scenes import CLIP_SAMPLE_CHANNELS
    from ..msaa_scenes import sample_buffer
    from ..technique_scenes import _clip_decision_may_multi
    from .clip import _surfaces
    bufs = {ch: scene.buffers[sample_buffer(s, ch)] for ch in CLIP_SAMPLE_CHANNELS
            if sample_buffer(s, ch) in scene.buffers}
    params = {k: v for k, v in scene.parameters.items() if k != "sample_pattern"}
    if interp != "sample":
        params["decision_offset"] = [-(float(position[0]) - 8.0) / 16.0,
                                     -(8.0 - float(position[1])) / 16.0]
    if interp == "centroid":
        # the decision at any point of the pixel ∩ the primitive (allowances/clip.py)
        params["decision_point"] = "centroid"
    sub = dataclasses.replace(scene, camera=moved, buffers=bufs, parameters=params,
                              raster=overrides, kinds={}, ids={}, may=None)
    # the clip decision's "may" pixels where the rate takes it: at the sample (the moved
    # scene's centre) or at the pixel centre (the scene's own)
    may = _clip_decision_may_multi(scene.draws, moved if interp == "sample" else scene.camera,
                                   _surfaces(sub), bufs["cap_mask"])
    return dataclasses.replace(sub, may=may)


class _Centre:
    """The scene's own prepared draws, for face-set values at the pixel centre."""

    def __init__(self, scene, raster):
        from ...raster import prepare
        from .core import _geometry
        cam = scene.camera
        self.scene, self.raster = scene, raster
        self.prep = prepare([d.mesh for d in scene.draws], **cam.kwargs,
                            model=[d.model for d in scene.draws], raster=_geometry(raster))

    def values(self, a, eps):
        """Replace the set entries' values other than window depth and facing by those at the
        pixel centre (in place)."""
        off = a["set_offsets"].astype(np.int64)
        if not len(a["set_face"]):
            return
        pix = np.repeat(np.arange(off.size - 1, dtype=np.int64), np.diff(off))
        vals = entry_values(self.scene, self.raster, self.prep, pix,
                            a["set_face"].astype(np.int64), eps)
        for k in _AT_CENTRE:
            a[k] = vals[k]


def centroid_ranges(scene, raster, a, bufs, eps, entries="set"):
    """Widen, in place, the barycentric and colour allowances of one sample's arrays ``a`` to
    what any point inside both the pixel and the primitive gives (centroid interpolation):
    for the golden's own face where it covers the sample, and for every face-set entry.
    Barycentrics are ratios of affine functions of the point, so their extremes over the
    (convex) polygon are at its vertices; the colour (a shade of the normal and the view
    direction) its proven range over the polygon (:func:`headlight_bounds`).

    ``entries="cs"``: a clip-surface scene's clip sets (``cs_offsets``, ``cs_face``,
    ``cs_<key>_lo``); a cap face (not among the scene's draws) is free there already, and
    where the golden shows a cap its barycentrics and colour become free (the cap's shading
    has no range bound here)."""
    from ...framebuffer import _build
    from ...raster import prepare
    from .core import _geometry
    from .homogeneous import face_barycentrics, pixel_triangle
    cam = scene.camera
    w, h = cam.width, cam.height
    prep = prepare([d.mesh for d in scene.draws], **cam.kwargs,
                   model=[d.model for d in scene.draws], raster=_geometry(raster))
    normals = ([d.normals for d in scene.draws] if raster["normals"] == "smooth" else "flat")
    prim = np.asarray(bufs["prim_id"], np.int64)
    obj = np.asarray(bufs.get("object_id", np.zeros_like(prim)), np.int64)
    offsets = np.asarray(prep.face_offsets, np.int64)
    n_draws = len(scene.draws)
    if entries == "cs":
        cap = ((prim >= 0) & (obj >= n_draws)).ravel()
        for key in ("barycentric", "color"):
            if f"{key}_lo" in a:
                a[f"{key}_lo"].reshape(-1, 3)[cap] = -np.inf
                a[f"{key}_hi"].reshape(-1, 3)[cap] = np.inf
        obj = np.where(obj < n_draws, obj, -1)
        prim = np.where(obj >= 0, prim, -1)
    own_pix = np.flatnonzero((prim >= 0).ravel())
    own_face = offsets[obj.ravel()[own_pix]] + prim.ravel()[own_pix]
    off = a.get(f"{entries}_offsets")
    if off is not None and len(a[f"{entries}_face"]):
        set_pix = np.repeat(np.arange(off.size - 1, dtype=np.int64), np.diff(off.astype(np.int64)))
        set_face = a[f"{entries}_face"].astype(np.int64)
        drawn = np.flatnonzero(set_face < int(offsets[-1]))   # not a cap
        set_pix, set_face = set_pix[drawn], set_face[drawn]
    else:
        set_pix = set_face = drawn = np.zeros(0, np.int64)
    pix = np.concatenate([own_pix, set_pix])
    face = np.concatenate([own_face, set_face])
    if not len(pix):
        return
    clip = prep.clip[prep.triangles.faces[face]].astype(np.float64)
    poly, ok = pixel_triangle(clip, pix, w, h, eps)
    has = ~np.isnan(poly[:, :, 0])
    ok &= has.any(axis=1)
    # pad each polygon with its first vertex (the extremes are unchanged)
    first = poly[:, 0]
    pts = np.where(has[:, :, None], poly, first[:, None, :])
    pts = np.where(np.isnan(pts), 0.0, pts)
    beta = face_barycentrics(clip, pts[:, :, 0], pts[:, :, 1], w, h)       # (E, K, 3)
    k = beta.shape[1]
    fb = _build(prep.meshes, prep.models, prep.view, prep.proj,
                np.full((len(pix), k), 0.5, np.float32), np.repeat(face, k).reshape(-1, k),
                prep.face_offsets, np.zeros((len(pix), k), np.bool_),
                np.nan_to_num(beta, nan=0.0).astype(np.float32), normals, np.ones(3))
    b_lo = np.where(ok[:, None], beta.min(axis=1) - BARY_TOL, -np.inf)
    b_hi = np.where(ok[:, None], beta.max(axis=1) + BARY_TOL, np.inf)
    eye = np.einsum("ekj,ejc->ekc", np.nan_to_num(beta, nan=0.0), _eye_corners(prep, face))
    c_lo, c_hi = headlight_bounds(fb.normal.astype(np.float64), eye, _base_colours(prep, face))
    c_lo = c_lo - COLOR_TOL
    c_hi = c_hi + COLOR_TOL
    c_lo = np.where(ok[:, None], c_lo, -np.inf)
    c_hi = np.where(ok[:, None], c_hi, np.inf)
    n_own = len(own_pix)
    for key, lo, hi in (("barycentric", b_lo, b_hi), ("color", c_lo, c_hi)):
        if f"{key}_lo" in a:
            flat_lo = a[f"{key}_lo"].reshape(-1, 3)
            flat_hi = a[f"{key}_hi"].reshape(-1, 3)
            flat_lo[own_pix] = np.minimum(flat_lo[own_pix], lo[:n_own]).astype(np.float32)
            flat_hi[own_pix] = np.maximum(flat_hi[own_pix], hi[:n_own]).astype(np.float32)
        if len(set_pix):
            sl, sh = f"{entries}_{key}_lo", f"{entries}_{key}_hi"
            if sl in a:
                new_lo = np.asarray(a[sl], np.float64).copy()
                new_hi = np.asarray(a[sh], np.float64).copy()
                new_lo[drawn] = np.minimum(new_lo[drawn], lo[n_own:])
                new_hi[drawn] = np.maximum(new_hi[drawn], hi[n_own:])
                a[sl], a[sh] = new_lo.astype(np.float32), new_hi.astype(np.float32)


def _eye_corners(prep, face):
    """The eye-space corners ``(E, 3, 3)`` float64 of global faces ``face`` (view · model ·
    vertex, the positions :func:`refraster.raster.gbuffer.shade` interpolates)."""
    offs = np.asarray(prep.face_offsets, np.int64)
    draw = np.searchsorted(offs, face, side="right") - 1
    out = np.zeros((len(face), 3, 3))
    for k, (mesh, model) in enumerate(zip(prep.meshes, prep.models)):
        sel = draw == k
        if sel.any():
            mv = np.asarray(prep.view, np.float64) @ np.asarray(model, np.float64)
            v = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[face[sel] - offs[k]]]
            out[sel] = v @ mv[:3, :3].T + mv[:3, 3]
    return out


def _base_colours(prep, face):
    """The palette colour ``(E, 3)`` of each global face's draw call (``shade``'s ``pk``)."""
    from ...framebuffer import PALETTE
    offs = np.asarray(prep.face_offsets, np.int64)
    draw = np.searchsorted(offs, face, side="right") - 1
    return np.asarray(PALETTE, np.float64)[draw % len(PALETTE)]


def _box(v):
    """Per entry, the componentwise range ``(lo, hi)`` of points ``v`` ``(E, K, 3)``."""
    return v.min(axis=1), v.max(axis=1)


def _product_range(a_lo, a_hi, b_lo, b_hi):
    """The range of ``a·b`` for ``a ∈ [a_lo, a_hi]``, ``b ∈ [b_lo, b_hi]`` (elementwise):
    the extremes of a bilinear function over a box are at its corners."""
    prods = np.stack([a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi])
    return prods.min(axis=0), prods.max(axis=0)


def _square_range(lo, hi):
    """The range of ``x²`` for ``x ∈ [lo, hi]`` (elementwise)."""
    sq_lo = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo * lo, hi * hi))
    return sq_lo, np.maximum(lo * lo, hi * hi)


def headlight_bounds(normals, eye, base):
    """A proven range ``(lo, hi) (E, 3)`` of the default colour (:func:`refraster.raster.
    gbuffer.shade`) over every point of a convex polygon of one face, from the unit normals
    ``normals`` ``(E, K, 3)`` and eye positions ``eye`` ``(E, K, 3)`` at its ``K`` vertices.

    The eye position is affine in the barycentrics, so it ranges over the vertices' convex
    hull; the smooth normal before normalising is linear in them, so its direction lies in the
    cone of the vertices' unit normals (a flat normal is one direction). Taking the two
    independently over the componentwise boxes of those hulls: ``n·e``, ``|n|²`` and ``|e|²``
    in interval arithmetic bound ``d = min(|n·e| / (|n|·|e|), 1)``, and the colour
    ``base·(A + D·d) + S·d⁴⁸`` (clamped to [0, 1]) is non-decreasing in ``d``: its range is
    the colour at the two ends. Exact arithmetic; the caller adds the float rounding
    (``COLOR_TOL``)."""
    from ...raster.gbuffer import AMBIENT, DIFFUSE, SHININESS, SPECULAR
    n_lo, n_hi = _box(normals)
    e_lo, e_hi = _box(eye)
    p_lo, p_hi = _product_range(n_lo, n_hi, e_lo, e_hi)
    dot_lo, dot_hi = p_lo.sum(axis=1), p_hi.sum(axis=1)
    abs_lo = np.where((dot_lo <= 0) & (dot_hi >= 0), 0.0,
                      np.minimum(np.abs(dot_lo), np.abs(dot_hi)))
    abs_hi = np.maximum(np.abs(dot_lo), np.abs(dot_hi))
    nn_lo, nn_hi = (x.sum(axis=1) for x in _square_range(n_lo, n_hi))
    ee_lo, ee_hi = (x.sum(axis=1) for x in _square_range(e_lo, e_hi))
    with np.errstate(divide="ignore", invalid="ignore"):
        d_lo = np.where(nn_hi * ee_hi > 0, abs_lo / np.sqrt(nn_hi * ee_hi), 0.0)
        d_hi = np.where(nn_lo * ee_lo > 0, abs_hi / np.sqrt(nn_lo * ee_lo), 1.0)
    # shade's d is 1 where the eye position is 0 (never in front of the eye)
    d_lo = np.clip(np.nan_to_num(d_lo, nan=0.0), 0.0, 1.0)
    d_hi = np.clip(np.nan_to_num(d_hi, nan=1.0), 0.0, 1.0)

    def colour(d):
        d = d[:, None]
        return np.clip(base * (AMBIENT + DIFFUSE * d) + SPECULAR * d ** SHININESS, 0.0, 1.0)

    return colour(d_lo), colour(d_hi)


def _set_envelope(a, key, h, w):
    """Per pixel, the envelope ``(lo, hi) (H·W, 3)`` of the face-set entries' ``key``
    intervals (NaN where a pixel has no entry)."""
    lo = np.full((h * w, 3), np.nan)
    hi = np.full((h * w, 3), np.nan)
    off = a["set_offsets"].astype(np.int64)
    n = np.diff(off)
    runs = np.flatnonzero(n > 0)
    if len(runs):
        lo[runs] = np.minimum.reduceat(a[f"set_{key}_lo"].astype(np.float64), off[runs], axis=0)
        hi[runs] = np.maximum.reduceat(a[f"set_{key}_hi"].astype(np.float64), off[runs], axis=0)
    return lo, hi


def resolve_bounds(per_sample, background):
    """The resolved colour's interval ``(lo, hi) (H, W, 3)`` float32 from the samples'
    allowances (module docstring)."""
    h, w = per_sample[0]["coverage"].shape
    bg = np.broadcast_to(np.asarray(background, np.float64), (h * w, 3))
    sum_lo = np.zeros((h * w, 3))
    sum_hi = np.zeros((h * w, 3))
    for a in per_sample:
        cov = a["coverage"].ravel()
        id_may = a["id_may"].ravel()
        own_lo = a["color_lo"].reshape(-1, 3).astype(np.float64)
        own_hi = a["color_hi"].reshape(-1, 3).astype(np.float64)
        if "set_offsets" in a:
            env_lo, env_hi = _set_envelope(a, "color", h, w)
        else:
            env_lo = np.full((h * w, 3), np.nan)
            env_hi = np.full((h * w, 3), np.nan)
        sure = ((cov == MUST) & ~id_may)[:, None]
        # where another face may show: the set's envelope (free without entries)
        may_lo = np.where(np.isnan(env_lo), 0.0, env_lo)
        may_hi = np.where(np.isnan(env_hi), 1.0, env_hi)
        lo = np.where(sure, own_lo, may_lo)
        hi = np.where(sure, own_hi, may_hi)
        none = (cov == MUST_NOT)[:, None]
        lo = np.where(none, bg, lo)
        hi = np.where(none, bg, hi)
        either = (cov == MAY)[:, None]
        lo = np.where(either, np.minimum(lo, bg), lo)
        hi = np.where(either, np.maximum(hi, bg), hi)
        sum_lo += np.clip(lo, 0.0, 1.0)
        sum_hi += np.clip(hi, 0.0, 1.0)
    n = float(len(per_sample))
    # the float32 mean of float32 samples: a few ulps (2^-22) around the exact mean
    lo = sum_lo / n - 2.0 ** -20
    hi = sum_hi / n + 2.0 ** -20
    from .conventions import _outward
    lo32, hi32 = _outward(lo, hi)
    return lo32.reshape(h, w, 3), hi32.reshape(h, w, 3)
