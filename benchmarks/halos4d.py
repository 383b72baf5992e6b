"""Benchmark: volumetric halos of the spun trefoil (~20k triangles) at 512² (Wang et al. Table 1).

    python -m benchmarks.halos4d [--size 512] [--repeats 5] [--reference-repeats 1]

Columns: refraster's fused engine (median wall time of ``repeats`` frames, and the median CPU
time summed over threads, which a busy machine inflates less), the reference engine
(:func:`refraster.rasterize` once per slice + NumPy; same output bits) measured in the same run,
and the paper's GPU figure (GeForce GTX 580, 2013, Table 1: 69.16 / 55.31 / 42.67 / 24.30 fps).
A frame is everything from the 4D surface to the composited image: rotation, projection,
thickening, tetrahedra, slicing, rasterization and compositing. Compile time (first call minus
steady state) is printed once.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

#: Wang et al. 2013, Table 1, spun-trefoil row (frames per second).
PAPER_FPS = {64: 69.16, 128: 55.31, 256: 42.67, 512: 24.30}


def frame(surface, size, slices, engine="fused"):
    import refraster.halos4d as h
    view = h.View4D(rotation=h.compose(("zw", 0.6), ("zx", 0.3), ("yz", 0.4)))
    return h.render_halos(surface, view=view, width=size, height=size, slices=slices,
                          engine=engine)


def timed(fn, repeats):
    """Median wall time and median CPU time (all threads) of ``fn``, in ms."""
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return 1000.0 * float(np.median(wall)), 1000.0 * float(np.median(cpu))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--reference-repeats", type=int, default=1)
    args = ap.parse_args(argv)
    import refraster.halos4d as h

    surface = h.spun_trefoil()
    t0 = time.perf_counter()
    frame(surface, args.size, 64)
    first = 1000.0 * (time.perf_counter() - t0)
    steady = timed(lambda: frame(surface, args.size, 64), 3)[0]
    print(f"spun trefoil: {surface.n_faces} triangles, {args.size}², "
          f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")
    print(f"compile time (first call − steady state): {first - steady:.0f} ms")
    print()
    print("| slices | refraster fused ms (CPU ms) | reference engine ms | ratio "
          "| paper GPU ms (fps) | fused / paper |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in (64, 128, 256, 512):
        fused, cpu = timed(lambda: frame(surface, args.size, n), args.repeats)
        ref = timed(lambda: frame(surface, args.size, n, "reference"), args.reference_repeats)[0]
        paper = 1000.0 / PAPER_FPS[n]
        print(f"| {n} | {fused:.0f} ({cpu:.0f}) | {ref:.0f} | {ref / fused:.1f}× | {paper:.1f} "
              f"({PAPER_FPS[n]}) | {fused / paper:.0f}× |")


if __name__ == "__main__":
    main()
