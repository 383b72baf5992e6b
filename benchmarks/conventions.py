"""What an API convention costs: the G-buffer at 1024×768 in OpenGL's convention beside
reversed-Z (zero-to-one depth, infinite far plane, ``greater``, cleared to 0) and Vulkan's
(zero-to-one, upper-left origin, NDC y down), in the same process, frames alternating.

    python -m benchmarks.conventions [--quick] [--repeats N] [--threads T ...]

Cases: icospheres of 81,920 and (without ``--quick``) 1,310,720 faces, framed by
``camera.frame_bounds``; the reversed-Z camera has the same view, field of view and near plane.
Each thread count runs in a process of its own (``NUMBA_NUM_THREADS``, ``REFRASTER_THREADS``);
after three warm-up frames of each convention the conventions take turns frame by frame, so a
slow spell of a shared machine hits all of them. Prints one table row per case and thread count:
median ms per convention and the ratio to OpenGL's.
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
FOVY = 35.0

_WORKER = """
import json, math, time, numpy as np, refraster as rf
z = np.load({path!r}, allow_pickle=False)
mesh = rf.mesh.as_mesh((z['vertices'].astype(np.float64), z['faces'].astype(np.int64)))
view, proj = z['view'], z['proj']
near, _ = rf.camera.near_far(proj)
rev = rf.camera.perspective({fovy}, {w} / {h}, near, math.inf, reversed=True,
                            depth_range="zero_to_one")
flip = np.diag([1.0, -1.0, 1.0, 1.0])
vk = flip @ rf.camera.perspective({fovy}, {w} / {h}, near, rf.camera.near_far(proj)[1],
                                  depth_range="zero_to_one")
RS = rf.RasterState
convs = {{
    "opengl": (proj, RS()),
    "reversed_z": (rev, RS(depth_range="zero_to_one", depth_func="greater", clear_depth=0.0)),
    "vulkan": (vk, RS(depth_range="zero_to_one", origin="upper_left", ndc_y="down")),
}}
def frame(name):
    p, st = convs[name]
    return rf.render(mesh, view=view, proj=p, width={w}, height={h}, raster=st)
cover = {{}}
for name in convs:
    for _ in range(3):
        fb = frame(name)
    cover[name] = int(fb.mask.sum())
times = {{name: [] for name in convs}}
for _ in range({repeats}):
    for name in convs:
        t0 = time.perf_counter(); frame(name); times[name].append((time.perf_counter() - t0) * 1e3)
print(json.dumps(dict(median={{k: float(np.median(v)) for k, v in times.items()}}, cover=cover)))
"""


def _cases(quick):
    import trimesh
    cases = [("icosphere 81,920", trimesh.creation.icosphere(6))]
    if not quick:
        cases.append(("icosphere 1,310,720", trimesh.creation.icosphere(8)))
    return cases


def _run(path, threads, repeats):
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), REFRASTER_THREADS=str(threads))
    code = _WORKER.format(path=str(path), fovy=FOVY, w=W, h=H, repeats=repeats)
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       cwd=ROOT, timeout=3600)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-3000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the 81,920-face case only")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    import refraster as rf
    print("| case | threads | OpenGL ms | reversed-Z ms | ratio | Vulkan ms | ratio |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, mesh in _cases(args.quick):
            cam = rf.camera.frame_bounds(mesh.bounds, width=W, height=H, fovy=FOVY, margin=1.0)
            path = pathlib.Path(tmp) / "mesh.npz"
            np.savez(path, vertices=np.asarray(mesh.vertices, np.float64),
                     faces=np.asarray(mesh.faces, np.int64), view=cam.view, proj=cam.proj)
            for t in args.threads:
                r = _run(path, t, args.repeats)
                m = r["median"]
                if len(set(r["cover"].values())) != 1:
                    print(f"  (covered pixels differ: {r['cover']})")
                print(f"| {name} | {t} | {m['opengl']:.1f} | {m['reversed_z']:.1f} | "
                      f"{m['reversed_z'] / m['opengl']:.3f} | {m['vulkan']:.1f} | "
                      f"{m['vulkan'] / m['opengl']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
