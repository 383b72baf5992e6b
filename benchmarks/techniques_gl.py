"""Benchmark: refraster.gl on Mesa llvmpipe beside refraster, in one run, 2 threads each.

Run from the repository root: ``python -m benchmarks.techniques_gl [--quick]``.

1. The G-buffer of the crank (about 100k faces) at 1024×768: refraster's
   :func:`refraster.render` (every channel: depth, eye depth, normal, ids, facing,
   barycentrics, colour) beside refraster.gl's one-pass MRT G-buffer (``shaders/gbuffer.*``,
   six targets read back).
2. An 8-layer depth peel of four nested spheres (81,920 faces) at 1024×1024: refraster's
   one-pass :func:`refraster.ldi.peel` beside refraster.gl's classic multi-pass peel
   (``shaders/peel.frag``, 8 passes against a 32-bit float depth buffer, each layer read back).

3. The four techniques at their papers' sizes (issue 26, item 7): the crank clipped by a 2.5D
   clip surface with its cap at 1024×768 (Trapp & Döllner Sec. 6.2), the paper's edge map of
   the crank at 1024×768 (Nienhaus & Döllner), the nested shells' cutaway with jump flooding
   at 512² (Burns & Finkelstein), the spun trefoil's 4D halos, 256 slices at 512² (Wang et al.
   Table 1). ``--techniques-only`` runs these alone.

All scenes go through scene packages (:func:`refraster.golden.io.package.export_package`), as a
GPU team's would. refraster runs with 2 Numba threads in this process; refraster.gl runs in a
process of its own with ``LP_NUM_THREADS=2`` and ``GLIBC_TUNABLES=glibc.malloc.trim_threshold=
4294967296`` (malloc trimming costs llvmpipe about 40 % on large frames: /work/shared/LLVMPIPE.md).
Timed for refraster.gl: ``Backend.draw`` (draw calls, ``glFinish``, read-back and the
background fill), meshes already uploaded; the upload (``Backend.load``) is reported apart.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._timing import first_ms, interleaved_medians

ROOT = Path(__file__).resolve().parents[1]
TUNED_MALLOC = "glibc.malloc.trim_threshold=4294967296"


def _packages(root, quick):
    """Write the two scene packages; return [(name, refraster callable, package dir)]."""
    import refraster
    from refraster.golden.io.package import export_package
    from refraster.golden.scenes import (DEFAULT_RASTER, Draw, GoldenScene, _framed,
                                         prepare_draws, render_draws)
    from refraster.ldi import peel
    from refraster.scenes import crank, icosphere

    w, h = (256, 192) if quick else (1024, 768)
    draws = prepare_draws([Draw("crank", crank())])
    cam = _framed([d.mesh for d in draws], w, h, (0.8, 1.0, 1.5))
    state = dict(DEFAULT_RASTER)
    g = GoldenScene(technique="render", camera=cam, draws=draws, buffers={})
    export_package(root / "gbuffer", "gbuffer", g, state)
    faces_g = len(draws[0].mesh.faces)

    size, sub = (256, 3) if quick else (1024, 5)
    shells = prepare_draws([Draw(f"shell{k}", icosphere(subdivisions=sub, radius=r))
                            for k, r in enumerate((1.0, 0.8, 0.6, 0.4))])
    pcam = refraster.Camera(refraster.look_at((0.4, 0.3, 2.6), (0, 0, 0)),
                            refraster.perspective(50, 1.0, 0.5, 10.0), size, size)
    params = dict(mode="peel", max_layers=8)
    p = GoldenScene(technique="ldi", camera=pcam, draws=shells, buffers={}, parameters=params)
    export_package(root / "peel", "peel", p, state)
    faces_p = sum(len(d.mesh.faces) for d in shells)

    def ours_gbuffer():
        return render_draws(draws, cam, state)

    def ours_peel():
        return peel([d.mesh for d in shells], **pcam.kwargs, model=[d.model for d in shells],
                    max_layers=8)

    return [(f"G-buffer, crank {faces_g} faces, {w}×{h}", ours_gbuffer, root / "gbuffer"),
            (f"peel 8 layers, {faces_p} faces, {size}²", ours_peel, root / "peel")]


def _technique_packages(root, quick):
    """The four techniques at their papers' sizes (issue 26, item 7): the scene packages are
    built the way the golden scenes' builders build theirs (the same parameter names, the same
    export helpers of :mod:`refraster.golden.technique_scenes`), only larger. Returns
    [(name, refraster callable, package dir)]; each callable is the technique's public entry
    point with the package's parameters (what the golden generator times)."""
    from refraster.clipsurface import offsetmaps as om
    from refraster.clipsurface import ClipSurface, render_clipped
    from refraster.cutaway import render_cutaway
    from refraster.edges import edge_map
    from refraster.golden.io.package import export_package
    from refraster.golden.scenes import (DEFAULT_RASTER, Draw, GoldenScene, _framed,
                                         prepare_draws, render_draws)
    from refraster.golden.technique_scenes import (clip_caps, clip_export, cutaway_options,
                                                   halo_options)
    import refraster.halos4d as h4
    from refraster.scenes import crank, icosphere, solid

    state = dict(DEFAULT_RASTER)
    cases = []

    # 1. Trapp & Döllner Sec. 6.2: the crank at 1024×768, one clip surface (Perlin offset map)
    # and its cap (benchmarks/clipsurface.py's surface, the sprite at 512 as the goldens')
    w, h = (256, 192) if quick else (1024, 768)
    raw = crank()
    draws = prepare_draws([Draw("crank", raw)])
    mesh = draws[0].mesh
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    n = np.array([0.0, 0.25, -1.0])
    n /= np.linalg.norm(n)
    u = np.cross(n, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    extent = float(np.linalg.norm(hi - lo))
    offset_map = om.perlin_noise((256, 256), seed=1)
    surface = dict(origin=((lo + hi) / 2).tolist(), u=(extent * u).tolist(),
                   v=(extent * v).tolist(), scale=[1.0, 1.0, 0.6], wrap="repeat", enabled=True)
    caps = dict(caps=True, cap_style="diffuse", cap_mode="mesh", cap_color=[0.8, 0.3, 0.25],
                subdivision=1, vds_resolution=256 if quick else 512, space="world")
    clip = ClipSurface(surface["origin"], surface["u"], surface["v"], surface["scale"],
                       offset_map, wrap=surface["wrap"])
    camera = _framed([mesh], w, h, (0.3, 0.7, 1.0))
    surfaces = [{**surface, "offset_map": "offset_map"}]
    bparams, bmaps = clip_export(draws, [clip], caps, surfaces)
    g = GoldenScene(technique="clipsurface", camera=camera, draws=draws, buffers={},
                    parameters={"surfaces": surfaces, **caps, **bparams},
                    maps={"offset_map": offset_map, **bmaps}, geometry=False)
    export_package(root / "clip", "clip", g, state)
    # refraster's side: the sprite is built once beforehand (the paper's preprocessing); the
    # crank as built (float64): rounded to float32 some of its distinct vertices coincide and
    # the caps' watertightness check refuses it (the package's float32 crank, on the gl side,
    # is not checked)
    from refraster import RasterState
    from refraster.ldi import VolumetricDepthSprite
    sprite = VolumetricDepthSprite.from_mesh(raw, resolution=caps["vds_resolution"])

    def ours_clip(meshes=[raw], clip=clip, camera=camera, caps=caps, sprite=sprite):
        fb = render_clipped(meshes, clip, **camera.kwargs, vds=[sprite], caps=clip_caps(caps),
                            space=caps["space"],
                        raster=RasterState(cull=state["cull"], precision=state["precision"]))
        return fb.color
    cases.append((f"clip + cap, crank {len(mesh.faces)} faces, {w}×{h}", ours_clip,
                  root / "clip"))

    # 2. Nienhaus & Döllner: the paper's edge map (diagonal operators) of the crank, 1024×768
    params = dict(bounds=[lo.tolist(), hi.tolist()], preset="paper", normal_filter="diagonal",
                  depth_filter="diagonal", ids=False, inner_threshold=0.0,
                  profile_threshold=0.0, width=1, k_n=1.0, k_z=1.0)
    ecam = _framed([mesh], w, h, (1.2, 0.9, 1.6))
    g = GoldenScene(technique="edges", camera=ecam, draws=draws, buffers={},
                    parameters={**params, "gbuffer_format": "rgba8", "output_format": "rgba8"})
    export_package(root / "edges", "edges", g, state)

    def ours_edges(params=params, ecam=ecam):
        fb = render_draws(draws, ecam, state)
        return edge_map(fb, **{**params, "bounds": np.array(params["bounds"])})
    cases.append((f"edge map (G-buffer + diagonal operators), crank, {w}×{h}", ours_edges,
                  root / "edges"))

    # 3. Burns & Finkelstein: the nested shells' cutaway at 512², jump flooding (jfa+1)
    size = 128 if quick else 512
    cdraws = prepare_draws([Draw("outer_shells", solid("nested_shells", quick=False)),
                            Draw("interest", icosphere(subdivisions=3, radius=0.3))])
    ccam = _framed([d.mesh for d in cdraws], size, size, (1.2, 0.9, 1.6))
    copts = dict(angle=1.0, variant="jfa+1", perspective_compensation=True,
                 edge_compression=0.1, dilation=True, outlines=True, ghost="lines",
                 ghost_distance=0.5, ghost_fade=True, crease_angle=30.0)
    g = GoldenScene(technique="cutaway", camera=ccam, draws=cdraws, buffers={},
                    parameters={**copts, "interest": ["interest"],
                                "secondary": ["outer_shells"]}, geometry=False)
    export_package(root / "cutaway", "cutaway", g, state)
    faces_c = sum(len(d.mesh.faces) for d in cdraws)

    def ours_cutaway(ccam=ccam, copts=copts):
        return render_cutaway([cdraws[1].mesh], [cdraws[0].mesh], **ccam.kwargs,
                              **cutaway_options(copts))
    cases.append((f"cutaway (jump flooding jfa+1), nested shells {faces_c} faces, {size}²",
                  ours_cutaway, root / "cutaway"))

    # 4. Wang et al. Table 1: the spun trefoil, 256 slices at 512² (benchmarks/halos4d.py)
    hs, slices = (128, 64) if quick else (512, 256)
    trefoil = h4.spun_trefoil()
    rot = h4.compose(("zw", 0.6), ("zx", 0.3), ("yz", 0.4))
    hopts = dict(projection="orthographic", slices=slices, delta_t=0.3, surface_width=0.3,
                 opacity=0.9, halos=True, margin=0.05, width=hs, height=hs,
                 background=[0.0, 0.0, 0.0])

    def ours_halos(trefoil=trefoil, rot=rot, hopts=hopts):
        return h4.render_halos(trefoil, **halo_options({**hopts, "rotation": rot}))
    out = ours_halos()
    from refraster.camera import Camera, orthographic
    hp = dict(hopts, rotation=rot.tolist(), delta_d=float(out.stats["delta_d"]),
              antialias=float(out.stats["antialias"]), halo_opacity=0.0,
              screen_bounds=np.asarray(out.bounds).tolist())
    rho = out.stats.get("rho")
    hp["rho"] = float(rho) if isinstance(rho, float) else None
    maps = {"surface_vertices4d": trefoil.vertices, "surface_faces": trefoil.faces,
            "surface_tangents": trefoil.tangents.reshape(len(trefoil.vertices), 8),
            "surface_colors": trefoil.colors}
    g = GoldenScene(technique="halos4d", camera=Camera(np.eye(4), orthographic(-1, 1, -1, 1,
                                                                               -1, 1), hs, hs),
                    draws=[], buffers={}, parameters=hp, maps=maps, geometry=False)
    export_package(root / "halos", "halos", g, state)
    cases.append((f"4D halos, spun trefoil {trefoil.n_faces} triangles, {slices} slices, "
                  f"{hs}²", ours_halos, root / "halos"))
    return cases


def _gl_child(packages, repeats):
    """Runs in the child process: time Backend.draw on each package, print JSON."""
    import time

    from refraster.gl.driver import Backend
    out = []
    with Backend() as gl:
        for pkg in packages:
            t0 = time.perf_counter()
            loaded = gl.load(pkg)
            load_ms = (time.perf_counter() - t0) * 1e3
            first = first_ms(lambda: gl.draw(loaded))
            times = [first_ms(lambda: gl.draw(loaded)) for _ in range(repeats)]
            layers = gl.draw(loaded)
            k = layers["layer_depth"].shape[-1] if "layer_depth" in layers else None
            gl.unload(loaded)
            out.append(dict(load_ms=load_ms, first_ms=first, median_ms=float(np.median(times)),
                            layers=k))
        out.append({"renderer": gl.renderer})
    print(json.dumps(out))


def _time_gl(packages, repeats, threads):
    env = {**os.environ, "LP_NUM_THREADS": str(threads), "GLIBC_TUNABLES": TUNED_MALLOC,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    code = ("import sys, json; from benchmarks.techniques_gl import _gl_child; "
            "_gl_child(json.loads(sys.argv[1]), int(sys.argv[2]))")
    proc = subprocess.run([sys.executable, "-c", code, json.dumps([str(p) for p in packages]),
                           str(repeats)], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=1800)
    if proc.returncode != 0:
        raise SystemExit(f"refraster.gl child failed: {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--techniques-only", action="store_true",
                    help="only the four techniques at their papers' sizes (issue 26 item 7)")
    ap.add_argument("--base-only", action="store_true",
                    help="only the G-buffer and the peel")
    args = ap.parse_args(argv)
    import numba
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    with tempfile.TemporaryDirectory() as tmp:
        cases = [] if args.techniques_only else _packages(Path(tmp), args.quick)
        if not args.base_only:
            cases += _technique_packages(Path(tmp), args.quick)
        gl = _time_gl([c[2] for c in cases], args.repeats, threads=2)
        renderer = gl.pop()["renderer"]
        rows = []
        for (name, ours, _), g in zip(cases, gl):
            first = first_ms(ours)
            (median,) = interleaved_medians([ours], args.repeats)
            rows.append((name, median, first, g))
    print(f"refraster: {numba.get_num_threads()} Numba threads; refraster.gl: {renderer}, "
          "LP_NUM_THREADS=2, tuned malloc")
    print("| case | refraster ms | refraster.gl (llvmpipe) ms | ratio (refraster / gl) | "
          "refraster first call ms | gl first draw ms | gl load+upload ms |")
    print("|---|---|---|---|---|---|---|")
    for name, median, first, g in rows:
        print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | {median / g['median_ms']:.2g} "
              f"| {first:.0f} | {g['first_ms']:.0f} | {g['load_ms']:.0f} |")
    for name, _, _, g in rows:
        if g["layers"] is not None:
            print(f"- {name}: refraster.gl peeled {g['layers']} layers")


if __name__ == "__main__":
    main()
