"""Buffer kinds: how each golden buffer is stored, read back from PNG, previewed and toleranced.

==========  =================================  ==========================================
kind        values                             PNG a candidate may send
==========  =================================  ==========================================
``unorm``   float in [0, 1] (window depth,     8/16-bit grey or RGB, ``value = png / max``
            barycentrics)
``snorm``   float in [−1, 1] (normals)         8/16-bit RGB, ``value = 2·png / max − 1``
``color``   float RGB in [0, 1], display       8/16-bit RGB or RGBA (alpha dropped),
            values (no gamma conversion)       ``value = png / max``
``float``   any float, ±inf allowed            none: ``.npy`` / ``.npz`` only
            (eye depth)
``id``      integer, −1 background             16-bit grey, ``value = png − 1``
``bool``    bool                               8-bit grey, ``value = png != 0``
==========  =================================  ==========================================

``max`` is 255 or 65535; the compare widens a buffer's threshold to one PNG step for a
candidate sent as PNG (a quantised picture cannot do better).
"""

from __future__ import annotations

import numpy as np

__all__ = ["KINDS", "GBUFFER_KINDS", "infer_kind", "preview", "preview_range", "peak",
           "png_decode", "DTYPES"]

KINDS = ("unorm", "snorm", "float", "id", "bool", "color")
#: dtypes a golden buffer may have.
DTYPES = ("float32", "float64", "int32", "int64", "uint8", "uint16", "bool")

#: Kinds of :meth:`refraster.Framebuffer.arrays`.
GBUFFER_KINDS = dict(depth="unorm", eye_depth="float", normal="snorm", prim_id="id",
                     object_id="id", front_facing="bool", barycentric="unorm", color="color")


def infer_kind(name, array):
    """The kind of a buffer: the G-buffer's own, else from its dtype and values."""
    if name in GBUFFER_KINDS:
        return GBUFFER_KINDS[name]
    a = np.asarray(array)
    if a.dtype == np.bool_:
        return "bool"
    if np.issubdtype(a.dtype, np.integer):
        return "id"
    finite = np.isfinite(a)
    if finite.all() and a.size and a.min() >= 0.0 and a.max() <= 1.0:
        return "color" if "color" in name and a.ndim == 3 and a.shape[2] == 3 else "unorm"
    if finite.all() and a.size and a.min() >= -1.0 and a.max() <= 1.0:
        return "snorm"
    return "float"


def peak(reference, kind):
    """The signal peak used by PSNR: the kind's value range, or the reference's finite range."""
    if kind in ("unorm", "color", "bool"):
        return 1.0
    if kind == "snorm":
        return 2.0
    r = np.asarray(reference, np.float64)
    r = r[np.isfinite(r)]
    span = float(r.max() - r.min()) if r.size else 0.0
    return span if span > 0 else 1.0


def preview_range(reference, kind):
    """(lo, hi) that maps the reference's values onto a visible grey ramp (``unorm`` depth is
    stretched over its covered range so the shape shows); used for the candidate too."""
    if kind in ("color", "snorm", "bool", "id"):
        return (0.0, 1.0)
    r = np.asarray(reference, np.float64)
    r = r[np.isfinite(r)]
    if kind == "unorm" and r.size:
        r = r[r < 1.0] if np.any(r < 1.0) else r
    if not r.size:
        return (0.0, 1.0)
    lo, hi = float(r.min()), float(r.max())
    return (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)


def _id_colours(ids):
    """A stable colour per id (Knuth multiplicative hash); white for −1."""
    h = (ids.astype(np.int64) * 2654435761) & 0xFFFFFFFF
    rgb = np.stack([(h >> 8) & 0xFF, (h >> 16) & 0xFF, (h >> 24) & 0xFF], axis=-1)
    rgb = 48 + (rgb * 176) // 255
    rgb[ids < 0] = 255
    return rgb.astype(np.uint8)


def preview(array, kind, vrange):
    """An (H, W, 3) uint8 picture of a buffer for humans (not for comparison)."""
    a = np.asarray(array)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if kind == "id":
        return _id_colours(a if a.ndim == 2 else a[..., 0])
    x = a.astype(np.float64)
    if kind == "snorm":
        x = x * 0.5 + 0.5
    elif kind not in ("bool", "color"):
        lo, hi = vrange
        with np.errstate(invalid="ignore", over="ignore"):
            x = (x - lo) / (hi - lo)
    x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(x, 0.0, 1.0)
    if x.ndim == 2:
        x = np.repeat(x[..., None], 3, axis=2)
    elif x.shape[2] < 3:
        x = np.concatenate([x, np.zeros(x.shape[:2] + (3 - x.shape[2],))], axis=2)
    return (x[..., :3] * 255.0 + 0.5).astype(np.uint8)


def png_decode(image, kind, reference_shape):
    """Turn a decoded PNG (uint8 or uint16) into buffer values of ``kind``.

    Returns ``(values, step)``: ``step`` is the quantisation step of the encoding (0 for exact
    encodings). Raises ``ValueError`` when the kind has no PNG encoding or the picture does not
    fit.
    """
    img = np.asarray(image)
    if img.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"a PNG candidate must be 8- or 16-bit, got {img.dtype}")
    top = float(np.iinfo(img.dtype).max)
    channels = reference_shape[2] if len(reference_shape) == 3 else 0
    if kind == "color" and img.ndim == 3 and img.shape[2] == 4 and channels == 3:
        img = img[..., :3]
    if channels == 0 and img.ndim == 3:
        raise ValueError(f"expected a one-channel (grey) PNG, got {img.shape[2]} channels")
    if kind == "float":
        raise ValueError("a 'float' buffer (may hold ±inf) has no PNG encoding; send .npy/.npz")
    if kind == "id":
        if img.dtype != np.uint16:
            raise ValueError("ids are sent as 16-bit PNG (value = id + 1), got 8-bit")
        return img.astype(np.int64) - 1, 0.0
    if kind == "bool":
        return img != 0, 0.0
    x = img.astype(np.float64) / top
    if kind == "snorm":
        return x * 2.0 - 1.0, 2.0 / top
    return x, 1.0 / top
