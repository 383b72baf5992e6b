"""The fused clip-and-cap pass: the rasterizer's tile loop with the clip stage of
:func:`refraster.clipsurface.render_clipped` between rasterization and the depth test
(clip test of every enabled surface, volumetric parity test of cap fragments), with the
per-box classification and the "surely inside" shortcut of cap faces. Equal, bit for bit, to
the fragment stream + stage + resolve (tests/test_clipsurface_fused.py)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from ..ldi import parity_at
from ..raster.gbuffer import _object_of
from ..raster.rasterizer import (NO_ITEM, TILE_SHIFT, _box_in_tile, _geometry, _setup,
                                 bin_primitives, depth_rows, depth_test, face_image_limit,
                                 fragment_depth, lambdas, perspective_bary, resolved_buffers,
                                 row_span, tile_rect, write_winner)
from .capping import SURE_EXTRAPOLATION
from .surfaces import _Packed, clipped_at

__all__: list[str] = []   # internal: render_clipped calls _fused_clip


@njit(**IJIT)
def _keep(b0, b1, b2, i0, i1, i2, tv, wv, separate, skip, solid, params, wrap, enabled, maps,
          offset, shape, v_first, v_mat, v_depth, v_sign, v_count, v_start, v_cstart, v_hw):
    """The clip stage of one fragment (``render_clipped``'s ``stage`` for a single fragment):
    interpolate its test-space and world positions, discard it where an enabled surface other
    than ``skip`` clips it, and a cap fragment of ``solid`` also where the volumetric parity
    test (majority over the sprite's axes) says outside."""
    c0 = np.float64(b0)
    c1 = np.float64(b1)
    c2 = np.float64(b2)
    px = (c0 * tv[i0, 0] + c1 * tv[i1, 0]) + c2 * tv[i2, 0]
    py = (c0 * tv[i0, 1] + c1 * tv[i1, 1]) + c2 * tv[i2, 1]
    pz = (c0 * tv[i0, 2] + c1 * tv[i1, 2]) + c2 * tv[i2, 2]
    if clipped_at(px, py, pz, skip, params, wrap, enabled, maps, offset, shape):
        return False
    if solid < 0:
        return True
    if separate:
        px = (c0 * wv[i0, 0] + c1 * wv[i1, 0]) + c2 * wv[i2, 0]
        py = (c0 * wv[i0, 1] + c1 * wv[i1, 1]) + c2 * wv[i2, 1]
        pz = (c0 * wv[i0, 2] + c1 * wv[i1, 2]) + c2 * wv[i2, 2]
    # majority vote, decided as soon as either side has it
    n = v_first[solid + 1] - v_first[solid]
    votes = 0
    for ld in range(v_first[solid], v_first[solid + 1]):
        if parity_at(px, py, pz, v_mat[ld], v_depth, v_sign, v_count, v_start[ld],
                     v_cstart[ld], v_hw[ld, 0], v_hw[ld, 1], False):
            votes += 1
            if votes * 2 > n:
                return True
        elif (ld - v_first[solid] + 1 - votes) * 2 >= n:
            return False
    return votes * 2 > n


@njit(**PJIT)
def _fused_clip_pass(f, vX, vY, vZ, vIW, vXf, vYf, fbox, sX, sY, sZ, sIW, sXf, sYf, sprim,
                     sfront, sbox, sarea, B, starts, lists, ntx, width, height, bits, rule,
                     face_offsets, n_solids, n_surf, n_enabled, h_lo, h_hi, tv, wv, separate,
                     params, wrap, enabled,
                     maps, offset, shape, v_first, v_mat, v_depth, v_sign, v_count, v_start,
                     v_cstart, v_hw, sure, sure_bary, tile_shift, func, clear, o_depth, o_prim,
                     o_front, o_bary):
    """The rasterizer's fused tile pass (depth function ``func`` of
    :data:`refraster.raster.DEPTH_FUNCS`, the buffer cleared to ``clear``; ``GL_LESS`` and 1 for
    the paper's pass) with the clip stage between
    rasterization and the depth test. A fragment that fails the depth test is left untested
    (it cannot change the tile whether discarded or not), so the result equals the fragment
    stream + stage + resolve exactly. A cap face flagged in ``sure`` skips its parity tests
    when its fragments provably stay in the box the flag was decided over
    (:func:`_fragments_stay_near`); they would all pass. The tile size comes in as an
    argument, not as the rasterizer's constant: Numba's cache does not see another module's
    constants change. The face image ``o_prim`` comes unfilled: the pass writes its −1 where no
    fragment won (the other outputs' background is the caller's)."""
    ntiles = starts.shape[0] - 1
    for tile in prange(ntiles):
        tx0, tx1, ty0, ty1 = tile_rect(tile, ntx, tile_shift, width, height)
        if starts[tile] == starts[tile + 1]:
            # nothing binned: the tile keeps resolved_buffers' clear values (the face
            # image's −1 written here, in parallel, as the rasterizer's pass does)
            for y in range(ty0, ty1 + 1):
                row = np.uint64(height - 1 - y)
                for x in range(tx0, tx1 + 1):
                    o_prim[row, np.uint64(x)] = -1
            continue
        size = 1 << tile_shift
        zbuf = np.full((size, size), clear, np.float32)
        win = np.full((size, size), NO_ITEM, np.int64)
        for j in range(starts[tile], starts[tile + 1]):
            item = lists[j]
            bx0, bx1, by0, by1 = _box_in_tile(item, fbox, sbox, tx0, tx1, ty0, ty1)
            if bx0 > bx1 or by0 > by1:
                continue
            (r0, sx0, sy0, b0, r1, sx1, sy1, b1, r2, sx2, sy2, b2, fx0, fy0, fx1, fy1, fx2, fy2,
             z0, z1, z2, iw0, iw1, iw2, prim, front, piece, inv_area, inv_af, dzdx,
             dzdy) = _setup(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf, sprim,
                            sfront, sarea, bits, rule, bx0, by0)
            obj = _object_of(face_offsets, prim)
            skip = -1
            solid = -1
            if obj >= n_solids:   # a cap of solid m and surface k: object M + m·K + k
                skip = (obj - n_solids) % n_surf
                solid = (obj - n_solids) // n_surf
            i0 = f[prim, 0]
            i1 = f[prim, 1]
            i2 = f[prim, 2]
            test = True
            if piece < 0 and inv_af > 0.0:   # interpolated from the unsnapped triangle
                # a cap face whose fragments all pass the parity test is tested as a solid's
                is_cap = solid >= 0 and not (sure[prim] and _fragments_stay_near(
                    fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, inv_af, bits, sure_bary))
                if n_enabled - (1 if skip >= 0 and enabled[skip] else 0) == 0:
                    cls = 2 if is_cap else 1   # no surface to classify against
                else:
                    cls = _box_class(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, i0,
                                     i1 if front else i2, i2 if front else i1, tv, skip,
                                     is_cap, params, enabled, h_lo, h_hi, bx0 + 0.5, bx1 + 0.5,
                                     by0 + 0.5, by1 + 0.5)
                if cls == 0:
                    continue
                test = cls == 2
            if not test and depth_rows(zbuf, win, item, func, r0, sx0, sy0, r1, sx1, sy1, r2,
                                       sx2, sy2, fx0, fy0, z0, dzdx, dzdy, inv_af, bx0, bx1,
                                       by0, by1, tx0, ty0):
                continue   # no fragment to test: the plain pass's depth-only loops
            for y in range(by0, by1 + 1):
                a, b = row_span(r0, sx0, r1, sx1, r2, sx2, bx1 - bx0 + 1)
                e0 = r0 + sx0 * a
                e1 = r1 + sx1 * a
                e2 = r2 + sx2 * a
                ly = y - ty0
                for x in range(bx0 + a, bx0 + b + 1):
                    if e0 >= 0 and e1 >= 0 and e2 >= 0:
                        z = fragment_depth(fx0, fy0, z0, z1, z2, dzdx, dzdy, inv_af, x, y,
                                           e0 + b0, e1 + b1, e2 + b2, inv_area)
                        lx = x - tx0
                        if not depth_test(func, z, zbuf[ly, lx]):
                            pass
                        elif not test:
                            zbuf[ly, lx] = z
                            win[ly, lx] = item
                        else:
                            l0, l1, l2 = lambdas(fx0, fy0, fx1, fy1, fx2, fy2, inv_af, x, y,
                                                 e0 + b0, e1 + b1, e2 + b2, inv_area)
                            c0, c1, c2 = perspective_bary(iw0, iw1, iw2, piece, front, B, l0,
                                                          l1, l2)
                            if _keep(c0, c1, c2, i0, i1, i2, tv, wv, separate, skip, solid,
                                     params, wrap, enabled, maps, offset, shape, v_first, v_mat,
                                     v_depth, v_sign, v_count, v_start, v_cstart, v_hw):
                                zbuf[ly, lx] = z
                                win[ly, lx] = item
                    e0 += sx0
                    e1 += sx1
                    e2 += sx2
                r0 += sy0
                r1 += sy1
                r2 += sy2
        # the rasterizer's _fused_pass post-pass, written out (see there)
        for y in range(ty0, ty1 + 1):
            row = height - 1 - y
            for x in range(tx0, tx1 + 1):
                item = win[y - ty0, x - tx0]
                if item == NO_ITEM:
                    o_prim[np.uint64(row), np.uint64(x)] = -1
                else:
                    o_depth[row, x] = zbuf[y - ty0, x - tx0]
                    write_winner(item, f, vX, vY, vZ, vIW, vXf, vYf, sX, sY, sZ, sIW, sXf, sYf,
                                 sprim, sfront, sarea, B, bits, rule, x, y, row, width, o_prim,
                                 o_front, o_bary)


@njit(**IJIT)
def _fragments_stay_near(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, inv_af, bits, limit):
    """True when no fragment of this unsnapped triangle (counter-clockwise, ``inv_af`` = 1 /
    its doubled area > 0) can have a perspective-correct barycentric below ``−limit``.

    A covered pixel centre lies in the snapped triangle, whose vertices are within
    ``δ = √2·2^−bits`` pixel of the unsnapped ones, so within δ of a point of the unsnapped
    triangle: its screen-space λ_i ≥ −δ / altitude_i ≥ −ε with ε = δ·(longest edge)·inv_af.
    Then ``c_i = λ_i w_i⁻¹ / Σ λ_j w_j⁻¹ ≥ −ε·max w⁻¹ / (min w⁻¹ − 2ε·max w⁻¹)``. (δ is twice
    the rounding to the subpixel grid.)"""
    e = max(max((fx1 - fx0) * (fx1 - fx0) + (fy1 - fy0) * (fy1 - fy0),
                (fx2 - fx1) * (fx2 - fx1) + (fy2 - fy1) * (fy2 - fy1)),
            (fx0 - fx2) * (fx0 - fx2) + (fy0 - fy2) * (fy0 - fy2))
    eps = 1.4142135623730951 * (1.0 / np.float64(np.int64(1) << bits)) * math.sqrt(e) * inv_af
    lo = min(iw0, iw1, iw2)
    hi = max(iw0, iw1, iw2)
    den = lo - 2.0 * eps * hi
    return den > 0.0 and eps * hi <= limit * den


#: Relative margin of the per-box classification (:func:`_box_class`): far above the
#: rounding of the float32 barycentrics (6e-8) the per-fragment test works from.
_CLASSIFY_MARGIN = 1e-6


@njit(**IJIT)
def _corner_q(x0, y0, x1, y1, x2, y2, iw0, iw1, iw2, px, py):
    """``q_i = λ_i·(1/w_i)`` at window point (px, py), λ the unnormalized barycentrics of the
    unsnapped triangle (the caller handles the sign of its area)."""
    return (((x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)) * iw0,
            ((x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)) * iw1,
            ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)) * iw2)


@njit(**IJIT)
def _box_class(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, c0, c1, c2, tv, skip, is_cap, params,
               enabled, h_lo, h_hi, px0, px1, py0, py1):
    """What the clip stage can do to the fragments of one triangle inside a pixel box:
    0 — some enabled surface (other than a cap's own) clips all of them; 1 — every enabled
    surface keeps all of them and the triangle is no cap (so no test is needed); 2 — test
    each fragment.

    Why this is exact: g's plane part is affine in the position and the offset term lies in
    [h_lo, h_hi]; a fragment's position is ``P = Σ q_i V_i / Σ q_i`` with ``q_i = λ_i / w_i``
    and λ affine in window space (the counter-clockwise, unsnapped triangle's, as the
    rasterizer interpolates: ``(fx, fy)``, ``iw`` and the vertices ``c0, c1, c2`` in that
    order), so the sign of ``Σ q_i (N·(V_i − O) + h)`` over the box's pixel centres is bounded
    by its values at the four corner centres ``(px, py)``. A margin covers the float32
    rounding of the barycentrics and their sum's distance from 1."""
    qs = (_corner_q(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, px0, py0),
          _corner_q(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, px1, py0),
          _corner_q(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, px0, py1),
          _corner_q(fx0, fy0, fx1, fy1, fx2, fy2, iw0, iw1, iw2, px1, py1))
    kept_by_all = not is_cap
    for k in range(params.shape[0]):
        if not enabled[k] or k == skip:
            continue
        p0 = ((tv[c0, 0] - params[k, 0]) * params[k, 9] + (tv[c0, 1] - params[k, 1])
              * params[k, 10]) + (tv[c0, 2] - params[k, 2]) * params[k, 11]
        p1 = ((tv[c1, 0] - params[k, 0]) * params[k, 9] + (tv[c1, 1] - params[k, 1])
              * params[k, 10]) + (tv[c1, 2] - params[k, 2]) * params[k, 11]
        p2 = ((tv[c2, 0] - params[k, 0]) * params[k, 9] + (tv[c2, 1] - params[k, 1])
              * params[k, 10]) + (tv[c2, 2] - params[k, 2]) * params[k, 11]
        # bound on the terms whose rounding the margin must cover: the fragment's
        # barycentrics need not sum to 1 exactly, which shifts N·P by up to |N·V|, |N·O|
        mag = max(abs(tv[c0, 0]) + abs(tv[c0, 1]) + abs(tv[c0, 2]),
                  abs(tv[c1, 0]) + abs(tv[c1, 1]) + abs(tv[c1, 2]),
                  abs(tv[c2, 0]) + abs(tv[c2, 1]) + abs(tv[c2, 2])) \
            + abs(params[k, 0]) + abs(params[k, 1]) + abs(params[k, 2])
        scale = max(abs(p0), abs(p1), abs(p2)) + mag + max(abs(h_lo[k]), abs(h_hi[k])) + 1e-300
        clipped = True
        kept = True
        for corner in range(4):
            q0, q1, q2 = qs[corner]
            q_abs = abs(q0) + abs(q1) + abs(q2)
            q_sum = q0 + q1 + q2
            if not q_sum > _CLASSIFY_MARGIN * q_abs:
                return 2
            tol = _CLASSIFY_MARGIN * q_abs * scale
            base = q0 * p0 + q1 * p1 + q2 * p2
            if not base + q_sum * h_hi[k] < -tol:
                clipped = False
            if not base + q_sum * h_lo[k] > tol:
                kept = False
            if not (clipped or kept):
                break
        if clipped:
            return 0
        if not kept:
            kept_by_all = False
    return 1 if kept_by_all else 2


def _pack_sprites(tests):
    """The sprites of all solids as one set of flat arrays for :func:`_fused_clip_pass`."""
    parts = [t.packed() for t in tests]
    first = np.zeros(len(parts) + 1, np.int64)
    np.cumsum([len(p[0]) for p in parts], out=first[1:])
    if len(parts) == 1:
        return (first, *parts[0])
    mats = np.concatenate([p[0] for p in parts])
    depth = np.concatenate([p[1] for p in parts])
    sign = np.concatenate([p[2] for p in parts])
    count = np.concatenate([p[3] for p in parts])
    dbase = np.cumsum([0] + [len(p[1]) for p in parts[:-1]])
    cbase = np.cumsum([0] + [len(p[3]) for p in parts[:-1]])
    start = np.concatenate([p[4] + b for p, b in zip(parts, dbase)])
    cstart = np.concatenate([p[5] + b for p, b in zip(parts, cbase)])
    hw = np.concatenate([p[6] for p in parts])
    for a in (depth, sign, count):
        a.setflags(write=False)
    return first, mats, depth, sign, count, start, cstart, hw


_NO_SPRITES = None


def _no_sprites():
    """Empty sprite arrays (typed as the real ones) for a pass without caps."""
    global _NO_SPRITES
    if _NO_SPRITES is None:
        arrays = [np.zeros(0, np.float32), np.zeros(0, np.int8), np.zeros(0, np.int32)]
        for a in arrays:
            a.setflags(write=False)
        _NO_SPRITES = (np.zeros(1, np.int64), np.zeros((0, 4, 4)), *arrays,
                       np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2), np.int64))
    return _NO_SPRITES


def _fused_clip(prep, test_vertices, world_vertices, n_solids, surfaces, tests,
                sure_flags=(), depth_func=1, clear_depth=1.0, fill=True, scratch=None):
    """Rasterize, clip, parity-test and depth-resolve the prepared draw calls in one pass,
    with the depth function ``depth_func`` (:data:`refraster.raster.DEPTH_FUNCS`) against a
    buffer cleared to ``clear_depth``.
    ``sure_flags`` holds, per cap draw call after the solids, the "surely inside" flags of its
    faces (:func:`refraster.clipsurface.capping.surely_inside`) or ``None``.

    Returns ``(depth, prim_global, front, bary)`` as :func:`refraster.raster.rasterizer.fused`;
    ``fill=False`` as its ``fill=False`` (depth, facing and barycentrics hold only the pixels a
    fragment won: the caller's ``finalize`` sweep writes the rest); ``scratch``: for the tile
    lists (:func:`refraster.raster.rasterizer.bin_primitives`).
    """
    prims = prep.triangles
    packed = _Packed(surfaces)
    n_surf = max(len(surfaces), 1)
    h_lo = np.zeros(len(surfaces))
    h_hi = np.zeros(len(surfaces))
    for k, srf in enumerate(surfaces):
        ends = srf.scale[2] * np.array(srf.height_range)
        h_lo[k], h_hi[k] = ends.min(), ends.max()
    face_image_limit(prims.n_faces, "the clip surfaces' tile pass")
    ntx, _, starts, lists = bin_primitives(prims, scratch)
    h, w = prims.height, prims.width
    depth, prim, front, bary = resolved_buffers(h, w, clear_depth, fill, face=False)
    sprites = _pack_sprites(tests) if tests else _no_sprites()
    separate = world_vertices is not test_vertices
    sure = np.zeros(int(prep.face_offsets[-1]), np.bool_)
    for call, flags in enumerate(sure_flags):
        if flags is not None and flags.size:
            at = int(prep.face_offsets[n_solids + call])
            sure[at:at + flags.size] = flags
    _fused_clip_pass(*_geometry(prims), starts, lists, ntx, w, h, prims.subpixel_bits,
                     prep.fill_rule, prep.face_offsets, n_solids, n_surf,
                     int(packed.enabled.sum()), h_lo, h_hi,
                     test_vertices, world_vertices, separate, *packed.args(), *sprites, sure,
                     SURE_EXTRAPOLATION,
                     TILE_SHIFT, int(depth_func), np.float32(clear_depth), depth, prim, front,
                     bary)
    return depth, prim, front, bary
