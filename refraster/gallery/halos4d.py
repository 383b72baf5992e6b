"""Gallery: volumetric halos for surfaces in 4D (Wang et al. 2013, Figs. 1, 5, 6, 7, 8)."""

from __future__ import annotations

import pathlib

import numpy as np

from ..io import write_png
from . import Item

SECTION = "Volumetric halos for surfaces in 4D"


def _views():
    import refraster.halos4d as h
    return {
        "fig1": h.compose(("zx", 0.5), ("yz", -1.0)),
        # Fig. 1(a): looking along (x, y, z, w) = (1, 0, 0, 1) separates the patches in w
        "fig1_oblique": h.compose(("xw", np.pi / 4), ("zx", 0.5), ("yz", -1.0)),
        "knot": h.compose(("zw", 0.9), ("yw", 0.35), ("xy", -0.3), ("yz", -0.35)),
        "fermat": h.compose(h.hanson_view(0.6), ("zx", 0.35), ("yz", -0.5)),
        "product": h.compose(("zw", 0.5), ("zx", 0.4), ("yz", -0.5)),
    }


def render(out_dir: pathlib.Path, *, quick: bool = False) -> list[Item]:
    """Render the halo figures into ``out_dir``; ``quick`` uses small images and meshes."""
    import refraster.halos4d as h

    out_dir = pathlib.Path(out_dir)
    size = 128 if quick else 512
    slices = 48 if quick else 256
    res = 0.4 if quick else 1.0
    v = _views()
    items = []

    def shot(name, surface, caption, **kw):
        kw.setdefault("width", size)
        kw.setdefault("height", size)
        kw.setdefault("slices", slices)
        r = h.render_halos(surface, **kw)
        fn = f"halos4d_{name}.png"
        write_png(out_dir / fn, np.clip(r.image, 0.0, 1.0))
        items.append(Item(SECTION, fn, caption))
        return r

    fig1 = h.figure1_scene(int(24 * res) + 4)
    common = dict(rho=0.1, delta_d=1.0, delta_t=0.3, surface_width=0.3)
    shot("fig1_oblique", fig1, "Fig. 1(a): the five strips at w = 0.1 … 0.5 seen along "
         "(1, 0, 0, 1): separated in 4D.", rotation=v["fig1_oblique"], halos=False, **common)
    shot("fig1_nohalo", fig1, "Fig. 1(b): projected along w the strips intersect the white "
         "patch; plain 4D depth test, no halos.", rotation=v["fig1"], halos=False, **common)
    shot("fig1_halo", fig1, "Fig. 1(c): depth-dependent volumetric halos — the gap in the "
         "white patch widens with the 4D depth difference (Eq. 3).", rotation=v["fig1"], **common)
    knot = h.spun_trefoil(int(200 * res), int(50 * res))
    shot("spun_trefoil", knot, f"Fig. 5(d): the spun trefoil ({knot.n_faces} triangles) with "
         "volumetric halos; the gaps mark where one sheet passes behind another in 4D.",
         rotation=v["knot"], rho=0.15, delta_d=0.3)
    fermat = h.quadratic_fermat(int(32 * res) + 4, int(32 * res) + 4)
    shot("fermat", fermat, "Fig. 6(a): quadratic Fermat surface z1² + z2² = 1 (4 patches), "
         "Hanson's view; halos open at the self-intersections.", rotation=v["fermat"],
         delta_d=0.4)
    cy = h.calabi_yau_quartic(int(16 * res) + 4, int(16 * res) + 4)
    shot("calabi_yau", cy, "Fig. 6(b): Calabi–Yau quartic cross-section z1⁴ + z2⁴ = 1 "
         "(16 patches).", rotation=v["fermat"], delta_d=0.3)
    prod = h.product_polynomial(int(24 * res) + 4, int(48 * res) + 4)
    shot("product_stereo", prod, "Fig. 7: product polynomial z1² z2² = 1, cross-eyed stereo "
         "pair.", rotation=v["product"], stereo=True, width=size, height=size)
    twist = h.twist_spun_trefoil(int(200 * res), int(50 * res), k=2)
    shot("twist_spun_stereo", twist, "Fig. 8: 2-twist-spun trefoil, cross-eyed stereo pair.",
         rotation=v["knot"], rho=0.15, delta_d=0.3, stereo=True)
    return items
