"""Benchmark: refraster.gl on Mesa llvmpipe beside refraster, in one run, 2 threads each.

Run from the repository root: ``python -m benchmarks.techniques_gl [--quick]``.

1. The G-buffer of the crank (about 100k faces) at 1024×768: refraster's
   :func:`refraster.render` (every channel: depth, eye depth, normal, ids, facing,
   barycentrics, colour) beside refraster.gl's one-pass MRT G-buffer (``shaders/gbuffer.*``,
   six targets read back).
2. An 8-layer depth peel of four nested spheres (81,920 faces) at 1024×1024: refraster's
   one-pass :func:`refraster.ldi.peel` beside refraster.gl's classic multi-pass peel
   (``shaders/peel.frag``, 8 passes against a 32-bit float depth buffer, each layer read back).

Both scenes go through scene packages (:func:`refraster.golden.package.export_package`), as a
GPU team's would. refraster runs with 2 Numba threads in this process; refraster.gl runs in a
process of its own with ``LP_NUM_THREADS=2`` and ``GLIBC_TUNABLES=glibc.malloc.trim_threshold=
4294967296`` (malloc trimming costs llvmpipe about 40 % on large frames: /work/shared/LLVMPIPE.md).
Timed for refraster.gl: ``Backend.draw`` (draw calls, ``glFinish``, read-back and the
background fill), meshes already uploaded; the upload (``Backend.load``) is reported apart.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._timing import first_ms, interleaved_medians

ROOT = Path(__file__).resolve().parents[1]
TUNED_MALLOC = "glibc.malloc.trim_threshold=4294967296"


def _packages(root, quick):
    """Write the two scene packages; return [(name, refraster callable, package dir)]."""
    import refraster
    from refraster.golden.package import export_package
    from refraster.golden.scenes import (DEFAULT_RASTER, Draw, GoldenScene, _framed,
                                         prepare_draws, render_draws)
    from refraster.ldi import peel
    from refraster.scenes import crank, icosphere

    w, h = (256, 192) if quick else (1024, 768)
    draws = prepare_draws([Draw("crank", crank())])
    cam = _framed([d.mesh for d in draws], w, h, (0.8, 1.0, 1.5))
    state = dict(DEFAULT_RASTER)
    g = GoldenScene(technique="render", camera=cam, draws=draws, buffers={})
    export_package(root / "gbuffer", "gbuffer", g, state)
    faces_g = len(draws[0].mesh.faces)

    size, sub = (256, 3) if quick else (1024, 5)
    shells = prepare_draws([Draw(f"shell{k}", icosphere(subdivisions=sub, radius=r))
                            for k, r in enumerate((1.0, 0.8, 0.6, 0.4))])
    pcam = refraster.Camera(refraster.look_at((0.4, 0.3, 2.6), (0, 0, 0)),
                            refraster.perspective(50, 1.0, 0.5, 10.0), size, size)
    params = dict(mode="peel", max_layers=8)
    p = GoldenScene(technique="ldi", camera=pcam, draws=shells, buffers={}, parameters=params)
    export_package(root / "peel", "peel", p, state)
    faces_p = sum(len(d.mesh.faces) for d in shells)

    def ours_gbuffer():
        return render_draws(draws, cam, state)

    def ours_peel():
        return peel([d.mesh for d in shells], **pcam.kwargs, model=[d.model for d in shells],
                    max_layers=8)

    return [(f"G-buffer, crank {faces_g} faces, {w}×{h}", ours_gbuffer, root / "gbuffer"),
            (f"peel 8 layers, {faces_p} faces, {size}²", ours_peel, root / "peel")]


def _gl_child(packages, repeats):
    """Runs in the child process: time Backend.draw on each package, print JSON."""
    import time

    from refraster.gl.driver import Backend
    out = []
    with Backend() as gl:
        for pkg in packages:
            t0 = time.perf_counter()
            loaded = gl.load(pkg)
            load_ms = (time.perf_counter() - t0) * 1e3
            first = first_ms(lambda: gl.draw(loaded))
            times = [first_ms(lambda: gl.draw(loaded)) for _ in range(repeats)]
            layers = gl.draw(loaded)
            k = layers["layer_depth"].shape[-1] if "layer_depth" in layers else None
            gl.unload(loaded)
            out.append(dict(load_ms=load_ms, first_ms=first, median_ms=float(np.median(times)),
                            layers=k))
        out.append({"renderer": gl.renderer})
    print(json.dumps(out))


def _time_gl(packages, repeats, threads):
    env = {**os.environ, "LP_NUM_THREADS": str(threads), "GLIBC_TUNABLES": TUNED_MALLOC,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    code = ("import sys, json; from benchmarks.techniques_gl import _gl_child; "
            "_gl_child(json.loads(sys.argv[1]), int(sys.argv[2]))")
    proc = subprocess.run([sys.executable, "-c", code, json.dumps([str(p) for p in packages]),
                           str(repeats)], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=1800)
    if proc.returncode != 0:
        raise SystemExit(f"refraster.gl child failed: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    import numba
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    with tempfile.TemporaryDirectory() as tmp:
        cases = _packages(Path(tmp), args.quick)
        gl = _time_gl([c[2] for c in cases], args.repeats, threads=2)
        renderer = gl.pop()["renderer"]
        rows = []
        for (name, ours, _), g in zip(cases, gl):
            first = first_ms(ours)
            (median,) = interleaved_medians([ours], args.repeats)
            rows.append((name, median, first, g))
    print(f"refraster: {numba.get_num_threads()} Numba threads; refraster.gl: {renderer}, "
          "LP_NUM_THREADS=2, tuned malloc")
    print("| case | refraster ms | refraster.gl (llvmpipe) ms | ratio (refraster / gl) | "
          "refraster first call ms | gl first draw ms | gl load+upload ms |")
    print("|---|---|---|---|---|---|---|")
    for name, median, first, g in rows:
        print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | {median / g['median_ms']:.2g} "
              f"| {first:.0f} | {g['first_ms']:.0f} | {g['load_ms']:.0f} |")
    for name, _, _, g in rows:
        if g["layers"] is not None:
            print(f"- {name}: refraster.gl peeled {g['layers']} layers")


if __name__ == "__main__":
    main()
