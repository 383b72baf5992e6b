"""Cutaway-function maximisation over an image: jump flooding, brute force and chamfer.

These are the space-agnostic kernels of Burns & Finkelstein's cutaway surface (MATH.md §4.1):

    D(x) = max_s C_s(x),   C_s(x) = z(s) − m(s, x) · ‖x − s‖            (Eq. 2 as corrected, D-C1)

``z`` is the seed depth (``-inf`` marks a pixel that is not a seed), ``m`` the seed's slope in depth
units per distance unit, and ``‖x − s‖`` the distance between pixel centres scaled by ``sampling``
(row spacing, column spacing), as in :func:`scipy.ndimage.distance_transform_edt`. With the
directional (floor) constraint (Sec. 5.5, D-C7) the slope depends on the direction from the seed
to the query pixel:

    m(s, x) = (1 − α) · m_e(s) + α · m_f(s),   α = clamp01(−d̂ · n̂_proj(s)),   d̂ = (x − s)/‖x − s‖

where d̂ and n̂_proj are screen directions with x to the right and y **up** (rows grow downward,
so the row offset enters with a minus sign), and α = 0 at x = s.

Tie rule (all three functions): among seeds with equal C_s(x) the seed with the smaller row-major
flat index ``row · W + col`` wins. The rule does not depend on the order in which candidates are
visited, so :func:`exact` and the jump-flood variants pick the same seed whenever they find the
same maximum, and every pass is bit-identical for any thread count.
"""

from __future__ import annotations

import numbers

import numpy as np
from numba import njit, prange

from .._config import JIT, PJIT
from .._validate import as_choice, as_float_array, MAX_PIXELS

__all__ = ["jump_flood", "exact", "chamfer", "VARIANTS"]

#: Jump-flood step schedules (D-C5). ``n`` is the next power of two ≥ max(H, W); the plain
#: schedule is n/2, …, 1 (Rong & Tan 2006); "+1"/"+2" append extra small steps, "1+" prepends one.
VARIANTS = ("jfa", "jfa+1", "jfa+2", "1+jfa")

#: Borgefors' (1986) optimal integer weights of the 5×5 chamfer mask for unit steps
#: (edge, diagonal, knight move) = (5, 7, 11), divided by 5 to be in pixel units.
BORGEFORS_5X5 = (1.0, 7.0 / 5.0, 11.0 / 5.0)


def step_schedule(height, width, variant):
    """The jump lengths k of one jump-flood run, in order (D-C5)."""
    n = 1
    while n < max(height, width):
        n *= 2
    plain = []
    k = n // 2
    while k >= 1:
        plain.append(k)
        k //= 2
    if not plain:  # a 1×1 image: the seed (if any) is already the answer
        plain = [1]
    return {"jfa": plain, "jfa+1": plain + [1], "jfa+2": plain + [2, 1],
            "1+jfa": [1] + plain}[variant]


# ------------------------------------------------------------------------------------------------
# kernels


#: Columns of the per-seed record table: pixel row and column, depth z(s), slope m_e(s), floor
#: slope m_f(s), projected floor normal (x, y up). One record per pixel, indexed by the row-major
#: flat index, so a candidate's seed is one gather.
_ROW, _COL, _Z, _ME, _MF, _NX, _NY = range(7)
#: Eight columns (one unused) make a record exactly one 64-byte cache line.
_RECORD = 8


@njit(**JIT)
def _cutaway_function(i, j, s, seeds, sy, sx, directional):
    """C_s(x) for the seed with flat index s at the query pixel x = (i, j)."""
    dy = (i - seeds[s, _ROW]) * sy
    dx = (j - seeds[s, _COL]) * sx
    d = np.sqrt(dy * dy + dx * dx)
    if d == 0.0:
        return seeds[s, _Z]
    m = seeds[s, _ME]
    if directional:
        # screen direction with y up: the row offset changes sign
        a = -(dx * seeds[s, _NX] - dy * seeds[s, _NY]) / d
        if a > 0.0:
            a = min(a, 1.0)
            m = (1.0 - a) * m + a * seeds[s, _MF]
    return seeds[s, _Z] - m * d


@njit(**PJIT)
def _jump_flood_pass(src, dst, k, seeds, sy, sx, directional):
    """One jump-flood pass with step k: read the seeds held by the 9 candidates p + k·{−1,0,1}²
    from ``src`` and write each pixel's best seed to ``dst`` (ping-pong: no pixel reads a value
    written in the same pass, so rows are independent)."""
    h, w = src.shape
    for i in prange(h):
        for j in range(w):
            # the pixel's own seed first: most neighbours share it and are then skipped
            best = src[i, j]
            best_c = -np.inf
            if best >= 0:
                best_c = _cutaway_function(i, j, best, seeds, sy, sx, directional)
            for oi in range(-1, 2):
                qi = i + oi * k
                if qi < 0 or qi >= h:
                    continue
                for oj in range(-1, 2):
                    qj = j + oj * k
                    if qj < 0 or qj >= w:
                        continue
                    s = src[qi, qj]
                    # C_s ≤ z(s) since m ≥ 0: a seed lying below the best value cannot win
                    if s < 0 or s == best or seeds[s, _Z] < best_c:
                        continue
                    c = _cutaway_function(i, j, s, seeds, sy, sx, directional)
                    if c > best_c or (c == best_c and s < best):
                        best_c = c
                        best = s
            dst[i, j] = best


@njit(**PJIT)
def _evaluate(seed, out, seeds, sy, sx, directional):
    h, w = seed.shape
    for i in prange(h):
        for j in range(w):
            if seed[i, j] >= 0:
                out[i, j] = _cutaway_function(i, j, seed[i, j], seeds, sy, sx, directional)


@njit(**PJIT)
def _exact(seed_list, seed, out, seeds, sy, sx, directional):
    """Brute force: every pixel tries every seed (listed in row-major order, so the first strict
    maximum is also the smallest flat index among ties)."""
    h, w = seed.shape
    for i in prange(h):
        for j in range(w):
            best_c = -np.inf
            best = -1
            for t in range(seed_list.shape[0]):
                c = _cutaway_function(i, j, seed_list[t], seeds, sy, sx, directional)
                if c > best_c:
                    best_c = c
                    best = seed_list[t]
            out[i, j] = best_c
            seed[i, j] = best


@njit(**JIT)
def _chamfer(z, slope, out, seed, offsets, weights):
    """Two raster scans (forward, then backward) of the 5×5 chamfer mask, carrying each value's
    seed so that its own slope applies (Borgefors 1986; Viola et al. 2004 scale the mask by m)."""
    h, w = z.shape
    for i in range(h):
        for j in range(w):
            if z[i, j] > -np.inf:
                out[i, j] = z[i, j]
                seed[i, j] = i * w + j
    for direction in (1, -1):
        for ii in range(h):
            i = ii if direction == 1 else h - 1 - ii
            for jj in range(w):
                j = jj if direction == 1 else w - 1 - jj
                best_c = out[i, j]
                best = seed[i, j]
                for t in range(offsets.shape[0]):
                    qi = i + direction * offsets[t, 0]
                    qj = j + direction * offsets[t, 1]
                    if qi < 0 or qi >= h or qj < 0 or qj >= w:
                        continue
                    s = seed[qi, qj]
                    if s < 0:
                        continue
                    c = out[qi, qj] - slope[s // w, s % w] * weights[t]
                    if c > best_c or (c == best_c and s < best):
                        best_c = c
                        best = s
                out[i, j] = best_c
                seed[i, j] = best


# ------------------------------------------------------------------------------------------------
# validation shared by the wrappers


def _as_sampling(sampling):
    if isinstance(sampling, numbers.Real) and not isinstance(sampling, bool):
        sampling = (sampling, sampling)
    s = as_float_array(sampling, "sampling", shape=(2,))
    if not np.all(s > 0):
        raise ValueError(f"sampling must be positive, got {tuple(s)}")
    return float(s[0]), float(s[1])


def _as_seed_depth(seed_depth):
    z = as_float_array(seed_depth, "seed_depth", shape=(None, None), finite=False)
    if z.shape[0] == 0 or z.shape[1] == 0:
        raise ValueError(f"seed_depth must not be empty, got shape {z.shape}")
    if z.size > MAX_PIXELS:
        raise ValueError(f"seed_depth has {z.size} pixels, more than the supported {MAX_PIXELS}")
    if np.isnan(z).any():
        raise ValueError(f"seed_depth contains {int(np.isnan(z).sum())} NaN value(s); "
                         "mark non-seeds with -inf")
    if (z == np.inf).any():
        raise ValueError("seed_depth contains +inf; mark non-seeds with -inf")
    return z


def _as_slope(slope, shape, name):
    if isinstance(slope, numbers.Real) and not isinstance(slope, bool):
        slope = np.full(shape, float(slope))
    s = as_float_array(slope, name, finite=False)
    if s.ndim == 0:
        s = np.full(shape, float(s))
    if s.shape != shape:
        raise ValueError(f"{name} must be a scalar or have the shape of seed_depth {shape}, "
                         f"got {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{name} contains {int((~np.isfinite(s)).sum())} non-finite value(s)")
    if (s < 0).any():
        raise ValueError(f"{name} must be non-negative (a cone opening toward the viewer), "
                         f"got min {s.min()}")
    return s


def _prepare(seed_depth, slope, sampling, floor_slope, floor_normal):
    z = _as_seed_depth(seed_depth)
    slope_e = _as_slope(slope, z.shape, "slope")
    sy, sx = _as_sampling(sampling)
    if (floor_slope is None) != (floor_normal is None):
        raise ValueError("floor_slope and floor_normal must be given together")
    directional = floor_slope is not None
    if directional:
        slope_f = _as_slope(floor_slope, z.shape, "floor_slope")
        n_proj = as_float_array(floor_normal, "floor_normal", shape=z.shape + (2,))
    else:
        slope_f = slope_e
        n_proj = np.zeros(z.shape + (2,))
    seeds = np.zeros((z.size, _RECORD))
    rows, cols = np.indices(z.shape)
    for col, values in ((_ROW, rows), (_COL, cols), (_Z, z), (_ME, slope_e), (_MF, slope_f),
                        (_NX, n_proj[..., 0]), (_NY, n_proj[..., 1])):
        seeds[:, col] = values.ravel()
    return z, seeds, sy, sx, directional


def _result(out, seed, return_seeds):
    if not return_seeds:
        return out
    w = seed.shape[1]
    flat = seed.astype(np.int64)
    rc = np.stack([flat // w, flat % w], axis=-1)
    rc[flat < 0] = -1
    return out, rc


_DOC_COMMON = """
    seed_depth : (H, W) float
        Depth z(s) of each seed; ``-inf`` marks a pixel that is not a seed. NaN and ``+inf``
        are rejected.
    slope : float or (H, W) float
        Each seed's slope m(s) ≥ 0, in depth units per unit of distance (see ``sampling``).
    sampling : float or (2,) float, optional
        Distance between pixel centres along rows and columns (row spacing, column spacing), as
        in ``scipy.ndimage.distance_transform_edt``. Default 1 (distances in pixels).
    floor_slope : (H, W) float, optional
        m_f(s), the slope toward the floor side (directional constraint, Sec. 5.5, D-C7).
    floor_normal : (H, W, 2) float, optional
        n̂_proj(s), the projected floor normal at each seed as a screen direction (x right, y up).
    return_seeds : bool
        Also return the winning seed's (row, column) per pixel, ``-1`` where there is none.

    Returns
    -------
    D : (H, W) float64
        The cutaway function's maximum; ``-inf`` where no seed exists.
    seeds : (H, W, 2) int64
        Only with ``return_seeds=True``."""


def jump_flood(seed_depth, slope, *, variant="jfa", sampling=1.0, floor_slope=None,
               floor_normal=None, return_seeds=False):
    """Approximate D(x) = max_s [z(s) − m(s)‖x − s‖] by jump flooding.

    Parameters
    ----------""" + _DOC_COMMON + """

    Other Parameters
    ----------------
    variant : {"jfa", "jfa+1", "jfa+2", "1+jfa"}
        Step schedule: n/2, …, 1 (``"jfa"``), followed by one more k = 1 pass (``"jfa+1"``), by
        k = 2, 1 (``"jfa+2"``), or preceded by a k = 1 pass (``"1+jfa"``); n is the next power of
        two ≥ max(H, W).

    Notes
    -----
    Burns & Finkelstein 2008, Sec. 5.1, with MATH.md D-C1 (the anchor depth belongs to the seed)
    and D-C5 (9 candidates p + k·{−1, 0, 1}², each pixel stores a *seed* and evaluates that
    seed's C at itself). Each pass reads one seed buffer and writes another (ping-pong), rows in
    parallel, so the result does not depend on the thread count. Ties go to the seed with the
    smaller row-major index. Jump flooding is not exact: compare with :func:`exact`.
    """
    z, seeds, sy, sx, directional = _prepare(seed_depth, slope, sampling, floor_slope,
                                             floor_normal)
    variant = as_choice(variant, "variant", VARIANTS)
    h, w = z.shape
    flat = np.arange(h * w, dtype=np.int32).reshape(h, w)
    src = np.where(z > -np.inf, flat, -1).astype(np.int32)
    dst = np.full_like(src, -1)
    for k in step_schedule(h, w, variant):
        _jump_flood_pass(src, dst, k, seeds, sy, sx, directional)
        src, dst = dst, src
    out = np.full(z.shape, -np.inf)
    _evaluate(src, out, seeds, sy, sx, directional)
    return _result(out, src, return_seeds)


def exact(seed_depth, slope, *, sampling=1.0, floor_slope=None, floor_normal=None,
          return_seeds=False):
    """D(x) = max_s [z(s) − m(s)‖x − s‖] by brute force over all seeds, O(H·W·seeds).

    Parameters
    ----------""" + _DOC_COMMON + """

    Notes
    -----
    The reference for :func:`jump_flood` and :func:`chamfer` (MATH.md D-C5: "test against brute
    force"). It evaluates C with the very same kernel, so where a jump-flood variant finds the
    optimal seed the two agree bit for bit. Ties go to the smaller row-major seed index.
    """
    z, seeds, sy, sx, directional = _prepare(seed_depth, slope, sampling, floor_slope,
                                             floor_normal)
    seed_list = np.flatnonzero(z > -np.inf).astype(np.int32)
    seed = np.full(z.shape, -1, dtype=np.int32)
    out = np.full(z.shape, -np.inf)
    _exact(seed_list, seed, out, seeds, sy, sx, directional)
    return _result(out, seed, return_seeds)


def chamfer(seed_depth, slope, *, sampling=1.0, return_seeds=False):
    """Approximate D(x) with the 5×5 Borgefors chamfer transform scaled by each seed's slope.

    Parameters
    ----------
    seed_depth, slope, sampling, return_seeds
        As in :func:`jump_flood` (no directional constraint: the paper compares the chamfer with
        the basic cutaway only).

    Returns
    -------
    D : (H, W) float64, and seeds (H, W, 2) int64 with ``return_seeds=True``.

    Notes
    -----
    The approximation Viola et al. (2004) used and Burns & Finkelstein (Sec. 3.1, Table 1)
    compare against: a forward and a backward raster scan of the 5×5 mask with Borgefors' weights
    (5, 7, 11)/5 for the edge, diagonal and knight steps. With anisotropic ``sampling`` each step's
    weight is its Euclidean length times Borgefors' ratio weight/‖step‖, which reduces to
    (5, 7, 11)/5 · spacing for square pixels. Each value carries its seed, and the step cost uses
    that seed's slope. Sequential by nature (each pixel reads values written in the same scan).
    """
    z = _as_seed_depth(seed_depth)
    slope_e = _as_slope(slope, z.shape, "slope")
    sy, sx = _as_sampling(sampling)
    offsets, weights = [], []
    # the causal half of the 5×5 mask for a top-left → bottom-right scan
    for di, dj in [(-2, -1), (-2, 1), (-1, -2), (-1, -1), (-1, 0), (-1, 1), (-1, 2), (0, -1)]:
        steps = abs(di) + abs(dj)
        ratio = BORGEFORS_5X5[min(steps, 3) - 1] / np.hypot(di, dj)
        offsets.append((di, dj))
        weights.append(np.hypot(di * sy, dj * sx) * ratio)
    out = np.full(z.shape, -np.inf)
    seed = np.full(z.shape, -1, dtype=np.int32)
    _chamfer(z, slope_e, out, seed, np.array(offsets, dtype=np.int64), np.array(weights))
    return _result(out, seed, return_seeds)
