"""Measurements for docs/edges.md, "Presets": the paper's operator against the "clean" preset.

    python docs/scripts/edges_presets.py      (from the repository root; prints a table)

For the crank (quick and full tessellation) framed by ``frame_bounds`` at 320×240 and 640×480,
rendered with flat normals (as before) and with smooth normals split at 30° creases:
profile pixels (A > 0), how many are exactly 1 (hard) or fractional (anti-aliased), the
fraction of surface pixels with an inner strength above 0.02 (a crease of 11.5°; the
facets of flat-shaded curved surfaces), and recall / precision of A > 0
against the projected visible silhouette and border edges (the reference of
``tests/test_edges.py``, 1-px matching).
"""

import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

import refraster as rf  # noqa: E402
from refraster import edges  # noqa: E402
from refraster.mesh import as_mesh  # noqa: E402
from refraster.scenes import solid  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402
import test_edges as T  # noqa: E402


def main():
    print("| crank | size | normals | preset | profile px | hard (=1) | fractional | "
          "surface px with E_N > 0.02 | recall | precision |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for quick in (True, False):
        raw = solid("crank", quick=quick)
        for w, h in ((320, 240), (640, 480)):
            cam = rf.camera.frame_bounds(raw.bounds, width=w, height=h)
            es = edges.classify_edges(raw, view=cam.view, proj=cam.proj)
            for normals in ("flat", "smooth"):
                mesh = raw if normals == "flat" else as_mesh(raw).with_smooth_normals(30.0)
                fb = rf.render(mesh, **cam.kwargs, normals=normals)
                ref = T._projected_profile_pixels(fb, raw, es, cam)
                for preset in ("paper", "clean"):
                    em = edges.edge_map(fb, preset=preset)
                    a = em[..., 3]
                    img = a > 0
                    near = np.ones((3, 3), bool)
                    recall = (ref & ndi.binary_dilation(img, near)).sum() / ref.sum()
                    precision = (img & ndi.binary_dilation(ref, near)).sum() / img.sum()
                    inner = (em[..., 0][fb.mask] > 0.02).mean()
                    print(f"| {'quick' if quick else 'full'} | {w}×{h} | {normals} | {preset} | "
                          f"{img.sum()} | {(a == 1).sum()} | {((a > 0) & (a < 1)).sum()} | "
                          f"{inner:.3f} | {recall:.3f} | {precision:.3f} |")


if __name__ == "__main__":
    main()
