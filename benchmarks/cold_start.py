"""Cold start: `refraster gallery --quick` twice in a fresh Numba cache directory.

The first run compiles every kernel it meets and writes them to the cache (``cache=True``); the
second run loads them. Both run in fresh subprocesses with the same ``NUMBA_CACHE_DIR``, so the
ratio is the time the cache saves a newcomer on their second command. Reported, not asserted.

``--kernels``: the per-kernel compile table of one cold run of the full gallery in this process'
order (``--jobs 1``, so that every compile happens in the one process whose Numba compile
events :mod:`benchmarks._compile_log` records): kernel, module, specialisations, compile
seconds (exclusive of the kernels compiled inside it), share of the cold run's wall time.
``--table LOG.json`` prints the table of a log written before.

Run from the repository root: ``python -m benchmarks.cold_start [--runs N] [--full]``,
``python -m benchmarks.cold_start --kernels [--quick] [--log OUT.json]``.
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="fresh cache directories to try")
    ap.add_argument("--full", action="store_true", help="full-size gallery instead of --quick")
    ap.add_argument("--kernels", action="store_true", help="the per-kernel compile table")
    ap.add_argument("--quick", action="store_true", help="with --kernels: the quick gallery")
    ap.add_argument("--log", help="with --kernels: keep the compile log here")
    ap.add_argument("--table", metavar="LOG.json", help="the table of an existing log")
    args = ap.parse_args(argv)
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
