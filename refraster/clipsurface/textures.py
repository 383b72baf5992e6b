"""Textures the user gives the caps: diffuse, normal and light maps of a clip surface
(Trapp & Döllner, Sec. 4.1: "a CS can be extended with further attributes (e.g., normal,
diffuse, and light texture maps)"; the Fig. 10 insets) and a 3D texture for solid texturing
(Fig. 11).

* :class:`CapTextures` — 2D maps addressed with the surface's own ``(s, t)`` (Eq. 2, so the
  surface's scale Sx, Sy tiles them as it tiles the offset map) and filtered with the
  surface's wrap mode and ``GL_LINEAR``, exactly as the offset map (:func:`sample_texture`).
* :class:`SolidTexture` — a volume ``(D, H, W[, C])`` sampled with trilinear ``GL_LINEAR`` at
  the cap point in the solid's **object space** (:func:`sample_volume`), so one solid's caps
  of several surfaces cut one continuous block of material.

Texel order as for offset maps (MATH.md §1.2b): ``tex[row, col]`` with ``col ↔ s`` and
``row ↔ t``, row 0 at ``t = 0``; an image file is flipped on loading (its bottom row becomes
row 0). A volume is ``vol[slice, row, col]`` with ``col ↔ s ↔ x``, ``row ↔ t ↔ y`` and
``slice ↔ r ↔ z``.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit, prange

from .._config import PJIT
from .._validate import as_float_array
from .offsetmaps import WRAP_MODES, _wrap_texel, as_wrap, bilinear_taps, unit_dtype, unit_range

__all__ = ["CapTextures", "SolidTexture", "as_texture", "load_texture", "sample_texture",
           "sample_volume", "decode_normals"]


def _unit_values(arr, name):
    """uint8 → /255, uint16 → /65535, float checked to lie in [0, 1]; float64, C order."""
    return unit_range(unit_dtype(arr, name), name)


def load_texture(path, name="texture"):
    """Read an image file (anything imageio reads) as a texture in texel order: ``(H, W, C)``
    float64 in [0, 1], the file's bottom row as row 0 (t = 0)."""
    import imageio.v3 as iio
    try:
        image = np.asarray(iio.imread(path))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{name}: cannot read image {os.fspath(path)!r} ({exc})") from None
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3:
        raise ValueError(f"{name}: {os.fspath(path)} is not a 2D image (shape {image.shape})")
    return _unit_values(image[::-1], f"{name} ({os.fspath(path)})")


def as_texture(texture, name="texture", channels=(1, 3), *, gray=True):
    """A texture given as an array ``(H, W)`` / ``(H, W, C)`` in texel order, or as an image
    file path → read-only ``(H, W, C)`` float64 in [0, 1] with C in ``channels``.

    A fourth (alpha) channel is dropped when 3 channels are wanted: caps are opaque. One
    channel is repeated when 3 are wanted and ``gray`` (a gray texture)."""
    if isinstance(texture, (str, os.PathLike)):
        arr = load_texture(texture, name)
    else:
        if texture is None or isinstance(texture, bytes):
            raise TypeError(f"{name} must be an array or an image file path, "
                            f"got {type(texture).__name__}")
        arr = np.asarray(texture)
        if arr.ndim == 2:
            arr = arr[:, :, None]
        if arr.ndim != 3:
            raise ValueError(f"{name} must be (H, W) or (H, W, C), got shape {arr.shape}")
        arr = _unit_values(arr, name)
    c = arr.shape[2]
    if 3 in channels and c == 4:
        arr = arr[:, :, :3]
    elif 3 in channels and c == 1 and 1 not in channels and gray:
        arr = np.repeat(arr, 3, axis=2)
    if arr.shape[2] not in channels:
        raise ValueError(f"{name} must have {' or '.join(map(str, channels))} channel(s), "
                         f"got {arr.shape[2]}")
    arr = np.ascontiguousarray(arr, np.float64)
    arr.setflags(write=False)
    return arr


def decode_normals(encoded):
    """Normal-map texels ``c ∈ [0, 1]³`` → components along (Û, V̂, N) of the clip surface.

    The encoding is the usual tangent-space one, ``n = 2c − 1`` with x along Û, y along V̂ and
    z pointing out of the cap towards its viewer, i.e. along −N (a flat texel (½, ½, 1) is the
    undisplaced cap's normal −N, the derived normal map's (0, 0, −1)). Not normalized here:
    the bilinear sample is normalized after the turn into eye space, as for the derived map.
    """
    n = 2.0 * np.asarray(encoded, np.float64) - 1.0
    return np.ascontiguousarray(np.stack([n[..., 0], n[..., 1], -n[..., 2]], axis=-1))


class CapTextures:
    """Diffuse, normal and light maps of a clip surface's caps (Sec. 4.1, Fig. 10 insets).

    Parameters
    ----------
    diffuse : (H, W), (H, W, 3|4) array or image path, optional
        The cap's base colour, replacing ``Caps.color`` (style ``"diffuse"``).
    normal : (H, W, 3) array or image path, optional
        Encoded tangent-space normals (:func:`decode_normals`), replacing the normal map
        derived from the offset map.
    light : (H, W) array or image path (gray), optional
        A light map multiplying the shade, replacing the derived occlusion map.

    All three are addressed with the surface's ``(s, t)`` and filtered as the offset map
    (``GL_LINEAR``, the surface's wrap mode); each may have its own resolution.
    """

    def __init__(self, diffuse=None, normal=None, light=None):
        self.diffuse = None if diffuse is None else as_texture(diffuse, "diffuse", (3,))
        self.normal = None if normal is None else as_texture(normal, "normal", (3,),
                                                             gray=False)
        self.light = None if light is None else as_texture(light, "light", (1,))
        if self.diffuse is None and self.normal is None and self.light is None:
            raise ValueError("CapTextures needs at least one of diffuse, normal, light")
        self._decoded = None

    @property
    def normal_frame(self):
        """The normal map decoded into (Û, V̂, N) components, ``(H, W, 3)`` (read-only)."""
        if self.normal is not None and self._decoded is None:
            d = decode_normals(self.normal)
            d.setflags(write=False)
            self._decoded = d
        return self._decoded

    def __repr__(self):
        shapes = {k: getattr(self, k).shape for k in ("diffuse", "normal", "light")
                  if getattr(self, k) is not None}
        return f"CapTextures({shapes})"


class SolidTexture:
    """A 3D texture for solid texturing of caps (Fig. 11; Kopf et al.'s solid textures).

    Parameters
    ----------
    volume : (D, H, W) or (D, H, W, 3|4) array, or a ``.npy`` file of one
        uint8, uint16 or float in [0, 1]; ``vol[slice, row, col]``, col ↔ x, row ↔ y,
        slice ↔ z.
    origin, size : (3,) float, optional
        The object-space box the volume spans once: ``(s, t, r) = (p − origin) / size``.
        Default: each solid's own object-space bounding box.
    wrap : {"repeat", "clamp_to_edge", "mirrored_repeat"}
        Outside the box (OpenGL 4.6 Table 8.20, per axis).
    """

    def __init__(self, volume, *, origin=None, size=None, wrap="repeat"):
        if isinstance(volume, (str, os.PathLike)):
            try:
                volume = np.load(volume, allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise ValueError(f"volume: cannot read {os.fspath(volume)!r} ({exc})") from None
        if volume is None or isinstance(volume, bytes):
            raise TypeError(f"volume must be an array or a .npy path, "
                            f"got {type(volume).__name__}")
        arr = np.asarray(volume)
        if arr.ndim == 3:
            arr = arr[..., None]
        if arr.ndim != 4:
            raise ValueError(f"volume must be (D, H, W) or (D, H, W, C), got shape {arr.shape}")
        arr = _unit_values(arr, "volume")
        if arr.shape[3] == 4:
            arr = arr[..., :3]
        elif arr.shape[3] == 1:
            arr = np.repeat(arr, 3, axis=3)
        if arr.shape[3] != 3:
            raise ValueError(f"volume must have 1, 3 or 4 channels, got {arr.shape[3]}")
        self.volume = np.ascontiguousarray(arr)
        self.volume.setflags(write=False)
        self.origin = None if origin is None else as_float_array(origin, "origin", shape=(3,))
        self.size = None if size is None else as_float_array(size, "size", shape=(3,))
        if self.size is not None and not np.all(self.size > 0):
            raise ValueError(f"size must be positive, got {self.size}")
        if (self.origin is None) != (self.size is None):
            raise ValueError("give both origin and size, or neither (the solid's box)")
        self.wrap = as_wrap(wrap)

    def texcoords(self, points, bounds=None):
        """``(s, t, r)`` of object-space points; ``bounds`` (lo, hi) is the solid's box, used
        when the texture has no origin and size of its own."""
        p = as_float_array(points, "points", shape=(None, 3))
        if self.origin is not None:
            origin, size = self.origin, self.size
        else:
            lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
            origin, size = lo, np.where(hi > lo, hi - lo, 1.0)
        return (p - origin) / size

    def sample(self, points, bounds=None):
        """Colours ``(N, 3)`` at object-space points (trilinear, :func:`sample_volume`)."""
        return sample_volume(self.volume, self.texcoords(points, bounds), wrap=self.wrap)

    def __repr__(self):
        return f"SolidTexture(volume={self.volume.shape}, wrap={self.wrap!r})"


# --------------------------------------------------------------------------------------------
# samplers (GL_LINEAR; the same texel arithmetic as the offset map's texture2D)


@njit(**PJIT)
def _sample2d_kernel(tex, height, width, st, mode, out):
    for n in prange(st.shape[0]):
        a, b, c, d, wa, wb, wc, wd = bilinear_taps(0, height, width, st[n, 0], st[n, 1], mode)
        for k in range(tex.shape[1]):
            out[n, k] = wa * tex[a, k] + wb * tex[b, k] + wc * tex[c, k] + wd * tex[d, k]


def _readonly(a):
    """``a`` as a read-only view (no copy): read-only and writable arrays are distinct Numba
    types, so passing only read-only ones compiles each sampling kernel once, not twice."""
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


def sample_texture(texture, st, *, wrap="repeat"):
    """``texture2D(tex, st)`` with ``GL_LINEAR`` for a multi-channel texture ``(H, W, C)``
    (texel order) at ``st (N, 2)`` → ``(N, C)`` float64. The texel arithmetic is the offset
    map's (:func:`refraster.clipsurface.offsetmaps.sample`), per channel."""
    tex = np.asarray(texture, np.float64)
    if tex.ndim == 2:
        tex = tex[:, :, None]
    if tex.ndim != 3 or tex.shape[0] == 0 or tex.shape[1] == 0:
        raise ValueError(f"texture must be (H, W) or (H, W, C), got shape {tex.shape}")
    st = as_float_array(st, "st", shape=(None, 2))
    h, w, c = tex.shape
    out = np.zeros((st.shape[0], c))
    if st.shape[0]:
        _sample2d_kernel(_readonly(np.ascontiguousarray(tex.reshape(h * w, c))), h, w,
                         np.ascontiguousarray(st), WRAP_MODES[as_wrap(wrap)], out)
    return out


#: Texel coordinates are clamped to ±2**52 before the integer conversion (as in offsetmaps).
_COORD_LIMIT = 2.0 ** 52


@njit(**PJIT)
def _sample3d_kernel(vol, depth, height, width, str_, mode, out):
    for n in prange(str_.shape[0]):
        x = min(max(str_[n, 0] * width - 0.5, -_COORD_LIMIT), _COORD_LIMIT)
        y = min(max(str_[n, 1] * height - 0.5, -_COORD_LIMIT), _COORD_LIMIT)
        z = min(max(str_[n, 2] * depth - 0.5, -_COORD_LIMIT), _COORD_LIMIT)
        fx = math.floor(x)
        fy = math.floor(y)
        fz = math.floor(z)
        ax = x - fx
        ay = y - fy
        az = z - fz
        i0 = _wrap_texel(np.int64(fx), width, mode)
        i1 = _wrap_texel(np.int64(fx) + 1, width, mode)
        j0 = _wrap_texel(np.int64(fy), height, mode)
        j1 = _wrap_texel(np.int64(fy) + 1, height, mode)
        k0 = _wrap_texel(np.int64(fz), depth, mode)
        k1 = _wrap_texel(np.int64(fz) + 1, depth, mode)
        w00 = (1.0 - ax) * (1.0 - ay)
        w10 = ax * (1.0 - ay)
        w01 = (1.0 - ax) * ay
        w11 = ax * ay
        for c in range(vol.shape[3]):
            lo = (w00 * vol[k0, j0, i0, c] + w10 * vol[k0, j0, i1, c]
                  + w01 * vol[k0, j1, i0, c] + w11 * vol[k0, j1, i1, c])
            hi = (w00 * vol[k1, j0, i0, c] + w10 * vol[k1, j0, i1, c]
                  + w01 * vol[k1, j1, i0, c] + w11 * vol[k1, j1, i1, c])
            out[n, c] = (1.0 - az) * lo + az * hi


def sample_volume(volume, str_, *, wrap="repeat"):
    """``texture3D(vol, str)`` with ``GL_LINEAR`` (trilinear) for a volume ``(D, H, W, C)`` at
    ``str (N, 3)`` → ``(N, C)``: ``u = s·W − ½``, ``i0 = wrap(⌊u⌋)``, ``i1 = wrap(⌊u⌋ + 1)``,
    ``α = frac(u)``, likewise t with H and r with D (OpenGL 4.6 §8.14.2, Table 8.20)."""
    vol = np.asarray(volume, np.float64)
    if vol.ndim == 3:
        vol = vol[..., None]
    if vol.ndim != 4 or 0 in vol.shape:
        raise ValueError(f"volume must be (D, H, W) or (D, H, W, C), got shape {vol.shape}")
    p = as_float_array(str_, "str", shape=(None, 3))
    d, h, w, c = vol.shape
    out = np.zeros((p.shape[0], c))
    if p.shape[0]:
        _sample3d_kernel(_readonly(np.ascontiguousarray(vol)), d, h, w, np.ascontiguousarray(p),
                         WRAP_MODES[as_wrap(wrap)], out)
    return out
