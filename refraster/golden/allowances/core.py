"""Tolerant goldens: per-pixel allowances stored beside a scene's buffers, and the tolerant check.

At ``golden generate`` every scene gets ``<scene>/tolerance.npz`` (listed in the manifest with
its sha256) holding what a conformant GPU may do differently (:mod:`refraster.conformance`):

==================  ===========  ================================================================
array               dtype        meaning
==================  ===========  ================================================================
``coverage``        int8         2 must be covered, 1 may be, 0 must not be
``id_may``          bool         the visible primitive may differ (ids, facing and values free)
``may``             bool         the technique's own "may" region (decision boundaries, filter
                                 footprints); technique buffers are free there
``depth_lo/_hi``    float32      window-depth interval (:func:`refraster.conformance.tolerance`)
``<buf>_lo/_hi``    float32      value interval of ``eye_depth``, ``barycentric``, ``color``
``normal_angle``    float32      largest angle (radians) between reference and candidate normal
``set_offsets``     int32        face sets (plain renders): the faces that may win at pixel k are
                                 ``set_face[set_offsets[k]:set_offsets[k + 1]]`` (global ids)
``set_*``           per entry    what that face shows there: ``set_depth_lo/_hi``,
                                 ``set_eye_depth_lo/_hi``, ``set_barycentric_lo/_hi``,
                                 ``set_color_lo/_hi``, ``set_normal`` + ``set_normal_angle``,
                                 ``set_facing`` (−1: a sliver that may flip there, free);
                                 ``draw_offsets`` maps
                                 (object_id, prim_id) to the global id (:func:`face_sets`)
==================  ===========  ================================================================

Each buffer's manifest entry says which checks apply (``"tolerant": {"checks": [...]}``):
``coverage`` (the candidate's coverage against the three-valued mask), ``id`` (equal where the id
must agree), ``interval`` (``lo ≤ value ≤ hi`` per channel where the id must agree), ``angle``
(normals), ``masked`` (the ``conformant`` profile, with the ``may`` region forgiven: buffers
without an interval of their own) and ``face`` (where the id may differ: the candidate's
``prim_id`` must name a face of the pixel's set and its values must be that face's).

How the arrays are derived
--------------------------
*Plain G-buffers* (``GoldenScene.geometry`` true: the buffers are what
:func:`refraster.render` makes of the draws): :func:`refraster.conformance.tolerance` gives the
coverage, id and depth allowances. Interpolated values (eye depth, barycentrics, normals,
colour) may change by what a shift of the sample point by the edge ε does:
``base + 1.5 · ε · step`` where ``step`` is the largest change to a 4-neighbour showing the same
primitive of the same draw (the discrete gradient of the value on that surface). ``base`` is the
float32 budget: eye depth ``1e−5 + 4e−6·z``, barycentrics ``1e−3``, normals
``NORMAL_TOL`` (2e−3 rad), colour ``COLOR_TOL`` (2/255).

*Technique scenes* whose G-buffer is not a plain render (a clip surface shows back faces):
:func:`refraster.conformance.edge_may` marks every edge of every drawn triangle (hidden ones
included), the scene adds its decision boundary (``GoldenScene.may``, from
:func:`refraster.conformance.decision_may`), the union is dilated by one pixel for ids and coverage
(coverage itself comes from the reference's ids) and values fall back to ``masked``.

*Technique buffers* (anything that is not a G-buffer channel, e.g. an edge map): ``may`` is the
id/coverage "may" region plus the scene's decision region, dilated by ``GoldenScene.may_radius``
pixels — the footprint of the technique's image filters — and the check is ``masked``.
"""

from __future__ import annotations

import math

import numpy as np

from ...conformance import (COLOR_TOL, DEPTH_EPS, MAY, MUST, MUST_NOT, NORMAL_TOL, edge_may,
                         facing_may, tolerance)
from refraster.raster.state import RasterState

from .conventions import covered_by, depth_covered
from .precision import candidate_bits, declared

__all__ = ["scene_allowances", "tolerant_metrics", "dilate", "surface_step", "TOLERANT_CHECKS"]

TOLERANT_CHECKS = ("coverage", "id", "interval", "angle", "masked", "face", "layers", "bounds",
                   "clip")

#: float32 budgets of the interpolated G-buffer values (see the module docstring).
EYE_DEPTH_ABS, EYE_DEPTH_REL = 1e-5, 4e-6
BARY_TOL = 1e-3
#: Second-order margin on the first-order "value changes by step · ε" estimate.
SHIFT_MARGIN = 1.5
#: Sub-pixel precisions an allowed rasterizer may snap to (docs/tolerance.md): from the
#: candidate's declared bits (:mod:`~refraster.golden.allowances.precision`, at least 4) to 8.
MIN_SNAP_BITS, MAX_SNAP_BITS = 4, 8


def dilate(mask, radius):
    """``mask`` grown by ``radius`` pixels (Chebyshev: a (2r+1)² square)."""
    m = np.asarray(mask, np.bool_)
    if radius <= 0:
        return m.copy()
    h, w = m.shape
    out = m.copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy or dx:
                out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] |= \
                    m[max(-dy, 0):h + min(-dy, 0), max(-dx, 0):w + min(-dx, 0)]
    return out


def changes(a, step=0.0):
    """Pixels whose value differs by more than ``step`` from a 4-neighbour's (both pixels of
    each such pair), for an (H, W) bool or numeric image."""
    a = np.asarray(a)
    d = a if a.dtype == np.bool_ else a.astype(np.float64)
    v = (d[1:, :] != d[:-1, :]) if a.dtype == np.bool_ else np.abs(d[1:, :] - d[:-1, :]) > step
    u = (d[:, 1:] != d[:, :-1]) if a.dtype == np.bool_ else np.abs(d[:, 1:] - d[:, :-1]) > step
    out = np.zeros(a.shape, np.bool_)
    out[1:, :] |= v
    out[:-1, :] |= v
    out[:, 1:] |= u
    out[:, :-1] |= u
    return out


def _neighbour_pairs(h, w):
    """(a, b) slice pairs of the right and lower 4-neighbours."""
    yield (slice(None), slice(0, w - 1)), (slice(None), slice(1, w))
    yield (slice(0, h - 1), slice(None)), (slice(1, h), slice(None))


def surface_step(values, surface, *, angle=False):
    """Per pixel, the largest change of ``values`` to a 4-neighbour on the same surface.

    ``surface (H, W)`` int64 labels (−1 background: no step); ``angle`` measures the change of
    unit vectors in radians instead of the largest absolute channel difference.
    """
    v = np.asarray(values, np.float64)
    h, w = surface.shape
    out = np.zeros((h, w))
    for a, b in _neighbour_pairs(h, w):
        same = (surface[a] == surface[b]) & (surface[a] >= 0)
        if angle:
            d = _angle(v[a], v[b])
        else:
            with np.errstate(invalid="ignore"):
                d = np.abs(v[a] - v[b])
            if d.ndim == 3:
                d = d.max(axis=2)
        d = np.where(same & np.isfinite(d), d, 0.0)
        out[a] = np.maximum(out[a], d)
        out[b] = np.maximum(out[b], d)
    return out


def _angle(n1, n2):
    """Angle (radians) between vectors; 0 when both are zero, π/2 when one is."""
    n1 = np.nan_to_num(np.asarray(n1, np.float64), nan=0.0)
    n2 = np.nan_to_num(np.asarray(n2, np.float64), nan=0.0)
    cross = np.linalg.norm(np.cross(n1, n2), axis=-1)
    dot = np.sum(n1 * n2, axis=-1)
    ang = np.arctan2(cross, dot)
    z1 = np.linalg.norm(n1, axis=-1) == 0
    z2 = np.linalg.norm(n2, axis=-1) == 0
    ang = np.where(z1 & z2, 0.0, ang)
    return np.where(z1 ^ z2, np.pi / 2, ang)


def _interval(ref, surface, eps, base):
    """``ref ∓ (base + SHIFT_MARGIN · eps · step)`` as float32 (lo, hi); base may be an array."""
    r = np.asarray(ref, np.float64)
    slack = SHIFT_MARGIN * eps * surface_step(r, surface)
    if r.ndim == 3:
        slack = slack[..., None]
    slack = slack + base
    with np.errstate(invalid="ignore"):
        lo, hi = r - slack, r + slack
    lo = np.where(np.isinf(r), r, lo)
    hi = np.where(np.isinf(r), r, hi)
    # round outwards so that the float32 interval still contains the float64 one
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def _surface_labels(buffers):
    prim = np.asarray(buffers["prim_id"], np.int64)
    obj = np.asarray(buffers.get("object_id", np.zeros_like(prim)), np.int64)
    return np.where(prim >= 0, obj * (int(prim.max()) + 1) + prim, -1)


def scene_allowances(scene, raster, bits=None):
    """Allowances of one scene, in its own conventions: derived on the equivalent scene in
    OpenGL's (:func:`refraster.golden.allowances.conventions.equivalent`) and moved back
    (:func:`~refraster.golden.allowances.conventions.move_back`), for a candidate of ``bits``
    sub-pixel bits (4 to 8; default the declared ones,
    :func:`refraster.golden.allowances.precision.candidate_bits`). Returns as
    :func:`gl_allowances`."""
    from .conventions import equivalent, move_back
    with declared(candidate_bits() if bits is None else bits):
        eq_scene, eq_raster = equivalent(scene, raster)
        arrays, info, checks = gl_allowances(eq_scene, eq_raster)
    move_back(arrays, scene, raster, eq_scene)
    return arrays, info, checks


def _geometry(raster):
    """The state the geometric allowances prepare with: the scene's cull and clip volume, and
    the reference's own sub-pixel bits, fill rule and precision (the allowance's "must" and
    "must not" are the reference's coverage; the ε of its snapping is the reference's)."""
    from ..scenes import as_state
    s = as_state(raster)
    return RasterState(cull=raster["cull"], depth_clamp=bool(raster.get("depth_clamp", False)),
                       subpixel_bits=s.subpixel_bits, fill_rule=s.fill_rule,
                       precision=s.precision)


def gl_allowances(scene, raster, d_bounds=None):
    """Allowances of one scene in OpenGL's conventions, for a candidate of the declared
    sub-pixel bits (:func:`refraster.golden.allowances.precision.candidate_bits`).
    ``d_bounds``: a cutaway scene's ``(lo, hi, slack)`` of D when it is not derived from the
    scene itself (:mod:`.sampled`: one surface shared by every sample).

    Returns
    -------
    arrays : dict of str → ndarray
        What ``tolerance.npz`` stores.
    info : dict
        The manifest's ``allowances`` entry (without ``file``): method, ε, budgets.
    checks : dict of str → dict
        Per buffer, its ``"tolerant"`` manifest entry.
    """
    cam = scene.camera
    meshes = [d.mesh for d in scene.draws]
    models = [d.model for d in scene.draws]
    buffers = scene.buffers
    # the geometric masks assume "less" against a buffer cleared to 1: under another clear
    # depth the reference drops fragments at or behind it, so its own coverage decides
    # (the decision path, as for the other depth functions)
    geometry = (bool(scene.geometry) and raster["depth_func"] == "less"
                and float(raster.get("clear_depth", 1.0)) == 1.0)
    geom = _geometry(raster)
    bits = candidate_bits()
    kw = dict(**cam.kwargs, model=models, cull=raster["cull"], min_bits=bits, raster=geom)
    tol = tolerance(meshes, **kw)
    # tolerance() decides whether an edge's triangle is "in front" at a pixel within depth_eps;
    # a plane set up from snapped vertices differs from the interpolated depth by up to
    # |∇z|·ε, so the coverage and id masks use depth_eps widened by that for the steepest
    # visible surface (the depth intervals keep the plain one)
    if "depth" in buffers and "prim_id" in buffers:
        steps = surface_step(np.asarray(buffers["depth"], np.float64), _surface_labels(buffers))
        wide = DEPTH_EPS + SHIFT_MARGIN * tol.eps * float(steps.max())
        masks = tolerance(meshes, **kw, depth_eps=wide)
    else:
        masks = tol
    extra = (np.zeros((cam.height, cam.width), np.bool_) if scene.may is None
             else np.asarray(scene.may, np.bool_))
    if extra.shape != (cam.height, cam.width):
        raise ValueError(f"GoldenScene.may must be (H, W) = {(cam.height, cam.width)}, got "
                         f"{extra.shape}")
    radius = int(scene.may_radius)
    # slivers that may change facing at the candidate's bits (a gap in tolerance()'s
    # shared-edge rule)
    flip_id, flip_cov = facing_may(meshes, **cam.kwargs, model=models, min_bits=bits,
                                   raster=geom)
    if geometry:
        coverage = masks.coverage.copy()
        coverage[flip_cov] = MAY
        id_may = masks.id_may | flip_id
        depth_lo = np.where(id_may, np.float32(0.0), tol.depth_lo)
        depth_hi = np.where(id_may, np.float32(1.0), tol.depth_hi)
        method = "geometry"
    else:
        edges_id, _ = edge_may(meshes, **cam.kwargs, model=models, cull=raster["cull"],
                               min_bits=bits,
                               raster=geom)
        id_may = dilate(edges_id | flip_id | extra, 1)
        if "prim_id" in buffers:
            ref_cov = np.asarray(buffers["prim_id"]) >= 0
        elif "depth" in buffers:
            ref_cov = depth_covered(buffers["depth"], raster["clear_depth"],
                                    raster["depth_func"])
        else:
            ref_cov = None
        coverage = (None if ref_cov is None else
                    np.where(id_may, MAY, np.where(ref_cov, MUST, MUST_NOT)).astype(np.int8))
        method = "decision" if scene.may is not None else "dilated"
    may = dilate(id_may | extra, max(radius, 0))
    arrays = {"id_may": id_may, "may": may}
    if coverage is not None:
        arrays["coverage"] = coverage
    sets = geometry and "prim_id" in buffers
    if sets:
        arrays.update(face_sets(scene, raster, id_may, tol.eps))
    checks = {}
    surface = _surface_labels(buffers) if "prim_id" in buffers else None
    for key in sorted(buffers):
        a = np.asarray(buffers[key])
        if key in ("prim_id", "object_id") and coverage is not None:
            checks[key] = {"checks": ["coverage", "id"]}
        elif key == "front_facing":
            checks[key] = {"checks": ["id"]}
        elif key == "depth" and coverage is not None:
            if geometry:
                arrays["depth_lo"], arrays["depth_hi"] = depth_lo, depth_hi
                checks[key] = {"checks": ["coverage", "interval"], "lo": "depth_lo",
                               "hi": "depth_hi"}
            else:
                checks[key] = {"checks": ["coverage", "masked"], "may": "id_may"}
        elif geometry and surface is not None and key in ("eye_depth", "barycentric", "color"):
            if key == "eye_depth":
                base = EYE_DEPTH_ABS + EYE_DEPTH_REL * np.where(np.isfinite(a), np.abs(a), 0.0)
            else:
                base = BARY_TOL if key == "barycentric" else COLOR_TOL
            arrays[f"{key}_lo"], arrays[f"{key}_hi"] = _interval(a, surface, tol.eps, base)
            checks[key] = {"checks": ["interval"], "lo": f"{key}_lo", "hi": f"{key}_hi"}
        elif geometry and surface is not None and key == "normal":
            step = surface_step(a, surface, angle=True)
            arrays["normal_angle"] = (NORMAL_TOL + SHIFT_MARGIN * tol.eps * step).astype(
                np.float32)
            checks[key] = {"checks": ["angle"], "angle": "normal_angle"}
        else:
            region = "id_may" if key in _GBUFFER else "may"
            checks[key] = {"checks": ["masked"], "may": region}
    if sets:
        for key, spec in checks.items():
            if key in _GBUFFER and "masked" not in spec["checks"]:
                spec["checks"] = spec["checks"] + ["face"]
    if scene.technique == "edges" and "edge_map" in buffers and sets:
        # edge maps: intervals propagated through the operator (golden/allowances/edges.py)
        from ...edges import fit_near_far
        from .edges import edge_map_bounds, npr_color_bounds, npr_supported, supported
        params = scene.parameters or {}
        if supported(params) and params.get("bounds") is not None:
            near, far = fit_near_far(cam.view, bounds=np.asarray(params["bounds"], np.float64))
            arrays["edge_map_lo"], arrays["edge_map_hi"] = edge_map_bounds(
                arrays, buffers, params, near, far,
                gbuffer_format=params.get("gbuffer_format", "rgba8"),
                output_format=params.get("output_format", "rgba8"))
            checks["edge_map"] = {"checks": ["bounds"], "lo": "edge_map_lo",
                                  "hi": "edge_map_hi"}
            if "npr_color" in buffers and npr_supported(params):
                # the NPR composite over Gooch shading (golden/allowances/edges.py)
                arrays["npr_color_lo"], arrays["npr_color_hi"] = npr_color_bounds(
                    arrays, buffers, params, near, far, arrays["edge_map_lo"],
                    arrays["edge_map_hi"])
                checks["npr_color"] = {"checks": ["bounds"], "lo": "npr_color_lo",
                                       "hi": "npr_color_hi"}
    if scene.technique == "cutaway" and "cutaway_depth" in buffers \
            and (scene.parameters or {}).get("accepted_variants"):
        # cutaways: D_variant − slack ≤ D ≤ D_exact + slack (golden/allowances/cutaway.py)
        from .cutaway import cutaway_bounds
        arrays["cutaway_depth_lo"], arrays["cutaway_depth_hi"], slack = (
            cutaway_bounds(scene, tol.eps) if d_bounds is None else d_bounds)
        checks["cutaway_depth"] = {"checks": ["bounds"], "lo": "cutaway_depth_lo",
                                   "hi": "cutaway_depth_hi"}
        if raster["depth_func"] == "less" and "cut_mask" in buffers:
            # the cut decision z < D free only where D's interval allows either
            from .clip import CLIP_BUFFERS, cutaway_allowances
            arrays.update(cutaway_allowances(scene, raster, tol.eps, arrays["cutaway_depth_lo"],
                                             arrays["cutaway_depth_hi"],
                                             (EYE_DEPTH_ABS, EYE_DEPTH_REL)))
            for key in CLIP_BUFFERS:
                if key in checks:
                    checks[key] = {"checks": ["clip"]}
            if "ghost" in buffers:
                # ghost lines: α intervals from D's, the occluder's and the line's (ghosts.py)
                from .ghosts import ghost_bounds
                # the line placement keeps the 4-bit ε (ghosts.LINE_BITS)
                from ...conformance import edge_epsilon
                from .ghosts import LINE_BITS
                gb = ghost_bounds(scene, arrays, max(tol.eps, edge_epsilon(
                    cam.width, cam.height, min_bits=LINE_BITS)))
                if gb is not None:
                    arrays["ghost_lo"], arrays["ghost_hi"], arrays["ghost_zero"] = gb
                    checks["ghost"] = {"checks": ["bounds"], "lo": "ghost_lo", "hi": "ghost_hi",
                                       "zero": "ghost_zero"}
    if scene.technique == "clipsurface" and "cap_mask" in buffers \
            and raster["depth_func"] == "less" and scene.maps is not None:
        # clip surfaces: the clip decision and cap parity bounded (golden/allowances/clip.py)
        from .clip import CLIP_BUFFERS, clip_allowances
        arrays.update(clip_allowances(scene, raster, tol.eps, (EYE_DEPTH_ABS, EYE_DEPTH_REL)))
        for key in CLIP_BUFFERS:
            if key in checks:
                checks[key] = {"checks": ["clip"]}
    if scene.technique == "vds" and "inside" in buffers and scene.may is not None:
        # the parity decision: equal to the golden's except where the scene's probes found it
        # may flip (GoldenScene.may, not dilated): a per-pixel check, not a fraction
        inside = np.asarray(buffers["inside"], np.bool_)
        arrays["inside_lo"] = inside & ~extra
        arrays["inside_hi"] = inside | extra
        checks["inside"] = {"checks": ["bounds"], "lo": "inside_lo", "hi": "inside_hi"}
    if "cs_offsets" in arrays and "prim_id" in buffers:
        # clip surfaces and cutaways: normal, barycentrics and colour held to the golden's
        # interval (its own surface's step over the ε-square) wherever the candidate names the
        # golden's face; free only where another face may win and the candidate names it
        _clip_value_checks(scene, raster, arrays, checks, buffers, tol.eps)
    if scene.technique == "ldi" and "layer_depth" in buffers:
        # layered depth images: per-layer face sets and depth intervals
        # (golden/allowances/layers.py)
        from .layers import LAYER_BUFFERS, ldi_allowances
        arrays.update(ldi_allowances(scene, raster, tol.eps, buffers["layer_depth"].shape[2],
                                     raster["clear_depth"]))
        for key, layer in LAYER_BUFFERS.items():
            if key in checks:
                checks[key] = {"checks": ["layers"], "layer": layer}
    if scene.technique == "halos4d" and scene.maps is not None \
            and "surface_vertices4d" in scene.maps:
        # 4D halos: class range and alpha / colour intervals from the classification margins
        # (golden/allowances/halos.py)
        from .halos import HALO_CHECKS, halo_allowances
        arrays.update(halo_allowances(scene, bits))
        for key, (lo, hi) in HALO_CHECKS.items():
            if key in checks:
                checks[key] = {"checks": ["bounds"], "lo": lo, "hi": hi}
    info = {"method": method, "eps": float(tol.eps), "depth_eps": float(tol.depth_eps),
            "normal_tol": NORMAL_TOL, "color_tol": COLOR_TOL, "may_radius": radius,
            "min_subpixel_bits": bits}
    return arrays, info, checks


_GBUFFER = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
            "barycentric", "color")


def _clip_value_checks(scene, raster, arrays, checks, buffers, eps):
    """Value checks of a clip-surface or cutaway scene (see the call): ``golden_face``,
    ``golden_object`` the golden's prim_id and object_id, ``face_may`` where another face may
    win (more than one entry of the clip sets, or the background), ``face_sliver`` where the
    golden's own entry is a sliver whose facing may flip (its values jump even for the same
    face: held to the entry's sliver bounds, not to the golden's interval). Where the
    candidate names the golden's face (and it is not such a sliver) the value is held to the
    golden's interval; where it names another entry, or the golden's sliver, to that entry's
    ``cs_<buffer>`` bounds (:func:`_clip_value_entries`, check
    ``clip``)."""
    from .clip import _named
    surface = _surface_labels(buffers)
    n = np.diff(arrays["cs_offsets"].astype(np.int64)).reshape(surface.shape)
    prim = np.asarray(buffers["prim_id"], np.int64)
    obj = np.asarray(buffers.get("object_id", np.zeros_like(prim)), np.int64)
    arrays["golden_face"] = np.where(prim >= 0, prim, -1).astype(np.int32)
    arrays["golden_object"] = np.where(prim >= 0, obj, -1).astype(np.int32)
    gold = _named(arrays, prim, obj)
    facing = np.asarray(arrays["cs_facing"])
    arrays["face_may"] = (n != 1) | np.asarray(arrays["cs_bg"], np.bool_)
    arrays["face_sliver"] = (gold >= 0) & (facing[np.maximum(gold, 0)] == -1) \
        if len(facing) else np.zeros(surface.shape, np.bool_)
    keys = [k for k in ("barycentric", "color", "normal") if k in buffers and k in checks]
    if keys:
        arrays.update(_clip_value_entries(scene, raster, arrays, eps, keys))
    for key in keys:
        a = np.asarray(buffers[key])
        if key == "normal":
            step = surface_step(a, surface, angle=True)
            arrays["normal_angle"] = (NORMAL_TOL + SHIFT_MARGIN * eps * step).astype(np.float32)
            checks[key] = {"checks": ["angle", "clip"], "angle": "normal_angle",
                           "may": "face_may"}
        else:
            base = BARY_TOL if key == "barycentric" else COLOR_TOL
            arrays[f"{key}_lo"], arrays[f"{key}_hi"] = _interval(a, surface, eps, base)
            checks[key] = {"checks": ["interval", "clip"], "lo": f"{key}_lo", "hi": f"{key}_hi",
                           "may": "face_may"}
    if keys and scene.technique == "cutaway" and "cut_mask" in buffers:
        _cut_entries_from_golden(arrays, buffers, keys)


def _cut_entries_from_golden(arrays, buffers, keys):
    """A cut surface's normal is the cutaway surface's at the pixel (the gradient of D there,
    whichever secondary back face shows it) and its colour the headlight shade of that normal
    along the pixel's ray with its object's palette colour: where the golden itself shows a
    cut surface, another cut entry (``cs_flag`` 1) of the pixel is held to the golden's normal
    interval, and — of the same object — to its colour interval."""
    off = arrays["cs_offsets"].astype(np.int64)
    face = arrays["cs_face"].astype(np.int64)
    draws = arrays["cs_draw_offsets"].astype(np.int64)
    pix = np.repeat(np.arange(off.size - 1, dtype=np.int64), np.diff(off))
    cut_px = np.asarray(buffers["cut_mask"], np.bool_).ravel()
    sel = (np.asarray(arrays["cs_flag"]) == 1) & cut_px[pix]
    p = pix[sel]
    if "normal" in keys:
        arrays["cs_normal"][sel] = np.asarray(buffers["normal"], np.float32).reshape(-1, 3)[p]
        arrays["cs_normal_angle"][sel] = arrays["normal_angle"].ravel()[p]
    if "color" in keys:
        obj = np.searchsorted(draws[1:], face, side="right")
        same = sel & (obj == np.asarray(buffers["object_id"], np.int64).ravel()[pix])
        q = pix[same]
        arrays["cs_color_lo"][same] = arrays["color_lo"].reshape(-1, 3)[q]
        arrays["cs_color_hi"][same] = arrays["color_hi"].reshape(-1, 3)[q]


def _value_region(spec, arrays, others):
    """Where an interval / angle check holds: outside ``id_may``, or — with a ``may`` entry
    (clip scenes) — outside that region or where the candidate names the golden's face, and
    not where the golden's own entry is a sliver that may flip (``face_sliver``; there and
    where the candidate names another entry, the ``clip`` check holds the value to the named
    entry's bounds)."""
    if "may" not in spec or "golden_face" not in arrays:
        return ~arrays["id_may"]
    return ~arrays[spec["may"]] & ~arrays["face_sliver"] | _golden_named(arrays, others)


def _golden_named(arrays, others):
    """(H, W) bool: the candidate's ids name the golden's face, not a sliver that may flip."""
    region = np.zeros(arrays["face_may"].shape, np.bool_)
    if others is not None and "prim_id" in others:
        prim = np.asarray(others["prim_id"], np.int64)
        obj = np.asarray(others.get("object_id", np.zeros_like(prim)), np.int64)
        if prim.shape == region.shape and obj.shape == region.shape:
            gp = arrays["golden_face"].astype(np.int64)
            region = (prim == gp) & (obj == arrays["golden_object"]) & (gp >= 0)
    return region & ~arrays["face_sliver"]


def _clip_value_entries(scene, raster, arrays, eps, keys):
    """Per entry of the clip sets (``cs_*``), what its face may show at its pixel, for the
    value buffers ``keys`` (of :data:`CLIP_VALUES`): the face sets' own derivation
    (:func:`refraster.golden.allowances.core.entry_values`: the ε-square's corners, the allowed
    snappings' barycentrics, a sliver's bounds from its snapped vertices). Entries whose value
    is not the face's own shading are free (±inf, angle π): cap faces of a clip-surface scene
    (their normal and colour come from the cap shading and textures, their faces are not
    among the scene's draws) and, in a cutaway, the entries that are or may be cut surfaces
    (``cs_flag`` ≠ 0: normal and colour come from the cutaway depth D's gradient, whose
    variants are bounded elsewhere) for normal and colour."""
    from ...raster import prepare
    from .clip import CLIP_VALUES
    cam = scene.camera
    meshes = [d.mesh for d in scene.draws]
    models = [d.model for d in scene.draws]
    prep = prepare(meshes, **cam.kwargs, model=models, raster=_geometry(raster))
    off = arrays["cs_offsets"].astype(np.int64)
    face = arrays["cs_face"].astype(np.int64)
    n = len(face)
    pix = np.repeat(np.arange(off.size - 1, dtype=np.int64), np.diff(off))
    own = face < int(prep.face_offsets[-1])         # the scene's draws (not a cap)
    vals = entry_values(scene, raster, prep, pix[own], face[own], eps) if own.any() else None
    shaded = own.copy()
    if scene.technique == "cutaway":
        shaded &= np.asarray(arrays["cs_flag"]) == 0
    out = {}
    for key in keys:
        a, b = CLIP_VALUES[key]
        if key == "normal":
            nrm = np.zeros((n, 3), np.float32)
            ang = np.full(n, np.float32(np.pi), np.float32)
            if vals is not None:
                nrm[own] = vals["set_normal"]
                ang[own] = vals["set_normal_angle"]
            ang[~shaded] = np.float32(np.pi)
            out[a], out[b] = nrm, ang
            continue
        lo = np.full((n, 3), -np.inf, np.float32)
        hi = np.full((n, 3), np.inf, np.float32)
        if vals is not None:
            lo[own] = vals[f"set_{key}_lo"]
            hi[own] = vals[f"set_{key}_hi"]
        if key == "color":
            lo[~shaded], hi[~shaded] = -np.inf, np.inf
        out[a], out[b] = lo, hi
    return out


def _clip_value_outside(key, cand, arrays, others, step):
    """Normal, barycentrics, colour: where the candidate names an entry of the pixel's clip set
    other than the golden's face — or the golden's face where it is a sliver that may flip —
    the value must be what that entry's face may show (``cs_<buffer>``); the golden's face
    elsewhere is held by the ``interval`` / ``angle`` check, a face outside the set by the id
    check."""
    from .clip import CLIP_VALUES, _named
    h, w = arrays["cs_bg"].shape
    named = None
    if others is not None and "prim_id" in others and "object_id" in others:
        prim = np.asarray(others["prim_id"])
        obj = np.asarray(others["object_id"])
        if prim.shape == (h, w) and obj.shape == (h, w):
            named = _named(arrays, prim, obj)
    if named is None or CLIP_VALUES[key][0] not in arrays:
        return np.zeros((h, w), np.bool_)
    hold = (named >= 0) & ~_golden_named(arrays, others)
    out = np.zeros((h, w), np.bool_)
    if not hold.any():
        return out
    e = named[hold]
    v = np.asarray(cand)[hold].astype(np.float64)
    a, b = CLIP_VALUES[key]
    if key == "normal":
        limit = arrays[b][e].astype(np.float64) + step * np.sqrt(3.0)
        out[hold] = ~(_angle(v, arrays[a][e].astype(np.float64)) <= limit)
    else:
        with np.errstate(invalid="ignore"):
            inside = (v >= arrays[a][e].astype(np.float64) - step) \
                & (v <= arrays[b][e].astype(np.float64) + step)
        out[hold] = ~inside.all(axis=1)
    return out


# --- per-pixel face sets (where the visible primitive may differ) --------------------------------

#: Per-entry value arrays of the face sets: buffer → (lo, hi) array names.
SET_INTERVALS = {"depth": ("set_depth_lo", "set_depth_hi"),
                 "eye_depth": ("set_eye_depth_lo", "set_eye_depth_hi"),
                 "barycentric": ("set_barycentric_lo", "set_barycentric_hi"),
                 "color": ("set_color_lo", "set_color_hi")}


from .homogeneous import corner_samples  # noqa: E402


def face_sets(scene, raster, id_may, eps):
    """The face-set arrays of a plain-rendering scene (``GoldenScene.geometry``): for every
    pixel where the visible primitive may differ (``id_may``), the faces that may win there
    (:func:`refraster.conformance.may_faces`) and, per (pixel, face), what that face shows at the
    pixel centre moved by up to ``eps`` — intervals of window depth, eye depth, barycentrics
    and colour, a normal with its angle, and the facing (−1 for a sliver,
    :func:`refraster.conformance.fragile_faces`, that an allowed snapping can flip while covering
    the centre) — so a candidate is checked against the face its own ``prim_id`` names instead
    of being free there. Barycentrics of faces in front of the eye come from the allowed
    snappings (:func:`_snap_barycentrics`), all of a sliver's values from its vertices
    (:func:`_sliver_bounds`)."""
    from ...raster import prepare
    from ...conformance import may_faces
    cam = scene.camera
    meshes = [d.mesh for d in scene.draws]
    models = [d.model for d in scene.draws]
    h, w = cam.height, cam.width
    offsets, faces = may_faces(meshes, **cam.kwargs, model=models, cull=raster["cull"],
                               mask=id_may, eps=eps,
                               raster=_geometry(raster))
    prep = prepare(meshes, **cam.kwargs, model=models, raster=_geometry(raster))
    pix = np.repeat(np.arange(h * w), np.diff(offsets))
    out = entry_values(scene, raster, prep, pix, faces, eps)
    out["set_offsets"] = offsets.astype(np.int32)
    out["set_face"] = faces.astype(np.int32)
    out["draw_offsets"] = np.asarray(prep.face_offsets, np.int32)
    return out


def entry_values(scene, raster, prep, pix, faces, eps):
    """Per (pixel, face) entry, what the face shows at the pixel centre moved by up to ``eps``
    (the ``set_*`` value arrays of :func:`face_sets`, without the offsets): ``prep`` the
    prepared draws of ``scene.draws``, ``pix`` flat pixel indices, ``faces`` global face ids.
    Shared by the face sets of plain scenes and the clip sets of clip-surface and cutaway
    scenes (:func:`_clip_value_entries`)."""
    from ...framebuffer import _build
    from ...conformance import _clipped_slack_at, _face_depth_slack, _face_facing, fragile_faces
    h, w = prep.height, prep.width
    # sample points: the centre and the corners of the square of half-side eps (⊇ the ε-disc);
    # every value here is quasi-linear (affine or a ratio of affine functions of the point), so
    # its extremes over the square are at the corners
    clip = prep.clip[prep.triangles.faces[faces]]
    beta, depth, px, py = corner_samples(clip, pix, w, h, eps)
    n = len(faces)
    smooth = raster["normals"] == "smooth"
    normals = [dd.normals for dd in scene.draws] if smooth else "flat"
    shape = depth.shape
    fb = _build(prep.meshes, prep.models, prep.view, prep.proj,
                np.nan_to_num(depth, nan=1.0).astype(np.float32), np.repeat(faces, 5).reshape(shape),
                prep.face_offsets, np.zeros(shape, np.bool_),
                np.nan_to_num(beta, nan=0.0).astype(np.float32), normals,
                np.ones(3))
    # the face's depth slack at the entry's pixel: a clipped face's part over the ε-square
    # (affine in 1/w: largest at a corner, _clipped_slack_at)
    slack = _face_depth_slack(prep.triangles, DEPTH_EPS)[faces] if n else np.zeros(0)
    if n:
        slack = slack + np.max([_clipped_slack_at(prep, faces, px[:, k], py[:, k])
                                for k in range(px.shape[1])], axis=0)

    def spread(v, base, margin=1.0):
        """``centre ∓ (margin · spread + base)`` per entry (and channel). Depth, eye depth and
        barycentrics are affine or ratios of affine functions of the sample point: their
        extremes over the square are at its corners, so the corners' spread is exact (margin
        1); the colour (a shade of the normal) gets ``SHIFT_MARGIN``."""
        c = v[:, 0]
        lo = c - margin * (c - v.min(axis=1)) - base
        hi = c + margin * (v.max(axis=1) - c) + base
        return lo.astype(np.float32), hi.astype(np.float32)

    out = {}
    if raster.get("depth_clamp"):   # each fragment's depth is clamped to [0, 1]
        depth = np.clip(depth, 0.0, 1.0)
    out["set_depth_lo"], out["set_depth_hi"] = spread(depth, slack)
    eye = fb.eye_depth.astype(np.float64)
    out["set_eye_depth_lo"], out["set_eye_depth_hi"] = spread(
        eye, EYE_DEPTH_ABS + EYE_DEPTH_REL * np.abs(eye[:, 0]))
    out["set_barycentric_lo"], out["set_barycentric_hi"] = spread(beta, BARY_TOL)
    col = fb.color.astype(np.float64)
    out["set_color_lo"], out["set_color_hi"] = spread(col, COLOR_TOL, SHIFT_MARGIN)
    nrm = fb.normal.astype(np.float64)
    out["set_normal"] = nrm[:, 0].astype(np.float32)
    ang = np.zeros(n)
    for k in range(1, depth.shape[1]):
        ang = np.maximum(ang, _angle(nrm[:, 0], nrm[:, k]))
    out["set_normal_angle"] = (NORMAL_TOL + SHIFT_MARGIN * ang).astype(np.float32)
    # a face's facing is definite unless the face itself is a sliver that may flip
    facing = _face_facing(prep.triangles)[faces].astype(np.int8)
    fragile = fragile_faces(prep, eps)[faces] if n else np.zeros(0, np.bool_)
    facing[fragile] = -1
    # a sliver's snapped plane is ill-conditioned (may_faces), but a fragment it covers has
    # non-negative barycentrics: its values are bounded by the face's vertices
    # (:func:`_sliver_bounds`)
    if fragile.any():
        _sliver_bounds(out, facing, fragile, prep, raster, scene, faces, px[:, 0], py[:, 0],
                       beta[:, 0], eps, slack)
    # barycentrics of the other faces in front of the eye: not a shift of the sample point
    # but what the allowed snappings (or unsnapped interpolation) give (_snap_barycentrics)
    whole = ~fragile & (clip[:, :, 3] > 0).all(axis=1)
    if whole.any():
        cw = clip[whole, :, 3].astype(np.float64)
        X = (clip[whole, :, 0] / cw + 1.0) * 0.5 * w
        Y = (clip[whole, :, 1] / cw + 1.0) * 0.5 * h
        _, (b_lo, b_hi), _ = _snap_barycentrics(X, Y, cw, px[whole, 0], py[whole, 0], eps)
        out["set_barycentric_lo"][whole] = (b_lo - BARY_TOL).astype(np.float32)
        out["set_barycentric_hi"][whole] = (b_hi + BARY_TOL).astype(np.float32)
    out["set_facing"] = facing
    # an entry whose values cannot be evaluated (a degenerate face that is not a sliver with
    # all vertices in front of the eye) leaves them free
    bad = ~np.isfinite(depth).all(axis=1) & ~fragile
    for lo_name, hi_name in SET_INTERVALS.values():
        lo, hi = out[lo_name], out[hi_name]
        lo[bad] = -np.inf
        hi[bad] = np.inf
    out["set_normal_angle"][bad] = np.pi
    return out


def _div(n_lo, n_hi, d_lo, d_hi):
    """Interval quotient ``[n_lo, n_hi] / [d_lo, d_hi]``; unbounded when ``0 ∈ [d_lo, d_hi]``."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        c = np.stack([n_lo / d_lo, n_lo / d_hi, n_hi / d_lo, n_hi / d_hi])
    zero = (d_lo <= 0.0) & (d_hi >= 0.0)
    return np.where(zero, -np.inf, c.min(axis=0)), np.where(zero, np.inf, c.max(axis=0))


def _affine_box(v, lo, hi):
    """Range of ``v_0 + b_1 (v_1 − v_0) + b_2 (v_2 − v_0)`` (``v (m, 3, ...)``) for ``b_1, b_2``
    in their intervals (``lo, hi (m, 3)``; ``b_0 = 1 − b_1 − b_2``): each ``b`` occurs once,
    so interval arithmetic is exact."""
    out_lo, out_hi = v[:, 0].copy(), v[:, 0].copy()
    for i in (1, 2):
        dv = v[:, i] - v[:, 0]
        bl = lo[:, i].reshape(lo.shape[:1] + (1,) * (dv.ndim - 1))
        bh = hi[:, i].reshape(bl.shape)
        with np.errstate(invalid="ignore"):
            c = np.where(dv == 0.0, 0.0, np.stack([bl * dv, bh * dv]))   # (±inf)·0 is 0 here
        out_lo = out_lo + c.min(axis=0)
        out_hi = out_hi + c.max(axis=0)
    return out_lo, out_hi


def _cone(lo, hi):
    """Centre direction of a box of vectors ``(m, 3)`` and the largest angle between it and
    any vector of the box (π when the box reaches the origin)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        c = np.nan_to_num(0.5 * (lo + hi), nan=0.0, posinf=0.0, neginf=0.0)
        r = 0.5 * np.linalg.norm(hi - lo, axis=1)
        nc = np.linalg.norm(c, axis=1)
        ang = np.where(np.isfinite(r) & (r < nc), np.arcsin(np.minimum(r / nc, 1.0)), np.pi)
    return c, ang


def _snap_barycentrics(X, Y, cw, px, py, eps, min_bits=None):
    """What barycentrics an allowed rasterizer can give a face at a pixel centre it covers.

    ``X, Y (m, 3)`` the face's unsnapped window vertices (pixels, GL y-up), ``cw (m, 3)`` their
    clip w (> 0), ``px, py (m,)`` the centre. A conformant implementation interpolates either
    from the snapped vertices or, as Mesa and refraster do, from the unsnapped ones (snapping
    deciding coverage only); so the screen-space ``λ`` and the perspective-correct ``β`` lie in
    the union of

    * (snapped) every snapping the allowed variation permits — each window coordinate rounded
      to the nearest multiple of ``2^−b``, ``b`` from the candidate's declared bits
      (``min_bits``; default :func:`~refraster.golden.allowances.precision.candidate_bits`)
      to 8, either way where the float part ``δ`` of
      ``ε`` (float32 arithmetic in another order) reaches a rounding boundary — that covers the
      centre (both fill rules: edges included): ``λ_i = A_i / Σ A_j`` with ``A_i`` the doubled
      signed area of ``(p, V_j, V_k)``, ``β_i ∝ λ_i / w_i``;
    * (unsnapped) the face's own barycentrics at the centre, widened by what moving every
      vertex coordinate by ``δ`` does to ``A_i`` (bilinear: ``δ·Σ|coordinates| + 2δ²``) and
      to ``Σ A_j`` (interval quotient, unbounded when the sum may vanish).

    Returns ``((λ_lo, λ_hi), (β_lo, β_hi), can)``, ``can (m, 2)``: some allowed snapping covers
    the centre with front / back facing.
    """
    m = len(px)
    b_min = candidate_bits() if min_bits is None else int(min_bits)
    delta = max(eps - math.sqrt(2.0) * (2.0 ** -(b_min + 1) + 2.0 ** -(MAX_SNAP_BITS + 1)), 0.0)
    q_of = (np.ones((m, 3)), 1.0 / cw)
    lims = [(np.full((m, 3), np.inf), np.full((m, 3), -np.inf)) for _ in q_of]
    can = np.zeros((m, 2), np.bool_)
    coords = np.concatenate([X, Y], axis=1)                         # (m, 6)

    def visit(rows, v):
        xs, ys = v[:, :3] - px[rows, None], v[:, 3:] - py[rows, None]
        A = np.empty((len(rows), 3))
        for i in range(3):
            j, k = (i + 1) % 3, (i + 2) % 3
            A[:, i] = xs[:, j] * ys[:, k] - xs[:, k] * ys[:, j]
        tot = A.sum(axis=1)
        front = (A >= 0.0).all(axis=1) & (tot > 0.0)
        back = (A <= 0.0).all(axis=1) & (tot < 0.0)
        can[rows, 0] |= front
        can[rows, 1] |= back
        ok = rows[front | back]
        Aok = A[front | back]
        for q, (lo, hi) in zip(q_of, lims):
            aq = Aok * q[ok]
            bb = aq / aq.sum(axis=1, keepdims=True)
            lo[ok] = np.minimum(lo[ok], bb)
            hi[ok] = np.maximum(hi[ok], bb)

    for bits in range(b_min, MAX_SNAP_BITS + 1):
        sc = float(1 << bits)
        t = coords * sc
        base = np.floor(t)
        frac = t - base
        near = np.where(frac >= 0.5, base + 1.0, base) / sc
        visit(np.arange(m), near)
        tie = np.abs(frac - 0.5) <= delta * sc
        other = np.where(near * sc == base, base + 1.0, base) / sc
        # the other neighbour at the ties, in every combination (rows grouped by their ties)
        tmask = (tie * (1 << np.arange(6))).sum(axis=1)
        for u in np.unique(tmask[tmask > 0]):
            rows = np.flatnonzero(tmask == u)
            sub = int(u)
            while sub:
                pick = (sub >> np.arange(6)) & 1 == 1
                visit(rows, np.where(pick, other[rows], near[rows]))
                sub = (sub - 1) & int(u)
    # (unsnapped) the face's own barycentrics at the centre, ± float rounding of the vertices
    spread = np.empty((m, 3))
    a_c = np.empty((m, 3))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        a_c[:, i] = (X[:, j] - px) * (Y[:, k] - py) - (X[:, k] - px) * (Y[:, j] - py)
        spread[:, i] = delta * (np.abs(X[:, j] - px) + np.abs(Y[:, j] - py)
                                + np.abs(X[:, k] - px) + np.abs(Y[:, k] - py)) + 2.0 * delta ** 2
    for q, (lo, hi) in zip(q_of, lims):
        d_c = (a_c * q).sum(axis=1)
        d_r = (spread * q).sum(axis=1)
        for i in range(3):
            u_lo, u_hi = _div((a_c[:, i] - spread[:, i]) * q[:, i],
                              (a_c[:, i] + spread[:, i]) * q[:, i], d_c - d_r, d_c + d_r)
            lo[:, i] = np.minimum(lo[:, i], u_lo)
            hi[:, i] = np.maximum(hi[:, i], u_hi)
    return lims[0], lims[1], can


def _sliver_bounds(out, facing, fragile, prep, raster, scene, faces, px, py, beta_c, eps,
                   slack):
    """Bound the values of the face-set entries of slivers (``fragile``, in place).

    Another snapping may flip a sliver or put its plane anywhere; but a conformant
    implementation interpolates either from the snapped vertices (the fragment's barycentrics
    are then non-negative) or, as Mesa and refraster do, from the unsnapped ones (the
    barycentrics of the unsnapped face at the centre, however far they extrapolate). So the
    screen-space barycentrics ``λ`` and the perspective-correct ``β`` lie in the union of

    * (snapped) the range over every vertex moved by up to ``ε/√2`` per axis that still
      covers the centre ``p``: from the signed areas ``A_i(p)`` of the triangles
      ``(p, V_j, V_k)`` (:func:`_area_interval`, exact per ``A_i``), covering ``p`` with
      facing ``s`` needs ``s·A_i ≥ 0`` for all three, and ``β_i = (A_i/w_i) / Σ_j (A_j/w_j)``
      (``λ``: ``w = 1``) is increasing in ``A_i`` and decreasing in the others, so its extremes
      are at the ends of the (independently taken, hence wider) intervals;
    * (unsnapped) the face's own barycentrics at ``p``, widened by what a float rounding of the
      vertices (the float part of ``ε``) does to ``A_i / A``.

    Every value is an affine function of ``λ`` (window depth) or ``β`` (eye depth, eye
    position, the smooth normal before normalisation), bounded over that box by interval
    arithmetic (:func:`_affine_box`); the normal by the cone of its box (flat: the face
    normal itself); the colour, a shade increasing in ``d = |m · v̂|``, between the shades of
    the least and largest ``d`` that angles within ``θ_n + θ_v`` of the centre's give
    (``θ_v`` the cone of the eye-position box). A facing is free (−1) only where both signs can
    cover ``p``.
    """
    from ...framebuffer import PALETTE, _build
    from ...raster.gbuffer import AMBIENT, DIFFUSE, SHININESS, SPECULAR
    idx = np.flatnonzero(fragile)
    g = faces[idx]
    m = len(idx)
    h, w = prep.height, prep.width
    vid = prep.triangles.faces[g]                                   # (m, 3) vertex ids
    clip = prep.clip[vid].astype(np.float64)                        # (m, 3, 4)
    cw = clip[:, :, 3]                                              # > 0 (fragile_faces)
    X = (clip[:, :, 0] / cw + 1.0) * 0.5 * w
    Y = (clip[:, :, 1] / cw + 1.0) * 0.5 * h
    Z = 0.5 * clip[:, :, 2] / cw + 0.5
    qx, qy = px[idx], py[idx]
    (lam_lo, lam_hi), (bet_lo, bet_hi), can = _snap_barycentrics(X, Y, cw, qx, qy, eps)
    facing[idx] = np.where(can[:, 0] & can[:, 1], -1,
                           np.where(can[:, 0], 1, np.where(can[:, 1], 0, -1)))
    out["set_barycentric_lo"][idx] = (bet_lo - BARY_TOL).astype(np.float32)
    out["set_barycentric_hi"][idx] = (bet_hi + BARY_TOL).astype(np.float32)
    # window depth: affine in λ, clamped to [0, 1], ∓ the face's slack
    z_lo, z_hi = _affine_box(Z, lam_lo, lam_hi)
    out["set_depth_lo"][idx] = (np.clip(z_lo, 0.0, 1.0) - slack[idx]).astype(np.float32)
    out["set_depth_hi"][idx] = (np.clip(z_hi, 0.0, 1.0) + slack[idx]).astype(np.float32)
    # the G-buffer's own finalisation at the three vertices
    samp = np.eye(3)
    bary = np.broadcast_to(samp, (m, 3, 3)).astype(np.float32)
    normals = [dd.normals for dd in scene.draws] if raster["normals"] == "smooth" else "flat"
    fb = _build(prep.meshes, prep.models, prep.view, prep.proj,
                np.zeros((m, 3), np.float32), np.repeat(g, 3).reshape(m, 3),
                prep.face_offsets, np.zeros((m, 3), np.bool_), bary, normals, np.ones(3))
    eye = fb.eye_depth.astype(np.float64)
    e_lo, e_hi = _affine_box(eye, bet_lo, bet_hi)
    budget = EYE_DEPTH_ABS + EYE_DEPTH_REL * np.maximum(np.abs(e_lo), np.abs(e_hi))
    out["set_eye_depth_lo"][idx] = (e_lo - budget).astype(np.float32)
    out["set_eye_depth_hi"][idx] = (e_hi + budget).astype(np.float32)
    # normal: flat, the face's own; smooth, the cone of the interpolated eye-space vertex
    # normals (normal matrix · vertex normal, before the renormalisation) over the β box
    nrm = fb.normal.astype(np.float64)
    obj, _ = prep.split(g)
    if raster["normals"] == "smooth":
        from ...framebuffer import _normal_matrix, _normals_per_mesh
        vn = np.concatenate(_normals_per_mesh(prep.meshes, normals)).astype(np.float64)
        nmat = np.stack([_normal_matrix(prep.view, mm) for mm in prep.models])
        u = np.einsum("mij,mkj->mki", nmat[obj], vn[vid])
        n_c, theta_n = _cone(*_affine_box(u, bet_lo, bet_hi))
        n_c = n_c / np.maximum(np.linalg.norm(n_c, axis=1, keepdims=True), 1e-300)
    else:
        n_c, theta_n = nrm[:, 0], np.zeros(m)
    out["set_normal"][idx] = n_c.astype(np.float32)
    out["set_normal_angle"][idx] = (NORMAL_TOL + theta_n).astype(np.float32)
    # colour: eye positions (from clip space: the projection is invertible) over the β box
    inv = np.linalg.inv(np.asarray(prep.proj, np.float64))
    e4 = np.einsum("ij,mkj->mki", inv, clip)
    ev = e4[:, :, :3] / e4[:, :, 3:4]
    e_c, theta_v = _cone(*_affine_box(ev, bet_lo, bet_hi))
    alpha = _angle(n_c, -e_c)           # the centre's angle to the eye direction, in [0, π]
    theta = np.minimum(theta_n + theta_v, np.pi)
    a0, a1 = alpha - theta, alpha + theta
    ends = np.abs(np.cos(np.stack([np.clip(a0, 0.0, np.pi), np.clip(a1, 0.0, np.pi)])))
    d_hi = np.where((a0 <= 0.0) | (a1 >= np.pi), 1.0, ends.max(axis=0))
    d_lo = np.where((a0 <= np.pi / 2) & (a1 >= np.pi / 2), 0.0, ends.min(axis=0))

    def shade(dd, pk):
        dd = np.minimum(dd, 1.0)[:, None]
        return np.clip(PALETTE[pk] * (AMBIENT + DIFFUSE * dd) + SPECULAR * dd ** SHININESS,
                       0.0, 1.0)

    pk = obj % PALETTE.shape[0]
    out["set_color_lo"][idx] = (shade(d_lo, pk) - COLOR_TOL).astype(np.float32)
    out["set_color_hi"][idx] = (shade(d_hi, pk) + COLOR_TOL).astype(np.float32)


def check_face_sets(arrays, height, width):
    """Raise ``ValueError`` unless the face-set arrays of ``tolerance.npz`` (when present) are
    consistent: a file is never trusted to index with."""
    if "set_offsets" not in arrays:
        return
    off = np.asarray(arrays["set_offsets"])
    face = np.asarray(arrays["set_face"])
    draws = np.asarray(arrays["draw_offsets"])
    n = len(face)
    if off.shape != (height * width + 1,) or off[0] != 0 or off[-1] != n \
            or np.any(np.diff(off.astype(np.int64)) < 0):
        raise ValueError("set_offsets is not an offset array over the frame's pixels")
    if draws.ndim != 1 or len(draws) < 2 or draws[0] != 0 or np.any(np.diff(draws) < 0):
        raise ValueError("draw_offsets is not an offset array over the draw calls")
    if n and (face.min() < 0 or face.max() >= draws[-1]):
        raise ValueError("set_face holds a face outside the scene's draws")
    for name in ("set_facing", "set_normal", "set_normal_angle") + tuple(
            x for pair in SET_INTERVALS.values() for x in pair):
        if np.asarray(arrays[name]).shape[:1] != (n,):
            raise ValueError(f"{name} does not have one row per face-set entry ({n})")
    if n and not np.isin(arrays["set_facing"], (-1, 0, 1)).all():
        raise ValueError("set_facing holds values other than -1, 0, 1")


def named_entries(arrays, prim_id, object_id=None):
    """(H, W) int64: the face-set entry of the face each candidate pixel names (its
    ``object_id``'s draw, its ``prim_id``), −1 where the pixel is uncovered, has no set, or
    names a face outside its set; ``None`` for a golden without face sets."""
    if "set_offsets" not in arrays:
        return None
    prim = np.asarray(prim_id, np.int64)
    h, w = prim.shape
    draws = arrays["draw_offsets"].astype(np.int64)
    if object_id is None:
        if len(draws) != 2:
            return None
        obj = np.zeros_like(prim)
    else:
        obj = np.asarray(object_id, np.int64)
    ok = (prim >= 0) & (obj >= 0) & (obj < len(draws) - 1)
    objc = np.clip(obj, 0, len(draws) - 2)
    g = np.where(ok & (prim < draws[objc + 1] - draws[objc]), draws[objc] + prim, -1).ravel()
    offsets = arrays["set_offsets"].astype(np.int64)
    faces = arrays["set_face"].astype(np.int64)
    out = np.full(h * w, -1, np.int64)
    has = np.flatnonzero((np.diff(offsets) > 0) & (g >= 0))
    for k in has:   # sets are small (a few faces); sorted, so a binary search
        lo, hi = offsets[k], offsets[k + 1]
        j = lo + np.searchsorted(faces[lo:hi], g[k])
        if j < hi and faces[j] == g[k]:
            out[k] = j
    return out.reshape(h, w)


# --- the tolerant check --------------------------------------------------------------------------

def _candidate_coverage(key, kind, candidate, clear_depth, depth_func="less", prim_id=None):
    if kind == "id":
        return np.asarray(candidate) >= 0
    if key == "depth":
        return covered_by(candidate, clear_depth, depth_func, prim_id)
    raise ValueError(f"buffer {key!r} ({kind}) cannot give coverage")


def _face_outside(key, kind, cand, arrays, named, step, clear_depth, depth_func="less",
                  prim_id=None):
    """(H, W) bool: where the visible primitive may differ (``id_may``), the candidate's value
    is not what the face its own ``prim_id`` names can show there (its face-set entry), or —
    for ids — that face may not win there. Without candidate ids (``named`` None) values are
    checked against the envelope of the pixel's whole set."""
    id_may = np.asarray(arrays["id_may"], np.bool_)
    h, w = id_may.shape
    offsets = arrays["set_offsets"].astype(np.int64)
    has = (np.diff(offsets) > 0).reshape(h, w)
    c = np.asarray(cand)
    if kind == "id" or key == "front_facing":
        if named is None:
            return np.zeros((h, w), np.bool_)
        if key == "front_facing":
            if not len(arrays["set_facing"]):    # no pixel where the primitive may differ
                return np.zeros((h, w), np.bool_)
            e = np.maximum(named, 0)
            facing = arrays["set_facing"][e]
            return id_may & (named >= 0) & (facing >= 0) & (c != (facing == 1))
        return id_may & has & (c >= 0) & (named < 0)
    # without ids (the envelope), a pixel counts as covered by what its own buffer says (or,
    # for buffers that cannot say, where the golden's coverage is "must")
    if key == "depth":
        covered = covered_by(c, clear_depth, depth_func, prim_id)
    elif key == "eye_depth":
        covered = np.isfinite(c)
    elif key == "normal":
        covered = np.linalg.norm(c.astype(np.float64), axis=2) > 0.5
    elif "coverage" in arrays:
        covered = np.asarray(arrays["coverage"]) == MUST
    else:
        covered = np.zeros((h, w), np.bool_)
    if named is not None:   # the candidate's ids say which pixels it covers
        pick = id_may & (named >= 0)
        e = named[pick]
    else:
        pick = id_may & has & covered
        e = None
    out = np.zeros((h, w), np.bool_)
    if not pick.any():
        return out
    v = c[pick].astype(np.float64)
    if key == "normal":
        limit = arrays["set_normal_angle"].astype(np.float64) + step * math.sqrt(3.0)
        if e is None:   # no ids: some face of the set must be within its angle
            k = np.flatnonzero(pick.ravel())
            n = offsets[k + 1] - offsets[k]
            ent = np.repeat(offsets[k], n) + (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
            miss = _angle(np.repeat(v, n, axis=0), arrays["set_normal"][ent]) - limit[ent]
            bad = np.minimum.reduceat(miss, np.cumsum(n) - n) > 0
        else:
            bad = _angle(v, arrays["set_normal"][e]) > limit[e]
    else:
        lo_name, hi_name = SET_INTERVALS[key]
        lo, hi = arrays[lo_name], arrays[hi_name]
        if e is None:   # the envelope of the pixel's set
            # pixels with entries own consecutive, non-empty runs of the entry arrays
            runs = np.flatnonzero(has.ravel())
            slot = np.full(h * w, -1, np.int64)
            slot[runs] = np.arange(len(runs))
            k = slot[np.flatnonzero(pick.ravel())]
            lo = np.minimum.reduceat(lo, offsets[runs], axis=0)[k]
            hi = np.maximum.reduceat(hi, offsets[runs], axis=0)[k]
        else:
            lo, hi = lo[e], hi[e]
        with np.errstate(invalid="ignore"):
            bad = ~((v >= lo.astype(np.float64) - step) & (v <= hi.astype(np.float64) + step))
        bad = bad.any(axis=1) if bad.ndim == 2 else bad
    out[pick] = bad
    return out


def _fmt(v):
    v = np.asarray(v, np.float64)
    return f"{float(v):.6g}" if v.ndim == 0 else "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _allowed_at(key, spec, arrays, outside, r, c, named, step):
    """What the allowance admits at pixel (r, c), for the checks that refuse it there: the
    interval, the angle, the coverage or the set of faces (object_id, prim_id)."""
    said = []
    for name, m in outside.items():
        if not m[r, c]:
            continue
        if name == "coverage":
            cov = int(arrays["coverage"][r, c])
            said.append("coverage: " + {MUST: "must be covered", MUST_NOT: "must not be covered",
                                        MAY: "may"}[cov])
        elif name == "id":
            said.append("id: equal to the golden's")
        elif name == "interval":
            said.append(f"interval [{_fmt(arrays[spec['lo']][r, c] - step)}, "
                        f"{_fmt(arrays[spec['hi']][r, c] + step)}]")
        elif name == "angle":
            said.append(f"angle to the golden's normal <= {float(arrays[spec['angle']][r, c]):.4g}"
                        " rad")
        elif name == "face":
            said.append("face: " + face_allowed(key, arrays, r, c, named, step))
        elif name == "bounds":
            said.append(f"interval [{_fmt(arrays[spec['lo']][r, c] - step)}, "
                        f"{_fmt(arrays[spec['hi']][r, c] + step)}]"
                        + (" or 0" if "zero" in spec and arrays[spec["zero"]][r, c] else ""))
        elif name == "clip":
            from .clip import clip_allowed
            said.append(clip_allowed(key, arrays, r, c, step=step))
        elif name == "layers":
            from .layers import layers_allowed
            said.append(layers_allowed(spec["layer"], arrays, r, c, step=step))
    return "; ".join(said) or None


def face_allowed(key, arrays, r, c, named, step=0.0):
    """What the face check admits at pixel (r, c) of buffer ``key``, in words: the set of faces
    (object_id, prim_id) that may win there, or the interval / normal / facing of the face the
    candidate names (the envelope of the set without ids)."""
    w = arrays["id_may"].shape[1]
    k = r * w + c
    lo, hi = int(arrays["set_offsets"][k]), int(arrays["set_offsets"][k + 1])
    draws = arrays["draw_offsets"].astype(np.int64)
    faces = arrays["set_face"][lo:hi].astype(np.int64)
    obj = np.searchsorted(draws[1:], faces, side="right")
    pairs = ", ".join(f"({int(o)}, {int(f - draws[o])})" for o, f in zip(obj, faces))
    e = -1 if named is None else int(named[r, c])
    if key in ("prim_id", "object_id"):
        return f"(object_id, prim_id) one of {{{pairs}}}"
    if e < 0:
        return f"the envelope of the faces {{{pairs}}}"
    if key == "front_facing":
        f = int(arrays["set_facing"][e])
        return "any (a sliver may flip)" if f < 0 else f"front_facing {bool(f)} (the named face's)"
    if key == "normal":
        return (f"within {float(arrays['set_normal_angle'][e]):.4g} rad of "
                f"{_fmt(arrays['set_normal'][e])} (the named face's)")
    lo_n, hi_n = SET_INTERVALS[key]
    return (f"[{_fmt(arrays[lo_n][e] - step)}, {_fmt(arrays[hi_n][e] + step)}] "
            "(the named face's)")


def tolerant_metrics(key, reference, candidate, kind, spec, arrays, *, clear_depth=1.0,
                     fallback=None, step=0.0, named=None, others=None, depth_func="less"):
    """Metrics, checks and images of one buffer under its tolerant checks.

    Parameters
    ----------
    key, kind : str
        Buffer name and kind.
    reference, candidate : arrays of the same shape
    spec : dict
        The buffer's ``"tolerant"`` manifest entry.
    arrays : dict
        The scene's ``tolerance.npz``.
    clear_depth : float
        Depth of an uncovered pixel (coverage of a depth buffer).
    depth_func : str
        The scene's depth test: a depth buffer covers a pixel where it holds a value before
        ``clear_depth`` in the test's direction (``greater``/``gequal``: above it), layers
        are peeled in that direction.
    fallback : dict
        The ``conformant`` tolerance, for ``masked``.
    step : float
        Quantisation step of the candidate's encoding (widens intervals and angles).
    named : (H, W) int64, optional
        :func:`named_entries` of the candidate's ids (the ``face`` check); ``None`` when the
        candidate sends no ids.
    others : dict, optional
        The candidate's buffers of the scene, for checks that read another buffer (the
        ``layers`` check names each layer's face by the candidate's ``layer_prim_id``).

    Returns
    -------
    (metrics, checks, images) as :func:`refraster.golden.compare.metrics.buffer_metrics`, plus
    ``metrics["outside"]`` (pixels outside the allowance per check) and ``images["may"]``.
    """
    from ..compare.metrics import _elementwise_error, buffer_metrics
    ref = np.asarray(reference)
    cand = np.asarray(candidate)
    id_may = arrays["id_may"]
    h, w = ref.shape[:2]
    outside = {}
    masked = None
    # the candidate's own ids, where coverage cannot be read from its depth alone
    ids = None if others is None or "prim_id" not in others else others["prim_id"]
    for name in spec["checks"]:
        if name == "coverage":
            cov = arrays["coverage"]
            cc = _candidate_coverage(key, kind, cand, clear_depth, depth_func, ids)
            outside["coverage"] = ((cov == MUST) & ~cc) | ((cov == MUST_NOT) & cc)
        elif name == "id":
            region = ~id_may
            if kind == "id":
                region &= (ref >= 0) & (cand >= 0)
            diff = ref != cand
            outside["id"] = region & (diff.any(axis=2) if diff.ndim == 3 else diff)
        elif name == "interval":
            lo = arrays[spec["lo"]].astype(np.float64) - step
            hi = arrays[spec["hi"]].astype(np.float64) + step
            c = cand.astype(np.float64)
            with np.errstate(invalid="ignore"):
                bad = ~((c >= lo) & (c <= hi))
            bad = bad.any(axis=2) if bad.ndim == 3 else bad
            region = _value_region(spec, arrays, others)
            if key == "depth" and "coverage" in arrays:
                region &= (arrays["coverage"] == MUST) & covered_by(cand, clear_depth,
                                                                    depth_func, ids)
            outside["interval"] = region & bad
        elif name == "angle":
            limit = arrays[spec["angle"]].astype(np.float64) + step * math.sqrt(3.0)
            outside["angle"] = _value_region(spec, arrays, others) & ~(_angle(ref, cand)
                                                                         <= limit)
        elif name == "masked":
            masked = buffer_metrics(ref, cand, kind, fallback, step=step,
                                    forgive=arrays[spec.get("may", "may")])
        elif name == "face":
            outside["face"] = _face_outside(key, kind, cand, arrays, named, step, clear_depth,
                                            depth_func, ids)
        elif name == "bounds":   # an interval at every pixel, whatever the visible face
            lo = arrays[spec["lo"]].astype(np.float64) - step
            hi = arrays[spec["hi"]].astype(np.float64) + step
            with np.errstate(invalid="ignore"):
                bad = ~((cand.astype(np.float64) >= lo) & (cand.astype(np.float64) <= hi))
            if "zero" in spec:   # or 0 where that is allowed (no fragment is sure)
                bad &= ~(np.asarray(arrays[spec["zero"]], np.bool_) & (cand == 0))
            outside["bounds"] = bad.any(axis=2) if bad.ndim == 3 else bad
        elif name == "clip":
            from .clip import CLIP_VALUES, clip_outside
            outside["clip"] = (_clip_value_outside(key, cand, arrays, others, step)
                               if key in CLIP_VALUES else
                               clip_outside(key, cand, arrays, others, step=step,
                                            clear=clear_depth, depth_func=depth_func))
        elif name == "layers":
            from .layers import layers_outside
            outside["layers"] = layers_outside(spec["layer"], cand, arrays, others, step=step,
                                               clear=clear_depth, depth_func=depth_func)
        else:
            raise ValueError(f"unknown tolerant check {name!r}")
    err_el = _elementwise_error(ref, cand)
    err = err_el.max(axis=2) if err_el.ndim == 3 else err_el
    bad = np.zeros((h, w), np.bool_)
    for m in outside.values():
        bad |= m
    checks = []
    if masked is not None:
        metrics, checks, images = masked
        bad |= images["over"] & ~images["forgiven"]
    else:
        mse = float(np.mean(err_el ** 2)) if err_el.size else 0.0
        from ..io.buffers import peak
        p = peak(ref, kind)
        psnr = math.inf if mse == 0 else (-math.inf if not math.isfinite(mse)
                                          else 10.0 * math.log10(p * p / mse))
        metrics = {"max_abs": float(err.max()) if err.size else 0.0, "rmse": math.sqrt(mse),
                   "psnr": psnr, "threshold": 0.0, "pixels": int(err.size)}
        images = {"error": err, "flip": None}
    differ = err > 0
    n = err.size
    metrics.update({"fraction_over": float(differ.sum()) / n, "n_over": int(differ.sum()),
                    "fraction_unforgiven": float(bad.sum()) / n, "n_unforgiven": int(bad.sum()),
                    "outside": {k: int(v.sum()) for k, v in outside.items()}})
    worst = None
    if bad.any():
        flat = int(np.argmax(np.where(bad, np.where(np.isfinite(err), err, 1e300), -1.0)))
        r, c = divmod(flat, w)
        worst = {"row": r, "col": c, "reference": ref[r, c].tolist(),
                 "candidate": cand[r, c].tolist(),
                 "allowed": _allowed_at(key, spec, arrays, outside, r, c, named, step)}
    metrics["worst"] = worst if masked is None or worst is not None else metrics.get("worst")
    images.update({"over": differ | bad, "forgiven": differ & ~bad, "may": id_may.copy()})
    for name, m in outside.items():
        where = np.argwhere(m)
        first = [[int(r), int(c)] for r, c in where[:5]]
        checks.append({"metric": name, "value": int(m.sum()), "limit": 0, "op": "<=",
                       "ok": not m.any(),
                       "detail": f"{int(m.sum())} of {n} pixels outside the allowance; first "
                                 f"(row, col): {first}"})
    return metrics, checks, images
