"""Cold start: `refraster gallery --quick` twice in a fresh Numba cache directory.

The first run compiles every kernel it meets and writes them to the cache (``cache=True``); the
second run loads them. Both run in fresh subprocesses with the same ``NUMBA_CACHE_DIR``, so the
ratio is the time the cache saves a newcomer on their second command. Reported, not asserted.

``--kernels``: the per-kernel compile table of one cold run of the full gallery in this process'
order (``--jobs 1``, so that every compile happens in the one process whose Numba compile
events :mod:`benchmarks._compile_log` records): kernel, module, specialisations, compile
seconds (exclusive of the kernels compiled inside it), share of the cold run's wall time.
``--table LOG.json`` prints the table of a log written before.

``--render``: a user's first ``refraster.render`` of a cube (640×480, colour read) in a fresh
``NUMBA_CACHE_DIR``, as ``python -c`` would run it: wall and CPU seconds of the process (its own
and its children's), the tier it ran (``refraster._tiers``), for the default (``auto``: the
quick tier while a second process compiles the full one) and ``REFRASTER_TIER=full`` in
alternation; then how long until the full tier is in the cache, the second run, and the median
frame of each tier once both are cached.

Run from the repository root: ``python -m benchmarks.cold_start [--runs N] [--full]``,
``python -m benchmarks.cold_start --kernels [--quick] [--log OUT.json]``,
``python -m benchmarks.cold_start --render [--runs N]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _gallery(cache_dir, out_dir, quick):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    cmd = [sys.executable, "-m", "refraster.cli", "gallery", "--out", str(out_dir), "-q"]
    if quick:
        cmd.append("--quick")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdin=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _cached_files(cache_dir):
    return sum(1 for p in Path(cache_dir).rglob("*") if p.suffix in (".nbi", ".nbc"))


def kernel_table(log):
    """Markdown rows of the per-kernel compile table of a :mod:`benchmarks._compile_log` log;
    Numba's own library functions (``np.empty``, ``min``, …, compiled for the kernels that
    call them) are one row."""
    import collections
    wall = log["wall"]
    rows = collections.OrderedDict()
    for r in log["records"]:
        key = ((r["module"], r["kernel"]) if r["module"].startswith("refraster")
               else ("numba", "(NumPy and builtin functions compiled for the kernels)"))
        a = rows.setdefault(key, [set(), 0.0])
        a[0].add((r["module"], r["kernel"], tuple(r["args"])))
        a[1] += r["exclusive"]
    total = sum(t for _, t in rows.values())
    out = [f"cold run {wall:.1f} s, compiling {total:.1f} s ({100 * total / wall:.0f} %), "
           f"{sum(len(k) for k, _ in rows.values())} compiles",
           "| kernel | module | specialisations | compile s | share of the cold run |",
           "|---|---|---:|---:|---:|"]
    for (module, kernel), (specs, t) in sorted(rows.items(), key=lambda kv: -kv[1][1]):
        out.append(f"| `{kernel}` | `{module}` | {len(specs)} | {t:.1f} | "
                   f"{100 * t / wall:.1f} % |")
    return out


def _kernels(args):
    import json
    if args.table:
        log = json.loads(Path(args.table).read_text())
    else:
        with tempfile.TemporaryDirectory(prefix="refraster-cold-") as tmp:
            out = Path(args.log) if args.log else Path(tmp) / "log.json"
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba-cache"))
            cmd = [sys.executable, "-m", "benchmarks._compile_log", str(out), "--", "gallery",
                   "--out", str(Path(tmp) / "g"), "-q", "--jobs", "1"]
            if args.quick:
                cmd.append("--quick")
            subprocess.run(cmd, check=True, env=env, stdin=subprocess.DEVNULL)
            log = json.loads(out.read_text())
    print("\n".join(kernel_table(log)))
    return 0


_FIRST_RENDER = """
import resource, sys, time
t0 = time.perf_counter()
c0 = time.process_time()
import numpy as np
import refraster
from refraster import _tiers, scenes
cube = scenes.cube()
mesh = (np.asarray(cube.vertices, np.float64), np.asarray(cube.faces, np.int64))
view = refraster.look_at((1.6, 1.2, 2.4), (0, 0, 0))
proj = refraster.perspective(45.0, 4 / 3, 0.5, 10.0)
t1 = time.perf_counter()
fb = refraster.render(mesh, view=view, proj=proj, width=640, height=480)
np.asarray(fb.color)
t2 = time.perf_counter()
tier = _tiers.state()[0]
frames = []
for _ in range(int(sys.argv[1])):
    t = time.perf_counter()
    fb = refraster.render(mesh, view=view, proj=proj, width=640, height=480)
    np.asarray(fb.color)
    frames.append(time.perf_counter() - t)
ch = resource.getrusage(resource.RUSAGE_CHILDREN)
print(t2 - t0, t2 - t1, time.process_time() - c0, ch.ru_utime + ch.ru_stime, tier,
      sorted(frames)[len(frames) // 2] if frames else 0.0)
"""


def _first_render(env, frames=0):
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", _FIRST_RENDER, str(frames)], env=env, check=True,
                       capture_output=True, text=True, stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    first, render, cpu, children, tier, frame = r.stdout.split()
    return dict(wall=wall, first=float(first), render=float(render), cpu=float(cpu),
                children=float(children), tier=tier, frame_ms=1e3 * float(frame))


def _full_tier_cached(env):
    code = "from refraster import _tiers; print(_tiers._full_cached())"
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL).stdout.strip() == "True"


def _load():
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _render(args):
    rows = []
    for i in range(args.runs):
        for setting in ("auto", "full"):
            with tempfile.TemporaryDirectory(prefix="refraster-cold-") as tmp:
                env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba-cache"),
                           REFRASTER_TIER=setting)
                load = _load()
                r = _first_render(env)
                t0 = time.perf_counter()
                while setting == "auto" and not _full_tier_cached(env):
                    time.sleep(2.0)
                r["full_after"] = time.perf_counter() - t0 if setting == "auto" else 0.0
                r["second"] = _first_render(env)["wall"]
                if setting == "auto" and i == 0:
                    r["frames"] = {t: _first_render(dict(env, REFRASTER_TIER=t), 15)["frame_ms"]
                                   for t in ("quick", "full", "quick", "full")}
                rows.append((setting, load, r))
    print("first refraster.render of a cube (640x480, colour read), fresh NUMBA_CACHE_DIR; "
          "CPU = the process's own + its children's (a second process outliving it is not "
          "counted: see 'full tier cached after')")
    print("| REFRASTER_TIER | load before | tier ran | python -c wall s | render wall s | "
          "CPU s | full tier cached after s | second run wall s |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    for setting, load, r in rows:
        print(f"| {setting} | {load} | {r['tier']} | {r['wall']:.1f} | {r['render']:.1f} | "
              f"{r['cpu'] + r['children']:.1f} | "
              f"{r['full_after']:.0f} | {r['second']:.1f} |" if setting == "auto" else
              f"| {setting} | {load} | {r['tier']} | {r['wall']:.1f} | {r['render']:.1f} | "
              f"{r['cpu'] + r['children']:.1f} | — | {r['second']:.1f} |")
    for setting, _, r in rows:
        if "frames" in r:
            print("median warm frame, cube 640x480 with colour (15 frames; the later of each "
                  "tier's two runs): quick "
                  f"{r['frames']['quick']:.1f} ms, full {r['frames']['full']:.1f} ms")
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="fresh cache directories to try")
    ap.add_argument("--full", action="store_true", help="full-size gallery instead of --quick")
    ap.add_argument("--kernels", action="store_true", help="the per-kernel compile table")
    ap.add_argument("--quick", action="store_true", help="with --kernels: the quick gallery")
    ap.add_argument("--log", help="with --kernels: keep the compile log here")
    ap.add_argument("--table", metavar="LOG.json", help="the table of an existing log")
    ap.add_argument("--render", action="store_true",
                    help="a first refraster.render of a cube, quick tier and full")
    args = ap.parse_args(argv)
    if args.render:
        return _render(args)
    if args.kernels or args.table:
        return _kernels(args)
    rows = []
    for _ in range(args.runs):
        with tempfile.TemporaryDirectory(prefix="refraster-cold-") as tmp:
            cache = Path(tmp) / "numba-cache"
            first = _gallery(cache, Path(tmp) / "g1", not args.full)
            n_files = _cached_files(cache)
            second = _gallery(cache, Path(tmp) / "g2", not args.full)
            rows.append((first, second, n_files, _cached_files(cache) - n_files))
    mode = "full" if args.full else "quick"
    print(f"refraster gallery --{mode}, fresh NUMBA_CACHE_DIR per run, wall time per subprocess")
    print("| run | first (compiles) s | second (cached) s | ratio | compile ≈ first − second s |"
          " cache files after first | files added by second |")
    print("|---|---|---|---|---|---|---|")
    for i, (first, second, n_files, added) in enumerate(rows, 1):
        print(f"| {i} | {first:.2f} | {second:.2f} | {first / second:.1f}x | "
              f"{first - second:.2f} | {n_files} | {added} |")
    print("'files added by second' > 0 means the second run compiled something (a cache miss).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
