"""SHA-256 digests of every buffer ``refraster.render`` returns, over scenes, sizes and options.

    python -m benchmarks.render_digests --write FILE     # record
    python -m benchmarks.render_digests --check FILE     # compare (exit 1 on any difference)

Speed work must not change a byte: record before a change, check after, and with
``NUMBA_NUM_THREADS`` = 1 and 2 (the outputs are bit-identical across thread counts). Covers the
fused path (flat, smooth and given normals, culling, depth functions, clear depth, two draw
calls, models, float64, 4 sub-pixel bits, top-left rule), the fragment-stream path (a fragment
stage) and reuse of a framebuffer (``out=``) when ``render`` has it, and of a
``Framebuffer.reusable`` (one per size, each frame after another scene's) when it exists.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import sys

import numpy as np


def _cases():
    import trimesh

    import refraster as rf
    from refraster import scenes

    cube = scenes.cube()
    ico = trimesh.creation.icosphere(4)
    torus = scenes.torus()
    crank = scenes.crank()
    tri_cube = (np.asarray(cube.vertices, np.float64), np.asarray(cube.faces, np.int64))
    tri_ico = (np.asarray(ico.vertices, np.float64), np.asarray(ico.faces, np.int64))
    tri_torus = (np.asarray(torus.vertices, np.float64), np.asarray(torus.faces, np.int64))
    tri_crank = (np.asarray(crank.vertices, np.float64), np.asarray(crank.faces, np.int64))
    view = rf.look_at([1.6, 1.2, 2.4], [0, 0, 0])
    view_far = rf.look_at([2.5, 1.8, 3.6], [0, 0, 0])
    RS = rf.RasterState
    smooth = RS(normals="smooth")
    out = []
    for w, h in ((160, 120), (512, 384), (1024, 768), (97, 61)):
        proj = rf.perspective(45, w / h, 0.5, 10)
        out += [
            (f"cube {w}x{h}", [tri_cube], dict(view=view, proj=proj, width=w, height=h)),
            (f"ico smooth {w}x{h}", [tri_ico], dict(view=view, proj=proj, width=w, height=h,
                                                   raster=smooth)),
        ]
    proj = rf.perspective(45, 4 / 3, 0.5, 10)
    kw = dict(view=view_far, proj=proj, width=512, height=384)
    m2 = np.eye(4)
    m2[:3, 3] = (0.4, 0.1, -0.3)
    out += [
        ("torus flat back-cull", [tri_torus], dict(kw, raster=RS(cull="back"))),
        ("torus smooth lequal", [tri_torus], dict(kw, raster=RS(normals="smooth",
                                                               depth_func="lequal"))),
        ("torus given normals", [tri_torus + (tri_torus[0] / np.linalg.norm(
            tri_torus[0], axis=1, keepdims=True),)], dict(kw, raster=smooth)),
        ("crank smooth", [tri_crank], dict(kw, raster=smooth)),
        ("crank greater clear0", [tri_crank], dict(kw, raster=RS(depth_func="greater",
                                                                clear_depth=0.0))),
        ("two draws models", [[tri_cube, tri_ico]], dict(kw, model=[np.eye(4), m2],
                                                        raster=smooth)),
        ("ico float64 4bit top-left", [tri_ico], dict(kw, raster=RS(
            precision="float64", subpixel_bits=4, fill_rule="top-left", cull="front"))),
        ("near clip", [tri_torus], dict(kw, view=rf.look_at([0.3, 0.2, 0.9], [0, 0, 0]))),
        ("fragment stage", [tri_ico], dict(kw, raster=smooth,
                                          fragment_stage=lambda fr: fr.depth < 0.995)),
    ]
    return out


def _digest(fb):
    d = {}
    for k, v in fb.arrays().items():
        a = np.ascontiguousarray(v)
        d[k] = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode() + a.tobytes()).hexdigest()[:16]
    return d


def digests():
    import refraster as rf
    has_out = "out" in inspect.signature(rf.render).parameters
    has_reusable = hasattr(rf.Framebuffer, "reusable")
    reusable = {}   # one per size, shared by the cases in turn: each frame follows another scene
    res = {}
    for name, args, kw in _cases():
        fb = rf.render(*args, **kw)
        res[name] = _digest(fb)
        if has_out and "fragment_stage" not in kw:   # a reused framebuffer: same bytes, twice
            out = rf.render(*args, **kw)
            for _ in range(2):
                fb2 = rf.render(*args, **kw, out=out)
                d2 = _digest(fb2)
                if d2 != res[name]:
                    res[name + " (out=)"] = d2
        if has_reusable and "fragment_stage" not in kw:   # cleared from the last frame's record
            size = (kw["width"], kw["height"])
            if size not in reusable:
                reusable[size] = rf.Framebuffer.reusable(*size)
            for _ in range(2):
                d3 = _digest(rf.render(*args, **kw, out=reusable[size]))
                if d3 != res[name]:
                    res[name + " (reusable out=)"] = d3
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write")
    g.add_argument("--check")
    a = ap.parse_args(argv)
    res = digests()
    if a.write:
        with open(a.write, "w") as fh:
            json.dump(res, fh, indent=1, sort_keys=True)
        print(f"{len(res)} renders, {sum(len(v) for v in res.values())} buffers -> {a.write}")
        return 0
    with open(a.check) as fh:
        ref = json.load(fh)
    bad = [(k, b) for k in sorted(set(ref) | set(res)) for b in
           sorted(set(ref.get(k, {})) | set(res.get(k, {})))
           if ref.get(k, {}).get(b) != res.get(k, {}).get(b)]
    for k, b in bad:
        print(f"DIFFERS: {k}: {b}")
    print(f"{len(res)} renders checked: {'all equal' if not bad else f'{len(bad)} differ'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
