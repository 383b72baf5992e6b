"""The fault-injection harness of ``tests/faults.py`` extended to the technique scenes
("Goldens with teeth (2)", item 6).

Same rules as the plain harness: one in-domain fault at every covered pixel, in batches on a
lattice spaced beyond the scene's may-radius and position-deviation radius, seeds fixed before
any tuning; a fault counts as caught only when the tolerant check (the code path of
``refraster golden compare --mode tolerant``) fails **at that pixel**; "admits" is the share of
covered pixels whose allowance admits the fault at all.

What the technique buffers add to the faults of ``tests/faults.py``:

==================  ============================================================================
buffer              fault
==================  ============================================================================
``layer_*``         one layer (seeded, among the pixel's ``layer_count``) changed as its kind
                    says: window depth moved by 0.25 reflected into [0, 1], id swapped, bool
                    flipped
``layer_count``     one more or one fewer layer (seeded; never below 0 or above the stored K)
``cap_mask``,       flipped
``cut_mask``
``edge_map``,       moved by 0.25, reflected into [0, 1]
``cutaway_depth``,
``ghost``, alpha
``halo_class``      swapped for another class of the scene (``ids`` range 0 … 3)
==================  ============================================================================

Covered pixels: where the golden shows something — ``prim_id ≥ 0``, ``layer_count > 0``,
``alpha > 0`` (halos).
"""

from __future__ import annotations

import numpy as np

import faults

SEED = faults.SEED


def covered_pixels(ref_all, clear=1.0):
    if "prim_id" in ref_all:
        return np.asarray(ref_all["prim_id"]) >= 0
    if "layer_count" in ref_all:
        return np.asarray(ref_all["layer_count"]) > 0
    if "alpha" in ref_all:
        return np.asarray(ref_all["alpha"]) > 0
    if "depth" in ref_all:
        return np.asarray(ref_all["depth"]) < clear
    return np.ones(next(iter(ref_all.values())).shape[:2], np.bool_)


def inject(key, kind, ref, pixels, rng, id_range, ref_all, size=faults.STANDARD):
    """A copy of ``ref`` with the fault of ``key`` at every (row, col) of ``pixels`` (faults of
    ``size``, :data:`faults.STANDARD` or :data:`faults.REALISTIC`)."""
    if key.startswith("layer_") and key != "layer_count":
        out = ref.copy()
        count = ref_all["layer_count"]
        for r, c in pixels:
            n = int(count[r, c])
            if n <= 0:
                continue
            k = int(rng.integers(0, n))
            v = out[r, c, k]
            if kind == "id":
                lo, hi = max(id_range[0], 0), id_range[1]
                f = int(v)
                while f == int(v):
                    f = int(rng.integers(lo, hi + 1))
                out[r, c, k] = f
            elif kind == "bool":
                out[r, c, k] = ~v
            else:
                out[r, c, k] = faults._reflect(float(v), size["value"])
        return out
    if key == "layer_count":
        out = ref.copy()
        top = ref_all["layer_depth"].shape[2]
        for r, c in pixels:
            n = int(out[r, c])
            d = 1 if rng.integers(0, 2) else -1
            if n + d < 0 or n + d > top:
                d = -d
            out[r, c] = n + d
        return out
    return faults.inject(key, kind, ref, pixels, rng, id_range, size=size)


def fault_table(golden_dir, scene, *, buffers=None, seed=SEED, admits=None, size=faults.STANDARD):
    """As :func:`faults.fault_table`, for any scene (technique buffers included).

    ``admits(key, kind, spec, arrays, ref, cand, named, ref_all)`` → (H, W) bool overrides how
    "admitted" is computed for the checks :func:`faults._admits` does not know."""
    admits = globals()["admits"] if admits is None else admits
    return faults.fault_table(golden_dir, scene, buffers=buffers, seed=seed,
                              covered_of=covered_pixels, inject_at=inject, admits=admits,
                              size=size)


def layers_admits(key, kind, spec, arrays, ref, cand, named, others):
    """Where the ``layers`` allowance admits the faulty value — written from the module
    docstring of :mod:`refraster.golden.allowances.layers`, pixel by pixel, not with its code: the
    entry the layer's id names (the candidate's ids) holds the depth / facing, the id is one of the
    pixel's faces and no face that must show went missing, the count lies in its bounds and
    agrees with the layers shown. ``None`` for other checks."""
    if "layers" not in spec["checks"]:
        return None
    layer = spec["layer"]
    h, w = ref.shape[:2]
    out = np.zeros((h, w), np.bool_)
    diff = ref != cand
    diff = diff.any(axis=2) if diff.ndim == 3 else diff
    off = arrays["ldi_offsets"]
    ids = np.asarray(others["layer_prim_id"])
    count = np.asarray(others["layer_count"])
    for r, c in np.argwhere(diff):
        k0, k1 = int(off[r * w + c]), int(off[r * w + c + 1])
        faces = [int(f) for f in arrays["ldi_face"][k0:k1]]
        n = int(count[r, c])
        if layer == "count":
            shown = int((ids[r, c] >= 0).sum())
            out[r, c] = (arrays["ldi_count_lo"][r, c] <= n <= arrays["ldi_count_hi"][r, c]
                         and n == shown)
            continue
        ok = True
        for k in range(ids.shape[2]):
            f = int(ids[r, c, k])
            if k >= n:
                ok &= f == -1 if layer == "prim_id" else True
                continue
            if f not in faces:
                ok = False
                continue
            e = k0 + faces.index(f)
            if layer == "depth":
                d = float(cand[r, c, k])
                ok &= float(arrays["ldi_depth_lo"][e]) <= d <= float(arrays["ldi_depth_hi"][e])
                if k > 0:
                    ok &= d > float(cand[r, c, k - 1])
            elif layer == "front_facing":
                fa = int(arrays["ldi_facing"][e])
                ok &= fa < 0 or bool(cand[r, c, k]) == (fa == 1)
        if layer == "prim_id":
            for i in range(k0, k1):
                if arrays["ldi_must"][i]:
                    ok &= int(arrays["ldi_face"][i]) in [int(x) for x in ids[r, c, :n]]
        out[r, c] = ok
    return out


def admits(key, kind, spec, arrays, ref, cand, named, others):
    """The technique checks' own "admits" (``None``: :func:`faults._admits` decides)."""
    for f in (layers_admits, bounds_admits, clip_admits, clip_value_admits):
        a = f(key, kind, spec, arrays, ref, cand, named, others)
        if a is not None:
            return a
    return None


def clip_value_admits(key, kind, spec, arrays, ref, cand, named, others):
    """Clip-surface and cutaway normal, barycentrics, colour (an ``interval`` or ``angle``
    check with a ``may`` region, the golden's ids and per-entry ``cs_*`` value arrays), pixel by
    pixel from the docstring of ``allowance._clip_value_checks``: the candidate's
    (object_id, prim_id) names an entry of the pixel's clip set; if it is the golden's face and
    that entry is not a sliver that may flip, the value must lie in the golden's interval
    (within the golden's angle); otherwise in the named entry's own bounds (``cs_<buffer>``;
    ±inf / π where that entry's value is free). A face outside the set: the value is not
    judged here (the id check fails)."""
    checks = spec["checks"]
    if "may" not in spec or "golden_face" not in arrays or not (
            "interval" in checks or "angle" in checks):
        return None
    h, w = ref.shape[:2]
    out = np.zeros((h, w), np.bool_)
    off = arrays["cs_offsets"]
    draws = [int(x) for x in arrays["cs_draw_offsets"]]
    prim, obj = np.asarray(others["prim_id"]), np.asarray(others["object_id"])
    c = np.asarray(cand, np.float64)
    r_ = np.asarray(ref, np.float64)

    def angle(a, b):
        cos = float(np.dot(a, b)) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-300)
        return float(np.arccos(np.clip(cos, -1.0, 1.0)))

    for r, cc in np.argwhere(prim >= 0):
        pr, ob = int(prim[r, cc]), int(obj[r, cc])
        if not 0 <= ob < len(draws) - 1 or pr >= draws[ob + 1] - draws[ob]:
            out[r, cc] = True
            continue
        k0, k1 = int(off[r * w + cc]), int(off[r * w + cc + 1])
        faces = [int(f) for f in arrays["cs_face"][k0:k1]]
        g = draws[ob] + pr
        if g not in faces:
            out[r, cc] = True
            continue
        e = k0 + faces.index(g)
        golden = (pr == int(arrays["golden_face"][r, cc])
                  and ob == int(arrays["golden_object"][r, cc]))
        if golden and int(arrays["cs_facing"][e]) != -1:
            if "interval" in checks:
                out[r, cc] = bool(np.all((c[r, cc] >= arrays[spec["lo"]][r, cc])
                                         & (c[r, cc] <= arrays[spec["hi"]][r, cc])))
            else:
                out[r, cc] = angle(r_[r, cc], c[r, cc]) <= float(arrays[spec["angle"]][r, cc])
        elif key == "normal":
            out[r, cc] = angle(arrays["cs_normal"][e], c[r, cc]) <= float(
                arrays["cs_normal_angle"][e])
        else:
            out[r, cc] = bool(np.all((c[r, cc] >= arrays[f"cs_{key}_lo"][e])
                                     & (c[r, cc] <= arrays[f"cs_{key}_hi"][e])))
    return out


def bounds_admits(key, kind, spec, arrays, ref, cand, named, others):
    """Where a ``bounds`` interval (every pixel, every channel) holds the faulty value."""
    if "bounds" not in spec["checks"]:
        return None
    c = np.asarray(cand, np.float64)
    inside = (c >= arrays[spec["lo"]]) & (c <= arrays[spec["hi"]])
    if "zero" in spec:
        inside |= np.asarray(arrays[spec["zero"]], np.bool_) & (c == 0)
    return inside.all(axis=2) if inside.ndim == 3 else inside


def clip_admits(key, kind, spec, arrays, ref, cand, named, others):
    """Where the ``clip`` allowance admits the faulty value, pixel by pixel from the module
    docstring of :mod:`refraster.golden.allowances.clip`: the candidate's (object_id, prim_id)
    names an entry of the pixel's set (or the pixel is background where the background may
    show), and its depth, facing and mask flag (a cap face; a secondary back face) are that
    entry's."""
    if "clip" not in spec["checks"] or key in ("barycentric", "color", "normal"):
        return None
    h, w = ref.shape[:2]
    out = np.zeros((h, w), np.bool_)
    diff = ref != cand
    diff = diff.any(axis=2) if diff.ndim == 3 else diff
    off = arrays["cs_offsets"]
    draws = [int(x) for x in arrays["cs_draw_offsets"]]
    prim, obj = np.asarray(others["prim_id"]), np.asarray(others["object_id"])
    for r, c in np.argwhere(diff):
        k0, k1 = int(off[r * w + c]), int(off[r * w + c + 1])
        faces = [int(f) for f in arrays["cs_face"][k0:k1]]
        pr, ob = int(prim[r, c]), int(obj[r, c])
        if pr < 0:
            out[r, c] = bool(arrays["cs_bg"][r, c]) and (
                key != "depth" or cand[r, c] >= 1.0) and (
                key != "eye_depth" or not np.isfinite(cand[r, c]))
            continue
        if not 0 <= ob < len(draws) - 1 or pr >= draws[ob + 1] - draws[ob]:
            continue
        g = draws[ob] + pr
        if g not in faces:
            continue
        e = k0 + faces.index(g)
        if key == "depth":
            out[r, c] = arrays["cs_depth_lo"][e] <= cand[r, c] <= arrays["cs_depth_hi"][e]
        elif key == "eye_depth":
            out[r, c] = arrays["cs_eye_lo"][e] <= cand[r, c] <= arrays["cs_eye_hi"][e]
        elif key == "front_facing":
            f = int(arrays["cs_facing"][e])
            out[r, c] = f < 0 or bool(cand[r, c]) == (f == 1)
        elif key in ("cap_mask", "cut_mask"):
            fl = int(arrays["cs_flag"][e])
            out[r, c] = fl < 0 or bool(cand[r, c]) == (fl == 1)
        else:
            out[r, c] = True
    return out
