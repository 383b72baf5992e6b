"""The discontinuity operators of edge enhancement (Nienhaus & Döllner, WSCG 2003, Sec. 4.1.2):
pass 2 of the edge pipeline, on the G-buffer of :mod:`refraster.edges.gbuffer`.

:func:`diagonal_normal`, :func:`diagonal_depth`, :func:`c1_depth`, :func:`sobel`,
:func:`sobel_depth`, :func:`sobel_normal`, :func:`object_id_edges`; :func:`edge_map` runs the
chosen ones in one fused pass (inner-edge strength in RGB, profile-edge strength in A).

Every filter returns an edge *strength* ``E ∈ [0, 1]`` with 0 = no edge (MATH.md §3.2); the
paper's printed operators have the opposite polarity for the diagonal variants (MATH.md §3.1).
Borders are clamp-to-edge, as texture sampling with ``GL_CLAMP_TO_EDGE``. Neighbourhood names
follow the paper's Fig. 2, with row 0 at the top of the image::

    A B C
    D X E
    F G H

Filters compute in float64 and return float32 (the raw :func:`sobel` keeps float64 unless
given float32). Their kernels run in parallel over rows; each
row writes only its own output, so the result does not depend on the number of threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import JIT, PJIT
from .._validate import as_choice, as_float_array, as_real, check_shape
from .gbuffer import EdgeGBuffer, edge_gbuffer

__all__ = [
    "diagonal_normal", "diagonal_depth", "c1_depth", "sobel", "sobel_depth", "sobel_normal",
    "object_id_edges", "edge_map", "EDGE_PRESETS", "DEFAULT_INNER_THRESHOLD",
    "DEFAULT_PROFILE_THRESHOLD",
]

#: Inner-edge strengths below this are set to 0 by :func:`edge_map` with ``preset="clean"``.
#: A crease of θ gives ``E_N = 1 − cos θ``, so this is a crease of about 26°: flat-shaded
#: facets of tessellated curved surfaces (a few degrees apart) stay clean, creases show.
DEFAULT_INNER_THRESHOLD = 0.1
#: Profile-edge strengths below this are set to 0 by :func:`edge_map` with ``preset="clean"``,
#: tuned for that preset's depth filter ("diagonal2"): a depth step of 1.5 % of the near–far
#: range passes. At it the image-space profile is compared with projected silhouettes in
#: ``tests/test_edges.py``.
DEFAULT_PROFILE_THRESHOLD = 0.03
#: The defaults of :func:`edge_map`'s filter options. ``"paper"`` is Nienhaus & Döllner's
#: operator (Sec. 4.1.2, first variant; Sec. 5 blends with the raw intensities); ``"clean"``
#: is this project's combination (MATH.md §3.2 conventions + docs/edges.md D-E3, id edges,
#: thresholds), the default of :func:`edge_map` until 2026-12-01.
EDGE_PRESETS = {
    "paper": dict(normal_filter="diagonal", depth_filter="diagonal", ids=False,
                  inner_threshold=0.0, profile_threshold=0.0),
    "clean": dict(normal_filter="diagonal", depth_filter="diagonal2", ids=True,
                  inner_threshold=DEFAULT_INNER_THRESHOLD,
                  profile_threshold=DEFAULT_PROFILE_THRESHOLD),
}

_DEPTH_FILTERS = {"diagonal": 0, "c1": 1, "c1-paper": 2, "sobel": 3, "diagonal2": 4}
_NORMAL_FILTERS = {"diagonal": 0, "sobel": 1, "angle": 2}
_C1_SCALES = {"normalized": 12.0, "paper": 8.0}


# ------------------------------------------------------------------------------------------
# Per-pixel operators (shared by the single-filter kernels and the fused edge map, so both give
# the same bits)


@njit(**JIT)
def _nb(y, x, h, w):
    """Clamp-to-edge neighbour rows and columns: (y−1, y+1, x−1, x+1)."""
    return max(y - 1, 0), min(y + 1, h - 1), max(x - 1, 0), min(x + 1, w - 1)


@njit(**JIT)
def _n(a, y, x, c, encoded):
    v = np.float64(a[y, x, c])
    if encoded:
        return 2.0 * v - 1.0
    return v


@njit(**JIT)
def _dot(a, y0, x0, y1, x1, encoded):
    c0, c1, c2 = np.int64(0), np.int64(1), np.int64(2)  # not literals: one _n for every caller
    return (_n(a, y0, x0, c0, encoded) * _n(a, y1, x1, c0, encoded)
            + _n(a, y0, x0, c1, encoded) * _n(a, y1, x1, c1, encoded)) \
        + _n(a, y0, x0, c2, encoded) * _n(a, y1, x1, c2, encoded)


@njit(**JIT)
def _diagonal_normal_at(n, y, x, h, w, encoded):
    ym, yp, xm, xp = _nb(y, x, h, w)
    i_n = 0.5 * (_dot(n, ym, xm, yp, xp, encoded) + _dot(n, ym, xp, yp, xm, encoded))
    return 1.0 - min(max(i_n, 0.0), 1.0)


@njit(**JIT)
def _diagonal_depth_at(z, y, x, h, w, order):
    ym, yp, xm, xp = _nb(y, x, h, w)
    if order == 1:
        d_ah = np.float64(z[ym, xm]) - np.float64(z[yp, xp])
        d_cf = np.float64(z[ym, xp]) - np.float64(z[yp, xm])
    else:
        zx2 = 2.0 * np.float64(z[y, x])
        d_ah = (np.float64(z[ym, xm]) + np.float64(z[yp, xp])) - zx2
        d_cf = (np.float64(z[ym, xp]) + np.float64(z[yp, xm])) - zx2
    a = 1.0 - 0.5 * abs(d_ah)
    b = 1.0 - 0.5 * abs(d_cf)
    return 1.0 - (a * a) * (b * b)


@njit(**JIT)
def _c1_depth_at(z, y, x, h, w, divisor):
    ym, yp, xm, xp = _nb(y, x, h, w)
    zx = np.float64(z[y, x])
    s = abs(np.float64(z[ym, xm]) - zx) + 2.0 * abs(np.float64(z[ym, x]) - zx)
    s += abs(np.float64(z[ym, xp]) - zx) + 2.0 * abs(np.float64(z[y, xm]) - zx)
    s += 2.0 * abs(np.float64(z[y, xp]) - zx) + abs(np.float64(z[yp, xm]) - zx)
    s += 2.0 * abs(np.float64(z[yp, x]) - zx) + abs(np.float64(z[yp, xp]) - zx)
    return min(s / divisor, 1.0)


@njit(**JIT)
def _sobel_at(a, y, x, h, w):
    """(G_y, G_x) of a 2D array: derivatives along axis 0 and axis 1, as scipy.ndimage.sobel."""
    ym, yp, xm, xp = _nb(y, x, h, w)
    za, zb, zc = np.float64(a[ym, xm]), np.float64(a[ym, x]), np.float64(a[ym, xp])
    zd, ze = np.float64(a[y, xm]), np.float64(a[y, xp])
    zf, zg, zh = np.float64(a[yp, xm]), np.float64(a[yp, x]), np.float64(a[yp, xp])
    gy = (zf + 2.0 * zg + zh) - (za + 2.0 * zb + zc)
    gx = (zc + 2.0 * ze + zh) - (za + 2.0 * zd + zf)
    return gy, gx


@njit(**JIT)
def _sobel_normal_at(n, y, x, h, w, encoded, k_n):
    ym, yp, xm, xp = _nb(y, x, h, w)
    s = 0.0
    for c in range(3):
        na, nb_, nc = _n(n, ym, xm, c, encoded), _n(n, ym, x, c, encoded), _n(n, ym, xp, c, encoded)
        nd, ne = _n(n, y, xm, c, encoded), _n(n, y, xp, c, encoded)
        nf, ng, nh = _n(n, yp, xm, c, encoded), _n(n, yp, x, c, encoded), _n(n, yp, xp, c, encoded)
        gy = (nf + 2.0 * ng + nh) - (na + 2.0 * nb_ + nc)
        gx = (nc + 2.0 * ne + nh) - (na + 2.0 * nd + nf)
        s += gy * gy + gx * gx
    return min(k_n * np.sqrt(s) / 8.0, 1.0)


@njit(**JIT)
def _angle_normal_at(n, y, x, h, w, encoded):
    best = 0.0
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            if dy == 0 and dx == 0:
                continue
            yy = min(max(y + dy, 0), h - 1)
            xx = min(max(x + dx, 0), w - 1)
            e = 0.5 * (1.0 - _dot(n, y, x, yy, xx, encoded))
            if e > best:
                best = e
    return min(best, 1.0)


@njit(**JIT)
def _id_edge_at(ids, y, x, h, w):
    own = ids[y, x]
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            if ids[min(max(y + dy, 0), h - 1), min(max(x + dx, 0), w - 1)] != own:
                return 1.0
    return 0.0


@njit(**JIT)
def _depth_edge_at(z, y, x, h, w, method, k_z):
    if method == 0 or method == 4:
        # the order as a variable, not a literal: one _diagonal_depth_at for both orders
        return _diagonal_depth_at(z, y, x, h, w, np.int64(1) if method == 0 else np.int64(2))
    if method == 1:
        return _c1_depth_at(z, y, x, h, w, 12.0)
    if method == 2:
        return _c1_depth_at(z, y, x, h, w, 8.0)
    gy, gx = _sobel_at(z, y, x, h, w)
    return min(k_z * np.sqrt(gy * gy + gx * gx) / 4.0, 1.0)


@njit(**JIT)
def _normal_edge_at(n, y, x, h, w, method, encoded, k_n):
    if method == 0:
        return _diagonal_normal_at(n, y, x, h, w, encoded)
    if method == 1:
        return _sobel_normal_at(n, y, x, h, w, encoded, k_n)
    return _angle_normal_at(n, y, x, h, w, encoded)


# ------------------------------------------------------------------------------------------
# Kernels: one output row per iteration


@njit(**PJIT)
def _normal_kernel(n, method, encoded, k_n, out):
    h, w = out.shape
    for yu in prange(h):
        y = np.int64(yu)
        for x in range(w):
            out[y, x] = _normal_edge_at(n, y, x, h, w, method, encoded, k_n)


@njit(**PJIT)
def _depth_kernel(z, method, k_z, out):
    h, w = out.shape
    for yu in prange(h):
        y = np.int64(yu)
        for x in range(w):
            out[y, x] = _depth_edge_at(z, y, x, h, w, method, k_z)


@njit(**PJIT)
def _sobel_kernel(a, axis, out):
    h, w = out.shape
    for yu in prange(h):
        y = np.int64(yu)
        for x in range(w):
            gy, gx = _sobel_at(a, y, x, h, w)
            if axis == 0:
                out[y, x] = gy
            elif axis == 1:
                out[y, x] = gx
            else:
                out[y, x] = np.sqrt(gy * gy + gx * gx)


@njit(**PJIT)
def _id_kernel(ids, out):
    h, w = out.shape
    for yu in prange(h):
        y = np.int64(yu)
        for x in range(w):
            out[y, x] = _id_edge_at(ids, y, x, h, w)


@njit(**PJIT)
def _edge_map_kernel(n, z, ids, use_ids, nmethod, zmethod, encoded, k_n, k_z, t_inner,
                     t_profile, out):
    h, w = z.shape
    for yu in prange(h):
        y = np.int64(yu)
        for x in range(w):
            e_n = np.float32(0.0)
            if ids[y, x] >= 0:
                e_n = np.float32(_normal_edge_at(n, y, x, h, w, nmethod, encoded, k_n))
            e_z = np.float32(_depth_edge_at(z, y, x, h, w, zmethod, k_z))
            if e_n < t_inner:
                e_n = np.float32(0.0)
            if e_z < t_profile:
                e_z = np.float32(0.0)
            if use_ids and _id_edge_at(ids, y, x, h, w) > 0.0:
                e_z = np.float32(1.0)
            out[y, x, 0] = e_n
            out[y, x, 1] = e_n
            out[y, x, 2] = e_n
            out[y, x, 3] = e_z


# ------------------------------------------------------------------------------------------
# Public filters


def _buffer(value, name, shape):
    """Float32 buffers stay float32 (no copy for the G-buffer); anything else becomes float64."""
    dt = np.float32 if getattr(value, "dtype", None) == np.float32 else np.float64
    arr = as_float_array(value, name, dtype=dt)
    check_shape(arr, name, shape)
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    return arr


def _ids(value, name="ids"):
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be an integer array, got {type(value).__name__}")
    arr = np.asarray(value)
    if not np.issubdtype(arr.dtype, np.integer):
        raise TypeError(f"{name} must be an integer array, got dtype {arr.dtype}")
    check_shape(arr, name, (None, None))
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    return np.ascontiguousarray(arr, np.int64 if arr.dtype.itemsize > 4 else np.int32)


def _encoded_flag(encoded):
    if not isinstance(encoded, (bool, np.bool_)):
        raise TypeError(f"encoded must be a bool, got {type(encoded).__name__}")
    return bool(encoded)


def diagonal_normal(normal, *, encoded=False):
    """Normal discontinuities by the paper's diagonal operator (the first variant).

    Parameters
    ----------
    normal : (H, W, 3) float
        Eye-space normals (unit; 0 in the background), or the encoded G-buffer ``0.5·n + 0.5``
        with ``encoded=True`` (expanded as ``2c − 1``, the paper's ``expand``).
    encoded : bool

    Returns
    -------
    (H, W) float32
        Inner-edge strength ``E_N = 1 − clamp(½(n_A·n_H + n_C·n_F), 0, 1)``.

    Notes
    -----
    Nienhaus & Döllner Sec. 4.1.2, operator ``I_N``; MATH.md §3.1 (it is a cosine, 1 = no edge)
    and §3.2 (``E_N``, negative cosines clamped as register combiners did). The centre X is not
    read: the response of an edge between two pixel columns covers both columns::

        A . C
        . X .
        F . H
    """
    enc = _encoded_flag(encoded)
    n = _buffer(normal, "normal", (None, None, 3))
    out = np.zeros(n.shape[:2], np.float32)
    _normal_kernel(n, 0, enc, 1.0, out)
    return out


def diagonal_depth(depth, *, order=1):
    """Depth discontinuities by the paper's diagonal operator (the first variant).

    Parameters
    ----------
    depth : (H, W) float
        Normalized linear depth in [0, 1] (:func:`edge_gbuffer`).
    order : {1, 2}
        1: the paper's first differences ``d_AH = z_A − z_H``, ``d_CF = z_C − z_F``.
        2: second differences through the centre, ``d_AH = z_A + z_H − 2 z_X`` and
        ``d_CF = z_C + z_F − 2 z_X`` [guess, ours]: the same response to a step, but 0 on a
        depth ramp, so planes and curved surfaces seen at grazing angles no longer light up.

    Returns
    -------
    (H, W) float32
        Profile-edge strength ``E_Z = 1 − (1 − ½|d_AH|)² · (1 − ½|d_CF|)²``.

    Notes
    -----
    Nienhaus & Döllner Sec. 4.1.2, operator ``I_Z``; MATH.md §3.2 ``E_Z^dg = 1 − I_Z``. A step
    of Δ between two columns gives ``1 − (1 − Δ/2)⁴`` on both columns beside it, with either
    order. With ``order=1`` a surface whose depth changes by s per pixel already gives about
    ``4s``; near silhouettes and on grazing planes that exceeds any useful threshold, which is
    why :func:`edge_map`'s ``"clean"`` preset uses ``order=2`` (``depth_filter="diagonal2"``);
    the paper's operator (and :func:`edge_map`'s default) is ``order=1``.
    """
    if isinstance(order, bool) or order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    z = _buffer(depth, "depth", (None, None))
    out = np.zeros(z.shape, np.float32)
    _depth_kernel(z, 0 if order == 1 else 4, 1.0, out)
    return out


def c1_depth(depth, *, scale="normalized"):
    """Depth discontinuities by the 8-neighbour C1 operator (the paper's second variant).

    Parameters
    ----------
    depth : (H, W) float
        Normalized linear depth in [0, 1].
    scale : {"normalized", "paper"}
        Divide the weighted sum by 12 (its weights' sum: a unit step all round gives 1) or by 8
        as printed.

    Returns
    -------
    (H, W) float32
        ``E_Z^C1 = min(1, (1/s) Σ_k w_k |z_k − z_X|)``, ``w = (1, 2, 1, 2, 2, 1, 2, 1)`` for
        ``A … H``, ``s`` = 12 or 8.

    Notes
    -----
    Nienhaus & Döllner Sec. 4.1.2 (after Saito–Takahashi and Decaudin); MATH.md §3.1 (the
    printed 1/8 lets the value reach 1.5; the P-buffer clamped it) and §3.2.
    """
    divisor = as_choice(scale, "scale", _C1_SCALES)
    z = _buffer(depth, "depth", (None, None))
    out = np.zeros(z.shape, np.float32)
    _depth_kernel(z, 1 if divisor == 12.0 else 2, 1.0, out)
    return out


def sobel(image, *, axis=None):
    """Sobel gradient of one channel, clamp-to-edge borders.

    Parameters
    ----------
    image : (H, W) float
    axis : {None, 0, 1}
        ``0``: the derivative along axis 0 (down the rows), ``(F + 2G + H) − (A + 2B + C)``,
        equal to ``scipy.ndimage.sobel(image, 0, mode="nearest")``; ``1``: along axis 1,
        ``(C + 2E + H) − (A + 2D + F)``; None: the magnitude ``sqrt(G_0² + G_1²)``.

    Returns
    -------
    (H, W) float32 for a float32 image, float64 otherwise
        Unscaled (a unit step gives a magnitude of 4). ``skimage.filters.sobel`` divides each
        derivative by 4 and the magnitude by ``sqrt(2)``; its default "reflect" border equals
        clamp-to-edge for a 3×3 kernel.

    Notes
    -----
    MATH.md §3.3 (``G_y`` = axis 0, ``G_x`` = axis 1). :func:`sobel_depth` and
    :func:`sobel_normal` turn it into edge strengths.
    """
    if axis is not None and (isinstance(axis, bool) or axis not in (0, 1)):
        raise ValueError(f"axis must be None, 0 or 1, got {axis!r}")
    a = _buffer(image, "image", (None, None))
    out = np.zeros(a.shape, a.dtype)
    _sobel_kernel(a, -1 if axis is None else int(axis), out)
    return out


def _gain(value, name):
    return as_real(value, name, lo=0.0)


def sobel_depth(depth, *, k_z=1.0):
    """Profile-edge strength from the Sobel gradient of depth.

    Parameters
    ----------
    depth : (H, W) float
    k_z : float, >= 0
        Gain.

    Returns
    -------
    (H, W) float32
        ``E_Z = min(1, k_z · |∇z| / 4)`` (a unit step gives ``k_z``).

    Notes
    -----
    MATH.md §3.3.
    """
    k = _gain(k_z, "k_z")
    z = _buffer(depth, "depth", (None, None))
    out = np.zeros(z.shape, np.float32)
    _depth_kernel(z, 3, k, out)
    return out


def sobel_normal(normal, *, form="channels", k_n=1.0, encoded=False):
    """Inner-edge strength from the normal buffer by Sobel per channel, or by angle.

    Parameters
    ----------
    normal : (H, W, 3) float
        Eye-space normals, or encoded ones with ``encoded=True``.
    form : {"channels", "angle"}
        ``"channels"``: ``E_N = min(1, k_n · sqrt(Σ_c G_0,c² + G_1,c²) / 8)`` (components lie in
        [−1, 1], so a step is at most 2 and gives 8). ``"angle"``:
        ``E_N = max_q (1 − n_X·n_q) / 2`` over the eight neighbours q.
    k_n : float, >= 0
        Gain of the channel form (ignored by the angle form).
    encoded : bool

    Returns
    -------
    (H, W) float32

    Notes
    -----
    MATH.md §3.3.
    """
    method = as_choice(form, "form", {"channels": 1, "angle": 2})
    k = _gain(k_n, "k_n")
    enc = _encoded_flag(encoded)
    n = _buffer(normal, "normal", (None, None, 3))
    out = np.zeros(n.shape[:2], np.float32)
    _normal_kernel(n, method, enc, k, out)
    return out


def object_id_edges(ids):
    """Id-buffer discontinuities: 1 where any of the eight neighbours has another id.

    Parameters
    ----------
    ids : (H, W) int
        Object (or primitive) ids; the background's −1 is an id like any other.

    Returns
    -------
    (H, W) float32
        0 or 1. A boundary between two columns marks both columns, like the diagonal depth
        operator.

    Notes
    -----
    The paper relies on depth alone; the id buffer follows Saito–Takahashi's G-buffer and
    Mitchell et al. (the paper's [Mit02a]) and catches profiles whose depth step is too small,
    e.g. an object's far side against the far plane.
    """
    a = _ids(ids)
    out = np.zeros(a.shape, np.float32)
    _id_kernel(a, out)
    return out


def edge_map(fb, *, preset="paper", bounds=None, near=None, far=None, normal_filter=None,
             depth_filter=None, ids=None, inner_threshold=None, profile_threshold=None, width=1,
             k_n=1.0, k_z=1.0):
    """The edge map: inner-edge strength in RGB, profile-edge strength in A.

    With no options this is the paper's operator (Sec. 4.1.2, first variant): the diagonal
    normal operator in RGB, the diagonal depth operator as printed in A, no id edges and no
    thresholds, so the raw (anti-aliased) intensities are the blend weights of Sec. 5.

    Parameters
    ----------
    fb : refraster.Framebuffer or EdgeGBuffer
        A framebuffer is first turned into an :class:`EdgeGBuffer` with ``bounds`` / ``near``
        / ``far`` (see :func:`edge_gbuffer`).
    preset : {"paper", "clean"}
        The defaults of the five options below (:data:`EDGE_PRESETS`). ``"paper"``: diagonal
        normal and depth operators, ``ids=False``, both thresholds 0. ``"clean"`` (ours, the
        default before 2026-12-01): second-order diagonal depth, id edges, thresholds 0.1 and
        0.03: clean outlines on grazing surfaces, hard id edges (docs/edges.md, "Presets").
        An option given explicitly overrides the preset's value.
    bounds, near, far : optional
        Only with a framebuffer.
    normal_filter : {"diagonal", "sobel", "angle"}
        :func:`diagonal_normal` (the paper's), :func:`sobel_normal` channels or angle form.
    depth_filter : {"diagonal", "diagonal2", "c1", "c1-paper", "sobel"}
        :func:`diagonal_depth` as printed (``"diagonal"``, the paper's preferred variant) or
        with second differences (``"diagonal2"``, ``order=2``), :func:`c1_depth` with the
        normalized 1/12 or printed 1/8 scale, :func:`sobel_depth`.
    ids : bool
        Also mark id discontinuities (:func:`object_id_edges`) as profile edges (strength 1).
    inner_threshold, profile_threshold : float in [0, 1]
        Strengths below them become 0 (those above keep their anti-aliased value); 0 keeps
        every raw intensity. :data:`DEFAULT_INNER_THRESHOLD` and
        :data:`DEFAULT_PROFILE_THRESHOLD` are the ``"clean"`` preset's; the strengths of the
        first-order filters grow with the depth slope per pixel and need larger thresholds
        (docs/edges.md).
    width : int >= 1
        Edge width: the thresholded strengths are grey-dilated with a disk of radius
        ``width − 1`` pixels (``skimage.morphology.dilation``); 1 leaves them as filtered.
    k_n, k_z : float >= 0
        Gains of the Sobel filters.

    Returns
    -------
    (H, W, 4) float32
        ``R = G = B = E_N`` (inner / crease edges), ``A = E_Z`` (profile: silhouette and
        border edges), each in [0, 1] with 0 = no edge. ``E_N`` is 0 on background pixels.

    Notes
    -----
    Nienhaus & Döllner Sec. 4.1 (RGB from normals, A from depth) in MATH.md §3.2's convention.
    The filters run in one fused pass and give the same bits as calling them one by one on
    the G-buffer with ``encoded=True`` and thresholding (tested).

    The background's normal is 0 (MATH.md §3.2), so ``E_N`` of a pixel whose diagonal
    neighbours are all background is 1. The paper never sees those values because it projects
    the edge map onto the objects only; an image-space edge map sets them to 0 [guess], so
    that inner edges stay inside the objects. Object pixels on the profile keep their value
    (0.5 or more), under the profile edge.
    """
    if isinstance(fb, EdgeGBuffer):
        if bounds is not None or near is not None or far is not None:
            raise ValueError("bounds/near/far apply to a Framebuffer, not to an EdgeGBuffer")
        gb = fb
    else:
        gb = edge_gbuffer(fb, bounds=bounds, near=near, far=far)
    options = dict(EDGE_PRESETS[as_choice(preset, "preset", {k: k for k in EDGE_PRESETS})])
    for key, value in (("normal_filter", normal_filter), ("depth_filter", depth_filter),
                       ("ids", ids), ("inner_threshold", inner_threshold),
                       ("profile_threshold", profile_threshold)):
        if value is not None:
            options[key] = value
    normal_filter, depth_filter, ids = (options["normal_filter"], options["depth_filter"],
                                        options["ids"])
    inner_threshold = options["inner_threshold"]
    profile_threshold = options["profile_threshold"]
    nmethod = as_choice(normal_filter, "normal_filter", _NORMAL_FILTERS)
    zmethod = as_choice(depth_filter, "depth_filter", _DEPTH_FILTERS)
    if not isinstance(ids, (bool, np.bool_)):
        raise TypeError(f"ids must be a bool, got {type(ids).__name__}")
    t_inner = as_real(inner_threshold, "inner_threshold", lo=0.0, hi=1.0)
    t_profile = as_real(profile_threshold, "profile_threshold", lo=0.0, hi=1.0)
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)):
        raise TypeError(f"width must be an int, got {type(width).__name__}")
    if not 1 <= width <= 64:
        raise ValueError(f"width must be in [1, 64], got {width}")
    kn, kz = _gain(k_n, "k_n"), _gain(k_z, "k_z")
    n = _buffer(gb.normal, "normal", (None, None, 3))
    z = _buffer(gb.depth, "depth", (None, None))
    obj = _ids(gb.object_id, "object_id")
    if n.shape[:2] != z.shape or obj.shape != z.shape:
        raise ValueError(f"G-buffer shapes differ: normal {n.shape}, depth {z.shape}, "
                         f"object_id {obj.shape}")
    out = np.zeros(z.shape + (4,), np.float32)
    _edge_map_kernel(n, z, obj, bool(ids), nmethod, zmethod, True, kn, kz,
                     np.float32(t_inner), np.float32(t_profile), out)
    if width > 1:
        from skimage.morphology import dilation, disk
        foot = disk(width - 1)
        inner = dilation(out[..., 0], foot)
        out[..., 0] = inner
        out[..., 1] = inner
        out[..., 2] = inner
        out[..., 3] = dilation(out[..., 3], foot)
    return out
