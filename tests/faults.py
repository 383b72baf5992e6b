"""A fault-injection harness for goldens ("Goldens with teeth (1)", item 4).

For one scene of a generated golden and one of its buffers, inject an in-domain fault at every
covered pixel — in batches on a lattice whose spacing exceeds the scene's may-radius and the
position-deviation radius, so that no two faults of a batch see each other — run the buffer's
tolerant check (the code path of ``refraster golden compare --mode tolerant``) and count:

* ``admitted``: covered pixels whose allowance admits the fault at all (the pixel's values are
  free there — ``id_may`` / ``may`` — or the faulty value lies inside its interval / angle);
* ``caught``: among the other covered pixels, those where the check fails **at that pixel** (the
  pixel is unforgiven and one unforgiven pixel fails the buffer).

The faults (seeds fixed before any tuning):

============  ==================================================================================
kind          fault
============  ==================================================================================
window depth  moved by 0.25, reflected into [0, 1]
eye depth     scaled by 1.25
normal        rotated by 20° about an axis perpendicular to it (seeded)
id            swapped for another valid id of the scene (the manifest's ``ids`` range, seeded)
bool          flipped
barycentric   moved along the simplex: (b0 + δ, b1 − δ, b2), δ = 0.25 reflected into the simplex
colour        one channel (seeded) moved by 0.25, reflected into [0, 1]
============  ==================================================================================

At the realistic size (:data:`REALISTIC`, issue 42 item 1) the same faults are 0.05 (values,
window depth, colour channel, barycentric δ), 0.05 rad (normals) and ×1.02 (eye depth), planted
in every float buffer; :func:`realistic_table` measures caught / covered per buffer, with the
listed exceptions (:data:`ENLARGED`, at most 2×) and open pairs (:data:`SHORT_OPEN`).
"""

from __future__ import annotations

import math

import numpy as np

from refraster.golden.allowances.core import named_entries, tolerant_metrics
from refraster.golden.compare.run import load_manifest

SEED = 20261201

#: The fault sizes. ``standard``: the table of "Goldens with teeth" (0.25 in a value, 20° on a
#: normal, eye depth ×1.25); ``realistic``: the size of real bugs (issue 42 item 1 — 0.05 in a
#: value, window depth, alpha, colour channel and barycentric δ; 0.05 rad on a normal; eye depth
#: ×1.02).
STANDARD = {"value": 0.25, "normal": math.radians(20.0), "eye": 0.25}
REALISTIC = {"value": 0.05, "normal": 0.05, "eye": 0.02}


def scaled(size, factor):
    """``size`` with every fault multiplied by ``factor`` (an enlarged fault of the listed
    exceptions; eye depth ×(1 + factor·0.02))."""
    return {k: v * factor for k, v in size.items()}


def _reflect(v, d=0.25):
    w = v + d
    return np.where(w > 1.0, 2.0 - w, w) if np.ndim(w) else (2.0 - w if w > 1.0 else w)


def _rotate(n, angle, rng):
    """``n`` (unit) rotated by ``angle`` about a random axis perpendicular to it."""
    n = np.asarray(n, np.float64)
    t = rng.normal(size=3)
    t -= n * (t @ n)
    t /= np.linalg.norm(t)
    return math.cos(angle) * n + math.sin(angle) * t


def inject(key, kind, ref, pixels, rng, id_range, size=STANDARD):
    """A copy of ``ref`` with the fault of ``key``/``kind`` at every (row, col) of ``pixels``
    (faults of ``size``: :data:`STANDARD` or :data:`REALISTIC`)."""
    out = ref.copy()
    d = size["value"]
    for r, c in pixels:
        v = ref[r, c]
        if kind == "id":
            lo, hi = id_range
            lo = max(lo, 0)
            if hi <= lo:   # no other valid id: the fault is not applicable
                continue
            f = int(v)
            while f == int(v):
                f = int(rng.integers(lo, hi + 1))
            out[r, c] = f
        elif kind == "bool":
            out[r, c] = ~v
        elif key == "normal":
            out[r, c] = _rotate(v, size["normal"], rng)
        elif key == "barycentric":
            b = np.asarray(v, np.float64).copy()
            e = d if b[1] >= d else -min(d, b[0])
            b[0] += e
            b[1] -= e
            out[r, c] = b
        elif key == "eye_depth" or kind == "float":
            out[r, c] = v * (1.0 + size["eye"])
        elif kind == "color":
            ch = int(rng.integers(0, v.shape[-1]))
            out[r, c, ch] = _reflect(float(v[ch]), d)
        else:  # unorm: window depth and other [0, 1] values
            if np.ndim(v):
                out[r, c] = _reflect(np.asarray(v, np.float64), d)
            else:
                out[r, c] = _reflect(float(v), d)
    return out


def _set_admits(key, kind, arrays, cand, named):
    """(H, W) bool, where the id may differ: the face the candidate names may win there and
    its value lies in that face's entry of the face set."""
    id_may = np.asarray(arrays["id_may"], np.bool_)
    ok = id_may & (named >= 0)
    if not len(arrays["set_face"]):   # no pixel where the id may differ: no entry admits
        return ok
    e = np.maximum(named, 0)
    if kind == "id":
        return ok
    if key == "front_facing":
        f = arrays["set_facing"][e]
        return ok & ((f < 0) | (cand == (f == 1)))
    if key == "normal":
        ang = np.degrees(np.arccos(np.clip(np.einsum("hwc,hwc->hw", cand.astype(np.float64),
                                                     arrays["set_normal"][e]), -1, 1)))
        return ok & (np.radians(ang) <= arrays["set_normal_angle"][e])
    lo = arrays[f"set_{key}_lo"][e]
    hi = arrays[f"set_{key}_hi"][e]
    inside = (cand >= lo) & (cand <= hi)
    return ok & (inside.all(axis=2) if inside.ndim == 3 else inside)


def _admits(key, kind, spec, arrays, ref, cand, named=None, step=0.0):
    """(H, W) bool: the allowance admits the candidate's value at the pixel — every check of
    the buffer does (a value is caught when any one check refuses it)."""
    checks = spec["checks"]
    if "masked" in checks:
        return np.asarray(arrays[spec.get("may", "may")], np.bool_)
    id_may = np.asarray(arrays["id_may"], np.bool_)
    sets = "face" in checks and named is not None
    # where the id may differ, the face check decides (with face sets) or values are free
    ok = np.ones(ref.shape[:2], np.bool_)
    if "interval" in checks:
        lo = arrays[spec["lo"]].astype(np.float64) - step
        hi = arrays[spec["hi"]].astype(np.float64) + step
        c = cand.astype(np.float64)
        inside = (c >= lo) & (c <= hi)
        inside = inside.all(axis=2) if inside.ndim == 3 else inside
        ok &= id_may | inside
    if "angle" in checks:
        a = np.einsum("hwc,hwc->hw", ref.astype(np.float64), cand.astype(np.float64))
        na = np.linalg.norm(ref, axis=2) * np.linalg.norm(cand, axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            ang = np.arccos(np.clip(a / na, -1.0, 1.0))
        ok &= id_may | (ang <= arrays[spec["angle"]])
    if "id" in checks:
        same = (ref == cand).all(axis=2) if ref.ndim == 3 else ref == cand
        ok &= id_may | same
    if sets:
        ok &= ~id_may | _set_admits(key, kind, arrays, cand, named)
    return ok


def _covered(ref_all, clear=1.0):
    if "prim_id" in ref_all:
        return ref_all["prim_id"] >= 0
    if "depth" in ref_all:
        return ref_all["depth"] < clear
    return np.ones(next(iter(ref_all.values())).shape[:2], np.bool_)


def fault_table(golden_dir, scene, *, buffers=None, seed=SEED, covered_of=None, inject_at=None,
                admits=None, size=STANDARD):
    """Per buffer of ``scene``: ``{buffer: {"covered", "admitted", "eligible", "caught",
    "missed": [(row, col), ...]}}`` for the tolerant check of a generated golden.

    The hooks are for scenes with technique buffers (``tests/faults_techniques.py``):
    ``covered_of(ref_all, clear)`` the covered pixels, ``inject_at(key, kind, ref, pixels, rng,
    id_range, ref_all)`` the fault (the check then also sees the scene's other buffers, with the
    faulty one swapped in), ``admits(key, kind, spec, arrays, ref, cand, named, others)`` where
    the allowance admits the fault, or ``None`` for checks :func:`_admits` knows.

    ``size``: the faults' size (:data:`STANDARD`, :data:`REALISTIC`), or a function
    ``size(key)`` → size (the realistic table's enlarged exceptions); ``inject_at`` then takes
    it as keyword ``size``."""
    manifest = load_manifest(golden_dir, verify=False)
    entry = manifest["scenes"][scene]
    with np.load(golden_dir / scene / "buffers.npz", allow_pickle=False) as z:
        ref_all = {k: z[k].copy() for k in z.files}
    with np.load(golden_dir / scene / "tolerance.npz", allow_pickle=False) as z:
        arrays = {k: z[k].copy() for k in z.files}
    info = entry["allowances"]
    clear = entry["parameters"]["raster"].get("clear_depth", 1.0)
    func = entry["parameters"]["raster"].get("depth_func", "less")
    covered = (covered_of or _covered)(ref_all, clear)
    radius = max(int(info["may_radius"]), 1)
    table = {}
    for key, spec in entry["buffers"].items():
        if buffers is not None and key not in buffers:
            continue
        kind = spec["kind"]
        ref = ref_all[key]
        if kind == "id" and spec.get("ids", (-1, 0))[1] <= 0:
            table[key] = None   # one valid id (one draw call): no other id to swap in
            continue
        fallback = spec["tolerance"]["conformant"]
        radius_k = max(radius, int(fallback["deviation_radius"]))
        gap = 2 * radius_k + 2
        rng = np.random.default_rng([seed, sum(map(ord, scene)), sum(map(ord, key))])
        n = ref.shape[0] * ref.shape[1]
        one_fails = ("masked" not in spec["tolerant"]["checks"]
                     or 1.0 / n > float(fallback["max_fraction"]))
        admitted = np.zeros(ref.shape[:2], np.bool_)
        caught = np.zeros(ref.shape[:2], np.bool_)
        for dy in range(gap):
            for dx in range(gap):
                lattice = np.zeros_like(covered)
                lattice[dy::gap, dx::gap] = True
                pix = np.argwhere(lattice & covered)
                if not len(pix):
                    continue
                idr = spec.get("ids", (-1, 0))
                sz = size(key) if callable(size) else size
                if inject_at is None:
                    cand, others = inject(key, kind, ref, pix, rng, idr, size=sz), None
                    ids = {**ref_all, key: cand}
                else:
                    cand = inject_at(key, kind, ref, pix, rng, idr, ref_all, size=sz)
                    ids = others = {**ref_all, key: cand}
                named = (named_entries(arrays, ids["prim_id"], ids.get("object_id"))
                         if "prim_id" in ids else None)
                _, checks, images = tolerant_metrics(
                    key, ref, cand, kind, spec["tolerant"], arrays, clear_depth=clear,
                    fallback=fallback, named=named, others=others, depth_func=func)
                bad = images["over"] & ~images["forgiven"]
                ok = all(c["ok"] for c in checks)
                m = np.zeros_like(covered)
                m[pix[:, 0], pix[:, 1]] = True
                adm = None if admits is None else admits(key, kind, spec["tolerant"], arrays,
                                                         ref, cand, named, others)
                if adm is None:
                    adm = _admits(key, kind, spec["tolerant"], arrays, ref, cand, named)
                admitted |= m & adm
                caught |= m & bad & (not ok) & one_fails
        eligible = covered & ~admitted
        table[key] = {"covered": int(covered.sum()), "admitted": int(admitted.sum()),
                      "eligible": int(eligible.sum()), "caught": int((caught & eligible).sum()),
                      "missed": [tuple(map(int, p)) for p in np.argwhere(eligible & ~caught)]}
    return table


def format_table(rows):
    """Markdown table of ``[(scene, buffer, row), ...]``."""
    out = ["| scene | buffer | covered | admits the fault | caught among the others |",
           "|---|---|---:|---:|---:|"]
    for scene, key, r in rows:
        if r is None:
            out.append(f"| {scene} | {key} | | n/a: one valid id | |")
            continue
        adm = r["admitted"] / r["covered"] if r["covered"] else 0.0
        got = r["caught"] / r["eligible"] if r["eligible"] else 1.0
        out.append(f"| {scene} | {key} | {r['covered']} | {100 * adm:.1f} % | "
                   f"{100 * got:.1f} % |")
    return "\n".join(out)


# --- the realistic table (issue 42 item 1) ------------------------------------------------------

#: The buffer kinds the realistic table measures (every float buffer).
FLOAT_KINDS = ("unorm", "snorm", "float", "color")
#: Its aim: caught / covered ≥ 95 % per (scene, float buffer).
REALISTIC_AIM = 0.95
#: The listed exceptions: (scene, buffer) → factor (≤ 2) of the enlarged fault. Each is a place
#: where a conformant implementation may differ by more than the realistic fault
#: (docs/tolerance.md, "Teeth at realistic sizes", says by how much); the tests fail when a pair
#: is listed but meets the aim at the realistic size, or is short and not listed.
ENLARGED = {}
#: Pairs short at the realistic size that no enlarged fault ≤ 2× brings to the aim (open):
#: none today. Listed exactly: a pair leaves the list when its allowance is tightened and it
#: meets the aim. The realistic table is measured on goldens of the default declaration, 8
#: sub-pixel bits (at 4 the edge maps, the NPR colour, the halos' alpha and colour and the
#: crank's barycentrics fall short too).
SHORT_OPEN = frozenset()


def float_buffers(golden_dir, scene):
    """The scene's float buffers (kinds :data:`FLOAT_KINDS`), in the manifest's order."""
    entry = load_manifest(golden_dir, verify=False)["scenes"][scene]
    return [k for k, s in entry["buffers"].items() if s["kind"] in FLOAT_KINDS]


def share(r):
    """caught / covered of a table row (an admitted fault counts as missed)."""
    return r["caught"] / r["covered"] if r["covered"] else 1.0


def realistic_table(golden_dir, scene, table=None, enlarged=None):
    """``{buffer: row}`` over the scene's float buffers at :data:`REALISTIC` size; a listed
    exception (``enlarged``, default :data:`ENLARGED`) is measured at the realistic size and at
    its enlarged fault: its row holds ``factor`` and ``enlarged`` (the row at that size)."""
    table = fault_table if table is None else table
    enlarged = ENLARGED if enlarged is None else enlarged
    keys = float_buffers(golden_dir, scene)
    rows = table(golden_dir, scene, buffers=keys, size=REALISTIC)
    big = {k: f for (s, k), f in enlarged.items() if s == scene and k in rows}
    for k, f in big.items():
        rows[k]["factor"] = f
        rows[k]["enlarged"] = table(golden_dir, scene, buffers=[k],
                                    size=scaled(REALISTIC, f))[k]
    return rows


def short_pairs(tables):
    """(scene, buffer) pairs below :data:`REALISTIC_AIM` at the realistic size."""
    return {(s, k) for s, t in tables.items() for k, r in t.items()
            if r is not None and share(r) < REALISTIC_AIM}


def measured_line(seconds):
    """"Measured <date> on <machine> (<cores> cores, load average <1 min>) in <s> s"."""
    import datetime
    import os
    import platform
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"Measured {now} on {platform.node()} ({os.cpu_count()} cores, load average "
            f"{load:.1f}) in {seconds:.0f} s.")


def check_realistic(tables, scene):
    """The realistic aim of one scene: its short pairs are exactly the listed exceptions
    (:data:`ENLARGED`) and open pairs (:data:`SHORT_OPEN`), and each exception, enlarged at
    most 2×, meets the aim at its enlarged fault."""
    short = {k for s, k in short_pairs({scene: tables[scene]})}
    listed = {k for s, k in ENLARGED if s == scene} | {k for s, k in SHORT_OPEN if s == scene}
    rows = {k: (r["caught"], r["admitted"], r["covered"], r["missed"][:5])
            for k, r in tables[scene].items() if k in short ^ listed}
    assert short == listed, (scene, "short", sorted(short), "listed", sorted(listed), rows)
    for k in {k for s, k in ENLARGED if s == scene}:
        f, e = ENLARGED[(scene, k)], tables[scene][k]["enlarged"]
        assert 1.0 < f <= 2.0, (scene, k, f)
        assert share(e) >= REALISTIC_AIM, (scene, k, f, e["caught"], e["covered"])


def format_realistic(rows):
    """Markdown table of ``[(scene, buffer, row), ...]`` of :func:`realistic_table`."""
    out = ["| scene | buffer | covered | admits the fault | caught / covered | "
           "enlarged fault | caught / covered at it |",
           "|---|---|---:|---:|---:|---|---:|"]
    for scene, key, r in rows:
        big = ""
        if "factor" in r:
            f, e = r["factor"], r["enlarged"]
            big = (f"×{f:g}: {f * REALISTIC['value']:g} / {f * REALISTIC['normal']:g} rad / "
                   f"×{1 + f * REALISTIC['eye']:g} | {100 * share(e):.1f} %")
        elif (scene, key) in SHORT_OPEN:
            big = "open (no enlarged fault ≤ 2× meets the aim) | "
        else:
            big = " | "
        adm = r["admitted"] / r["covered"] if r["covered"] else 0.0
        out.append(f"| {scene} | {key} | {r['covered']} | {100 * adm:.1f} % | "
                   f"{100 * share(r):.1f} % | {big} |")
    return "\n".join(out)
