"""llvmpipe timings in a process of their own.

llvmpipe's speed depends on its environment: ``LP_NUM_THREADS`` must be set before the context
exists, and glibc's default malloc trimming costs it about 40 % on large frames (its per-frame
scene memory is unmapped and faulted in again; ``/work/shared/LLVMPIPE.md``). :func:`time_llvmpipe`
therefore runs the oracle of ``tests/oracles/llvmpipe.py`` in a fresh interpreter with
``LP_NUM_THREADS`` and ``GLIBC_TUNABLES=glibc.malloc.trim_threshold=4294967296`` set, and reads back
its timings as JSON. Run from the repository root::

    python -m benchmarks._llvmpipe SCENE.npz --mode peel --layers 8 --repeats 5

``SCENE.npz`` holds ``clip_<k>`` (V, 4) float32 and ``faces_<k>`` (F, 3) int32 for draw calls
k = 0, 1, ..., plus ``width`` and ``height``. Timed: the draw passes and ``glFinish`` with the
geometry already uploaded; nothing is read back (a GPU application keeps its layers in textures).
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

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
TUNED_MALLOC = "glibc.malloc.trim_threshold=4294967296"


def _load(path):
    with np.load(path, allow_pickle=False) as z:
        n = sum(1 for k in z.files if k.startswith("clip_"))
        draws = [(z[f"clip_{k}"], z[f"faces_{k}"]) for k in range(n)]
        return draws, int(z["width"]), int(z["height"])


def _measure(draws, width, height, *, mode, layers, repeats, cull):
    from tests.oracles import llvmpipe

    t0 = time.perf_counter()
    scene = llvmpipe.GLScene(draws, width, height, cull=cull)
    upload_ms = (time.perf_counter() - t0) * 1e3

    def frame():
        if mode == "peel":
            scene.peel(layers, read=False)
        else:
            scene._pass(0, peel=False, count_samples=False)
            scene.ctx.finish()

    t0 = time.perf_counter()
    frame()
    first_ms = (time.perf_counter() - t0) * 1e3
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        frame()
        times.append((time.perf_counter() - t0) * 1e3)
    layers_found = len(scene.peel(None)) if mode == "peel" else 1
    scene.release()
    return {
        "renderer": llvmpipe.renderer(),
        "threads": os.environ.get("LP_NUM_THREADS", ""),
        "glibc_tunables": os.environ.get("GLIBC_TUNABLES", ""),
        "mode": mode,
        "layers": layers,
        "layers_in_scene": layers_found,
        "upload_ms": upload_ms,
        "first_ms": first_ms,
        "times_ms": times,
        "median_ms": float(np.median(times)),
    }


def time_llvmpipe(draws, width, height, *, mode="peel", layers=8, repeats=5, threads=2,
                  cull="none", timeout=900):
    """Time ``draws`` (list of ``(clip (V, 4) float32, faces (F, 3))``) in a fresh process.

    Returns the child's JSON result (``median_ms``, ``times_ms``, ``renderer`` ...). Raises
    ``RuntimeError`` with the child's stderr when it fails (for example no EGL).
    """
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / "scene.npz"
        arrays = {"width": np.int64(width), "height": np.int64(height)}
        for k, (clip, faces) in enumerate(draws):
            arrays[f"clip_{k}"] = np.ascontiguousarray(clip, np.float32)
            arrays[f"faces_{k}"] = np.ascontiguousarray(faces, np.int32)
        np.savez(path, **arrays)
        env = dict(os.environ, LP_NUM_THREADS=str(threads), GLIBC_TUNABLES=TUNED_MALLOC)
        cmd = [sys.executable, "-m", "benchmarks._llvmpipe", str(path), "--mode", mode,
               "--layers", str(layers), "--repeats", str(repeats), "--cull", cull]
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=timeout)
        if proc.returncode != 0:
            raise RuntimeError(f"llvmpipe timing process failed:\n{proc.stderr.strip()}")
        return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", help=".npz with clip_<k>, faces_<k>, width, height")
    ap.add_argument("--mode", choices=("peel", "raster"), default="peel")
    ap.add_argument("--layers", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--cull", choices=("none", "back", "front"), default="none")
    args = ap.parse_args(argv)
    draws, width, height = _load(args.scene)
    result = _measure(draws, width, height, mode=args.mode, layers=args.layers,
                      repeats=args.repeats, cull=args.cull)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
