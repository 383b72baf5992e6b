"""Each graphics API's conventions as raster fields, and a scene moved into them.

``refraster golden generate --convention API`` renders a scene as that API draws it
(``docs/backends.md``, "Conventions"): the raster fields of :data:`API_CONVENTIONS`, the
projection converted to the API's clip depth (:func:`convert_projection`) and, where the API's
NDC y points down (Vulkan), the front winding flipped (:func:`convention_overrides`).

The projection's conversion is exact in intent and written down: a ``[−1, 1]`` clip depth
becomes ``[0, 1]`` by ``z' = ½·z + ½·w`` (third row ``½·row₂ + ½·row₃``), back by
``z = 2·z' − w``; window depth is the same function of the eye position in both (OpenGL's
``½·z/w + ½`` is the other's ``z'/w``), so the depth test, the clear depth and reversed-Z
carry over unchanged. x and y are left alone: under ``ndc_y="down"`` the picture is mirrored
top to bottom (what a Vulkan application sees with an OpenGL projection), every face's
winding as seen is reversed, and ``front_face`` flips (``ccw`` ↔ ``cw``) so that the same
faces are front and culled.
"""

from __future__ import annotations

import numpy as np

from ..raster.state import DEPTH_RANGES

__all__ = ["API_CONVENTIONS", "convert_projection", "convention_overrides",
           "TECHNIQUES_IN_CONVENTIONS", "REFUSED", "SAMPLED", "in_convention"]

#: API → the raster fields that API's conventions set (the rest stay the scene's own). The
#: fill rule: Direct3D's top-left rule is exact; Vulkan, Metal and WebGPU leave ties to the
#: implementation (a golden takes them as "may"), so the scene's own rule stays.
API_CONVENTIONS = {
    "gl": dict(depth_range="negative_one_to_one", origin="lower_left", ndc_y="up"),
    "vulkan": dict(depth_range="zero_to_one", origin="upper_left", ndc_y="down"),
    "d3d12": dict(depth_range="zero_to_one", origin="upper_left", ndc_y="up",
                  fill_rule="top_left"),
    "metal": dict(depth_range="zero_to_one", origin="upper_left", ndc_y="up"),
    "webgpu": dict(depth_range="zero_to_one", origin="upper_left", ndc_y="up"),
}

#: Techniques whose scenes can be re-rendered in any convention: plain rendering (the scene's
#: draws rendered again) and the techniques that rasterize through the raster state and whose
#: built scene carries every option to run them again
#: (:data:`refraster.golden.technique_scenes.IN_RASTER`: clip surfaces, cutaways). A scene of
#: another technique is refused, naming the scene and why (:data:`REFUSED`).
TECHNIQUES_IN_CONVENTIONS = ("render", "clipsurface", "cutaway")
#: Technique → why ``--convention`` refuses its scenes.
REFUSED = {
    "ldi": "the peel is not run again from the built scene with the converted camera and "
           "raster state, so its layers and their face sets would stay OpenGL's (the "
           "reversed-Z peel golden is 'reversed_z_peel')",
    "edges": "the edge operators read OpenGL's window depth and their allowances are "
             "derived on it",
    "vds": "its parity decision's probes are derived in OpenGL's conventions only",
    "halos4d": "it does not rasterize through the raster state (4D slicing into its own "
               "volume)",
    "msaa": "its per-sample allowances are derived in OpenGL's conventions only (depth_func "
            "'less', a float32 depth buffer cleared to 1)",
}
#: Why ``--convention`` refuses a multisampled technique scene (``samples > 1``).
SAMPLED = ("the scene is multisampled (raster.samples > 1): its per-sample pass is not run "
           "again with the converted camera and raster state")


def convert_projection(proj, depth_range, *, source="negative_one_to_one", reversed=False):
    """``proj`` (built for the clip depth ``source``) for the clip depth ``depth_range``.

    ``[−1, 1]`` → ``[0, 1]``: third row ``½·row₂ + ½·row₃``; ``[0, 1]`` → ``[−1, 1]``:
    ``2·row₂ − row₃``; the same range: unchanged. ``reversed=True`` also reverses the depth
    direction (``[−1, 1]``: ``−row₂``; ``[0, 1]``: ``row₃ − row₂``), for a projection built
    the usual way round. Returns a new float64 array."""
    for name, value in (("depth_range", depth_range), ("source", source)):
        if value not in DEPTH_RANGES:
            raise ValueError(f"{name} must be one of {', '.join(DEPTH_RANGES)}; got {value!r}")
    if not isinstance(reversed, (bool, np.bool_)):
        raise TypeError(f"reversed must be a bool, got {type(reversed).__name__}")
    p = np.array(proj, np.float64)
    if p.shape != (4, 4):
        raise ValueError(f"proj must be a 4x4 matrix, got shape {p.shape}")
    z, w = p[2].copy(), p[3].copy()
    if source != depth_range:
        z = 0.5 * z + 0.5 * w if depth_range == "zero_to_one" else 2.0 * z - w
    if reversed:
        z = w - z if depth_range == "zero_to_one" else -z
    p[2] = z
    return p


def convention_overrides(api, raster):
    """The raster fields of ``raster`` (a scene's complete fields) that change when the scene
    is drawn in ``api``'s conventions: :data:`API_CONVENTIONS` and, when the NDC y direction
    changes, ``front_face`` flipped."""
    if api not in API_CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(API_CONVENTIONS)}; got {api!r}")
    out = dict(API_CONVENTIONS[api])
    if out["ndc_y"] != raster.get("ndc_y", "up"):
        out["front_face"] = {"ccw": "cw", "cw": "ccw"}[raster.get("front_face", "ccw")]
    return out


def in_convention(entry, api, *, reversed=False):
    """The scene ``entry`` (a :class:`~refraster.golden.scenes.SceneEntry`) drawn in ``api``'s
    conventions: a new entry of the same name whose build renders the scene, moves its raster
    fields (:func:`convention_overrides`) and its projection (:func:`convert_projection`) into
    the API's and renders it again — a plain scene by its draws, a clip-surface or cutaway
    scene by running its technique with the converted camera and raster state
    (:data:`refraster.golden.technique_scenes.IN_RASTER`). ``reversed=True`` also reverses the
    depth direction (reversed-Z: the projection's depth row, ``less``/``lequal`` →
    ``greater``/``gequal``, clear depth ``c → 1 − c``) of a scene that is not reversed yet. A
    scene that already is in them is returned as built; a technique scene whose technique does
    not honour the conventions (:data:`TECHNIQUES_IN_CONVENTIONS`) is refused with one line
    naming the scene and why."""
    from ..camera import Camera
    from .scenes import DEFAULT_RASTER, SceneEntry, raster_state, render_scene
    if api not in API_CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(API_CONVENTIONS)}; got {api!r}")
    if (api != "gl" or reversed) and entry.technique not in TECHNIQUES_IN_CONVENTIONS:
        _refuse(entry.name, entry.technique, api)
    if (api != "gl" or reversed) and entry.samples > 1:
        _refuse(entry.name, entry.technique, api, why=SAMPLED)

    def build(**params):
        scene = entry.build(**params)
        raster = raster_state(scene.raster)
        changes = {k: v for k, v in convention_overrides(api, raster).items() if raster[k] != v}
        flip = reversed and raster["depth_func"] in _REVERSE
        if flip:
            changes.update(depth_func=_REVERSE[raster["depth_func"]],
                           clear_depth=1.0 - float(raster["clear_depth"]))
        if not changes:
            return scene
        if scene.technique not in TECHNIQUES_IN_CONVENTIONS:
            _refuse(entry.name, scene.technique, api)
        new = {**raster, **changes}
        cam = scene.camera
        proj = convert_projection(cam.proj, new["depth_range"], source=raster["depth_range"],
                                  reversed=bool(flip))
        camera = Camera(cam.view, proj, cam.width, cam.height)
        overrides = {k: v for k, v in new.items() if v != DEFAULT_RASTER[k]}
        if scene.technique == "render":
            out = render_scene(scene.draws, camera, raster=overrides)
        else:
            from .technique_scenes import IN_RASTER
            out = IN_RASTER[scene.technique](scene, camera, new)
            out.raster = overrides
        where = f"{api}'s conventions" + (", reversed-Z" if flip else "")
        out.description = (scene.description or entry.description) + f" In {where}."
        return out

    build.__signature__ = _signature(entry.build)
    return SceneEntry(entry.name, entry.technique, entry.description, build, entry.samples)


#: The depth tests reversed-Z turns the usual ones into.
_REVERSE = {"less": "greater", "lequal": "gequal"}


def _refuse(name, technique, api, why=None):
    if why is None:
        why = REFUSED.get(technique, "its scenes cannot be rendered again from the built scene")
    raise ValueError(f"--convention {api} cannot emit scene {name!r}: technique {technique!r} "
                     f"is not drawn again in other conventions: {why} (--convention emits "
                     f"{', '.join(TECHNIQUES_IN_CONVENTIONS)} scenes)")


def _signature(fn):
    import inspect
    try:
        return inspect.signature(fn)
    except (TypeError, ValueError):
        return None
