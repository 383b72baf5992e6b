"""Golden generation of every registered scene: cold (fresh Numba cache) and warm, in subprocesses.

Each run is ``refraster golden generate --out DIR -q`` in a fresh subprocess. The first run in a
fresh ``NUMBA_CACHE_DIR`` compiles every kernel it meets; the next ``--warm`` runs load them, so
"compile ≈ cold − median(warm)". ``--repo PATH`` times another checkout (its ``refraster`` on
``PYTHONPATH``), so a change is measured beside the code before it in the same session; the
rounds alternate between the checkouts so that a slow spell of a shared machine hits both.

Run from the repository root: ``python -m benchmarks.golden_generate [--repo OLD] [--warm 3]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _generate(repo, cache_dir, out_dir):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(repo))
    cmd = [sys.executable, "-m", "refraster.cli", "-q", "golden", "generate", "--out",
           str(out_dir)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdin=subprocess.DEVNULL, cwd=str(repo))
    return time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", action="append", default=[],
                    help="another checkout to time beside this one (repeatable)")
    ap.add_argument("--warm", type=int, default=3, help="warm runs per checkout")
    args = ap.parse_args(argv)
    repos = [Path(__file__).resolve().parents[1]] + [Path(r).resolve() for r in args.repo]
    with tempfile.TemporaryDirectory(prefix="refraster-genbench-") as tmp:
        tmp = Path(tmp)
        cold = {}
        for k, repo in enumerate(repos):
            cold[k] = _generate(repo, tmp / f"cache{k}", tmp / f"cold{k}")
        warm = {k: [] for k in range(len(repos))}
        for i in range(args.warm):
            for k, repo in enumerate(repos):
                warm[k].append(_generate(repo, tmp / f"cache{k}", tmp / f"warm{k}-{i}"))
    print("golden generate (all registered scenes), wall time per subprocess, seconds")
    print("| checkout | cold (compiles) | warm (median) | warm runs | compile ≈ cold − warm |")
    print("|---|---:|---:|---|---:|")
    for k, repo in enumerate(repos):
        w = statistics.median(warm[k])
        runs = ", ".join(f"{x:.1f}" for x in warm[k])
        print(f"| {repo} | {cold[k]:.1f} | {w:.1f} | {runs} | {cold[k] - w:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
