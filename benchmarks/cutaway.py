"""Benchmark of the cutaway surface kernels: jump-flood variants and the chamfer pass beside
``scipy.ndimage.distance_transform_edt`` (the anchor), at 512² and 1024².

Run: ``python -m benchmarks.cutaway``. The seed image is rear-hull-like: two discs (3 % of the
pixels) of smoothly varying depth, with per-seed slopes that depend on depth as Eq. 3's do.
Times are the median and the minimum of REPEATS runs: the minimum is the better estimate of the
kernel's own speed on a machine shared with other jobs.
"""

from __future__ import annotations

import time

import numba
import numpy as np

from refraster.cutaway import VARIANTS, chamfer, jump_flood

REPEATS = 15


def seed_image(n):
    yy, xx = np.mgrid[:n, :n]
    mask = ((yy - 0.5 * n) ** 2 + (xx - 0.35 * n) ** 2 < (0.08 * n) ** 2) \
        | ((yy - 0.3 * n) ** 2 + (xx - 0.7 * n) ** 2 < (0.05 * n) ** 2)
    # a smooth rear-hull-like depth, and slopes that vary with it as Eq. 3 makes them
    z = np.where(mask, 0.3 + 0.4 * np.sin(xx / n * 7.0) * np.cos(yy / n * 5.0), -np.inf)
    slope = np.where(mask, (1.5 - z) * 4.0 / n, 0.0)
    return z, slope, mask


def timings_ms(fn, repeats=REPEATS):
    """(median, minimum) wall time of ``repeats`` calls, in ms."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times)), float(np.min(times))


def main():
    from scipy import ndimage
    z, slope, _ = seed_image(64)
    t0 = time.perf_counter()
    for v in VARIANTS:
        jump_flood(z, slope, variant=v)
    chamfer(z, slope)
    first = (time.perf_counter() - t0) * 1e3
    warm = timings_ms(lambda: ([jump_flood(z, slope, variant=v) for v in VARIANTS],
                               chamfer(z, slope)), 3)[0]
    print(f"kernel compile/load time (first call minus steady state): {first - warm:.0f} ms")
    print(f"Numba threads: {numba.get_num_threads()}; times: median / min of {REPEATS} runs")
    print(f"{'case':<20} | {'refraster ms':>14} | {'edt ms':>12} | {'ratio':>11}")
    print("-" * 68)
    for n in (512, 1024):
        z, slope, mask = seed_image(n)
        edt, edt_min = timings_ms(lambda: ndimage.distance_transform_edt(~mask))
        cases = [(v, lambda v=v: jump_flood(z, slope, variant=v)) for v in VARIANTS]
        cases.append(("chamfer 5x5", lambda: chamfer(z, slope)))
        for name, fn in cases:
            ms, ms_min = timings_ms(fn)
            print(f"{name + f' {n}²':<20} | {ms:6.1f} / {ms_min:5.1f} | {edt:5.1f} / {edt_min:4.1f}"
                  f" | {ms / edt:4.2f} / {ms_min / edt_min:4.2f}")


if __name__ == "__main__":
    main()
