"""Benchmark: depth peeling and the volumetric parity test.

Run from the repository root: ``python -m benchmarks.ldi [--quick]``.

1. An 8-layer peel of four nested spheres (81,920 faces) at 1024×1024: refraster's one-pass
   :func:`refraster.ldi.peel` (rasterization included) beside llvmpipe's classic multi-pass
   peel (8 passes, 32-bit float depth), timed in its own process with ``LP_NUM_THREADS=2`` and
   ``GLIBC_TUNABLES=glibc.malloc.trim_threshold=4294967296`` (``benchmarks/_llvmpipe.py``).
2. :meth:`VolumetricDepthSprite.contains` on 1M points beside ``trimesh``'s ray-based
   ``Trimesh.contains`` on fewer points (per-point times compared), for the crank.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._timing import first_ms, median_ms


def bench_peel(size, subdivisions, repeats):
    import refraster
    from refraster.ldi import peel
    from refraster.scenes import icosphere
    from benchmarks._llvmpipe import time_llvmpipe
    from refraster.raster.primitive import transform_vertices

    shells = [icosphere(subdivisions=subdivisions, radius=r) for r in (1.0, 0.8, 0.6, 0.4)]
    meshes = [(s.vertices, s.faces) for s in shells]
    cam = dict(view=refraster.look_at((0.4, 0.3, 2.6), (0, 0, 0)),
               proj=refraster.perspective(50, 1.0, 0.5, 10.0), width=size, height=size)

    def run():
        return peel(meshes, max_layers=8, **cam)

    first = first_ms(run)
    ours = median_ms(run, repeats)
    lay = run()
    mvp = cam["proj"] @ cam["view"]
    draws = [(transform_vertices(v, mvp), f) for v, f in meshes]
    gl = time_llvmpipe(draws, size, size, mode="peel", layers=8, repeats=repeats, threads=2)
    faces = sum(len(f) for _, f in meshes)
    return dict(case=f"peel 8 layers, {faces} faces, {size}²", ours=ours, anchor=gl["median_ms"],
                anchor_name="llvmpipe 8-pass peel (2 threads)", compile=first - ours,
                note=f"layers found {len(lay)}; {gl['renderer']}")


def bench_contains(n_points, n_trimesh, resolution, quick):
    import trimesh
    from refraster.ldi import VolumetricDepthSprite
    from refraster.scenes import crank

    mesh = crank(segments=32) if quick else crank()
    lo, hi = mesh.bounds
    pts = np.random.default_rng(0).uniform(lo, hi, size=(n_points, 3))
    t0 = time.perf_counter()
    vds = VolumetricDepthSprite.from_mesh(mesh, resolution, axis="x")
    build = (time.perf_counter() - t0) * 1e3
    first = first_ms(lambda: vds.contains(pts[:10]))
    ours = median_ms(lambda: vds.contains(pts), 5)
    sub = pts[:n_trimesh]
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    tm.contains(sub[:10])  # builds trimesh's ray acceleration structure outside the timing
    theirs = median_ms(lambda: tm.contains(sub), 3)
    per_ours = ours / n_points * 1e6
    per_theirs = theirs / n_trimesh * 1e6
    return dict(case=f"contains, crank {len(mesh.faces)} faces, VDS {resolution}² (x)",
                ours=per_ours, anchor=per_theirs,
                anchor_name=f"trimesh.contains ({n_trimesh} pts)", compile=first,
                note=f"ns per point; refraster on {n_points} pts ({ours:.1f} ms), "
                     f"VDS build {build:.0f} ms, d = {vds.d}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes")
    args = ap.parse_args(argv)
    if args.quick:
        rows = [bench_peel(256, 3, 3), bench_contains(100_000, 500, 256, True)]
    else:
        rows = [bench_peel(1024, 5, 5), bench_contains(1_000_000, 500, 1024, False)]
    print("| case | refraster | anchor | anchor | ratio (refraster / anchor) | compile ms |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        unit = "ns/pt" if "contains" in r["case"] else "ms"
        print(f"| {r['case']} | {r['ours']:.1f} {unit} | {r['anchor']:.1f} {unit} "
              f"| {r['anchor_name']} | {r['ours'] / r['anchor']:.3g} | {r['compile']:.0f} |")
    for r in rows:
        print(f"- {r['case']}: {r['note']}")


if __name__ == "__main__":
    main()
