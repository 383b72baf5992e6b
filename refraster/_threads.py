"""How many threads a frame's parallel kernels use: serial for small work and on busy cores.

Numba's parallel kernels (``prange``) split their loop over ``numba.get_num_threads()`` threads
and wait for all of them at the end of each kernel. A frame runs 4–6 such kernels. On a core
another process is using, the thread that must finish a kernel's share may wait a whole
scheduler time slice (milliseconds) before it runs, and the frame waits with it: measured with
two other CPU-bound processes on the 2 cores, a 12-face cube took ~90 ms with 2 threads and
~1 ms with 1. And for a small frame, waking a second thread costs more than it saves.

So :func:`frame_threads` (used by ``render``, ``draw`` and the pending colour shade) chooses
per frame, once, before the first kernel:

* ``1`` when the frame is small (:data:`SMALL_WORK`: faces + pixels / 4 below 16,384 — a
  small mesh at 160×120, the golden size, is ~5k; the cube at 512×384 ~49k; the 82k-face
  frame at 1024×768 ~278k): one thread does such a frame in well under a millisecond, and
  waking a second one for each of its kernels costs about what it would save;
* otherwise Numba's current thread count (``NUMBA_NUM_THREADS`` or ``numba.set_num_threads``,
  the user's cap), lowered to the cores other processes leave free: the number of runnable
  tasks in ``/proc/loadavg`` (an instantaneous count, read in ~10 µs) minus up to this
  process's own threads, against the CPUs this process may run on. Never below 1. Not lowered
  when idle workers sleep instead of spinning (``OMP_WAIT_POLICY=passive`` with the ``omp``
  layer, or the ``workqueue`` layer): the collapse comes from libgomp's default of spinning
  workers — the spinning thread holds a core the descheduled one needs — and with passive
  waiting 2 threads stayed faster than 1 on the busy cores (docs/performance.md).

Override with ``REFRASTER_THREADS``, read on every frame: ``auto`` (the default, above) or an
integer ``N`` — exactly ``min(N, numba.config.NUMBA_NUM_THREADS)`` threads for every frame,
small or not, busy or not (``REFRASTER_THREADS=2`` gives the plain Numba behaviour back).

The thread count never changes a byte of output: every parallel kernel writes disjoint slices
and the outputs are bit-identical for any thread count (tests/test_raster.py).

The threading layer is Numba's default: ``tbb`` first, and refraster depends on the ``tbb``
package, so an ordinary install runs on TBB, which is safe both for several Python threads
rendering at once and for a process that forks after rendering (docs/reliability.md). Without
it Numba takes ``omp`` (GNU libgomp on Linux), then ``workqueue``. refraster sets neither the
layer nor ``OMP_WAIT_POLICY``/``GOMP_SPINCOUNT``/``KMP_BLOCKTIME``, since both are read once
per process and belong to the application. With omp's default (spinning) policy, being serial
on busy cores is what avoids the collapse; an application that sets ``OMP_WAIT_POLICY=passive``
before Numba's first parallel kernel keeps both threads on busy cores too. ``workqueue`` is not
safe for several Python threads rendering at once (Numba aborts); ``omp`` is, but GNU OpenMP
cannot run in a process forked after it started: Numba terminates such a child at its first
parallel kernel, whatever the thread count. :func:`check_fork` turns that into one line
(``RuntimeError``) at the start of every frame of a forked child under GNU OpenMP, instead of a
killed worker and a ``multiprocessing.Pool`` that never returns.
"""

from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager

import numba

#: Below this much work (faces + pixels / 4) a frame runs on one thread.
SMALL_WORK = 16384

_local = threading.local()


def _cpus():
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):   # not Linux
        return os.cpu_count() or 1


_LOADAVG = [None]   # a descriptor of /proc/loadavg kept open (non-inheritable), or False


def _runnable():
    """Runnable tasks on the machine now (``/proc/loadavg``'s fourth field), or None. Read with
    one ``pread`` on a descriptor kept open (~1 µs; opening, reading and closing the file each
    frame took ~10 µs and three system calls)."""
    fd = _LOADAVG[0]
    try:
        if fd is None:
            fd = _LOADAVG[0] = os.open("/proc/loadavg", os.O_RDONLY)
        elif fd is False:
            return None
        return int(os.pread(fd, 128, 0).split()[3].split(b"/")[0])
    except (OSError, ValueError, IndexError):
        _LOADAVG[0] = False   # not Linux, or an unexpected format: no load to read
        return None


def _override():
    v = os.environ.get("REFRASTER_THREADS", "auto").strip().lower()
    if v in ("", "auto"):
        return None
    try:
        n = int(v)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"REFRASTER_THREADS must be 'auto' or a positive integer, got {v!r}")
    return min(n, numba.config.NUMBA_NUM_THREADS)


_PASSIVE = None


def _waits_passively():
    """Whether idle worker threads sleep rather than spin: the ``workqueue`` layer, or the
    ``omp`` layer with ``OMP_WAIT_POLICY=passive`` (or ``GOMP_SPINCOUNT=0``) in the environment
    when this was first asked (libgomp reads it once, when Numba loads it)."""
    global _PASSIVE
    if _PASSIVE is None:
        try:
            layer = numba.threading_layer()
        except ValueError:   # not launched yet: decide on the next frame
            return False
        env = os.environ
        _PASSIVE = layer == "workqueue" or (layer == "omp" and (
            env.get("OMP_WAIT_POLICY", "").strip().lower() == "passive"
            or env.get("GOMP_SPINCOUNT", "").strip() == "0"))
    return _PASSIVE


def frame_threads(work):
    """Threads for a frame of ``work`` (faces + pixels / 4); see the module docstring."""
    n = _override()
    if n is not None:
        return n
    cap = numba.get_num_threads()
    if cap <= 1 or work < SMALL_WORK:
        return 1
    if _waits_passively():   # sleeping workers do not collapse on busy cores (measured)
        return cap
    running = _runnable()
    if running is None:
        return cap
    # our own threads may be among the runnable ones (the caller, and workers still spinning
    # after the previous kernel): count them as ours, the rest as other processes'
    others = max(running - cap, 0)
    return max(1, min(cap, _cpus() - others))


#: Set in a child forked after this process ran a parallel kernel on GNU OpenMP.
_FORKED_FROM_GOMP = [False]


def _after_fork_in_child():
    try:
        layer = numba.threading_layer()
    except ValueError:   # no parallel kernel ran before the fork: the child launches its own
        return
    omp = sys.modules.get("numba.np.ufunc.omppool")
    if layer == "omp" and getattr(omp, "openmp_vendor", "GNU") == "GNU":
        _FORKED_FROM_GOMP[0] = True


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def check_fork():
    """Raise one line in a child forked after its parent ran parallel kernels on GNU OpenMP
    (every parallel kernel there is terminated by Numba): called before a frame's kernels."""
    if _FORKED_FROM_GOMP[0]:
        raise RuntimeError(
            "refraster cannot run in this process: it was forked after its parent ran Numba "
            "kernels on GNU OpenMP, which Numba terminates in a forked child; install tbb "
            "(a refraster dependency; Numba then uses it unless NUMBA_THREADING_LAYER says "
            "otherwise) or start processes with the 'spawn' or 'forkserver' method")


def frame_work(n_faces, width, height):
    return int(n_faces) + (int(width) * int(height)) // 4


@contextmanager
def threads_for(work=None, n=None):
    """Run the body with :func:`frame_threads`\\ (``work``) threads (or ``n``), unless an
    enclosing frame of this thread has already chosen; restores Numba's count afterwards.
    In a forked child that cannot run parallel kernels, raises first (:func:`check_fork`)."""
    check_fork()
    if getattr(_local, "active", False):
        yield numba.get_num_threads()
        return
    if n is None:
        n = frame_threads(work)
    old = numba.get_num_threads()
    _local.active = True
    try:
        if n != old:
            numba.set_num_threads(n)
        yield n
    finally:
        if n != old:
            numba.set_num_threads(old)
        _local.active = False
