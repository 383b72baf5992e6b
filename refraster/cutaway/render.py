"""Cutaway rendering (Burns & Finkelstein 2008, Sec. 4): clip the secondary objects against the
cutaway surface, shade their exposed interiors as cut surfaces, outline them, and add ghost lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import framebuffer as _fb
from .._validate import as_choice, as_float_array, as_image_size, as_matrix, as_real
from ..mesh import as_meshes
from .flood import VARIANTS
from .lines import GHOST_CREASE_ANGLE, feature_segments, ghost_alpha
from .surface import (FLOOR_MARGIN, as_angles, cutaway_surface, min_filter_3x3, ndc_to_eye_depth, pixel_ndc,
                      unproject, upsample_bilinear)

#: Grey level of the ghost lines composited into ``image``.
GHOST_GREY = 0.12

__all__ = ["CutawayFramebuffer", "render_cutaway", "cut_surface_normals", "outline",
           "ghost_lines"]


@dataclass(eq=False)
class CutawayFramebuffer(_fb.Framebuffer):
    """A :class:`refraster.Framebuffer` of the cutaway render plus its cutaway layers.

    The G-buffer fields describe the visible fragments after clipping; at cut-surface pixels
    ``normal`` holds the cutaway surface's normal and ``color`` its shading (MATH.md D-C9).
    Object ids are draw-call indices: the secondary objects first, then the objects of interest.

    Attributes
    ----------
    cutaway_depth : (H, W) float32
        The cutaway surface D at frame resolution, as *window* depth (0 = near: nothing cut).
    cutaway_buffer : (Hc, Wc) float64
        The cutaway surface at the cutaway buffer's own resolution, in NDC depth.
    cut_mask : (H, W) bool
        Pixels showing a cut surface (a visible back-facing secondary fragment).
    carved : (H, W) bool
        Pixels where at least one secondary fragment was discarded.
    outline : (H, W) bool
        Cut-surface outlines (D-C10).
    ghost : (H, W) float32
        Ghost-line opacity in [0, 1] (D-C11).
    image : (H, W, 3) float32
        ``color`` with outlines (black) and ghost lines (dark grey, ``GHOST_GREY``, opacity α) composited.
    """

    cutaway_depth: np.ndarray = field(default=None, repr=False)
    cutaway_buffer: np.ndarray = field(default=None, repr=False)
    cut_mask: np.ndarray = field(default=None, repr=False)
    carved: np.ndarray = field(default=None, repr=False)
    outline: np.ndarray = field(default=None, repr=False)
    ghost: np.ndarray = field(default=None, repr=False)
    image: np.ndarray = field(default=None, repr=False)


def cut_surface_normals(cutaway_ndc, proj):
    """Eye-space unit normals of a cutaway surface given as an NDC depth image (D-C9).

    P(x) = unproject(x, D(x)); n = normalize(∂P/∂col × ∂P/∂row) (central differences, one-sided
    at the border), oriented toward the eye (n·(−P) > 0; for an orthographic camera n_z > 0).
    """
    d = np.asarray(cutaway_ndc, np.float64)
    h, w = d.shape
    x, y = pixel_ndc(h, w)
    pos = unproject(x, y, d, proj)
    if h < 2 or w < 2:
        return np.broadcast_to(np.array([0.0, 0.0, 1.0]), (h, w, 3)).copy()
    d_col = np.gradient(pos, axis=1)
    d_row = np.gradient(pos, axis=0)
    n = np.cross(d_col, d_row)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), np.array([0.0, 0.0, 1.0]))
    toward = -pos if proj[3, 2] != 0 else np.array([0.0, 0.0, 1.0])
    flip = np.sum(n * toward, axis=-1, keepdims=True) < 0
    return np.where(flip, -n, n)


def outline(mask):
    """Boundary of a binary mask: mask = 1 and some 8-neighbour = 0 (MATH.md D-C10; pixels
    outside the image count as equal to the edge pixel)."""
    m = np.asarray(mask, bool)
    return m & (min_filter_3x3(m.astype(np.float64)) < 0.5)


def ghost_lines(edges, line_depth, cutaway_ndc, visible_depth, proj, g_max):
    """Ghost-line opacity (MATH.md D-C11).

    Parameters
    ----------
    edges : (H, W) float
        Edge strength in [0, 1] of the secondary objects rendered without the cutaway.
    line_depth : (H, W) float
        Window depth of those lines (1.0 where nothing was drawn).
    cutaway_ndc : (H, W) float
        The cutaway surface D in NDC depth at frame resolution.
    visible_depth : (H, W) float
        Window depth of the cutaway render (lines hidden by what remains are not drawn).
    proj : (4, 4) float
    g_max : float
        Largest eye-space distance in front of the surface at which a line is still drawn.

    Returns
    -------
    (H, W) float32: α = E · (1 − (d(D) − d(z_l))/g_max) where z_l < D and the gap < g_max, with d
    the eye depth (both depths converted from NDC first), 0 elsewhere.
    """
    z_l = 2.0 * np.asarray(line_depth, np.float64) - 1.0
    inside = (np.asarray(line_depth) < 1.0) & (z_l < cutaway_ndc) \
        & (np.asarray(line_depth, np.float64) <= np.asarray(visible_depth, np.float64))
    gap = np.zeros(z_l.shape)
    gap[inside] = ndc_to_eye_depth(cutaway_ndc[inside], proj) - ndc_to_eye_depth(z_l[inside], proj)
    alpha = np.where(inside, np.clip(1.0 - gap / g_max, 0.0, 1.0), 0.0)
    return (np.asarray(edges, np.float64) * alpha).astype(np.float32)


def _as_size_pair(size, width, height):
    if size is None:
        return width, height
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise TypeError(f"cutaway_size must be None or a (width, height) pair, got {size!r}")
    try:
        return as_image_size(size[0], size[1])
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"cutaway_size: {exc}") from None


def _shade_cut(normal, pos, base):
    """The framebuffer's headlight shading applied to the cut-surface normal."""
    v = -pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    diff = np.clip(np.abs(np.sum(normal * v, axis=-1, keepdims=True)), 0.0, 1.0)
    return np.clip(base * (0.18 + 0.72 * diff) + 0.22 * diff ** 48, 0.0, 1.0)


def render_cutaway(interest, secondary, *, view, proj, width, height, angle=np.pi / 6,
                   stand_ins=(), cutaway_size=None, variant="jfa+1",
                   perspective_compensation=True, edge_compression=0.1, floor_normal=None,
                   floor_margin=FLOOR_MARGIN, dilation=True, outlines=True, ghost_distance=None, cut_color=None,
                   normals=None, background=(1.0, 1.0, 1.0), ghost="lines", ghost_fade=True,
                   crease_angle=GHOST_CREASE_ANGLE, cut_surfaces=True):
    """Render a cutaway: secondary objects carved away in front of the objects of interest.

    Parameters
    ----------
    interest : mesh or sequence of meshes
        Objects of interest (OOI): define the cutaway and are drawn unclipped. May be empty.
    secondary : mesh or sequence of meshes
        Secondary objects, clipped by the cutaway surface. Should be watertight and
        non-intersecting for the cut surfaces to read as solid (Sec. 4.1).
    view, proj : (4, 4) float
        Camera (perspective or orthographic OpenGL matrices).
    width, height : int
        Frame size.
    angle : float or sequence of float
        Cutaway half-angle θ to the view vector in radians, in (0, π/2): one value, or one per
        cutaway object (the ``interest`` meshes followed by the ``stand_ins``; Sec. 5.3).
    stand_ins : sequence of meshes
        Invisible objects that shape the cutaway but are not drawn (Fig. 9).
    cutaway_size : (int, int), optional
        (width, height) of the cutaway buffer; default the frame size. Pixels may be non-square:
        distances are measured in view-plane tangent units. Upsampled bilinearly (Sec. 6).
    variant : {"jfa", "jfa+1", "jfa+2", "1+jfa", "exact"}
        How D is computed (:func:`refraster.cutaway.jump_flood`).
    perspective_compensation : bool
        Eq. 3 as corrected (MATH.md D-C4).
    edge_compression : float or None
        r of Sec. 5.4 (D-C6); None or 0 turns it off.
    floor_normal : (3,) float, optional
        World-space floor normal: turns on the directional constraint (Sec. 5.5, D-C7).
    floor_margin : float
        Safety angle δ of the floor constraint (:func:`refraster.cutaway.seed_slopes`).
    dilation : bool
        Clip back faces against the 3×3 minimum of D (Sec. 4.2, D-C8).
    outlines : bool
        Mark the cut surfaces' boundaries (D-C10).
    ghost_distance : float or None
        g_max of the ghost lines in eye-space units (D-C11); None: 10 % of the diagonal of the
        secondary objects' bounding box [guess]; 0: no ghost lines.
    cut_color : (3,) float, optional
        Base colour of cut surfaces; default the cut object's own palette colour.
    normals, background
        As in :func:`refraster.render`.
    ghost : {"lines", "visible"}
        Source of the ghost lines. ``"lines"`` (default, the paper's): the creases, silhouettes
        and borders of the secondary meshes as line segments (:mod:`.lines`), drawn where they
        lie in the removed region in front of D — every removed layer, not only the first.
        ``"visible"``: the former image-space variant, the edge map of the first visible
        surface of the uncut scene only (kept for comparison; misses hidden structure).
    ghost_fade : bool
        Fade α = 1 − gap/g_max (Fig. 4e, default) or draw at full opacity up to g_max (4d).
    crease_angle : float
        Dihedral angle in degrees above which an edge is a crease (``ghost="lines"``).
    cut_surfaces : bool
        Shade the exposed back faces with the cutaway's normals (Sec. 4.1, Fig. 4b); False
        leaves them as drawn, the hollow look of Fig. 4(a).

    Returns
    -------
    CutawayFramebuffer

    Notes
    -----
    Pipeline (Sec. 4): (1) rear hulls of the OOI and stand-ins at the cutaway resolution with
    depth test ``greater`` (clear 0 = near); (2) :func:`cutaway_surface` in NDC depth; (3) D
    upsampled to the frame and converted to window depth; (4) one draw of the secondary objects
    then the OOI with a fragment stage that discards a secondary fragment iff z < D (front
    faces) or z < D_dil (back faces, with ``dilation``); OOI fragments are always kept, so the
    OOI are unclipped (Sec. 4.1); (5) cut surfaces shaded with normals from the surface that
    clipped them; (6) outlines and ghost lines: the secondary meshes' feature lines drawn
    where they lie in front of D, within g_max, faded (:func:`.lines.ghost_alpha`).
    """
    interest = as_meshes(interest, "interest") if _nonempty(interest) else []
    secondary = as_meshes(secondary, "secondary") if _nonempty(secondary) else []
    stand_ins = as_meshes(stand_ins, "stand_ins") if _nonempty(stand_ins) else []
    if not interest and not secondary:
        raise ValueError("nothing to draw: interest and secondary are both empty")
    view = as_matrix(view, "view")
    proj = as_matrix(proj, "proj")
    width, height = as_image_size(width, height)
    cw, ch = _as_size_pair(cutaway_size, width, height)
    thetas = as_angles(angle)
    hull = interest + stand_ins
    if len(thetas) > 1 and len(thetas) != len(hull):
        raise ValueError(f"angle has {len(thetas)} entries but there are {len(hull)} cutaway "
                         "objects (interest + stand_ins)")
    as_choice(variant, "variant", VARIANTS + ("exact",))
    ghost_source = as_choice(ghost, "ghost", {"lines": "lines", "visible": "visible"})
    crease_angle = as_real(crease_angle, "crease_angle", lo=0.0, hi=180.0)
    if ghost_distance is None:
        ghost_distance = 0.1 * _diagonal(secondary)
    ghost_distance = as_real(ghost_distance, "ghost_distance", lo=0.0)
    if cut_color is not None:
        cut_color = as_float_array(cut_color, "cut_color", shape=(3,))
    camera = dict(view=view, proj=proj)

    # (1)–(2) the cutaway surface at its own resolution
    if hull:
        rear = _fb.render(hull, width=cw, height=ch, depth_func="greater", clear_depth=0.0,
                          **camera)
        buffer = cutaway_surface(rear.depth, rear.object_id, proj=proj, view=view,
                                 angle=thetas, variant=variant,
                                 perspective_compensation=perspective_compensation,
                                 edge_compression=edge_compression, floor_normal=floor_normal,
                                 floor_margin=floor_margin)
    else:
        buffer = np.full((ch, cw), -1.0)
    # (3) at frame resolution
    d_ndc = upsample_bilinear(buffer, height, width)
    d_back = min_filter_3x3(d_ndc) if dilation else d_ndc
    n_sec = len(secondary)

    # (4) clip secondary fragments, keep every OOI fragment
    carved_px = np.zeros(height * width, bool)

    def fragment_stage(frags):
        z = 2.0 * frags.depth.astype(np.float64) - 1.0
        limit = np.where(frags.front_facing, d_ndc.reshape(-1)[frags.pixel],
                         d_back.reshape(-1)[frags.pixel])
        cut = (frags.object_id < n_sec) & (z < limit)
        carved_px[frags.pixel[cut]] = True
        return ~cut

    fb = _fb.render(secondary + interest, width=width, height=height, normals=normals,
                    fragment_stage=fragment_stage, background=background, **camera)

    # (5) cut surfaces
    cut_mask = fb.mask & ~fb.front_facing & (fb.object_id < n_sec)
    normal = fb.normal.copy()
    color = fb.color.copy()
    if cut_surfaces and cut_mask.any():
        n_cut = cut_surface_normals(d_back, proj)[cut_mask]
        x, y = pixel_ndc(height, width)
        pos = unproject(x[cut_mask], y[cut_mask], 2.0 * fb.depth[cut_mask].astype(np.float64) - 1.0,
                        proj)
        base = cut_color if cut_color is not None else \
            _fb.PALETTE[fb.object_id[cut_mask] % len(_fb.PALETTE)]
        normal[cut_mask] = n_cut
        color[cut_mask] = _shade_cut(n_cut, pos, base)

    # (6) lines
    edge = outline(cut_mask) if outlines else np.zeros((height, width), bool)
    ghost = np.zeros((height, width), np.float32)
    if ghost_distance > 0 and secondary and carved_px.any():
        if ghost_source == "lines":
            segments = feature_segments(secondary, view=view, proj=proj,
                                        crease_angle=crease_angle)
            ooi = fb.mask & (fb.object_id >= n_sec)
            occluder = np.where(ooi, 2.0 * fb.depth.astype(np.float64) - 1.0, np.inf)
            ghost = ghost_alpha(segments, view=view, proj=proj, width=width, height=height,
                                cutaway_ndc=d_ndc, g_max=ghost_distance, fade=ghost_fade,
                                occluder_depth=occluder)
        else:
            from ..edges import edge_map
            plain = _fb.render(secondary, width=width, height=height, normals=normals, **camera)
            em = edge_map(plain, preset="clean")
            strength = np.maximum(em[..., 0], em[..., 3])
            ghost = ghost_lines(strength, plain.depth, d_ndc, fb.depth, proj, ghost_distance)
            if not ghost_fade:
                ghost = np.where(ghost > 0, strength, 0.0).astype(np.float32)
    image = color.astype(np.float64) * (1.0 - ghost[..., None]) + GHOST_GREY * ghost[..., None]
    image[edge] = 0.0

    base = fb.field_values()
    base.update(normal=normal, color=color)
    return CutawayFramebuffer(
        **base, cutaway_depth=(0.5 * d_ndc + 0.5).astype(np.float32), cutaway_buffer=buffer,
        cut_mask=cut_mask, carved=carved_px.reshape(height, width), outline=edge, ghost=ghost,
        image=image.astype(np.float32))


def _nonempty(meshes):
    return not (isinstance(meshes, (list, tuple)) and len(meshes) == 0)


def _diagonal(meshes):
    if not meshes:
        return 0.0
    v = np.concatenate([m.vertices for m in meshes])
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
