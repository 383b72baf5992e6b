"""Benchmark: the full edge map at 1920×1080 beside scikit-image's Sobel on the same channels.

Run from the repository root: ``python -m benchmarks.edges [--quick]``.

The crank is rendered once (not timed). Then, each the median of N runs:

1. ``edge_map(gbuffer)``: normals (diagonal operator), depth (second-order diagonal), object ids,
   thresholds, in one fused pass over the G-buffer.
2. ``edge_map(framebuffer)``: the same plus building the G-buffer (normal encoding, near/far fit
   to the mesh, linear depth).
3. Per-filter kernels for reference (diagonal normal, C1 depth, Sobel magnitude of depth).

Anchor: ``skimage.filters.sobel`` on the four channels the edge map reads (normal x, y, z and
depth), float32, measured in the same run. Compile time = first call minus the median.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks._timing import first_ms, median_ms


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="640×360, fewer repeats")
    args = ap.parse_args(argv)
    import numba
    import skimage.filters

    import refraster
    from refraster import edges
    from refraster.camera import frame_bounds
    from refraster.scenes import crank

    width, height = (640, 360) if args.quick else (1920, 1080)
    repeats = 3 if args.quick else 9
    mesh = crank()
    cam = frame_bounds(mesh.bounds, width=width, height=height, margin=0.75)
    fb = refraster.render(mesh, **cam.kwargs)
    gb = edges.edge_gbuffer(fb)
    channels = [np.ascontiguousarray(gb.normal[..., c]) for c in range(3)] + [gb.depth]

    def anchor():
        return [skimage.filters.sobel(ch) for ch in channels]

    anchor()
    theirs = median_ms(anchor, repeats)
    cases = [
        ("edge_map(gbuffer): normals + depth + ids", lambda: edges.edge_map(gb, preset="clean")),
        ("edge_map(framebuffer): G-buffer build included", lambda: edges.edge_map(fb, preset="clean")),
        ("diagonal_normal (encoded)", lambda: edges.diagonal_normal(gb.normal, encoded=True)),
        ("c1_depth", lambda: edges.c1_depth(gb.depth)),
        ("sobel (depth, magnitude)", lambda: edges.sobel(gb.depth)),
    ]
    covered = int(fb.mask.sum())
    print(f"crank {len(mesh.faces)} faces at {width}×{height}, {covered} covered px, "
          f"numba threads {numba.get_num_threads()}, median of {repeats}")
    print("| case | refraster ms | anchor ms (skimage.filters.sobel × 4 channels) | ratio | "
          "compile ms |")
    print("|---|---|---|---|---|")
    for name, fn in cases:
        first = first_ms(fn)
        ours = median_ms(fn, repeats)
        print(f"| {name} | {ours:.1f} | {theirs:.1f} | {ours / theirs:.2f} | "
              f"{max(first - ours, 0.0):.0f} |")


if __name__ == "__main__":
    main()
