"""Benchmark: refraster.wgpu on Mesa's lavapipe beside refraster and refraster.gl on llvmpipe,
in one run, 2 threads each.

Run from the repository root: ``python -m benchmarks.techniques_wgpu [--quick]
[--techniques-only | --base-only]``.

The two base cases of :mod:`benchmarks.techniques_gl` (the same scene packages):

1. The G-buffer of the crank (about 100k faces) at 1024×768: refraster's :func:`refraster.render`
   (every channel) beside refraster.gl's one-pass MRT G-buffer and refraster.wgpu's three
   passes within WebGPU's default 32 bytes per sample (ids and depths; normal and
   barycentrics; colour), every target read back.
2. An 8-layer depth peel of four nested spheres (81,920 faces) at 1024×1024: refraster's
   one-pass :func:`refraster.ldi.peel` beside the two backends' classic multi-pass peels (each
   layer read back).
3. The four techniques at their papers' sizes (issue 45, the wgpu column): the packages of
   :func:`benchmarks.techniques_gl._technique_packages` (clip surface with its cap, edge map,
   cutaway, 4D halos); a technique refraster.wgpu does not draw yet is listed with "—".
   ``--techniques-only`` runs these alone, ``--base-only`` the first two.

refraster runs with 2 Numba threads in this process; each backend runs in a process of its own
with ``LP_NUM_THREADS=2`` (lavapipe and llvmpipe read the same variable) and
``GLIBC_TUNABLES=glibc.malloc.trim_threshold=4294967296`` (/work/shared/LLVMPIPE.md). Timed for
the backends: ``Backend.draw`` (the passes, read-back and background fill), the meshes already
uploaded; the upload (``Backend.load``) is reported apart.
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
from benchmarks.techniques_gl import TUNED_MALLOC, _packages, _technique_packages, _time_gl

ROOT = Path(__file__).resolve().parents[1]


def _wgpu_child(packages, repeats):
    """Runs in the child process: time Backend.draw on each package, print JSON."""
    import time

    from refraster.wgpu.driver import Backend, Unsupported
    out = []
    with Backend() as gpu:
        for pkg in packages:
            t0 = time.perf_counter()
            try:
                loaded = gpu.load(pkg)
            except Unsupported as exc:
                out.append(dict(skipped=str(exc)))
                continue
            load_ms = (time.perf_counter() - t0) * 1e3
            first = first_ms(lambda: gpu.draw(loaded))
            times = [first_ms(lambda: gpu.draw(loaded)) for _ in range(repeats)]
            layers = gpu.draw(loaded)
            k = layers["layer_depth"].shape[-1] if "layer_depth" in layers else None
            gpu.unload(loaded)
            out.append(dict(load_ms=load_ms, first_ms=first, median_ms=float(np.median(times)),
                            layers=k))
        out.append({"renderer": gpu.renderer})
    print(json.dumps(out))


def _time_wgpu(packages, repeats, threads):
    env = {**os.environ, "LP_NUM_THREADS": str(threads), "GLIBC_TUNABLES": TUNED_MALLOC,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    code = ("import sys, json; from benchmarks.techniques_wgpu import _wgpu_child; "
            "_wgpu_child(json.loads(sys.argv[1]), int(sys.argv[2]))")
    proc = subprocess.run([sys.executable, "-c", code, json.dumps([str(p) for p in packages]),
                           str(repeats)], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=1800)
    if proc.returncode != 0:
        raise SystemExit(f"refraster.wgpu child failed: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--techniques-only", action="store_true",
                    help="only the four techniques at their papers' sizes (issue 45)")
    ap.add_argument("--base-only", action="store_true",
                    help="only the G-buffer and the peel")
    args = ap.parse_args(argv)
    import numba
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    with tempfile.TemporaryDirectory() as tmp:
        cases = [] if args.techniques_only else _packages(Path(tmp), args.quick)
        if not args.base_only:
            cases += _technique_packages(Path(tmp), args.quick)
        gl = _time_gl([c[2] for c in cases], args.repeats, threads=2)
        gl_renderer = gl.pop()["renderer"]
        wg = _time_wgpu([c[2] for c in cases], args.repeats, threads=2)
        wgpu_renderer = wg.pop()["renderer"]
        rows = []
        for (name, ours, _), g, w in zip(cases, gl, wg):
            first = first_ms(ours)
            (median,) = interleaved_medians([ours], args.repeats)
            rows.append((name, median, first, g, w))
    print(f"refraster: {numba.get_num_threads()} Numba threads; refraster.gl: {gl_renderer}; "
          f"refraster.wgpu: {wgpu_renderer}; LP_NUM_THREADS=2, tuned malloc")
    print("| case | refraster ms | refraster.gl (llvmpipe) ms | refraster.wgpu (lavapipe) ms | "
          "wgpu / refraster | gl first draw ms | wgpu first draw ms | gl load ms | wgpu load ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, median, first, g, w in rows:
        if "skipped" in w:
            print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | — | — | "
                  f"{g['first_ms']:.0f} | — | {g['load_ms']:.0f} | — |")
            continue
        print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | {w['median_ms']:.0f} | "
              f"{w['median_ms'] / median:.2g} | {g['first_ms']:.0f} | {w['first_ms']:.0f} | "
              f"{g['load_ms']:.0f} | {w['load_ms']:.0f} |")
    for name, _, _, g, w in rows:
        if "skipped" in w:
            print(f"- {name}: refraster.wgpu skipped it ({w['skipped']})")
        elif g["layers"] is not None:
            print(f"- {name}: refraster.gl peeled {g['layers']} layers, refraster.wgpu "
                  f"{w['layers']}")


if __name__ == "__main__":
    main()
