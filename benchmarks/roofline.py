"""A roofline for the G-buffer frame: how far ``refraster.render`` is from the machine's limits.

    python -m benchmarks.roofline [--quick] [--repeats N] [--check-only]

Two ceilings are measured in the same run as the frame, on the same machine and load:

* **fill bandwidth** — the frame's output bytes (window and eye depth, normal, primitive and
  object ids, facing, barycentrics: what ``render`` returns) written by a library baseline:
  ``ndarray.fill`` into an array already mapped (a memset), ``np.copyto`` between two mapped
  arrays (read + write), and ``np.zeros`` + ``fill`` of a fresh array (the page faults a fresh
  output pays). The fill ceiling of a frame is its bytes at the mapped memset's rate;
* **triangle setup** — :func:`setup_ceiling`, the least per-triangle work any exact rasterizer
  does before its first pixel: perspective divide and viewport of each vertex, snapping to
  1/256 pixel, then per triangle the doubled signed area (the edge functions' determinant) and
  the clamped pixel bounding box, 24 bytes per triangle stored (no clipping, no culling
  decisions, no binning; the edge coefficients follow from the snapped vertices, which a
  rasterizer keeps per vertex). Its triangles/s, run with the frame's threads, bound setup.

For each case the frame's time is split by stage (:func:`benchmarks.raster._stages`: vertex,
setup, binning, rasterization + resolve, G-buffer) and set beside both ceilings; the frame can be
no faster than the slower of the two (``bound``), and ``frame / bound`` says how far is left.

The ceiling kernels are the yardstick, so they must not move with optimisation work: their
outputs on the 81,920-face icosphere have a recorded SHA-256 (:data:`DIGESTS`), checked on every
run (``--check-only`` checks and exits; a changed kernel fails with the digests named).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pathlib
import platform
import time

import numpy as np
from numba import njit, prange

from benchmarks._timing import median_ms

W, H = 1024, 768
SUBPIXEL = 8
#: SHA-256 of :func:`setup_ceiling`'s outputs (area, box) on the icosphere of 81,920
#: faces with :func:`benchmarks.raster._camera`'s view at 1024×768.
DIGESTS = pathlib.Path(__file__).with_name("roofline_digests.json")


@njit(parallel=True, cache=True)
def _vertices(clip, width, height, bits, X, Y):
    scale = float(1 << bits)
    for i in prange(clip.shape[0]):
        iw = 1.0 / clip[i, 3]
        x = (clip[i, 0] * iw * 0.5 + 0.5) * width
        y = (clip[i, 1] * iw * 0.5 + 0.5) * height
        X[i] = np.int64(np.round(x * scale - 0.5 * scale))
        Y[i] = np.int64(np.round(y * scale - 0.5 * scale))


@njit(parallel=True, cache=True)
def _triangles(faces, X, Y, width, height, bits, area, box):
    for t in prange(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        x0, y0, x1, y1, x2, y2 = X[a], Y[a], X[b], Y[b], X[c], Y[c]
        area[t] = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        lo_x = min(x0, min(x1, x2)) >> bits
        hi_x = (max(x0, max(x1, x2)) >> bits) + 1
        lo_y = min(y0, min(y1, y2)) >> bits
        hi_y = (max(y0, max(y1, y2)) >> bits) + 1
        box[t, 0] = max(lo_x, 0)
        box[t, 1] = min(hi_x, width - 1)
        box[t, 2] = max(lo_y, 0)
        box[t, 3] = min(hi_y, height - 1)


def setup_ceiling(clip, faces, width=W, height=H, bits=SUBPIXEL):
    """The setup-only kernel: ``(area, box)`` of every face (see the module docstring)."""
    nv, nf = len(clip), len(faces)
    X, Y = np.empty(nv, np.int64), np.empty(nv, np.int64)
    area = np.empty(nf, np.int64)
    box = np.empty((nf, 4), np.int32)
    _vertices(clip, width, height, bits, X, Y)
    _triangles(faces, X, Y, width, height, bits, area, box)
    return area, box


def digest(arrays):
    """SHA-256 of the arrays' bytes, in order."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _scene(mesh):
    from benchmarks.raster import _camera
    from refraster.raster.primitive import transform_vertices
    view, proj = _camera(mesh)
    clip = transform_vertices(np.asarray(mesh.vertices, np.float64), proj @ view)
    return view, proj, np.ascontiguousarray(clip, np.float64), np.asarray(mesh.faces, np.int64)


def check_digests():
    """Compare the ceiling kernel's outputs with :data:`DIGESTS`; returns the mismatches."""
    import trimesh
    recorded = json.loads(DIGESTS.read_text())
    _, _, clip, faces = _scene(trimesh.creation.icosphere(6))
    got = {"setup_ceiling/icosphere_81920": digest(setup_ceiling(clip, faces))}
    return {k: (recorded.get(k), v) for k, v in got.items() if recorded.get(k) != v}


def _bandwidth(nbytes, repeats):
    """GB/s of a memset into a mapped array, a copy between mapped arrays, a fresh fill."""
    n = nbytes // 4
    dst, src = np.ones(n, np.float32), np.ones(n, np.float32)
    t_fill = median_ms(lambda: dst.fill(0.0), repeats, warmup=True)
    t_copy = median_ms(lambda: np.copyto(dst, src), repeats, warmup=True)
    t_fresh = median_ms(lambda: np.zeros(n, np.float32).fill(1.0), repeats, warmup=True)
    gb = n * 4 / 1e9
    return dict(fill=gb / (t_fill / 1e3), copy=2 * gb / (t_copy / 1e3),
                fresh=gb / (t_fresh / 1e3), fill_ms=t_fill, fresh_ms=t_fresh)


def _frame_bytes(mesh, view, proj):
    import refraster as rf
    fb = rf.render(mesh, view=view, proj=proj, width=W, height=H)
    return sum(getattr(fb, k).nbytes for k in ("depth", "eye_depth", "normal", "prim_id",
                                              "object_id", "front_facing", "barycentric"))


def _load():
    try:
        return "load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        return "load average unknown"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 1.3M-face case")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--check-only", action="store_true",
                    help="check the ceiling kernel's digest and exit")
    a = ap.parse_args(argv)
    bad = check_digests()
    if bad:
        raise SystemExit("the ceiling kernels moved (recorded, now): "
                         + "; ".join(f"{k}: {r} != {g}" for k, (r, g) in bad.items()))
    if a.check_only:
        print("ceiling kernels: digests equal")
        return
    import trimesh
    from benchmarks.raster import _stages
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
    print(f"roofline, {W}x{H}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"{threads} Numba threads, {_load()} at start")
    sizes = [6] if a.quick else [6, 8]
    rows = []
    for sub in sizes:
        mesh = trimesh.creation.icosphere(sub)
        view, proj, clip, faces = _scene(mesh)
        nbytes = _frame_bytes(mesh, view, proj)
        bw = _bandwidth(nbytes, a.repeats)
        t_setup = median_ms(lambda: setup_ceiling(clip, faces), a.repeats, warmup=True)
        s = _stages(mesh, view, proj, a.repeats)
        fill_ceiling = bw["fill_ms"]
        bound = max(fill_ceiling, t_setup)
        rows.append((len(faces), nbytes, bw, t_setup, s, bound))
    print(f"{'faces':>9} {'MB':>6} {'fill GB/s':>9} {'copy GB/s':>9} {'fresh GB/s':>10}"
          f" {'fill ms':>7} {'setup-ceil ms':>13} {'Mtri/s':>7} | {'vertex':>6} {'setup':>6}"
          f" {'bin':>6} {'raster':>6} {'gbuf':>6} {'frame':>6} | {'bound':>6} {'frame/bound':>11}")
    for faces, nbytes, bw, t_setup, s, bound in rows:
        print(f"{faces:9d} {nbytes / 1e6:6.1f} {bw['fill']:9.2f} {bw['copy']:9.2f}"
              f" {bw['fresh']:10.2f} {bw['fill_ms']:7.2f} {t_setup:13.2f}"
              f" {faces / t_setup / 1e3:7.1f} | {s['vertex']:6.2f} {s['setup']:6.2f}"
              f" {s['binning']:6.2f} {s['raster']:6.2f} {s['gbuffer']:6.2f} {s['total']:6.2f} |"
              f" {bound:6.2f} {s['total'] / bound:11.2f}")
    print(f"{_load()} at end. fill ms: the frame's output bytes at the mapped memset's rate; "
          "setup-ceil: benchmarks.roofline.setup_ceiling (digest checked); bound: the slower "
          "of the two ceilings; frame: refraster.render, median of the repeats")


if __name__ == "__main__":
    main()
