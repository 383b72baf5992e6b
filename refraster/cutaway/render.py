"""Cutaway rendering (Burns & Finkelstein 2008, Sec. 4): clip the secondary objects against the
cutaway surface, shade their exposed interiors as cut surfaces, outline them, and add ghost lines.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import framebuffer as _fb
from .._validate import as_image_size, as_matrix, as_option
from ..raster.state import as_raster_state, gl_clip_map, require_depth_direction, reverses
from ..mesh import as_meshes
from .lines import feature_segments, ghost_alpha
from .options import GHOST_DISTANCE_FRACTION, Cutaway, CutSurfaces, GhostLines
from .surface import (as_angles, cutaway_surface, min_filter_3x3, ndc_to_eye_depth, pixel_ndc,
                      unproject, upsample_bilinear)

#: Grey level of the ghost lines composited into ``image``.
GHOST_GREY = 0.12

__all__ = ["CutawayFramebuffer", "render_cutaway", "cut_surface_normals", "outline",
           "ghost_lines", "DEFAULT_CUTAWAY", "DEFAULT_CUT_SURFACES", "DEFAULT_GHOSTS"]


@dataclass(eq=False)
class CutawayFramebuffer(_fb.Framebuffer):
    """A :class:`refraster.Framebuffer` of the cutaway render plus its cutaway layers.

    The G-buffer fields describe the visible fragments after clipping; at cut-surface pixels
    ``normal`` holds the cutaway surface's normal and ``color`` its shading (MATH.md D-C9).
    Object ids are draw-call indices: the secondary objects first, then the objects of interest.

    Attributes
    ----------
    cutaway_depth : (H, W) float32
        The cutaway surface D at frame resolution, as the frame's *window* depth (the near
        plane's depth — 0, or 1 under reversed-Z — where nothing is cut).
    cutaway_buffer : (Hc, Wc) float64
        The cutaway surface at the cutaway buffer's own resolution, in OpenGL's NDC depth
        (near = −1; in another convention the frame's clip space mapped by
        :func:`refraster.raster.state.gl_clip_map`).
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


def _shade_cut(normal, pos, base):
    """The framebuffer's headlight shading applied to the cut-surface normal."""
    v = -pos / np.linalg.norm(pos, axis=-1, keepdims=True)
    diff = np.clip(np.abs(np.sum(normal * v, axis=-1, keepdims=True)), 0.0, 1.0)
    return np.clip(base * (0.18 + 0.72 * diff) + 0.22 * diff ** 48, 0.0, 1.0)


#: The defaults of :func:`render_cutaway`'s option values (the paper's choices).
DEFAULT_CUTAWAY = Cutaway()
DEFAULT_CUT_SURFACES = CutSurfaces()
DEFAULT_GHOSTS = GhostLines()


def render_cutaway(interest, secondary, *, view, proj, width, height, stand_ins=(),
                   cutaway=DEFAULT_CUTAWAY, cut_surfaces=DEFAULT_CUT_SURFACES,
                   ghosts=DEFAULT_GHOSTS, raster=None, background=(1.0, 1.0, 1.0)):
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
    stand_ins : sequence of meshes
        Invisible objects that shape the cutaway but are not drawn (Fig. 9).
    cutaway : Cutaway
        The cutaway surface: angle(s) θ — one, or one per cutaway object (the ``interest``
        meshes followed by the ``stand_ins``) —, flooding variant, perspective compensation,
        edge compression, floor constraint, buffer size (:class:`refraster.cutaway.Cutaway`;
        default ``Cutaway()``, the paper's choices).
    cut_surfaces : CutSurfaces
        Shading, colour, dilation and outlines of the cut (:class:`refraster.cutaway.CutSurfaces`;
        default ``CutSurfaces()``: shaded, dilated, outlined).
    ghosts : GhostLines or None
        The ghost lines (:class:`refraster.cutaway.GhostLines`; default ``GhostLines()``: the
        secondary meshes' feature lines, faded out over 10 % of their bounding box's diagonal);
        None: no ghost lines.
    raster : RasterState, optional
        The fixed-function state (:class:`refraster.RasterState`) of the frame: its depth
        test, cull mode, front face, precision, sub-pixel bits, fill rule, normals and the API
        conventions (depth range, window origin, NDC y, depth clamp) apply. The depth test
        must have a direction: ``less``/``lequal`` cleared to 1 (the paper's) or
        ``greater``/``gequal`` cleared to 0 (reversed-Z), depth writes on; anything else is
        refused with one line naming the field. The rear hulls are drawn with the opposite
        test (``greater`` cleared to 0, or ``less`` cleared to 1 under reversed-Z), no
        culling; the cut surfaces are the back faces as the state's front face defines them.
        The cutaway surface itself is computed in OpenGL's clip space (the projection mapped
        by :func:`refraster.raster.state.gl_clip_map`). None: the default.
    background
        As in :func:`refraster.render`.

    Returns
    -------
    CutawayFramebuffer

    Notes
    -----
    Pipeline (Sec. 4): (1) rear hulls of the OOI and stand-ins at the cutaway resolution with
    depth test ``greater`` (clear 0 = near); (2) :func:`cutaway_surface` in NDC depth; (3) D
    upsampled to the frame and converted to window depth; (4) one draw of the secondary objects
    then the OOI with a fragment stage that discards a secondary fragment iff z < D (front
    faces) or z < D_dil (back faces, with ``cut_surfaces.dilation``); OOI fragments are always
    kept, so the OOI are unclipped (Sec. 4.1); (5) cut surfaces shaded with normals from the
    surface that clipped them; (6) outlines and ghost lines: the secondary meshes' feature lines
    drawn where they lie in front of D, within g_max, faded (:func:`.lines.ghost_alpha`).

    Examples
    --------
    >>> from refraster.cutaway import Cutaway, GhostLines, render_cutaway
    >>> fb = render_cutaway(core, shells, view=view, proj=proj, width=320, height=240,
    ...                     cutaway=Cutaway(angle=0.5, floor_normal=(0, 1, 0)),
    ...                     ghosts=GhostLines(distance=1.0, fade=False))  # doctest: +SKIP
    """
    ctx = _setup(interest, secondary, stand_ins, view, proj, width, height, cutaway,
                 cut_surfaces, ghosts, raster, background, "render_cutaway")
    return _carve(ctx, _flood(ctx, *_rear(ctx, ctx.proj), ctx.proj_gl), ctx.proj)


class _Context:
    """The validated arguments of one cutaway and what follows from them."""


def _setup(interest, secondary, stand_ins, view, proj, width, height, cutaway, cut_surfaces,
           ghosts, raster, background, where, multisample=False):
    ctx = _Context()
    ctx.cutaway = cutaway = as_option(cutaway, Cutaway, "cutaway")
    ctx.cut_surfaces = cut_surfaces = as_option(cut_surfaces, CutSurfaces, "cut_surfaces")
    ctx.ghosts = ghosts = as_option(ghosts, GhostLines, "ghosts", optional=True)
    interest = as_meshes(interest, "interest") if _nonempty(interest) else []
    secondary = as_meshes(secondary, "secondary") if _nonempty(secondary) else []
    stand_ins = as_meshes(stand_ins, "stand_ins") if _nonempty(stand_ins) else []
    if not interest and not secondary:
        raise ValueError("nothing to draw: interest and secondary are both empty")
    ctx.interest, ctx.secondary, ctx.stand_ins = interest, secondary, stand_ins
    ctx.view = as_matrix(view, "view")
    ctx.proj = proj = as_matrix(proj, "proj")
    ctx.width, ctx.height = as_image_size(width, height)
    state = as_raster_state(raster)
    ctx.multisample_state = state
    if multisample:
        state = state.replace(samples=1, sample_locations="standard", interpolation="center")
    ctx.state = state = require_depth_direction(state, where)
    ctx.background = background
    # the cutaway is computed in OpenGL's clip space (MATH.md §4: NDC depth, near = −1): the
    # frame's conventions map there by T (gl_clip_map) and window depth by d → 1 − d under a
    # reversing depth test, so the paper's arithmetic and its comparisons stay as written
    ctx.rev = reverses(state)
    ctx.clip_map = gl_clip_map(state)
    ctx.proj_gl = proj if ctx.clip_map is None else ctx.clip_map @ proj
    ctx.buffer_size = cutaway.buffer_size or (ctx.width, ctx.height)
    ctx.thetas = thetas = as_angles(cutaway.angle, "cutaway.angle")
    ctx.hull = hull = interest + stand_ins
    if len(thetas) > 1 and len(thetas) != len(hull):
        raise ValueError(f"cutaway.angle has {len(thetas)} entries but there are {len(hull)} "
                         "cutaway objects (interest + stand_ins)")
    ghost_distance = 0.0
    if ghosts is not None:
        ghost_distance = ghosts.distance
        if ghost_distance is None:
            ghost_distance = GHOST_DISTANCE_FRACTION * _diagonal(secondary)
    ctx.ghost_distance = ghost_distance
    cut_color = cut_surfaces.color
    if cut_color is not None:
        cut_color = np.array(cut_color, np.float64)
    ctx.cut_color = cut_color
    return ctx


def _ndc(ctx, window_depth):
    """OpenGL-equivalent NDC depth of the frame's window depths (float64)."""
    z = 2.0 * np.asarray(window_depth, np.float64) - 1.0
    return -z if ctx.rev else z


def _rear(ctx, proj):
    """(1) The rear hulls of the cutaway objects at the cutaway buffer's size under ``proj``:
    ``(rear_depth, object_id)`` in OpenGL's window depth (the near end 0), or None."""
    if not ctx.hull:
        return None, None
    cw, ch = ctx.buffer_size
    rev = ctx.rev
    # the farthest surface: the depth test opposite to the frame's, cleared to the near end
    rear = _fb.render(ctx.hull, width=cw, height=ch, raster=ctx.state.replace(
        depth_func="less" if rev else "greater", clear_depth=1.0 if rev else 0.0,
        cull="none", normals="flat"), view=ctx.view, proj=proj)
    rear_depth = 1.0 - rear.depth.astype(np.float64) if rev else rear.depth
    return rear_depth, rear.object_id


def _flood(ctx, rear_depth, rear_ids, proj_gl):
    """(2) The cutaway surface at the cutaway buffer's resolution, in OpenGL's NDC depth."""
    cw, ch = ctx.buffer_size
    if rear_depth is None:
        return np.full((ch, cw), -1.0)
    cutaway = ctx.cutaway
    return cutaway_surface(rear_depth, rear_ids, proj=proj_gl, view=ctx.view,
                           angle=ctx.thetas, variant=cutaway.variant,
                           perspective_compensation=cutaway.perspective_compensation,
                           edge_compression=cutaway.edge_compression,
                           floor_normal=cutaway.floor_normal,
                           floor_margin=cutaway.floor_margin)


def _carve(ctx, buffer, proj):
    """(3)–(6): the cutaway surface ``buffer`` at frame resolution, the frame under ``proj``
    carved by it, cut surfaces, outlines and ghost lines."""
    width, height, state, rev = ctx.width, ctx.height, ctx.state, ctx.rev
    secondary, interest = ctx.secondary, ctx.interest
    cut_surfaces, ghosts, view = ctx.cut_surfaces, ctx.ghosts, ctx.view
    ghost_distance, cut_color = ctx.ghost_distance, ctx.cut_color
    proj_gl = proj if ctx.clip_map is None else ctx.clip_map @ proj

    def ndc(window_depth):
        return _ndc(ctx, window_depth)

    camera = dict(view=view, proj=proj)
    # (3) at frame resolution
    d_ndc = upsample_bilinear(buffer, height, width)
    d_back = min_filter_3x3(d_ndc) if cut_surfaces.dilation else d_ndc
    n_sec = len(secondary)

    # (4) clip secondary fragments, keep every OOI fragment
    carved_px = np.zeros(height * width, bool)

    def fragment_stage(frags):
        z = ndc(frags.depth)
        limit = np.where(frags.front_facing, d_ndc.reshape(-1)[frags.pixel],
                         d_back.reshape(-1)[frags.pixel])
        cut = (frags.object_id < n_sec) & (z < limit)
        carved_px[frags.pixel[cut]] = True
        return ~cut

    fb = _fb.render(secondary + interest, width=width, height=height, raster=state,
                    fragment_stage=fragment_stage, background=ctx.background, **camera)

    # (5) cut surfaces
    cut_mask = fb.mask & ~fb.front_facing & (fb.object_id < n_sec)
    normal = fb.normal.copy()
    color = fb.color.copy()
    if cut_surfaces.shade and cut_mask.any():
        n_cut = cut_surface_normals(d_back, proj_gl)[cut_mask]
        x, y = pixel_ndc(height, width)
        pos = unproject(x[cut_mask], y[cut_mask], ndc(fb.depth[cut_mask]), proj_gl)
        base = cut_color if cut_color is not None else \
            _fb.PALETTE[fb.object_id[cut_mask] % len(_fb.PALETTE)]
        normal[cut_mask] = n_cut
        color[cut_mask] = _shade_cut(n_cut, pos, base)

    # (6) lines
    edge = outline(cut_mask) if cut_surfaces.outlines else np.zeros((height, width), bool)
    ghost = np.zeros((height, width), np.float32)
    if ghost_distance > 0 and secondary and carved_px.any():
        if ghosts.source == "lines":
            segments = feature_segments(secondary, view=view, proj=proj_gl,
                                        crease_angle=ghosts.crease_angle)
            ooi = fb.mask & (fb.object_id >= n_sec)
            occluder = np.where(ooi, ndc(fb.depth), np.inf)
            ghost = ghost_alpha(segments, view=view, proj=proj_gl, width=width, height=height,
                                cutaway_ndc=d_ndc, g_max=ghost_distance, fade=ghosts.fade,
                                occluder_depth=occluder)
        else:
            from ..edges import edge_map
            plain = _fb.render(secondary, width=width, height=height, raster=state, **camera)
            em = edge_map(plain, preset="clean")
            strength = np.maximum(em[..., 0], em[..., 3])
            if rev:   # OpenGL-equivalent window depths (the background's clear 0 becomes 1)
                ghost = ghost_lines(strength, 1.0 - plain.depth.astype(np.float64), d_ndc,
                                    1.0 - fb.depth.astype(np.float64), proj_gl, ghost_distance)
            else:
                ghost = ghost_lines(strength, plain.depth, d_ndc, fb.depth, proj_gl,
                                    ghost_distance)
            if not ghosts.fade:
                ghost = np.where(ghost > 0, strength, 0.0).astype(np.float32)
    image = color.astype(np.float64) * (1.0 - ghost[..., None]) + GHOST_GREY * ghost[..., None]
    image[edge] = 0.0

    base = fb.field_values()
    base.update(normal=normal, color=color)
    return CutawayFramebuffer(
        **base, cutaway_depth=(0.5 - 0.5 * d_ndc if rev else 0.5 * d_ndc + 0.5).astype(
            np.float32), cutaway_buffer=buffer,
        cut_mask=cut_mask, carved=carved_px.reshape(height, width), outline=edge, ghost=ghost,
        image=image.astype(np.float32))


def _nonempty(meshes):
    return not (isinstance(meshes, (list, tuple)) and len(meshes) == 0)


def _diagonal(meshes):
    if not meshes:
        return 0.0
    v = np.concatenate([m.vertices for m in meshes])
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
