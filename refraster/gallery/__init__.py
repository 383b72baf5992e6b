"""The gallery: every technique contributes pictures.

Each technique has a module here exposing ``render(out_dir, *, quick=False) -> list[Item]``.
``quick=True`` renders at a small size for tests. ``refraster gallery`` calls them in
:data:`SECTIONS` order and writes ``index.html``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["Item", "SECTIONS", "WORKER_GROUPS", "PAPERS", "PAGE_ORDER", "WITHOUT_PIPELINE",
           "PARTS", "WARM_SECONDS", "work_items", "split_item", "warm_plan", "merge_parts",
           "section_modules"]


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


#: Sections a warm run renders as several work items, one per worker (issue 27): the item
#: ``"name#k"`` is the module's ``render(out_dir, quick=…, part=k)`` for k < n, and the
#: section's items are the parts' items in part order.
PARTS = {"halos4d": 2}
#: CPU seconds of each work item of a warm full-size run, one thread
#: (``python -m benchmarks.gallery_profile``, 2026-12-02; the halo parts re-measured after
#: ``fig5d_diagram`` joined, split after it, and after the one-pass halo pair): a warm run
#: hands the items to its workers longest first (:func:`warm_plan`). An item not listed
#: counts as 1 s.
WARM_SECONDS = {"halos4d#0": 12.4, "halos4d#1": 14.7, "clipsurface": 6.3, "edges": 4.6,
                "cutaway": 3.5, "basic": 1.7, "ldi": 1.4}


def work_items(names):
    """The work items of sections ``names``: each section, or its parts (:data:`PARTS`)."""
    return [item for n in names
            for item in ([f"{n}#{k}" for k in range(PARTS[n])] if n in PARTS else [n])]


def split_item(item):
    """``(section, part)`` of a work item; ``part`` is None for a whole section."""
    name, sep, part = item.partition("#")
    return (name, int(part)) if sep else (name, None)


def warm_plan(items, jobs, seconds=None):
    """Work items split into at most ``jobs`` lists, one per worker process: longest first,
    each to the worker with the least work so far (ties: the lower worker; equal costs keep
    their order). Each item is in exactly one list."""
    seconds = WARM_SECONDS if seconds is None else seconds
    order = sorted(range(len(items)), key=lambda i: (-seconds.get(items[i], 1.0), i))
    plan = [[] for _ in range(max(1, min(jobs, len(items))))]
    load = [0.0] * len(plan)
    for i in order:
        w = min(range(len(plan)), key=lambda k: (load[k], k))
        plan[w].append(items[i])
        load[w] += seconds.get(items[i], 1.0)
    return [p for p in plan if p]


def merge_parts(results):
    """``{work item: (items, error)}`` → ``{section: (items, error)}``: the parts of a section
    (:data:`PARTS`) joined in part order, the first part's error if any; a part that did not
    answer is an error naming it."""
    out = {}
    for item in results:
        name, part = split_item(item)
        if part is None:
            out[name] = results[item]
        elif name not in out:
            keys = [f"{name}#{k}" for k in range(PARTS.get(name, part + 1))]
            items, error = [], None
            for key in keys:
                got, err = results.get(key, ([], f"work item {key} did not answer"))
                items += got
                error = error or err
            out[name] = (items, error)
    return out


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
