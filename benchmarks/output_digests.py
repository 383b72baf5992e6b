"""SHA-256 digests of what refraster writes, to show that speed work changed no byte.

``python -m benchmarks.output_digests OUT.json [--gallery DIR] [--golden DIR] [--quick]``

* the buffers of every registered golden scene (``refraster golden generate``): each array of
  each scene's buffer file, by name, dtype, shape and bytes (not the file, whose zip headers
  carry no time but whose manifest names the version);
* ``refraster render`` of a cube and of a torus (flat and smooth): every array of ``--buffers``
  and the PNG;
* the gallery's PNGs (``refraster gallery``), each file's bytes; the reference sections are
  rendered single-sample, display pictures may differ (``compare`` names them).

``python -m benchmarks.output_digests compare BEFORE.json AFTER.json`` prints what differs and
exits 1 if a golden or render digest differs.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path


def _run(*args, env=None):
    subprocess.run([sys.executable, "-m", "refraster.cli", "-q", *args], check=True,
                   stdin=subprocess.DEVNULL, env=env)


def _npz_digests(path):
    import numpy as np
    out = {}
    with np.load(path, allow_pickle=False) as z:
        for name in sorted(z.files):
            a = np.ascontiguousarray(z[name])
            h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
            out[name] = h.hexdigest()
    return out


def _file_digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def golden_digests(root):
    root = Path(root)
    out = {}
    for p in sorted(root.rglob("*.npz")):
        for name, d in _npz_digests(p).items():
            out[f"{p.relative_to(root)}:{name}"] = d
    return out


def render_digests(tmp):
    import numpy as np
    import trimesh
    tmp = Path(tmp)
    out = {}
    meshes = {"cube": trimesh.creation.box((1.0, 1.2, 0.8)),
              "torus": trimesh.creation.torus(1.0, 0.3)}
    for name, mesh in meshes.items():
        src = tmp / f"{name}.ply"
        mesh.export(src)
        for normals in ("flat", "smooth"):
            png, npz = tmp / f"{name}_{normals}.png", tmp / f"{name}_{normals}.npz"
            _run("render", str(src), "--out", str(png), "--buffers", str(npz), "--width", "320",
                 "--height", "240", "--normals", normals)
            out[f"{name}_{normals}.png"] = _file_digest(png)
            for k, d in _npz_digests(npz).items():
                out[f"{name}_{normals}.npz:{k}"] = d
    del np
    return out


def gallery_digests(root):
    root = Path(root)
    return {str(p.relative_to(root)): _file_digest(p) for p in sorted(root.rglob("*.png"))}


def compare(before, after):
    a, b = (json.loads(Path(p).read_text()) for p in (before, after))
    bad = 0
    for part in ("golden", "render", "gallery"):
        x, y = a.get(part, {}), b.get(part, {})
        if not x or not y:
            print(f"{part}: not in both ({len(x)} / {len(y)} digests)")
            continue
        diff = sorted(k for k in set(x) | set(y) if x.get(k) != y.get(k))
        same = len(set(x) & set(y)) - len([k for k in diff if k in x and k in y])
        print(f"{part}: {same} equal, {len(diff)} differ or missing")
        for k in diff:
            print(f"  {k}: {'differs' if k in x and k in y else 'only before' if k in x else 'only after'}")
        if part != "gallery":
            bad += len(diff)
    return 1 if bad else 0


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "compare":
        return compare(argv[1], argv[2])
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--gallery", help="an existing gallery directory to digest (else rendered)")
    ap.add_argument("--golden", help="an existing golden directory to digest (else generated)")
    ap.add_argument("--quick", action="store_true", help="render the gallery with --quick")
    ap.add_argument("--no-gallery", action="store_true")
    args = ap.parse_args(argv)
    result = {}
    with tempfile.TemporaryDirectory(prefix="refraster-digests-") as tmp:
        tmp = Path(tmp)
        golden = args.golden
        if golden is None:
            golden = tmp / "golden"
            _run("golden", "generate", "--out", str(golden))
        result["golden"] = golden_digests(golden)
        result["render"] = render_digests(tmp)
        if not args.no_gallery:
            gallery = args.gallery
            if gallery is None:
                gallery = tmp / "gallery"
                _run("gallery", "--out", str(gallery), *(["--quick"] if args.quick else []))
            result["gallery"] = gallery_digests(gallery)
    Path(args.out).write_text(json.dumps(result, indent=1, sort_keys=True))
    print(f"{args.out}: " + ", ".join(f"{k} {len(v)}" for k, v in result.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
