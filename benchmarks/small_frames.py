"""Issue 28 in one run: small frames, the default environment beside the tuned one, shared cores.

    python -m benchmarks.small_frames [--repeats N] [--rounds R] [--no-load] [--threads N]
                                      [--loop | --loop-only] [--loop-frames N]
                                      [--shared-ab [--ab-frames N]]

1. **Small frames**: a 12-face cube at 160×120 and 512×384, ``render`` with new outputs and
   with a reused framebuffer (``out=``: one from ``render``, cleared whole each frame, and a
   ``Framebuffer.reusable``, cleared where the previous frame drew), beside the cost of
   allocating and filling the buffers a frame returns or keeps — the seven ``Framebuffer``
   arrays (depth, eye depth, normal, primitive and object ids, facing, barycentrics: 37 bytes
   per pixel) and the int64 face image the pending colour keeps (8 bytes per pixel) — filled
   with their clear values.
2. **Default vs tuned environment**: every number of 1 and 3 in two processes, one with the
   environment as a user has it, one with ``GLIBC_TUNABLES`` malloc tuning
   (:data:`benchmarks.raster.TUNED`); the 82k-face icosphere at 1024×768, flat and
   ``normals="smooth"`` (vertex normals cached on the mesh's digest; the uncached cost, a
   ``vertex_normals`` call, is printed beside).
   A ``faults`` column counts the minor page faults per frame (fresh memory touched by the
   frame): a count, not a time, so the default-vs-tuned comparison holds on a busy machine.
3. **Shared cores**: with two CPU-bound processes started by this script (busy loops, one per
   core) running, the cube at 512×384 and the 82k frame with ``NUMBA_NUM_THREADS=2`` in three
   modes, each in processes of its own, alternating over the rounds: ``auto`` (refraster's
   choice, :mod:`refraster._threads`), ``2`` (``REFRASTER_THREADS=2``: Numba's plain
   behaviour), the same with ``OMP_WAIT_POLICY=passive`` and with the ``workqueue`` layer, and
   ``1`` thread (:data:`MODES`); the ratios to ``1`` are the issue's measure.

   ``--shared-ab``: the same comparison without the process-to-process noise of busy
   cores — ``auto`` and ``1`` alternating frame by frame in one process (the variable is read
   per frame), one process per round.
4. **Loops** (``--loop``): the same numbers as 1–2, but each call alone in a process of its
   own, repeated (:func:`worker_loop`) — a loop over frames that drops each framebuffer, or
   reuses one — in three environments: as a user has it, tuned, and as a user had it before
   the output pool (``REFRASTER_POOL_MB=0``). In part 1 every call follows a different one
   (the 82k-face frames among them), so caches are cold and malloc's state is the one those
   left behind; in a loop, malloc's own behaviour shows (a loop of fresh 512×384 outputs
   page-faults every frame with glibc's defaults).

Wall times are medians of per-round medians (rounds alternate the cases, so a slow spell of a
shared machine hits all alike); ``cpu`` is the calling thread's CPU time (``time.thread_time``;
on one thread the frame's own cost, whatever else runs).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

from benchmarks.raster import TUNED

W, H = 1024, 768


def _scenes():
    import trimesh

    import refraster as rf
    from refraster import scenes
    from refraster.mesh import as_mesh
    cube = scenes.cube()
    ico = trimesh.creation.icosphere(6)
    mk = lambda tm: as_mesh((np.asarray(tm.vertices, np.float64),   # noqa: E731
                             np.asarray(tm.faces, np.int64)))
    view = rf.look_at([1.6, 1.2, 2.4], [0, 0, 0])
    cam = rf.camera.frame_bounds(ico.bounds, width=W, height=H, margin=1.0)
    out = {}
    for w, h in ((160, 120), (512, 384)):
        out[f"cube {w}x{h}"] = (mk(cube), dict(view=view, proj=rf.perspective(45, w / h, .5, 10),
                                               width=w, height=h))
    out["ico 81,920 1024x768"] = (mk(ico), dict(view=cam.view, proj=cam.proj, width=W, height=H))
    out["ico 81,920 smooth"] = (out["ico 81,920 1024x768"][0],
                                dict(out["ico 81,920 1024x768"][1],
                                     raster=rf.RasterState(normals="smooth")))
    return out


def _alloc_fill(h, w):
    return (np.full((h, w), np.float32(1), np.float32), np.full((h, w), np.inf, np.float32),
            np.zeros((h, w, 3), np.float32), np.full((h, w), -1, np.int32),
            np.full((h, w), -1, np.int32), np.zeros((h, w), np.bool_),
            np.zeros((h, w, 3), np.float32), np.full((h, w), -1, np.int64))


def _time(fn):
    t0, c0 = time.perf_counter(), time.thread_time()
    fn()
    return (time.perf_counter() - t0) * 1e3, (time.thread_time() - c0) * 1e3


def _faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def _rounds(fns, repeats, rounds):
    """{name: (wall ms, cpu ms, page faults per call)}: median over rounds of the median of
    ``repeats`` calls, the functions alternating call by call; the minor page faults (fresh
    memory touched) are the mean per call (a count, not a time: immune to other processes)."""
    for fn in fns.values():
        fn()
        fn()
    per = {k: ([], [], []) for k in fns}
    for _ in range(rounds):
        acc = {k: ([], [], []) for k in fns}
        for _ in range(repeats):
            for k, fn in fns.items():
                f0 = _faults()
                wall, cpu = _time(fn)
                acc[k][0].append(wall)
                acc[k][1].append(cpu)
                acc[k][2].append(_faults() - f0)
        for k in fns:
            for j in range(3):
                per[k][j].append(np.median(acc[k][j]) if j < 2 else np.mean(acc[k][j]))
    return {k: (float(np.median(v[0])), float(np.median(v[1])), float(np.mean(v[2])))
            for k, v in per.items()}


def worker_frames(repeats, rounds):
    import refraster as rf
    from refraster.mesh import vertex_normals
    sc = _scenes()
    fns = {}
    for name, (m, kw) in sc.items():
        out = rf.render(m, **kw)
        fns[name] = (lambda m=m, kw=kw: rf.render(m, **kw))
        fns[name + " out="] = (lambda m=m, kw=kw, out=out: rf.render(m, **kw, out=out))
        if hasattr(rf.Framebuffer, "reusable"):   # the fast clear (fifth pass)
            ro = rf.Framebuffer.reusable(kw["width"], kw["height"])
            fns[name + " out=reusable"] = (lambda m=m, kw=kw, ro=ro: rf.render(m, **kw, out=ro))
        if name.startswith("cube"):
            fns[name + " alloc+fill"] = (lambda kw=kw: _alloc_fill(kw["height"], kw["width"]))
    m = sc["ico 81,920 smooth"][0]
    fns["vertex_normals 81,920 (uncached)"] = lambda: vertex_normals(m.vertices, m.faces)
    return _rounds(fns, repeats, rounds)


#: The calls of the loop part: each alone in a process, as a loop of frames makes it.
LOOP_KINDS = ("new", "new+colour", "out=", "out=reusable", "alloc+fill")
LOOP_CASES = ("cube 160x120", "cube 512x384", "ico 81,920 1024x768", "ico 81,920 smooth")
#: Environments of the loop part: as a user has it, with malloc tuning, and as a user had it
#: before the output pool (``REFRASTER_POOL_MB=0``: every frame's outputs new NumPy arrays).
LOOP_ENVS = {"default": {}, "tuned": {"GLIBC_TUNABLES": TUNED},
             "default, pool off": {"REFRASTER_POOL_MB": "0"}}


def worker_loop(case, kind, frames):
    """One call repeated ``frames`` times after 20 warm-up calls (nothing else in between: a
    loop over frames that drops each one, or reuses one framebuffer): (wall ms, cpu ms, page
    faults per call), medians."""
    import refraster as rf
    m, kw = _scenes()[case]
    if kind == "alloc+fill":
        def fn():
            return _alloc_fill(kw["height"], kw["width"])
    elif kind in ("out=", "out=reusable"):
        fb = (rf.render(m, **kw) if kind == "out=" else
              rf.Framebuffer.reusable(kw["width"], kw["height"]))

        def fn():
            return rf.render(m, **kw, out=fb)
    else:
        colour = kind == "new+colour"

        def fn():
            fb = rf.render(m, **kw)
            return fb.color if colour else fb
    for _ in range(20):
        fn()
    walls, cpus = [], []
    f0 = _faults()
    for _ in range(frames):
        wall, cpu = _time(fn)
        walls.append(wall)
        cpus.append(cpu)
    return (float(np.median(walls)), float(np.median(cpus)), (_faults() - f0) / frames)


def _loop(base, a):
    """Part 1-2 as loops: every (case, call, environment) in a process of its own, the
    environments alternating process by process over ``rounds``; medians of the processes."""
    print(f"\nloops (each call alone in a process, {a.loop_frames} frames after 20 warm-up; "
          f"load before: {_loadavg()})")
    res = {}
    for _ in range(a.rounds):
        for case in a.loop_cases.split(";"):
            kinds = LOOP_KINDS if case.startswith("cube") else LOOP_KINDS[:4]
            for kind in kinds:
                for env, extra in LOOP_ENVS.items():
                    code = (f"import json; from benchmarks.small_frames import worker_loop as w; "
                            f"print(json.dumps(w({case!r}, {kind!r}, {a.loop_frames})))")
                    r = subprocess.run([sys.executable, "-c", code], env=dict(base, **extra),
                                       capture_output=True, text=True, timeout=1800)
                    if r.returncode != 0:
                        raise RuntimeError(r.stderr)
                    res.setdefault((case, kind, env), []).append(
                        json.loads(r.stdout.strip().splitlines()[-1]))
    print(f"load after: {_loadavg()}")
    med = {k: tuple(float(np.median([x[j] for x in v])) for j in range(3))
           for k, v in res.items()}
    envs = list(LOOP_ENVS)
    print(f"{'case':22} {'call':13}" + "".join(f" {e + ' cpu':>19} {'faults':>7}" for e in envs)
          + f" {'default/tuned':>14}")
    for case in a.loop_cases.split(";"):
        for kind in LOOP_KINDS:
            if (case, kind, "default") not in med:
                continue
            cells = "".join(f" {med[case, kind, e][1]:19.3f} {med[case, kind, e][2]:7.0f}"
                            for e in envs)
            ratio = med[case, kind, "default"][1] / med[case, kind, "tuned"][1]
            print(f"{case:22} {kind:13}{cells} {ratio:14.2f}")
    for case in ("cube 160x120", "cube 512x384"):
        if (case, "new", "default") not in med:
            continue
        for env in envs:
            new, fill = med[case, "new", env][1], med[case, "alloc+fill", env][1]
            print(f"{case} {env}: new / alloc+fill = {new / fill:.2f} ({new:.3f} / {fill:.3f} "
                  f"ms cpu); out= {med[case, 'out=', env][1]:.3f}, out=reusable "
                  f"{med[case, 'out=reusable', env][1]:.3f} ms cpu")


SHARED = ("cube 512x384", "ico 81,920 1024x768")
#: Thread modes of the shared-core part: refraster's choice, Numba's plain 2 threads (OpenMP
#: layer, libgomp's default wait policy; then passive waiting; then the workqueue layer), 1.
MODES = {"auto": dict(REFRASTER_THREADS="auto"), "2": dict(REFRASTER_THREADS="2"),
         "2 passive": dict(REFRASTER_THREADS="2", OMP_WAIT_POLICY="passive"),
         "2 workqueue": dict(REFRASTER_THREADS="2", NUMBA_THREADING_LAYER="workqueue"),
         "auto passive": dict(REFRASTER_THREADS="auto", OMP_WAIT_POLICY="passive"),
         "1": dict(REFRASTER_THREADS="1")}


def worker_shared(repeats, rounds):
    """One thread mode per process (``REFRASTER_THREADS`` from the caller): a mode's spinning
    or sleeping workers never touch another mode's frames."""
    import refraster as rf
    sc = _scenes()
    fns = {name: (lambda m=sc[name][0], kw=sc[name][1]: rf.render(m, **kw)) for name in SHARED}
    return _rounds(fns, repeats, rounds)


def _run(kind, env, repeats, rounds):
    code = (f"import json; from benchmarks.small_frames import worker_{kind} as w; "
            f"print(json.dumps(w({repeats}, {rounds})))")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       timeout=1800)
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _hogs(n):
    code = "while True: pass"
    return [subprocess.Popen([sys.executable, "-c", code]) for _ in range(n)]


def _loadavg():
    with open("/proc/loadavg") as fh:
        return fh.read().strip()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-load", action="store_true", help="skip the shared-core part")
    ap.add_argument("--shared-only", action="store_true", help="only the shared-core part")
    ap.add_argument("--loop", action="store_true",
                    help="also the loop part: each call alone in its own process (as a loop "
                         "of frames makes it), default / tuned / pool off")
    ap.add_argument("--loop-only", action="store_true", help="only the loop part")
    ap.add_argument("--shared-ab", action="store_true",
                    help="only part 3b: auto and 1 thread alternating frame by frame in one "
                         "process under two busy loops (one process per round)")
    ap.add_argument("--ab-frames", type=int, default=400)
    ap.add_argument("--loop-frames", type=int, default=200)
    ap.add_argument("--loop-cases", default=";".join(LOOP_CASES),
                    help="semicolon-separated cases of the loop part (case names contain commas; default: all)")
    ap.add_argument("--threads", default=None,
                    help="REFRASTER_THREADS for parts 1-2 (default: refraster's choice; 1 gives "
                         "the one-thread CPU times the issue's aims are stated in)")
    a = ap.parse_args(argv)
    base = {k: v for k, v in os.environ.items()
            if k not in ("GLIBC_TUNABLES", "REFRASTER_THREADS", "OMP_WAIT_POLICY",
                         "GOMP_SPINCOUNT", "NUMBA_THREADING_LAYER")}
    base["NUMBA_NUM_THREADS"] = "2"
    fbase = base if a.threads is None else dict(base, REFRASTER_THREADS=str(a.threads))
    if a.shared_ab:
        _shared_ab(base, a)
        return
    if not a.shared_only and not a.loop_only:
        _frames(fbase, a)
    if a.loop or a.loop_only:
        _loop(fbase, a)
    if not a.no_load and not a.loop_only:
        _shared(base, a)


def _frames(base, a):
    print(f"load before: {_loadavg()}")
    default = _run("frames", base, a.repeats, a.rounds)
    tuned = _run("frames", dict(base, GLIBC_TUNABLES=TUNED), a.repeats, a.rounds)
    print(f"load after:  {_loadavg()}")
    print("\n1-2. frames, NUMBA_NUM_THREADS=2, refraster's thread choice (ms, median; "
          "wall | thread cpu)")
    print(f"{'case':38} {'default wall':>12} {'cpu':>7} {'faults':>7} {'tuned wall':>11}"
          f" {'cpu':>7} {'faults':>7} {'default/tuned':>13}")
    for k in default:
        dw, dc, df = default[k]
        tw, tc, tf = tuned[k]
        print(f"{k:38} {dw:12.3f} {dc:7.3f} {df:7.0f} {tw:11.3f} {tc:7.3f} {tf:7.0f}"
              f" {dw / tw:13.2f}")
    for size in ("160x120", "512x384"):
        k = f"cube {size}"
        for env, r in (("default", default), ("tuned", tuned)):
            reu = (f", out=reusable {r[k + ' out=reusable'][1]:.3f} ms cpu"
                   if k + " out=reusable" in r else "")
            print(f"cube {size} {env}: render / alloc+fill = "
                  f"{r[k][0] / r[k + ' alloc+fill'][0]:.2f} (wall), "
                  f"{r[k][1] / r[k + ' alloc+fill'][1]:.2f} (cpu); out= {r[k + ' out='][0]:.3f} ms"
                  f" wall, {r[k + ' out='][1]:.3f} ms cpu{reu}")


def worker_shared_ab(frames):
    """In this one process, with the busy loops of the caller running: the same frame with
    ``REFRASTER_THREADS=auto`` and ``=1`` alternating frame by frame (the variable is read per
    frame), so both see the same moments of the shared machine; {case: (auto ms, 1-thread ms)},
    median wall times."""
    import refraster as rf
    sc = _scenes()
    out = {}
    for name in SHARED:
        m, kw = sc[name]
        n = frames if name.startswith("cube") else max(frames // 10, 5)
        res = {"auto": [], "1": []}
        for mode in res:
            os.environ["REFRASTER_THREADS"] = mode
            rf.render(m, **kw)
        for r in range(n):
            for mode in (("auto", "1") if r % 2 else ("1", "auto")):
                os.environ["REFRASTER_THREADS"] = mode
                res[mode].append(_time(lambda: rf.render(m, **kw))[0])
        out[name] = (float(np.median(res["auto"])), float(np.median(res["1"])))
    return out


def _shared_ab(base, a):
    hogs = _hogs(2)
    try:
        time.sleep(1.0)
        print(f"\n3b. shared cores, one process, auto and 1 thread alternating frame by frame; "
              f"two busy loops; load: {_loadavg()}")
        code = ("import json; from benchmarks.small_frames import worker_shared_ab as w; "
                f"print(json.dumps(w({a.ab_frames})))")
        runs = []
        for _ in range(a.rounds):
            r = subprocess.run([sys.executable, "-c", code], env=dict(base), capture_output=True,
                               text=True, timeout=1800)
            if r.returncode != 0:
                raise RuntimeError(r.stderr)
            runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
        print(f"   load at the end: {_loadavg()}")
    finally:
        for p in hogs:
            p.kill()
            p.wait()
    for name in SHARED:
        cells = " ".join(f"{r[name][0]:.2f}/{r[name][1]:.2f} ({r[name][0] / r[name][1]:.2f})"
                         for r in runs)
        print(f"{name:24} auto/1-thread wall ms (ratio), one process per round: {cells}")


def _shared(base, a):
    hogs = _hogs(2)
    try:
        time.sleep(1.0)
        print(f"\n3. shared cores: two busy-loop processes running; load: {_loadavg()}")
        shared = {}
        for _ in range(a.rounds):   # the modes alternate process by process
            for mode, env in MODES.items():
                r = _run("shared", dict(base, **env), a.repeats, 1)
                for name in SHARED:
                    shared.setdefault(f"{name} {mode}", []).append(r[name][0])
        shared = {k: (float(np.median(v)),) for k, v in shared.items()}
        print(f"   load at the end: {_loadavg()}")
    finally:
        for p in hogs:
            p.kill()
            p.wait()
    print("wall ms, median of per-process medians; in brackets: / the 1-thread time")
    print(f"{'case':24}" + "".join(f" {m:>18}" for m in MODES))
    for name in SHARED:
        t1 = shared[f"{name} 1"][0]
        cells = [shared[f"{name} {m}"][0] for m in MODES]
        print(f"{name:24}" + "".join(f" {c:9.2f} ({c / t1:5.2f})" for c in cells))


if __name__ == "__main__":
    main()
