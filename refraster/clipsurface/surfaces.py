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
and closes the cuts with cap surfaces (:mod:`refraster.clipsurface.capping`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from .._validate import as_choice, as_float_array, as_matrix, as_real
from .offsetmaps import (WRAP_MODES, as_offset_map, as_wrap, normal_map, occlusion_map,
                         texture2d_flat)
from .textures import CapTextures

__all__ = ["ClipSurface", "ReliefClipPlane", "as_surfaces", "clip_function", "clip_mask",
           "clipped_at"]

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
    offset_map : (H, W) or (W,) array
        OM, heights in [0, 1] in texel order (:mod:`refraster.clipsurface.offsetmaps`): uint8,
        uint16 or float. A 1D map (W,) is a ``texture1D`` along s (Sec. 4.3: "1D, 2D, or 3D
        representations"), stored as the 1×W map it equals.
    wrap : {"repeat", "clamp_to_edge", "mirrored_repeat"}
        The offset map's wrap mode (MATH.md §1.1 takes repeat as the default [guess]).
    enabled : bool
        ``config[3].w`` of Listing 1: a disabled surface clips nothing.
    textures : CapTextures, optional
        The user's diffuse, normal and light maps of the caps (Sec. 4.1's "further
        attributes"), addressed with this surface's ``(s, t)`` and wrap mode
        (:mod:`refraster.clipsurface.textures`).

    Notes
    -----
    D7: U and V must be orthogonal (``|Û·V̂| ≤ 1e-6``); V̂ is then re-orthogonalized against Û
    (Gram–Schmidt) so that N is exactly unit. Parallel or zero vectors raise ``ValueError``.
    """

    def __init__(self, origin, u, v, scale=(1.0, 1.0, 1.0), offset_map=None, *, wrap="repeat",
                 enabled=True, textures=None):
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
        if textures is not None and not isinstance(textures, CapTextures):
            raise TypeError(f"textures must be a CapTextures, got {type(textures).__name__}")
        self.textures = textures
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
                f"enabled={self.enabled}"
                + (f", textures={self.textures!r})" if self.textures is not None else ")"))

    def replace(self, **changes):
        """A copy with some constructor arguments changed (e.g. ``enabled=False``)."""
        args = dict(origin=self.origin, u=self.u, v=self.v, scale=self.scale,
                    offset_map=self.offset_map, wrap=self.wrap, enabled=self.enabled,
                    textures=self.textures)
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
    wrap, enabled, textures
        As for :class:`ClipSurface`.

    Notes
    -----
    MATH.md D8: RCP discards ``N·(X − P) − s·h > 0``, the clip-surface test with
    ``N_CS = −N / |N|``, ``O = P``, ``Sz = s``. :attr:`clip_surface` is that surface, with
    ``Û`` from ``u`` and ``V̂ = N_CS × Û`` (so ``Û × V̂ = N_CS``).
    """

    def __init__(self, normal, point, offset_map, height_scale, u=None, *, extent=1.0,
                 wrap="repeat", enabled=True, textures=None):
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
                                        enabled=enabled, textures=textures)

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
