"""Reused intermediate arrays of a frame (the default environment as fast as a tuned one).

A frame of ``render`` makes ~20 intermediate arrays (clip coordinates, per-vertex window
positions, per-face classes and boxes, tile lists; ~6 MB for an 82k-face mesh). With glibc's
default malloc settings, arrays of this size are returned to the system when freed and
page-faulted in again by the next frame (``GLIBC_TUNABLES`` malloc tuning avoids it; users do
not have it). :func:`frame_scratch` gives ``render``'s fused path one :class:`Scratch` per
thread whose buffers outlive the frame: ``empty`` hands out an unfilled view of a kept
buffer, for arrays the frame's kernels write whole (``render_samples`` takes it too).

Only arrays that die with the frame come from here: never an array ``render`` returns, nor one
a :class:`~refraster.Framebuffer` (or its pending colour) keeps, nor any array of the public
``refraster.raster.prepare`` (which does not use a scratch). Each thread has its own buffers,
and a frame takes them with :func:`scratch_lease`: a frame started on the same thread while
another is in progress (the fused path calls no user code, but a garbage-collector finalizer
or a signal handler may run between any two bytecodes and call ``render``) finds them taken
and allocates its own arrays (docs/reliability.md, re-entrancy).

The arrays a frame *does* return or keep come from :data:`OUTPUTS`, an :class:`OutputPool`
shared by all threads: it hands an array out again only once nothing else holds it.
"""

from __future__ import annotations

import ctypes
import math
import os
import sys
import threading
import weakref
from contextlib import contextmanager

import numpy as np

#: A thread keeps at most this many bytes of scratch; larger requests get fresh arrays.
MAX_BYTES = 256 << 20
#: ``render`` uses the scratch from this many faces up (16 bytes of boxes per face: 128 KiB, the
#: size from which glibc's malloc starts with fresh ``mmap`` pages).
SCRATCH_FACES = 8192

_local = threading.local()

#: Arrays from this many bytes up are filled by the C library (:func:`fill`).
FILL_MIN_BYTES = 1 << 16


def _wmemset():
    """The C library's ``wmemset`` where its ``wchar_t`` is 4 bytes (Linux, macOS), else None."""
    if ctypes.sizeof(ctypes.c_wchar) != 4:
        return None
    try:
        f = ctypes.CDLL(None).wmemset
    except (OSError, AttributeError):
        return None
    f.restype = ctypes.c_void_p
    f.argtypes = [ctypes.c_void_p, ctypes.c_int32, ctypes.c_size_t]
    return f


_WMEMSET = _wmemset()


def fill(a, value):
    """``a.fill(value)``, the same bytes: a large C-contiguous array whose element is one byte
    repeated (0, −1, False) is filled by ``memset``, one of 4 bytes (1.0, +inf, −1 as int32) by
    ``wmemset``; the C library's stores are full cache lines, about 1.3× NumPy's fill on a
    4× frame's 38 MB of barycentrics (docs/performance.md, "Output pool"). Others: NumPy's."""
    if (a.nbytes < FILL_MIN_BYTES or a.dtype.kind not in "biufc"
            or not (a.flags.c_contiguous and a.flags.writeable and a.flags.aligned)):
        a.fill(value)
        return
    one = np.empty(1, a.dtype)
    one.fill(value)
    pattern = one.tobytes()
    if pattern == pattern[:1] * len(pattern):
        ctypes.memset(a.ctypes.data, pattern[0], a.nbytes)
    elif len(pattern) == 4 and _WMEMSET is not None:
        _WMEMSET(a.ctypes.data, int.from_bytes(pattern, sys.byteorder, signed=True), a.size)
    else:
        a.fill(value)


class Scratch:
    """Named buffers reused from frame to frame (one frame at a time: :func:`scratch_lease`)."""

    def __init__(self):
        self._bufs = {}
        self._holder = None   # a weak reference to the token of the frame holding the buffers

    @property
    def in_use(self):
        return self._holder is not None and self._holder() is not None

    @property
    def nbytes(self):
        return sum(b.nbytes for b in self._bufs.values())

    def empty(self, key, shape, dtype):
        """A C-contiguous array of ``shape`` and ``dtype``, a view of the buffer named ``key``
        (valid until ``key`` is asked for again), not filled (as ``np.empty``): for an array
        whose every element the frame's kernels write before anything reads it
        (``tests/test_render_reuse.py`` poisons the buffers and compares the frame's arrays
        with those of a frame without the scratch)."""
        dtype = np.dtype(dtype)
        shape = (int(shape),) if isinstance(shape, (int, np.integer)) else \
            tuple(int(s) for s in shape)
        n = math.prod(shape) * dtype.itemsize
        buf = self._bufs.get(key)
        if buf is None or buf.nbytes < n:
            size = max(n + n // 4, 64)   # room to grow a little without a new buffer
            if self.nbytes - (0 if buf is None else buf.nbytes) + size > MAX_BYTES:
                self._bufs.pop(key, None)
                return np.empty(shape, dtype)
            buf = np.empty(size, np.uint8)
            self._bufs[key] = buf
        return buf[:n].view(dtype).reshape(shape)

    def clear(self):
        self._bufs.clear()


def frame_scratch():
    """This thread's :class:`Scratch`."""
    s = getattr(_local, "scratch", None)
    if s is None:
        s = _local.scratch = Scratch()
    return s


@contextmanager
def scratch_lease(wanted=True):
    """This thread's :class:`Scratch` for the body of a ``with`` (one frame), or None: when not
    ``wanted``, or when a frame of this thread already holds it (a ``render`` re-entered from a
    finalizer or a signal handler: that frame then allocates its own arrays, the same bytes)."""
    s = frame_scratch() if wanted else None
    if s is None or s.in_use:
        yield None
        return
    # held while this generator lives (no flag to reset: an exception that a signal handler
    # raises between two bytecodes could skip a reset, not the end of the generator)
    token = _Token()
    s._holder = weakref.ref(token)
    yield s
    del token


class _Token:
    __slots__ = ("__weakref__",)


# ---------------------------------------------------------------------------------------------
# Output arrays recycled once nobody holds them (issue 28 item 3)

#: Output arrays of at least this many bytes come from :data:`OUTPUTS` (smaller ones are below
#: glibc's initial mmap threshold and come from malloc's free lists without page faults).
POOL_MIN_BYTES = 64 << 10
#: ``REFRASTER_POOL_MB`` (default): the most bytes of outputs the pool keeps; 0 turns it off.
#: 512 MiB holds what the benchmarks drop and ask for again, each in its steady state: an
#: 8-layer peel at 1024² (244 MiB with its fragment stream), or the 1×, 4× and 8× G-buffers
#: of 1024×768 in turn (37, 135 and 270 MiB). At 256 the 8× frame evicts the 4× one's arrays
#: and each is new again (docs/performance.md, "The output pool").
POOL_MB = 512
#: At most this many arrays of one shape and dtype are kept (a frame asks for at most two:
#: depth and eye depth; normal and colour), so a user keeping a few frames alive still finds
#: one free and the scan stays short.
POOL_PER_KIND = 6


_LIMIT = [None, 0]   # the last REFRASTER_POOL_MB string read and its limit in bytes
#: Larger ``REFRASTER_POOL_MB`` values mean this many MiB (2**43 bytes, 8 TiB: no bound).
MAX_POOL_MB = float(1 << 23)


def _pool_limit():
    raw = os.environ.get("REFRASTER_POOL_MB", "")
    if raw == _LIMIT[0]:
        return _LIMIT[1]
    try:
        mb = float(raw) if raw.strip() else POOL_MB
    except ValueError:
        mb = POOL_MB   # a malformed value: the default (refraster info shows what is in use)
    if not math.isfinite(mb):
        mb = POOL_MB
    # a finite number of MiB too large for bytes (1e308 · 2**20 is inf) is no bound: at most
    # the largest size an array can have; negative is off
    _LIMIT[:] = [raw, int(min(max(mb, 0.0), MAX_POOL_MB) * (1 << 20))]
    return _LIMIT[1]


def pooling():
    """Whether the output pool keeps arrays (``REFRASTER_POOL_MB`` > 0): then a frame's outputs
    are recycled memory in the steady state, not fresh pages."""
    return _pool_limit() > 0


class OutputPool:
    """Arrays handed out as a frame's outputs (a new :class:`~refraster.Framebuffer`'s depth,
    eye depth, normal, ids, facing, barycentrics, its private face image and its colour),
    taken back when **nobody else holds them**.

    Why: with glibc's default malloc settings, a loop of frames that drops each framebuffer
    gives the freed output memory back to the system and page-faults it in again for the next
    frame — for a 512×384 frame ~1.3 ms of its ~1.5 ms, for the 82k-face frame at 1024×768
    ~2,400 faults (``docs/performance.md``). ``GLIBC_TUNABLES`` malloc tuning avoids it; users
    do not have it, and refraster changes no allocator setting. The pool keeps the memory of
    recent outputs and hands an array out again only when its reference count says the pool
    holds the only reference: no framebuffer, no view, slice, memoryview or ``np.frombuffer``
    of it, no pending colour, no other thread (each of them holds a reference to the array or
    to its base, which is this array), and no weak reference to it. The caller then writes
    every byte it would have written into a new array (``full``: the fill value; ``empty``: a
    kernel that writes every element), so a recycled array gives the same bytes as a new one. Like memory malloc reuses, a raw
    pointer (``a.ctypes.data``, ``__array_interface__``) kept past the array's life is not a
    reference. ``REFRASTER_POOL_MB`` (default 512) bounds the bytes kept (the oldest arrays are
    dropped first: one that is still held simply stays the user's); ``0`` (or a negative
    number) turns it off; a value that is not a finite number means the default, and one
    above :data:`MAX_POOL_MB` (8 TiB) means that much (no bound). One
    difference from a new array remains: a dropped frame's array cannot be resized in place
    (``ndarray.resize``) while the pool keeps it (NumPy's reference check sees the pool's
    reference).
    """

    def __init__(self):
        # reentrant: a finalizer run by a garbage collection inside the pool (an allocation
        # can trigger one), or a signal handler, may itself render in this thread; that
        # frame finds the lock already this thread's and gets new arrays, so the entries
        # never change under the scan of the frame it interrupted. (The lock's own record of
        # its owner, not a flag: a flag set inside ``with`` can be left set by an exception
        # a signal handler raises between two bytecodes; the ``with`` itself cannot.)
        self._lock = threading.RLock()
        self._entries = [np.empty(0)]   # the sentinel (see _scan), then arrays, oldest first

    def _reset_after_fork(self):
        # a fork while another thread held the lock would leave the child's copy locked
        self._lock = threading.RLock()

    def _scan(self, shape, dtype):
        """A kept array of ``shape`` and ``dtype`` that nobody else holds, or None.

        The first entry is a sentinel array only the list holds: its reference count is what
        a free entry shows. Every count is taken by ``map`` over the list, so no local
        variable (which a tracer, a debugger or a signal handler reading ``f_locals`` could
        copy into a dict and keep) names an entry while it is counted. An entry its last user
        changed in place (made read-only, unaligned, given other strides) is not what a new
        array is: it is dropped, never handed out.
        """
        counts = list(map(sys.getrefcount, self._entries))
        free = counts[0]
        for i in range(len(counts) - 1, 0, -1):   # most recently kept first
            if counts[i] > free:
                continue
            a = self._entries[i]
            # (a weak reference is no reference, but it still reaches the array, which the
            # pool keeps alive where a freed one would be dead: never reused)
            if a.shape != shape or a.dtype != dtype or weakref.getweakrefcount(a):
                continue
            if not (a.flags.writeable and a.flags.aligned and a.flags.c_contiguous):
                del self._entries[i]
                continue
            self._entries.append(self._entries.pop(i))   # most recently used last
            return a
        return None

    def empty(self, shape, dtype):
        """An array of ``shape`` and ``dtype`` whose contents are undefined (as ``np.empty``):
        recycled when a kept one is free, else new (and kept, within the limit)."""
        return self._get(shape, dtype, np.empty)[0]

    def zeros(self, shape, dtype):
        """As ``np.zeros(shape, dtype)``: a recycled array zero-filled, or a new one from
        ``np.zeros`` (``calloc``: memory fresh from the system is zero already, and is touched
        only where the caller writes — most of a 4× frame's barycentrics are background)."""
        a, recycled = self._get(shape, dtype, np.zeros)
        if recycled:
            fill(a, 0)
        return a

    def _get(self, shape, dtype, new):
        """``(array, recycled)``: a kept one that is free, else ``new(shape, dtype)``."""
        dtype = np.dtype(dtype)
        nbytes = math.prod(shape) * dtype.itemsize
        if nbytes < POOL_MIN_BYTES:
            return new(shape, dtype), False
        limit = _pool_limit()
        if self._lock._is_owned():   # re-entered in this thread: a new array, not kept
            return new(shape, dtype), False
        if limit <= 0:
            if len(self._entries) > 1:
                self.clear()
            return new(shape, dtype), False
        with self._lock:
            return self._take(shape, dtype, nbytes, limit, new)

    def _take(self, shape, dtype, nbytes, limit, new):
        a = self._scan(shape, dtype)
        if a is not None:
            return a, True
        a = new(shape, dtype)
        same = [k for k, b in enumerate(self._entries)
                if k and b.shape == shape and b.dtype == dtype]
        drop = set(same[:max(len(same) + 1 - POOL_PER_KIND, 0)])
        kept = self.nbytes + nbytes - sum(self._entries[k].nbytes for k in drop)
        for k, b in enumerate(self._entries):   # oldest first, until the new one fits
            if kept <= limit:
                break
            if k and k not in drop:
                drop.add(k)
                kept -= b.nbytes
        if kept <= limit:
            self._entries = [b for k, b in enumerate(self._entries) if k not in drop]
            self._entries.append(a)
        return a, False

    def full(self, shape, value, dtype):
        """As ``np.full(shape, value, dtype)`` (every element written)."""
        a = self.empty(shape, dtype)
        fill(a, value)
        return a

    @property
    def nbytes(self):
        """Bytes of the arrays kept (held by users or free); summed, not tracked, so an
        interrupt between two updates cannot make it drift."""
        return sum(e.nbytes for e in self._entries[1:])

    def __len__(self):
        return len(self._entries) - 1

    def clear(self):
        """Drop every kept array (those users hold stay theirs); not while this thread is
        inside the pool (a finalizer or signal handler run there: nothing is dropped)."""
        if self._lock._is_owned():
            return
        with self._lock:
            del self._entries[1:]


#: The process's output pool (one for all threads; a lock guards the scan).
OUTPUTS = OutputPool()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=OUTPUTS._reset_after_fork)
