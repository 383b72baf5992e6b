"""The gallery: every technique contributes pictures.

Each technique has a module here exposing ``render(out_dir, *, quick=False) -> list[Item]``.
``quick=True`` renders at a small size for tests. ``refraster gallery`` calls them in
:data:`SECTIONS` order and writes ``index.html``.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["Item", "SECTIONS", "section_modules"]


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
