"""The prefetch hint (``refraster.raster._prefetch``) reads and writes nothing a kernel sees.

The kernels that use it (``finalize``, ``shade``, the fused tile pass) are held to their
bytes by the entry digests; here the intrinsic itself: rows inside and far outside an array
(a hint never faults), any integer type, and nothing written."""

import numpy as np
import pytest
from numba import njit

from refraster.raster._prefetch import prefetch_row


@njit(cache=False)
def _touch(a, rows):
    total = 0.0
    for r in rows:
        prefetch_row(a, r)
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            total += a[i, j]
    return total


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint64])
def test_prefetch_changes_nothing_and_never_faults(dtype):
    a = np.random.default_rng(1).random((8, 3))   # no zero bytes to hide a stray write
    before = a.copy()
    rows = np.array([0, 7, 3, 1 << 30, 0], dtype=dtype)   # far past the end: still harmless
    if np.issubdtype(dtype, np.signedinteger):
        rows = np.append(rows, dtype(-(1 << 30)))
    assert _touch(a, rows) == _touch(before, rows[:0])
    assert np.array_equal(a, before)


def test_prefetch_of_a_strided_view_reads_nothing():
    base = np.random.default_rng(2).random((10, 6)).astype(np.float32)
    view = base[::2, ::3]               # rows 2·6 elements apart: the stride, not the width
    before = base.copy()
    assert _touch(view, np.arange(5)) == _touch(view.copy(), np.arange(0))
    assert np.array_equal(base, before)
