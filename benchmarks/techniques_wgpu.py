"""Benchmark: refraster.wgpu on Mesa's lavapipe beside refraster and refraster.gl on llvmpipe,
in one run, 2 threads each.

Run from the repository root: ``python -m benchmarks.techniques_wgpu [--quick]
[--techniques-only | --base-only]``.

The two base cases of :mod:`benchmarks.techniques_gl` (the same scene packages):

1. The G-buffer of the crank (about 100k faces) at 1024×768: refraster's :func:`refraster.render`
   (every channel) beside refraster.gl's one-pass MRT G-buffer and refraster.wgpu's three
   passes within WebGPU's default 32 bytes per sample (ids and depths; normal and
   barycentrics; colour), every target read back.
2. An 8-layer depth peel of four nested spheres (81,920 faces) at 1024×1024: refraster's
   one-pass :func:`refraster.ldi.peel` beside the two backends' classic multi-pass peels (each
   layer read back).
3. The four techniques at their papers' sizes (issue 45, the wgpu column): the packages of
   :func:`benchmarks.techniques_gl._technique_packages` (clip surface with its cap, edge map,
   cutaway, 4D halos); a technique refraster.wgpu does not draw yet is listed with "—".
   ``--techniques-only`` runs these alone, ``--base-only`` the first two.

refraster runs with 2 Numba threads in this process; each backend runs in a process of its own
with ``LP_NUM_THREADS=2`` (lavapipe and llvmpipe read the same variable) and
``GLIBC_TUNABLES=glibc.malloc.trim_threshold=4294967296`` (/work/shared/LLVMPIPE.md). Timed for
the backends: ``Backend.draw`` (the passes, read-back and background fill), the meshes already
uploaded; the upload (``Backend.load``) is reported apart.
"""

from __future__ import annotations

from benchmarks.techniques_gl import run


def main(argv=None):
    threads, (gl_renderer, wgpu_renderer), rows = run(argv, __doc__, ("gl", "wgpu"), "issue 45")
    print(f"refraster: {threads} Numba threads; refraster.gl: {gl_renderer}; "
          f"refraster.wgpu: {wgpu_renderer}; LP_NUM_THREADS=2, tuned malloc")
    print("| case | refraster ms | refraster.gl (llvmpipe) ms | refraster.wgpu (lavapipe) ms | "
          "wgpu / refraster | gl first draw ms | wgpu first draw ms | gl load ms | wgpu load ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, median, first, g, w in rows:
        if "skipped" in w:
            print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | — | — | "
                  f"{g['first_ms']:.0f} | — | {g['load_ms']:.0f} | — |")
            continue
        print(f"| {name} | {median:.0f} | {g['median_ms']:.0f} | {w['median_ms']:.0f} | "
              f"{w['median_ms'] / median:.2g} | {g['first_ms']:.0f} | {w['first_ms']:.0f} | "
              f"{g['load_ms']:.0f} | {w['load_ms']:.0f} |")
    for name, _, _, g, w in rows:
        if "skipped" in w:
            print(f"- {name}: refraster.wgpu skipped it ({w['skipped']})")
        elif g["layers"] is not None:
            print(f"- {name}: refraster.gl peeled {g['layers']} layers, refraster.wgpu "
                  f"{w['layers']}")


if __name__ == "__main__":
    main()
