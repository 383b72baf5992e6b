"""Benchmark: volumetric halos of the spun trefoil (~20k triangles) at 512² (Wang et al. Table 1).

    python -m benchmarks.halos4d [--size 512] [--repeats 5] [--reference-repeats 1]
                                 [--slices 64,128,256,512] [--stages] [--stage-minima]

Columns: refraster's fused engine (median wall time of ``repeats`` frames, and the median CPU
time summed over threads, which a busy machine inflates less), the reference engine
(:func:`refraster.rasterize` once per slice + NumPy; same output bits) measured in the same run,
and the paper's GPU figure (GeForce GTX 580, 2013, Table 1: 69.16 / 55.31 / 42.67 / 24.30 fps).
A frame is everything from the 4D surface to the composited image: rotation, projection,
thickening, tetrahedra, slicing, rasterization and compositing. Compile time (first call minus
steady state) is printed once. ``--stages``: the CPU time of each stage of the 256-slice frame
(projection and thickening, the default δd, screen z and NDC, slice ranges with the band
binning, the fused slicing and fill), which a shared machine inflates less than wall time;
``--stage-minima``: each stage of that frame called ``repeats`` times on the frame's own
arguments (captured from one frame), the minimum CPU time of each, and of the whole frame
(steadier than ``--stages`` on a busy machine);
``--reference-repeats 0`` skips the reference engine.
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


def stages(surface, size, slices, repeats):
    """Median CPU ms per frame of each stage (the render module's functions, wrapped), and of
    the whole frame; the δd estimate is cached after the first frame, as in an interactive
    session (render._default_delta_d)."""
    from refraster.halos4d import render as hr
    names = ("prepare", "default_halo_parameters", "_tet_slices", "_window", "_fused")
    spent = {n: 0.0 for n in names}
    saved = {n: getattr(hr, n) for n in names}

    def wrap(name, fn):
        def timed_fn(*a, **k):
            c = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += time.process_time() - c
        return timed_fn
    frame(surface, size, slices)
    try:
        for n in names:
            setattr(hr, n, wrap(n, saved[n]))
        frame(surface, size, slices)        # the wrapped δd is a new cache entry: paid once
        for n in names:
            spent[n] = 0.0
        total = timed(lambda: frame(surface, size, slices), repeats)
    finally:
        for n, fn in saved.items():
            setattr(hr, n, fn)
    per = {n: 1000.0 * v / repeats for n, v in spent.items()}
    per["fill"] = per.pop("_fused") - per["_window"]
    return total, per


def stage_minima(surface, size, slices, repeats):
    """Minimum CPU ms of each stage over ``repeats`` calls on the captured arguments of one
    frame (prepare, screen z and NDC, slice ranges with the band binning, the fused slicing
    and fill), and of the whole frame."""
    import refraster.halos4d as h
    from refraster.halos4d import render as hr
    got = {}
    fused, tet_slices = hr._fused, hr._tet_slices

    def cap_fused(*a, **k):
        got["fused"] = a
        return fused(*a, **k)

    def cap_slices(*a):
        got["slices"] = a
        return tet_slices(*a)
    hr._fused, hr._tet_slices = cap_fused, cap_slices
    try:
        frame(surface, size, slices)
    finally:
        hr._fused, hr._tet_slices = fused, tet_slices
    ts, width, height, params, volume = got["fused"][:5]
    win = hr._window(ts, width, height)
    view = h.View4D(rotation=h.compose(("zw", 0.6), ("zx", 0.3), ("yz", 0.4)))
    calls = {"prepare": lambda: hr.prepare(surface, view=view),
             "screen z and NDC": lambda: tet_slices(*got["slices"]),
             "slice ranges and band binning": lambda: hr._window(ts, width, height),
             "slicing, fill and compositing (fused)": lambda: fused(ts, width, height, params,
                                                                    volume, win),
             "frame": lambda: frame(surface, size, slices)}
    best = {k: np.inf for k in calls}
    for _ in range(repeats):
        for k, fn in calls.items():
            c = time.process_time()
            fn()
            best[k] = min(best[k], 1000.0 * (time.process_time() - c))
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--reference-repeats", type=int, default=1)
    ap.add_argument("--slices", default="64,128,256,512")
    ap.add_argument("--stages", action="store_true")
    ap.add_argument("--stage-minima", action="store_true")
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
    for n in (int(x) for x in args.slices.split(",")):
        fused, cpu = timed(lambda: frame(surface, args.size, n), args.repeats)
        paper = 1000.0 / PAPER_FPS[n]
        if args.reference_repeats > 0:
            ref = timed(lambda: frame(surface, args.size, n, "reference"),
                        args.reference_repeats)[0]
            ref_cells = f"{ref:.0f} | {ref / fused:.1f}×"
        else:
            ref_cells = "— | —"
        print(f"| {n} | {fused:.0f} ({cpu:.0f}) | {ref_cells} | {paper:.1f} "
              f"({PAPER_FPS[n]}) | {fused / paper:.0f}× |")
    if args.stages:
        (wall, cpu), per = stages(surface, args.size, 256, args.repeats)
        print()
        print(f"256 slices, {args.repeats} frames: wall {wall:.0f} ms, CPU {cpu:.0f} ms per frame")
        print("| stage | CPU ms per frame |")
        print("|---|---:|")
        labels = {"prepare": "projection, thickening, tetrahedra (prepare)",
                  "default_halo_parameters": "default δd (pair search; cached)",
                  "_tet_slices": "screen z and NDC", "_window": "slice ranges and band binning",
                  "fill": "slicing, fill and compositing (fused)"}
        for k, label in labels.items():
            print(f"| {label} | {per[k]:.0f} |")

    if args.stage_minima:
        print()
        print(f"256 slices, minimum CPU ms of {args.repeats} calls per stage")
        print("| stage | CPU ms (min) |")
        print("|---|---:|")
        for k, v in stage_minima(surface, args.size, 256, args.repeats).items():
            print(f"| {k} | {v:.0f} |")


if __name__ == "__main__":
    main()
