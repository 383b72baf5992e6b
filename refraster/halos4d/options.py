"""The options of :func:`refraster.halos4d.render_halos` as three immutable values.

Wang et al. (2013) render a 4D surface in three steps, and the values follow them:

* :class:`View4D` — how the surface is seen (Sec. 4.2): the 4D rotation, the 4D → 3D
  projection (eye, scale), the framing of the projected bounds and the cross-eyed stereo pair.
* :class:`Halos` — the halos themselves (Sec. 4.3–4.6, Eq. 2–3): the thickening radius ρ, the
  4D-depth drop-off δd and core δt, the surface's share w_s of the thickness and its
  anti-aliasing ramp, the occlusion rule's ε; ``enabled=False`` renders without halos
  (Fig. 1(b)).
* :class:`HaloStyle` — how the surface and its halos are drawn: the surface's opacity and
  headlight ambient, the halo volume's colour and opacity (Fig. 3(e)), the halo boundaries
  (Fig. 8).

Each value checks its fields when it is made; a bad field is refused with one line that names
it (``halos.delta_t must be <= 1.0, …``), so that a value that exists is a valid one. Arrays
are kept as tuples of floats: the values compare with ``==`` and hash.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import (OptionValue, as_choice, as_colour, as_flag, as_float_array, as_matrix,
                         as_real)
from .thicken import SPLITS
from .transforms import PROJECTIONS

__all__ = ["View4D", "Halos", "HaloStyle", "AMBIENT", "STEREO_ANGLE"]

#: Ambient part of the headlight shading ``ambient + (1 − ambient)·|n̂_z|``.
AMBIENT = 0.3
#: The angle in degrees between the two eyes of the paper's stereo pairs (Figs. 7–8) [guess].
STEREO_ANGLE = 6.0




@dataclass(frozen=True)
class View4D(OptionValue):
    """How a 4D surface is seen (Wang et al. Sec. 4.2; MATH.md §5.1–5.2).

    Parameters
    ----------
    rotation : (4, 4) float or None
        4D rotation applied before projection (see :mod:`refraster.halos4d.transforms`; 3D
        rotations are the xy, yz, zx planes); orthogonal to 1e-9. None (default): identity.
        Kept as a tuple of four rows of floats.
    projection : {"orthographic", "perspective"}
        4D → 3D projection (MATH.md §5.2), orthographic by default.
    eye : float or None
        Eye position on the w-axis (:func:`refraster.halos4d.project`); positive under
        perspective. None (default): ``3·max|v|`` (at least 1).
    scale : float > 0
        ``s`` (orthographic) or ``f/eye`` (perspective), default 1.
    margin : float in [0, 10]
        Share of the projected xy extent added on each side of the image (default 0.05); the
        image is the orthographic view of those bounds, square pixels.
    stereo : float in [0, 90] or None
        A cross-eyed stereo pair (Figs. 7–8): the thickened geometry turned by ∓``stereo``/2
        degrees about the screen y axis through the bounds' centre (the right eye's view on the
        left); :data:`STEREO_ANGLE` is 6°. None (default): one view.

    Examples
    --------
    >>> from refraster.halos4d import View4D, compose
    >>> View4D(rotation=compose(("zx", 0.5)), stereo=6.0).stereo
    6.0
    """

    rotation: tuple | None = None
    projection: str = "orthographic"
    eye: float | None = None
    scale: float = 1.0
    margin: float = 0.05
    stereo: float | None = None

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        if self.rotation is not None:
            r = as_matrix(self.rotation, "view.rotation")
            if not np.allclose(r @ r.T, np.eye(4), atol=1e-9, rtol=0.0):
                raise ValueError("view.rotation must be orthogonal (R Rᵀ = I to 1e-9)")
            put("rotation", tuple(tuple(float(x) for x in row) for row in r))
        put("projection", as_choice(self.projection, "view.projection", PROJECTIONS))
        if self.eye is not None:
            put("eye", as_real(self.eye, "view.eye"))
            if self.projection == "perspective" and self.eye <= 0.0:
                raise ValueError(f"view.eye must be positive under perspective, got {self.eye}")
        put("scale", as_real(self.scale, "view.scale", lo=0.0, lo_open=True))
        put("margin", as_real(self.margin, "view.margin", lo=0.0, hi=10.0))
        if self.stereo is not None:
            if isinstance(self.stereo, (bool, np.bool_)):
                raise TypeError("view.stereo must be None or the angle between the eyes in "
                                f"degrees (e.g. {STEREO_ANGLE}), got bool")
            put("stereo", as_real(self.stereo, "view.stereo", lo=0.0, hi=90.0))


@dataclass(frozen=True)
class Halos(OptionValue):
    """The depth-dependent volumetric halos (Wang et al. Sec. 4.3–4.6, Eq. 2–3; MATH.md §5.3–5.4).

    Parameters
    ----------
    enabled : bool
        True (default): the halos carve the surfaces behind them in 4D (Fig. 1(c)). False: no
        halo carving, only surface fragments take part in the 4D depth test (Fig. 1(b)); the
        surface is still thickened by ρ and drawn where |2t − 1| < w_s.
    rho : float > 0 or None
        Halo radius ρ (Eq. 2) in screen units; None (default): 3 % of the projected bounding-box
        diagonal (``thicken.RHO_FRACTION``) [guess: the paper gives no value; docs/halos4d.md,
        "Defaults"].
    delta_d : float ≥ 0 or None
        δd of Eq. 3 (4D-depth increase across the half-thickness); None (default):
        :func:`refraster.halos4d.default_halo_parameters`: ``(1 − δt)·δd`` = the 95th percentile
        of the 4D-depth differences of sheets that overlap in projection, so that Eq. 3 stays
        depth-dependent (``stats["crossing_pairs"]`` says how many differences were used).
    delta_t : float in [0, 1]
        δt of Eq. 3 (the core |2t − 1| < δt keeps the surface's own 4D depth); default 0.3,
        equal to the default w_s: the constant-depth middle region is the drawn surface, and
        the halo's depth drops off from where the surface ends.
    surface_width : float in (0, 1]
        w_s: a fragment is a surface fragment when |2t − 1| < w_s (the paper's "proximity of t
        to 0.5"), otherwise halo; default 0.3.
    antialias : float in [0, surface_width] or None
        a: the surface anti-aliased from t (Sec. 4.6): a surface fragment covers
        c = ``clamp((w_s + a − |2t − 1|)/(2a), 0, 1)`` of its voxel's thickness, so its opacity
        is ``1 − (1 − α)^c`` instead of the hard threshold ``|2t − 1| < w_s``; the mean
        thickness, and so the accumulated opacity, is unchanged. 0: the hard threshold.
        None (default): a ramp one pixel wide across a sheet seen edge-on,
        ``a = min(w_s, 0.5·pixel/ρ)`` (:func:`refraster.halos4d.render.default_antialias`):
        the drawn surface reaches at most half a pixel past ``w_s·ρ``, so the ramp never
        covers a halo gap wider than one pixel (a = w_s, the former default, covered gaps up
        to 0.3ρ, several pixels).
    depth_eps : float ≥ 0 or None
        ε of the occlusion rule δ ≤ minD + ε (MATH.md §5.4 [guess]); None (default):
        1e-6·max|δ|, above the rounding of float32 barycentrics, which do not sum to exactly 1.
    split : {"paper", "global_index"}
        How the prisms become tetrahedra (Sec. 4.4, 5.1; MATH.md §5.5;
        :func:`refraster.halos4d.thicken.split_prisms`). ``"paper"`` (default): each prism in
        its face's vertex order, then the paper's repair of mismatched shared faces (a diagonal
        flip, Fig. 4(b); two inserted vertices and three smaller prisms where a prism's sides
        end cyclic, Fig. 4(d)). ``"global_index"``: the global vertex-index rule (Dompierre et
        al.), conforming by construction, no inserted vertex; the output of the releases
        before issue 46.
    """

    enabled: bool = True
    rho: float | None = None
    delta_d: float | None = None
    delta_t: float = 0.3
    surface_width: float = 0.3
    antialias: float | None = None
    depth_eps: float | None = None
    split: str = "paper"

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("enabled", as_flag(self.enabled, "halos.enabled"))
        if self.rho is not None:
            put("rho", as_real(self.rho, "halos.rho", lo=0.0, lo_open=True))
        if self.delta_d is not None:
            put("delta_d", as_real(self.delta_d, "halos.delta_d", lo=0.0))
        put("delta_t", as_real(self.delta_t, "halos.delta_t", lo=0.0, hi=1.0))
        put("surface_width", as_real(self.surface_width, "halos.surface_width", lo=0.0, hi=1.0,
                                     lo_open=True))
        if self.antialias is not None:
            put("antialias", as_real(self.antialias, "halos.antialias", lo=0.0,
                                     hi=self.surface_width))
        if self.depth_eps is not None:
            put("depth_eps", as_real(self.depth_eps, "halos.depth_eps", lo=0.0))
        put("split", as_choice(self.split, "halos.split", SPLITS))


@dataclass(frozen=True)
class HaloStyle(OptionValue):
    """How the surface and its halos are drawn (Wang et al. Sec. 4.6, Figs. 3(e), 5(b), 8).

    Parameters
    ----------
    opacity : float in (0, 1]
        Accumulated opacity of a face-on surface, independent of the slice count (the opacity
        correction of :mod:`refraster.halos4d.render`); default 0.9.
    ambient : float in [0, 1]
        Ambient part of the headlight shading ``ambient + (1 − ambient)·|n̂_z|`` (default
        :data:`AMBIENT`, 0.3); a sheet seen edge-on (n̂_z = 0) is drawn at ``ambient`` × its
        colour.
    halo_color : (3,) float
        Colour of the halo volume itself (halo-only and carved voxels, Fig. 3(e)'s grey);
        default (0.5, 0.5, 0.5).
    halo_opacity : float in [0, 1)
        Accumulated opacity of a face-on halo shell (both sides, thickness 2·(1 − w_s − a)·ρ),
        independent of the slice count. Default 0: the halos carve holes and are not drawn, as
        in the paper's Figs. 1, 5–8.
    boundary_color : (3,) float or None
        Halo boundaries (Fig. 8's green): a carved surface voxel that the halos would no longer
        carve if every halo fragment were ``boundary_width``·ρ farther out (|2t − 1| + b in
        Eq. 3, fragments past the halo's edge dropped) is drawn in this colour: the rim, b·ρ
        wide, just inside each hole. None (default): off.
    boundary_width : float in (0, 1)
        b, default 0.15.
    """

    opacity: float = 0.9
    ambient: float = AMBIENT
    halo_color: tuple = (0.5, 0.5, 0.5)
    halo_opacity: float = 0.0
    boundary_color: tuple | None = None
    boundary_width: float = 0.15

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("opacity", as_real(self.opacity, "style.opacity", lo=0.0, hi=1.0, lo_open=True))
        put("ambient", as_real(self.ambient, "style.ambient", lo=0.0, hi=1.0))
        put("halo_color", as_colour(self.halo_color, "style.halo_color"))
        put("halo_opacity", as_real(self.halo_opacity, "style.halo_opacity", lo=0.0, hi=1.0,
                                    hi_open=True))
        if self.boundary_color is not None:
            put("boundary_color", as_colour(self.boundary_color, "style.boundary_color"))
        put("boundary_width", as_real(self.boundary_width, "style.boundary_width", lo=0.0,
                                      hi=1.0, lo_open=True, hi_open=True))
