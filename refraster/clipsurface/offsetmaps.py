"""Offset maps of 2.5D clip surfaces: loading, sampling, generators, blends, derived maps.

An **offset map** OM is a 2D array of heights ``h ∈ [0, 1]`` (Trapp & Döllner, Sec. 4.2).
Texel order (MATH.md §1.2b): ``offset_map[row, col]`` with ``col ↔ s`` and ``row ↔ t``; row 0
lies at ``t = 0`` (it is the first row handed to ``glTexImage2D``) and texel centres sit at
``((col + 0.5) / W, (row + 0.5) / H)``. An image file is stored top row first, so
:func:`load_offset_map` flips it vertically: the image's *bottom* row becomes texel row 0,
exactly as an OpenGL program that uploads a decoded image bottom-up.

Sampling (:func:`sample`) is GLSL ``texture2D`` with ``GL_LINEAR`` filtering and one of the wrap
modes ``"repeat"``, ``"clamp_to_edge"``, ``"mirrored_repeat"`` (OpenGL 4.6 spec, §8.14.2,
Table 8.20), evaluated in float64.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numba import njit, prange

from .._config import IJIT, PJIT
from .._validate import as_choice, as_float_array, as_real

__all__ = [
    "WRAP_MODES", "as_offset_map", "load_offset_map", "sample",
    "constant", "value_noise", "perlin_noise", "ragged_cut", "sinusoid", "steps", "blend",
    "normal_map", "encode_normal_map", "occlusion_map",
]

#: Wrap modes and their kernel codes.
WRAP_MODES = {"repeat": 0, "clamp_to_edge": 1, "mirrored_repeat": 2}
_REPEAT, _CLAMP, _MIRROR = 0, 1, 2
#: Texel coordinates beyond ±2**52 carry no fractional part in float64; they are clamped there
#: so that the integer conversion in the kernel cannot overflow.
_COORD_LIMIT = 2.0 ** 52


def as_wrap(wrap, name="wrap"):
    """Validate a wrap mode name; returns the canonical name."""
    return as_choice(wrap, name, {k: k for k in WRAP_MODES})


def unit_dtype(arr, name):
    """Texel values as stored → floats: ``uint8`` / 255, ``uint16`` / 65535, floats as they are;
    other dtypes (other integers, booleans, complex) are refused."""
    if arr.dtype == np.uint8:
        return arr.astype(np.float64) / 255.0
    if arr.dtype == np.uint16:
        return arr.astype(np.float64) / 65535.0
    if not np.issubdtype(arr.dtype, np.floating):
        raise TypeError(
            f"{name} must be uint8, uint16 or float with values in [0, 1], got dtype {arr.dtype}")
    return arr


def unit_range(arr, name):
    """Non-empty, finite float64 in C order with every value in [0, 1]."""
    if arr.size == 0:
        raise ValueError(f"{name} is empty (shape {arr.shape})")
    arr = as_float_array(arr, name)
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{name} values must lie in [0, 1], got [{lo}, {hi}]")
    return np.ascontiguousarray(arr)


def as_offset_map(offset_map, name="offset_map"):
    """Validate an offset map and return it as C-contiguous, read-only ``float64`` ``(H, W)``.

    Accepted: ``uint8`` (value / 255), ``uint16`` (value / 65535), or a float array with every
    value in ``[0, 1]``; 2D ``(H, W)``, or 1D ``(W,)`` (a 1D offset map, Sec. 4.3), returned as
    ``(1, W)``. Other integer types, booleans, complex or arrays of other ranks are refused.
    """
    if isinstance(offset_map, (str, bytes)) or offset_map is None:
        raise TypeError(f"{name} must be a 2D array, got {type(offset_map).__name__}")
    arr = unit_dtype(np.asarray(offset_map), name)
    if arr.ndim == 1:
        # a 1D offset map (Sec. 4.3): texture1D(s) is texture2D(s, t) of the 1×W map, whose
        # t taps are always row 0 under every wrap mode
        arr = arr.reshape(1, -1)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be 1D (W,) or 2D (H, W) grayscale, got shape {arr.shape}")
    arr = unit_range(arr, name)
    arr.setflags(write=False)
    return arr


def load_offset_map(path, *, channel=None):
    """Load a grayscale image file as an offset map in texel order.

    Parameters
    ----------
    path : str or path-like
        Any image ``imageio`` reads: 8-bit or 16-bit integer, or float (values in [0, 1]).
    channel : int, optional
        For a multi-channel image, the channel to use. Without it a colour image is refused,
        because its conversion to gray is a choice the caller should make.

    Returns
    -------
    (H, W) float64, read-only, values in [0, 1]; row 0 = the image's **bottom** row (t = 0).

    Notes
    -----
    The vertical flip follows MATH.md §1.2b: texel row 0 is ``t = 0``, the first row given to
    ``glTexImage2D``, while image files list their top row first.
    """
    import imageio.v3 as iio
    image = np.asarray(iio.imread(path))
    if image.ndim == 3:
        if channel is None:
            if image.shape[2] == 1:
                image = image[:, :, 0]
            else:
                raise ValueError(
                    f"{path} has {image.shape[2]} channels; an offset map is grayscale "
                    "(pass channel=k to choose one)")
        else:
            if isinstance(channel, bool) or not isinstance(channel, numbers.Integral):
                raise TypeError(f"channel must be an int, got {type(channel).__name__}")
            if not 0 <= channel < image.shape[2]:
                raise ValueError(f"channel must be in [0, {image.shape[2]}), got {channel}")
            image = image[:, :, channel]
    if image.ndim != 2:
        raise ValueError(f"{path} is not a 2D image (shape {image.shape})")
    return as_offset_map(image[::-1], name=f"image {path}")


# --------------------------------------------------------------------------------------------
# texture2D with GL_LINEAR filtering


@njit(**IJIT)
def _wrap_texel(i, size, mode):
    """Texel index ``i`` wrapped as OpenGL 4.6 Table 8.20 says."""
    if mode == _REPEAT:
        return i % size
    if mode == _CLAMP:
        return min(max(i, 0), size - 1)
    m = i % (2 * size) - size
    mirrored = m if m >= 0 else -(1 + m)
    return (size - 1) - mirrored


@njit(**IJIT)
def _repeat(i, size):
    """``i mod size`` (in [0, size)); one add or subtract for |i| < 2·size."""
    if i < 0:
        i += size
        return i if i >= 0 else i % size
    if i >= size:
        i -= size
        return i if i < size else i % size
    return i


@njit(**IJIT)
def bilinear_taps(start, height, width, s, t, mode):
    """GL_LINEAR's four texels (flat indices from ``start``, row-major ``height × width``) and
    weights at ``(s, t)``: u = s·W, i0 = ⌊u − ½⌋, α = frac(u − ½), wrapped per ``mode``."""
    x = s * width - 0.5
    y = t * height - 0.5
    x = min(max(x, -_COORD_LIMIT), _COORD_LIMIT)
    y = min(max(y, -_COORD_LIMIT), _COORD_LIMIT)
    fx = math.floor(x)
    fy = math.floor(y)
    alpha = x - fx
    beta = y - fy
    if mode == _REPEAT:
        # the same texels as _wrap_texel, without an integer division within a tile's reach
        i0 = _repeat(np.int64(fx), width)
        i1 = i0 + 1 if i0 + 1 < width else np.int64(0)
        j0 = _repeat(np.int64(fy), height)
        j1 = j0 + 1 if j0 + 1 < height else np.int64(0)
    else:
        i0 = _wrap_texel(np.int64(fx), width, mode)
        i1 = _wrap_texel(np.int64(fx) + 1, width, mode)
        j0 = _wrap_texel(np.int64(fy), height, mode)
        j1 = _wrap_texel(np.int64(fy) + 1, height, mode)
    r0 = start + j0 * width
    r1 = start + j1 * width
    return (r0 + i0, r0 + i1, r1 + i0, r1 + i1, (1.0 - alpha) * (1.0 - beta),
            alpha * (1.0 - beta), (1.0 - alpha) * beta, alpha * beta)


@njit(**IJIT)
def bilinear(maps, taps):
    """Combine four texels of ``maps`` with :func:`bilinear_taps`' weights."""
    a, b, c, d, wa, wb, wc, wd = taps
    return wa * maps[a] + wb * maps[b] + wc * maps[c] + wd * maps[d]


@njit(**IJIT)
def texture2d_flat(maps, start, height, width, s, t, mode):
    """``texture2D(tex, vec2(s, t)).x`` with GL_LINEAR for a ``height × width`` map stored
    row-major at ``maps[start:]``."""
    return bilinear(maps, bilinear_taps(start, height, width, s, t, mode))


@njit(**IJIT)
def _texture2d_linear(tex, s, t, mode):
    """:func:`texture2d_flat` of a C-contiguous ``(H, W)`` map."""
    return texture2d_flat(tex.reshape(-1), 0, tex.shape[0], tex.shape[1], s, t, mode)


@njit(**PJIT)
def _sample_kernel(tex, st, mode, out):
    for n in prange(st.shape[0]):
        out[n] = _texture2d_linear(tex, st[n, 0], st[n, 1], mode)


def sample(offset_map, st, *, wrap="repeat"):
    """Sample an offset map at texture coordinates, as GLSL ``texture2D`` with ``GL_LINEAR``.

    Parameters
    ----------
    offset_map : (H, W) array
        Heights in texel order (see the module docstring); uint8, uint16 or float in [0, 1].
    st : (N, 2) float
        Texture coordinates ``(s, t)``; finite.
    wrap : {"repeat", "clamp_to_edge", "mirrored_repeat"}
        The texture's wrap mode (the same for s and t).

    Returns
    -------
    (N,) float64 heights.

    Notes
    -----
    With ``u = s·W`` and ``v = t·H``: ``i0 = wrap(⌊u − ½⌋)``, ``i1 = wrap(⌊u − ½⌋ + 1)``,
    ``α = frac(u − ½)`` (and j0, j1, β from v), then the bilinear blend of the four texels
    (OpenGL 4.6 §8.14.2, Table 8.20). Trapp & Döllner, Sec. 4.3; MATH.md §1.1 and §1.2b.
    Evaluated in float64, not in a GPU's float32 with 8-bit filter weights.
    """
    tex = as_offset_map(offset_map)
    st = as_float_array(st, "st", shape=(None, 2))
    mode = WRAP_MODES[as_wrap(wrap)]
    out = np.zeros(st.shape[0], np.float64)
    _sample_kernel(tex, st, mode, out)
    return out


# --------------------------------------------------------------------------------------------
# generators (periodic, so that they tile seamlessly under the default "repeat" wrap)


def _as_shape(shape):
    if isinstance(shape, numbers.Integral) and not isinstance(shape, bool):
        shape = (shape, shape)
    if not isinstance(shape, (tuple, list)) or len(shape) != 2:
        raise TypeError(f"shape must be an int or a (height, width) pair, got {shape!r}")
    out = []
    for name, n in zip(("height", "width"), shape):
        if isinstance(n, bool) or not isinstance(n, numbers.Integral):
            raise TypeError(f"shape {name} must be an int, got {type(n).__name__}")
        if not 1 <= int(n) <= 1 << 14:
            raise ValueError(f"shape {name} must be in [1, 16384], got {n}")
        out.append(int(n))
    return tuple(out)


def _as_count(value, name, lo=1, hi=1 << 12):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if not lo <= int(value) <= hi:
        raise ValueError(f"{name} must be in [{lo}, {hi}], got {value}")
    return int(value)


def _texel_centres(shape):
    """(t, s) grids of texel centres in [0, 1]."""
    h, w = shape
    t = (np.arange(h) + 0.5) / h
    s = (np.arange(w) + 0.5) / w
    return np.meshgrid(t, s, indexing="ij")


def _fade(x):
    return x * x * x * (x * (x * 6.0 - 15.0) + 10.0)


def _finish(values, normalize):
    if normalize:
        lo, hi = values.min(), values.max()
        values = (values - lo) / (hi - lo) if hi > lo else np.full_like(values, 0.5)
    out = np.ascontiguousarray(np.clip(values, 0.0, 1.0))
    out.setflags(write=False)
    return out


def constant(shape, value=0.0):
    """A flat offset map: every texel ``value`` (a planar clip surface)."""
    value = as_real(value, "value", lo=0.0, hi=1.0)
    return _finish(np.full(_as_shape(shape), value), False)


def _octaves(shape, cells, octaves, persistence, seed, one_octave):
    shape = _as_shape(shape)
    cells = _as_count(cells, "cells")
    octaves = _as_count(octaves, "octaves", hi=16)
    persistence = as_real(persistence, "persistence", lo=0.0, hi=1.0)
    rng = np.random.default_rng(seed)
    t, s = _texel_centres(shape)
    total = np.zeros(shape)
    amp, norm = 1.0, 0.0
    for k in range(octaves):
        c = cells << k
        total += amp * one_octave(s * c, t * c, c, rng)
        norm += amp
        amp *= persistence
    return total / norm


def _value_octave(x, y, c, rng):
    lattice = rng.random((c, c))
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = _fade(x - x0), _fade(y - y0)
    v00 = lattice[y0 % c, x0 % c]
    v10 = lattice[y0 % c, (x0 + 1) % c]
    v01 = lattice[(y0 + 1) % c, x0 % c]
    v11 = lattice[(y0 + 1) % c, (x0 + 1) % c]
    return (v00 * (1 - fx) + v10 * fx) * (1 - fy) + (v01 * (1 - fx) + v11 * fx) * fy


def _perlin_octave(x, y, c, rng):
    angle = rng.random((c, c)) * 2.0 * np.pi
    gx, gy = np.cos(angle), np.sin(angle)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    dx, dy = x - x0, y - y0

    def dot(ix, iy, ox, oy):
        return gx[iy % c, ix % c] * ox + gy[iy % c, ix % c] * oy

    n00 = dot(x0, y0, dx, dy)
    n10 = dot(x0 + 1, y0, dx - 1, dy)
    n01 = dot(x0, y0 + 1, dx, dy - 1)
    n11 = dot(x0 + 1, y0 + 1, dx - 1, dy - 1)
    fx, fy = _fade(dx), _fade(dy)
    n = (n00 * (1 - fx) + n10 * fx) * (1 - fy) + (n01 * (1 - fx) + n11 * fx) * fy
    # |n| ≤ √2/2 for unit gradients; map to [0, 1].
    return 0.5 + n / np.sqrt(2.0)


def value_noise(shape, *, cells=8, octaves=1, persistence=0.5, seed=0, normalize=True):
    """Periodic value noise: random lattice values, quintic-faded bilinear interpolation.

    ``cells`` lattice cells across the map in the first octave, doubled per octave; amplitudes
    multiply by ``persistence``. ``normalize`` stretches the result to span [0, 1] exactly.
    Deterministic for a given ``seed`` (NumPy's PCG64).
    """
    return _finish(_octaves(shape, cells, octaves, persistence, seed, _value_octave), normalize)


def perlin_noise(shape, *, cells=8, octaves=4, persistence=0.5, seed=0, normalize=True):
    """Periodic gradient (Perlin) noise with the quintic fade; parameters as :func:`value_noise`."""
    return _finish(_octaves(shape, cells, octaves, persistence, seed, _perlin_octave), normalize)


def ragged_cut(shape, *, teeth=12, jitter=0.3, seed=0, axis="s"):
    """A sketchy, ragged cut line: a random zig-zag profile along ``axis``, constant across it.

    The profile alternates between high and low random heights at ``teeth`` pairs of knots
    (periodic), then a ``jitter`` fraction of fine value noise roughens it, as hand-drawn
    break lines do. Values span [0, 1].
    """
    shape = _as_shape(shape)
    teeth = _as_count(teeth, "teeth")
    jitter = as_real(jitter, "jitter", lo=0.0, hi=1.0)
    axis = as_choice(axis, "axis", {"s": "s", "t": "t"})
    rng = np.random.default_rng(seed)
    knots = 2 * teeth
    heights = np.where(np.arange(knots) % 2 == 0, 0.55 + 0.45 * rng.random(knots),
                       0.45 * rng.random(knots))
    positions = (np.arange(knots) + 0.8 * (rng.random(knots) - 0.5)) / knots
    n = shape[1] if axis == "s" else shape[0]
    x = (np.arange(n) + 0.5) / n
    profile = np.interp(x, np.concatenate([positions - 1, positions, positions + 1]),
                        np.tile(heights, 3))
    fine = value_noise((1, n), cells=max(4, 4 * teeth), seed=rng.integers(1 << 31))[0]
    profile = (1.0 - jitter) * profile + jitter * fine
    values = np.broadcast_to(profile[None, :] if axis == "s" else profile[:, None], shape)
    return _finish(values.copy(), True)


def sinusoid(shape, *, periods=(8, 0), phase=0.0):
    """Sinusoidal waves ``½ + ½·sin(2π(ps·s + pt·t) + phase)``; ``periods = (ps, pt)`` whole
    periods across the map (integers, so the map tiles)."""
    shape = _as_shape(shape)
    if not isinstance(periods, (tuple, list)) or len(periods) != 2:
        raise TypeError(f"periods must be a (ps, pt) pair of ints, got {periods!r}")
    ps = _as_count(periods[0], "periods[0]", lo=0)
    pt = _as_count(periods[1], "periods[1]", lo=0)
    phase = as_real(phase, "phase")
    t, s = _texel_centres(shape)
    return _finish(0.5 + 0.5 * np.sin(2.0 * np.pi * (ps * s + pt * t) + phase), False)


def steps(shape, *, levels=4, periods=1, axis="s"):
    """A staircase along ``axis``: ``levels`` flat terraces per period, heights 0 … 1."""
    shape = _as_shape(shape)
    levels = _as_count(levels, "levels", lo=2)
    periods = _as_count(periods, "periods")
    axis = as_choice(axis, "axis", {"s": "s", "t": "t"})
    t, s = _texel_centres(shape)
    x = s if axis == "s" else t
    k = np.floor((x * periods % 1.0) * levels)
    return _finish(k / (levels - 1), False)


_BLENDS = ("add", "max", "min", "multiply", "lerp")


def blend(a, b, mode="lerp", *, weight=0.5):
    """Blend two offset maps of one shape, as image blending does (Trapp & Döllner, Sec. 4.2).

    ``"add"`` saturates at 1 (as a unorm target does); ``"lerp"`` is ``(1 − w)·a + w·b`` with
    ``weight`` a scalar in [0, 1] or an ``(H, W)`` array of weights in [0, 1].
    """
    a = as_offset_map(a, "a")
    b = as_offset_map(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a and b must have one shape, got {a.shape} and {b.shape}")
    mode = as_choice(mode, "mode", {m: m for m in _BLENDS})
    if mode == "add":
        out = np.minimum(a + b, 1.0)
    elif mode == "max":
        out = np.maximum(a, b)
    elif mode == "min":
        out = np.minimum(a, b)
    elif mode == "multiply":
        out = a * b
    else:
        if np.ndim(weight) == 0:
            w = as_real(weight, "weight", lo=0.0, hi=1.0)
        else:
            w = as_float_array(weight, "weight", shape=a.shape)
            if w.min() < 0.0 or w.max() > 1.0:
                raise ValueError("weight values must lie in [0, 1]")
        out = (1.0 - w) * a + w * b
    return _finish(out, False)


# --------------------------------------------------------------------------------------------
# derived maps (MATH.md §1.2b)


def _as_geometry(extent, scale):
    extent = as_float_array(extent, "extent", shape=(2,))
    scale = as_float_array(scale, "scale", shape=(3,))
    if np.any(extent <= 0):
        raise ValueError(f"extent must be positive (|U|, |V|), got {extent}")
    if np.any(scale[:2] <= 0):
        raise ValueError(f"scale Sx, Sy must be positive, got {scale[:2]}")
    return extent, scale


def _neighbour_index(n, wrap):
    """Indices of the previous and next texel along an axis of ``n`` texels under ``wrap``."""
    i = np.arange(n)
    code = WRAP_MODES[wrap]
    prev = np.array([_wrap_texel(k - 1, n, code) for k in i], np.int64)
    nxt = np.array([_wrap_texel(k + 1, n, code) for k in i], np.int64)
    return prev, nxt


def normal_map(offset_map, *, extent=(1.0, 1.0), scale=(1.0, 1.0, 1.0), wrap="repeat"):
    """Per-texel unit normal of the displaced cap surface, in the surface frame (Û, V̂, N).

    Parameters
    ----------
    offset_map : (H, W) array
        Heights in [0, 1], texel order.
    extent : (2,) float
        ``(|U|, |V|)`` of the clip surface.
    scale : (3,) float
        ``S = (Sx, Sy, Sz)``.
    wrap : str
        The wrap mode; it decides the neighbours of border texels for the central differences.

    Returns
    -------
    (H, W, 3) float64 unit vectors; components along (Û, V̂, N). A flat map gives (0, 0, −1).

    Notes
    -----
    MATH.md §1.2b: ``X(a, b) = O + aU + bV − Sz·h(a·Sx, b·Sy)·N``, differentiated by central
    differences over the texel grid; ``n = normalize(∂X/∂a × ∂X/∂b)`` oriented towards −N, the
    side from which the cut is seen. In the (Û, V̂, N) frame this is
    ``−(Sz·Sx·|V|·∂h/∂s, Sz·Sy·|U|·∂h/∂t, |U|·|V|)`` normalized.
    """
    h = as_offset_map(offset_map)
    extent, scale = _as_geometry(extent, scale)
    wrap = as_wrap(wrap)
    rows, cols = h.shape
    cprev, cnext = _neighbour_index(cols, wrap)
    rprev, rnext = _neighbour_index(rows, wrap)
    # Central differences of the sampled surface: the neighbour beyond a border is whatever
    # texture2D returns there (wrapped, mirrored or clamped), always two texels apart.
    ds = (h[:, cnext] - h[:, cprev]) * (cols / 2.0)
    dt = (h[rnext, :] - h[rprev, :]) * (rows / 2.0)
    ul, vl = extent
    sx, sy, sz = scale
    n = np.stack([-sz * sx * vl * ds, -sz * sy * ul * dt, np.full_like(h, -ul * vl)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return n


def encode_normal_map(normals):
    """Map unit normals to RGB in [0, 1] as ``0.5·n + 0.5`` (the usual normal-map picture)."""
    n = as_float_array(normals, "normals", shape=(None, None, 3))
    return np.clip(0.5 * n + 0.5, 0.0, 1.0)


@njit(**PJIT)
def _occlusion_kernel(heights, du, dv, radius, directions, steps_, mode, out):
    rows, cols = heights.shape
    for j in prange(rows):
        for i in range(cols):
            s0 = (i + 0.5) / cols
            t0 = (j + 0.5) / rows
            z0 = heights[j, i]
            blocked = 0.0
            for k in range(directions):
                phi = 2.0 * math.pi * k / directions
                cx = math.cos(phi)
                cy = math.sin(phi)
                best = 0.0
                for m in range(1, steps_ + 1):
                    r = radius * m / steps_
                    z = _texture2d_linear(heights, s0 + r * cx / du, t0 + r * cy / dv, mode)
                    rise = z - z0
                    if rise > 0.0:
                        sin_h = rise / math.sqrt(rise * rise + r * r)
                        if sin_h > best:
                            best = sin_h
                blocked += best
            out[j, i] = 1.0 - blocked / directions


def occlusion_map(offset_map, *, extent=(1.0, 1.0), scale=(1.0, 1.0, 1.0), wrap="repeat",
                  radius=None, directions=8, steps=8):
    """Ambient-occlusion map of the cap height field seen from −N (horizon-based).

    Parameters
    ----------
    offset_map, extent, scale, wrap
        As :func:`normal_map`.
    radius : float, optional
        Search radius R in world units (default: 8 texels along the shorter texel side).
    directions : int
        Number K of azimuth directions.
    steps : int
        Samples per direction (evenly spaced up to R, bilinear, with the wrap mode).

    Returns
    -------
    (H, W) float64 in [0, 1]: 1 = unoccluded.

    Notes
    -----
    MATH.md §1.2b [guess]: seen from −N the cap's elevation is ``Sz·h`` (larger h lies further
    towards the viewer). For each azimuth the horizon elevation angle θ_k is the largest over
    the samples; the unblocked fraction of the hemisphere's solid angle is
    ``1 − (1/K)·Σ sin θ_k``. Texel spacing in world units: ``|U| / (Sx·W)`` along Û and
    ``|V| / (Sy·H)`` along V̂.
    """
    h = as_offset_map(offset_map)
    extent, scale = _as_geometry(extent, scale)
    mode = WRAP_MODES[as_wrap(wrap)]
    rows, cols = h.shape
    # world length of one unit of s and of t
    du = extent[0] / scale[0]
    dv = extent[1] / scale[1]
    if radius is None:
        radius = 8.0 * min(du / cols, dv / rows)
    radius = as_real(radius, "radius", lo=0.0, lo_open=True)
    directions = _as_count(directions, "directions", hi=256)
    steps = _as_count(steps, "steps", hi=1024)
    # heights in world units, so that the horizon angles are geometric
    field = np.ascontiguousarray(h * scale[2])
    out = np.zeros(h.shape, np.float64)
    _occlusion_kernel(field, du, dv, radius, directions, steps, mode, out)
    return out
