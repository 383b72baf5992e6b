"""Allowances of goldens in other API conventions (``docs/tolerance.md``, "Conventions").

The allowances of :mod:`refraster.conformance` and of this package are derived in OpenGL's
conventions: counter-clockwise fronts, ``less`` with the buffer cleared to 1, −w ≤ z ≤ w with
window depth ``½·z/w + ½``, NDC y up. A scene in other conventions is first mapped into an
*equivalent* OpenGL scene (:func:`equivalent`) that draws the same picture with the same
coverage, the same faces and the same eye-space values, by a linear map ``T`` of the clip
coordinates (:func:`clip_map`):

* ``ndc_y="down"``: ``y → −y`` (the picture as the API shows it; the window origin only moves
  where snapping ties round, which the allowed 4…8-bit snappings already cover);
* ``depth_range="zero_to_one"``: ``z → 2·z − w`` (same clip volume, same window depth
  ``z/w = ½·(2z − w)/w + ½``);
* a depth test that keeps the larger depth (``greater``, ``gequal``: reversed-Z): ``z → −z``
  after that (window depth ``d → 1 − d``; the clip volume is symmetric), the test becomes
  ``less``/``lequal``, the clear depth ``1 − c``;
* ``front_face="cw"``: culling ``back`` ↔ ``front`` (what the pipeline's ``cull_code`` does).

``depth_clamp`` stays (:func:`refraster.conformance.tolerance` takes it). The allowances are
derived on the equivalent scene and moved back (:func:`move_back`): depth intervals
``[lo, hi] → [1 − hi, 1 − lo]`` under a reversing test, facings flipped under ``cw``; every
depth interval widened by the depth format's quantisation (``0.6·Δ``, :func:`quantum`), and
under ``zero_to_one`` the plain depth interval is re-derived around the golden's own depth
with the relative error model ``32·κ·2⁻²⁴·S`` of the visible face (:func:`face_depth_model`)
instead of the absolute ``4e−5`` of OpenGL's ``½·z + ½``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["is_gl", "reverses", "clip_map", "equivalent", "move_back", "quantum",
           "face_depth_model", "depth_covered", "covered_by", "NO_DIRECTION", "DEPTH_K",
           "QUANT_MARGIN"]

#: Depth tests that keep the larger depth, and their mirror images under ``d → 1 − d``.
REVERSING = {"greater": "less", "gequal": "lequal"}
#: The key :func:`equivalent` sets in the equivalent raster when the scene's front faces are
#: the equivalent scene's back faces.
FACES_FLIPPED = "faces_flipped"
#: The depth tests with no direction: their depths lie on both sides of the clear value.
NO_DIRECTION = frozenset({"always", "never", "equal", "notequal"})
#: The relative depth model's constant (docs/tolerance.md, "zero_to_one": 16 counted, doubled).
DEPTH_K = 32.0
U = 2.0 ** -24
#: A fixed-point depth buffer's bits, and the part of a step its conversion may be off
#: (Direct3D: 0.6 ULP for float → UNORM).
UNORM_BITS = {"unorm24": 24, "unorm16": 16}
QUANT_MARGIN = 0.6
#: Intervals of window depth among the allowance arrays (plain scenes, face sets, layers).
DEPTH_INTERVALS = (("depth_lo", "depth_hi"), ("set_depth_lo", "set_depth_hi"),
                   ("ldi_depth_lo", "ldi_depth_hi"), ("cs_depth_lo", "cs_depth_hi"),
                   ("cutaway_depth_lo", "cutaway_depth_hi"))
#: Buffers of window depth (in the scene's direction): ``d → 1 − d`` in the equivalent scene
#: of a reversing test.
WINDOW_DEPTHS = ("depth", "layer_depth", "cutaway_depth")
_FACINGS = ("set_facing", "ldi_facing", "cs_facing")
_GL = dict(depth_range="negative_one_to_one", origin="lower_left", ndc_y="up",
           front_face="ccw")


def reverses(raster):
    """Whether the scene's depth test keeps the larger depth (reversed-Z)."""
    return raster.get("depth_func", "less") in REVERSING


def is_gl(raster):
    """Whether the allowances can be derived on the scene as it is (OpenGL's conventions)."""
    return all(raster.get(k, v) == v for k, v in _GL.items()) and not reverses(raster)


def clip_map(raster):
    """``T`` (4×4): equivalent OpenGL clip coordinates of the scene's (module docstring)."""
    t = np.eye(4)
    if raster.get("ndc_y", "up") == "down":
        t[1, 1] = -1.0
    if raster.get("depth_range", "negative_one_to_one") == "zero_to_one":
        t[2] = (0.0, 0.0, 2.0, -1.0)
    if reverses(raster):
        t[2] = -t[2]
    return t


def equivalent(scene, raster):
    """``(scene', raster')``: the OpenGL scene whose allowances are the scene's (moved back by
    :func:`move_back`); ``scene`` itself when it already is one."""
    if is_gl(raster):
        return scene, raster
    from ...camera import Camera
    new = {**raster, **_GL}
    if raster.get("front_face", "ccw") == "cw":
        if raster["cull"] != "none":
            new["cull"] = {"back": "front", "front": "back"}[raster["cull"]]
        new[FACES_FLIPPED] = True
    buffers = dict(scene.buffers)
    if reverses(raster):
        new["depth_func"] = REVERSING[raster["depth_func"]]
        new["clear_depth"] = 1.0 - float(raster["clear_depth"])
        for key in WINDOW_DEPTHS:
            if key in buffers:
                buffers[key] = (1.0 - np.asarray(buffers[key], np.float64)).astype(
                    np.asarray(buffers[key]).dtype)
    cam = scene.camera
    camera = Camera(cam.view, clip_map(raster) @ cam.proj, cam.width, cam.height)
    from ..scenes import DEFAULT_RASTER
    overrides = {k: v for k, v in new.items()
                 if k != FACES_FLIPPED and v != DEFAULT_RASTER.get(k)}
    return dataclasses.replace(scene, camera=camera, buffers=buffers, raster=overrides), new


def quantum(raster):
    """One step ``Δ = 1/(2ⁿ − 1)`` of the scene's depth format (0 for float32)."""
    bits = UNORM_BITS.get(raster.get("depth_format", "float32"))
    return 0.0 if bits is None else 1.0 / float((1 << bits) - 1)


def _outward(lo, hi):
    """float64 bounds → float32, rounded outward."""
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return lo32.astype(np.float32), hi32.astype(np.float32)


def move_back(arrays, scene, raster, eq_scene):
    """Move the allowances derived on ``eq_scene`` (:func:`equivalent`) back to ``scene``'s
    conventions, in place (module docstring)."""
    if is_gl(raster) and quantum(raster) == 0.0:
        return arrays
    model = None
    if raster.get("depth_range") == "zero_to_one" and "depth_lo" in arrays \
            and "depth" in scene.buffers and "prim_id" in scene.buffers:
        model = _plain_depth(arrays, scene, raster)
    for lo_name, hi_name in DEPTH_INTERVALS:
        if lo_name not in arrays:
            continue
        lo = arrays[lo_name].astype(np.float64)
        hi = arrays[hi_name].astype(np.float64)
        if reverses(raster):
            lo, hi = 1.0 - hi, 1.0 - lo
        if lo_name == "depth_lo" and model is not None:
            lo, hi = model
        q = QUANT_MARGIN * quantum(raster)
        arrays[lo_name], arrays[hi_name] = _outward(lo - q, hi + q)
    if raster.get("front_face", "ccw") == "cw":
        for key in _FACINGS:
            if key in arrays:
                f = arrays[key]
                arrays[key] = np.where(f >= 0, 1 - f, f).astype(f.dtype)
    return arrays


def _plain_depth(arrays, scene, raster):
    """The plain depth interval under ``zero_to_one``: the golden's depth ∓ (the visible
    face's relative model + the geometric part of the OpenGL derivation: its half-width less
    its ``depth_eps``), where the id must agree; the moved-back interval elsewhere."""
    from ...conformance import DEPTH_EPS
    from ...raster import prepare
    from ..scenes import as_state
    eq_lo = arrays["depth_lo"].astype(np.float64)
    eq_hi = arrays["depth_hi"].astype(np.float64)
    lo, hi = (1.0 - eq_hi, 1.0 - eq_lo) if reverses(raster) else (eq_lo, eq_hi)
    geo = np.maximum(0.5 * (eq_hi - eq_lo) - DEPTH_EPS, 0.0)
    cam = scene.camera
    prep = prepare([d.mesh for d in scene.draws], **cam.kwargs,
                   model=[d.model for d in scene.draws], raster=as_state(raster))
    per_face = face_depth_model(prep)
    prim = np.asarray(scene.buffers["prim_id"], np.int64)
    obj = (np.asarray(scene.buffers["object_id"], np.int64) if "object_id" in scene.buffers
           else np.zeros_like(prim))
    offsets = np.asarray(prep.face_offsets, np.int64)
    own = (prim >= 0) & ~np.asarray(arrays["id_may"], np.bool_)
    face = np.where(own, offsets[np.clip(obj, 0, len(offsets) - 1)] + np.maximum(prim, 0), 0)
    slack = np.where(own, per_face[face] if len(per_face) else np.inf, 0.0) + geo
    d = np.asarray(scene.buffers["depth"], np.float64)
    lo = np.where(own, d - slack, lo)
    hi = np.where(own, d + slack, hi)
    return lo, hi


def face_depth_model(prep):
    """Per face, ``32·κ·2⁻²⁴·S`` (docs/tolerance.md, "zero_to_one"): ``S = max |z_ndc|`` over
    the viewport's corners ``+ |∂z/∂x|·W + |∂z/∂y|·H`` of the face's depth plane
    ``z_ndc = α·x_ndc + β·y_ndc + δ`` (from its clip coordinates: all of it scales with the
    depths, a relative model), ``κ = max(1, ℓ_a·ℓ_b / 2A)`` over the face's pairs of window
    edges (1 for a face reaching behind the eye; ∞ for one degenerate in the window)."""
    f = prep.triangles.faces
    t = prep.clip[f].astype(np.float64)                  # (F, 3, 4)
    n = len(f)
    if n == 0:
        return np.zeros(0)
    m = t[:, :, [0, 1, 3]]
    det = np.linalg.det(m)
    ok = np.abs(det) > 1e-300
    m[~ok] = np.eye(3)
    coef = np.linalg.solve(m, t[:, :, 2:3])[:, :, 0]    # (α, β, δ)
    al, be, de = coef[:, 0], coef[:, 1], coef[:, 2]
    s = np.max([np.abs(al * sx + be * sy + de) for sx in (-1, 1) for sy in (-1, 1)], axis=0)
    s = s + 2.0 * np.abs(al) + 2.0 * np.abs(be)
    w = t[:, :, 3]
    front = (w > 0).all(axis=1)
    kappa = np.ones(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(front[:, None], t[:, :, 0] / w, 0.0) * 0.5 * prep.width
        y = np.where(front[:, None], t[:, :, 1] / w, 0.0) * 0.5 * prep.height
        ex = np.roll(x, -1, axis=1) - x
        ey = np.roll(y, -1, axis=1) - y
        area = np.abs(ex[:, 0] * ey[:, 1] - ey[:, 0] * ex[:, 1])
        length = np.hypot(ex, ey)
        longest = np.max(length * np.roll(length, -1, axis=1), axis=1)
        k = np.where(area > 0, np.maximum(1.0, longest / area), np.inf)
    kappa = np.where(front, k, kappa)
    out = DEPTH_K * U * kappa * s
    out[~ok] = np.inf
    return out


def depth_covered(depth, clear_depth, depth_func="less"):
    """Where a depth buffer holds a fragment: strictly before the clear value in the test's
    direction (``< clear`` for ``less``-like tests, ``> clear`` for ``greater``/``gequal``).
    A test with no direction (``always``, ``notequal``, ``never``, ``equal``) writes depths on
    both sides of the clear value, so a fragment reads as any value other than it; under
    ``equal`` every fragment writes the clear value itself and the depth buffer cannot tell
    coverage at all (:func:`covered_by` reads the ids when there are some)."""
    d = np.asarray(depth)
    if depth_func in REVERSING:
        return d > clear_depth
    if depth_func in NO_DIRECTION:
        return d != clear_depth
    return d < clear_depth


def covered_by(depth, clear_depth, depth_func="less", prim_id=None):
    """Where a frame covers a pixel: its ``prim_id`` when it has one and the depth test has no
    direction (a fragment may then land on the clear value exactly), else
    :func:`depth_covered`."""
    if prim_id is not None and depth_func in NO_DIRECTION:
        return np.asarray(prim_id) >= 0
    return depth_covered(depth, clear_depth, depth_func)
