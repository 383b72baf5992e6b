"""Rasterizer speed: the G-buffer pass beside Mesa's llvmpipe, measured in the same run.

    python -m benchmarks.raster [--quick] [--repeats N] [--rounds R] [--vertex-order first-use]
        [--only NAME] [--normals smooth]

Cases (1024×768): icospheres of 81,920 and 1,310,720 faces and the crank. refraster renders the
full G-buffer (``refraster.render``: depth, eye depth, normal, ids, facing, barycentrics) with 2
threads and with 1, and the same frame with its default colour read (``+colour``: shaded when
first read); llvmpipe renders depth + normal + id + facing in its own process
with ``LP_NUM_THREADS`` = 2 or 1, timed as draw + glFinish + read-back into reused arrays.
Both run in processes of their own with the same ``GLIBC_TUNABLES`` (:data:`TUNED`); the
``default`` column times refraster's frame again without it (the environment users have). Compile time is reported apart (the
first call in a fresh cache directory minus a steady-state call), and the stage breakdown of one
frame (vertex, setup, binning + rasterization + resolve, G-buffer) follows the table. Peak memory
of the 1.3M-face frame and of a 4096×4096 frame is measured with tracemalloc.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time
import tracemalloc

import numpy as np

from benchmarks._timing import median_ms

ROOT = pathlib.Path(__file__).resolve().parents[1]
W, H = 1024, 768
#: Both renderers run in processes of their own with the same glibc malloc tuning: freed frame
#: buffers stay mapped, so a new frame's outputs are not page-faulted in again (for llvmpipe
#: ../shared/LLVMPIPE.md measured ~40 %; for refraster's fresh output arrays about the same).
TUNED = "glibc.malloc.trim_threshold=4294967296:glibc.malloc.mmap_threshold=33554432"


def _cases(quick):
    import trimesh
    from refraster import scenes
    cases = [("icosphere 81,920", trimesh.creation.icosphere(6))]
    if not quick:
        cases.append(("icosphere 1,310,720", trimesh.creation.icosphere(8)))
    cases.append(("crank", scenes.crank()))
    return cases


def first_use_order(vertices, faces):
    """The mesh with its vertices renumbered in the order the faces first use them (what a
    vertex-fetch optimiser does, e.g. meshoptimizer's ``optimizeVertexFetch``): the same
    triangles, faces in the same order with their corners in the same order, so every output
    byte is the same; only the vertex arrays' memory order changes (``--vertex-order``)."""
    faces = np.asarray(faces, np.int64)
    flat = faces.ravel()
    _, first = np.unique(flat, return_index=True)
    used = flat[np.sort(first)]
    new = np.full(len(vertices), -1, np.int64)
    new[used] = np.arange(len(used))
    unused = np.flatnonzero(new < 0)
    new[unused] = len(used) + np.arange(len(unused))
    v = np.empty_like(np.asarray(vertices))
    v[new] = vertices
    return v, new[faces]


def _camera(mesh):
    import refraster as rf
    cam = rf.camera.frame_bounds(mesh.bounds, width=W, height=H, margin=1.0)
    return cam.view, cam.proj


def _refraster_worker(path, threads, repeats, tuned=True):
    """Time refraster in a subprocess with NUMBA_NUM_THREADS set (prints JSON); ``tuned``:
    with :data:`TUNED` malloc settings, else in the environment as a user has it."""
    code = f"""
import json, time, numpy as np, refraster as rf
z = np.load({str(path)!r}, allow_pickle=False)
# validated once, as llvmpipe's mesh is uploaded once (render() skips the checks for a Mesh)
smooth = 'normals' in z.files   # --normals smooth: the mesh's own vertex normals
mesh = rf.mesh.as_mesh((z['vertices'].astype(np.float64), z['faces'].astype(np.int64))
                       + ((z['normals'].astype(np.float64),) if smooth else ()))
view, proj = z['view'], z['proj']
state = rf.RasterState(normals='smooth') if smooth else None
def frame(color):
    fb = rf.render(mesh, view=view, proj=proj, width={W}, height={H}, raster=state)
    if color:
        fb.color   # the default shade, made when first read
for _ in range(3):   # steady state, as the llvmpipe worker (benchmarks._gl_gbuffer.WARMUP)
    frame(False)
    frame(True)
ts, tc = [], []
for _ in range({repeats}):   # alternately, so a slow spell hits both
    t0 = time.perf_counter(); frame(False); ts.append((time.perf_counter() - t0) * 1e3)
    t0 = time.perf_counter(); frame(True); tc.append((time.perf_counter() - t0) * 1e3)
print(json.dumps(dict(median_ms=float(np.median(ts)), color_ms=float(np.median(tc)),
                      times_ms=ts)))
"""
    env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    env["NUMBA_NUM_THREADS"] = str(threads)
    if tuned:
        env["GLIBC_TUNABLES"] = TUNED
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       cwd=ROOT, timeout=1800)
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _llvmpipe(path, threads, repeats):
    env = dict(os.environ, LP_NUM_THREADS=str(threads), GLIBC_TUNABLES=TUNED)
    r = subprocess.run([sys.executable, "-m", "benchmarks._gl_gbuffer", str(path), "--repeats",
                        str(repeats)], env=env, capture_output=True, text=True, cwd=ROOT,
                       timeout=1800)
    if r.returncode != 0:
        return None
    return json.loads(r.stdout.strip().splitlines()[-1])


def _stages(mesh, view, proj, repeats):
    import refraster as rf
    from refraster.framebuffer import _build
    from refraster.mesh import as_meshes
    from refraster.raster.primitive import setup_triangles, transform_vertices
    from refraster.raster.rasterizer import bin_primitives, fused
    m = as_meshes(mesh)[0]
    mvp = proj @ view
    t_vertex = median_ms(lambda: transform_vertices(m.vertices, mvp), repeats, warmup=True)
    clip = transform_vertices(m.vertices, mvp).astype(np.float64)
    t_setup = median_ms(lambda: setup_triangles(clip, m.faces, W, H), repeats, warmup=True)
    st = setup_triangles(clip, m.faces, W, H)
    t_bin = median_ms(lambda: bin_primitives(st), repeats, warmup=True)
    t_raster = median_ms(lambda: fused(st), repeats, warmup=True) - t_bin
    depth, prim, front, bary = fused(st)
    offsets = np.array([0, m.n_faces])
    t_gbuf = median_ms(lambda: _build([m], [np.eye(4)], view, proj, depth, prim, offsets, front,
                                      bary.reshape(H, W, 3), None, np.ones(3)), repeats,
                       warmup=True)
    t_total = median_ms(lambda: rf.render(m, view=view, proj=proj, width=W, height=H), repeats,
                        warmup=True)

    def shade():
        fb = _build([m], [np.eye(4)], view, proj, depth, prim, offsets, front,
                    bary.reshape(H, W, 3), None, np.ones(3))
        t0 = time.perf_counter()
        fb.color
        return (time.perf_counter() - t0) * 1e3

    shade()
    t_color = float(np.median([shade() for _ in range(repeats)]))
    return dict(vertex=t_vertex, setup=t_setup, binning=t_bin, raster=t_raster, gbuffer=t_gbuf,
                total=t_total, color=t_color, triangles=int((st.status == 1).sum()) + len(st.clipped))


def _compile_time():
    """First render in a fresh NUMBA_CACHE_DIR minus a steady-state render, in a subprocess."""
    code = """
import time, trimesh, refraster as rf
m = trimesh.creation.icosphere(3)
kw = dict(view=rf.look_at([0, 0, 3], [0, 0, 0]), proj=rf.perspective(45, 4/3, .5, 10),
          width=256, height=192)
t0 = time.perf_counter(); rf.render(m, **kw); first = time.perf_counter() - t0
t0 = time.perf_counter(); rf.render(m, **kw); second = time.perf_counter() - t0
print(first * 1e3, second * 1e3)
# the quick tier's background compile of the full tier (refraster._tiers) would outlive this
# process and take a core from the benchmark's next runs: stopped, its cache is thrown away
from refraster import _tiers
proc = _tiers._st["proc"]
if proc is not None:
    proc.kill()
    proc.wait()
"""
    out = []
    with tempfile.TemporaryDirectory() as cache:
        for _ in range(2):
            env = dict(os.environ, NUMBA_CACHE_DIR=cache)
            r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                               text=True, cwd=ROOT, timeout=900)
            out.append([float(x) for x in r.stdout.split()])
    return out  # [[cold first, steady], [cached first, steady]]


def _memory(mesh, view, proj, w, h):
    import refraster as rf
    rf.render(mesh, view=view, proj=proj, width=64, height=48)
    tracemalloc.start()
    rf.render(mesh, view=view, proj=proj, width=w, height=h)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 1.3M-face case")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--rounds", type=int, default=3,
                    help="alternating rounds of both renderers per case (median of medians)")
    ap.add_argument("--vertex-order", choices=("as-given", "first-use"), default="as-given",
                    help="first-use: each mesh's vertices renumbered in the order its faces "
                         "first use them, for both renderers (first_use_order)")
    ap.add_argument("--only", default="", help="run the cases whose name contains this")
    ap.add_argument("--normals", choices=("flat", "smooth"), default="flat",
                    help="smooth: each mesh's own vertex normals given to both renderers, "
                         "refraster with normals='smooth', llvmpipe interpolating them")
    a = ap.parse_args(argv)
    rows, stage_rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, mesh in _cases(a.quick):
            if a.only and a.only not in name:
                continue
            view, proj = _camera(mesh)
            path = pathlib.Path(tmp) / "scene.npz"
            vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
            if a.vertex_order == "first-use":
                vertices, faces = first_use_order(vertices, faces)
            extra = {}
            if a.normals == "smooth":
                extra["normals"] = np.asarray(mesh.vertex_normals)
                if a.vertex_order == "first-use":
                    raise SystemExit("--normals smooth: not with --vertex-order first-use")
            np.savez(path, vertices=vertices, faces=faces,
                     view=view, proj=proj, mvp=proj @ view, mv=view, width=W, height=H, **extra)
            for threads in (2, 1):
                # alternate the two renderers over a few rounds and keep the median of each
                # one's medians, so a slow spell of the shared machine hits both alike
                ours, colored, theirs, plain = [], [], [], []
                for _ in range(a.rounds):
                    r = _refraster_worker(path, threads, a.repeats)
                    ours.append(r["median_ms"])
                    colored.append(r["color_ms"])
                    plain.append(_refraster_worker(path, threads, a.repeats,
                                                   tuned=False)["median_ms"])
                    gl = _llvmpipe(path, threads, a.repeats)
                    theirs.append(gl["median_ms"] if gl else float("nan"))
                rows.append((name, len(mesh.faces), threads, float(np.median(ours)),
                             float(np.median(theirs)), float(np.median(colored)),
                             float(np.median(plain))))
            stage_rows.append((name, _stages((vertices, faces), view, proj, a.repeats)))
        big = _cases(False)[1][1] if not (a.quick or a.only) else None
    print(f"refraster {W}x{H} G-buffer vs llvmpipe (median over {a.rounds} alternating rounds "
          f"of the median ms/frame of {a.repeats} frames after 3 warm-up frames; "
          f"both processes with GLIBC_TUNABLES={TUNED}; {a.normals} normals)")
    print(f"{'case':22} {'faces':>9} {'thr':>3} {'refraster':>10} {'llvmpipe':>9} {'ratio':>6}"
          f" {'Mtri/s':>7} {'Mpx/s':>7} {'+colour':>8} {'ratio':>6} {'default':>8}"
          f" {'ratio':>6} {'dflt/tuned':>10}")
    for name, faces, thr, ms, gl, mc, md in rows:
        print(f"{name:22} {faces:9d} {thr:3d} {ms:10.1f} {gl:9.1f} {ms / gl:6.2f}"
              f" {faces / ms / 1e3:7.1f} {W * H / ms / 1e3:7.1f} {mc:8.1f} {mc / gl:6.2f}"
              f" {md:8.1f} {md / gl:6.2f} {md / ms:10.2f}")
    print("refraster: the G-buffer (window and eye depth, normal, primitive and object ids, "
          "facing, barycentrics); +colour: the same frame with Framebuffer.color read (the "
          "default shade, made on first read); llvmpipe: depth, normal, id, facing; default: "
          "the refraster G-buffer frame in a process without GLIBC_TUNABLES (the environment "
          "as a user has it), beside llvmpipe (tuned) and beside the tuned frame")
    print("\nstage breakdown, 2 threads (ms): vertex | setup | binning | raster+resolve (one"
          " fused pass) | G-buffer | total | colour (on read)")
    for name, s in stage_rows:
        print(f"{name:22} {s['vertex']:7.2f} {s['setup']:7.2f} {s['binning']:7.2f}"
              f" {s['raster']:7.2f}"
              f" {s['gbuffer']:7.2f} {s['total']:7.2f} {s['color']:7.2f}"
              f"   ({s['triangles']} triangles set up)")
    if a.only:
        return   # one case: no compile and memory measurements
    (cold, steady), (cached, steady2) = _compile_time()
    print(f"\ncompile: first render in a fresh cache {cold:.0f} ms (steady {steady:.1f} ms); "
          f"first render with the cache filled {cached:.0f} ms (steady {steady2:.1f} ms)")
    if big is not None:
        view, proj = _camera(big)
        print(f"peak traced memory, 1.3M faces at {W}x{H}: {_memory(big, view, proj, W, H):.0f} MiB;"
              f" at 4096x4096: {_memory(big, view, proj, 4096, 4096):.0f} MiB")


if __name__ == "__main__":
    main()
