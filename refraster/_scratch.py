"""Reused intermediate arrays of a frame (the default environment as fast as a tuned one).

A frame of ``render`` makes ~20 intermediate arrays (clip coordinates, per-vertex window
positions, per-face classes and boxes, tile lists; ~6 MB for an 82k-face mesh). With glibc's
default malloc settings, arrays of this size are returned to the system when freed and
page-faulted in again by the next frame (``GLIBC_TUNABLES`` malloc tuning avoids it; users do
not have it). :func:`frame_scratch` gives ``render``'s fused path one :class:`Scratch` per
thread whose buffers outlive the frame: ``zeros`` hands out a zero-filled view of a kept
buffer, the same bytes ``np.zeros`` would give.

Only arrays that die with the frame come from here: never an array ``render`` returns, nor one
a :class:`~refraster.Framebuffer` (or its pending colour) keeps, nor any array of the public
``refraster.raster.prepare`` (which does not use a scratch). Two frames in one thread never
overlap (the fused path calls no user code), and each thread has its own buffers.
"""

from __future__ import annotations

import math
import threading

import numpy as np

#: A thread keeps at most this many bytes of scratch; larger requests get fresh arrays.
MAX_BYTES = 256 << 20
#: ``render`` uses the scratch from this many faces up (16 bytes of boxes per face: 128 KiB, the
#: size from which glibc's malloc starts with fresh ``mmap`` pages).
SCRATCH_FACES = 8192

_local = threading.local()


class Scratch:
    """Named buffers reused from frame to frame (one frame at a time)."""

    def __init__(self):
        self._bufs = {}

    @property
    def nbytes(self):
        return sum(b.nbytes for b in self._bufs.values())

    def zeros(self, key, shape, dtype):
        """A zero-filled C-contiguous array of ``shape`` and ``dtype`` (as ``np.zeros``),
        a view of the buffer named ``key``: valid until ``key`` is asked for again."""
        dtype = np.dtype(dtype)
        shape = (int(shape),) if isinstance(shape, (int, np.integer)) else \
            tuple(int(s) for s in shape)
        n = math.prod(shape) * dtype.itemsize
        buf = self._bufs.get(key)
        if buf is None or buf.nbytes < n:
            size = max(n + n // 4, 64)   # room to grow a little without a new buffer
            if self.nbytes - (0 if buf is None else buf.nbytes) + size > MAX_BYTES:
                self._bufs.pop(key, None)
                return np.zeros(shape, dtype)
            buf = np.empty(size, np.uint8)
            self._bufs[key] = buf
        a = buf[:n].view(dtype).reshape(shape)
        a.fill(0)
        return a

    def clear(self):
        self._bufs.clear()


def frame_scratch():
    """This thread's :class:`Scratch`."""
    s = getattr(_local, "scratch", None)
    if s is None:
        s = _local.scratch = Scratch()
    return s
