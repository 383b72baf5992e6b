"""Benchmark: the ~100k-face crank at 1024×768, plain rendering against clip + cap.

Trapp & Döllner Sec. 6.2 report 131 fps plain and 125 fps with clipping and a cap on a GPU
(5 % overhead). Run: ``python -m benchmarks.clipsurface``. The volumetric depth sprite is
built once beforehand (the paper's preprocessing step) and timed on its own line.
``--msaa`` adds clip + tessellated cap at 4 samples, pixel rate and sample rate
(``docs/clipsurface.md``, "Multisampling"), against the same 1x anchor.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks._timing import interleaved_medians


def main(repeats=15, msaa=False):
    import refraster
    from refraster.clipsurface import offsetmaps as om
    from refraster.camera import frame_bounds
    from refraster.clipsurface import Caps, ClipSurface, render_clipped
    from refraster.ldi import VolumetricDepthSprite
    from refraster.scenes import crank

    mesh = crank()
    lo, hi = mesh.bounds
    n = np.array([0.0, 0.25, -1.0])
    n /= np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    extent = float(np.linalg.norm(hi - lo))
    cs = ClipSurface((lo + hi) / 2, extent * u, extent * v, (1.0, 1.0, 0.6),
                     om.perlin_noise(256, seed=1))
    cam = frame_bounds(mesh.bounds, width=1024, height=768, direction=(0.3, 0.7, 1.0))
    t = time.perf_counter()
    vds = VolumetricDepthSprite.from_mesh(mesh, resolution=1024)
    build_ms = (time.perf_counter() - t) * 1e3

    # every case reads the shaded colour (render() shades it on first read): frames to look at
    def plain():
        fb = refraster.render(mesh, **cam.kwargs)
        fb.color
        return fb

    def clipped(mode="mesh", caps=True, raster=None):
        fb = render_clipped(mesh, cs, **cam.kwargs, vds=[vds],
                            caps=Caps(style="hatch", mode=mode) if caps else None,
                            raster=raster)
        fb.color
        return fb

    cases = [("plain render", plain), ("clip only (caps=None)", lambda: clipped(caps=False)),
             ("clip + tessellated cap", clipped), ("clip + exact cap", lambda: clipped("exact"))]
    if msaa:
        from refraster import RasterState
        cases += [("clip + cap 4x, pixel rate",
                   lambda: clipped(raster=RasterState(samples=4))),
                  ("clip + cap 4x, sample rate",
                   lambda: clipped(raster=RasterState(samples=4, interpolation="sample")))]
    print(f"crank: {len(mesh.faces)} faces, 1024x768, offset map 256x256, "
          f"VDS 1024^2 (d = {vds.d}) built in {build_ms:.0f} ms")
    first = {}
    for name, fn in cases:
        t = time.perf_counter()
        fb = fn()
        first[name] = (time.perf_counter() - t) * 1e3
        if name.startswith("clip +"):
            print(f"  {name}: {int(fb.cap_mask.sum())} cap pixels")
    medians = interleaved_medians([fn for _, fn in cases], repeats)
    base = medians[0]
    print(f"{'case':28s} | {'refraster ms':>12s} | {'anchor ms':>10s} | {'ratio':>6s} | "
          "first-call extra ms")
    for (name, _), ms in zip(cases, medians):
        print(f"{name:28s} | {ms:12.1f} | {base:10.1f} | {ms / base:6.2f} | "
              f"{max(first[name] - ms, 0.0):.0f}")
    print(f"medians of {repeats} rounds (each round times every case once); anchor: the plain "
          "render of the same crank in the same run (paper: 5 % overhead). First-call extra: "
          "compilation (none when the cache is warm) plus, for the caps, the cap grid, its "
          "culling against the sprite and the normal/occlusion maps, made once per surface.")


if __name__ == "__main__":
    import sys
    main(msaa="--msaa" in sys.argv[1:])
