"""Benchmark of the cutaway surface kernels: jump-flood variants and the chamfer pass beside
``scipy.ndimage.distance_transform_edt`` (the anchor), at 512² and 1024².

Run: ``python -m benchmarks.cutaway``. The seed image is rear-hull-like: two discs (3 % of the
pixels) of smoothly varying depth, with per-seed slopes that depend on depth as Eq. 3's do.
"""

from __future__ import annotations

import time

import numpy as np

from refraster.cutaway import VARIANTS, chamfer, jump_flood

REPEATS = 7


def seed_image(n):
    yy, xx = np.mgrid[:n, :n]
    mask = ((yy - 0.5 * n) ** 2 + (xx - 0.35 * n) ** 2 < (0.08 * n) ** 2) \
        | ((yy - 0.3 * n) ** 2 + (xx - 0.7 * n) ** 2 < (0.05 * n) ** 2)
    # a smooth rear-hull-like depth, and slopes that vary with it as Eq. 3 makes them
    z = np.where(mask, 0.3 + 0.4 * np.sin(xx / n * 7.0) * np.cos(yy / n * 5.0), -np.inf)
    slope = np.where(mask, (1.5 - z) * 4.0 / n, 0.0)
    return z, slope, mask


def median_ms(fn, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times))


def main():
    from scipy import ndimage
    z, slope, _ = seed_image(64)
    t0 = time.perf_counter()
    for v in VARIANTS:
        jump_flood(z, slope, variant=v)
    chamfer(z, slope)
    first = (time.perf_counter() - t0) * 1e3
    warm = median_ms(lambda: ([jump_flood(z, slope, variant=v) for v in VARIANTS],
                              chamfer(z, slope)), 3)
    print(f"kernel compile/load time (first call minus steady state): {first - warm:.0f} ms")
    print(f"{'case':<20} | {'refraster ms':>12} | {'edt ms':>8} | {'ratio':>6}")
    print("-" * 56)
    for n in (512, 1024):
        z, slope, mask = seed_image(n)
        edt = median_ms(lambda: ndimage.distance_transform_edt(~mask))
        cases = [(v, lambda v=v: jump_flood(z, slope, variant=v)) for v in VARIANTS]
        cases.append(("chamfer 5x5", lambda: chamfer(z, slope)))
        for name, fn in cases:
            ms = median_ms(fn)
            print(f"{name + f' {n}²':<20} | {ms:12.1f} | {edt:8.1f} | {ms / edt:6.2f}")


if __name__ == "__main__":
    main()
