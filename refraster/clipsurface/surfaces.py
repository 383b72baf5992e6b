"""2.5D clip surfaces and relief clip planes (Trapp & Döllner), as a fragment stage.

A **clip surface** ``CS = (O, U, V, S, OM)`` is a plane through O spanned by the orthogonal
vectors U and V, displaced along −N by ``Sz·h`` where ``h = OM(s, t)`` is an offset-map sample
(MATH.md §1.1)::

    Û = U/|U|,  V̂ = V/|V|,  N = Û × V̂                               (D1)
    s = ((P − O)·Û / |U|)·Sx,   t = ((P − O)·V̂ / |V|)·Sy              (Eq. 2, D2, D5)
    g(P) = N·(P − O) + Sz·OM(s, t)                                    (Eq. 1, D3, D4)
    clipped(P)  ⇔  enabled ∧ g(P) < 0

The kept material lies on the +N side. A **relief clip plane** ``RCP = (N, P, OM, s)`` is the
same test with the opposite normal (D8): :class:`ReliefClipPlane` maps onto :class:`ClipSurface`.

Any number of surfaces is evaluated in one pass (:func:`clip_mask`): a point is discarded when
any enabled surface clips it (Sec. 4.5). :func:`render_clipped` draws solids clipped this way
and closes the cuts with cap surfaces (:mod:`refraster.capping`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange

from ._config import IJIT, PJIT
from ._validate import as_choice, as_float_array, as_matrix, as_real
from .framebuffer import Framebuffer
from .ldi import parity_at
from .raster.gbuffer import _object_of
from .raster.rasterizer import (NO_ITEM, TILE_SHIFT, _box_in_tile, _geometry, _setup,
                                bin_primitives, fragment_depth, lambdas, perspective_bary,
                                resolved_buffers, row_span, tile_rect, write_winner)
from .offsetmaps import (WRAP_MODES, as_offset_map, as_wrap, normal_map, occlusion_map,
                         texture2d_flat)

__all__ = ["ClipSurface", "ReliefClipPlane", "ClippedFramebuffer", "as_surfaces",
           "clip_function", "clip_mask", "render_clipped"]

#: Largest |Û·V̂| accepted as "orthogonal" (D7); V is then made exactly orthogonal.
ORTHOGONALITY_TOLERANCE = 1e-6
#: Smallest accepted length of U, V or an RCP normal, relative to the largest coordinate.
_MIN_LENGTH = 1e-12

# Columns of the packed parameter table read by the kernels.
_O, _UH, _VH, _N = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
_ULEN, _VLEN, _SX, _SY, _SZ = 12, 13, 14, 15, 16
_N_PARAMS = 17


def _vector(value, name):
    v = as_float_array(value, name, shape=(3,))
    length = float(np.linalg.norm(v))
    if not length > _MIN_LENGTH * max(1.0, float(np.abs(v).max())):
        raise ValueError(f"{name} must have non-zero length, got {v}")
    return v, length


class ClipSurface:
    """A 2.5D clip surface ``CS = (O, U, V, S, OM)`` (Trapp & Döllner, Sec. 4.1).

    Parameters
    ----------
    origin : (3,) float
        O, in world space.
    u, v : (3,) float
        U and V, orthogonal, non-zero, in world space; their lengths set the texture domain:
        ``s ∈ [0, Sx]`` spans ``|U|`` along Û.
    scale : (3,) float
        ``S = (Sx, Sy, Sz)``: texture repeats along U and V (positive) and the height scale
        Sz in world units (any sign; 0 gives a plane).
    offset_map : (H, W) array
        OM, heights in [0, 1] in texel order (:mod:`refraster.offsetmaps`): uint8, uint16 or
        float.
    wrap : {"repeat", "clamp_to_edge", "mirrored_repeat"}
        The offset map's wrap mode (MATH.md §1.1 takes repeat as the default [guess]).
    enabled : bool
        ``config[3].w`` of Listing 1: a disabled surface clips nothing.

    Notes
    -----
    D7: U and V must be orthogonal (``|Û·V̂| ≤ 1e-6``); V̂ is then re-orthogonalized against Û
    (Gram–Schmidt) so that N is exactly unit. Parallel or zero vectors raise ``ValueError``.
    """

    def __init__(self, origin, u, v, scale=(1.0, 1.0, 1.0), offset_map=None, *, wrap="repeat",
                 enabled=True):
        self.origin = as_float_array(origin, "origin", shape=(3,))
        self.u, u_len = _vector(u, "u")
        self.v, v_len = _vector(v, "v")
        self.scale = as_float_array(scale, "scale", shape=(3,))
        if not (self.scale[0] > 0 and self.scale[1] > 0):
            raise ValueError(f"scale Sx and Sy must be positive, got {self.scale[:2]}")
        if offset_map is None:
            raise TypeError("offset_map is required (use offsetmaps.constant(1) for a plane)")
        self.offset_map = as_offset_map(offset_map)
        self.wrap = as_wrap(wrap)
        if not isinstance(enabled, (bool, np.bool_)):
            raise TypeError(f"enabled must be a bool, got {type(enabled).__name__}")
        self.enabled = bool(enabled)
        u_hat = self.u / u_len
        v_hat = self.v / v_len
        cosine = float(u_hat @ v_hat)
        if abs(cosine) > 1.0 - 1e-9:
            raise ValueError("u and v are parallel; a clip surface needs two orthogonal vectors")
        if abs(cosine) > ORTHOGONALITY_TOLERANCE:
            raise ValueError(
                f"u and v must be orthogonal (D7), got Û·V̂ = {cosine:.3g}; orthogonalize them "
                "(Gram–Schmidt) first")
        v_hat = v_hat - (v_hat @ u_hat) * u_hat
        v_hat /= np.linalg.norm(v_hat)
        self.u_length, self.v_length = u_len, v_len
        self.u_hat, self.v_hat = u_hat, v_hat
        self.normal = np.cross(u_hat, v_hat)
        self.normal /= np.linalg.norm(self.normal)
        self._derived = {}  # normal and occlusion maps, derived on first use
        for arr in (self.origin, self.u, self.v, self.scale, self.u_hat, self.v_hat, self.normal):
            arr.setflags(write=False)

    def __repr__(self):
        return (f"ClipSurface(origin={self.origin.tolist()}, u={self.u.tolist()}, "
                f"v={self.v.tolist()}, scale={self.scale.tolist()}, "
                f"offset_map={self.offset_map.shape}, wrap={self.wrap!r}, "
                f"enabled={self.enabled})")

    def replace(self, **changes):
        """A copy with some constructor arguments changed (e.g. ``enabled=False``)."""
        args = dict(origin=self.origin, u=self.u, v=self.v, scale=self.scale,
                    offset_map=self.offset_map, wrap=self.wrap, enabled=self.enabled)
        args.update(changes)
        return ClipSurface(**args)

    def transformed(self, matrix):
        """The surface in another space: ``O' = M·O`` (affine), ``U' = L·U``, ``V' = L·V``
        with L the linear part of M, normalized afterwards (D6). For a rigid M the clip test
        in the new space equals the old one up to rounding."""
        m = as_matrix(matrix, "matrix")
        lin = m[:3, :3]
        origin = lin @ self.origin + m[:3, 3]
        return self.replace(origin=origin, u=lin @ self.u, v=lin @ self.v)

    @property
    def params(self):
        """The packed parameter row the kernels read (internal layout)."""
        row = np.zeros(_N_PARAMS)
        row[_O], row[_UH], row[_VH], row[_N] = self.origin, self.u_hat, self.v_hat, self.normal
        row[_ULEN], row[_VLEN] = self.u_length, self.v_length
        row[_SX], row[_SY], row[_SZ] = self.scale
        return row

    @property
    def height_range(self):
        """(min, max) of the offset map (cached)."""
        if "range" not in self._derived:
            self._derived["range"] = (float(self.offset_map.min()), float(self.offset_map.max()))
        return self._derived["range"]

    @property
    def texel_size(self):
        """World length of one texel along Û and along V̂."""
        rows, cols = self.offset_map.shape
        return (self.u_length / (self.scale[0] * cols), self.v_length / (self.scale[1] * rows))

    def texcoords(self, points):
        """``(s, t)`` of Eq. 2 for world points ``(N, 3)`` → ``(N, 2)``."""
        p = as_float_array(points, "points", shape=(None, 3))
        d = p - self.origin
        s = (d @ self.u_hat / self.u_length) * self.scale[0]
        t = (d @ self.v_hat / self.v_length) * self.scale[1]
        return np.stack([s, t], axis=1)

    def normal_map(self):
        """MATH.md §1.2b normal map of this surface, ``(H, W, 3)`` in the (Û, V̂, N) frame
        (computed once per surface, read-only)."""
        key = ("normal",)
        if key not in self._derived:
            n = normal_map(self.offset_map, extent=(self.u_length, self.v_length),
                           scale=self.scale, wrap=self.wrap)
            n.setflags(write=False)
            self._derived[key] = n
        return self._derived[key]

    def occlusion_map(self, *, radius=None, directions=8, steps=8):
        """MATH.md §1.2b occlusion map of this surface (see :func:`offsetmaps.occlusion_map`;
        computed once per surface and parameter set, read-only)."""
        key = ("occlusion", radius, directions, steps)
        if key not in self._derived:
            a = occlusion_map(self.offset_map, extent=(self.u_length, self.v_length),
                              scale=self.scale, wrap=self.wrap, radius=radius,
                              directions=directions, steps=steps)
            a.setflags(write=False)
            self._derived[key] = a
        return self._derived[key]


class ReliefClipPlane:
    """A relief clip plane ``RCP = (N, P, OM, s)`` (Trapp & Döllner, RCP poster).

    Parameters
    ----------
    normal : (3,) float
        The RCP normal N; the side it points to is **discarded** (the poster's ``… > 0``).
    point : (3,) float
        P, a point of the undisplaced plane.
    offset_map : (H, W) array
        OM, as for :class:`ClipSurface`.
    height_scale : float
        s: the plane is displaced by ``s·h`` along N.
    u : (3,) float, optional
        The in-plane direction of the texture's s axis (projected onto the plane). When
        omitted it is the projection of the world axis least aligned with N (ties: x before y
        before z), so the choice is deterministic.
    extent : float
        World length of one texture tile along each in-plane axis (``|U| = |V|``).
    wrap, enabled
        As for :class:`ClipSurface`.

    Notes
    -----
    MATH.md D8: RCP discards ``N·(X − P) − s·h > 0``, the clip-surface test with
    ``N_CS = −N / |N|``, ``O = P``, ``Sz = s``. :attr:`clip_surface` is that surface, with
    ``Û`` from ``u`` and ``V̂ = N_CS × Û`` (so ``Û × V̂ = N_CS``).
    """

    def __init__(self, normal, point, offset_map, height_scale, u=None, *, extent=1.0,
                 wrap="repeat", enabled=True):
        n, n_len = _vector(normal, "normal")
        self.normal = n / n_len
        self.point = as_float_array(point, "point", shape=(3,))
        self.height_scale = as_real(height_scale, "height_scale")
        extent = as_real(extent, "extent", lo=0.0, lo_open=True)
        n_cs = -self.normal
        if u is None:
            axis = np.zeros(3)
            axis[int(np.argmin(np.abs(self.normal)))] = 1.0
            u_dir = axis
        else:
            u_dir, u_len = _vector(u, "u")
            u_dir = u_dir / u_len
        u_dir = u_dir - (u_dir @ n_cs) * n_cs
        u_len = float(np.linalg.norm(u_dir))
        if not u_len > 1e-9:
            raise ValueError("u must not be parallel to the normal")
        u_hat = u_dir / u_len
        v_hat = np.cross(n_cs, u_hat)
        self.u = u_hat
        self.clip_surface = ClipSurface(self.point, extent * u_hat, extent * v_hat,
                                        (1.0, 1.0, self.height_scale), offset_map, wrap=wrap,
                                        enabled=enabled)

    def __repr__(self):
        return (f"ReliefClipPlane(normal={self.normal.tolist()}, point={self.point.tolist()}, "
                f"height_scale={self.height_scale}, u={self.u.tolist()})")


def as_surfaces(surfaces, name="surfaces"):
    """One surface or a sequence of :class:`ClipSurface` / :class:`ReliefClipPlane` → list of
    :class:`ClipSurface`."""
    if isinstance(surfaces, (ClipSurface, ReliefClipPlane)):
        surfaces = [surfaces]
    if not isinstance(surfaces, (list, tuple)):
        raise TypeError(f"{name} must be a ClipSurface, a ReliefClipPlane or a list of them, "
                        f"got {type(surfaces).__name__}")
    out = []
    for i, s in enumerate(surfaces):
        if isinstance(s, ReliefClipPlane):
            s = s.clip_surface
        if not isinstance(s, ClipSurface):
            raise TypeError(f"{name}[{i}] must be a ClipSurface or ReliefClipPlane, "
                            f"got {type(s).__name__}")
        out.append(s)
    return out


class _Packed:
    """Surfaces packed for the kernels: parameter table, wrap codes and concatenated maps."""

    def __init__(self, surfaces):
        k = len(surfaces)
        self.params = np.zeros((k, _N_PARAMS))
        self.wrap = np.zeros(k, np.int64)
        self.enabled = np.zeros(k, np.bool_)
        self.shape = np.zeros((k, 2), np.int64)
        self.offset = np.zeros(k, np.int64)
        pos = 0
        for i, s in enumerate(surfaces):
            self.params[i] = s.params
            self.wrap[i] = WRAP_MODES[s.wrap]
            self.enabled[i] = s.enabled
            self.shape[i] = s.offset_map.shape
            self.offset[i] = pos
            pos += s.offset_map.size
        if k == 1:   # the common case: the map itself (C-contiguous, read-only)
            self.maps = surfaces[0].offset_map.reshape(-1)
        else:
            self.maps = np.zeros(pos)
            for i, s in enumerate(surfaces):
                self.maps[self.offset[i]:self.offset[i] + s.offset_map.size] = \
                    s.offset_map.ravel()
            self.maps.setflags(write=False)

    def args(self):
        return self.params, self.wrap, self.enabled, self.maps, self.offset, self.shape


@njit(**IJIT)
def _g(px, py, pz, params, k, maps, offset, shape, mode):
    """g(P) = N·(P − O) + Sz·OM(s, t) of surface ``k`` (MATH.md §1.1); its map is
    ``maps[offset[k]:]``, ``shape[k]`` texels."""
    dx = px - params[k, 0]
    dy = py - params[k, 1]
    dz = pz - params[k, 2]
    s = ((dx * params[k, 3] + dy * params[k, 4] + dz * params[k, 5]) / params[k, 12]) \
        * params[k, 14]
    t = ((dx * params[k, 6] + dy * params[k, 7] + dz * params[k, 8]) / params[k, 13]) \
        * params[k, 15]
    h = texture2d_flat(maps, offset[k], shape[k, 0], shape[k, 1], s, t, mode)
    return (dx * params[k, 9] + dy * params[k, 10] + dz * params[k, 11]) + params[k, 16] * h


@njit(**IJIT)
def clipped_at(px, py, pz, skip, params, wrap, enabled, maps, offset, shape):
    """True when any enabled surface ``k ≠ skip`` has ``g(P) < 0`` (the fragment is discarded)."""
    for k in range(params.shape[0]):
        if enabled[k] and k != skip:
            if _g(px, py, pz, params, k, maps, offset, shape, wrap[k]) < 0.0:
                return True
    return False


@njit(**PJIT)
def _clip_kernel(points, skip, params, wrap, enabled, maps, offset, shape, out):
    """out[n] = any enabled surface k ≠ skip[n] has g(points[n]) < 0."""
    for n in prange(points.shape[0]):
        out[n] = clipped_at(points[n, 0], points[n, 1], points[n, 2], skip[n], params, wrap,
                            enabled, maps, offset, shape)


@njit(**PJIT)
def _g_kernel(points, params, maps, offset, shape, mode, out):
    for n in prange(points.shape[0]):
        out[n] = _g(points[n, 0], points[n, 1], points[n, 2], params, 0, maps, offset, shape,
                    mode)


# ------------------------------------------------------------- fused clip-and-cap pass

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
                     v_cstart, v_hw, sure, sure_bary, tile_shift, o_depth, o_prim, o_front, o_bary):
    """The rasterizer's fused tile pass (``GL_LESS``, clear 1) with the clip stage between
    rasterization and the depth test. A fragment that fails the depth test is left untested
    (it cannot change the tile whether discarded or not), so the result equals the fragment
    stream + stage + resolve exactly. A cap face flagged in ``sure`` skips its parity tests
    when its fragments provably stay in the box the flag was decided over
    (:func:`_fragments_stay_near`); they would all pass. The tile size comes in as an
    argument, not as the rasterizer's constant: Numba's cache does not see another module's
    constants change."""
    ntiles = starts.shape[0] - 1
    for tile in prange(ntiles):
        if starts[tile] == starts[tile + 1]:
            continue   # nothing binned: the tile keeps resolved_buffers' clear values
        size = 1 << tile_shift
        tx0, tx1, ty0, ty1 = tile_rect(tile, ntx, tile_shift, width, height)
        zbuf = np.full((size, size), np.float32(1.0), np.float32)
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
                        if z < zbuf[ly, lx] and not test:
                            zbuf[ly, lx] = z
                            win[ly, lx] = item
                        elif z < zbuf[ly, lx]:
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
                if item != NO_ITEM:
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
                sure_flags=()):
    """Rasterize, clip, parity-test and depth-resolve the prepared draw calls in one pass.
    ``sure_flags`` holds, per cap draw call after the solids, the "surely inside" flags of its
    faces (:func:`refraster.capping.surely_inside`) or ``None``.

    Returns ``(depth, prim_global, front, bary)`` as :func:`refraster.raster.rasterizer.fused`.
    """
    prims = prep.triangles
    packed = _Packed(surfaces)
    n_surf = max(len(surfaces), 1)
    h_lo = np.zeros(len(surfaces))
    h_hi = np.zeros(len(surfaces))
    for k, srf in enumerate(surfaces):
        ends = srf.scale[2] * np.array(srf.height_range)
        h_lo[k], h_hi[k] = ends.min(), ends.max()
    ntx, _, starts, lists = bin_primitives(prims)
    h, w = prims.height, prims.width
    depth, prim, front, bary = resolved_buffers(h, w, 1.0)
    from . import capping
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
                     capping.SURE_EXTRAPOLATION,
                     TILE_SHIFT, depth, prim, front, bary)
    return depth, prim, front, bary


def _surfaces_in_space(surfaces, space, view):
    space = as_choice(space, "space", {"world": "world", "eye": "eye"})
    if space == "eye":
        if view is None:
            raise ValueError("space='eye' needs the view matrix (view=...)")
        view = as_matrix(view, "view")
        surfaces = [s.transformed(view) for s in surfaces]
    return surfaces


def clip_function(points, surface, *, space="world", view=None):
    """Evaluate ``g(P) = N·(P − O) + Sz·OM(s, t)`` of one surface at ``points``.

    Parameters
    ----------
    points : (N, 3) float
        Positions in world space, or in eye space when ``space="eye"``.
    surface : ClipSurface or ReliefClipPlane
        Given in world space.
    space : {"world", "eye"}
        Where the test is evaluated; ``"eye"`` transforms O, U and V by ``view`` (D6).
    view : (4, 4) float, optional
        World → eye matrix, needed for ``space="eye"``.

    Returns
    -------
    (N,) float64: negative where the surface clips (the enabled flag is ignored here).

    Notes
    -----
    Trapp & Döllner, Eq. 1–3 and Listing 1; MATH.md §1.1 with D1–D5.
    """
    (surface,) = as_surfaces([surface], "surface")
    points = as_float_array(points, "points", shape=(None, 3))
    (surface,) = _surfaces_in_space([surface], space, view)
    out = np.zeros(points.shape[0])
    packed = _Packed([surface])
    _g_kernel(points, packed.params, packed.maps, packed.offset, packed.shape,
              WRAP_MODES[surface.wrap], out)
    return out


def clip_mask(points, surfaces, *, space="world", view=None, skip=None):
    """Which points the clip surfaces discard: any enabled surface with ``g(P) < 0``.

    Parameters
    ----------
    points : (N, 3) float
        Positions in world space, or in eye space when ``space="eye"``.
    surfaces : ClipSurface, ReliefClipPlane or a list of them
        Given in world space, evaluated together in one pass (Sec. 4.5).
    space : {"world", "eye"}
        Where the test is evaluated (the paper's shader: eye space; D6).
    view : (4, 4) float, optional
        World → eye matrix, needed for ``space="eye"``.
    skip : (N,) int, optional
        Per point, the index of one surface to ignore (−1: none). A cap fragment of surface k
        skips k: it lies on that surface's zero set by construction.

    Returns
    -------
    (N,) bool: True = clipped (discard).

    Notes
    -----
    MATH.md §1.1: ``clipped(P) ⇔ enabled ∧ N·(P − O) + Sz·OM(s, t) < 0``; OM is sampled as
    GLSL ``texture2D`` with linear filtering and the surface's wrap mode (MATH.md §1.2b).
    """
    surfaces = _surfaces_in_space(as_surfaces(surfaces), space, view)
    points = as_float_array(points, "points", shape=(None, 3))
    if skip is None:
        skip = np.full(points.shape[0], -1, np.int64)
    else:
        skip = np.asarray(skip)
        if not np.issubdtype(skip.dtype, np.integer) or skip.shape != (points.shape[0],):
            raise ValueError(f"skip must be an int array of shape ({points.shape[0]},)")
        skip = np.ascontiguousarray(skip, np.int64)
    out = np.zeros(points.shape[0], np.bool_)
    if surfaces and points.shape[0]:
        _clip_kernel(points, skip, *_Packed(surfaces).args(), out)
    return out


@dataclass(eq=False)
class ClippedFramebuffer(Framebuffer):
    """A :class:`~refraster.Framebuffer` of :func:`render_clipped`, with the caps marked.

    Extra attributes
    ----------------
    cap_mask : (H, W) bool
        Pixels showing a cap.
    cap_points : (C, 3) float64
        World position of each cap pixel, in row-major order of ``cap_mask``.
    cap_position : (H, W, 3) float64
        The same as an image, NaN elsewhere (made on first use).
    n_solids, n_surfaces : int
        M and K: a cap of solid m and surface k has ``object_id = M + m·K + k``.
    """

    cap_mask: np.ndarray = field(default=None, repr=False)
    cap_points: np.ndarray = field(default=None, repr=False)
    n_solids: int = 0
    n_surfaces: int = 0

    @property
    def cap_position(self):
        if getattr(self, "_cap_position", None) is None:
            out = np.full(self.cap_mask.shape + (3,), np.nan)
            out[self.cap_mask] = self.cap_points
            self._cap_position = out
        return self._cap_position

    def eye_position(self):
        """Eye-space position of the visible surface (caps included), NaN background."""
        out = np.full(self.mask.shape + (3,), np.nan)
        solid = self.mask & ~self.cap_mask
        sub = Framebuffer.eye_position(self)
        out[solid] = sub[solid]
        out[self.cap_mask] = self.cap_points @ self.view[:3, :3].T + self.view[:3, 3]
        return out


def _solid_tests(world_solids, vds, resolution):
    """One volumetric parity test per solid: given ``vds`` objects, or built with
    :class:`refraster.ldi.VolumetricDepthSprite` (MATH.md §2)."""
    if vds is not None:
        tests = list(vds) if isinstance(vds, (list, tuple)) else [vds]
        if len(tests) != len(world_solids):
            raise ValueError(f"vds must hold one sprite per mesh ({len(world_solids)}), "
                             f"got {len(tests)}")
        for i, t in enumerate(tests):
            if not callable(getattr(t, "contains", None)):
                raise TypeError(f"vds[{i}] must have a contains(points) method")
        return tests
    from .ldi import VolumetricDepthSprite
    return [VolumetricDepthSprite.from_mesh(m, resolution=resolution) for m in world_solids]


def _stage(n_solids, surfaces, tests, space, view):
    """``render_clipped``'s clip stage as a ``fragment_stage`` over the fragment stream (what
    :func:`_fused_clip_pass` equals, and the path for duck-typed parity tests)."""
    n_surf = max(len(surfaces), 1)

    def stage(frags):
        obj = frags.object_id
        keep = np.ones(len(frags), np.bool_)
        pos = frags.world_position()
        test_pos = frags.eye_position() if space == "eye" else pos
        is_cap = obj >= n_solids
        skip = np.where(is_cap, (obj - n_solids) % n_surf, -1).astype(np.int64)
        keep &= ~clip_mask(test_pos, surfaces, space=space, view=view, skip=skip)
        for m in range(n_solids if tests is not None and is_cap.any() else 0):
            sel = np.flatnonzero(keep & is_cap & ((obj - n_solids) // n_surf == m))
            if sel.size:
                keep[sel] = tests[m].contains(pos[sel])
        return keep

    return stage


def _concat_vertices(vertices):
    if len(vertices) == 1:
        return np.ascontiguousarray(vertices[0], np.float64)
    return np.ascontiguousarray(np.concatenate(vertices), np.float64) if vertices \
        else np.zeros((0, 3))


#: Whether render_clipped uses the fused tile pass when it can (tests switch it off to compare
#: with the fragment stream and the Python stage, which it must equal bit for bit).
_USE_FUSED = True

#: Cap meshes kept per surface (keyed by the solid's bounds and the subdivision).
_CAP_CACHE_SIZE = 8


def _cached_cap(surface, bounds, subdivision, sprite=None):
    """``(mesh, sure)``: :func:`refraster.capping.cap_mesh`, made once per surface, bounds and
    subdivision (a surface is immutable; the cached mesh's arrays are read-only). With a
    volumetric depth sprite, only the faces that can pass its parity test
    (:func:`refraster.capping.cull_cap`) and their "surely inside" flags
    (:func:`refraster.capping.surely_inside`), made once per sprite too; ``sure`` is ``None``
    without a sprite."""
    import weakref

    from . import capping
    cache = surface._derived

    def put(key, mesh, value):
        caps = [k for k in cache if k[0] == "cap"]
        if len(caps) >= _CAP_CACHE_SIZE:
            del cache[caps[0]]
        if mesh is not None:
            mesh.vertices.setflags(write=False)
            mesh.faces.setflags(write=False)
        cache[key] = value

    key = ("cap", bounds.tobytes(), subdivision)
    cap = cache.get(key, False)
    if cap is False:
        cap = capping.cap_mesh(surface, bounds, subdivision=subdivision)
        put(key, cap, cap)
    if sprite is None or cap is None:
        return cap, None
    # the sprite is held weakly: an id can be reused once its sprite is gone
    culled_key = key + (id(sprite),)
    entry = cache.get(culled_key)
    if entry is None or entry[0]() is not sprite:
        culled = capping.cull_cap(cap, sprite)
        sure = capping.surely_inside(culled, sprite)
        sure.setflags(write=False)
        entry = (weakref.ref(sprite), culled, sure)
        put(culled_key, culled, entry)
    return entry[1], entry[2]


def render_clipped(meshes, surfaces, *, view, proj, width, height, caps=True,
                   cap_style="diffuse", cap_mode="mesh", cap_color=(0.80, 0.30, 0.25),
                   hatch_spacing=None, texture_frequency=4.0, space="world", model=None,
                   normals=None, cull="none", precision="float32", subdivision=1, vds=None,
                   vds_resolution=1024, occlusion_radius=None, background=(1.0, 1.0, 1.0)):
    """Render solids clipped by 2.5D clip surfaces, with cap surfaces closing the cuts.

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        The solids (draw calls 0 … M−1). With ``caps=True`` each must be watertight.
    surfaces : ClipSurface, ReliefClipPlane or a list of them (K surfaces, world space)
    view, proj, width, height
        The camera (:mod:`refraster.camera`).
    caps : bool
        Draw cap surfaces (Trapp & Döllner, Sec. 5).
    cap_style : {"diffuse", "hatch", "marble", "wood", "noise"}
        Cap shading over the normal and occlusion maps (:func:`refraster.capping.shade_caps`).
    cap_mode : {"mesh", "exact"}
        ``"mesh"``: the paper's tessellated, displaced grid (``subdivision`` vertices per texel
        and axis) whose fragments pass the volumetric parity test; ``"exact"``: per-pixel ray –
        height-field intersection (:func:`refraster.capping.exact_caps`).
    cap_color : (3,) float
        Base (diffuse), ink (hatch) or dark texture colour of the caps.
    hatch_spacing : float, optional
        World distance between hatch lines (default 1.5 % of the solids' bounding diagonal).
    texture_frequency : float
        Solid-texture features per world unit.
    space : {"world", "eye"}
        Where the clip test is evaluated (D6; equal for a rigid view).
    model : (4, 4) or list of them, optional
        Object → world matrix per solid; surfaces are always given in world space.
    normals : None, "flat" or "smooth"
        Shading normals of the solids.
    cull, precision
        As :func:`refraster.render`.
    vds : sequence of objects with ``contains(points)``, optional
        Pre-built volumetric depth sprites (world space), one per solid; built with
        ``VolumetricDepthSprite.from_mesh(solid, resolution=vds_resolution)`` otherwise.
    occlusion_radius : float, optional
        Radius of the occlusion maps (:func:`refraster.offsetmaps.occlusion_map`).
    background : (3,) float

    Returns
    -------
    ClippedFramebuffer
        The foundation's Framebuffer; cap pixels carry the cap's window and eye depth, its
        eye-space normal (from the normal map), its colour, ``front_facing`` (True when the
        cap is seen from its −N side) and ``object_id = M + m·K + k`` for the cap of solid m
        and surface k. ``prim_id`` is the cap mesh's face (``"mesh"``) or the cap texel
        ``row·W + col`` (``"exact"``). ``cap_mask`` marks the cap pixels.

    Notes
    -----
    Solid fragments are discarded where any enabled surface clips them (MATH.md §1.1). A cap
    fragment of surface k is kept where the volumetric parity test says inside (MATH.md §2.2)
    and no *other* enabled surface clips it. Caps are drawn after the solids with ``GL_LESS``,
    so at equal depth the solid wins.
    """
    from . import capping
    from .framebuffer import _build, render
    from .ldi import VolumetricDepthSprite
    from .mesh import Mesh, as_meshes, bounds
    from .raster import _models, prepare
    from .raster.fragments import vertices_in

    solids = as_meshes(meshes)
    surfaces = as_surfaces(surfaces)
    view = as_matrix(view, "view")
    proj = as_matrix(proj, "proj")
    if not isinstance(caps, (bool, np.bool_)):
        raise TypeError(f"caps must be a bool, got {type(caps).__name__}")
    style = as_choice(cap_style, "cap_style", {s: s for s in capping.CAP_STYLES})
    mode = as_choice(cap_mode, "cap_mode", {"mesh": "mesh", "exact": "exact"})
    space = as_choice(space, "space", {"world": "world", "eye": "eye"})
    color = as_float_array(cap_color, "cap_color", shape=(3,))
    freq = as_real(texture_frequency, "texture_frequency", lo=0.0, lo_open=True)
    if normals is not None and not (isinstance(normals, str)
                                    and normals.lower() in ("flat", "smooth")):
        raise ValueError("normals must be None, 'flat' or 'smooth' for render_clipped")
    models = _models(model, len(solids))
    world = [Mesh(v, s.faces) if v is not s.vertices else s
             for s, v in zip(solids, vertices_in(solids, models, None, "world"))]
    n_solids, n_surf = len(solids), len(surfaces)
    do_caps = caps and any(s.enabled for s in surfaces)
    tests = None
    if do_caps:
        for i, w in enumerate(world):
            capping.check_watertight(w, f"meshes[{i}]")
        tests = _solid_tests(world, vds, vds_resolution)
    boxes = [bounds(w.vertices) if w.n_vertices else None for w in world]
    lo = np.min([b[0] for b in boxes if b is not None], axis=0) \
        if any(w.n_vertices for w in world) else np.zeros(3)
    hi = np.max([b[1] for b in boxes if b is not None], axis=0) \
        if any(w.n_vertices for w in world) else np.ones(3)
    spacing = (0.015 * float(np.linalg.norm(hi - lo)) or 0.01) if hatch_spacing is None \
        else as_real(hatch_spacing, "hatch_spacing", lo=0.0, lo_open=True)

    fused = _USE_FUSED and (not do_caps or mode != "mesh" or all(
        isinstance(t, VolumetricDepthSprite) for t in tests))
    draw_list, draw_models = list(solids), list(models)
    sure_flags = []   # per cap draw call: its faces' "surely inside" flags (or None)
    if do_caps and mode == "mesh":
        empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        for m, box in enumerate(boxes):
            sprite = tests[m] if isinstance(tests[m], VolumetricDepthSprite) else None
            for s in surfaces:
                cap, sure = _cached_cap(s, box, subdivision, sprite) \
                    if s.enabled and box is not None else (None, None)
                draw_list.append(empty if cap is None else cap)
                sure_flags.append(sure)
                draw_models.append(np.eye(4))

    bg = as_float_array(background, "background", shape=(3,))
    geometry = None
    cap_tests = tests if do_caps and mode == "mesh" else None
    if not fused:
        # duck-typed parity tests: the fragment stream with a Python stage
        fb = render(draw_list, view=view, proj=proj, width=width, height=height,
                    normals=normals, cull=cull, model=draw_models, precision=precision,
                    fragment_stage=_stage(n_solids, surfaces, cap_tests, space, view),
                    background=bg)
    else:
        prep = prepare(draw_list, view=view, proj=proj, width=width, height=height, cull=cull,
                       model=draw_models, precision=precision)
        tv = _concat_vertices(vertices_in(prep.meshes, prep.models, view, space))
        wv = tv if space == "world" else _concat_vertices(
            vertices_in(prep.meshes, prep.models, view, "world"))
        depth, prim_global, front, bary = _fused_clip(
            prep, tv, wv, n_solids, _surfaces_in_space(surfaces, space, view), cap_tests,
            sure_flags)
        h, w = depth.shape
        identity = all(np.array_equal(m, np.eye(4)) for m in prep.models)
        geometry = (tv, prep.triangles.faces) if identity and space == "world" else None
        # the mesh caps' pixels are coloured by shade_cap_pixels below, not by the default
        fb = _build(prep.meshes, prep.models, view, proj, depth, prim_global, prep.face_offsets,
                    front, bary.reshape(h, w, 3), normals, bg, geometry,
                    prep.face_offsets[n_solids] if do_caps and mode == "mesh" else None)
    h, w = fb.depth.shape
    cap_mask = fb.object_id >= n_solids
    out = ClippedFramebuffer(**fb.field_values(), cap_mask=cap_mask,
        cap_points=np.zeros((0, 3)), n_solids=n_solids, n_surfaces=n_surf)
    if not do_caps:
        return out
    if mode == "mesh":
        # the caps are drawn in world space (identity model): interpolate, light and colour
        # their pixels in one pass
        if geometry is None:
            vbase = np.cumsum([0] + [m.n_vertices for m in fb.meshes])
            geometry = (_concat_vertices([m.vertices for m in fb.meshes]),
                        np.concatenate([m.faces + vbase[k] for k, m in enumerate(fb.meshes)]))
        face_offsets = np.cumsum([0] + [m.n_faces for m in fb.meshes]).astype(np.int64)
        out.cap_points = capping.shade_cap_pixels(
            np.flatnonzero(cap_mask), out, n_solids, n_surf, geometry[1], face_offsets,
            geometry[0], surfaces, view=view, style=style, color=color, hatch_spacing=spacing,
            frequency=freq, occlusion_radius=occlusion_radius)
        return out
    else:
        tau, which, origin, direction = capping.exact_caps(
            surfaces, world, tests, view=view, proj=proj, width=width, height=height)
        hit = np.isfinite(tau)
        pts = origin[hit] + tau[hit, None] * direction[hit]
        clip = np.c_[pts, np.ones(len(pts))] @ (proj @ view).T
        depth = (0.5 * (clip[:, 2] / clip[:, 3]) + 0.5).astype(np.float32)
        flat = np.flatnonzero(hit)
        nearer = depth < fb.depth.ravel()[flat]
        flat, pts, depth = flat[nearer], pts[nearer], depth[nearer]
        m_k = which[flat]
        r, c = np.divmod(flat, w)
        cap_mask[r, c] = True
        out.cap_points = pts  # row-major order, as cap_mask lists them
        out.depth[r, c] = depth
        eye = pts @ view[:3, :3].T + view[:3, 3]
        out.eye_depth[r, c] = -eye[:, 2]
        out.object_id[r, c] = n_solids + m_k[:, 0] * n_surf + m_k[:, 1]
        texel = np.zeros(len(pts), np.int64)
        facing = np.zeros(len(pts), np.bool_)
        for k, s in enumerate(surfaces):
            sel = np.flatnonzero(m_k[:, 1] == k)
            if sel.size:
                st = s.texcoords(pts[sel])
                rows, cols = s.offset_map.shape
                col = np.floor(st[:, 0] * cols).astype(np.int64) % cols
                row = np.floor(st[:, 1] * rows).astype(np.int64) % rows
                texel[sel] = row * cols + col
                facing[sel] = direction[flat[sel]] @ s.normal > 0
        out.prim_id[r, c] = texel
        out.front_facing[r, c] = facing
        out.barycentric[r, c] = 0.0
        flat = np.flatnonzero(cap_mask)
    which_surface = (out.object_id.reshape(-1)[flat] - n_solids) % n_surf
    col, nrm = capping.shade_caps(out.cap_points, which_surface, surfaces, view=view,
                                  style=style, color=color, hatch_spacing=spacing,
                                  frequency=freq, occlusion_radius=occlusion_radius)
    out.color.reshape(-1, 3)[flat] = col
    out.normal.reshape(-1, 3)[flat] = nrm
    return out
