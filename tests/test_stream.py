"""Streaming stores (``refraster.raster._stream``): ``fill_stretch`` writes exactly
``row[a:b] = v``, at any alignment, length and element size, with and without streaming.

``finalize``, which uses it for the background of frames larger than the last-level cache, is
held to its bytes by ``tests/test_gbuffer_paths.py::test_background_runs_of_every_length``
(both ways) and the entry digests; here the helper itself against NumPy, and (on x86) that the
streaming path really compiles to non-temporal stores and a fence."""

import platform

import numpy as np
import pytest
from numba import njit

from refraster.raster._stream import (STREAM_BYTES, STREAM_MIN_BYTES, fill_stretch,
                                      last_level_cache, stream_fence)


@njit(cache=False)
def _fill(row, a, b, v, stream):
    fill_stretch(row, np.uint64(a), np.uint64(b), v, stream)
    stream_fence()


_VALUES = [(np.float32, np.inf), (np.float32, 0.0), (np.int32, -1), (np.bool_, False),
           (np.float64, -2.5), (np.int64, -1)]


@pytest.mark.parametrize("stream", [False, True])
@pytest.mark.parametrize("dtype, value", _VALUES, ids=[f"{d.__name__}={v}" for d, v in _VALUES])
def test_fill_stretch_writes_exactly_the_stretch(dtype, value, stream):
    """Random stretches of random rows starting at every byte phase of the 32-byte blocks:
    the bytes equal NumPy's slice assignment, nothing before ``a`` or from ``b`` on written
    (the row sits inside a larger buffer of a different value)."""
    rng = np.random.default_rng(7)
    isz = np.dtype(dtype).itemsize
    lengths = list(rng.integers(1, 40, 60)) + list(rng.integers(STREAM_MIN_BYTES // isz,
                                                                  3000, 200))
    for n in lengths:
        n = int(n)
        pad = np.ones(n + 2 * STREAM_BYTES, dtype) if dtype is np.bool_ \
            else np.full(n + 2 * STREAM_BYTES, 7, dtype)
        off = int(rng.integers(0, STREAM_BYTES // isz + 1))
        row = pad[off:off + n]
        a = int(rng.integers(0, n))
        b = int(rng.integers(a, n + 1))
        expect = pad.copy()
        expect[off + a:off + b] = value
        _fill(row, a, b, dtype(value), stream)
        assert pad.tobytes() == expect.tobytes(), (n, off, a, b)


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"),
                    reason="the instruction names checked are x86's")
def test_streaming_path_compiles_to_non_temporal_stores():
    row = np.zeros(1024, np.float32)
    _fill(row, 0, 1024, np.float32(1.0), True)
    asm = "\n".join(_fill.inspect_asm().values())
    assert "movnt" in asm and "sfence" in asm


def test_last_level_cache_is_a_size():
    n = last_level_cache()
    assert isinstance(n, int) and (1 << 16) <= n <= (1 << 34)


@pytest.mark.parametrize("texts, expect", [
    ({3: "32768K\n", 2: "1024K\n"}, 32 << 20), ({2: "2M"}, 2 << 20), ({3: "512"}, 512),
    ({3: "garbage", 2: "1024K"}, 1 << 20), ({3: "0K"}, 32 << 20), ({}, 32 << 20)])
def test_last_level_cache_reads_sys_and_falls_back(monkeypatch, texts, expect):
    """The size as ``/sys`` gives it (L3, else L2; K, M or plain bytes); 32 MiB when neither
    file is there or says something else."""
    import refraster.raster._stream as st

    def read_text(self):
        for index, text in texts.items():
            if f"index{index}" in str(self):
                return text
        raise OSError("no such file")
    monkeypatch.setattr(st.Path, "read_text", read_text)
    assert st.last_level_cache() == expect
