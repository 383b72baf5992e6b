"""The gallery: every technique contributes pictures.

Each technique has a module here exposing ``render(out_dir, *, quick=False) -> list[Item]``.
``quick=True`` renders at a small size for tests. ``refraster gallery`` calls them in
:data:`SECTIONS` order and writes ``index.html``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["Item", "SECTIONS", "WORKER_GROUPS", "PAPERS", "PAGE_ORDER", "WITHOUT_PIPELINE", "section_modules"]


@dataclass(frozen=True)
class Item:
    """One picture: ``filename`` relative to the gallery directory, and its caption."""

    section: str
    filename: str
    caption: str


#: (module name under refraster.gallery, section title), in page order.
SECTIONS = [
    ("basic", "Canonical solids and the G-buffer"),
    ("ldi", "Layered depth images and the volumetric parity test"),
    ("clipsurface", "2.5D clip surfaces, relief clip planes and caps"),
    ("edges", "Edge enhancement and NPR styles"),
    ("cutaway", "Adaptive cutaways"),
    ("halos4d", "Volumetric halos for surfaces in 4D"),
]

#: The page shows the papers first, the plain G-buffer last.
PAGE_ORDER = ["clipsurface", "ldi", "edges", "cutaway", "halos4d", "basic"]

#: Per section: the paper it reproduces (shown under the section's title and in the table of
#: contents) and its headline picture, shown first.
PAPERS = {
    "clipsurface": dict(
        paper="Trapp & Döllner, 2.5D Clip-Surfaces for Technical Visualization; "
              "Relief Clipping Planes for Real-Time Rendering (poster)",
        headline="clipsurface_crank_hatched.png"),
    "ldi": dict(
        paper="Trapp & Döllner, 2.5D Clip-Surfaces for Technical Visualization, Sec. 5.2–5.4 "
              "(the layered depth images and the volumetric parity test behind the caps)",
        headline="ldi/crank_slice.png"),
    "edges": dict(
        paper="Nienhaus & Döllner, Edge-Enhancement – An Algorithm for Real-Time "
              "Non-Photorealistic Rendering, Journal of WSCG 11(1), 2003",
        headline="edges/edges_crank_gooch.png"),
    "cutaway": dict(
        paper="Burns & Finkelstein, Adaptive Cutaways for Comprehensible Rendering of Polygonal "
              "Scenes, ACM Trans. Graph. 27(5), 2008",
        headline="cutaway_galleon.png"),
    "halos4d": dict(
        paper="Wang, Yan, Fu, Hanson & Heng, Interactive Exploration of 4D Geometry with "
              "Volumetric Halos, Pacific Graphics 2013",
        headline="halos4d_fig1bc.png"),
    "basic": dict(paper="", headline=""),
}

#: Worker processes of ``refraster gallery --jobs N``, started in this order as workers free
#: up: each group's sections render in one process. On a first run the clip-surface section is
#: the longest (its kernels are ~60 % of the gallery's compile time, 2026-12-01), so it starts
#: first, with the depth peeling it needs; the edge maps it also uses are compiled meanwhile by
#: the other worker (edges first), and loaded from the cache when the clip surfaces need them.
WORKER_GROUPS = [("ldi", "clipsurface"), ("edges", "cutaway", "basic"), ("halos4d",)]
#: Sections that do not use the pipeline's kernels: on a first run their worker starts while
#: the pipeline's kernels compile in the parent (the others wait for those to be cached).
WITHOUT_PIPELINE = {"halos4d"}


def section_modules():
    """Yield ``(title, module)`` for each section whose module exists."""
    for name, title in SECTIONS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"{__name__}.{name}":
                continue
            raise
        yield title, mod
