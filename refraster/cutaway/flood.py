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


#: Columns of the per-seed record table of :func:`exact`: pixel row and column, depth z(s), slope
#: m_e(s), floor slope m_f(s), projected floor normal (x, y up). One record per pixel, indexed by
#: the row-major flat index, so a seed is one gather.
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


@njit(**JIT)
def _offsets(fi, fj, s, w, inv_w, sy, sx):
    """(dy, dx, ‖x − s‖) from the seed with flat index s to the pixel (fi, fj): the very operations
    of :func:`_cutaway_function`. The seed's row comes from its flat index in floating point:
    (s + 0.5)/W lies ≥ 0.5/W from an integer, far more than the rounding error of (s + 0.5)·(1/W)
    for an image of at most MAX_PIXELS pixels, so the floor is exact (and so is col = s − row·W)."""
    f = float(s)
    r = np.floor((f + 0.5) * inv_w)
    dy = (fi - r) * sy
    dx = (fj - (f - r * w)) * sx
    return dy, dx, np.sqrt(dy * dy + dx * dx)


@njit(**JIT)
def _value(fi, fj, s, z, me, w, inv_w, sy, sx):
    """C_s(x) of :func:`_cutaway_function` without the directional term, for the seed with flat
    index s, depth z and slope m_e at the pixel (fi, fj)."""
    dy, dx, d = _offsets(fi, fj, s, w, inv_w, sy, sx)
    return z if d == 0.0 else z - me * d


@njit(**JIT)
def _value_directional(fi, fj, s, z, me, mf, nx, ny, w, inv_w, sy, sx):
    """C_s(x) of :func:`_cutaway_function` with the directional slope, as selects."""
    dy, dx, d = _offsets(fi, fj, s, w, inv_w, sy, sx)
    # at d = 0 the value is z whatever a is: divide by 1 there (no ZeroDivisionError)
    a = -(dx * nx - dy * ny) / (d if d != 0.0 else 1.0)
    a1 = min(a, 1.0)
    m = (1.0 - a1) * me + a1 * mf if a > 0.0 else me
    return z if d == 0.0 else z - m * d


@njit(**JIT)
def _better(s, c, best, best_c):
    """The tie rule: the candidate seed s with value c beats the best so far if it is a seed and
    its C is larger, or equal with a smaller flat index. A strict order, so the result does not
    depend on the order in which the candidates are visited."""
    return (s >= 0) & ((c > best_c) | ((c == best_c) & (s < best)))


# The row loops below are branch-free (selects only) and touch at most five arrays, few enough
# for LLVM's runtime alias checks, so that it vectorizes them (AVX2/AVX-512, no fastmath needed).

@njit(**JIT)
def _own(fi, lab, values, best, best_c, w, inv_w, sy, sx):
    """Each pixel's own seed is its first best (value −inf where it holds none)."""
    z, me = values[0], values[1]
    if values.shape[0] == 5:
        mf, nx, ny = values[2], values[3], values[4]
        for j in range(lab.shape[0]):
            best_c[j] = _value_directional(fi, float(j), lab[j], z[j], me[j], mf[j], nx[j], ny[j],
                                           w, inv_w, sy, sx)
    else:
        for j in range(lab.shape[0]):
            best_c[j] = _value(fi, float(j), lab[j], z[j], me[j], w, inv_w, sy, sx)
    for j in range(lab.shape[0]):
        best[j] = lab[j]
        best_c[j] = best_c[j] if lab[j] >= 0 else -np.inf


@njit(**JIT)
def _sweep(fi, j0, lab, z, me, best, best_c, w, inv_w, sy, sx):
    """One candidate offset along a row: the seeds ``lab[j]`` (flat index, −1: none) with
    parameters ``z[j]``, ``me[j]`` compete at the pixels (fi, j0 + j)."""
    for j in range(lab.shape[0]):
        s = lab[j]
        c = _value(fi, float(j0 + j), s, z[j], me[j], w, inv_w, sy, sx)
        take = _better(s, c, best[j], best_c[j])
        best_c[j] = c if take else best_c[j]
        best[j] = s if take else best[j]


@njit(**JIT)
def _sweep_directional(fi, j0, lab, values, a, b, c, best, best_c, w, inv_w, sy, sx):
    """:func:`_sweep` with the directional slope, the seeds' parameters being columns a … b − 1
    of ``values``; in two loops (values into the scratch ``c``, then the tie rule), as one loop
    would read too many arrays to be vectorized."""
    z, me, mf = values[0, a:b], values[1, a:b], values[2, a:b]
    nx, ny = values[3, a:b], values[4, a:b]
    for j in range(lab.shape[0]):
        c[j] = _value_directional(fi, float(j0 + j), lab[j], z[j], me[j], mf[j], nx[j], ny[j],
                                  w, inv_w, sy, sx)
    for j in range(lab.shape[0]):
        s = lab[j]
        take = _better(s, c[j], best[j], best_c[j])
        best_c[j] = c[j] if take else best_c[j]
        best[j] = s if take else best[j]


@njit(**JIT)
def _carry(lab, seed_values, values):
    """Gather each pixel's seed parameters so that the next pass reads them as contiguous rows
    (a gather inside the candidate loops would stop LLVM from vectorizing them)."""
    for f in range(seed_values.shape[0]):
        for j in range(lab.shape[0]):
            values[f, j] = seed_values[f, max(lab[j], 0)]


@njit(**PJIT)
def _jump_flood_pass(k, src, src_values, dst, dst_values, seed_values, out, sy, sx):
    """One jump-flood pass with step k: each pixel keeps the best of its own seed and the seeds
    its 8 candidates p + k·{−1,0,1}² \\ {p} hold in ``src``, and writes it to ``dst`` (ping-pong:
    no pixel reads a value written in the same pass, so rows are independent).

    ``src`` holds flat seed indices (−1: none); ``src_values`` (H, F, W) the parameters of each
    pixel's seed (F = 2: z, m_e; F = 5 adds m_f, n_x, n_y for the directional constraint) and
    ``seed_values`` (F, H·W) the same per seed. A row is one sweep per candidate offset over the
    columns where that candidate lies inside the image. The last pass (``out`` of shape (H, W))
    writes D to ``out`` instead of carrying the parameters on."""
    h, w = src.shape
    inv_w = 1.0 / w
    fw = float(w)
    last = out.shape[0] == h
    for i in prange(h):
        fi = float(i)
        best = dst[i]
        best_c = out[i] if last else np.empty(w)
        _own(fi, src[i], src_values[i], best, best_c, fw, inv_w, sy, sx)
        c = np.empty(w)
        for oi in range(-1, 2):
            qi = i + oi * k
            if qi < 0 or qi >= h:
                continue
            for oj in range(-1, 2):
                lo = max(0, -oj * k)
                hi = min(w, w - oj * k)
                if (oi == 0 and oj == 0) or lo >= hi:
                    continue
                a, b = lo + oj * k, hi + oj * k
                if src_values.shape[1] == 5:
                    _sweep_directional(fi, lo, src[qi, a:b], src_values[qi], a, b, c[lo:hi],
                                       best[lo:hi], best_c[lo:hi], fw, inv_w, sy, sx)
                else:
                    _sweep(fi, lo, src[qi, a:b], src_values[qi, 0, a:b], src_values[qi, 1, a:b],
                           best[lo:hi], best_c[lo:hi], fw, inv_w, sy, sx)
        if not last:
            _carry(dst[i], seed_values, dst_values[i])


@njit(**PJIT)
def _exact(seed_list, seed, out, seeds, sy, sx, directional):
    """Brute force: every pixel tries every seed (listed in row-major order, so the first strict
    maximum is also the smallest flat index among ties)."""
    h, w = seed.shape
    for iu in prange(h):
        i = np.int64(iu)  # one _cutaway_function: the prange index is uint64 in the parallel pass
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
    # a negative row spacing: rows run up the screen (a picture mirrored top to bottom, NDC y
    # down); distances use |spacing|, the floor's screen direction the sign
    if not (np.all(s != 0) and s[1] > 0):
        raise ValueError(f"sampling must be nonzero (the column spacing positive), got "
                         f"{tuple(s)}")
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
    fields = [z, slope_e]
    if floor_slope is not None:
        n_proj = as_float_array(floor_normal, "floor_normal", shape=z.shape + (2,))
        fields += [_as_slope(floor_slope, z.shape, "floor_slope"), n_proj[..., 0], n_proj[..., 1]]
    # the seed parameters, one row per field (z, m_e[, m_f, n_x, n_y]), indexed by flat index
    params = np.stack([f.ravel() for f in fields])
    return z, params, sy, sx


def _records(params, width):
    """The per-seed record table of :func:`_cutaway_function` (one row per flat index)."""
    n = params.shape[1]
    seeds = np.zeros((n, _RECORD))
    seeds[:, _ROW], seeds[:, _COL] = np.divmod(np.arange(n), width)
    seeds[:, _Z] = params[0]
    seeds[:, _ME] = params[1]
    seeds[:, _MF] = params[1]
    if params.shape[0] == 5:
        seeds[:, _MF], seeds[:, _NX], seeds[:, _NY] = params[2:]
    return seeds, params.shape[0] == 5


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
        in ``scipy.ndimage.distance_transform_edt``. Default 1 (distances in pixels). A
        negative row spacing says the rows run up the screen (the picture of a projection
        drawn with NDC y down): distances use its magnitude, the floor normal's screen
        direction (y up) its sign.
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

    Each pixel carries its seed's parameters (z, m, …) beside the seed's index, so a pass is, per
    row, one branch-free sweep per candidate offset over contiguous memory, which LLVM vectorizes;
    C is computed with the same floating-point operations as :func:`exact`, and the result is
    bit-identical to the plain per-pixel loop (``tests/naive.py``).
    """
    z, params, sy, sx = _prepare(seed_depth, slope, sampling, floor_slope, floor_normal)
    variant = as_choice(variant, "variant", VARIANTS)
    h, w = z.shape
    src = np.where(z > -np.inf, np.arange(h * w, dtype=np.int32).reshape(h, w), np.int32(-1))
    # each pixel's seed parameters, (H, F, W): a row's fields are contiguous for the sweeps (a
    # copy even where the transpose is a view: the passes overwrite it while reading ``params``)
    src_values = params.reshape(-1, h, w).transpose(1, 0, 2).copy()
    dst = np.full_like(src, -1)
    dst_values = np.zeros_like(src_values)
    out = np.full(z.shape, -np.inf)
    schedule = step_schedule(h, w, variant)
    for n, k in enumerate(schedule):
        target = out if n == len(schedule) - 1 else out[:0]
        _jump_flood_pass(k, src, src_values, dst, dst_values, params, target, sy, sx)
        src, dst = dst, src
        src_values, dst_values = dst_values, src_values
    return _result(out, src, return_seeds)


def exact(seed_depth, slope, *, sampling=1.0, floor_slope=None, floor_normal=None,
          return_seeds=False):
    """D(x) = max_s [z(s) − m(s)‖x − s‖] by brute force over all seeds, O(H·W·seeds).

    Parameters
    ----------""" + _DOC_COMMON + """

    Notes
    -----
    The reference for :func:`jump_flood` and :func:`chamfer` (MATH.md D-C5: "test against brute
    force"). It evaluates C with the very same floating-point operations, so where a jump-flood
    variant finds the optimal seed the two agree bit for bit. Ties go to the smaller row-major
    seed index.
    """
    z, params, sy, sx = _prepare(seed_depth, slope, sampling, floor_slope, floor_normal)
    seeds, directional = _records(params, z.shape[1])
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
