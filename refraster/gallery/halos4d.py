"""Gallery: volumetric halos for surfaces in 4D (Wang et al. 2013): every figure, each beside
its halos-off twin and a difference picture, with the measured share of covered pixels that the
halos change (issue 21).

Each picture ``halos4d_<name>.png`` is a triptych ``halos off | halos on | difference`` (side by
side; stacked for the stereo pairs of Figs. 7 and 8). The difference panel is white where a
pixel changes by more than 5/255 in some channel, dark grey where the surface covers it.
"""

from __future__ import annotations

import pathlib
from typing import NamedTuple

import numpy as np

from ..io import write_png
from . import Item

SECTION = "Volumetric halos for surfaces in 4D"

#: a pixel "changes" when some channel differs by more than this
CHANGE_THRESHOLD = 5.0 / 255.0
#: a pixel is "covered" when the accumulated opacity of either picture exceeds this
COVER_THRESHOLD = 0.02
GAP = 8
#: Fig. 5: ρ of the spun trefoil's pictures (the default, 2 % of the diagonal, is 0.37)
KNOT_RHO = 0.6
#: Fig. 5(d): the carved gaps drawn in this colour with the halo-boundary option (Fig. 8's),
#: b = GAP_WIDTH: an opaque gap otherwise shows the other sheet's continuation behind it in
#: nearly the same colour (docs/halos4d.md, "Why Fig. 5(d) needs its gaps drawn")
GAP_DARK = (0.02, 0.02, 0.02)
GAP_WIDTH = 0.95
#: Fig. 5(d) as a knot diagram (`fig5d_diagram`): the band φ ∈ [−b, b] of the spun sphere
#: around one meridian, coloured by 4D depth, seen along the spin direction; the band is seen
#: edge-on, so the headlight's ambient part sets its brightness, and a narrow anti-aliasing
#: ramp keeps its edges sharp (docs/halos4d.md, "Fig. 5(d) as a knot diagram")
DIAGRAM_BAND = 0.15
DIAGRAM_AMBIENT = 0.7
DIAGRAM_ANTIALIAS = 0.05


#: Why the section has no multisampled picture (refraster.gallery.multisample).
NO_MSAA = ("No multisampled picture: the slicing composite refuses raster.samples > 1 (it "
           "blends each slice per pixel and has no per-sample meaning; halos.antialias is its "
           "anti-aliasing, docs/halos4d.md).")


def views():
    """The 4D rotations of the gallery (applied first, then orthographic projection)."""
    import refraster.halos4d as h
    return {
        "fig1": h.compose(("zx", 0.35), ("yz", -0.6)),
        # Fig. 1(a): looking along (x, y, z, w) = (1, 0, 0, 1) separates the patches in w
        "fig1_oblique": h.compose(("xw", np.pi / 4), ("zx", 0.35), ("yz", -0.6)),
        "fig3": h.compose(("zx", 0.6), ("yz", -0.9)),
        # the spun knot seen along z (z ↔ w): the surface of revolution of the trefoil's
        # diagram in the xy plane, its crossings separated in 4D depth by z. Seen from above
        # (yz = +0.75) both kinds of crossing circle show: the equator (outer crossing) and the
        # ring around the inner disc (the two crossings next to the spinning plane)
        "knot": h.compose(("zw", np.pi / 2), ("yz", 0.75), ("zx", 0.2)),
        "knot_open": h.compose(("zw", np.pi / 2), ("zx", 0.3), ("yz", 0.25)),
        # along the spin direction at the meridian φ = 0: the knotted arc's xy diagram, the
        # knot's z as the 4D depth
        "knot_band": h.rotation("zw", np.pi / 2),
        "twist": h.compose(("zw", np.pi / 2), ("yz", -0.5), ("zx", 0.3)),
        "fermat": h.compose(h.hanson_view(0.6), ("zx", 0.35), ("yz", -0.5)),
        "product": h.compose(("zw", 0.5), ("zx", 0.4), ("yz", -0.5)),
    }


def figure3_scene(n=12):
    """Two patches apart in 4D whose projections cross (Figs. 2 and 3): a square at w = 0 and
    a tilted one at w = 0.4 through it."""
    import refraster.halos4d as h
    a = h.uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1), (-1, 1),
                     n, n, color=(0.95, 0.85, 0.5))
    b = h.uv_surface(lambda u, v: np.stack([0.5 * u, v, 0.8 * u, 0 * u + 0.4], axis=-1),
                     (-1, 1), (-0.8, 0.8), n, n, color=(0.35, 0.6, 1.0))
    return h.merge([a, b], "Fig. 3 patches")


def change_share(on, off):
    """(changed, covered): pixels covered in either picture, and those the halos change."""
    covered = (on.alpha > COVER_THRESHOLD) | (off.alpha > COVER_THRESHOLD)
    changed = (np.abs(on.image - off.image).max(axis=2) > CHANGE_THRESHOLD) & covered
    return int(changed.sum()), int(covered.sum())


def triptych(on, off, stacked=False):
    """``off | on | difference`` as one float image."""
    a, b = np.clip(off.image, 0, 1), np.clip(on.image, 0, 1)
    covered = (on.alpha > COVER_THRESHOLD) | (off.alpha > COVER_THRESHOLD)
    changed = (np.abs(on.image - off.image).max(axis=2) > CHANGE_THRESHOLD) & covered
    diff = np.where(changed, 1.0, np.where(covered, 0.22, 0.0))
    diff = np.repeat(diff[..., None], 3, axis=2).astype(np.float32)
    axis = 0 if stacked else 1
    shape = list(a.shape)
    shape[axis] = GAP
    pad = np.full(shape, 0.5, np.float32)
    return np.concatenate([a, pad, b, pad, diff], axis=axis)


class Figure(NamedTuple):
    """One gallery figure: its name, surface, panel caption, the options of its halos-on
    picture (its halos-off twin: ``halos.replace(enabled=False)``, the rest the same) and
    whether its triptych is stacked (the stereo pairs)."""

    name: str
    surface: object
    caption: str
    view: object
    halos: object
    style: object
    stacked: bool


def figures(quick=False):
    """One :class:`Figure` per figure; the options not set are ``View4D``'s, ``Halos``' and
    ``HaloStyle``'s defaults."""
    import refraster.halos4d as h
    from refraster.halos4d import HaloStyle, Halos, View4D
    res = 0.4 if quick else 1.0
    v = views()
    fig1 = h.figure1_scene(int(24 * res) + 4)
    spun = h.spun_trefoil(int(240 * res), int(64 * res))
    spun_open = h.spun_trefoil(int(240 * res), int(48 * res), cut_open=True)
    spun_band = h.colored_by_depth(h.spun_trefoil(int(240 * res), 8, band=DIAGRAM_BAND),
                                   v["knot_band"])
    twist = h.twist_spun_trefoil(int(320 * res), int(64 * res), k=2)
    # the paper's curvature-adaptive u and v lists (Sec. 4.1)
    fermat = h.quadratic_fermat(int(40 * res) + 4, int(40 * res) + 4, adaptive=True)
    cy = h.calabi_yau_quartic(int(18 * res) + 4, int(18 * res) + 4, adaptive=True)
    prod = h.product_polynomial(int(24 * res) + 4, int(48 * res) + 4)
    green = (0.1, 0.95, 0.2)
    plain, knot = Halos(), Halos(rho=KNOT_RHO)
    gaps = dict(boundary_color=GAP_DARK, boundary_width=GAP_WIDTH)
    return [
        Figure("fig1a", fig1, "Fig. 1(a): the five strips at w = 0.1 … 0.5 seen along "
               "(1, 0, 0, 1), where they are apart", View4D(rotation=v["fig1_oblique"]), plain,
               HaloStyle(), False),
        Figure("fig1bc", fig1, "Fig. 1(b) projected along w, plain 4D depth test | Fig. 1(c) "
               "with depth-dependent halos: the gap widens from red (Δw = 0.1) to blue (0.5)",
               View4D(rotation=v["fig1"]), plain, HaloStyle(), False),
        Figure("fig3e", figure3_scene(int(12 * res) + 4), "Fig. 3(e): two patches apart in 4D, "
               "the halo volumes drawn grey (halo_opacity = 0.35)", View4D(rotation=v["fig3"]),
               plain, HaloStyle(halo_opacity=0.35), False),
        Figure("fig5ad", spun, f"Fig. 5(a) the spun trefoil ({spun.n_faces} triangles), "
               "traditional rendering | Fig. 5(d) with volumetric halos, opaque, the defaults: "
               "where the sheet farther in 4D passes behind the nearer one it is cut back, at "
               "the ring around the inner disc and along the equator (the two crossings of the "
               "knot's diagram that the view from above does not hide), as in a knot diagram",
               View4D(rotation=v["knot"]), plain, HaloStyle(), False),
        Figure("fig5d_dark", spun, "Fig. 5(d) with the carved gaps drawn dark (not in the "
               "paper: the halo-boundary option of Fig. 8, b = 0.95, in near-black; ρ = 0.6): "
               "the sheet farther in 4D breaks where it crosses the nearer one",
               View4D(rotation=v["knot"]), knot, HaloStyle(**gaps), False),
        Figure("fig5d_open", spun_open, "Fig. 5(d), the sphere cut open (φ ∈ [0, π], not in "
               "the paper; ρ = 0.6): inside, the halos cut the sheet that is farther in 4D where "
               "two sheets cross, and the cut edge is the knotted arc",
               View4D(rotation=v["knot_open"]), Halos(rho=0.6), HaloStyle(), False),
        Figure("fig5d_translucent", spun, "Fig. 5(d) translucent (opacity 0.45, the option of "
               "Fig. 5(b) and Fig. 8, not the default 0.9), ρ = 0.6, the carved gaps drawn "
               "dark: through the nearer sheets all three crossing circles of the knot's "
               "diagram show their under-sheet cut, the ring below the inner disc too",
               View4D(rotation=v["knot"]), knot, HaloStyle(opacity=0.45, **gaps), False),
        Figure("fig5d_diagram", spun_band, "Fig. 5(d) as a knot diagram (not in the paper: the "
               f"band |φ| ≤ {DIAGRAM_BAND} of the spun sphere, coloured by 4D depth from red, "
               "near, to blue, far; ambient 0.7, anti-aliasing a = 0.05; ρ = 0.6): seen along "
               "the spin direction the band is the knotted arc, and the halos break the strand "
               "farther in 4D at each of the diagram's three crossings",
               View4D(rotation=v["knot_band"]), Halos(rho=KNOT_RHO, antialias=DIAGRAM_ANTIALIAS),
               HaloStyle(ambient=DIAGRAM_AMBIENT), False),
        Figure("fig5b", spun, "Fig. 5(b): the spun trefoil translucent (opacity 0.45), halos "
               "off | on (ρ = 0.6)", View4D(rotation=v["knot"]), knot,
               HaloStyle(opacity=0.45), False),
        Figure("fig6a", fermat, "Fig. 6(a): quadratic Fermat surface z1² + z2² = 1, Hanson's "
               "view, curvature-adaptive u, v lists", View4D(rotation=v["fermat"]), plain,
               HaloStyle(), False),
        Figure("fig6b", cy, "Fig. 6(b): Calabi–Yau quartic cross-section z1⁴ + z2⁴ = 1 (16 "
               "patches), curvature-adaptive u, v lists", View4D(rotation=v["fermat"]), plain,
               HaloStyle(), False),
        Figure("fig7", prod, "Fig. 7: product polynomial z1² z2² = 1, cross-eyed stereo (top: "
               "halos off, middle: on)", View4D(rotation=v["product"], stereo=h.STEREO_ANGLE),
               plain, HaloStyle(), True),
        Figure("fig8", twist, "Fig. 8: 2-twist-spun trefoil, cross-eyed stereo, translucent "
               "(opacity 0.6) with the halo boundaries in green (top: halos off, middle: on)",
               View4D(rotation=v["twist"], stereo=h.STEREO_ANGLE), plain,
               HaloStyle(opacity=0.6, boundary_color=green, boundary_width=0.3), True),
    ]


#: ``refraster gallery`` renders this section as two work items when the kernel cache is warm
#: (one per worker, :data:`refraster.gallery.PARTS`): part 0 the figures up to and including
#: this one, part 1 the rest — each about half of the section's time (issue 27)
SPLIT_AFTER = "fig5d_diagram"


def render(out_dir: pathlib.Path, *, quick: bool = False, measurements=None,
           only=None, part=None) -> list[Item]:
    """Render the halo figures into ``out_dir``; ``quick`` uses small images and meshes.
    ``measurements``, a dict, receives ``name -> (changed, covered, stats)``; ``only``, a
    collection of names, renders just those figures; ``part`` 0 or 1 just those up to and
    including :data:`SPLIT_AFTER`, or the others."""
    out_dir = pathlib.Path(out_dir)
    from refraster.halos4d import render_halos_pair
    size = 128 if quick else 512
    slices = 48 if quick else 256
    items = []
    figs = figures(quick)
    first = figs[0][0]
    if part is not None:
        if part not in (0, 1):
            raise ValueError(f"part must be 0 or 1, got {part!r}")
        k = [f[0] for f in figs].index(SPLIT_AFTER) + 1
        figs = figs[:k] if part == 0 else figs[k:]
    for name, surface, caption, view, halos, style, stacked in figs:
        if only is not None and name not in only:
            continue
        if name == first:
            # the other techniques show a 4x picture beside their own; the halos have none
            caption = f"{caption}. {NO_MSAA[:-1]}"
        # the figure and its halos-off twin from one slicing (render_halos_pair: the same bits
        # as two render_halos calls, ~1/6 less time, issue 27)
        on, off = render_halos_pair(surface, view=view, width=size, height=size, slices=slices,
                                    halos=halos, style=style)
        changed, covered = change_share(on, off)
        share = changed / max(covered, 1)
        if measurements is not None:
            measurements[name] = (changed, covered, on.stats)
        fn = f"halos4d_{name}.png"
        write_png(out_dir / fn, triptych(on, off, stacked))
        items.append(Item(SECTION, fn, f"{caption}. Halos off | on | changed pixels: the halos "
                          f"change {100 * share:.1f} % of the {covered} covered pixels "
                          f"(ρ = {on.stats['rho']:.3g}, δd = {on.stats['delta_d']:.3g})."))
    return items
