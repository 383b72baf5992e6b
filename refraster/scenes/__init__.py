"""Canonical scenes: procedural solids shared by the tests, the gallery and the benchmarks.

:data:`SOLIDS` maps each canonical solid's name to its constructor (defaults = full detail) and
:data:`QUICK` holds the keyword arguments of a lighter version for quick runs. See
:mod:`refraster.scenes.solids` and ``docs/scenes.md``.
"""

from __future__ import annotations

from .solids import building, crank, cube, fluted_column, icosphere, nested_shells, torus

__all__ = [
    "SOLIDS", "QUICK", "solid",
    "building", "crank", "cube", "fluted_column", "icosphere", "nested_shells", "torus",
]

#: name → constructor, in gallery order.
SOLIDS = {
    "cube": cube,
    "icosphere": icosphere,
    "torus": torus,
    "fluted_column": fluted_column,
    "nested_shells": nested_shells,
    "building": building,
    "crank": crank,
}

#: name → keyword arguments for a light version (small images, quick tests).
QUICK = {
    "cube": {},
    "icosphere": {"subdivisions": 2},
    "torus": {"major_segments": 32, "minor_segments": 12},
    "fluted_column": {"samples_per_flute": 4, "rings": 8},
    "nested_shells": {"subdivisions": 2},
    "building": {},
    "crank": {"segments": 32},
}


def solid(name, *, quick=False):
    """The canonical solid ``name`` (a key of :data:`SOLIDS`), light when ``quick``."""
    from .._validate import as_choice
    key = as_choice(name, "name", {k: k for k in SOLIDS})
    return SOLIDS[key](**(QUICK[key] if quick else {}))
