"""Tolerant goldens: per-pixel allowances stored beside a scene's buffers, and the tolerant check.

At ``golden generate`` every scene gets ``<scene>/tolerance.npz`` (listed in the manifest with
its sha256) holding what a conformant GPU may do differently (:mod:`refraster.tolerance`):

==================  ===========  ================================================================
array               dtype        meaning
==================  ===========  ================================================================
``coverage``        int8         2 must be covered, 1 may be, 0 must not be
``id_may``          bool         the visible primitive may differ (ids, facing and values free)
``may``             bool         the technique's own "may" region (decision boundaries, filter
                                 footprints); technique buffers are free there
``depth_lo/_hi``    float32      window-depth interval (:func:`refraster.tolerance.tolerance`)
``<buf>_lo/_hi``    float32      value interval of ``eye_depth``, ``barycentric``, ``color``
``normal_angle``    float32      largest angle (radians) between reference and candidate normal
==================  ===========  ================================================================

Each buffer's manifest entry says which checks apply (``"tolerant": {"checks": [...]}``):
``coverage`` (the candidate's coverage against the three-valued mask), ``id`` (equal where the id
must agree), ``interval`` (``lo ≤ value ≤ hi`` per channel where the id must agree), ``angle``
(normals) and ``masked`` (the ``conformant`` profile, with the ``may`` region forgiven: buffers
without an interval of their own).

How the arrays are derived
--------------------------
*Plain G-buffers* (``GoldenScene.geometry`` true: the buffers are what
:func:`refraster.render` makes of the draws): :func:`refraster.tolerance.tolerance` gives the
coverage, id and depth allowances. Interpolated values (eye depth, barycentrics, normals,
colour) may change by what a shift of the sample point by the edge ε does:
``base + 1.5 · ε · step`` where ``step`` is the largest change to a 4-neighbour showing the same
primitive of the same draw (the discrete gradient of the value on that surface). ``base`` is the
float32 budget: eye depth ``1e−5 + 4e−6·z``, barycentrics ``1e−3``, normals
``NORMAL_TOL`` (2e−3 rad), colour ``COLOR_TOL`` (2/255).

*Technique scenes* whose G-buffer is not a plain render (a clip surface shows back faces):
:func:`refraster.tolerance.edge_may` marks every edge of every drawn triangle (hidden ones
included), the scene adds its decision boundary (``GoldenScene.may``, from
:func:`refraster.tolerance.decision_may`), the union is dilated by one pixel for ids and coverage
(coverage itself comes from the reference's ids) and values fall back to ``masked``.

*Technique buffers* (anything that is not a G-buffer channel, e.g. an edge map): ``may`` is the
id/coverage "may" region plus the scene's decision region, dilated by ``GoldenScene.may_radius``
pixels — the footprint of the technique's image filters — and the check is ``masked``.
"""

from __future__ import annotations

import math

import numpy as np

from ..tolerance import (COLOR_TOL, DEPTH_EPS, MAY, MUST, MUST_NOT, NORMAL_TOL, edge_may,
                         facing_may, tolerance)

__all__ = ["scene_allowances", "tolerant_metrics", "dilate", "surface_step", "TOLERANT_CHECKS"]

TOLERANT_CHECKS = ("coverage", "id", "interval", "angle", "masked")

#: float32 budgets of the interpolated G-buffer values (see the module docstring).
EYE_DEPTH_ABS, EYE_DEPTH_REL = 1e-5, 4e-6
BARY_TOL = 1e-3
#: Second-order margin on the first-order "value changes by step · ε" estimate.
SHIFT_MARGIN = 1.5


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


def scene_allowances(scene, raster):
    """Allowances of one scene.

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
    geometry = bool(scene.geometry) and raster["depth_func"] == "less"
    kw = dict(**cam.kwargs, model=models, cull=raster["cull"])
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
    # slivers that may change facing at 4 bits (a gap in tolerance()'s shared-edge rule)
    flip_id, flip_cov = facing_may(meshes, **cam.kwargs, model=models)
    if geometry:
        coverage = masks.coverage.copy()
        coverage[flip_cov] = MAY
        id_may = masks.id_may | flip_id
        depth_lo = np.where(id_may, np.float32(0.0), tol.depth_lo)
        depth_hi = np.where(id_may, np.float32(1.0), tol.depth_hi)
        method = "geometry"
    else:
        edges_id, _ = edge_may(meshes, **cam.kwargs, model=models, cull=raster["cull"])
        id_may = dilate(edges_id | flip_id | extra, 1)
        if "prim_id" in buffers:
            ref_cov = np.asarray(buffers["prim_id"]) >= 0
        elif "depth" in buffers:
            ref_cov = np.asarray(buffers["depth"]) < raster["clear_depth"]
        else:
            ref_cov = None
        coverage = (None if ref_cov is None else
                    np.where(id_may, MAY, np.where(ref_cov, MUST, MUST_NOT)).astype(np.int8))
        method = "decision" if scene.may is not None else "dilated"
    may = dilate(id_may | extra, max(radius, 0))
    arrays = {"id_may": id_may, "may": may}
    if coverage is not None:
        arrays["coverage"] = coverage
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
    info = {"method": method, "eps": float(tol.eps), "depth_eps": float(tol.depth_eps),
            "normal_tol": NORMAL_TOL, "color_tol": COLOR_TOL, "may_radius": radius,
            "min_subpixel_bits": 4}
    return arrays, info, checks


_GBUFFER = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
            "barycentric", "color")


# --- the tolerant check --------------------------------------------------------------------------

def _candidate_coverage(key, kind, candidate, clear_depth):
    if kind == "id":
        return np.asarray(candidate) >= 0
    if key == "depth":
        return np.asarray(candidate) < clear_depth
    raise ValueError(f"buffer {key!r} ({kind}) cannot give coverage")


def tolerant_metrics(key, reference, candidate, kind, spec, arrays, *, clear_depth=1.0,
                     fallback=None, step=0.0):
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
    fallback : dict
        The ``conformant`` tolerance, for ``masked``.
    step : float
        Quantisation step of the candidate's encoding (widens intervals and angles).

    Returns
    -------
    (metrics, checks, images) as :func:`refraster.golden.metrics.buffer_metrics`, plus
    ``metrics["outside"]`` (pixels outside the allowance per check) and ``images["may"]``.
    """
    from .metrics import _elementwise_error, buffer_metrics
    ref = np.asarray(reference)
    cand = np.asarray(candidate)
    id_may = arrays["id_may"]
    h, w = ref.shape[:2]
    outside = {}
    masked = None
    for name in spec["checks"]:
        if name == "coverage":
            cov = arrays["coverage"]
            cc = _candidate_coverage(key, kind, cand, clear_depth)
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
            region = ~id_may
            if key == "depth" and "coverage" in arrays:
                region &= (arrays["coverage"] == MUST) & (cand < clear_depth)
            outside["interval"] = region & bad
        elif name == "angle":
            limit = arrays[spec["angle"]].astype(np.float64) + step * math.sqrt(3.0)
            outside["angle"] = ~id_may & ~(_angle(ref, cand) <= limit)
        elif name == "masked":
            masked = buffer_metrics(ref, cand, kind, fallback, step=step,
                                    forgive=arrays[spec.get("may", "may")])
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
        from .buffers import peak
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
                 "candidate": cand[r, c].tolist()}
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
