"""Layered depth images, volumetric depth sprites and the volumetric parity test.

Trapp & Döllner, "2.5D Clip-Surfaces for Technical Visualization", Sec. 5.2–5.4, with the
corrections of MATH.md §2.

* :func:`peel` builds a layered depth image (LDI) from **one** pass over the fragment stream
  (:func:`refraster.draw`): the fragments of each pixel are sorted by depth with a stable sort,
  so fragments at equal depth keep draw order. ``mode="peel"`` then keeps, per pixel, the first
  fragment of each run of equal depths — exactly what classic multi-pass depth peeling with
  ``GL_LESS`` and a strict "behind the previous layer" test produces; ``mode="all"`` keeps every
  fragment (an A-buffer), which the parity test needs (MATH.md §2.3: peeling merges coincident
  fragments and breaks parity). The peel follows the depth direction of the raster state: under
  ``greater``/``gequal`` (reversed-Z) the nearest fragment has the **largest** depth, and the
  layers are sorted from depth 1 downwards (:func:`peel_fragments`).
* :class:`VolumetricDepthSprite` is the paper's VDS = (G, LDI, d, w, h): the solid scaled
  uniformly into the unit cube (with the margin of MATH.md §2.1), seen by an orthographic camera,
  linear depth, built with ``mode="all"``; ``contains`` is the corrected parity test of
  MATH.md §2.2 (inside iff the number of layers at or in front of ``T_r`` is odd), or the
  nonzero winding rule of §2.3.
"""

from __future__ import annotations

import numbers
import warnings
from dataclasses import dataclass

import numpy as np
from numba import get_num_threads, njit, prange

from ._config import IJIT, PJIT
from ._scratch import OUTPUTS
from ._validate import as_choice, as_float_array, as_size
from .mesh import as_mesh
from .raster.rasterizer import DEPTH_FUNCS, depth_test
from .raster.state import RasterState, as_raster_state, require_single_sample

__all__ = ["LayeredDepthImage", "peel", "peel_fragments", "VolumetricDepthSprite",
           "NonWatertightWarning", "MODES", "RULES", "AXES"]

MODES = {"peel": 0, "all": 1}
RULES = {"parity": 0, "nonzero": 1}
#: LDI frames: rows (s, t, r) of the rotation B. The ray runs along +r and (s, t, −r) is
#: right-handed, as (x, y, z) of GL's eye space, so a face whose outward normal points at the
#: viewer (an entry into the solid) is front-facing (counter-clockwise as seen).
AXES = {
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
    "x": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]),
    "y": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
}
#: Largest number of layer texels (K·H·W) an LDI may allocate.
MAX_LAYER_TEXELS = 1 << 28
#: Largest VDS resolution (texels per side).
MAX_RESOLUTION = 4096
#: Format tag written into every saved sprite.
FORMAT = "refraster.vds"
FORMAT_VERSION = 1


class NonWatertightWarning(UserWarning):
    """A VDS texel has an odd number of layers: the mesh is not watertight there."""


# ----------------------------------------------------------------------------- kernels

#: Pixels per parallel block of :func:`_fill_layers` (64 rows at 1024 wide: each layer's
#: block written whole; 47–49 ms of one thread's CPU for the 8-layer 1024² peel against 56–58
#: with 4,096-pixel blocks, 2026-12-05).
FILL_BLOCK = 65536


#: Fragments per chunk of the parallel bucket sort, at least (:func:`bucket_by_pixel`): a
#: smaller stream is one chunk.
BUCKET_MIN_CHUNK = 1 << 16
#: Pixels per block of the bucket sort's parallel prefix sum (:func:`_bucket_scan`).
SCAN_BLOCK = 1 << 14


@njit(**PJIT)
def _bucket_pass(pixel, n_pixels, bounds, hist, scatter, bad, order):
    """One pass of the chunked counting sort, parallel over the fragment chunks
    ``bounds[c]:bounds[c + 1]``. Counting (``scatter`` False): ``hist[c, p]`` = fragments of
    chunk c at pixel p, ``bad[c]`` True (and the chunk's count left unfinished) at a pixel
    index outside ``[0, n_pixels)``. Scattering: ``hist[c, p]`` holds chunk c's first slot
    for pixel p (:func:`_bucket_scan`); each fragment index goes to its pixel's next slot."""
    for c in prange(bounds.shape[0] - 1):
        if scatter:
            for i in range(bounds[c], bounds[c + 1]):
                p = pixel[i]
                order[hist[c, p]] = i
                hist[c, p] += 1
            continue
        for p in range(n_pixels):
            hist[c, p] = 0
        for i in range(bounds[c], bounds[c + 1]):
            p = pixel[i]
            if p < 0 or p >= n_pixels:
                bad[c] = True
                break
            hist[c, p] += 1


@njit(**PJIT)
def _bucket_scan(hist, offsets, sums):
    """The counts ``hist[c, p]`` → pixel p's first slot ``offsets[p]`` (and the total in
    ``offsets[P]``) and chunk c's first slot for it, ``offsets[p] + Σ_{c' < c} hist[c', p]``
    (in place): pixels before chunks, so each pixel's fragments stay in stream order. Two
    parallel passes over blocks of :data:`SCAN_BLOCK` pixels around a short serial sum."""
    nch, n_pixels = hist.shape
    nb = sums.shape[0]
    for b in prange(nb):
        lo = b * SCAN_BLOCK
        hi = min(lo + SCAN_BLOCK, n_pixels)
        s = 0
        for c in range(nch):
            for p in range(lo, hi):
                s += hist[c, p]
        sums[b] = s
    run = 0
    for b in range(nb):
        t = sums[b]
        sums[b] = run
        run += t
    offsets[n_pixels] = run
    for b in prange(nb):
        lo = b * SCAN_BLOCK
        hi = min(lo + SCAN_BLOCK, n_pixels)
        acc = sums[b]
        for p in range(lo, hi):
            offsets[p] = acc
            for c in range(nch):
                t = hist[c, p]
                hist[c, p] = acc
                acc += t


def bucket_by_pixel(pixel, n_pixels, chunks=None):
    """Stable counting sort of fragment indices by pixel → ``(offsets (P+1), order (N), ok)``,
    ``ok`` False (and the rest empty) if a pixel index lies outside ``[0, n_pixels)``.

    The stream is cut into ``chunks`` equal parts (default: Numba's thread count, fewer for a
    short stream): each counts its fragments per pixel, a prefix sum over (pixel, chunk) gives
    every chunk its own slots in each pixel's range, and each scatters into them — the order
    a serial counting sort gives, whatever the number of chunks (``tests/test_ldi.py`` holds
    it against NumPy's stable argsort). Its time for the 1024² peel's 2.6M fragments:
    docs/ldi.md, "Benchmark"."""
    n = pixel.shape[0]
    if chunks is None:
        chunks = get_num_threads()
    chunks = max(1, min(int(chunks), n // BUCKET_MIN_CHUNK))
    bounds = (np.arange(chunks + 1, dtype=np.int64) * n) // chunks
    hist = np.empty((chunks, n_pixels), np.int64)   # zeroed by the counting pass
    bad = np.zeros(chunks, np.bool_)
    order = np.empty(n, np.int64)   # every element written by the scattering pass
    _bucket_pass(pixel, n_pixels, bounds, hist, False, bad, order)
    if bad.any():
        return np.zeros(n_pixels + 1, np.int64), np.empty(0, np.int64), False
    offsets = np.empty(n_pixels + 1, np.int64)
    _bucket_scan(hist, offsets, np.empty((n_pixels + SCAN_BLOCK - 1) // SCAN_BLOCK, np.int64))
    _bucket_pass(pixel, n_pixels, bounds, hist, True, bad, order)
    return offsets, order, True


@njit(**PJIT)
def _sort_select(order, offsets, depth, mode, func, clear, count):
    """Sort each pixel's slice of ``order`` by depth and compact it to its layers;
    ``count[p]`` = number of layers. One pass per pixel, its slice hot in cache.

    The sort is a stable insertion sort, ascending, or (``greater``, ``gequal``: reversed-Z)
    descending; ties keep draw order. mode 0 (peel), with the depth function ``func``
    (:data:`refraster.raster.DEPTH_FUNCS`: ``less``, ``lequal``, ``greater`` or ``gequal``): one
    fragment of each run of equal depths — the first drawn under ``less``/``greater``, the last
    drawn under ``lequal``/``gequal`` (the fragment the depth test lets win) — and only depths
    that pass ``func`` against ``clear`` (the cleared depth buffer). mode 1 (all): every
    fragment.
    """
    last = func == 3 or func == 6          # lequal, gequal: the last drawn of a tie wins
    descending = func == 4 or func == 6    # greater, gequal: nearest = largest depth
    for p in prange(offsets.shape[0] - 1):
        a = offsets[p]
        b = offsets[p + 1]
        for i in range(a + 1, b):
            k = order[i]
            d = depth[k]
            j = i - 1
            if descending:
                while j >= a and depth[order[j]] < d:
                    order[j + 1] = order[j]
                    j -= 1
            else:
                while j >= a and depth[order[j]] > d:
                    order[j + 1] = order[j]
                    j -= 1
            order[j + 1] = k
        if mode == 1:
            count[p] = b - a
            continue
        w = a
        for i in range(a, b):
            k = order[i]
            d = depth[k]
            if not depth_test(func, d, clear):
                break
            if w == a or (d < depth[order[w - 1]] if descending else d > depth[order[w - 1]]):
                order[w] = k
                w += 1
            elif last:
                order[w - 1] = k
        count[p] = w - a


@njit(**PJIT)
def _fill_layers(order, offsets, count, depth, prim, obj, front, clear, out_index, out_depth,
                 out_prim, out_obj, out_front, out_count, out_overflow):
    """Every texel of the ``(K, P)`` layers: pixel p's first ``min(count[p], K)`` layers from
    its selected fragments, the rest empty (index, prim and object −1, depth ``clear``, back);
    ``out_count`` the layers stored, ``out_overflow`` whether more existed. Parallel over
    blocks of :data:`FILL_BLOCK` pixels, each layer's block written in pixel order."""
    k_max = out_depth.shape[0]
    n_pixels = offsets.shape[0] - 1
    for b in prange((n_pixels + FILL_BLOCK - 1) // FILL_BLOCK):
        lo = b * FILL_BLOCK
        hi = min(lo + FILL_BLOCK, n_pixels)
        for p in range(lo, hi):
            out_count[p] = min(count[p], k_max)
            out_overflow[p] = count[p] > k_max
        for layer in range(k_max):
            for p in range(lo, hi):
                if layer < out_count[p]:
                    i = order[offsets[p] + layer]
                    out_index[layer, p] = i
                    out_depth[layer, p] = depth[i]
                    out_prim[layer, p] = prim[i]
                    out_obj[layer, p] = obj[i]
                    out_front[layer, p] = front[i]
                else:
                    out_index[layer, p] = -1
                    out_depth[layer, p] = clear
                    out_prim[layer, p] = -1
                    out_obj[layer, p] = -1
                    out_front[layer, p] = False


@njit(**IJIT)
def parity_at(x, y, z, m, depth, sign, count, start, cstart, h, w, nonzero):
    """MATH.md §2.2 for one world point: T = M·P; inside iff T ∈ [0,1]³ and the number of
    layers with d_j ≤ T_r at the nearest texel is odd (nonzero: Σ sign_j over them ≠ 0).
    ``depth`` and ``sign`` hold the ``(d, h, w)`` layers row-major from ``start``, ``count``
    the ``(h, w)`` layer counts from ``cstart``."""
    ts = ((m[0, 0] * x + m[0, 1] * y) + m[0, 2] * z) + m[0, 3]
    tt = ((m[1, 0] * x + m[1, 1] * y) + m[1, 2] * z) + m[1, 3]
    tr = ((m[2, 0] * x + m[2, 1] * y) + m[2, 2] * z) + m[2, 3]
    if not (0.0 <= ts <= 1.0 and 0.0 <= tt <= 1.0 and 0.0 <= tr <= 1.0):
        return False
    col = min(int(ts * w), w - 1)
    row = h - 1 - min(int(tt * h), h - 1)
    texel = row * w + col
    acc = 0
    for layer in range(count[cstart + texel]):
        i = start + layer * (h * w) + texel
        if depth[i] <= tr:
            acc += sign[i] if nonzero else 1
        else:
            break
    return acc != 0 if nonzero else (acc & 1) == 1


@njit(**PJIT)
def _parity_test(points, m, depth, sign, count, nonzero, out):
    """:func:`parity_at` for each point of one LDI."""
    d, h, w = depth.shape
    flat_depth = depth.reshape(-1)
    flat_sign = sign.reshape(-1)
    flat_count = count.reshape(-1)
    for i in prange(points.shape[0]):
        out[i] = parity_at(points[i, 0], points[i, 1], points[i, 2], m, flat_depth, flat_sign,
                           flat_count, 0, 0, h, w, nonzero)


# ----------------------------------------------------------------------------- peeling

@dataclass(frozen=True, eq=False)
class LayeredDepthImage:
    """Layers front to back, all ``(K, H, W)`` with row 0 at the top.

    Attributes
    ----------
    depth : (K, H, W) float32
        Window depth; the clear value (``raster.clear_depth``, 1.0 by default) where a pixel
        has fewer than ``k + 1`` layers.
    prim_id, object_id : (K, H, W) int32
        Face index within its mesh and draw-call index; −1 where empty.
    front_facing : (K, H, W) bool
    index : (K, H, W) int64
        Index of the layer's fragment in the stream the LDI was built from; −1 where empty.
    count : (H, W) int32
        Layers stored per pixel (``≤ K``).
    overflow : (H, W) bool
        True where more layers existed than ``max_layers`` allowed.
    mode : str
        ``"peel"`` or ``"all"``.
    """

    depth: np.ndarray
    prim_id: np.ndarray
    object_id: np.ndarray
    front_facing: np.ndarray
    index: np.ndarray
    count: np.ndarray
    overflow: np.ndarray
    mode: str

    def __len__(self):
        return int(self.depth.shape[0])


def _as_max_layers(max_layers):
    if max_layers is None:
        return None
    if isinstance(max_layers, bool) or not isinstance(max_layers, numbers.Integral):
        raise TypeError(f"max_layers must be an int or None, got {type(max_layers).__name__}")
    if max_layers < 1:
        raise ValueError(f"max_layers must be at least 1, got {max_layers}")
    return int(max_layers)


#: The depth functions a peel can follow: front to back by ascending depth (``less``,
#: ``lequal``) or by descending depth (``greater``, ``gequal``: reversed-Z).
PEEL_DEPTH_FUNCS = ("less", "lequal", "greater", "gequal")


def _peel_state(raster):
    state = require_single_sample(as_raster_state(raster), "depth peeling")
    if state.depth_func not in PEEL_DEPTH_FUNCS:
        raise ValueError(f"raster.depth_func must be one of {', '.join(PEEL_DEPTH_FUNCS)} for "
                         f"depth peeling (a front-to-back order), got {state.depth_func!r}")
    return state


def peel_fragments(frags, *, max_layers=None, mode="peel", raster=None):
    """Layered depth image of a fragment stream (one pass, sorted per pixel).

    Parameters
    ----------
    frags : Fragments
        A stream from :func:`refraster.draw` or :func:`refraster.rasterize`; within each pixel
        its fragments are in draw order.
    max_layers : int, optional
        Keep at most this many layers; ``overflow`` marks pixels that had more. ``None`` keeps
        the full depth complexity.
    mode : {"peel", "all"}
        ``"peel"``: classic depth peeling — layer k is the nearest fragment strictly behind
        layer k − 1, fragments at equal depth merge and the first drawn survives (``GL_LESS``),
        and depths ≥ 1.0 (the cleared depth) never appear. ``"all"``: every fragment, sorted by
        depth front to back, ties in draw order.
    raster : RasterState, optional
        Its ``depth_func`` gives the direction and ``clear_depth`` the cleared depth (None:
        ``less``, 1.0). "Nearest" and "behind" follow the depth function: under ``less`` and
        ``lequal`` depth grows away from the eye; under ``greater`` and ``gequal``
        (reversed-Z) it shrinks, so layer 0 holds the largest depth that passes against the
        clear depth and layer k the largest depth strictly below layer k − 1's. Of fragments
        at equal depth the first drawn survives under ``less``/``greater`` and the last drawn
        under ``lequal``/``gequal`` (the one the depth test lets win); only depths passing the
        depth function against the clear depth appear. Other depth functions define no
        front-to-back order and are refused.

    Returns
    -------
    LayeredDepthImage

    Notes
    -----
    Equal to a literal multi-pass loop bit for bit (``tests/test_ldi.py``): pass k resolves
    with ``raster`` and ``keep=depth > layer_{k−1}`` (``depth < layer_{k−1}`` under
    ``greater``/``gequal``), the first pass keeping everything. Trapp & Döllner Sec. 5.2;
    MATH.md §2.3 (why ``"all"``).
    """
    mode_code = as_choice(mode, "mode", MODES)
    k_cap = _as_max_layers(max_layers)
    state = _peel_state(raster)
    func = DEPTH_FUNCS[state.depth_func]
    clear = np.float32(state.clear_depth)
    for name in ("pixel", "depth", "prim_id", "object_id", "front_facing"):
        if not hasattr(frags, name):
            raise TypeError(f"frags must be a Fragments stream, got {type(frags).__name__}")
    h, w = int(frags.height), int(frags.width)
    n_pixels = h * w
    pixel = np.ascontiguousarray(frags.pixel, np.int64)
    depth = np.ascontiguousarray(frags.depth, np.float32)
    offsets, order, ok = bucket_by_pixel(pixel, n_pixels)
    if not ok:
        raise ValueError(f"frags.pixel has indices outside the {w}×{h} image")
    count = np.empty(n_pixels, np.int64)
    _sort_select(order, offsets, depth, mode_code, func, clear, count)
    k_all = int(count.max()) if n_pixels else 0
    k = k_all if k_cap is None else min(k_all, k_cap)
    if k * n_pixels > MAX_LAYER_TEXELS:
        raise ValueError(f"{k} layers of {w}×{h} exceed {MAX_LAYER_TEXELS} texels; "
                         f"pass a smaller max_layers")
    # every texel is written by _fill_layers: recycled (or new) arrays, no fills
    out_index = OUTPUTS.empty((k, n_pixels), np.int64)
    out_depth = OUTPUTS.empty((k, n_pixels), np.float32)
    out_prim = OUTPUTS.empty((k, n_pixels), np.int32)
    out_obj = OUTPUTS.empty((k, n_pixels), np.int32)
    out_front = OUTPUTS.empty((k, n_pixels), np.bool_)
    out_count = np.empty(n_pixels, np.int32)
    out_overflow = np.empty(n_pixels, np.bool_)
    _fill_layers(order, offsets, count, depth, np.ascontiguousarray(frags.prim_id, np.int32),
                 np.ascontiguousarray(frags.object_id, np.int32),
                 np.ascontiguousarray(frags.front_facing, np.bool_), clear,
                 out_index, out_depth, out_prim, out_obj, out_front, out_count, out_overflow)
    shape = (k, h, w)
    return LayeredDepthImage(
        depth=out_depth.reshape(shape), prim_id=out_prim.reshape(shape),
        object_id=out_obj.reshape(shape), front_facing=out_front.reshape(shape),
        index=out_index.reshape(shape), count=out_count.reshape(h, w),
        overflow=out_overflow.reshape(h, w), mode=next(n for n, c in MODES.items() if c == mode_code))


def peel(meshes, *, view, proj, width, height, max_layers=None, mode="peel", model=None,
         raster=None):
    """Layered depth image of meshes: depth peeling from one pass over the fragment stream.

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        Draw calls in order (as :func:`refraster.draw`).
    view, proj : (4, 4) float
    width, height : int
    max_layers : int, optional
        Cap on the number of layers (``overflow`` marks pixels that had more).
    mode : {"peel", "all"}
        See :func:`peel_fragments`.
    model, raster
        Passed to :func:`refraster.draw` (the state's cull mode, front face, precision,
        sub-pixel bits, fill rule and conventions; a :class:`refraster.RasterState`, None for
        the default) and ``raster`` to :func:`peel_fragments` (its depth function and clear
        depth: the peel's direction).

    Returns
    -------
    LayeredDepthImage
        At ``raster.samples > 1`` each sample peels its own layers (layer k of sample s is the
        k-th nearest fragment covering s): the arrays gain a sample axis, ``(K, H, W, S)`` and
        ``count``, ``overflow`` ``(H, W, S)`` (``docs/ldi.md``, "Multisampled depth peeling").

    Notes
    -----
    Trapp & Döllner Sec. 5.2 build the LDI with multi-pass depth peeling (Everitt 2001); this is
    the same result from one rasterization. MATH.md §2.3.
    """
    from .raster import draw_stream
    as_choice(mode, "mode", MODES)
    _as_max_layers(max_layers)
    state = as_raster_state(raster)
    if state.samples != 1 or state.sample_locations != "standard":
        return _peel_samples(meshes, view, proj, width, height, max_layers, mode, model, state)
    state = _peel_state(state)
    # the layers need no barycentrics: a stream without them (the same fragments, in order)
    frags = draw_stream(meshes, view, proj, width, height, model, state, bary=False)
    return peel_fragments(frags, max_layers=max_layers, mode=mode, raster=state)


def _peel_samples(meshes, view, proj, width, height, max_layers, mode, model, state):
    """Depth peeling of a multisampled depth buffer: each sample peels its own layers (layer k
    of sample s is the k-th nearest fragment covering s, by the same rules as one sample), from
    the per-sample fragment stream over the sample image ``(H, W·S)``."""
    from .multisample import draw_samples, sample_image
    one = _peel_state(sample_image(state))
    frags = draw_samples(meshes, view=view, proj=proj, width=width, height=height,
                         model=model, raster=state)
    lay = peel_fragments(frags, max_layers=max_layers, mode=mode, raster=one)
    k, h, ws = lay.depth.shape
    s = state.samples
    per = (k, h, ws // s, s)
    return LayeredDepthImage(
        depth=lay.depth.reshape(per), prim_id=lay.prim_id.reshape(per),
        object_id=lay.object_id.reshape(per), front_facing=lay.front_facing.reshape(per),
        index=lay.index.reshape(per), count=lay.count.reshape(per[1:]),
        overflow=lay.overflow.reshape(per[1:]), mode=lay.mode)


# ----------------------------------------------------------------------------- the sprite

def _texture_to_ndc():
    """[0, 1]³ → NDC [−1, 1]³: the orthographic projection of the LDI camera."""
    a = np.eye(4) * 2.0
    a[3, 3] = 1.0
    a[:3, 3] = -1.0
    return a


def _sprite_matrix(center, scale, basis):
    """M = T(C) · S · B · T(−G) (Trapp Sec. 5.3, MATH.md §2.1), world → LDI texture space."""
    t_g = np.eye(4)
    t_g[:3, 3] = -center
    b = np.eye(4)
    b[:3, :3] = basis
    s = np.diag([scale, scale, scale, 1.0])
    t_c = np.eye(4)
    t_c[:3, 3] = 0.5
    return t_c @ s @ b @ t_g


@dataclass(frozen=True, eq=False)
class _AxisLDI:
    """One LDI of a sprite: its basis, matrix and layers (unused layers hold +inf)."""

    axis: str
    basis: np.ndarray      # (3, 3) rows s, t, r
    matrix: np.ndarray     # (4, 4) world → texture space
    depth: np.ndarray      # (d, h, w) float32, ascending, +inf unused
    sign: np.ndarray       # (d, h, w) int8, +1 front (entry), −1 back (exit), 0 unused
    count: np.ndarray      # (h, w) int32


class VolumetricDepthSprite:
    """A VDS = (G, LDI, d, w, h) (Trapp & Döllner Sec. 5.2) and its volumetric parity test.

    Build with :meth:`from_mesh`; test points with :meth:`contains`; store with :meth:`save` /
    :meth:`load`. With ``axis="xyz"`` the sprite holds one LDI per axis and :meth:`contains`
    takes the majority vote of the three (MATH.md §2.3, for grazing faces and small leaks).

    Attributes
    ----------
    G : (3,) float64
        Reference position: the centre of the mesh's bounding box.
    scale : float
        Uniform scale S (world units → texture units).
    axes : str
        ``"x"``, ``"y"``, ``"z"`` or ``"xyz"``.
    M, B : (4, 4), (3, 3) float64
        World → LDI texture matrix and basis of the first axis.
    depth : (d, h, w) float32
        Linear depth layers of the first axis, ascending, +inf in unused layers.
    count : (h, w) int32
        Layers per texel (first axis).
    d, w, h : int
        Depth complexity and resolution (first axis).
    """

    def __init__(self, center, scale, ldis):
        self.G = np.asarray(center, np.float64)
        self.scale = float(scale)
        self._ldis = tuple(ldis)
        self.axes = "".join(ldi.axis for ldi in self._ldis)
        for ldi in self._ldis:  # a sprite is immutable: kernels may keep views of its arrays
            for arr in (ldi.basis, ldi.matrix, ldi.depth, ldi.sign, ldi.count):
                arr.setflags(write=False)
        self._flat = None

    # the paper's names for the (first) LDI
    @property
    def M(self):
        return self._ldis[0].matrix

    @property
    def B(self):
        return self._ldis[0].basis

    @property
    def depth(self):
        return self._ldis[0].depth

    @property
    def sign(self):
        return self._ldis[0].sign

    @property
    def count(self):
        return self._ldis[0].count

    @property
    def d(self):
        return int(self._ldis[0].depth.shape[0])

    @property
    def h(self):
        return int(self._ldis[0].depth.shape[1])

    @property
    def w(self):
        return int(self._ldis[0].depth.shape[2])

    @property
    def texel_size(self):
        """Edge length of one texel in world units."""
        return 1.0 / (self.scale * self.w)

    def __repr__(self):
        return (f"VolumetricDepthSprite(axes={self.axes!r}, w={self.w}, h={self.h}, "
                f"d={[int(x.depth.shape[0]) for x in self._ldis]})")

    @classmethod
    def from_mesh(cls, mesh, resolution=256, axis="z", *, margin=2, strict=False,
                  raster=None):
        """Build the sprite of a closed mesh.

        Parameters
        ----------
        mesh : (vertices, faces) or trimesh.Trimesh
            A watertight, consistently (outward) oriented solid.
        resolution : int
            Texels per side of the LDI (w = h).
        axis : {"z", "x", "y", "xyz"}
            Viewing axis; ``"xyz"`` builds all three for a majority vote.
        margin : int
            Empty texels left around the solid in s and t; the same fraction of the unit
            interval is left in depth (MATH.md §2.1: no face may lie on a clip plane).
        strict : bool
            Raise instead of warning when a texel has an odd layer count.
        raster : RasterState, optional
            The rasterization's state (:class:`refraster.RasterState`: its precision,
            sub-pixel bits and fill rule; culling must stay off, and the sprite's own camera
            decides the facing). None: the default state.

        Returns
        -------
        VolumetricDepthSprite

        Notes
        -----
        Step 1–3 of Trapp Sec. 5.2: uniform scale into [0, 1]³, orthographic camera, depth
        complexity d, layers by peeling with linear depth — here one pass with ``mode="all"``
        so coincident fragments are kept (MATH.md §2.3). Unused layers hold +inf, so the test
        counts only layers that exist (MATH.md §2.2, "Loop bound").
        """
        from .raster import draw
        state = as_raster_state(raster)
        if state.cull != "none" or state.front_face != "ccw":
            raise ValueError(f"raster.cull must be 'none' and raster.front_face 'ccw' for a "
                             f"volumetric depth sprite (every layer counts, and the sign of a "
                             f"layer is its facing), got cull={state.cull!r}, "
                             f"front_face={state.front_face!r}")
        gl = RasterState()
        if (state.depth_range, state.origin, state.ndc_y, state.depth_clamp) != (
                gl.depth_range, gl.origin, gl.ndc_y, gl.depth_clamp):
            raise ValueError(f"raster.depth_range, origin, ndc_y and depth_clamp must be "
                             f"OpenGL's for a volumetric depth sprite (its own orthographic "
                             f"camera maps texture depth to GL's clip space), got "
                             f"{state.depth_range!r}, {state.origin!r}, {state.ndc_y!r}, "
                             f"{state.depth_clamp!r}")
        m = as_mesh(mesh)
        if m.n_faces == 0:
            raise ValueError("mesh has no faces: a volumetric depth sprite needs a closed solid")
        res = as_size(resolution, "resolution", maximum=MAX_RESOLUTION)
        if res < 8:
            raise ValueError(f"resolution must be at least 8, got {res}")
        axes = as_choice(axis, "axis", {"x": "x", "y": "y", "z": "z", "xyz": "xyz"})
        if isinstance(margin, bool) or not isinstance(margin, numbers.Integral):
            raise TypeError(f"margin must be an int, got {type(margin).__name__}")
        if not 1 <= margin < res // 4:
            raise ValueError(f"margin must be in [1, {res // 4}), got {margin}")
        used = m.vertices[np.unique(m.faces)]
        lo, hi = used.min(axis=0), used.max(axis=0)
        extent = float((hi - lo).max())
        if not extent > 0.0:
            raise ValueError("mesh is degenerate: its bounding box has zero extent")
        center = 0.5 * (lo + hi)
        scale = (1.0 - 2.0 * margin / res) / extent
        ldis = []
        for name in axes:
            basis = AXES[name]
            matrix = _sprite_matrix(center, scale, basis)
            frags = draw(m, view=matrix, proj=_texture_to_ndc(), width=res, height=res,
                         raster=state)
            ldi = peel_fragments(frags, mode="all")
            depth = np.where(ldi.index >= 0, ldi.depth, np.float32(np.inf)).astype(np.float32)
            sign = np.where(ldi.index >= 0, np.where(ldi.front_facing, 1, -1), 0).astype(np.int8)
            ldis.append(_AxisLDI(name, basis.copy(), matrix, depth, sign, ldi.count))
            odd = int(np.count_nonzero(ldi.count % 2))
            if odd:
                msg = (f"mesh is not watertight: {odd} of {int(np.count_nonzero(ldi.count))} "
                       f"covered texels along axis {name!r} have an odd number of layers")
                if strict:
                    raise ValueError(msg)
                warnings.warn(msg, NonWatertightWarning, stacklevel=2)
        return cls(center, scale, ldis)

    def contains(self, points, *, rule="parity"):
        """Volumetric parity test of world-space points.

        Parameters
        ----------
        points : (N, 3) float
            World-space positions (finite).
        rule : {"parity", "nonzero"}
            ``"parity"``: inside iff the count of layers with ``d_j ≤ T_r`` is odd (MATH.md
            §2.2). ``"nonzero"``: inside iff the sum of their facing signs (+1 entry, −1 exit)
            is nonzero — the winding number, for overlapping shells (MATH.md §2.3).

        Returns
        -------
        (N,) bool
            With three axes, the majority of the three tests.

        Notes
        -----
        Trapp Sec. 5.3, Eq. VPT and Listing 2 as corrected by MATH.md §2.2: the parity counts
        layers at or in front of ``T_r`` (entry closed, exit open); unused layers never count;
        texels are looked up by nearest filtering (integer indexing, no slice-boundary
        addressing); ``T`` outside the unit cube is outside. The initial parity is *outside*.
        """
        pts = as_float_array(points, "points", shape=(None, 3))
        code = as_choice(rule, "rule", RULES)
        votes = np.zeros(len(pts), np.int64)
        out = np.zeros(len(pts), np.bool_)
        for ldi in self._ldis:
            _parity_test(pts, ldi.matrix, ldi.depth, ldi.sign, ldi.count, code == 1, out)
            votes += out
        return votes * 2 > len(self._ldis)

    def packed(self):
        """The sprite's LDIs for a kernel (internal): ``(matrices (L, 4, 4), depth (Σ d·h·w,)
        float32, sign int8, count (Σ h·w,) int32, start (L,), count start (L,), shape (L, 2) =
        (h, w))``, views of the sprite's arrays when it has one axis; made once."""
        if self._flat is None:
            ldis = self._ldis
            def cat(arrays):
                flat = [np.ascontiguousarray(a).reshape(-1) for a in arrays]
                out = flat[0] if len(flat) == 1 else np.concatenate(flat)
                out.setflags(write=False)
                return out
            sizes = np.array([ldi.depth.size for ldi in ldis], np.int64)
            csizes = np.array([ldi.count.size for ldi in ldis], np.int64)
            self._flat = (np.stack([ldi.matrix for ldi in ldis]), cat([x.depth for x in ldis]),
                          cat([x.sign for x in ldis]), cat([x.count for x in ldis]),
                          np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64),
                          np.concatenate([[0], np.cumsum(csizes)[:-1]]).astype(np.int64),
                          np.array([ldi.count.shape for ldi in ldis], np.int64))
        return self._flat

    def fragment_stage(self, *, rule="parity"):
        """A ``fragment_stage`` for :func:`refraster.render`: keep fragments inside the solid.

        The per-fragment form the cap stage uses (Trapp Sec. 5.4: cap fragments that fail the
        parity test are discarded).
        """
        as_choice(rule, "rule", RULES)

        def keep_inside(frags):
            return self.contains(frags.world_position(), rule=rule)

        return keep_inside

    # ------------------------------------------------------------------ storage

    def save(self, path):
        """Write the sprite to ``path`` as ``.npz`` (atomically; loadable without pickle)."""
        from .io import write_npz
        arrays = {"format": np.array(FORMAT), "version": np.array(FORMAT_VERSION),
                  "G": self.G, "scale": np.array(self.scale), "axes": np.array(self.axes)}
        for i, ldi in enumerate(self._ldis):
            arrays[f"basis_{i}"] = ldi.basis
            arrays[f"matrix_{i}"] = ldi.matrix
            arrays[f"depth_{i}"] = ldi.depth
            arrays[f"sign_{i}"] = ldi.sign
            arrays[f"count_{i}"] = ldi.count
        return write_npz(path, **arrays)

    @classmethod
    def load(cls, path):
        """Read a sprite written by :meth:`save`, validating every array.

        Raises ``ValueError`` naming the file for anything that is not such a sprite (a corrupt
        archive, another program's ``.npz``, inconsistent shapes, unsorted layers ...).
        """
        try:
            with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise
        except Exception as exc:
            raise ValueError(f"{path}: not a readable .npz archive ({exc})") from exc
        try:
            return cls._from_arrays(data)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: not a valid volumetric depth sprite: {exc}") from exc

    @classmethod
    def _from_arrays(cls, data):
        def get(key, kind, ndim):
            if key not in data:
                raise KeyError(f"missing array {key!r}")
            a = data[key]
            if a.dtype.kind not in kind or a.ndim != ndim:
                raise TypeError(f"array {key!r} has dtype {a.dtype} and {a.ndim} dims")
            return a

        if str(get("format", "U", 0)) != FORMAT:
            raise ValueError(f"format tag is not {FORMAT!r}")
        if int(get("version", "iu", 0)) != FORMAT_VERSION:
            raise ValueError(f"unsupported version {int(data['version'])}")
        axes = str(get("axes", "U", 0))
        if axes not in ("x", "y", "z", "xyz"):
            raise ValueError(f"axes {axes!r} is not one of x, y, z, xyz")
        center = get("G", "f", 1).astype(np.float64)
        scale = float(get("scale", "f", 0))
        if center.shape != (3,) or not np.all(np.isfinite(center)):
            raise ValueError("G must be 3 finite numbers")
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError("scale must be positive and finite")
        ldis = []
        for i, name in enumerate(axes):
            basis = get(f"basis_{i}", "f", 2).astype(np.float64)
            matrix = get(f"matrix_{i}", "f", 2).astype(np.float64)
            depth = get(f"depth_{i}", "f", 3).astype(np.float32)
            sign = get(f"sign_{i}", "i", 3).astype(np.int8)
            count = get(f"count_{i}", "iu", 2).astype(np.int32)
            if not np.array_equal(basis, AXES[name]):
                raise ValueError(f"basis_{i} is not the basis of axis {name!r}")
            if not np.allclose(matrix, _sprite_matrix(center, scale, basis), rtol=0, atol=1e-12):
                raise ValueError(f"matrix_{i} does not equal T(C)·S·B·T(−G)")
            d, h, w = depth.shape
            if sign.shape != depth.shape or count.shape != (h, w) or h != w or h < 8:
                raise ValueError(f"LDI {i}: inconsistent shapes {depth.shape}, {sign.shape}, "
                                 f"{count.shape}")
            if count.min(initial=0) < 0 or count.max(initial=0) > d:
                raise ValueError(f"count_{i} outside [0, {d}]")
            used = np.arange(d)[:, None, None] < count[None]
            if np.any(used & ~((depth >= 0) & (depth <= 1))) or np.any(~used & (depth != np.inf)):
                raise ValueError(f"depth_{i}: used layers must lie in [0, 1], unused be +inf")
            if np.any(depth[1:] < depth[:-1]):
                raise ValueError(f"depth_{i}: layers are not sorted front to back")
            if np.any(used & (np.abs(sign) != 1)) or np.any(~used & (sign != 0)):
                raise ValueError(f"sign_{i}: used layers must be ±1, unused 0")
            ldis.append(_AxisLDI(name, basis, matrix, depth, sign, count))
        extra = set(data) - {"format", "version", "axes", "G", "scale"} - {
            f"{k}_{i}" for i in range(len(axes))
            for k in ("basis", "matrix", "depth", "sign", "count")}
        if extra:
            raise ValueError(f"unexpected arrays {sorted(extra)}")
        return cls(center, scale, ldis)
