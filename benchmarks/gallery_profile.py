"""Where a warm gallery's time goes, per section and per picture (issue 27).

``python -m benchmarks.gallery_profile [--sections a,b#k] [--quick] [--out DIR]``

Runs each gallery section in this process, one Numba thread (as ``refraster gallery``'s
workers do), with the kernel cache warm, and prints per section and per written picture the
CPU time (``time.process_time``) spent computing it (render, composition, difference pictures:
everything since the previous picture was written) and encoding + writing the PNG
(:func:`refraster.io.write_png`). Run it after a gallery has filled the cache, else it times
compiling.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path


def profile(sections, out_dir, quick=False):
    """``[(section, total_cpu, total_wall, [(file, compute_cpu, encode_cpu)])]``."""
    import importlib

    import refraster.io as rio

    real = rio.write_png
    rows = []
    mark = [0.0]
    log = []

    def timed_write(path, image):
        t0 = time.process_time()
        compute = t0 - mark[0]
        r = real(path, image)
        t1 = time.process_time()
        log.append((Path(path).relative_to(out_dir).as_posix(), compute, t1 - t0))
        mark[0] = t1
        return r

    rio.write_png = timed_write
    try:
        from refraster.gallery import split_item
        for name in sections:
            section, part = split_item(name)   # a work item "name#k": part k
            module = importlib.import_module(f"refraster.gallery.{section}")
            # sections import write_png by name: patch their module too
            patched = [m for m in list(sys.modules.values())
                       if m is not None and getattr(m, "__name__", "").startswith(
                           "refraster.gallery") and getattr(m, "write_png", None) is real]
            for m in patched:
                m.write_png = timed_write
            log.clear()
            c0, w0 = time.process_time(), time.perf_counter()
            mark[0] = c0
            module.render(out_dir, quick=quick, **({} if part is None else {"part": part}))
            rows.append((name, time.process_time() - c0, time.perf_counter() - w0, list(log)))
            for m in patched:
                m.write_png = real
    finally:
        rio.write_png = real
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sections", default="clipsurface,ldi,edges,cutaway,halos4d#0,halos4d#1,basic",
                   help="sections or work items (halos4d#0: part 0 of the halo section)")
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    if os.environ.get("NUMBA_NUM_THREADS") != "1":
        os.environ["NUMBA_NUM_THREADS"] = "1"
        os.execv(sys.executable, [sys.executable, "-m", "benchmarks.gallery_profile",
                                  *(argv if argv is not None else sys.argv[1:])])
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(a.out or tmp)
        out.mkdir(parents=True, exist_ok=True)
        rows = profile(a.sections.split(","), out, a.quick)
    total = sum(r[1] for r in rows)
    print(f"{'section / picture':48s} {'compute s':>10s} {'PNG s':>7s}")
    for name, cpu, wall, log in rows:
        enc = sum(e for _, _, e in log)
        print(f"{name:48s} {cpu - enc:10.2f} {enc:7.2f}   (section {cpu:.2f} s CPU, "
              f"{wall:.2f} s wall, {len(log)} pictures)")
        for fn, comp, e in log:
            print(f"  {fn:46s} {comp:10.2f} {e:7.2f}")
    print(f"all sections: {total:.2f} s CPU")


if __name__ == "__main__":
    main()
