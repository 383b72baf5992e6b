"""Wall-clock helpers shared by the benchmarks (milliseconds)."""

from __future__ import annotations

import time

import numpy as np


def first_ms(fn, clock=time.perf_counter):
    """Time of one call (the first call of a kernel includes loading or compiling it);
    ``clock=time.process_time``: the process's CPU time instead of the wall clock."""
    t0 = clock()
    fn()
    return (clock() - t0) * 1e3


def median_ms(fn, repeats, *, warmup=False):
    """Median of ``repeats`` calls; ``warmup`` makes one untimed call first."""
    if warmup:
        fn()
    times = [first_ms(fn) for _ in range(repeats)]
    return float(np.median(times))


def interleaved_medians(fns, repeats, clock=time.perf_counter):
    """Median ms of each function, timed in rounds (one call of each per round), so that a
    slow spell of a shared machine falls on all of them alike (``clock``: as
    :func:`first_ms`)."""
    times = [[] for _ in fns]
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            times[k].append(first_ms(fn, clock))
    return [float(np.median(t)) for t in times]
