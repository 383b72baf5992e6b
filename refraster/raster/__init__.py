"""Vertex and primitive stages, the rasterizer, the fragment stream and the resolve.

Public entry points: :func:`draw` (meshes → fragments), :func:`rasterize` (clip-space
positions → fragments), :func:`resolve` (fragments → visible fragment per pixel).
"""

from __future__ import annotations

import numpy as np

from .._threads import check_fork, frame_work, threads_for
from .._validate import as_float_array, as_image_size, as_index_array, as_matrix
from ..mesh import as_meshes
from .fragments import Fragments, concat, split_ids
from .primitive import CULL, FILL_RULES, W_EPS, convention_code, setup_triangles, transform_counted
from .rasterizer import DEPTH_FUNCS, stream
from .resolve import Resolved, resolve
from .state import RasterState, as_raster_state, require_single_sample

__all__ = ["draw", "rasterize", "resolve", "Fragments", "Resolved", "concat", "DEPTH_FUNCS",
           "prepare", "RasterState"]


def cull_code(state):
    """The primitive stage's cull code for a state: the stage tells front from back by GL's
    counter-clockwise rule, so under ``front_face="cw"`` culling the back culls what it calls
    front (and :func:`facing` turns the facing it reports)."""
    cull = state.cull
    if state.front_face == "cw" and cull != "none":
        cull = "front" if cull == "back" else "back"
    return CULL[cull]


def conv_code(state):
    """The primitive stage's convention bits of a state (depth range, depth clamp, window
    origin, NDC y; :func:`refraster.raster.primitive.convention_code`)."""
    return convention_code(state.depth_range, state.depth_clamp, state.origin, state.ndc_y)


def facing(state, front, face=None):
    """Turn the rasterizer's counter-clockwise facing into the state's, in place: under
    ``front_face="cw"`` a fragment is front-facing where the rasterizer found it back-facing
    (with the face image ``face`` (−1 background) only covered pixels change; the background
    stays False). The coverage mask is made only then (a frame under ``"ccw"`` needs none)."""
    if state.front_face == "cw":
        if face is None:
            np.logical_not(front, out=front)
        else:
            np.not_equal(front, face >= 0, out=front)
    return front


def _models(model, n):
    if model is None or (n == 0 and isinstance(model, (list, tuple)) and len(model) == 0):
        return [np.eye(4)] * n
    arr = np.asarray(model, dtype=object if isinstance(model, (list, tuple)) else None)
    if isinstance(model, (list, tuple)) and len(model) == n and n and np.ndim(model[0]) == 2:
        return [as_matrix(m, f"model[{i}]") for i, m in enumerate(model)]
    if arr.shape == (4, 4) or np.shape(model) == (4, 4):
        m = as_matrix(model, "model")
        return [m] * n
    raise ValueError(f"model must be a 4×4 matrix or a list of {n} such matrices")


class Prepared:
    """Validated draw calls after the vertex and primitive stages."""

    __slots__ = ("meshes", "models", "view", "proj", "width", "height", "triangles",
                 "face_offsets", "fill_rule", "clip", "state")

    def split(self, prim_global):
        """(object_id, prim_id) of global primitive indices (draw-call order)."""
        return split_ids(prim_global, self.face_offsets)


_F32_MAX = float(np.finfo(np.float32).max)
#: The smallest normal number of each vertex-stage precision: a w row of ``P·V·M`` whose
#: largest entry is below it is subnormal there (a GPU's vertex stage flushes it to zero).
_TINY = {"float32": float(np.finfo(np.float32).tiny), "float64": float(np.finfo(np.float64).tiny)}


def _check_projection(proj):
    """A projection must be invertible: a singular one (all zeros, w equal to z, …) puts every
    vertex on one plane or at w = 0 and draws an empty frame. The last few projections that
    passed are remembered by their bytes (a loop of frames checks one camera once)."""
    key = proj.tobytes()
    if key in _GOOD_PROJ:
        return
    # at unit scale (the largest entry 1): a large or small but invertible projection is not
    # singular because its determinant overflows or underflows (1e300 entries: inf)
    top = float(np.abs(proj).max())
    det = float(np.linalg.det(proj / top)) if top > 0.0 else 0.0
    if not (np.isfinite(det) and det != 0.0):
        raise ValueError(f"proj is singular (determinant {det:g} at unit scale): it maps the "
                         "scene onto a plane; give a perspective or orthographic matrix "
                         "(refraster.camera)")
    if len(_GOOD_PROJ) >= 16:
        _GOOD_PROJ.clear()
    _GOOD_PROJ.add(key)


_GOOD_PROJ: set = set()


def _mvp_name(k, n):
    return "proj @ view @ model" if n == 1 else f"proj @ view @ model (draw call {k})"


def _check_w_row(mvp, k, n, prec):
    """The w row of ``P·V·M`` must not underflow the vertex stage's precision: every clip w is
    a product of it (``perspective(...) * 1e-40`` has entries of ~1e-40, subnormal in float32:
    refused here). Not a determinant test: a uniform scale keeps the matrix invertible."""
    wrow = float(np.abs(mvp[3]).max())
    if 0.0 < wrow < _TINY[prec]:
        raise ValueError(f"{_mvp_name(k, n)} underflows {prec}: its w row's largest entry is "
                         f"{wrow:.3g}, below the smallest normal {prec} {_TINY[prec]:.3g}; "
                         "scale the matrices up (a uniform scale does not change the picture)")


def _check_w(clip, vfirst, meshes, prec):
    """Each draw call needs a vertex whose clip w is at least the w plane the primitive stage
    clips against (``W_EPS``, 1e-30) in magnitude, or w exactly 0 everywhere (a mesh in the
    eye's plane): when every vertex has ``0 < |w| < W_EPS`` — a matrix scaled so small that
    the products fall under the w plane (``perspective(...) * 1e-35`` in either precision) —
    every face is outside that plane and the draw would be silently empty. So it is refused;
    a draw that renders anything is never refused."""
    for k, m in enumerate(meshes):
        if m.n_faces == 0 or m.n_vertices == 0:
            continue
        w = clip[vfirst[k]:vfirst[k + 1], 3]
        if abs(float(w[0])) >= W_EPS:   # the largest |w| is too: nothing to refuse, no pass
            continue
        wmax = float(np.abs(w).max())
        if 0.0 < wmax < W_EPS:
            raise ValueError(f"{_mvp_name(k, len(meshes))} scales clip coordinates below the "
                             f"w plane: every vertex of meshes[{k}] has |w| < {W_EPS:g} "
                             f"(largest {wmax:.3g}), so the draw would be empty; scale the "
                             "matrices up (a uniform scale does not change the picture)")


def _check_divide(prims, clip, vfirst, face_offsets, meshes):
    """The perspective divide and viewport are float32 in both precisions (as Mesa's draw
    module): with ``precision="float64"`` a vertex that reaches them with a clip coordinate
    beyond float32's range (a view scaled by 1e38: w ~ 1.4e38, x ~ 3e39) became inf there and
    its faces vanished without a word. Clip coordinates of the float32 vertex stage are within
    range by construction (inf is refused by :func:`_check_clip`), so only a float64 stage
    whose clip coordinates exceed it is looked at: the vertices inside every clip plane must
    be within float32's range, and so must the clipped pieces' corners (finite window
    positions, w below float32's largest: 1/w of a larger w is 0 there). Vertices that are
    clipped away (a huge mesh around the camera) may be as large as they like."""
    if clip.size == 0 or float(np.abs(clip).max()) <= _F32_MAX:
        return
    used = np.zeros(len(clip), np.bool_)
    used[prims.faces.ravel()] = True
    bad = used & (prims.vcode == 0) & (np.abs(clip) > _F32_MAX).any(axis=1)
    st = prims.clipped
    # a corner's w beyond float32 gives 1/w = 0 there: finite, and wrong
    pieces = ~(np.isfinite(st.xf).all(axis=1) & np.isfinite(st.yf).all(axis=1)
               & np.isfinite(st.z).all(axis=1)) | (st.inv_w < 1.0 / _F32_MAX).any(axis=1)
    if not (bad.any() or pieces.any()):
        return
    if bad.any():
        k = int(np.searchsorted(vfirst, int(np.argmax(bad)), side="right")) - 1
    else:
        g = int(st.prim[int(np.argmax(pieces))])
        k = int(np.searchsorted(face_offsets, g, side="right")) - 1
    raise ValueError(f"meshes[{k}]: clip coordinates exceed float32 where the perspective "
                     f"divide (float32 in both precisions) needs them (largest "
                     f"{float(np.abs(clip).max()):.3g}, float32 ends at {_F32_MAX:.3g}); "
                     "scale the matrices or the mesh down")


def _check_clip(clip, meshes, prec, nonfinite=None):
    """Clip coordinates must be finite: a vertex whose transform overflows (1e300 in float32,
    ±3e38 moved by the view) would silently vanish. Far but finite vertices (1e30) are fine:
    the clipper places them (see :mod:`refraster.raster.primitive`). ``nonfinite``: how many
    are not, as the vertex stage counted them (0: nothing to look at; None: not counted)."""
    if nonfinite == 0:
        return
    # one sum first: finite only if every coordinate is (an inf or a nan makes it inf or nan;
    # finite values summing past float64's range are looked at one by one)
    with np.errstate(over="ignore", invalid="ignore"):
        total = clip.sum()
    if clip.size == 0 or np.isfinite(total) or np.isfinite(clip).all():
        return
    first = int(np.argmax(~np.isfinite(clip).all(axis=1)))
    ends = np.cumsum([m.n_vertices for m in meshes])
    k = int(np.searchsorted(ends, first, side="right"))
    v = meshes[k].vertices
    raise ValueError(f"meshes[{k}]: clip coordinates overflow to inf in {prec} precision "
                     f"(vertex {first - int(ends[k] - len(v))}; largest |coordinate| "
                     f"{np.abs(v).max():.3g}); scale the mesh down or use precision='float64'")


def prepare(meshes, *, view, proj, width, height, model=None, raster=None, scratch=None):
    """Validate draw calls and run the vertex and primitive stages (shared by draw and render)
    with the :class:`RasterState` ``raster`` (its cull, front face, precision, sub-pixel bits,
    fill rule and API conventions; None: the default state).
    ``scratch`` (internal, ``render``): a :class:`refraster._scratch.Scratch` for the clip
    coordinates and the primitive stage's arrays — the result is then valid only until that
    scratch is used again.

    Called on its own, its kernels run on the threads :mod:`refraster._threads` chooses for the
    frame (one for small frames and on busy cores), as ``render`` and ``draw`` do; inside them
    it keeps their choice."""
    state = as_raster_state(raster)
    meshes = as_meshes(meshes)
    w, h = as_image_size(width, height)
    with threads_for(frame_work(sum(m.n_faces for m in meshes), w, h)):
        return _prepare(meshes, view=view, proj=proj, width=w, height=h, model=model,
                        state=state, scratch=scratch)


def _prepare(meshes, *, view, proj, width, height, model, state, scratch, multisample=False):
    view = as_matrix(view, "view")
    proj = as_matrix(proj, "proj")
    width, height = as_image_size(width, height)
    prec = state.precision
    rule = FILL_RULES[state.fill_rule]
    models = _models(model, len(meshes))
    mvps = []
    for mm in models:
        with np.errstate(over="ignore", invalid="ignore"):   # refused just below, in one line
            mvp = proj @ view @ mm
        if not np.all(np.isfinite(mvp)):
            raise ValueError("proj @ view @ model overflows to non-finite values")
        if prec == "float32" and np.abs(mvp).max() > _F32_MAX:
            raise ValueError(f"proj @ view @ model overflows float32 (largest entry "
                             f"{np.abs(mvp).max():.3g}); scale the scene down or use "
                             "precision='float64'")
        _check_w_row(mvp, len(mvps), len(models), prec)
        mvps.append(mvp)
    _check_projection(proj)
    offsets = np.cumsum([0] + [m.n_faces for m in meshes])
    vfirst = np.cumsum([0] + [m.n_vertices for m in meshes])
    # the clip coordinates are written as float64 by the vertex stage (a float32 stage's
    # values exactly), each draw call once, into the scratch's reused buffer for render
    if len(meshes) == 1:   # the common case: no copies
        nv = meshes[0].n_vertices
        clip = (np.zeros((nv, 4)) if scratch is None   # zeros: warm-up stubs the stage
                else scratch.empty("clip", (nv, 4), np.float64))
        nonfinite = transform_counted(meshes[0].vertices, mvps[0], prec, out=clip)[1]
        face = meshes[0].faces
    else:
        clip = np.zeros((int(vfirst[-1]), 4))
        face = np.empty((int(offsets[-1]), 3), np.int64)
        nonfinite = 0
        for k, (m, mvp) in enumerate(zip(meshes, mvps)):
            bad = transform_counted(m.vertices, mvp, prec, out=clip[vfirst[k]:vfirst[k + 1]])[1]
            nonfinite = None if bad is None or nonfinite is None else nonfinite + bad
            np.add(m.faces, vfirst[k], out=face[offsets[k]:offsets[k + 1]])
    _check_clip(clip, meshes, prec, nonfinite)
    _check_w(clip, vfirst, meshes, prec)
    p = Prepared()
    p.meshes, p.models, p.view, p.proj = meshes, models, view, proj
    p.width, p.height, p.fill_rule = width, height, rule
    p.face_offsets = np.asarray(offsets, np.int64)
    p.clip = clip
    p.state = state
    # multisampling: boxes widened by half a pixel, for samples away from the centre
    pad = (1 << (state.subpixel_bits - 1)) if multisample else 0
    p.triangles = setup_triangles(clip, face, width, height, cull=cull_code(state),
                                  subpixel_bits=state.subpixel_bits, conv=conv_code(state),
                                  scratch=scratch, pad=pad)
    if prec == "float64":
        _check_divide(p.triangles, clip, vfirst, offsets, meshes)
    return p


def _fragments_from(prep, pixel, depth, prim_global, front, bary):
    obj, prim = prep.split(prim_global)
    return _fragments_of(prep, pixel, depth, obj, prim, front, bary)


def _fragments_of(prep, pixel, depth, obj, prim, front, bary):
    """The stream of ``prep``'s draw calls from :func:`rasterizer.stream`'s outputs (ids
    already split per draw call), its facing turned by the state's front face."""
    facing(prep.state, front)
    return Fragments(pixel, depth, prim, obj, bary, front, prep.width, prep.height,
                     meshes=prep.meshes, models=prep.models, view=prep.view, proj=prep.proj)


def draw(meshes, *, view, proj, width, height, model=None, raster=None):
    """Draw meshes (one or a sequence of draw calls, in order) into a fragment stream.

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        ``(vertices (V, 3), faces (F, 3))`` pairs or ``trimesh.Trimesh`` objects.
    view, proj : (4, 4) float
        World → eye and eye → clip matrices (OpenGL conventions, :mod:`refraster.camera`).
    width, height : int
        Viewport size in pixels.
    model : (4, 4) float or list of them, optional
        Object → world matrix, one for all meshes or one per mesh.
    raster : RasterState, optional
        The fixed-function state (:class:`refraster.RasterState`); its cull mode, front face,
        vertex-stage precision, sub-pixel bits, fill rule and API conventions (depth range,
        depth clamp, window origin, NDC y) apply here (the depth test is :func:`resolve`'s).
        None: OpenGL's defaults.

    Returns
    -------
    Fragments
        With ``meshes``, ``models``, ``view`` and ``proj`` attached, so ``interpolate`` and
        ``world_position`` work.
    """
    return draw_stream(meshes, view, proj, width, height, model, raster, bary=True)


def draw_stream(meshes, view, proj, width, height, model, raster, *, bary):
    """:func:`draw`, with the barycentrics only if ``bary`` (else ``Fragments.bary`` is empty,
    ``(0, 3)``: depth peeling needs none, and they are a fifth of the stream's time)."""
    require_single_sample(as_raster_state(raster), "draw")
    meshes = as_meshes(meshes)
    w, h = as_image_size(width, height)
    with threads_for(frame_work(sum(m.n_faces for m in meshes), w, h)):
        prep = prepare(meshes, view=view, proj=proj, width=w, height=h, model=model,
                       raster=raster)
        pixel, depth, obj, prim, front, bary, _ = stream(
            prep.triangles, fill_rule=prep.fill_rule, bary=bary, face_offsets=prep.face_offsets)
    return _fragments_of(prep, pixel, depth, obj, prim, front, bary)


def rasterize(clip_positions, faces, width, height, *, raster=None):
    """Rasterize triangles given in clip space into a fragment stream.

    Parameters
    ----------
    clip_positions : (V, 4) float
        Homogeneous clip coordinates (as ``gl_Position``); float32 values are used exactly.
    faces : (F, 3) int
        Vertex indices; the primitive id of a fragment is its face's row.
    width, height : int
    raster : RasterState, optional
        Its cull mode, front face, sub-pixel bits, fill rule and API conventions, as in
        :func:`draw`.

    Returns
    -------
    Fragments
        ``object_id`` is 0; no meshes are attached.
    """
    check_fork()
    c = as_float_array(clip_positions, "clip_positions", shape=(None, 4))
    f = np.asarray(faces)
    if f.size == 0:
        f = np.zeros((0, 3), np.int64)
    f = as_index_array(f, "faces", shape=(None, 3), upper=len(c))
    width, height = as_image_size(width, height)
    state = require_single_sample(as_raster_state(raster), "rasterize")
    st = setup_triangles(c, f, width, height, cull=cull_code(state),
                         subpixel_bits=state.subpixel_bits, conv=conv_code(state))
    pixel, depth, obj, prim, front, bary, _ = stream(st, fill_rule=FILL_RULES[state.fill_rule])
    facing(state, front)
    return Fragments(pixel, depth, prim, obj, bary, front, width, height)
