"""The options of :func:`refraster.cutaway.render_cutaway` as three immutable values.

Burns & Finkelstein (2008) build a cutaway in two parts, and the values follow them:

* :class:`Cutaway` — the cutaway surface D (Sec. 3, 5, 6): the cone angle, how D is flooded,
  perspective compensation, edge compression, the floor constraint, the cutaway buffer's size.
* :class:`CutSurfaces` — what the cut looks like (Sec. 4.1–4.2): shaded cut surfaces, their
  colour, the dilation that exposes them, their outlines.
* :class:`GhostLines` — the ghost lines (Sec. 4.3): the removed structure's lines drawn within a
  distance in front of D, faded. ``render_cutaway(ghosts=None)`` draws none.

Each value checks its fields when it is made; a bad field is refused with one line that names
it (``cutaway.variant must be one of …``), so that a value that exists is a valid one. Arrays
are kept as tuples of floats: the values compare with ``==`` and hash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._validate import (OptionValue, as_choice, as_colour, as_flag, as_float_array,
                         as_image_size, as_real)
from .flood import VARIANTS
from .lines import GHOST_CREASE_ANGLE
from .surface import FLOOR_MARGIN, as_angles

__all__ = ["Cutaway", "CutSurfaces", "GhostLines", "GHOST_SOURCES", "GHOST_DISTANCE_FRACTION"]

#: Where ghost lines come from (:attr:`GhostLines.source`).
GHOST_SOURCES = ("lines", "visible")
#: ``GhostLines(distance=None)``: g_max is this share of the diagonal of the secondary objects'
#: bounding box [guess].
GHOST_DISTANCE_FRACTION = 0.1




@dataclass(frozen=True)
class Cutaway(OptionValue):
    """The cutaway surface D (Burns & Finkelstein Sec. 3, 5, 6; MATH.md §4).

    Parameters
    ----------
    angle : float or sequence of float
        Cutaway half-angle θ to the view vector in radians, in (0, π/2): one value, or one per
        cutaway object (the ``interest`` meshes followed by the ``stand_ins``; local angles,
        Sec. 5.3). Default π/6. Kept as a float or a tuple of floats.
    variant : {"jfa", "jfa+1", "jfa+2", "1+jfa", "exact"}
        How D is computed (:func:`refraster.cutaway.jump_flood`); default ``"jfa"``, the
        paper's: Rong & Tan's jump flooding, log n passes k = n/2, …, 1 (Sec. 5.1).
        ``"jfa+1"`` (ours) appends one k = 1 pass, which repairs most of the pixels where plain
        jump flooding loses the best seed (MATH.md D-C5; docs/cutaway.md, "Variants").
    perspective_compensation : bool
        Eq. 3 as corrected (D-C4), the paper's choice (default True); False: the basic surface
        of Sec. 3.2, a cone in NDC.
    edge_compression : float ≥ 0 or None
        r of Sec. 5.4 (D-C6), the paper's 0.1 by default; None or 0 turns it off.
    floor_normal : (3,) float or None
        World-space floor normal: turns on the directional constraint (Sec. 5.5, D-C7). Not
        zero. Default None (off). Kept as a tuple of floats.
    floor_margin : float in [0, π/2]
        Safety angle δ of the floor constraint (:func:`refraster.cutaway.seed_slopes`), 2° by
        default [guess: the paper has none].
    buffer_size : (int, int) or None
        (width, height) of the cutaway buffer; None (default): the frame's size. Pixels may be
        non-square (the paper's 512² buffer for a 640×480 frame): distances are measured in
        view-plane tangent units. Upsampled bilinearly (Sec. 6).

    Examples
    --------
    >>> from refraster.cutaway import Cutaway
    >>> Cutaway(angle=0.5, floor_normal=(0, 1, 0)).floor_normal
    (0.0, 1.0, 0.0)
    """

    angle: float | tuple = math.pi / 6
    variant: str = "jfa"
    perspective_compensation: bool = True
    edge_compression: float | None = 0.1
    floor_normal: tuple | None = None
    floor_margin: float = FLOOR_MARGIN
    buffer_size: tuple | None = None

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        thetas = as_angles(self.angle, "cutaway.angle")
        put("angle", float(thetas[0]) if np.ndim(self.angle) == 0
            else tuple(float(t) for t in thetas))
        put("variant", as_choice(self.variant, "cutaway.variant", VARIANTS + ("exact",)))
        put("perspective_compensation", as_flag(self.perspective_compensation,
                                              "cutaway.perspective_compensation"))
        if self.edge_compression is not None:
            put("edge_compression", as_real(self.edge_compression, "cutaway.edge_compression",
                                            lo=0.0))
        if self.floor_normal is not None:
            n = as_colour(self.floor_normal, "cutaway.floor_normal")
            if not any(n):
                raise ValueError("cutaway.floor_normal must not be zero")
            put("floor_normal", n)
        put("floor_margin", as_real(self.floor_margin, "cutaway.floor_margin", lo=0.0,
                                    hi=math.pi / 2))
        if self.buffer_size is not None:
            size = self.buffer_size
            if not isinstance(size, (tuple, list)) or len(size) != 2:
                raise TypeError("cutaway.buffer_size must be None or a (width, height) pair, "
                                f"got {size!r}")
            try:
                put("buffer_size", as_image_size(size[0], size[1]))
            except (TypeError, ValueError) as exc:
                raise type(exc)(f"cutaway.buffer_size: {exc}") from None


@dataclass(frozen=True)
class CutSurfaces(OptionValue):
    """What the cut looks like (Burns & Finkelstein Sec. 4.1–4.2; MATH.md D-C8 … D-C10).

    Parameters
    ----------
    shade : bool
        Shade the exposed back faces of the secondary objects with the cutaway surface's
        normals (Sec. 4.1, Fig. 4b; default True); False leaves them as drawn, the hollow look
        of Fig. 4(a).
    color : (3,) float or None
        Base colour of the cut surfaces; None (default): the cut object's own palette colour.
        Kept as a tuple of floats.
    dilation : bool
        Clip back faces against the 3×3 minimum of D (Sec. 4.2, D-C8), the paper's choice
        (default True): a back face is exposed wherever a surface is clipped.
    outlines : bool
        Mark the cut surfaces' boundaries (Sec. 4.2, D-C10; default True).
    """

    shade: bool = True
    color: tuple | None = None
    dilation: bool = True
    outlines: bool = True

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("shade", as_flag(self.shade, "cut_surfaces.shade"))
        if self.color is not None:
            put("color", as_colour(self.color, "cut_surfaces.color"))
        put("dilation", as_flag(self.dilation, "cut_surfaces.dilation"))
        put("outlines", as_flag(self.outlines, "cut_surfaces.outlines"))


@dataclass(frozen=True)
class GhostLines(OptionValue):
    """Ghost lines (Burns & Finkelstein Sec. 4.3, Fig. 4d–e; MATH.md D-C11).

    ``render_cutaway(ghosts=None)`` draws no ghost lines; a :class:`GhostLines` value always
    draws them (within a positive distance).

    Parameters
    ----------
    source : {"lines", "visible"}
        ``"lines"`` (default, the paper's): the creases, silhouettes and borders of the
        secondary meshes as line segments (:mod:`refraster.cutaway.lines`), drawn where they lie
        in the removed region in front of D — every removed layer, not only the first.
        ``"visible"``: the image-space variant, the edge map of the first visible surface of
        the uncut scene only (kept for comparison; misses hidden structure).
    distance : float > 0 or None
        g_max, the largest eye-space distance in front of D at which a line is drawn. None
        (default): :data:`GHOST_DISTANCE_FRACTION` (10 %) of the diagonal of the secondary
        objects' bounding box [guess: the paper's is "user-specified"].
    fade : bool
        Fade α = 1 − gap/g_max (Fig. 4e, default) or draw at full opacity up to g_max (Fig. 4d).
    crease_angle : float in [0, 180]
        Dihedral angle in degrees above which an edge is a crease (``source="lines"``); 30° by
        default [guess].
    """

    source: str = "lines"
    distance: float | None = None
    fade: bool = True
    crease_angle: float = GHOST_CREASE_ANGLE

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("source", as_choice(self.source, "ghosts.source", GHOST_SOURCES))
        if self.distance is not None:
            distance = as_real(self.distance, "ghosts.distance", lo=0.0)
            if distance == 0.0:
                raise ValueError("ghosts.distance must be > 0, got 0.0 (ghosts=None draws no "
                                 "ghost lines)")
            put("distance", distance)
        put("fade", as_flag(self.fade, "ghosts.fade"))
        put("crease_angle", as_real(self.crease_angle, "ghosts.crease_angle", lo=0.0, hi=180.0))
