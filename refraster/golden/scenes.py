"""The golden scene registry, the plain-rendering scenes and the TOML scene format.

A scene is a name bound to a function that returns a :class:`GoldenScene` (the plain-rendering
scenes take keyword arguments ``width``, ``height`` and any raster field, so that a suite can
sweep them: :func:`refraster.golden.generate.suite`): the draws (meshes
and model matrices), the camera, the raster state, the buffers refraster computed and the
technique parameters. A technique registers its scenes with the :func:`register_scene`
decorator in a module listed in :data:`SCENE_MODULES`::

    from refraster.golden import GoldenScene, register_scene, prepare_draws

    @register_scene("edges_crank", technique="edges", description="C1 + id edges of the crank")
    def _edges_crank():
        draws = prepare_draws([Draw("crank", solid("crank"))])
        ...
        return GoldenScene(technique="edges", camera=cam, draws=draws,
                           buffers={"edge": edge_map}, parameters={"threshold": 0.1})

Every mesh is rounded to float32 (:func:`prepare_draws`) *before* it is rendered, because the
scene package stores float32 PLY vertices: what a GPU backend loads is exactly what refraster
drew.
"""

from __future__ import annotations

import importlib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validate import as_choice, as_float_array, as_matrix
from ..camera import Camera, frame_bounds, look_at, orthographic, perspective
from ..mesh import Mesh, as_mesh, load_mesh_file, vertex_normals
from ..raster.state import RasterState

__all__ = [
    "Draw", "GoldenScene", "SceneEntry", "SCENES", "SCENE_MODULES", "TECHNIQUES",
    "register_scene", "register_technique", "prepare_draws", "render_scene", "available_scenes",
    "load_scene_file", "DEFAULT_RASTER", "CONVENTION_FIELDS", "MULTISAMPLE_DEFAULTS",
]

#: Raster state of every golden unless a scene overrides a field (``scene.json`` "raster").
DEFAULT_RASTER = dict(subpixel_bits=8, fill_rule="llvmpipe", precision="float32", cull="none",
                      depth_func="less", front_face="ccw", clear_depth=1.0, normals="flat",
                      depth_range="negative_one_to_one", origin="lower_left", ndc_y="up",
                      depth_clamp=False, depth_format="float32")
#: The API conventions among the raster fields (:class:`refraster.RasterState`'s names and
#: values; ``docs/architecture.md``, "Conventions"). A manifest's ``parameters.raster`` lists
#: them only where they differ from :data:`DEFAULT_RASTER` (``scene.json`` always has them).
CONVENTION_FIELDS = ("depth_range", "origin", "ndc_y", "depth_clamp", "depth_format")
#: The multisample fields (:class:`refraster.RasterState`'s ``samples``, ``sample_locations``
#: and ``interpolation``; ``docs/multisample.md``) and their single-sample defaults. A scene
#: stores them (``scene.json``'s ``"raster"``) only where it overrides them, so a
#: single-sample package keeps the bytes it had before they existed; user positions are
#: stored as a list of ``[x, y]`` pairs in 1/16 pixel.
MULTISAMPLE_DEFAULTS = dict(samples=1, sample_locations="standard", interpolation="center")

#: Modules imported by :func:`available_scenes`; each registers its scenes on import.
SCENE_MODULES = ("refraster.golden.technique_scenes", "refraster.golden.convention_scenes",
                 "refraster.golden.catalogue_scenes", "refraster.golden.msaa_scenes",
                 "refraster.golden.msaa_technique_scenes", "refraster.golden.msaa_clip_scenes")

_NAME = re.compile(r"^[a-z0-9][a-z0-9_]*$")
#: Longest scene or draw name: a name becomes a directory (``<scene>/``, with ``__<sweep>``
#: and ``__<W>x<H>`` suffixes) or a file (``meshes/<draw>.ply``) name, and file systems stop
#: at 255 bytes.
NAME_MAX = 128


def _control(text):
    return any(ord(c) < 32 or 127 <= ord(c) <= 159 for c in text)


def check_name(name, what):
    """``name`` if it is a scene or draw name (lower-case ``[a-z0-9_]``, at most
    :data:`NAME_MAX` characters, no control character: a trailing newline does not pass);
    else one line naming ``what`` and what is wrong."""
    if not isinstance(name, str):
        raise TypeError(f"{what} must be a string, got {type(name).__name__}")
    if _control(name):
        raise ValueError(f"{what} must not contain control characters, got {name!r}"[:300])
    if len(name) > NAME_MAX:
        raise ValueError(f"{what} must be at most {NAME_MAX} characters (it names "
                         f"directories), got {len(name)}")
    if not _NAME.fullmatch(name):
        raise ValueError(f"{what} must match {_NAME.pattern}, got {name!r}")
    return name


@dataclass(frozen=True)
class Draw:
    """One draw call: a mesh (``(vertices, faces)``, :class:`~refraster.mesh.Mesh` or
    ``trimesh.Trimesh``), its model matrix and, after :func:`prepare_draws`, its vertex
    normals when the scene is smooth-shaded."""

    name: str
    mesh: object
    model: np.ndarray = field(default_factory=lambda: np.eye(4))
    normals: np.ndarray | None = None


@dataclass
class GoldenScene:
    """What a scene function returns.

    Attributes
    ----------
    technique : str
        ``"render"`` for plain rendering, else the technique's module name.
    camera : refraster.camera.Camera
    draws : list of Draw
        From :func:`prepare_draws` (float32-exact vertices).
    buffers : dict of str → ndarray
        ``(H, W)`` or ``(H, W, C)`` arrays, row 0 at the top; the golden.
    parameters : dict
        Every technique parameter, JSON-serialisable.
    raster : dict
        Overrides of :data:`DEFAULT_RASTER`.
    maps : dict of str → ndarray
        Offset maps, textures… exported as ``.npy`` and PNG in the package.
    kinds : dict of str → str
        Buffer kind overrides (see :data:`refraster.golden.io.buffers.KINDS`).
    tolerances : dict
        ``{buffer: {profile: {key: value}}}`` overrides of the default tolerances.
    geometry : bool
        True when the G-buffer channels among ``buffers`` are what
        :func:`refraster.render` makes of ``draws`` (then the geometric allowances of
        :func:`refraster.conformance.tolerance` apply); False for techniques that change
        visibility (a clip surface), whose allowances are dilated instead
        (:mod:`refraster.golden.allowances.core`).
    may : (H, W) bool, optional
        The technique's own "may" pixels, e.g. :func:`refraster.conformance.decision_may` of its
        per-fragment decision.
    may_radius : int
        Pixels the "may" region grows by for technique buffers: their filters' footprint.
    ids : dict of str → (int, int)
        ``{buffer: (smallest, largest)}``: the ids the scene can produce in an ``id`` buffer
        (background −1 included), stored in the manifest for the compare's domain check.
        Default (:func:`id_range`): ``prim_id`` / ``layer_prim_id`` [−1, F − 1] with F the
        largest face count of a draw (ids are face indices within their draw call, as
        :func:`refraster.render` writes them), ``object_id`` [−1, D − 1] with D the draw
        count. A
        technique whose ids follow another convention (caps) states it here.
    """

    technique: str
    camera: Camera
    draws: list
    buffers: dict
    parameters: dict = field(default_factory=dict)
    raster: dict = field(default_factory=dict)
    maps: dict = field(default_factory=dict)
    kinds: dict = field(default_factory=dict)
    tolerances: dict = field(default_factory=dict)
    description: str = ""
    geometry: bool = True
    may: np.ndarray | None = None
    may_radius: int = 1
    ids: dict = field(default_factory=dict)


def _face_count(mesh):
    faces = getattr(mesh, "faces", None)
    if faces is None and isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        faces = mesh[1]
    return int(np.asarray(faces).reshape(-1, 3).shape[0])


def id_range(scene, key):
    """``(smallest, largest)`` id ``scene`` can produce in its ``id`` buffer ``key``: the
    scene's own statement (:attr:`GoldenScene.ids`) or the default convention; ``None`` when
    there is none for that buffer name."""
    if key in scene.ids:
        lo, hi = scene.ids[key]
        return int(lo), int(hi)
    if key in ("prim_id", "layer_prim_id"):
        return -1, max((_face_count(d.mesh) for d in scene.draws), default=0) - 1
    if key in ("object_id", "layer_object_id"):
        return -1, len(scene.draws) - 1
    return None


@dataclass(frozen=True)
class SceneEntry:
    name: str
    technique: str
    description: str
    build: object
    samples: int = 1


#: name → :class:`SceneEntry`, in registration order.
SCENES: dict = {}
#: technique name → ``fn(draws, camera, raster, parameters) -> (buffers, parameters)``, for
#: TOML scenes.
TECHNIQUES: dict = {}


def register_scene(name, *, technique, description="", samples=1):
    """Decorator: register ``fn() -> GoldenScene`` as the golden scene ``name``.

    ``name`` is lower-case ``[a-z0-9_]`` (it becomes a directory name). Registering a name twice
    is an error. ``samples``: the scene's ``raster.samples`` (a technique scene with more than
    one joins the 4× technique matrix of ``docs/backends.md`` without being built).
    """
    check_name(name, "scene name")
    if name in SCENES:
        raise ValueError(f"golden scene {name!r} is already registered")

    def decorator(fn):
        if not callable(fn):
            raise TypeError("register_scene decorates a function returning a GoldenScene")
        SCENES[name] = SceneEntry(name, technique, description, fn, int(samples))
        return fn

    return decorator


def register_technique(name):
    """Decorator: make technique ``name`` available to TOML scenes (``technique = "name"``)."""
    def decorator(fn):
        if name in TECHNIQUES:
            raise ValueError(f"technique {name!r} is already registered")
        TECHNIQUES[name] = fn
        return fn
    return decorator


def available_scenes():
    """Import :data:`SCENE_MODULES` (each registers its scenes) and return the registered scenes
    (name → :class:`SceneEntry`) in a fixed order: this module's scenes, then each of
    :data:`SCENE_MODULES`' in its order, then any other module's, each in registration order —
    the same whichever module a program imported first."""
    for module in SCENE_MODULES:
        importlib.import_module(module)
    rank = {m: i for i, m in enumerate((__name__,) + SCENE_MODULES)}
    order = sorted(SCENES.values(),
                   key=lambda e: rank.get(getattr(e.build, "__module__", None), len(rank)))
    return {e.name: e for e in order}


def _float32_exact(a):
    return np.asarray(a, np.float64).astype(np.float32).astype(np.float64)


def _check_smooth_normals(v, faces, vn, where):
    """Refuse a mesh whose smooth normal is undefined at a vertex of a face that can cover a
    pixel: the normals of the faces around it cancel (a face drawn twice with opposite
    windings, say), so the normal there would be 0 and a GPU's ``normalize`` undefined."""
    f = np.asarray(faces, np.int64)
    if not len(f):
        return
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    used = np.unique(f[area > 0])
    zero = used[~np.any(vn[used] != 0.0, axis=1)]
    if len(zero):
        raise ValueError(f"{where}: the smooth normal of vertex {int(zero[0])} is undefined "
                         f"({len(zero)} vertices): the normals of its faces cancel (a face "
                         "drawn twice with opposite windings?); use normals = \"flat\"")


def prepare_draws(draws, *, normals="flat"):
    """Round each draw's vertices to float32 (the PLY precision) and, for ``"smooth"``,
    compute area-weighted vertex normals of the rounded mesh, also float32-exact.

    Returns a new list of :class:`Draw` whose ``mesh`` is a :class:`~refraster.mesh.Mesh`.
    """
    normals = as_choice(normals, "normals", ("flat", "smooth"))
    out = []
    for i, d in enumerate(draws):
        if not isinstance(d, Draw):
            raise TypeError(f"draws[{i}] must be a Draw, got {type(d).__name__}")
        check_name(d.name, f"draws[{i}].name")
        m = as_mesh(d.mesh, f"draws[{i}].mesh")
        v = _float32_exact(m.vertices)
        vn = _float32_exact(vertex_normals(v, m.faces)) if normals == "smooth" else None
        if vn is not None:
            _check_smooth_normals(v, m.faces, vn, f"draws[{i}].mesh")
        out.append(Draw(d.name, Mesh(v, m.faces), as_matrix(d.model, f"draws[{i}].model"), vn))
    if len({d.name for d in out}) != len(out):
        raise ValueError("draw names must be unique within a scene")
    return out


def raster_state(overrides):
    """:data:`DEFAULT_RASTER` updated with ``overrides`` (unknown keys are an error)."""
    known = set(DEFAULT_RASTER) | set(MULTISAMPLE_DEFAULTS)
    unknown = set(overrides) - known
    if unknown:
        raise ValueError(f"unknown raster fields {sorted(unknown)}; known: {sorted(known)}")
    out = {**DEFAULT_RASTER, **overrides}
    if not isinstance(out.get("sample_locations", "standard"), str):
        out["sample_locations"] = [[int(c) for c in p] for p in out["sample_locations"]]
    return out


def manifest_raster(raster):
    """The raster fields a manifest's ``parameters.raster`` lists: every field of
    :data:`DEFAULT_RASTER` but the :data:`CONVENTION_FIELDS` at their defaults (so a golden in
    OpenGL's conventions keeps the manifest it had before the conventions existed)."""
    return {k: v for k, v in raster.items()
            if k not in CONVENTION_FIELDS or v != DEFAULT_RASTER[k]}


def as_state(raster):
    """The :class:`refraster.RasterState` of a scene's stored raster fields (``scene.json``'s
    ``"raster"``; a field it lacks — a package written before the conventions, a manifest's
    ``parameters.raster`` — takes its :data:`DEFAULT_RASTER` (or :data:`MULTISAMPLE_DEFAULTS`)
    value; the package spells the fill
    rule ``"top_left"``, the state ``"top-left"``)."""
    fields = {k: raster.get(k, v)
              for k, v in {**DEFAULT_RASTER, **MULTISAMPLE_DEFAULTS}.items()}
    fields["fill_rule"] = fields["fill_rule"].replace("_", "-")
    return RasterState(**fields)


def draw_meshes(draws, raster):
    """The meshes of prepared draws, carrying their stored vertex normals under
    ``normals="smooth"`` (the normals of the package, not recomputed)."""
    if raster["normals"] != "smooth":
        return [d.mesh for d in draws]
    return [Mesh(d.mesh.vertices, d.mesh.faces, d.normals) for d in draws]


def render_draws(draws, camera, raster):
    """Render prepared draws with ``raster`` state; returns a :class:`refraster.Framebuffer`."""
    from .. import render
    return render(draw_meshes(draws, raster), **camera.kwargs, model=[d.model for d in draws],
                  raster=as_state(raster))


@register_technique("render")
def _render_technique(draws, camera, raster, parameters):
    if parameters:
        raise ValueError(f"technique 'render' takes no parameters, got {sorted(parameters)}")
    return render_draws(draws, camera, raster).arrays(), {}


def render_scene(draws, camera, *, raster=None, description=""):
    """A plain-rendering :class:`GoldenScene`: prepare ``draws``, render every G-buffer
    channel (:meth:`refraster.Framebuffer.arrays`). ``raster``: a mapping of the raster fields
    that differ from :data:`DEFAULT_RASTER` (``scene.json``'s ``"raster"``; None: none)."""
    if raster is None:
        raster = {}
    if not isinstance(raster, dict):
        raise TypeError("raster must be a dict of the raster fields that differ from "
                        f"DEFAULT_RASTER (or None), got {type(raster).__name__}")
    state = raster_state(raster)
    prepared = prepare_draws(draws, normals=state["normals"])
    buffers, params = _render_technique(prepared, camera, state, {})
    return GoldenScene(technique="render", camera=camera, draws=prepared, buffers=buffers,
                       parameters=params, raster=dict(raster), description=description)


# --- the plain-rendering scenes: canonical solids, fixed cameras --------------------------------

def _framed(meshes, width, height, direction, margin=1.0, fovy=35.0):
    lo = np.min([np.asarray(m.vertices).min(axis=0) for m in meshes], axis=0)
    hi = np.max([np.asarray(m.vertices).max(axis=0) for m in meshes], axis=0)
    return frame_bounds(np.stack([lo, hi]), width=width, height=height, fovy=fovy,
                        direction=direction, margin=margin)


def _translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def _rotate_x(degrees):
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    m = np.eye(4)
    m[1:3, 1:3] = [[c, -s], [s, c]]
    return m


def _solid_scene(solid_name, *, width=160, height=120, direction=(1.0, 0.8, 1.4), **raster):
    from ..scenes import solid
    mesh = solid(solid_name)
    return render_scene([Draw(solid_name, mesh)], _framed([mesh], width, height, direction),
                        raster=raster)


@register_scene("render_cube", technique="render",
                description="Cube, flat normals, perspective, no culling.")
def _render_cube(**params):
    return _solid_scene("cube", **params)


@register_scene("render_icosphere_smooth", technique="render",
                description="Icosphere (1 280 faces), smooth vertex normals, back-face culling.")
def _render_icosphere_smooth(**params):
    return _solid_scene("icosphere", **{"normals": "smooth", "cull": "back", **params})


@register_scene("render_torus_ortho", technique="render",
                description="Torus under an orthographic camera, flat normals.")
def _render_torus_ortho(width=160, height=120, **raster):
    from ..scenes import solid
    mesh = solid("torus")
    view = look_at((0.0, 2.2, 2.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    half = 1.2 * width / height
    camera = Camera(view, orthographic(-half, half, -1.2, 1.2, 0.5, 6.0), width, height)
    return render_scene([Draw("torus", mesh)], camera, raster=raster)


@register_scene("render_fluted_column", technique="render",
                description="Fluted column (thin flutes: many near-edge pixel centres).")
def _render_fluted_column(**params):
    return _solid_scene("fluted_column", **{"width": 120, "height": 160,
                                             "direction": (1.0, 0.3, 1.2), **params})


@register_scene("render_nested_shells", technique="render",
                description="Nested shells seen from outside, front-face culling (inner shells "
                            "show through the culled outer surface).")
def _render_nested_shells(**params):
    return _solid_scene("nested_shells", **{"cull": "front", **params})


@register_scene("render_building", technique="render",
                description="Building (manifold3d boolean result), flat normals.")
def _render_building(**params):
    return _solid_scene("building", **{"direction": (1.2, 0.9, 1.6), **params})


@register_scene("render_crank", technique="render",
                description="Crank (about 100k faces, sub-pixel triangles).")
def _render_crank(**params):
    return _solid_scene("crank", **{"width": 192, "height": 144, "direction": (0.8, 1.0, 1.5),
                                    **params})


@register_scene("render_multi_draw", technique="render",
                description="Three draw calls with model matrices: object ids and palette "
                            "colours; the torus passes through the cube.")
def _render_multi_draw(width=160, height=120, **raster):
    from ..scenes import solid
    draws = [Draw("cube", solid("cube"), _translate(-0.6, 0.0, 0.0)),
             Draw("torus", solid("torus", quick=True), _translate(0.2, 0.0, 0.0) @ _rotate_x(70)),
             Draw("icosphere", solid("icosphere", quick=True), _translate(1.5, 0.3, -0.4))]
    view = look_at((1.0, 2.5, 5.0), (0.4, 0.0, 0.0))
    camera = Camera(view, perspective(35.0, width / height, 2.0, 9.0), width, height)
    return render_scene(draws, camera, raster=raster)


# --- TOML scenes ---------------------------------------------------------------------------------

def _toml_camera(spec, meshes, width, height, where, depth_range="negative_one_to_one"):
    def num(key, default=None):
        value = spec.get(key, default)
        if value is None:
            raise ValueError(f"{where}: [camera] needs {key!r}")
        return value

    kind = spec.get("kind", "frame")
    rev = bool(spec.get("reversed", False))
    if spec.get("far") == math.inf and kind != "perspective":
        raise ValueError(f"{where}: [camera] far = inf needs kind = 'perspective', got "
                         f"{kind!r}")
    if kind == "frame":
        lo = np.min([m.vertices.min(axis=0) for m in meshes], axis=0)
        hi = np.max([m.vertices.max(axis=0) for m in meshes], axis=0)
        cam = frame_bounds(np.stack([lo, hi]), width=width, height=height,
                           fovy=num("fovy", 35.0), direction=num("direction", (1.0, 0.8, 1.4)),
                           up=num("up", (0.0, 1.0, 0.0)), margin=num("margin", 1.1))
        if depth_range == "negative_one_to_one" and not rev:
            return cam
        near, far = cam.near_far   # the same frustum, built for the depth range
        return Camera(cam.view, perspective(num("fovy", 35.0), width / height, near, far,
                                            reversed=rev, depth_range=depth_range),
                      width, height)
    view = look_at(num("eye"), num("target"), num("up", (0.0, 1.0, 0.0)))
    if kind == "perspective":
        proj = perspective(num("fovy"), width / height, num("near"), num("far"),
                           reversed=rev, depth_range=depth_range)
    elif kind == "orthographic":
        left, right, bottom, top = as_float_array(num("extent"), f"{where}: camera.extent",
                                                  shape=(4,))
        proj = orthographic(left, right, bottom, top, num("near"), num("far"),
                            reversed=rev, depth_range=depth_range)
    else:
        raise ValueError(f"{where}: camera.kind must be 'frame', 'perspective' or "
                         f"'orthographic', got {kind!r}")
    return Camera(view, proj, width, height)


def _describe(value):
    """How a TOML value is named in an error: its TOML type and the value."""
    if isinstance(value, bool):
        kind = "a boolean"
    elif isinstance(value, int):
        kind = "an integer"
    elif isinstance(value, float):
        kind = "a float"
    elif isinstance(value, str):
        kind = "a string"
    elif isinstance(value, list):
        kind = "an array"
    elif isinstance(value, dict):
        return "a table"
    else:
        kind = f"a {type(value).__name__}"
    text = repr(value) if not isinstance(value, bool) else str(value).lower()
    return f"{kind} {text if len(text) <= 60 else text[:57] + '...'}"


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _vector(n):
    return (f"an array of {n} finite numbers",
            lambda v: isinstance(v, list) and len(v) == n and all(map(_is_number, v)))


_STR = ("a string", lambda v: isinstance(v, str))
_BOOL = ("a boolean", lambda v: isinstance(v, bool))
_INT = ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool))
_NUM = ("a finite number", _is_number)
_TABLE = ("a table", lambda v: isinstance(v, dict))
_MAT4 = ("a 4x4 array of finite numbers (4 rows of 4)",
         lambda v: isinstance(v, list) and len(v) == 4 and all(_vector(4)[1](r) for r in v))

#: Exact TOML types of every key (an int is an int: not a string, a float or a boolean).
_TOML_TYPES = {
    None: {"name": _STR, "description": _STR, "technique": _STR, "viewport": _TABLE,
           "camera": _TABLE, "raster": _TABLE, "parameters": _TABLE,
           "draw": ("an array of tables ([[draw]])",
                    lambda v: isinstance(v, list) and all(isinstance(d, dict) for d in v))},
    "viewport": {"width": _INT, "height": _INT},
    "camera": {"kind": _STR, "eye": _vector(3), "target": _vector(3), "up": _vector(3),
               "direction": _vector(3), "fovy": _NUM, "near": _NUM,
               "far": ("a finite number (or inf: an infinite far plane, perspective only)",
                       lambda v: _is_number(v) or (isinstance(v, float) and v == math.inf)),
               "margin": _NUM, "extent": _vector(4), "reversed": _BOOL},
    "raster": {"subpixel_bits": _INT, "fill_rule": _STR, "precision": _STR, "cull": _STR,
               "depth_func": _STR, "front_face": _STR, "clear_depth": _NUM, "normals": _STR,
               "depth_range": _STR, "origin": _STR, "ndc_y": _STR, "depth_clamp": _BOOL,
               "depth_format": _STR},
    "draw": {"mesh": ("a string (a path relative to the scene file)", _STR[1]),
             "solid": _STR, "name": _STR, "model": _MAT4},
}
_CAMERA_KINDS = ("frame", "perspective", "orthographic")
#: Largest TOML scene file read.
_MAX_TOML_BYTES = 16 << 20


def _toml_enums():
    from .io.schema import SCENE_SCHEMA
    raster = SCENE_SCHEMA["properties"]["raster"]["properties"]
    enums = {("raster", k): raster[k]["enum"] for k in ("precision", "cull", "depth_func",
                                                        "normals", "front_face", "depth_range",
                                                        "origin", "ndc_y", "depth_format")}
    enums[("camera", "kind")] = list(_CAMERA_KINDS)
    return enums


def _check_toml(spec, where):
    """Exact types, known tables and keys, allowed values; one message naming the table, the
    key, the expected type and the value given."""
    from .._validate import MAX_SIDE
    enums = _toml_enums()

    def check(table, label, values):
        types = _TOML_TYPES[table]
        unknown = sorted(set(values) - set(types))
        if unknown:
            what = "unknown tables/keys" if table is None else f"{label} has unknown keys"
            raise ValueError(f"{where}: {what} {unknown}; known: {sorted(types)}")
        for key, value in values.items():
            expected, ok = types[key]
            loc = key if table is None else f"{label} {key}"
            if not ok(value):
                raise ValueError(f"{where}: {loc} must be {expected}, got {_describe(value)}")
            allowed = enums.get((table, key))
            if allowed is not None and value not in allowed:
                raise ValueError(f"{where}: {loc} must be one of {allowed}, got "
                                 f"{_describe(value)}")
            if table == "viewport" and not 1 <= value <= MAX_SIDE:
                raise ValueError(f"{where}: {loc} must be between 1 and {MAX_SIDE}, got "
                                 f"{_describe(value)}")

    check(None, "", spec)
    for table in ("viewport", "camera", "raster"):
        check(table, f"[{table}]", spec.get(table, {}))
    for i, d in enumerate(spec.get("draw", ())):
        check("draw", f"[[draw]] {i}:", d)
        if ("mesh" in d) == ("solid" in d):
            raise ValueError(f"{where}: [[draw]] {i}: needs exactly one of 'mesh' or 'solid'")
        if "name" in d:
            check_name(d["name"], f"{where}: [[draw]] {i}: name")
        if "mesh" in d and _control(d["mesh"]):
            raise ValueError(f"{where}: [[draw]] {i}: mesh must not contain control "
                             f"characters, got {d['mesh']!r}"[:300])


_TOML_KEY = re.compile(r"""^\s*([A-Za-z0-9_."'-]+?)\s*=""")
_TOML_TABLE = re.compile(r"^\s*(\[\[?[^\]]+\]\]?)")


def _toml_value_error(text, path, exc):
    """One line for a ``ValueError`` ``tomllib`` raised outside its own errors: an integer
    beyond Python's int-string conversion limit, named by line, table and key."""
    from .io.safe import huge_int_digits
    limit = huge_int_digits()
    for m in re.finditer(r"(?<![.\w])[0-9][0-9_]*(?![.\w])", text):
        digits = len(m.group().replace("_", ""))
        if limit and digits > limit:
            lines = text[:m.start()].split("\n")
            key = next((k.group(1) for k in map(_TOML_KEY.match, reversed(lines)) if k), "?")
            table = next((t.group(1) + " " for t in map(_TOML_TABLE.match, reversed(lines))
                          if t), "")
            return (f"scene file {path} line {len(lines)}: {table}{key} is an integer of "
                    f"{digits} digits (more than the {limit} this reader converts)")
    return f"cannot read scene file {path}: {' '.join(str(exc).split())}"


def load_scene_file(path):
    """Read a TOML scene description and return its :class:`SceneEntry` (not registered).

    See ``docs/golden.md`` for the format. Mesh paths are relative to the TOML file; any format
    trimesh reads (PLY, OBJ, STL, glTF…) works, or ``solid = "crank"`` names a canonical solid.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"scene file {path} " + ("is not a regular file" if path.exists()
                                                  else "does not exist"))
    if path.stat().st_size > _MAX_TOML_BYTES:
        raise ValueError(f"scene file {path} is larger than {_MAX_TOML_BYTES >> 20} MiB")
    try:
        text = path.read_text(encoding="utf-8")
        spec = tomllib.loads(text)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"cannot read scene file {path}: {exc}") from exc
    except RecursionError:
        raise ValueError(f"cannot read scene file {path}: nested too deeply") from None
    except ValueError as exc:   # tomllib lets the int-string conversion limit through
        raise ValueError(_toml_value_error(text, path, exc)) from None
    where = str(path)
    _check_toml(spec, where)
    name = check_name(spec.get("name", path.stem), f"{where}: name")
    technique = spec.get("technique", "render")
    if technique not in TECHNIQUES:
        raise ValueError(f"{where}: unknown technique {technique!r}; "
                         f"known: {sorted(TECHNIQUES)}")
    if not spec.get("draw"):
        raise ValueError(f"{where}: at least one [[draw]] table is needed")
    raster_state(spec.get("raster", {}))

    def build():
        from ..scenes import solid
        draws = []
        for i, d in enumerate(spec["draw"]):
            if ("mesh" in d) == ("solid" in d):
                raise ValueError(f"{where}: draw[{i}] needs exactly one of 'mesh' or 'solid'")
            if "solid" in d:
                mesh = solid(d["solid"])
                default_name = d["solid"]
            else:
                try:
                    mesh = load_mesh_file(path.parent / d["mesh"])
                except ValueError as exc:
                    raise ValueError(f"{where}: draw[{i}]: {exc}") from exc
                default_name = re.sub(r"[^a-z0-9_]", "_", Path(d["mesh"]).stem.lower())
            draws.append(Draw(d.get("name", f"{default_name}_{i}" if i else default_name), mesh,
                              np.asarray(d.get("model", np.eye(4)), np.float64)))
        viewport = spec.get("viewport", {})
        width, height = int(viewport.get("width", 320)), int(viewport.get("height", 240))
        state = raster_state(spec.get("raster", {}))
        try:
            prepared = prepare_draws(draws, normals=state["normals"])
        except ValueError as exc:   # a smooth normal that is undefined
            raise ValueError(f"{where}: {str(exc).replace('draws[', 'draw[', 1)}") from None
        try:
            camera = _toml_camera(spec.get("camera", {}), [d.mesh for d in prepared], width,
                                  height, where, state["depth_range"])
        except ValueError as exc:   # a projection beyond float32, a degenerate look_at, …
            if str(exc).startswith(where):
                raise
            raise ValueError(f"{where}: [camera] {exc}") from None
        buffers, params = TECHNIQUES[technique](prepared, camera, state,
                                                spec.get("parameters", {}))
        return GoldenScene(technique=technique, camera=camera, draws=prepared, buffers=buffers,
                           parameters=params, raster=spec.get("raster", {}),
                           description=spec.get("description", ""))

    return SceneEntry(name, technique, spec.get("description", ""), build)
