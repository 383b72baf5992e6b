"""``render_clipped``: solids clipped by 2.5D clip surfaces, with cap surfaces closing the
cuts (Trapp & Döllner, Sec. 3 pipeline), its cap options :class:`Caps` and its
:class:`ClippedFramebuffer`."""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from .._scratch import SCRATCH_FACES, scratch_lease
from .._validate import as_choice, as_float_array, as_matrix, as_real, as_size
from ..framebuffer import Framebuffer
from ..ldi import MAX_RESOLUTION
from ..multisample import SampleFramebuffer
from ..raster.state import as_raster_state, require_depth_direction
from . import capping
from .fused import _fused_clip
from .surfaces import as_surfaces, clip_mask, _surfaces_in_space
from .textures import SolidTexture

__all__ = ["Caps", "ClippedFramebuffer", "ClippedSampleFramebuffer", "render_clipped"]


@dataclass(frozen=True)
class Caps:
    """How :func:`render_clipped` draws the cap surfaces that close the cuts (Trapp & Döllner,
    Sec. 5–6): one immutable value, built once and passed as ``caps=``; ``caps=None`` draws
    no caps (the solids are still clipped).

    Parameters
    ----------
    style : {"diffuse", "hatch", "marble", "wood", "noise", "solid"}
        Cap shading over the normal and occlusion maps
        (:func:`refraster.clipsurface.capping.shade_caps`). Default ``"diffuse"``: the paper's
        cap shading through the normal and occlusion maps (Sec. 5.1); ``"hatch"`` and the solid
        textures ``"marble"``, ``"wood"``, ``"noise"`` draw its Sec. 6.1 styles (Fig. 10,
        Fig. 11) procedurally. ``"diffuse"`` takes a surface's diffuse map
        (``ClipSurface(textures=CapTextures(...))``) as its base colour where it has one;
        ``"solid"`` takes ``solid_texture``. A surface's user normal and light maps replace
        the derived ones in every style (:func:`refraster.clipsurface.capping.texture_caps`).
    mode : {"mesh", "exact"}
        Default ``"mesh"``, the paper's (Sec. 5.1): the tessellated, displaced grid
        (``subdivision`` vertices per texel and axis) whose fragments pass the volumetric parity
        test. ``"exact"`` (not in the paper; it removes the Sec. 6.3 tessellation gaps):
        per-pixel ray – height-field intersection
        (:func:`refraster.clipsurface.capping.exact_caps`).
    color : (3,) float
        Base (diffuse), ink (hatch) or dark texture colour of the caps. Default
        ``(0.80, 0.30, 0.25)``, a brick red.
    hatch_spacing : float > 0, optional
        World distance between hatch lines. Default ``None``: 1.5 % of the solids' bounding
        diagonal.
    texture_frequency : float > 0
        Procedural solid-texture features per world unit. Default 4.0.
    subdivision : int in [1, 64]
        Cap-mesh vertices per offset-map texel and axis (``mode="mesh"``). Default 1: one
        vertex per texel centre, the paper's refined quad (Sec. 5.1) at the offset map's
        resolution.
    occlusion_radius : float > 0, optional
        Radius of the derived occlusion maps (:func:`refraster.offsetmaps.occlusion_map`).
        Default ``None``: 8 texels along the shorter texel side.
    solid_texture : SolidTexture or (D, H, W[, C]) array, optional
        The 3D texture of ``style="solid"`` (Fig. 11), required by it and used by no other
        style; sampled trilinearly at each cap point in its solid's object space (``model``
        inverted). An array becomes a :class:`refraster.clipsurface.textures.SolidTexture`
        spanning each solid's object-space bounding box once.
    vds_resolution : int in [8, 4096]
        Texels per side of the volumetric depth sprites built for the parity test
        (``VolumetricDepthSprite.from_mesh(solid, resolution=vds_resolution)``, Sec. 5.2) when
        :func:`render_clipped` is given none. Default 1024.

    Notes
    -----
    Pre-built sprites (``render_clipped(vds=...)``) are not a field: they are data about the
    solids (one per mesh, in world space, as the meshes and ``model`` place them), not a way of
    drawing caps, so one ``Caps`` value serves any scene; a cap option is a small value that
    compares and hashes by its fields (``solid_texture`` by identity) and that a scene package
    can store.

    Bad input raises one ``TypeError``/``ValueError`` naming the field (``caps.style ...``).
    ``dataclasses.replace(caps, style="hatch")`` makes a variant (validated again).
    """

    style: str = "diffuse"
    mode: str = "mesh"
    color: tuple = (0.80, 0.30, 0.25)
    hatch_spacing: float | None = None
    texture_frequency: float = 4.0
    subdivision: int = 1
    occlusion_radius: float | None = None
    solid_texture: SolidTexture | None = None
    vds_resolution: int = 1024

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        style = as_choice(self.style, "caps.style", {s: s for s in capping.CAP_STYLES})
        put("style", style)
        put("mode", as_choice(self.mode, "caps.mode", {"mesh": "mesh", "exact": "exact"}))
        put("color", tuple(float(c) for c in as_float_array(self.color, "caps.color",
                                                              shape=(3,))))
        if self.hatch_spacing is not None:
            put("hatch_spacing", as_real(self.hatch_spacing, "caps.hatch_spacing", lo=0.0,
                                         lo_open=True))
        put("texture_frequency", as_real(self.texture_frequency, "caps.texture_frequency",
                                         lo=0.0, lo_open=True))
        sub = self.subdivision
        if isinstance(sub, bool) or not isinstance(sub, numbers.Integral):
            raise TypeError(f"caps.subdivision must be an int, got {type(sub).__name__}")
        if not 1 <= sub <= 64:
            raise ValueError(f"caps.subdivision must be an int in [1, 64], got {sub!r}")
        put("subdivision", int(sub))
        if self.occlusion_radius is not None:
            put("occlusion_radius", as_real(self.occlusion_radius, "caps.occlusion_radius",
                                            lo=0.0, lo_open=True))
        put("solid_texture", _as_solid_texture(self.solid_texture, style))
        res = as_size(self.vds_resolution, "caps.vds_resolution", maximum=MAX_RESOLUTION)
        if res < 8:
            raise ValueError(f"caps.vds_resolution must be at least 8, got {res}")
        put("vds_resolution", res)


def _as_solid_texture(solid_texture, style):
    if solid_texture is None:
        if style == "solid":
            raise ValueError("caps.solid_texture is needed by caps.style='solid' (a "
                             "SolidTexture or a (D, H, W[, C]) volume)")
        return None
    if style != "solid":
        raise ValueError(f"caps.solid_texture is used by caps.style='solid' only, "
                         f"not {style!r}")
    if isinstance(solid_texture, SolidTexture):
        return solid_texture
    try:
        return SolidTexture(solid_texture)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"caps.solid_texture: {exc}") from None


#: ``render_clipped``'s default caps (read for nothing but defaults when ``caps=None``).
_DEFAULT_CAPS = Caps()


@dataclass(eq=False)
class ClippedFramebuffer(Framebuffer):
    """A :class:`~refraster.Framebuffer` of :func:`render_clipped`, with the caps marked.

    Extra attributes
    ----------------
    cap_mask : (H, W) bool
        Pixels showing a cap.
    cap_points : (C, 3) float64
        World position of each cap pixel, in row-major order of ``cap_mask``.
    cap_position : (H, W, 3) float64
        The same as an image, NaN elsewhere (made on first use).
    n_solids, n_surfaces : int
        M and K: a cap of solid m and surface k has ``object_id = M + m·K + k``.
    """

    cap_mask: np.ndarray = field(default=None, repr=False)
    cap_points: np.ndarray = field(default=None, repr=False)
    n_solids: int = 0
    n_surfaces: int = 0

    @property
    def cap_position(self):
        if getattr(self, "_cap_position", None) is None:
            out = np.full(self.cap_mask.shape + (3,), np.nan)
            out[self.cap_mask] = self.cap_points
            self._cap_position = out
        return self._cap_position

    def eye_position(self):
        """Eye-space position of the visible surface (caps included), NaN background."""
        out = np.full(self.mask.shape + (3,), np.nan)
        solid = self.mask & ~self.cap_mask
        sub = Framebuffer.eye_position(self)
        out[solid] = sub[solid]
        out[self.cap_mask] = self.cap_points @ self.view[:3, :3].T + self.view[:3, 3]
        return out


def _solid_tests(world_solids, vds, resolution):
    """One volumetric parity test per solid: given ``vds`` objects, or built with
    :class:`refraster.ldi.VolumetricDepthSprite` (MATH.md §2)."""
    if vds is not None:
        tests = list(vds) if isinstance(vds, (list, tuple)) else [vds]
        if len(tests) != len(world_solids):
            raise ValueError(f"vds must hold one sprite per mesh ({len(world_solids)}), "
                             f"got {len(tests)}")
        for i, t in enumerate(tests):
            if not callable(getattr(t, "contains", None)):
                raise TypeError(f"vds[{i}] must have a contains(points) method")
        return tests
    from ..ldi import VolumetricDepthSprite
    return [VolumetricDepthSprite.from_mesh(m, resolution=resolution) for m in world_solids]


def _stage(n_solids, surfaces, tests, space, view):
    """``render_clipped``'s clip stage as a ``fragment_stage`` over the fragment stream (what
    :func:`_fused_clip_pass` equals, and the path for duck-typed parity tests)."""
    n_surf = max(len(surfaces), 1)

    def stage(frags):
        obj = frags.object_id
        keep = np.ones(len(frags), np.bool_)
        pos = frags.world_position()
        test_pos = frags.eye_position() if space == "eye" else pos
        is_cap = obj >= n_solids
        skip = np.where(is_cap, (obj - n_solids) % n_surf, -1).astype(np.int64)
        keep &= ~clip_mask(test_pos, surfaces, space=space, view=view, skip=skip)
        for m in range(n_solids if tests is not None and is_cap.any() else 0):
            sel = np.flatnonzero(keep & is_cap & ((obj - n_solids) // n_surf == m))
            if sel.size:
                keep[sel] = tests[m].contains(pos[sel])
        return keep

    return stage


def _concat_vertices(vertices):
    if len(vertices) == 1:
        return np.ascontiguousarray(vertices[0], np.float64)
    return np.ascontiguousarray(np.concatenate(vertices), np.float64) if vertices \
        else np.zeros((0, 3))


#: Whether render_clipped uses the fused tile pass when it can (tests switch it off to compare
#: with the fragment stream and the Python stage, which it must equal bit for bit).
_USE_FUSED = True

#: Cap meshes kept per surface (keyed by the solid's bounds and the subdivision).
_CAP_CACHE_SIZE = 8


def _cached_cap(surface, bounds, subdivision, sprite=None):
    """``(mesh, sure)``: :func:`refraster.clipsurface.capping.cap_mesh`, made once per surface,
    bounds and subdivision (a surface is immutable; the cached mesh's arrays are read-only). With
    a volumetric depth sprite, only the faces that can pass its parity test
    (:func:`refraster.clipsurface.capping.cull_cap`) and their "surely inside" flags
    (:func:`refraster.clipsurface.capping.surely_inside`), made once per sprite too; ``sure`` is
    ``None`` without a sprite."""
    import weakref

    cache = surface._derived

    def put(key, mesh, value):
        caps = [k for k in cache if k[0] == "cap"]
        if len(caps) >= _CAP_CACHE_SIZE:
            del cache[caps[0]]
        if mesh is not None:
            mesh.vertices.setflags(write=False)
            mesh.faces.setflags(write=False)
        cache[key] = value

    key = ("cap", bounds.tobytes(), subdivision)
    cap = cache.get(key, False)
    if cap is False:
        cap = capping.cap_mesh(surface, bounds, subdivision=subdivision)
        put(key, cap, cap)
    if sprite is None or cap is None:
        return cap, None
    # the sprite is held weakly: an id can be reused once its sprite is gone
    culled_key = key + (id(sprite),)
    entry = cache.get(culled_key)
    if entry is None or entry[0]() is not sprite:
        culled = capping.cull_cap(cap, sprite)
        sure = capping.surely_inside(culled, sprite)
        sure.setflags(write=False)
        entry = (weakref.ref(sprite), culled, sure)
        put(culled_key, culled, entry)
    return entry[1], entry[2]


def render_clipped(meshes, surfaces, *, view, proj, width, height, caps=_DEFAULT_CAPS,
                   space="world", model=None, raster=None, vds=None,
                   background=(1.0, 1.0, 1.0)):
    """Render solids clipped by 2.5D clip surfaces, with cap surfaces closing the cuts.

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        The solids (draw calls 0 … M−1). With caps each must be watertight.
    surfaces : ClipSurface, ReliefClipPlane or a list of them (K surfaces, world space)
    view, proj, width, height
        The camera (:mod:`refraster.camera`).
    caps : Caps or None
        How the cap surfaces are drawn (Trapp & Döllner, Sec. 5): style, mode, colour,
        hatch spacing, texture frequency, subdivision, occlusion radius, solid texture and
        sprite resolution (:class:`Caps`; default ``Caps()``). ``None``: no caps, the solids
        are only clipped.
    space : {"world", "eye"}
        Where the clip test is evaluated (D6; equal for a rigid view). A keyword of its own,
        not a :class:`Caps` field: it decides which fragments the clip surfaces discard, with
        or without caps.
    model : (4, 4) or list of them, optional
        Object → world matrix per solid; surfaces are always given in world space.
    raster : RasterState, optional
        The fixed-function state (:class:`refraster.RasterState`): its depth test, cull mode,
        front face, precision, sub-pixel bits, fill rule, normals (the solids' shading
        normals) and the API conventions (depth range, window origin, NDC y, depth clamp)
        apply. The depth test must have a direction: ``less``/``lequal`` with the buffer
        cleared to 1 (the paper's ``GL_LESS``) or ``greater``/``gequal`` cleared to 0
        (reversed-Z), depth writes on; anything else is refused with one line naming the
        field. None: the default.
    vds : sequence of objects with ``contains(points)``, optional
        Pre-built volumetric depth sprites (world space), one per solid; built with
        ``VolumetricDepthSprite.from_mesh(solid, resolution=caps.vds_resolution)`` otherwise.
        Data about the solids rather than a cap option (see :class:`Caps`); unused without
        caps.
    background : (3,) float

    Returns
    -------
    ClippedFramebuffer
        The foundation's Framebuffer; cap pixels carry the cap's window and eye depth, its
        eye-space normal (from the normal map), its colour, ``front_facing`` (True when the
        cap is seen from its −N side, under either front face) and
        ``object_id = M + m·K + k`` for the cap of solid m and surface k. ``prim_id`` is the cap mesh's face (``"mesh"``) or the cap texel
        ``row·W + col`` (``"exact"``). ``cap_mask`` marks the cap pixels.

    Notes
    -----
    Solid fragments are discarded where any enabled surface clips them (MATH.md §1.1). A cap
    fragment of surface k is kept where the volumetric parity test says inside (MATH.md §2.2)
    and no *other* enabled surface clips it. Caps are drawn after the solids with the state's
    depth test, so at equal depth the solid wins under ``less``/``greater`` (the cap under
    ``lequal``/``gequal``). The volumetric parity test is a test of world positions (the
    sprites have their own camera) and so the same in every convention; the exact caps' rays
    and window depths follow the state's conventions (:func:`capping.pixel_rays`).
    """
    from ..framebuffer import _build, render
    from ..ldi import VolumetricDepthSprite
    from ..mesh import Mesh, as_meshes, bounds
    from ..raster import DEPTH_FUNCS, _models, facing, prepare
    from ..raster.fragments import vertices_in

    solids = as_meshes(meshes)
    surfaces = as_surfaces(surfaces)
    view = as_matrix(view, "view")
    proj = as_matrix(proj, "proj")
    if caps is not None and not isinstance(caps, Caps):
        raise TypeError(f"caps must be a Caps or None, got {type(caps).__name__}")
    space = as_choice(space, "space", {"world": "world", "eye": "eye"})
    options = _DEFAULT_CAPS if caps is None else caps
    style, mode = options.style, options.mode
    color = np.array(options.color, np.float64)
    freq = options.texture_frequency
    solid_tex = options.solid_texture
    occlusion_radius = options.occlusion_radius
    textured = [s.textures is not None for s in surfaces]
    if caps is not None and style in capping._PROCEDURAL and any(
            s.enabled and s.textures is not None and s.textures.diffuse is not None
            for s in surfaces):
        raise ValueError(f"caps.style={style!r} draws its own pattern; a surface's diffuse map "
                         "is used by caps.style='diffuse'")
    # the base pass colours "solid" caps as "diffuse"; texture_caps recolours them
    base_style = "diffuse" if style == "solid" else style
    state = require_depth_direction(as_raster_state(raster), "render_clipped",
                                    multisample=True)
    multi = state.samples != 1 or state.sample_locations != "standard"
    if multi and caps is not None and mode == "exact":
        raise ValueError(f"caps.mode must be 'mesh' at raster.samples={state.samples} (the "
                         "exact caps cast one ray per pixel centre), got 'exact'")
    if caps is not None and mode == "exact" and state.depth_clamp:
        raise ValueError("raster.depth_clamp must be False for caps.mode='exact' (its rays "
                         "span the clip volume between the near and far planes), got True")
    normals = state.normals
    models = _models(model, len(solids))
    world = [Mesh(v, s.faces) if v is not s.vertices else s
             for s, v in zip(solids, vertices_in(solids, models, None, "world"))]
    n_solids, n_surf = len(solids), len(surfaces)
    do_caps = caps is not None and any(s.enabled for s in surfaces)
    tests = None
    if do_caps:
        # the check keeps each solid's bounds (a solid seen before: one comparison for both)
        boxes = [capping.check_watertight(w, f"meshes[{i}]") for i, w in enumerate(world)]
        tests = _solid_tests(world, vds, options.vds_resolution)
    else:
        boxes = [bounds(w.vertices) if w.n_vertices else None for w in world]
    lo = np.min([b[0] for b in boxes if b is not None], axis=0) \
        if any(w.n_vertices for w in world) else np.zeros(3)
    hi = np.max([b[1] for b in boxes if b is not None], axis=0) \
        if any(w.n_vertices for w in world) else np.ones(3)
    spacing = (0.015 * float(np.linalg.norm(hi - lo)) or 0.01) \
        if options.hatch_spacing is None else options.hatch_spacing

    fused = _USE_FUSED and not multi and (not do_caps or mode != "mesh" or all(
        isinstance(t, VolumetricDepthSprite) for t in tests))
    draw_list, draw_models = list(solids), list(models)
    sure_flags = []   # per cap draw call: its faces' "surely inside" flags (or None)
    if do_caps and mode == "mesh":
        empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
        for m, box in enumerate(boxes):
            sprite = tests[m] if isinstance(tests[m], VolumetricDepthSprite) else None
            for s in surfaces:
                cap, sure = _cached_cap(s, box, options.subdivision, sprite) \
                    if s.enabled and box is not None else (None, None)
                draw_list.append(empty if cap is None else cap)
                sure_flags.append(sure)
                draw_models.append(np.eye(4))

    bg = as_float_array(background, "background", shape=(3,))
    geometry = None
    cap_tests = tests if do_caps and mode == "mesh" else None
    if multi:
        # the per-sample fragment stream with the same stage, at the state's shading rate
        fb = _render_samples(draw_list, view, proj, width, height, state, draw_models,
                             _stage(n_solids, surfaces, cap_tests, space, view), bg)
    elif not fused:
        # duck-typed parity tests: the fragment stream with a Python stage
        fb = render(draw_list, view=view, proj=proj, width=width, height=height,
                    raster=state, model=draw_models,
                    fragment_stage=_stage(n_solids, surfaces, cap_tests, space, view),
                    background=bg)
    else:
        # the primitive stage's and binning's intermediates from this thread's reused buffers
        # (as render: none of them outlives the tile pass), the outputs from the output pool
        with scratch_lease(sum(m.n_faces for m in draw_list) >= SCRATCH_FACES) as scratch:
            prep = prepare(draw_list, view=view, proj=proj, width=width, height=height,
                           raster=state, model=draw_models, scratch=scratch)
            tv = _concat_vertices(vertices_in(prep.meshes, prep.models, view, space))
            wv = tv if space == "world" else _concat_vertices(
                vertices_in(prep.meshes, prep.models, view, "world"))
            depth, prim_global, front, bary = _fused_clip(
                prep, tv, wv, n_solids, _surfaces_in_space(surfaces, space, view), cap_tests,
                sure_flags, DEPTH_FUNCS[state.depth_func], state.clear_depth, fill=False,
                scratch=scratch)
        facing(state, front, prim_global)
        h, w = depth.shape
        identity = all(np.array_equal(m, np.eye(4)) for m in prep.models)
        geometry = (tv, prep.triangles.faces) if identity and space == "world" else None
        # the mesh caps' pixels are coloured by shade_cap_pixels below, not by the default
        fb = _build(prep.meshes, prep.models, view, proj, depth, prim_global, prep.face_offsets,
                    front, bary.reshape(h, w, 3), normals, bg, geometry,
                    prep.face_offsets[n_solids] if do_caps and mode == "mesh" else None,
                    raster_bg=state.clear_depth)   # the background in finalize's sweep
    h, w = fb.depth.shape
    cap_mask, cap_flat = capping.cap_pixels(fb.object_id, n_solids)
    out = ClippedFramebuffer(**fb.field_values(), cap_mask=cap_mask,
        cap_points=np.zeros((0, 3)), n_solids=n_solids, n_surfaces=n_surf)
    if not do_caps:
        return _as_samples(out, state) if multi else out
    if mode == "mesh":
        p = np.asarray(proj, np.float64)
        if (state.front_face == "cw") ^ (state.ndc_y == "down") ^ bool(p[0, 0] * p[1, 1] < 0):
            # the cap meshes are the technique's own (counter-clockwise as seen from their −N
            # side): a cap's facing keeps that meaning whatever the solids' front face. Each of
            # clockwise fronts, NDC y down and a projection mirroring x against y reverses
            # which winding reads as front; an odd number of them turns the caps' round
            np.logical_xor(out.front_facing, cap_mask, out=out.front_facing)
        # the caps are drawn in world space (identity model): interpolate, light and colour
        # their pixels in one pass
        if geometry is None:
            vbase = np.cumsum([0] + [m.n_vertices for m in fb.meshes])
            geometry = (_concat_vertices([m.vertices for m in fb.meshes]),
                        np.concatenate([m.faces + vbase[k] for k, m in enumerate(fb.meshes)]))
        face_offsets = np.cumsum([0] + [m.n_faces for m in fb.meshes]).astype(np.int64)
        out.cap_points = capping.shade_cap_pixels(
            cap_flat, out, n_solids, n_surf, geometry[1], face_offsets,
            geometry[0], surfaces, view=view, style=base_style, color=color,
            hatch_spacing=spacing, frequency=freq, occlusion_radius=occlusion_radius)
        _texture_pass(out, surfaces, textured, style, color, solid_tex, solids, models, view,
                      occlusion_radius)
        return _as_samples(out, state) if multi else out
    else:
        tau, which, origin, direction = capping.exact_caps(
            surfaces, world, tests, view=view, proj=proj, width=width, height=height,
            raster=state)
        hit = np.isfinite(tau)
        pts = origin[hit] + tau[hit, None] * direction[hit]
        clip = np.c_[pts, np.ones(len(pts))] @ (proj @ view).T
        if state.depth_range == "zero_to_one":
            depth = (clip[:, 2] / clip[:, 3]).astype(np.float32)
        else:
            depth = (0.5 * (clip[:, 2] / clip[:, 3]) + 0.5).astype(np.float32)
        flat = np.flatnonzero(hit)
        nearer = _passes(state.depth_func, depth, fb.depth.ravel()[flat])
        flat, pts, depth = flat[nearer], pts[nearer], depth[nearer]
        m_k = which[flat]
        r, c = np.divmod(flat, w)
        cap_mask[r, c] = True
        out.cap_points = pts  # row-major order, as cap_mask lists them
        out.depth[r, c] = depth
        eye = pts @ view[:3, :3].T + view[:3, 3]
        out.eye_depth[r, c] = -eye[:, 2]
        out.object_id[r, c] = n_solids + m_k[:, 0] * n_surf + m_k[:, 1]
        texel = np.zeros(len(pts), np.int64)
        facing = np.zeros(len(pts), np.bool_)
        for k, s in enumerate(surfaces):
            sel = np.flatnonzero(m_k[:, 1] == k)
            if sel.size:
                st = s.texcoords(pts[sel])
                rows, cols = s.offset_map.shape
                col = np.floor(st[:, 0] * cols).astype(np.int64) % cols
                row = np.floor(st[:, 1] * rows).astype(np.int64) % rows
                texel[sel] = row * cols + col
                facing[sel] = direction[flat[sel]] @ s.normal > 0
        out.prim_id[r, c] = texel
        out.front_facing[r, c] = facing
        out.barycentric[r, c] = 0.0
        flat = np.flatnonzero(cap_mask)
    which_surface = (out.object_id.reshape(-1)[flat] - n_solids) % n_surf
    col, nrm = capping.shade_caps(out.cap_points, which_surface, surfaces, view=view,
                                  style=base_style, color=color, hatch_spacing=spacing,
                                  frequency=freq, occlusion_radius=occlusion_radius)
    out.color.reshape(-1, 3)[flat] = col
    out.normal.reshape(-1, 3)[flat] = nrm
    _texture_pass(out, surfaces, textured, style, color, solid_tex, solids, models, view,
                  occlusion_radius)
    return out


def _render_samples(draw_list, view, proj, width, height, state, models, stage, bg):
    """The frame at ``state.samples`` as a single-sample frame of the sample image
    ``(H, W·S)`` (:func:`refraster.multisample.draw_samples`): the clip stage keeps or
    discards each per-sample fragment — at pixel rate all samples of one triangle in one pixel
    carry the centre's (or centroid's) position and so one decision, at sample rate each its
    own — and the per-sample depth test is the resolve of the sample image."""
    from ..framebuffer import Framebuffer
    from ..multisample import draw_samples, sample_image
    from ..raster import resolve
    frags = draw_samples(draw_list, view=view, proj=proj, width=width, height=height,
                         model=models, raster=state)
    keep = np.asarray(stage(frags))
    one = sample_image(state)
    res = resolve(frags, raster=one, keep=keep)
    return Framebuffer.from_fragments(frags, res, raster=one, background=bg)


def _as_samples(out, state):
    """A sample-image :class:`ClippedFramebuffer` ``(H, W·S)`` as a
    :class:`ClippedSampleFramebuffer` ``(H, W, S)``."""
    from ..raster.samples import sample_points
    h, ws = out.depth.shape
    s = state.samples
    w = ws // s
    color = np.asarray(out.color)
    return ClippedSampleFramebuffer(
        depth=out.depth.reshape(h, w, s), eye_depth=out.eye_depth.reshape(h, w, s),
        normal=out.normal.reshape(h, w, s, 3), prim_id=out.prim_id.reshape(h, w, s),
        object_id=out.object_id.reshape(h, w, s),
        front_facing=out.front_facing.reshape(h, w, s),
        barycentric=out.barycentric.reshape(h, w, s, 3), color=color.reshape(h, w, s, 3),
        positions=sample_points(state), raster=state,
        cap_mask=out.cap_mask.reshape(h, w, s), cap_points=out.cap_points,
        n_solids=out.n_solids, n_surfaces=out.n_surfaces)


class ClippedSampleFramebuffer(SampleFramebuffer):
    """:func:`render_clipped`'s result at ``raster.samples > 1``: a
    :class:`refraster.SampleFramebuffer` (buffers ``(H, W, S[, C])``) with the caps marked.

    Extra attributes: ``cap_mask (H, W, S)`` the samples showing a cap; ``cap_points (C, 3)``
    the world position of each cap sample, in row-major order of ``cap_mask`` (pixel, then
    sample); ``n_solids``, ``n_surfaces`` (a cap of solid m and surface k has
    ``object_id = M + m·K + k``)."""

    __slots__ = ("cap_mask", "cap_points", "n_solids", "n_surfaces")

    def __init__(self, *, depth, eye_depth, normal, prim_id, object_id, front_facing,
                 barycentric, color, positions, raster, cap_mask, cap_points, n_solids,
                 n_surfaces):
        super().__init__(depth=depth, eye_depth=eye_depth, normal=normal, prim_id=prim_id,
                         object_id=object_id, front_facing=front_facing,
                         barycentric=barycentric, color=color, positions=positions,
                         raster=raster)
        self.cap_mask, self.cap_points = cap_mask, cap_points
        self.n_solids, self.n_surfaces = n_solids, n_surfaces

    def arrays(self):
        out = super().arrays()
        out["cap_mask"] = self.cap_mask
        return out


def _passes(depth_func, depth, stored):
    """The depth test of drawn cap fragments against the stored depths (vectorized)."""
    if depth_func == "less":
        return depth < stored
    if depth_func == "lequal":
        return depth <= stored
    if depth_func == "greater":
        return depth > stored
    return depth >= stored


def _texture_pass(out, surfaces, textured, style, color, solid_tex, solids, models, view,
                  occlusion_radius):
    """Recolour the cap pixels that take user textures: every cap for ``"solid"``, else those
    of surfaces with :class:`CapTextures` (:func:`capping.texture_caps`)."""
    if style != "solid" and not any(textured):
        return
    n_solids, n_surf = out.n_solids, out.n_surfaces
    flat = np.flatnonzero(out.cap_mask)
    obj = out.object_id.reshape(-1)[flat] - n_solids
    k, m = obj % n_surf, obj // n_surf
    sel = np.arange(len(flat)) if style == "solid" else \
        np.flatnonzero(np.asarray(textured, np.bool_)[k])
    if sel.size == 0:
        return
    pts = out.cap_points[sel]
    solid_colors = None
    if style == "solid":
        solid_colors = np.zeros((sel.size, 3))
        for j in np.unique(m[sel]):
            which = np.flatnonzero(m[sel] == j)
            inv = np.linalg.inv(models[j])
            local = pts[which] @ inv[:3, :3].T + inv[:3, 3]
            v = solids[j].vertices
            solid_colors[which] = solid_tex.sample(local, (v.min(axis=0), v.max(axis=0)))
    col, nrm = capping.texture_caps(pts, k[sel], surfaces, view=view, style=style,
                                    color=color, occlusion_radius=occlusion_radius,
                                    solid_colors=solid_colors)
    out.color.reshape(-1, 3)[flat[sel]] = col
    out.normal.reshape(-1, 3)[flat[sel]] = nrm
