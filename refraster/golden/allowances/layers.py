"""Allowances of layered depth images ("Goldens with teeth (2)", item 2).

A layered depth image (:func:`refraster.ldi.peel`, ``mode="peel"``) holds, per pixel, the
fragments of every face the pixel's centre lies in, sorted by window depth, one layer per
distinct depth (a fragment at exactly the depth of the previous layer merges into it: classic
depth peeling with ``GL_LESS``), up to ``K`` layers. Another conformant rasterizer may differ
only where the edge rules may (a face whose footprint passes within ``ε`` of the centre,
:func:`refraster.conformance.edge_epsilon`) and by the float32 depth of each fragment.

Stored per pixel (``tolerance.npz``, CSR like the face sets of plain scenes):

=====================  ===========  =========================================================
array                  dtype        meaning
=====================  ===========  =========================================================
``ldi_offsets``        int32        the entries of pixel ``k`` are ``ldi_offsets[k] … [k + 1]``
``ldi_face``           int32        a face whose footprint dilated by ε covers the centre
                                    (ascending per pixel, global ids: draws concatenated)
``ldi_depth_lo/_hi``   float32      the window depth that face may show there: its plane at
                                    the centre moved by up to ε (corners of the ε-square)
                                    ∓ the face's float32 depth slack
``ldi_facing``         int8         its facing (−1: a sliver whose facing may flip)
``ldi_must``           bool         it surely covers the centre (ε to spare from every edge,
                                    not a sliver) and its depth interval meets no other
                                    entry's: every conformant LDI has it as a layer
``ldi_count_lo/_hi``   int32        the layer count allowed: from the least number of
                                    distinct depths the surely-covering entries can take
                                    (interval stabbing) to the number of entries (≤ K)
=====================  ===========  =========================================================

The check (``"layers"``, the buffer's ``"layer"`` names which of ``depth``, ``prim_id``,
``front_facing``, ``count`` it is) reads the candidate's own ``layer_prim_id`` to name, per
layer, the entry its values must lie in — the per-layer counterpart of the plain scenes'
named-face check.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..._config import JIT
from refraster.raster.state import RasterState

__all__ = ["ldi_allowances", "layers_outside", "layers_allowed", "LAYER_ARRAYS"]

LAYER_ARRAYS = ("ldi_offsets", "ldi_face", "ldi_depth_lo", "ldi_depth_hi", "ldi_facing",
                "ldi_must", "ldi_count_lo", "ldi_count_hi")
#: the LDI buffers of a scene and what each is
LAYER_BUFFERS = {"layer_depth": "depth", "layer_prim_id": "prim_id",
                 "layer_front_facing": "front_facing", "layer_count": "count"}


def _covering_faces(prep, eps):
    """Per pixel, every face (hidden ones included) whose footprint dilated by ``eps`` covers
    the centre: :func:`refraster.conformance.may_faces` without its visibility test."""
    from ...conformance import DEPTH_EPS, _depth_slacks, _set_pass, fragile_faces
    w, h = prep.width, prep.height
    p = prep.triangles
    scale = float(1 << p.subpixel_bits)
    fslack = _depth_slacks(prep, DEPTH_EPS)
    f = p.faces
    whole = np.flatnonzero(p.vcode[f].max(axis=1) == 0) if len(f) else np.zeros(0, np.int64)
    st = p.clipped
    X = np.concatenate([p.vx[f[whole]] / scale, st.x / scale])
    Y = np.concatenate([p.vy[f[whole]] / scale, st.y / scale])
    Z = np.concatenate([p.vz[f[whole]].astype(np.float64), st.z.astype(np.float64)])
    face = np.concatenate([whole, st.prim]).astype(np.int64)
    fragile = fragile_faces(prep, eps)
    mask = np.ones((h, w), np.bool_)
    zsure = np.full((h, w), np.inf)      # no visibility test: every covering face counts
    counts = np.zeros(h * w, np.int64)
    offsets = np.zeros(h * w + 1, np.int64)
    out = np.zeros(0, np.int64)
    _set_pass(1, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets[:-1], out)
    offsets[1:] = np.cumsum(counts)
    out = np.zeros(int(offsets[-1]), np.int64)
    counts[:] = 0
    _set_pass(2, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets[:-1], out)
    pix = np.repeat(np.arange(h * w), np.diff(offsets))
    order = np.lexsort((out, pix))
    pix, out = pix[order], out[order]
    keep = (np.r_[True, (pix[1:] != pix[:-1]) | (out[1:] != out[:-1])] if len(out)
            else np.zeros(0, np.bool_))
    pix, out = pix[keep], out[keep]
    # surely covering: a whole (unclipped) face, not a sliver, the centre inside with ε to
    # spare from every edge
    row_of = np.full(len(f), -1, np.int64)
    row_of[whole] = np.arange(len(whole))
    r = row_of[out]
    ok = (r >= 0) & ~fragile[out]
    rr = np.maximum(r, 0)
    x, y = X[:len(whole)][rr] if len(whole) else np.zeros((0, 3)), \
        Y[:len(whole)][rr] if len(whole) else np.zeros((0, 3))
    rows, cols = np.divmod(pix, w)
    px = cols.astype(np.float64)
    py = (h - 1 - rows).astype(np.float64)
    area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    sgn = np.where(area > 0, 1.0, -1.0)
    sure = ok & (area != 0)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e = sgn * ((x[:, b] - x[:, a]) * (py - y[:, a]) - (px - x[:, a]) * (y[:, b] - y[:, a]))
        length = np.hypot(x[:, b] - x[:, a], y[:, b] - y[:, a])
        sure &= e >= eps * length
    return pix, out, sure, fragile, fslack


@njit(**JIT)
def _count_bounds(offsets, lo, hi, sure, clear, k_max, count_lo, count_hi, must):
    """Per pixel: the allowed layer count and which entries every LDI must show."""
    n_pix = offsets.shape[0] - 1
    for p in range(n_pix):
        a = offsets[p]
        b = offsets[p + 1]
        n_may = 0
        for i in range(a, b):
            if lo[i] < clear:
                n_may += 1
        # least number of distinct depths the surely-covering, surely-in-front entries can
        # take: stab their intervals greedily by increasing upper end
        m = 0
        for i in range(a, b):
            if sure[i] and hi[i] < clear:
                m += 1
        ends = np.empty(m)
        starts = np.empty(m)
        j = 0
        for i in range(a, b):
            if sure[i] and hi[i] < clear:
                ends[j] = hi[i]
                starts[j] = lo[i]
                j += 1
        order = np.argsort(ends, kind="mergesort")
        stab = 0
        point = -np.inf
        for t in range(m):
            q = order[t]
            if starts[q] > point:
                stab += 1
                point = ends[q]
        count_lo[p] = min(stab, k_max)
        count_hi[p] = min(n_may, k_max)
        for i in range(a, b):
            if not (sure[i] and hi[i] < clear):
                continue
            alone = True
            for k in range(a, b):
                if k != i and lo[k] <= hi[i] and hi[k] >= lo[i]:
                    alone = False
                    break
            must[i] = alone


def covering_entries(meshes, models, camera, cull, eps, with_beta=False):
    """Per pixel, every face whose ε-dilated footprint covers the centre, whether it surely
    covers it, and the window-depth interval it may show there (see the module docstring).

    Returns ``(prep, pix, faces, sure, fragile, lo, hi)``: entries sorted by pixel then face,
    ``lo``/``hi`` float64 (±inf where a sliver's or degenerate face's depth is free);
    ``with_beta``: also the perspective-correct barycentrics ``(E, 5, 3)`` at the centre and
    the corners of the ε-square."""
    from ...raster import prepare
    from .homogeneous import corner_samples
    h, w = camera.height, camera.width
    prep = prepare(meshes, **camera.kwargs, model=models, raster=RasterState(cull=cull))
    pix, faces, sure, fragile, fslack = _covering_faces(prep, eps)
    beta, depth, _, _ = corner_samples(prep.clip[prep.triangles.faces[faces]], pix, w, h, eps)
    slack = fslack[faces]
    bad = ~np.isfinite(depth).all(axis=1) | fragile[faces]
    lo = np.where(bad, -np.inf, depth.min(axis=1) - slack)
    hi = np.where(bad, np.inf, depth.max(axis=1) + slack)
    if with_beta:
        return prep, pix, faces, sure & ~bad, fragile, lo, hi, beta
    return prep, pix, faces, sure & ~bad, fragile, lo, hi


def ldi_allowances(scene, raster, eps, k_max, clear=1.0):
    """The ``ldi_*`` arrays of a layered-depth-image scene (see the module docstring)."""
    from ...raster import prepare
    from ...conformance import _face_facing
    from .homogeneous import corner_samples
    cam = scene.camera
    meshes = [d.mesh for d in scene.draws]
    models = [d.model for d in scene.draws]
    h, w = cam.height, cam.width
    prep = prepare(meshes, **cam.kwargs, model=models,
                   raster=RasterState(cull=raster["cull"],
                                      depth_clamp=bool(raster.get("depth_clamp", False))))
    pix, faces, sure, fragile, fslack = _covering_faces(prep, eps)
    # the centre and the corners of the square of half-side ε (⊇ the ε-disc): window depth is
    # a ratio of affine functions of the point, so its extremes over the square are corners
    _, depth, _, _ = corner_samples(prep.clip[prep.triangles.faces[faces]], pix, w, h, eps)
    slack = fslack[faces]
    facing = _face_facing(prep.triangles)[faces].astype(np.int8)
    facing[fragile[faces]] = -1
    bad = ~np.isfinite(depth).all(axis=1) | (facing < 0)
    lo = np.where(bad, -np.inf, depth.min(axis=1) - slack)
    hi = np.where(bad, np.inf, depth.max(axis=1) + slack)
    lo32 = lo.astype(np.float32)
    hi32 = hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    offsets = np.zeros(h * w + 1, np.int64)
    np.add.at(offsets, pix + 1, 1)
    offsets = np.cumsum(offsets)
    count_lo = np.zeros(h * w, np.int32)
    count_hi = np.zeros(h * w, np.int32)
    must = np.zeros(len(faces), np.bool_)
    _count_bounds(offsets, lo32.astype(np.float64), hi32.astype(np.float64), sure & ~bad,
                  float(clear), int(k_max), count_lo, count_hi, must)
    return {"ldi_offsets": offsets.astype(np.int32), "ldi_face": faces.astype(np.int32),
            "ldi_depth_lo": lo32.astype(np.float32), "ldi_depth_hi": hi32.astype(np.float32),
            "ldi_facing": facing, "ldi_must": must,
            "ldi_count_lo": count_lo.reshape(h, w), "ldi_count_hi": count_hi.reshape(h, w)}


def check_layer_arrays(arrays, height, width):
    """Raise ``ValueError`` unless the ``ldi_*`` arrays (when present) are consistent: a file is
    never trusted to index with."""
    if "ldi_offsets" not in arrays:
        return
    missing = [k for k in LAYER_ARRAYS if k not in arrays]
    if missing:
        raise ValueError(f"the layered-depth allowance lacks {missing}")
    off = np.asarray(arrays["ldi_offsets"]).astype(np.int64)
    n = len(np.asarray(arrays["ldi_face"]))
    if off.shape != (height * width + 1,) or off[0] != 0 or off[-1] != n \
            or np.any(np.diff(off) < 0):
        raise ValueError("ldi_offsets is not an offset array over the frame's pixels")
    for k in ("ldi_depth_lo", "ldi_depth_hi", "ldi_facing", "ldi_must"):
        if np.asarray(arrays[k]).shape != (n,):
            raise ValueError(f"{k} does not have one entry per ldi_face ({n})")
    for k in ("ldi_count_lo", "ldi_count_hi"):
        if np.asarray(arrays[k]).shape != (height, width):
            raise ValueError(f"{k} is not (H, W) = ({height}, {width})")
    if n and not np.isin(arrays["ldi_facing"], (-1, 0, 1)).all():
        raise ValueError("ldi_facing holds values other than -1, 0, 1")
    if n and np.any(np.diff(off) > 0):
        f = np.asarray(arrays["ldi_face"]).astype(np.int64)
        pix = np.repeat(np.arange(height * width), np.diff(off))
        if f.min() < 0 or np.any((pix[1:] == pix[:-1]) & (f[1:] <= f[:-1])):
            raise ValueError("ldi_face is not ascending without repeats per pixel")


def _named(arrays, ids):
    """(H, W, K) int64: the entry of the face each layer names, −1 if none (or not in the
    pixel's set)."""
    h, w, k = ids.shape
    off = arrays["ldi_offsets"].astype(np.int64)
    face = arrays["ldi_face"].astype(np.int64)
    if not len(face):
        return np.full(ids.shape, -1, np.int64)
    top = int(max(face.max(), ids.max(initial=0))) + 2
    pix = np.repeat(np.arange(h * w, dtype=np.int64), np.diff(off))
    keys = pix * top + face                       # ascending: pixels, then faces
    q = (np.arange(h * w, dtype=np.int64)[:, None] * top
         + np.asarray(ids, np.int64).reshape(h * w, k)).reshape(-1)
    j = np.searchsorted(keys, q)
    jc = np.minimum(j, len(keys) - 1)
    ok = (j < len(keys)) & (keys[jc] == q) & (np.asarray(ids).reshape(-1) >= 0)
    return np.where(ok, jc, -1).reshape(h, w, k)


def _candidate_count(cand, others, layer, clear, depth_func="less"):
    if layer == "count":
        return np.asarray(cand, np.int64)
    if others is not None and "layer_count" in others:
        return np.asarray(others["layer_count"], np.int64)
    if others is not None and "layer_prim_id" in others:
        return (np.asarray(others["layer_prim_id"]) >= 0).sum(axis=2)
    if others is not None and "layer_depth" in others:
        from .conventions import depth_covered
        return depth_covered(others["layer_depth"], clear, depth_func).sum(axis=2)
    return None


def layers_outside(layer, cand, arrays, others=None, *, step=0.0, clear=1.0, depth_func="less"):
    """(H, W) bool: pixels whose candidate ``layer`` buffer lies outside the allowance
    (layers peeled in ``depth_func``'s direction: front to back, so increasing depth under
    ``less``, decreasing under ``greater``).

    ``others``: the candidate's buffers (its ``layer_prim_id`` names each layer's entry, its
    ``layer_count`` says which layers are present); without ids, depths are held to the
    envelope of the pixel's entries."""
    h, w = arrays["ldi_count_lo"].shape
    off = arrays["ldi_offsets"].astype(np.int64)
    c = np.asarray(cand)
    count = _candidate_count(c, others, layer, clear, depth_func)
    if layer == "count":
        bad = (c < arrays["ldi_count_lo"]) | (c > arrays["ldi_count_hi"])
        if others is not None and "layer_prim_id" in others:
            # the count the candidate's own layers show: its leading layers with an id
            ids = np.asarray(others["layer_prim_id"])
            if ids.ndim == 3 and ids.shape[:2] == c.shape:
                lead = np.cumprod(ids >= 0, axis=2).sum(axis=2)
                bad |= (c != lead) | ((ids >= 0).sum(axis=2) != lead)
        return bad
    k = c.shape[2]
    present = (np.arange(k)[None, None, :] < (count if count is not None
                                              else np.full((h, w), k))[..., None])
    ids = None
    if layer == "prim_id":
        ids = c
    elif others is not None and "layer_prim_id" in others \
            and np.asarray(others["layer_prim_id"]).shape == c.shape:
        ids = np.asarray(others["layer_prim_id"])
    named = _named(arrays, ids) if ids is not None else None
    if layer == "prim_id":
        bad = (present & (named < 0)).any(axis=2) | (~present & (c != -1)).any(axis=2)
        # every entry that must show is among the pixel's layers
        must = np.flatnonzero(arrays["ldi_must"])
        if len(must):
            pix = np.searchsorted(off, must, side="right") - 1
            face = arrays["ldi_face"][must].astype(np.int64)
            flat = c.reshape(h * w, k)
            shown = ((flat[pix] == face[:, None]) & present.reshape(h * w, k)[pix]).any(axis=1)
            miss = np.zeros(h * w, np.bool_)
            miss[pix[~shown]] = True
            bad |= miss.reshape(h, w)
        return bad
    if layer == "front_facing":
        if named is None:
            return np.zeros((h, w), np.bool_)
        e = np.maximum(named, 0)
        f = arrays["ldi_facing"][e] if len(arrays["ldi_facing"]) else np.full(e.shape, -1)
        return (present & (named >= 0) & (f >= 0) & (c != (f == 1))).any(axis=2)
    if layer != "depth":
        raise ValueError(f"unknown layer buffer {layer!r}")
    v = c.astype(np.float64)
    lo = arrays["ldi_depth_lo"].astype(np.float64)
    hi = arrays["ldi_depth_hi"].astype(np.float64)
    n = np.diff(off).reshape(h, w)
    if named is not None:
        e = np.maximum(named, 0)
        lo_k = np.where(named >= 0, lo[e] if len(lo) else -np.inf, np.nan)
        hi_k = np.where(named >= 0, hi[e] if len(hi) else np.inf, np.nan)
    else:
        lo_k = hi_k = np.full(c.shape, np.nan)
    # no id (or one outside the set): the envelope of the pixel's entries
    has = n > 0
    env_lo = np.full(h * w, np.nan)
    env_hi = np.full(h * w, np.nan)
    runs = np.flatnonzero(has.ravel())
    if len(runs):
        env_lo[runs] = np.minimum.reduceat(lo, off[runs])
        env_hi[runs] = np.maximum.reduceat(hi, off[runs])
    env_lo = np.broadcast_to(env_lo.reshape(h, w, 1), c.shape)
    env_hi = np.broadcast_to(env_hi.reshape(h, w, 1), c.shape)
    lo_k = np.where(np.isnan(lo_k), env_lo, lo_k)
    hi_k = np.where(np.isnan(hi_k), env_hi, hi_k)
    with np.errstate(invalid="ignore"):
        inside = (v >= lo_k - step) & (v <= hi_k + step)
    bad = (present & ~inside).any(axis=2)
    # layers strictly behind one another (peeling), the absent ones at the clear depth
    if k > 1:
        both = present[..., 1:] & present[..., :-1]
        behind = (v[..., 1:] < v[..., :-1] if depth_func in ("greater", "gequal")
                  else v[..., 1:] > v[..., :-1])
        bad |= (both & ~behind).any(axis=2)
    bad |= (~present & ~(np.abs(v - clear) <= step)).any(axis=2)
    return bad


def layers_allowed(layer, arrays, r, c, cand=None, others=None, step=0.0):
    """What the allowance admits at pixel (r, c), in words."""
    h, w = arrays["ldi_count_lo"].shape
    k = r * w + c
    a, b = int(arrays["ldi_offsets"][k]), int(arrays["ldi_offsets"][k + 1])
    if layer == "count":
        return (f"layer count in [{int(arrays['ldi_count_lo'][r, c])}, "
                f"{int(arrays['ldi_count_hi'][r, c])}]")
    parts = []
    for i in range(a, b):
        s = (f"{int(arrays['ldi_face'][i])}: depth [{float(arrays['ldi_depth_lo'][i]) - step:.6g},"
             f" {float(arrays['ldi_depth_hi'][i]) + step:.6g}]")
        if layer == "front_facing":
            f = int(arrays["ldi_facing"][i])
            s += ", facing any" if f < 0 else f", front_facing {bool(f)}"
        if arrays["ldi_must"][i]:
            s += " (must show)"
        parts.append(s)
    return ("layers strictly increasing in depth, each naming one of the faces {"
            + "; ".join(parts) + "}")
