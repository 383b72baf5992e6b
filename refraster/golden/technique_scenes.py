"""Golden scenes of the techniques whose public entry points exist: edge maps
(:mod:`refraster.edges`) and 2.5D clip surfaces with caps (:mod:`refraster.clipsurface`).

Each scene's parameters name every argument the technique was called with, so a GPU
implementation can reproduce the frame from the scene package.
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..raster.state import RasterState
from .allowances.core import changes
from .scenes import Draw, GoldenScene, _framed, prepare_draws, raster_state, register_scene, \
    render_draws


def _building_edges(normal_filter, depth_filter):
    """The building rendered as the edge scenes show it and its edge map with the given
    operators (no ids, no thresholds, width 1, gains 1): ``(draws, camera, fb, params, edges)``."""
    from ..edges import edge_map
    from ..scenes import solid
    state = raster_state({})
    draws = prepare_draws([Draw("building", solid("building"))])
    camera = _framed([d.mesh for d in draws], 160, 120, (1.2, 0.9, 1.6))
    fb = render_draws(draws, camera, state)
    lo, hi = draws[0].mesh.vertices.min(axis=0), draws[0].mesh.vertices.max(axis=0)
    params = dict(bounds=[lo.tolist(), hi.tolist()], preset="paper", normal_filter=normal_filter,
                  depth_filter=depth_filter, ids=False, inner_threshold=0.0,
                  profile_threshold=0.0, width=1, k_n=1.0, k_z=1.0)
    edges = edge_map(fb, **{**params, "bounds": np.array(params["bounds"])})
    return draws, camera, fb, params, edges


@register_scene("edges_building", technique="edges",
                description="Edge map (Nienhaus & Döllner), the paper's operator: diagonal "
                            "normal filter in RGB, diagonal depth filter as printed in A, no id "
                            "edges, no thresholds (raw intensities).")
def _edges_building():
    draws, camera, fb, params, edges = _building_edges("diagonal", "diagonal")
    # the texture formats a backend may use, as the paper's (RGBA8 G-buffer and edge map); the
    # edge map's allowance includes their quantisation (docs/tolerance.md, "Edge maps")
    params.update(gbuffer_format="rgba8", output_format="rgba8")
    # the diagonal operators read the 8-neighbourhood; a "may" pixel of the G-buffer may change
    # the edge map one pixel away (two kept as margin)
    return GoldenScene(technique="edges", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "edge_map": edges}, parameters=params,
                       may_radius=2)


def _edges_operator_scene(normal_filter, depth_filter):
    """The building of ``edges_building`` with other operators (issue 26, item 5: a scene per
    edge operator), float32 textures, no thresholds."""
    draws, camera, fb, params, edges = _building_edges(normal_filter, depth_filter)
    params.update(gbuffer_format="float32", output_format="float32")
    return GoldenScene(technique="edges", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "edge_map": edges}, parameters=params,
                       may_radius=2)


@register_scene("edges_sobel", technique="edges",
                description="Edge map of the building with the Sobel operators (Nienhaus & "
                            "Döllner Sec. 4.1.2's alternative): Sobel of the normal channels in "
                            "RGB, Sobel of depth in A, gains 1, float32 textures.")
def _edges_sobel():
    return _edges_operator_scene("sobel", "sobel")


@register_scene("edges_c1", technique="edges",
                description="Edge map of the building with the C1 depth operator (normalized "
                            "1/12) in A and the angle normal operator in RGB, float32 textures.")
def _edges_c1():
    return _edges_operator_scene("angle", "c1")


@register_scene("edges_diagonal2", technique="edges",
                description="Edge map of the building with the second-difference diagonal depth "
                            "operator ('diagonal2', docs/edges.md D-E3) in A and the diagonal "
                            "normal operator in RGB, float32 textures.")
def _edges_diagonal2():
    return _edges_operator_scene("diagonal", "diagonal2")


@register_scene("edges_c1_paper", technique="edges",
                description="Edge map of the building with the C1 depth operator at the paper's "
                            "printed 1/8 scale ('c1-paper') in A and the Sobel normal operator "
                            "in RGB, float32 textures.")
def _edges_c1_paper():
    return _edges_operator_scene("sobel", "c1-paper")


@register_scene("edges_npr_gooch", technique="edges",
                description="The paper's edge map of the building composited over Gooch shading "
                            "(Nienhaus & Döllner Sec. 5.1: inner edges towards white, profile "
                            "edges towards black, on the objects only), as npr_color.")
def _edges_npr_gooch():
    from ..edges import npr as _npr
    draws, camera, fb, params, edges = _building_edges("diagonal", "diagonal")
    style = dict(light=list(_npr.DEFAULT_LIGHT), base=[0.75, 0.75, 0.75], cool=[0.0, 0.0, 0.55],
                 warm=[0.3, 0.3, 0.0], alpha=0.25, beta=0.5, background=[1.0, 1.0, 1.0])
    shade = _npr.gooch(fb.normal, **style)
    colors = dict(inner_color=[1.0, 1.0, 1.0], profile_color=[0.0, 0.0, 0.0])
    out = _npr.composite(shade, edges, **colors, mask=np.asarray(fb.object_id) >= 0)
    params.update(gbuffer_format="rgba8", output_format="rgba8",
                  npr={"style": "gooch", **style, **colors, "mask": "objects"})
    return GoldenScene(technique="edges", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "edge_map": edges, "npr_color": out},
                       parameters=params, may_radius=2)


def clip_caps(parameters):
    """The cap options a clip-surface scene stores, as
    :func:`refraster.clipsurface.render_clipped` takes them: a
    :class:`refraster.clipsurface.Caps`, or ``None`` for ``"caps": false``.

    A scene package keeps them as flat keys of ``scene.json`` (``caps``, ``cap_style``,
    ``cap_mode``, ``cap_color``, ``subdivision``, ``vds_resolution`` and the backend export's
    ``occlusion_radius``; docs/golden-schema.md); a missing key takes the default of
    :class:`~refraster.clipsurface.Caps`. The clip test's ``space`` is stored beside them."""
    from ..clipsurface import Caps
    if not parameters.get("caps", True):
        return None
    return Caps(**{name: parameters[key] for key, name in (
        ("cap_style", "style"), ("cap_mode", "mode"), ("cap_color", "color"),
        ("subdivision", "subdivision"), ("vds_resolution", "vds_resolution"),
        ("occlusion_radius", "occlusion_radius")) if key in parameters})


@register_scene("clipsurface_building", technique="clipsurface",
                description="Building cut by a 2.5D clip surface with a Perlin offset map "
                            "(N = −z: the front half is removed), diffuse caps (Trapp & "
                            "Döllner).")
def _clipsurface_building():
    from ..clipsurface import render_clipped
    state = raster_state({})
    draws, camera, surface, caps, clip, offset_map = perlin_building_clip(160, 120)
    fb = render_clipped([d.mesh for d in draws], clip, **camera.kwargs,
                        caps=clip_caps(caps), space=caps["space"],
                        raster=RasterState(cull=state["cull"], precision=state["precision"]))
    surfaces = [{**surface, "offset_map": "offset_map"}]
    backend_params, backend_maps = clip_export(draws, [clip], caps, surfaces)
    return GoldenScene(technique="clipsurface", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "cap_mask": fb.cap_mask},
                       ids=_clip_ids(draws, [clip], caps["subdivision"]),
                       parameters={"surfaces": surfaces, **caps, **backend_params},
                       maps={"offset_map": offset_map, **backend_maps}, geometry=False,
                       may=_clip_decision_may(draws, camera, clip, fb.cap_mask))


def perlin_building_clip(width, height):
    """``clipsurface_building``'s scene at ``width × height``: the building, its camera, the
    Perlin clip surface (stored fields and :class:`refraster.clipsurface.ClipSurface`) and the
    diffuse caps — ``(draws, camera, surface, caps, clip, offset_map)`` (the multisampled
    clip-surface scenes, :mod:`.msaa_clip_scenes`, draw the same at 96×72)."""
    from ..clipsurface import ClipSurface
    from ..clipsurface.offsetmaps import perlin_noise
    from ..scenes import solid
    draws = prepare_draws([Draw("building", solid("building"))])
    camera = _framed([d.mesh for d in draws], width, height, (1.2, 0.9, 1.6))
    offset_map = perlin_noise((64, 64), seed=1)
    surface = dict(origin=[0.0, 0.0, 3.5], u=[0.0, 6.25, 0.0], v=[10.0, 0.0, 0.0],
                   scale=[1.0, 1.0, 0.8], wrap="repeat", enabled=True)
    caps = dict(caps=True, cap_style="diffuse", cap_mode="mesh", cap_color=[0.8, 0.3, 0.25],
                subdivision=1, vds_resolution=512, space="world")
    clip = ClipSurface(surface["origin"], surface["u"], surface["v"], surface["scale"],
                       offset_map, wrap=surface["wrap"])
    return draws, camera, surface, caps, clip, offset_map


def clip_export(draws, clips, caps, surfaces):
    """:func:`_clip_backend_export` with the derived maps named in ``surfaces`` (the stored
    surface entries, changed in place): ``(backend_params, backend_maps)``."""
    backend_params, backend_maps = _clip_backend_export(draws, clips, caps)
    _name_derived_maps(surfaces, backend_maps)
    return backend_params, backend_maps


def _clip_backend_export(draws, surfaces, caps, occlusion_radius=None):
    """What a backend needs to redraw a clip-surface scene (issue 25 item 2;
    docs/golden-schema.md, "Clip surfaces: what the package carries"): per solid its volumetric
    depth sprite (as the vds scene exports it), per solid and surface the cap mesh exactly as
    ``render_clipped`` draws it (the displaced grid culled by the sprite: its face numbering
    *is* the caps' ``prim_id``), and per surface the derived normal and occlusion maps the caps
    are shaded with. Returns ``(parameters, maps)`` to add to the scene's."""
    from ..clipsurface.capping import cap_mesh
    from ..clipsurface.capping import cull_cap
    from ..ldi import VolumetricDepthSprite
    from ..mesh import Mesh, as_mesh, bounds
    params, maps = {"sprites": [], "cap_meshes": [], "occlusion_radius": occlusion_radius,
                    "evaluation_space": caps.get("space", "world")}, {}
    m_count, k_count = len(draws), len(surfaces)
    for m, d in enumerate(draws):
        mesh = as_mesh(d.mesh)
        if not np.array_equal(np.asarray(d.model), np.eye(4)):
            raise AssertionError("clip-surface scenes draw their solids with identity models")
        sprite = VolumetricDepthSprite.from_mesh(mesh, resolution=caps["vds_resolution"])
        ldi = sprite._ldis[0]
        depth = np.where(ldi.sign != 0, ldi.depth, np.float32(1.0)).astype(np.float32)
        names = [f"sprite{m}_depth_{j}" for j in range(len(depth))]
        for j, name in enumerate(names):
            maps[name] = np.ascontiguousarray(depth[j])
        maps[f"sprite{m}_count"] = np.asarray(ldi.count, np.int32)
        params["sprites"].append(dict(
            test="parity", resolution=int(caps["vds_resolution"]), axis=ldi.axis, margin=2,
            sprite_matrix=np.asarray(ldi.matrix, np.float64).tolist(), layers=len(depth),
            sprite_depth=names, sprite_count=f"sprite{m}_count"))
        box = bounds(mesh.vertices)
        for k, s in enumerate(surfaces):
            cap = cap_mesh(s, box, subdivision=caps["subdivision"]) if s.enabled else None
            cap = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64)) if cap is None \
                else cull_cap(cap, sprite)
            vname, fname = f"cap{m}_{k}_vertices", f"cap{m}_{k}_faces"
            maps[vname] = np.asarray(cap.vertices, np.float64)
            maps[fname] = np.asarray(cap.faces, np.int32)
            params["cap_meshes"].append(dict(solid=m, surface=k, object_id=m_count + m * k_count
                                             + k, vertices=vname, faces=fname,
                                             n_vertices=int(cap.n_vertices),
                                             n_faces=int(cap.n_faces)))
    for k, s in enumerate(surfaces):
        n = s.normal_map()
        for i, ch in enumerate("xyz"):
            maps[f"surface{k}_normal_{ch}"] = np.ascontiguousarray(n[..., i], np.float64)
        maps[f"surface{k}_occlusion"] = np.ascontiguousarray(
            s.occlusion_map(radius=occlusion_radius), np.float64)
    return params, maps


def _name_derived_maps(surfaces, maps):
    """Name each surface's derived maps (:func:`_clip_backend_export`) in its entry."""
    for k, s in enumerate(surfaces):
        s["normal_map"] = [f"surface{k}_normal_{ch}" for ch in "xyz"]
        s["occlusion_map"] = f"surface{k}_occlusion"
        assert all(name in maps for name in s["normal_map"] + [s["occlusion_map"]])


def _clip_ids(draws, surfaces, subdivision):
    """The id convention of a clip-surface scene (:func:`refraster.clipsurface.render_clipped`):
    solid pixels carry their solid's face (prim_id < F) and draw (object_id < M); the cap of
    solid m and surface k carries object_id M + m·K + k and the face of its cap mesh (at most
    the faces of the cap mesh over the solid's box)."""
    from ..clipsurface.capping import cap_mesh
    from ..mesh import as_mesh, bounds
    meshes = [as_mesh(d.mesh) for d in draws]
    m, k = len(meshes), len(surfaces)
    faces = [len(x.faces) for x in meshes]
    for x in meshes:
        for s in surfaces:
            cap = cap_mesh(s, bounds(x.vertices), subdivision=subdivision)
            faces.append(0 if cap is None else len(cap.faces))
    return {"prim_id": (-1, max(faces) - 1), "object_id": (-1, m + m * k - 1)}


def _clip_decision_may(draws, camera, clip, cap_mask):
    """Pixels where the clip decision ``g(P) ≥ 0`` may go either way on a conformant GPU.

    A sample moved by the edge ε (pixels) moves ``P`` by ``ε · s`` in the world (``s``: world
    size of a pixel at the fragment's eye depth) and ``g`` by up to ``|∇g| · ε · s``; ``∇g`` is
    taken by central differences of ``g`` itself (offset-map slopes included). So the decision
    ``g / (|∇g| · s)`` in pixels is compared with 1.5 ε. Caps lie on the surface's zero set and
    their triangles are not among the scene's draws: every cap pixel's id may differ (their
    coverage follows the solid's inside test, whose boundary is the same decision boundary).
    """
    from .. import draw, resolve
    from ..camera import is_perspective
    from ..clipsurface import clip_function
    from ..conformance import decision_may, edge_epsilon
    from .allowances.precision import candidate_bits
    from .allowances.core import dilate
    frags = draw([d.mesh for d in draws], **camera.kwargs, model=[d.model for d in draws])
    pos = frags.world_position()
    g = clip_function(pos, clip)
    h = 1e-4 * max(1.0, float(np.abs(pos).max()))
    grad = np.stack([(clip_function(pos + h * e, clip) - clip_function(pos - h * e, clip))
                     / (2 * h) for e in np.eye(3)], axis=1)
    proj = camera.proj
    if is_perspective(proj):
        pixel = -frags.eye_position()[:, 2] * 2.0 / (proj[1, 1] * camera.height)
    else:
        pixel = np.full(len(frags), 2.0 / (proj[1, 1] * camera.height))
    scale = np.maximum(np.linalg.norm(grad, axis=1) * pixel, 1e-12)
    eps = edge_epsilon(camera.width, camera.height, min_bits=candidate_bits())
    res = resolve(frags, keep=g >= 0)
    return decision_may(frags, res, g / scale, 1.5 * eps) | dilate(cap_mask, 1)


@register_scene("ldi_nested_shells", technique="ldi",
                description="Layered depth image of the nested shells by classic depth peeling "
                            "(Trapp & Döllner Sec. 5.2): per-layer window depth, primitive id "
                            "and facing, stacked along the last axis (layer 0 = nearest), and the "
                            "layer count.")
def _ldi_nested_shells():
    from ..ldi import peel
    from ..scenes import solid
    state = raster_state({})
    draws = prepare_draws([Draw("nested_shells", solid("nested_shells", quick=True))])
    camera = _framed([d.mesh for d in draws], 256, 192, (1.2, 0.9, 1.6))
    params = dict(mode="peel", max_layers=None)
    layers = peel([d.mesh for d in draws], **camera.kwargs, model=[d.model for d in draws],
                  raster=RasterState(cull=state["cull"]), **params)
    buffers = {
        "layer_depth": np.ascontiguousarray(np.moveaxis(layers.depth, 0, -1)),
        "layer_prim_id": np.ascontiguousarray(np.moveaxis(layers.prim_id, 0, -1)),
        "layer_front_facing": np.ascontiguousarray(np.moveaxis(layers.front_facing, 0, -1)),
        "layer_count": np.asarray(layers.count, np.int32),
    }
    # a hidden layer changes wherever any triangle's edge passes (every edge is marked by the
    # technique allowance); the layers' depths are window depths
    # ids: layer_prim_id follows the default convention; a pixel's layer count is at most the
    # number of faces (each face is crossed once by the pixel's ray)
    faces = sum(len(d.mesh.faces) for d in draws)
    return GoldenScene(technique="ldi", camera=camera, draws=draws, buffers=buffers,
                       parameters=params, kinds={"layer_depth": "unorm"}, geometry=False,
                       ids={"layer_count": (0, faces)})


@register_scene("cutaway_shells", technique="cutaway",
                description="Adaptive cutaway (Burns & Finkelstein): the innermost of the nested "
                            "shells as the object of interest inside the outer shells, jump "
                            "flooding variant jfa+1, θ = 1 rad, perspective compensation, edge "
                            "compression 0.1, dilation, outlines and ghost lines (the removed "
                            "shells' silhouettes within g_max = 0.5, faded).")
def _cutaway_shells():
    # θ = 1 rad: wide enough that the cut removes the inner shells' silhouettes, so the ghost
    # buffer is not empty (issue 23); the flooding variants a backend may use: the scene's own,
    # the exact maximum and the schedules at least as good (docs/tolerance.md, "Cutaways").
    # "jfa+1" is stored explicitly (the default until issue 46), so the package is unchanged;
    # the paper's "jfa", Cutaway's default, is cutaway_shells_jfa
    return _cutaway_variant_scene("jfa+1")


@register_scene("halos4d_figure1", technique="halos4d",
                description="Volumetric halos for surfaces in 4D (Wang et al., Fig. 1): a white "
                            "square patch at w = 0 crossed by five coloured patches at w = 0.1 … "
                            "0.5, turned in the zx and yz planes, 48 slices, composited colour, "
                            "accumulated opacity and each pixel's halo class (carved, surface, halo "
                            "only). The 4D surface travels as maps (vertices (V, 4), "
                            "faces, per-vertex tangents and colours), the rotation as a parameter.")
def _halos4d_figure1():
    return _halos4d_patches("orthographic")


#: A halos4d scene's stored parameter → (option of :func:`refraster.halos4d.render_halos`,
#: field of its value or None for a plain keyword). ``stereo``/``stereo_angle`` are one field.
HALO_FIELDS = {
    "rotation": ("view", "rotation"), "projection": ("view", "projection"),
    "eye": ("view", "eye"), "scale": ("view", "scale"), "margin": ("view", "margin"),
    "halos": ("halos", "enabled"), "rho": ("halos", "rho"), "delta_d": ("halos", "delta_d"),
    "delta_t": ("halos", "delta_t"), "surface_width": ("halos", "surface_width"),
    "antialias": ("halos", "antialias"), "depth_eps": ("halos", "depth_eps"),
    "split": ("halos", "split"),
    "opacity": ("style", "opacity"), "ambient": ("style", "ambient"),
    "halo_color": ("style", "halo_color"), "halo_opacity": ("style", "halo_opacity"),
    "boundary_color": ("style", "boundary_color"),
    "boundary_width": ("style", "boundary_width"),
    "width": ("width", None), "height": ("height", None), "slices": ("slices", None),
    "background": ("background", None)}


def halo_options(parameters):
    """The options of :func:`refraster.halos4d.render_halos` that a halos4d scene's stored
    parameters name (``scene.json``'s ``"parameters"``, flat: :data:`HALO_FIELDS`), as keyword
    arguments: the ``view``, ``halos`` and ``style`` values and ``width``, ``height``,
    ``slices``, ``background``. A field not stored keeps its default; other parameters
    (``screen_bounds``, an output) are not options."""
    from ..halos4d import STEREO_ANGLE, HaloStyle, Halos, View4D
    fields = {"view": {}, "halos": {}, "style": {}}
    plain = {}
    for key, (option, name) in HALO_FIELDS.items():
        if key in parameters:
            if name is None:
                plain[option] = parameters[key]
            else:
                fields[option][name] = parameters[key]
    if parameters.get("stereo"):
        fields["view"]["stereo"] = parameters.get("stereo_angle", STEREO_ANGLE)
    return dict(view=View4D(**fields["view"]), halos=Halos(**fields["halos"]),
                style=HaloStyle(**fields["style"]), **plain)


def _halos4d_patches(projection):
    """The Fig. 1 patches (``halos4d_figure1``) under the given 4D → 3D projection."""
    from ..camera import orthographic
    from ..halos4d import compose, figure1_scene, render_halos
    surface = figure1_scene(n=12)
    rot = compose(("zx", 0.5), ("yz", -1.0))
    params = dict(rotation=rot.tolist(), projection=projection, slices=48, delta_t=0.3,
                  surface_width=0.3, opacity=0.9, halos=True, margin=0.05, width=128,
                  height=128, background=[0.0, 0.0, 0.0], split="paper")
    out = render_halos(surface, **halo_options(params), volume=True)
    params["rho"] = float(out.stats["rho"])
    # the defaults the reference derived (issue 21), so a backend can use the same values
    params.update(delta_d=float(out.stats["delta_d"]), antialias=float(out.stats["antialias"]),
                  halo_opacity=0.0)
    params["screen_bounds"] = np.asarray(out.bounds).tolist()
    # per pixel, the halo class of its column: 2 if a halo carved some surface voxel, else 1 if a
    # surface voxel is drawn, else 3 if only halo voxels, else 0 (empty)
    vol = np.asarray(out.volume)
    halo_class = np.where((vol == 2).any(axis=0), 2, np.where(
        (vol == 1).any(axis=0), 1, np.where((vol == 3).any(axis=0), 3, 0))).astype(np.int32)
    camera = Camera(np.eye(4), orthographic(-1, 1, -1, 1, -1, 1), 128, 128)
    # slicing moves a surface's boundary by up to a slice spacing: every pixel where the
    # opacity changes between neighbours may differ
    edge = changes(np.asarray(out.alpha, np.float64), 0.02)
    maps = {"surface_vertices4d": surface.vertices, "surface_faces": surface.faces,
            "surface_tangents": surface.tangents.reshape(len(surface.vertices), 8),
            "surface_colors": surface.colors}
    return GoldenScene(technique="halos4d", camera=camera, draws=[],
                       buffers={"color": np.asarray(out.image, np.float32),
                                "alpha": np.asarray(out.alpha, np.float32),
                                "halo_class": halo_class},
                       parameters=params, maps=maps, kinds={"alpha": "unorm",
                                                            "halo_class": "id"},
                       ids={"halo_class": (0, 3)},  # the classes above: 0 … 3
                       geometry=False, may=edge, may_radius=1)


@register_scene("clipsurface_textured_caps", technique="clipsurface",
                description="Cube cut by a tilted 2.5D clip surface (Perlin offset map) whose "
                            "caps carry the user's diffuse, normal and light texture maps "
                            "(Trapp & Döllner Sec. 4.1, Fig. 10): each map is addressed with "
                            "the surface's (s, t) = ((P − O)·Û/|U|·Sx, (P − O)·V̂/|V|·Sy), "
                            "GL_LINEAR, mirrored_repeat; the normal map is tangent-space "
                            "n = 2c − 1 along (Û, V̂, −N).")
def _clipsurface_textured_caps():
    from ..clipsurface import ClipSurface, render_clipped
    from ..clipsurface.textures import CapTextures
    from ..clipsurface.offsetmaps import perlin_noise
    from ..scenes import solid
    state = raster_state({})
    draws = prepare_draws([Draw("cube", solid("cube"))])
    camera = _framed([d.mesh for d in draws], 160, 120, (0.9, 1.1, 1.5))
    lo, hi = draws[0].mesh.vertices.min(axis=0), draws[0].mesh.vertices.max(axis=0)
    c = (lo + hi) / 2
    offset_map = perlin_noise((32, 32), cells=4, seed=2)
    # a diffuse map whose every texel differs from its neighbours (a GPU's wrong texel or
    # half-texel shift shows), a bumpy normal map and a striped light map, all of their own
    # resolutions
    r, k = np.mgrid[0:16, 0:24]
    diffuse = np.stack([(k % 6) / 5.0, (r % 4) / 3.0, ((r + 2 * k) % 5) / 4.0], -1) * 0.7 + 0.3
    a, b = np.mgrid[0:32, 0:32] / 32.0 * 2 * np.pi
    nx, ny = 0.4 * np.sin(2 * a), 0.4 * np.cos(3 * b)
    n = np.stack([nx, ny, np.ones_like(nx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    normal = 0.5 * n + 0.5
    light = 0.6 + 0.4 * (np.mgrid[0:8, 0:8][1] % 2)
    textures = CapTextures(diffuse=diffuse, normal=normal, light=light)
    size = float(np.linalg.norm(hi - lo))
    u = np.array([1.0, 0.0, 0.3]) / np.linalg.norm([1.0, 0.0, 0.3]) * size
    v = np.cross([0.3, 0.4, -1.0], u)
    v = v / np.linalg.norm(v) * size
    surface = dict(origin=(c + [0.0, 0.0, 0.1]).tolist(), u=u.tolist(), v=v.tolist(),
                   scale=[1.5, 1.5, 0.25], wrap="mirrored_repeat", enabled=True)
    caps = dict(caps=True, cap_style="diffuse", cap_mode="mesh", cap_color=[0.8, 0.3, 0.25],
                subdivision=1, vds_resolution=256, space="world")
    clip = ClipSurface(surface["origin"], surface["u"], surface["v"], surface["scale"],
                       offset_map, wrap=surface["wrap"], textures=textures)
    fb = render_clipped([d.mesh for d in draws], clip, **camera.kwargs,
                        caps=clip_caps(caps), space=caps["space"],
                        raster=RasterState(cull=state["cull"], precision=state["precision"]))
    # one map per channel (the package's maps are single-channel images); texel order, row 0
    # at t = 0, values in [0, 1] (the normal map encoded as 2n − 1 = c)
    maps = {"offset_map": offset_map, "cap_light": textures.light[..., 0]}
    names = {"light": ["cap_light"]}
    for key, arr, chans in (("diffuse", textures.diffuse, "rgb"),
                            ("normal", textures.normal, "xyz")):
        names[key] = [f"cap_{key}_{ch}" for ch in chans]
        for i, name in enumerate(names[key]):
            maps[name] = np.ascontiguousarray(arr[..., i])
    surfaces = [{**surface, "offset_map": "offset_map", "textures": names}]
    backend_params, backend_maps = clip_export(draws, [clip], caps, surfaces)
    return GoldenScene(technique="clipsurface", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "cap_mask": fb.cap_mask},
                       parameters={"surfaces": surfaces, **caps, **backend_params},
                       maps={**maps, **backend_maps}, geometry=False,
                       ids=_clip_ids(draws, [clip], caps.get("subdivision", 1)),
                       may=_clip_decision_may(draws, camera, clip, fb.cap_mask))


def _tilted_grid(n, half, rx, ry):
    """A square grid (n × n quads, side 2·half) through the origin, turned by rx about x and
    then ry about y (degrees): vertices (V, 3), faces (F, 3), CCW seen from +z before turning."""
    a = np.linspace(-half, half, n + 1)
    x, y = np.meshgrid(a, a)
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    cx, sx = np.cos(np.radians(rx)), np.sin(np.radians(rx))
    cy, sy = np.cos(np.radians(ry)), np.sin(np.radians(ry))
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    v = v @ (rot_y @ rot_x).T
    i = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    faces = np.concatenate([np.stack([i, i + 1, i + n + 2], 1),
                            np.stack([i, i + n + 2, i + n + 1], 1)])
    return v, faces


@register_scene("vds_parity_building", technique="vds",
                description="Volumetric parity test (Trapp & Döllner Sec. 5.3, MATH.md §2.2): "
                            "a tilted plane through the building; per pixel, whether the "
                            "plane's visible point is inside the building by the parity test "
                            "over its volumetric depth sprite (128², axis z, margin 2 texels), "
                            "which the package exports as maps (one per layer, and the counts).")
def _vds_parity_building():
    from .. import draw, resolve
    from ..camera import is_perspective
    from ..ldi import VolumetricDepthSprite
    from ..scenes import solid
    from ..conformance import edge_epsilon
    from .allowances.precision import candidate_bits
    state = raster_state({})
    building = solid("building")
    resolution, axis, margin = 128, "z", 2
    vds = VolumetricDepthSprite.from_mesh(building, resolution, axis=axis, margin=margin)
    ldi = vds._ldis[0]
    lo, hi = building.vertices.min(axis=0), building.vertices.max(axis=0)
    centre = np.eye(4)
    centre[:3, 3] = (lo + hi) / 2
    draws = prepare_draws([Draw("plane", _tilted_grid(16, 0.6 * float((hi - lo).max()), 25.0,
                                                      -20.0), centre)])
    corners = (centre[:3, :3] @ draws[0].mesh.vertices.T).T + centre[:3, 3]
    camera = _framed([type(draws[0].mesh)(corners, draws[0].mesh.faces)], 160, 120,
                     (0.3, 0.5, 1.4), margin=0.6)
    fb = render_draws(draws, camera, state)
    frags = draw([d.mesh for d in draws], **camera.kwargs, model=[d.model for d in draws])
    res = resolve(frags)
    winner = res.winner.ravel()
    covered = winner >= 0
    pos = frags.world_position()[winner[covered]]
    inside = np.zeros(winner.shape, np.bool_)
    inside[covered] = vds.contains(pos)
    inside = inside.reshape(camera.height, camera.width)
    if not np.array_equal(res.winner >= 0, fb.prim_id >= 0):
        raise AssertionError("draw/resolve and render disagree on coverage")
    # the decision may flip where moving the sample by 1.5 ε pixels (ε·s world units, s the
    # world size of a pixel at the fragment) crosses a texel border or a layer depth of the
    # sprite: the sprite's axes are the world's (axis z), so six axis probes find every such
    # crossing within that distance
    proj = camera.proj
    eye_z = -frags.eye_position()[winner[covered], 2]
    pixel = (eye_z if is_perspective(proj) else 1.0) * 2.0 / (proj[1, 1] * camera.height)
    delta = 1.5 * edge_epsilon(camera.width, camera.height,
                               min_bits=candidate_bits()) * pixel + 1e-6
    centre = inside.ravel()[covered]
    flip = np.zeros(len(pos), np.bool_)
    for e in np.eye(3):
        for sign in (-1.0, 1.0):
            flip |= vds.contains(pos + sign * delta[:, None] * e) != centre
    may = np.zeros(winner.shape, np.bool_)
    may[np.flatnonzero(covered)[flip]] = True
    depth = np.where(ldi.sign != 0, ldi.depth, np.float32(1.0)).astype(np.float32)
    maps = {f"sprite_depth_{k}": np.ascontiguousarray(depth[k]) for k in range(len(depth))}
    maps["sprite_count"] = np.asarray(ldi.count, np.int32)
    params = dict(test="parity", resolution=resolution, axis=axis, margin=margin,
                  sprite_matrix=np.asarray(ldi.matrix, np.float64).tolist(),
                  layers=len(depth), sprite_depth=[f"sprite_depth_{k}" for k in range(len(depth))],
                  sprite_count="sprite_count")
    return GoldenScene(technique="vds", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "inside": inside}, parameters=params,
                       maps=maps, may=may.reshape(camera.height, camera.width), may_radius=0)


# --- clip-surface scenes for options that had none (issue 26 item 5) ------------------------

def _clip_decision_may_multi(draws, camera, clips, cap_mask):
    """:func:`_clip_decision_may` for K surfaces: a solid fragment is kept iff every enabled
    surface has ``g_k ≥ 0``, so its decision distance in pixels is ``min_k g_k / (|∇g_k|·s)``
    (each term as the one-surface function; for K = 1 the two are the same)."""
    from .. import draw, resolve
    from ..camera import is_perspective
    from ..clipsurface import clip_function
    from ..conformance import decision_may, edge_epsilon
    from .allowances.precision import candidate_bits
    from .allowances.core import dilate
    frags = draw([d.mesh for d in draws], **camera.kwargs, model=[d.model for d in draws])
    pos = frags.world_position()
    proj = camera.proj
    # |proj[1, 1]|: an equivalent camera of NDC y down has it negated (_equivalent_camera)
    if is_perspective(proj):
        pixel = -frags.eye_position()[:, 2] * 2.0 / (abs(proj[1, 1]) * camera.height)
    else:
        pixel = np.full(len(frags), 2.0 / (abs(proj[1, 1]) * camera.height))
    h = 1e-4 * max(1.0, float(np.abs(pos).max()))
    dist = np.full(len(frags), np.inf)
    for clip in clips:
        if not clip.enabled:
            continue
        g = clip_function(pos, clip)
        grad = np.stack([(clip_function(pos + h * e, clip) - clip_function(pos - h * e, clip))
                         / (2 * h) for e in np.eye(3)], axis=1)
        dist = np.minimum(dist, g / np.maximum(np.linalg.norm(grad, axis=1) * pixel, 1e-12))
    eps = edge_epsilon(camera.width, camera.height, min_bits=candidate_bits())
    res = resolve(frags, keep=dist >= 0)
    return decision_may(frags, res, dist, 1.5 * eps) | dilate(cap_mask, 1)


def _clip_scene(draws, camera, surfaces, clips, maps, caps, extra=None):
    """A clip-surface GoldenScene rendered by ``render_clipped`` with everything a backend
    needs exported (:func:`_clip_backend_export`)."""
    from ..clipsurface import render_clipped
    state = raster_state({})
    fb = render_clipped([d.mesh for d in draws], clips, **camera.kwargs,
                        caps=clip_caps(caps), space=caps["space"],
                        raster=RasterState(cull=state["cull"], precision=state["precision"]))
    backend_params, backend_maps = clip_export(draws, clips, caps, surfaces)
    return GoldenScene(technique="clipsurface", camera=camera, draws=draws,
                       buffers={**fb.arrays(), "cap_mask": fb.cap_mask},
                       ids=_clip_ids(draws, clips, caps["subdivision"]),
                       parameters={"surfaces": surfaces, **caps, **backend_params,
                                   **(extra or {})},
                       maps={**maps, **backend_maps}, geometry=False,
                       may=_clip_decision_may_multi(draws, camera, clips, fb.cap_mask))


@register_scene("clipsurface_two_surfaces", technique="clipsurface",
                description="Building cut by two 2.5D clip surfaces at once (Trapp & Döllner "
                            "Sec. 4: several surfaces, each with its own offset map and wrap "
                            "mode): a Perlin cut of the top (N = −z, repeat) and a sinusoidal "
                            "cut of the side (N = −x, mirrored_repeat); each surface's caps are "
                            "clipped by the other surface.")
def _clipsurface_two_surfaces():
    from ..clipsurface import ClipSurface
    from ..clipsurface.offsetmaps import perlin_noise, sinusoid
    from ..scenes import solid
    draws = prepare_draws([Draw("building", solid("building"))])
    camera = _framed([d.mesh for d in draws], 160, 120, (1.2, 0.9, 1.6))
    top = perlin_noise((48, 48), seed=3)
    side = sinusoid((32, 32), periods=(3, 2))
    specs = [dict(origin=[0.0, 0.0, 4.0], u=[0.0, 6.25, 0.0], v=[10.0, 0.0, 0.0],
                  scale=[1.0, 1.0, 0.8], wrap="repeat", enabled=True),
             dict(origin=[7.0, 0.0, 0.0], u=[0.0, 0.0, 7.0], v=[0.0, 6.25, 0.0],
                  scale=[1.5, 1.0, 1.0], wrap="mirrored_repeat", enabled=True)]
    maps = {"offset_map_top": top, "offset_map_side": side}
    clips = [ClipSurface(s["origin"], s["u"], s["v"], s["scale"], om, wrap=s["wrap"])
             for s, om in zip(specs, (top, side))]
    surfaces = [{**specs[0], "offset_map": "offset_map_top"},
                {**specs[1], "offset_map": "offset_map_side"}]
    caps = dict(caps=True, cap_style="diffuse", cap_mode="mesh", cap_color=[0.8, 0.3, 0.25],
                subdivision=1, vds_resolution=512, space="world")
    return _clip_scene(draws, camera, surfaces, clips, maps, caps)


@register_scene("clipsurface_relief_plane", technique="clipsurface",
                description="Cube cut by a relief clip plane (Trapp & Döllner, RCP poster; "
                            "MATH.md D8): RCP = (N, P, OM, s) discards N·(X − P) − s·h > 0; the "
                            "package gives it as its equivalent clip surface (O = P, "
                            "N_CS = −N, Sz = s, |U| = |V| = extent) beside the RCP's own "
                            "parameters; offset map wrapped with clamp (to edge).")
def _clipsurface_relief_plane():
    from ..clipsurface import ReliefClipPlane
    from ..clipsurface.offsetmaps import perlin_noise
    from ..scenes import solid
    draws = prepare_draws([Draw("cube", solid("cube"))])
    camera = _framed([d.mesh for d in draws], 160, 120, (0.9, 1.1, 1.5))
    om = perlin_noise((32, 32), cells=4, seed=5)
    rcp = dict(normal=[0.6, 0.5, 0.8], point=[0.05, 0.05, 0.1], height_scale=0.2,
               u=[1.0, 0.0, 0.0], extent=1.2, wrap="clamp_to_edge")
    plane = ReliefClipPlane(rcp["normal"], rcp["point"], om, rcp["height_scale"], rcp["u"],
                            extent=rcp["extent"], wrap=rcp["wrap"])
    cs = plane.clip_surface
    surfaces = [dict(origin=cs.origin.tolist(), u=cs.u.tolist(), v=cs.v.tolist(),
                     scale=[float(x) for x in cs.scale], wrap=cs.wrap, enabled=True,
                     offset_map="offset_map")]
    caps = dict(caps=True, cap_style="diffuse", cap_mode="mesh", cap_color=[0.8, 0.3, 0.25],
                subdivision=1, vds_resolution=256, space="world")
    return _clip_scene(draws, camera, surfaces, [cs], {"offset_map": om}, caps,
                       extra={"relief_clip_plane": rcp})


# --- issue 26, item 5: scenes for options that had none (a GPU backend's proof needs them) ---

_VARIANT_ACCEPTS = {"jfa": ["jfa", "jfa+1", "jfa+2", "1+jfa", "exact"],
                    "jfa+1": ["jfa+1", "jfa+2", "1+jfa", "exact"],
                    "jfa+2": ["jfa+2", "exact"], "1+jfa": ["1+jfa", "jfa+2", "exact"]}


#: A cutaway scene's stored parameter → (option of :func:`refraster.cutaway.render_cutaway`,
#: field of its value).
CUTAWAY_FIELDS = {
    "angle": ("cutaway", "angle"), "variant": ("cutaway", "variant"),
    "perspective_compensation": ("cutaway", "perspective_compensation"),
    "edge_compression": ("cutaway", "edge_compression"),
    "floor_normal": ("cutaway", "floor_normal"), "floor_margin": ("cutaway", "floor_margin"),
    "cutaway_size": ("cutaway", "buffer_size"),
    "cut_surfaces": ("cut_surfaces", "shade"), "cut_color": ("cut_surfaces", "color"),
    "dilation": ("cut_surfaces", "dilation"), "outlines": ("cut_surfaces", "outlines"),
    "ghost": ("ghosts", "source"), "ghost_distance": ("ghosts", "distance"),
    "ghost_fade": ("ghosts", "fade"), "crease_angle": ("ghosts", "crease_angle")}


def cutaway_options(parameters):
    """The options of :func:`refraster.cutaway.render_cutaway` that a cutaway scene's stored
    parameters name (``scene.json``'s ``"parameters"``, flat: :data:`CUTAWAY_FIELDS`), as
    ``dict(cutaway=, cut_surfaces=, ghosts=)`` values. A field not stored keeps its default; a
    stored ``ghost_distance`` of 0 means no ghost lines (``ghosts=None``); other parameters
    (``interest``, ``accepted_variants``, …) are not options."""
    from ..cutaway import CutSurfaces, Cutaway, GhostLines
    fields = {"cutaway": {}, "cut_surfaces": {}, "ghosts": {}}
    for key, (option, name) in CUTAWAY_FIELDS.items():
        if key in parameters:
            fields[option][name] = parameters[key]
    size = fields["cutaway"].get("buffer_size")
    if size is not None:
        fields["cutaway"]["buffer_size"] = tuple(size)    # JSON stores the pair as a list
    ghosts = fields["ghosts"]
    return dict(cutaway=Cutaway(**fields["cutaway"]),
                cut_surfaces=CutSurfaces(**fields["cut_surfaces"]),
                ghosts=None if ghosts.get("distance") == 0 else GhostLines(**ghosts))


def _cutaway_variant_scene(variant, extra=None):
    """``cutaway_shells`` with another jump-flooding schedule (the same camera and options);
    ``extra``: further stored options of :func:`refraster.cutaway.render_cutaway` (the floor:
    :func:`cutaway_options` names)."""
    from ..scenes import icosphere, solid
    outer = solid("nested_shells", quick=True)
    inner = icosphere(subdivisions=2, radius=0.3)
    draws = prepare_draws([Draw("outer_shells", outer), Draw("interest", inner)])
    camera = _framed([d.mesh for d in draws], 96, 72, (1.2, 0.9, 1.6))
    params = dict(angle=1.0, variant=variant, perspective_compensation=True,
                  edge_compression=0.1, dilation=True, outlines=True, ghost="lines",
                  ghost_distance=0.5, ghost_fade=True, crease_angle=30.0,
                  interest=["interest"], secondary=["outer_shells"],
                  accepted_variants=list(_VARIANT_ACCEPTS[variant]))
    params.update(extra or {})
    return _cutaway_golden(draws, [draws[1].mesh], [draws[0].mesh], camera, params)


def _cutaway_golden(draws, interest, secondary, camera, params, raster=None):
    """The cutaway GoldenScene of ``params`` (:func:`cutaway_options`) rendered by
    ``render_cutaway`` with ``camera`` and ``raster`` (None: the default state)."""
    from ..cutaway import render_cutaway
    kw = {} if raster is None else {"raster": raster}
    fb = render_cutaway(interest, secondary, **camera.kwargs, **cutaway_options(params), **kw)
    buffers = {**fb.arrays(), "cutaway_depth": fb.cutaway_depth, "cut_mask": fb.cut_mask,
               "ghost": fb.ghost}
    # the cut decision z < D(x) is free within a pixel of where the cut region changes
    edge = changes(np.asarray(fb.cut_mask, np.bool_))
    edge |= fb.ghost > 0        # a line's pixels depend on the line rasterizer
    return GoldenScene(technique="cutaway", camera=camera, draws=draws, buffers=buffers,
                       parameters=params, kinds={"cutaway_depth": "unorm", "ghost": "unorm"},
                       geometry=False, may=edge, may_radius=2)


@register_scene("cutaway_shells_jfa", technique="cutaway",
                description="cutaway_shells with the plain jump-flooding schedule n/2 … 1 "
                            "(Rong & Tan), variant 'jfa'.")
def _cutaway_shells_jfa():
    return _cutaway_variant_scene("jfa")


@register_scene("cutaway_shells_jfa2", technique="cutaway",
                description="cutaway_shells with the schedule n/2 … 1, 2, 1 (variant 'jfa+2').")
def _cutaway_shells_jfa2():
    return _cutaway_variant_scene("jfa+2")


@register_scene("cutaway_shells_1jfa", technique="cutaway",
                description="cutaway_shells with the schedule 1, n/2 … 1 (variant '1+jfa').")
def _cutaway_shells_1jfa():
    return _cutaway_variant_scene("1+jfa")


@register_scene("cutaway_floor", technique="cutaway",
                description="cutaway_shells (jfa+1) with the directional floor constraint "
                            "(Burns & Finkelstein Sec. 5.5, D-C7): floor normal +y, safety angle "
                            "δ = 2°; on the floor side the cut's angle is clamped to φ − δ "
                            "(φ: the view vector's elevation above the floor).")
def _cutaway_floor():
    # "jfa+1" stored explicitly, as cutaway_shells; the paper's "jfa" is cutaway_floor_jfa
    return _cutaway_variant_scene("jfa+1", dict(floor_normal=[0.0, 1.0, 0.0],
                                                floor_margin=float(np.radians(2.0))))


@register_scene("cutaway_floor_jfa", technique="cutaway",
                description="cutaway_floor with the paper's jump flooding, variant 'jfa' "
                            "(Rong & Tan, log n passes; the default of Cutaway): the directional "
                            "floor constraint, floor normal +y, δ = 2°.")
def _cutaway_floor_jfa():
    return _cutaway_variant_scene("jfa", dict(floor_normal=[0.0, 1.0, 0.0],
                                              floor_margin=float(np.radians(2.0))))


@register_scene("halos4d_perspective", technique="halos4d",
                description="The Fig. 1 patches of halos4d_figure1 under the perspective 4D → 3D "
                            "projection (eye on the w axis at 3·max|v|, MATH.md §5.2), 48 slices.")
def _halos4d_perspective():
    return _halos4d_patches("perspective")


# --- technique scenes in another API's conventions (golden generate --convention) -----------

def _equivalent_camera(camera, raster):
    """The camera whose OpenGL-convention frame draws the picture ``camera`` draws under
    ``raster``'s conventions (:func:`refraster.golden.allowances.conventions.clip_map`): the
    technique's own "may" pixels are derived on it, in OpenGL's conventions."""
    from .allowances.conventions import clip_map
    return Camera(camera.view, clip_map(raster) @ np.asarray(camera.proj, np.float64),
                  camera.width, camera.height)


def _scene_clips(scene):
    """The clip surfaces a clip-surface scene stores (``parameters["surfaces"]`` and its maps,
    cap textures included), as :func:`refraster.clipsurface.render_clipped` takes them."""
    from ..clipsurface import ClipSurface
    from ..clipsurface.textures import CapTextures
    out = []
    for s in scene.parameters["surfaces"]:
        om = scene.maps[s["offset_map"]] if s.get("offset_map") else None
        textures = None
        names = s.get("textures")
        if names:
            kw = {}
            for key, chans in names.items():
                arrs = [np.asarray(scene.maps[n]) for n in chans]
                kw[key] = arrs[0] if len(arrs) == 1 else np.stack(arrs, axis=-1)
            textures = CapTextures(**kw)
        out.append(ClipSurface(s["origin"], s["u"], s["v"], s["scale"], om,
                               wrap=s.get("wrap", "repeat"), textures=textures))
    return out


def clipsurface_in_raster(scene, camera, raster):
    """The clip-surface ``scene`` (built) rendered again by
    :func:`refraster.clipsurface.render_clipped` with ``camera`` and the complete raster
    fields ``raster`` (another API's conventions): the same surfaces, caps and exported maps,
    the buffers, cap mask and decision "may" pixels of the new frame (the latter derived on
    its OpenGL equivalent, :func:`_equivalent_camera`)."""
    from ..clipsurface import render_clipped
    from .scenes import as_state
    if int(raster.get("samples", 1)) > 1:
        raise ValueError("a multisampled clip-surface scene is derived in OpenGL's conventions "
                         "only (its per-sample allowances are)")
    params = scene.parameters
    clips = _scene_clips(scene)
    fb = render_clipped([d.mesh for d in scene.draws], clips, **camera.kwargs,
                        caps=clip_caps(params), space=params["space"], raster=as_state(raster))
    may = _clip_decision_may_multi(scene.draws, _equivalent_camera(camera, raster), clips,
                                   fb.cap_mask)
    return GoldenScene(technique="clipsurface", camera=camera, draws=scene.draws,
                       buffers={**fb.arrays(), "cap_mask": fb.cap_mask}, ids=scene.ids,
                       parameters=params, maps=scene.maps, geometry=False, may=may)


def cutaway_in_raster(scene, camera, raster):
    """The cutaway ``scene`` (built) rendered again by :func:`refraster.cutaway.render_cutaway`
    with ``camera`` and the complete raster fields ``raster`` (another API's conventions): the
    same options (:func:`cutaway_options`), the buffers and "may" pixels of the new frame."""
    from .scenes import as_state
    named = {d.name: d.mesh for d in scene.draws}
    params = scene.parameters
    return _cutaway_golden(scene.draws, [named[n] for n in params["interest"]],
                           [named[n] for n in params["secondary"]], camera, params,
                           as_state(raster))


#: Technique → how its built scene is rendered again in other conventions
#: (``(scene, camera, raster) → GoldenScene``); :func:`refraster.golden.conventions.in_convention`.
IN_RASTER = {"clipsurface": clipsurface_in_raster, "cutaway": cutaway_in_raster}
