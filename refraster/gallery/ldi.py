"""Gallery section "ldi": the crank's depth layers and the parity classification of a slice.

* ``ldi/crank_layer_<k>.png``: layer k of the crank's layered depth image (``mode="peel"``),
  front-facing fragments (entries into the solid) in warm, back-facing (exits) in cool tones,
  shaded by depth; empty texels white.
* ``ldi/crank_slice.png``: the plane through the crank's axis, each point classified by the
  volumetric parity test of a volumetric depth sprite built along the z axis (inside dark red,
  outside light grey).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Item

__all__ = ["render", "layer_image", "slice_image"]

SECTION = "ldi"
FULL = dict(size=(512, 384), vds=512, slice=(768, 256))
QUICK = dict(size=(160, 120), vds=96, slice=(240, 80))
FRONT = np.array([0.90, 0.45, 0.20])
BACK = np.array([0.20, 0.45, 0.85])


def layer_image(depth, front, present):
    """One LDI layer as RGB: facing picks the hue, window depth darkens it, empty is white."""
    d = np.where(present, depth, 0.0)
    lo, hi = (d[present].min(), d[present].max()) if present.any() else (0.0, 1.0)
    shade = 1.0 - 0.6 * (d - lo) / max(hi - lo, 1e-9)
    rgb = np.where(front[..., None], FRONT, BACK) * shade[..., None]
    return np.where(present[..., None], rgb, 1.0).astype(np.float32)


def slice_image(inside):
    """Parity classification: inside dark red, outside light grey."""
    return np.where(inside[..., None], [0.55, 0.08, 0.08], [0.92, 0.92, 0.92]).astype(np.float32)


def render(out_dir, *, quick=False):
    """Write the section's PNGs under ``out_dir / "ldi"`` and return their :class:`Item` s."""
    import refraster
    from ..io import write_png
    from ..ldi import VolumetricDepthSprite, peel
    from ..scenes import solid

    p = QUICK if quick else FULL
    out = Path(out_dir) / SECTION
    mesh = solid("crank", quick=quick)
    lo, hi = mesh.bounds
    w, h = p["size"]
    cam = refraster.camera.frame_bounds(np.array([lo, hi]), width=w, height=h)
    lay = peel(mesh, max_layers=8, **cam.kwargs)
    items = []
    for k in range(len(lay)):
        name = f"crank_layer_{k}.png"
        write_png(out / name, layer_image(lay.depth[k], lay.front_facing[k], lay.prim_id[k] >= 0))
        items.append(Item(SECTION, f"{SECTION}/{name}",
                          f"Crank, depth-peeled layer {k}: front faces (entries) orange, back "
                          f"faces (exits) blue, darker = farther"))
    vds = VolumetricDepthSprite.from_mesh(mesh, p["vds"], axis="z")
    sw, sh = p["slice"]
    # the plane z = centre through the crank's axis (x), seen from +z: row 0 at the top
    xs = np.linspace(lo[0], hi[0], sw)
    ys = np.linspace(hi[1], lo[1], sh)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx, gy, np.full(gx.shape, 0.5 * (lo[2] + hi[2]))], axis=-1).reshape(-1, 3)
    inside = vds.contains(pts).reshape(sh, sw)
    write_png(out / "crank_slice.png", slice_image(inside))
    items.append(Item(SECTION, f"{SECTION}/crank_slice.png",
                      f"Crank, slice z = {0.5 * (lo[2] + hi[2]):.2f} through its axis classified "
                      f"by the volumetric parity test (VDS {vds.w}², d = {vds.d}; inside red)"))
    return items
