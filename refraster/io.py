"""Atomic file writers: write to a temporary name in the same directory, then rename.

A reader never sees a half-written file, and a failed write leaves the old file untouched.
"""

from __future__ import annotations

import io
import json
import os
import stat
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["atomic_write_bytes", "write_png", "write_npz", "write_json", "to_uint8", "npy_bytes",
           "npz_bytes"]


def atomic_write_bytes(path, data: bytes):
    """Write ``data`` to ``path`` atomically (same-directory temporary file + ``os.replace``)."""
    path = Path(path)
    try:
        st = os.stat(path)   # a FIFO, socket or device there (or a link to one) is never replaced
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = next((word for test, word in (
            (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
            (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
            (stat.S_ISDIR, "a directory")) if test(st.st_mode)), "not a regular file")
        raise ValueError(f"{path} is {kind}, not a regular file; refraster writes only regular "
                         "files")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates 0600; a written file should have the usual permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def to_uint8(image):
    """Float image in [0, 1] (clipped; NaN → 0) or uint8 → uint8."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return a
    a = np.nan_to_num(a.astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return (np.clip(a, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def write_png(path, image):
    """Write an ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` image (float in [0, 1], uint8 or
    uint16) as PNG, atomically. Row 0 is the top of the picture."""
    import imageio.v3 as iio
    a = np.asarray(image)
    if a.dtype != np.uint16:
        a = to_uint8(a)
    buf = io.BytesIO()
    iio.imwrite(buf, np.ascontiguousarray(a), extension=".png")
    return atomic_write_bytes(path, buf.getvalue())


def npy_bytes(array):
    """``.npy`` bytes of ``array`` (never pickled; 0-d arrays stay 0-d)."""
    a = np.asarray(array)
    if a.dtype == object:
        raise TypeError("an array of dtype object cannot be stored without pickle")
    buf = io.BytesIO()
    np.lib.format.write_array(buf, a if a.flags.c_contiguous else a.copy(order="C"),
                              allow_pickle=False)
    return buf.getvalue()


def npz_bytes(arrays):
    """A compressed ``.npz`` of ``arrays`` whose bytes depend on the arrays only.

    ``numpy.savez_compressed`` stamps each member with the current time, so two runs would hash
    differently; here every member has the zip epoch (1980-01-01), mode 0644, and names are
    sorted. No object arrays: the file loads without pickle.
    """
    import zipfile
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            try:
                data = npy_bytes(arrays[name])
            except TypeError:
                raise TypeError(f"array {name!r} has dtype object and cannot be stored "
                                "without pickle") from None
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, data)
    return buf.getvalue()


def write_npz(path, **arrays):
    """Write arrays to a compressed ``.npz`` atomically; the bytes depend only on the arrays."""
    return atomic_write_bytes(path, npz_bytes(arrays))


def write_json(path, obj):
    """Write JSON (sorted keys, 2-space indent, trailing newline) atomically."""
    text = json.dumps(obj, indent=2, sort_keys=True) + "\n"
    return atomic_write_bytes(path, text.encode("utf-8"))
