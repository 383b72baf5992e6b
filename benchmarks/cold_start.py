"""Cold start: `refraster gallery --quick` twice in a fresh Numba cache directory.

The first run compiles every kernel it meets and writes them to the cache (``cache=True``); the
second run loads them. Both run in fresh subprocesses with the same ``NUMBA_CACHE_DIR``, so the
ratio is the time the cache saves a newcomer on their second command. Reported, not asserted.

Run from the repository root: ``python -m benchmarks.cold_start [--runs N] [--full]``.
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="fresh cache directories to try")
    ap.add_argument("--full", action="store_true", help="full-size gallery instead of --quick")
    args = ap.parse_args(argv)
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
