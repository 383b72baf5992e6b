"""Picture for docs/clipsurface.md: where the planar cut of the crank differs from manifold3d.

    python docs/scripts/clipsurface_rim.py   (from the repository root; writes
    docs/img/clipsurface_rim_mismatch.png)

Blue: covered pixels whose depth differs by more than 1e-5 between ``render_clipped`` (flat
offset map, tessellated cap, parity test) and manifold3d's ``trim_by_plane`` rendered by the
foundation; the same set-up as ``tests/test_clipsurface_render.py``.
"""

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

import refraster  # noqa: E402
import test_clipsurface_render as T  # noqa: E402
from refraster.io import write_png  # noqa: E402


def main():
    make, normal, tilt = T.CASES["crank"]
    mesh = make()
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    c = np.array([1.2, 0.0, 0.0])
    u, v = T.frame(n, c)
    cs = T.ClipSurface(c, 2 * u, 2 * v, (1, 1, 0.2), T.om.constant(4, 0.5))
    trimmed = T.from_manifold(T.to_manifold(mesh).trim_by_plane(list(n), float(n @ c - 0.1)))
    on_plane = trimmed.vertices[np.abs(trimmed.vertices @ n - (n @ c - 0.1)) < 1e-5]
    cam = T.frame_bounds(np.stack([on_plane.min(0), on_plane.max(0)]), width=480, height=360,
                         direction=-n + tilt)
    fb = T.render_clipped(mesh, cs, **cam.kwargs, vds=T.parity_tests(mesh))
    ref = refraster.render(trimmed, **cam.kwargs)
    covered = fb.mask | ref.mask
    bad = covered & (np.abs(fb.depth.astype(np.float64) - ref.depth) > 1e-5)
    img = 0.35 + 0.65 * fb.color
    img[bad] = (0.0, 0.15, 1.0)
    out = ROOT / "docs" / "img" / "clipsurface_rim_mismatch.png"
    write_png(out, img)
    print(f"{bad.sum()} of {covered.sum()} covered pixels differ "
          f"({100 * (1 - bad.sum() / covered.sum()):.2f} % agree) -> {out}")


if __name__ == "__main__":
    main()
