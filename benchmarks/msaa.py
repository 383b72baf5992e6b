"""Multisampled G-buffers: 1×, 4× and 8× beside llvmpipe 4×, measured in the same run.

    python -m benchmarks.msaa [--repeats N] [--threads T] [--cpu]

The 81,920-face icosphere at 1024×768 (``benchmarks/raster.py``'s first case). refraster, in a
process of its own with ``NUMBA_NUM_THREADS`` = T and the tuned malloc of ``benchmarks.raster``:
the 1× G-buffer (``refraster.render``), and ``refraster.render_samples`` at 4× and 8× (standard
positions; per-sample depth, eye depth, normal, ids, facing, barycentrics; colour not read), timed
in rounds (one call of each per round) so that a slow spell of the shared machine falls on all
alike. llvmpipe, in a process of its own with ``LP_NUM_THREADS`` = T: the 4× draw of the same
clip positions into a 4-sample ``R32I`` id target with a 4-sample float depth buffer, timed as
clear + draw + ``glFinish`` (``tests/oracles/llvmpipe_msaa.py``; nothing is resolved or read
back), and with the per-sample read-back (``texelFetch`` of the four samples into an
``RGBA32I`` target and its read) apart. Prints one JSON line and a Markdown table; the cost per
sample is each frame's time over the 1× frame's. ``--cpu`` times refraster's frames in the
process's CPU time (with ``--threads 1``, one thread's: on a busy shared machine a steadier
measure of the ratios than the wall clock; llvmpipe stays wall-clock).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
W, H = 1024, 768
TUNED = "glibc.malloc.trim_threshold=4294967296:glibc.malloc.mmap_threshold=33554432"


def _scene(path):
    import trimesh
    import refraster as rf
    from tests.oracles.llvmpipe import clip_positions
    mesh = trimesh.creation.icosphere(6)
    cam = rf.camera.frame_bounds(mesh.bounds, width=W, height=H, margin=1.0)
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    clip = clip_positions(v, cam.proj @ cam.view)
    np.savez(path, vertices=v, faces=f, view=cam.view, proj=cam.proj, clip=clip)
    return len(f)


_REFRASTER = """
import json, sys, time, numpy as np, refraster as rf
from benchmarks._timing import interleaved_medians
z = np.load(sys.argv[1], allow_pickle=False)
mesh = rf.mesh.as_mesh((z['vertices'], z['faces']))
view, proj = z['view'], z['proj']
kw = dict(view=view, proj=proj, width=%d, height=%d)
s4, s8 = rf.RasterState(samples=4), rf.RasterState(samples=8)
fns = [lambda: rf.render(mesh, **kw), lambda: rf.render_samples(mesh, **kw, raster=s4),
       lambda: rf.render_samples(mesh, **kw, raster=s8)]
for fn in fns:       # compile and reach the steady state
    fn(); fn()
t1, t4, t8 = interleaved_medians(fns, int(sys.argv[2]),
                                 time.process_time if sys.argv[3] == "cpu" else time.perf_counter)
print(json.dumps(dict(x1_ms=t1, x4_ms=t4, x8_ms=t8)))
""" % (W, H)

_LLVMPIPE = """
import json, sys, time, numpy as np
sys.path.insert(0, 'tests')
from oracles import llvmpipe as L
from oracles.llvmpipe_msaa import MultisampleScene
z = np.load(sys.argv[1], allow_pickle=False)
with MultisampleScene(z['clip'], z['faces'].astype(np.int32), %d, %d) as sc:
    for _ in range(3):
        sc.draw()
    draw, read = [], []
    for _ in range(int(sys.argv[2])):
        t0 = time.perf_counter(); sc.draw(); draw.append((time.perf_counter() - t0) * 1e3)
        t0 = time.perf_counter(); sc.read(); read.append((time.perf_counter() - t0) * 1e3)
print(json.dumps(dict(draw_ms=float(np.median(draw)), read_ms=float(np.median(read)),
                      renderer=L.renderer())))
""" % (W, H)


def _run(code, path, repeats, env, clock="wall"):
    r = subprocess.run([sys.executable, "-c", code, str(path), str(repeats), clock], env=env,
                       capture_output=True, text=True, cwd=ROOT, timeout=3600)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cpu", action="store_true",
                    help="refraster's frames in CPU time (process_time), not wall-clock; on a "
                         "busy machine with --threads 1 the steadier measure of the ratios")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "scene.npz"
        faces = _scene(path)
        base = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
        env = dict(base, NUMBA_NUM_THREADS=str(a.threads), GLIBC_TUNABLES=TUNED,
                   PYTHONPATH=str(ROOT))
        ours = _run(_REFRASTER, path, a.repeats, env, "cpu" if a.cpu else "wall")
        gl_env = dict(base, LP_NUM_THREADS=str(a.threads), GLIBC_TUNABLES=TUNED)
        try:
            gl = _run(_LLVMPIPE, path, a.repeats, gl_env)
        except RuntimeError as exc:
            gl = {"error": str(exc).splitlines()[-1] if str(exc) else "failed"}
    out = dict(faces=faces, width=W, height=H, threads=a.threads, load=os.getloadavg(),
               clock="cpu" if a.cpu else "wall",
               refraster=ours, llvmpipe=gl)
    print(json.dumps(out))
    x1 = ours["x1_ms"]
    unit = "ms (refraster: CPU)" if a.cpu else "ms"
    print(f"\n| frame ({faces:,} faces, {W}×{H}, {a.threads} threads) | {unit} | × the 1× frame |")
    print("|---|---|---|")
    print(f"| refraster 1× G-buffer (`render`) | {x1:.1f} | 1.00 |")
    for n in (4, 8):
        t = ours[f"x{n}_ms"]
        print(f"| refraster {n}× G-buffer (`render_samples`) | {t:.1f} | {t / x1:.2f} |")
    if "draw_ms" in gl:
        print(f"| llvmpipe 4× ids + depth (draw + glFinish) | {gl['draw_ms']:.1f} | "
              f"{gl['draw_ms'] / x1:.2f} |")
        print(f"| llvmpipe 4× per-sample read-back (texelFetch + read) | {gl['read_ms']:.1f} | |")
    else:
        print(f"| llvmpipe 4× | {gl.get('error')} | |")


if __name__ == "__main__":
    main()
