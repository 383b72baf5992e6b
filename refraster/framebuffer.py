"""The framebuffer / G-buffer and :func:`render`, the one-call entry point."""

from __future__ import annotations

import dataclasses
import threading
import weakref
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ._scratch import OUTPUTS, SCRATCH_FACES, pooling, scratch_lease
from ._threads import frame_work, threads_for
from ._tiers import kernel as tiered
from ._validate import as_float_array, as_image_size, as_real
from .mesh import as_meshes, smooth_normals
from .raster import DEPTH_FUNCS, Fragments, facing, prepare, resolve
from .raster.state import as_raster_state, require_single_sample
from .raster.fragments import _interpolate
from .raster._stream import last_level_cache
from .raster.gbuffer import clear_spans, finalize, per_face_normals, readonly, shade
from .raster.rasterizer import MAX_FACES, fused

__all__ = ["Framebuffer", "render", "normalized_linear_depth", "PALETTE"]

#: Base colours of draw calls 0, 1, 2, … (cycled) used by the simple shading.
PALETTE = np.array([
    [0.80, 0.80, 0.82], [0.90, 0.55, 0.35], [0.40, 0.62, 0.85], [0.55, 0.78, 0.45],
    [0.85, 0.75, 0.40], [0.70, 0.50, 0.80], [0.45, 0.75, 0.75], [0.85, 0.45, 0.55],
])


@dataclass(eq=False)
class Framebuffer:
    """Per-pixel results of a render; every array is ``(H, W, …)`` with row 0 at the top.

    Attributes
    ----------
    depth : float32
        Window depth in [0, 1] (``0.5·z/w + 0.5``, or ``z/w`` under
        ``depth_range="zero_to_one"``); the clear value (``raster.clear_depth``, 1.0 by
        default) where nothing was drawn.
    eye_depth : float32
        Distance along the view axis, ``−z_eye``; ``+inf`` background.
    normal : float32 (H, W, 3)
        Eye-space unit normal (transformed by the normal matrix, not flipped towards the
        viewer); 0 background.
    prim_id : int32
        Face index within its mesh; −1 background.
    object_id : int32
        Draw-call index; −1 background.
    front_facing : bool
    barycentric : float32 (H, W, 3)
        Perspective-correct barycentrics in the visible face; 0 background.
    color : float32 (H, W, 3)
        Headlight Blinn–Phong shading of :data:`PALETTE` colours by ``object_id``
        (two-sided); ``background`` elsewhere. :func:`render` shades it when it is first
        read (a G-buffer pass that never reads it does not pay for it), from the meshes,
        ``barycentric`` and, with one draw call, ``prim_id`` (the face image itself) as they
        are then — read it before changing them in place. Once read it is an ordinary array
        (writes to it stay).
    """

    depth: np.ndarray
    eye_depth: np.ndarray
    normal: np.ndarray
    prim_id: np.ndarray
    object_id: np.ndarray
    front_facing: np.ndarray
    barycentric: np.ndarray
    color: np.ndarray
    view: np.ndarray = field(repr=False)
    proj: np.ndarray = field(repr=False)
    meshes: list = field(repr=False, default=None)
    models: list = field(repr=False, default=None)

    @property
    def width(self):
        return int(self.depth.shape[1])

    @property
    def height(self):
        return int(self.depth.shape[0])

    @property
    def mask(self):
        """Covered pixels, ``(H, W)`` bool."""
        return self.prim_id >= 0

    def interpolate(self, attr):
        """Interpolate per-vertex attributes at the visible fragments.

        ``attr``: one ``(V, C)``/``(V,)`` array (one mesh) or a list with one per mesh.
        Returns ``(H, W, C)`` (or ``(H, W)``) float64, 0 in the background.
        """
        if self.meshes is None:
            raise ValueError("this framebuffer carries no meshes")
        m = self.mask
        vals = _interpolate(self.meshes, attr, self.object_id[m], self.prim_id[m],
                            self.barycentric[m].astype(np.float64))
        out = np.zeros(m.shape + vals.shape[1:])
        out[m] = vals
        return out

    def eye_position(self):
        """Eye-space position of the visible surface, ``(H, W, 3)`` float64, NaN background."""
        if self.meshes is None:
            raise ValueError("this framebuffer carries no meshes")
        out = np.full(self.mask.shape + (3,), np.nan)
        m = self.mask
        out[m] = _eye_positions(self.meshes, self.models, self.view, self.object_id[m],
                                self.prim_id[m], self.barycentric[m].astype(np.float64))
        return out

    def field_values(self):
        """The dataclass fields as a dict, ``color`` as stored (not shaded if it is still
        pending): for building a subclass's framebuffer from this one."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(Framebuffer)
               if f.name != "color"}
        out["color"] = self.__dict__["_color"]
        return out

    def arrays(self):
        """The buffers as a dict (for ``.npz`` export)."""
        return dict(depth=self.depth, eye_depth=self.eye_depth, normal=self.normal,
                    prim_id=self.prim_id, object_id=self.object_id,
                    front_facing=self.front_facing, barycentric=self.barycentric,
                    color=self.color)

    @classmethod
    def from_fragments(cls, frags: Fragments, resolved, *, raster=None, background=(1, 1, 1)):
        """Build the G-buffer from a resolved fragment stream (``frags`` from :func:`draw`),
        with the normals of ``raster.normals`` (:class:`refraster.RasterState`; None: flat)."""
        normals = as_raster_state(raster).normals
        background = as_float_array(background, "background", shape=(3,))
        if frags.meshes is None:
            raise ValueError("frags must come from refraster.draw (it carries the meshes)")
        win = resolved.winner
        m = win >= 0
        idx = win[m]
        h, w = win.shape
        offsets = np.cumsum([0] + [mesh.n_faces for mesh in frags.meshes])
        if offsets[-1] > MAX_FACES:
            raise ValueError(f"frags: {int(offsets[-1]):,} faces in all; a framebuffer takes at "
                             f"most {MAX_FACES:,} (its face image is int32)")
        prim_global = np.full((h, w), -1, np.int32)
        front = np.zeros((h, w), np.bool_)
        bary = np.zeros((h, w, 3), np.float32)
        prim_global[m] = offsets[frags.object_id[idx]] + frags.prim_id[idx]
        front[m] = frags.front_facing[idx]
        bary[m] = frags.bary[idx]
        return _build(frags.meshes, frags.models, frags.view, frags.proj, resolved.depth,
                      prim_global, offsets, front, bary, normals, background)

    @classmethod
    def reusable(cls, width, height):
        """An empty framebuffer (every pixel background) for a loop of ``render(out=fb)``
        frames that clear only what the previous frame drew.

        Its seven arrays (``depth`` … ``barycentric``; not ``color``) are **read-only** views
        of memory only ``render`` writes: numpy refuses to make them, or any view of them,
        writeable. So the pixels a frame did not cover still hold the clear values when the
        next frame starts, and that frame clears only the rows' spans the previous one covered
        (:func:`refraster.raster.gbuffer.clear_spans`) instead of every byte. Copy an array to
        change it. Putting another array into the framebuffer (``fb.depth = a``) makes the
        frames clear everything until every view is back; a private memory found writeable
        at the start of a frame (made so through ``fb.depth.base``) makes every later frame
        clear everything; a frame that fails midway makes the next one clear everything. Not
        detected, so not supported: making the private memory writeable, writing into it and
        making it read-only again between two frames; writes through raw pointers; another
        thread writing into it while ``render`` runs. ``color`` is written whole by the shade
        and stays an ordinary array.
        """
        w, h = as_image_size(width, height)
        own = {}
        public = {}
        for name, tail, dtype in _OUT_ARRAYS:
            a = np.full((h, w) + tail, _BACKGROUND[name], dtype)
            a.flags.writeable = False
            v = a.view()
            own[name] = a
            public[name] = v
        fb = cls(**public, color=np.ones((h, w, 3), np.float32), view=np.eye(4),
                 proj=np.eye(4), meshes=None, models=None)
        face = np.full((h, w), -1, np.int32)
        fb.__dict__["_prim_scratch"] = face
        fb.__dict__["_owners"] = {name: (public[name], a) for name, a in own.items()}
        fb.__dict__["_owner_id"] = id(fb)   # a copy (copy.copy, deepcopy, pickle) is not it
        # nothing covered yet, clear depth 1: the record of an empty frame
        fb.__dict__["_record"] = (np.tile(np.array([0, -1], np.int64), (h, 1)), 1.0, face)
        return fb


class _PendingShade:
    """The inputs of :func:`refraster.raster.gbuffer.shade`, kept until ``color`` is read;
    ``work`` sizes its thread count (:mod:`refraster._threads`), ``into`` is a colour array of
    a reused framebuffer (``render(out=…)``) to shade into, or None."""

    __slots__ = ("args", "work", "into")

    def __init__(self, *args, work=0, into=None):
        self.args = args
        self.work = work
        self.into = into

    def __call__(self):
        prim_global = self.args[0]
        color = self.into
        if color is None:
            # shade writes every element (recycled memory gives the same bytes)
            color = OUTPUTS.empty(prim_global.shape + (3,), np.float32)
        # read-only again: a deep copy or an unpickled (protocol < 5) frame holds writeable
        # copies of the inputs, which would compile shade a second time (scratch 9 excepted)
        args = [readonly(a) if k != 9 and isinstance(a, np.ndarray) else a
                for k, a in enumerate(self.args)]
        if args[10]:   # per-face normals: a fresh array, filled by shade from today's vertices
            args[9] = np.empty((int(args[6][-1]), 3))
        with threads_for(self.work):
            tiered(shade)(*args, color)
        return color


def _get_color(self):
    color = self.__dict__["_color"]
    if isinstance(color, _PendingShade):
        color = self.__dict__["_color"] = color()
    return color


def _set_color(self, value):
    self.__dict__["_color"] = value


# a property over the dataclass field, so the generated __init__ stores through the setter
Framebuffer.color = property(_get_color, _set_color, doc="Shaded colour (H, W, 3) float32.")


def _eye_positions(meshes, models, view, obj, prim, bary):
    eye = [m.vertices @ (view @ mm)[:3, :3].T + (view @ mm)[:3, 3]
           for m, mm in zip(meshes, models)]
    return _interpolate(meshes, eye, obj, prim, bary)


#: The last few normal matrices, keyed on the bytes of the 3×3 matrix they invert (a loop of
#: frames with one camera asks for the same one every frame: ~20 µs of det and inv saved; the
#: value is the one computed from those bytes, so a hit returns the same bits).
_NMAT_CACHE: dict = {}


def _normal_matrix(view, model):
    mv = np.ascontiguousarray((view @ model)[:3, :3])
    key = mv.tobytes()
    hit = _NMAT_CACHE.get(key)
    if hit is not None:
        return hit
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):   # refused below
        det = np.linalg.det(mv)
    if not np.isfinite(det):
        raise ValueError(f"view @ model is too large for a normal matrix (its 3×3 part's "
                         f"determinant overflows; largest entry {np.abs(mv).max():.3g})")
    if abs(det) < 1e-300:
        raise ValueError("view @ model is singular; normals are undefined")
    nm = np.linalg.inv(mv).T
    nm.flags.writeable = False
    if len(_NMAT_CACHE) >= 16:
        _NMAT_CACHE.clear()
    _NMAT_CACHE[key] = nm
    return nm


def _normals_per_mesh(meshes, normals):
    """None/'flat' → None (use face normals); 'smooth' → vertex normals; arrays as given."""
    if normals is None or (isinstance(normals, str) and normals.lower() == "flat"):
        return None
    if isinstance(normals, str):
        # a Mesh built directly (not through as_mesh) carries its normals unchecked
        return [smooth_normals(m) if m.vertex_normals is None else
                as_float_array(m.vertex_normals, f"meshes[{k}].vertex_normals",
                               shape=(m.n_vertices, 3))
                for k, m in enumerate(meshes)]
    if len(meshes) == 1 and not isinstance(normals, (list, tuple)):
        normals = [normals]
    if not isinstance(normals, (list, tuple)) or len(normals) != len(meshes):
        raise ValueError("normals must be 'flat', 'smooth', one (V, 3) array, or one per mesh")
    return [as_float_array(n, f"normals[{k}]", shape=(m.n_vertices, 3))
            for k, (n, m) in enumerate(zip(normals, meshes))]


#: Placeholders for the kernels' optional arrays (read-only, so never written).
_NO_NORMALS = readonly(np.zeros((1, 3)))
_NO_FACE_NORMALS = np.zeros((1, 3))
#: ``finalize``'s ``prim_id`` when the face image is the ids (``_build(share_ids=True)``).
_NO_IDS = np.zeros((0, 0), np.int32)
#: ``finalize``'s rasterizer outputs when it writes no background into them.
_NO_RASTER = (np.zeros((0, 0), np.float32), np.zeros((0, 0), np.bool_),
              np.zeros((0, 0, 3), np.float32), np.float32(1.0))
#: From this many pixels, ``finalize`` writes the G-buffer's background itself (a reused
#: framebuffer's and a new one's from the output pool), not NumPy's fills.
FILL_IN_KERNEL = 1 << 16
#: From this many bytes of the arrays ``finalize`` fills, it writes long stretches of background
#: by streaming stores (:mod:`refraster.raster._stream`): arrays this much larger than the
#: last-level cache leave it anyway, so reading their lines in first is wasted (a quarter
#: larger: a 640×480 4× frame, 45 MB, is 2–6 % faster streamed; a 1024×768 1× frame, 32 MB,
#: 1 % slower).
STREAM_FROM_BYTES = last_level_cache() * 5 // 4


def _fill_background(bg, depth, front, bary, clear_depth):
    """The rasterizer's background values where ``bg``: what ``finalize``'s sweep writes
    (``_build(raster_bg=)``) when it writes no background."""
    depth[bg] = clear_depth
    front[bg] = False
    bary[bg] = 0.0


def _build(meshes, models, view, proj, depth, prim_global, face_offsets, front, bary, normals,
           background, geometry=None, n_shaded=None, out=None, targets=None, spans=None,
           share_ids=False, raster_bg=None):
    """Finalize the G-buffer from the visible primitive (global index over all draw calls,
    −1 background) and its barycentrics. ``geometry``: the draw calls' vertices and faces
    already concatenated (faces indexing the concatenation), when the caller has them.
    ``n_shaded``: only pixels of the first ``n_shaded`` faces get the default colour (the
    others the background), for a caller that colours the rest itself. ``out``: a framebuffer
    checked by :func:`_check_out` whose arrays (``depth``, ``front`` and ``bary`` already among
    them) are filled and returned instead of new ones; ``targets``: the arrays to write its
    eye depth, normal and ids into (the private memory of a :meth:`Framebuffer.reusable`,
    already holding the background: then nothing else is filled) instead of ``out``'s own.
    ``spans``: an (H, 2) int64 array for :func:`finalize`'s record of the covered spans.
    ``share_ids``: with one draw call and an int32 face image (a new frame, not ``out``), the
    face image *is* the ids (face ``g`` of call 0 has id ``g``, the background −1): it becomes
    ``prim_id`` itself, not written again (``render_samples``: 12.6 MB at 4×, 1024×768).
    ``raster_bg``: ``clear_depth`` when ``depth``, ``front`` and ``bary`` hold only what the
    tile pass won (``fused(fill=False)``, ``rasterize_samples(fill=False)``): their
    background is written here, in ``finalize``'s sweep, or by NumPy's fills when the sweep
    writes none."""
    h, w = depth.shape
    if prim_global.dtype != np.int32:   # one specialisation of finalize and shade
        prim_global = prim_global.astype(np.int32)
    vn = _normals_per_mesh(meshes, normals)
    if geometry is not None:
        vertices, faces = geometry
    elif len(meshes) == 1:
        vertices, faces = meshes[0].vertices, meshes[0].faces
    else:
        vertices = np.concatenate([m.vertices for m in meshes]) if meshes else np.zeros((0, 3))
        vbase = np.cumsum([0] + [m.n_vertices for m in meshes])
        faces = (np.concatenate([m.faces + vbase[k] for k, m in enumerate(meshes)])
                 if meshes else np.zeros((0, 3), np.int64))
    vnormals = (vn[0] if len(vn) == 1 else np.concatenate(vn)) if vn is not None and meshes \
        else _NO_NORMALS
    n = max(len(meshes), 1)
    mv = np.zeros((n, 4, 4))
    nmat = np.zeros((n, 3, 3))
    for k, model in enumerate(models):
        mv[k] = view @ model
        if face_offsets[k + 1] > face_offsets[k]:
            nmat[k] = _normal_matrix(view, model)
    offsets = np.asarray(face_offsets, np.int64)
    smooth = vn is not None
    per_face = per_face_normals(offsets[-1], h, w, smooth)
    fnormal = np.empty((int(offsets[-1]), 3)) if per_face else _NO_FACE_NORMALS
    # the background: written by finalize in its sweep over every pixel (one sweep instead of
    # five) into a reused framebuffer's arrays and into the output pool's (recycled memory, no
    # page faults in the steady state; 2026-12-04: 0.77x the CPU of NumPy's fills + finalize)
    # from FILL_IN_KERNEL pixels; NumPy's fills for smaller frames and, with the pool off,
    # into new arrays (first touches in the kernel: ~1.04x the frame's CPU)
    fill_bg = targets is None and h * w >= FILL_IN_KERNEL and (out is not None or pooling())
    if spans is None:
        spans = np.empty((h, 2), np.int64)
    share_ids = (share_ids and len(models) == 1 and out is None and targets is None
                 and prim_global.dtype == np.int32)
    if targets is not None:
        eye_depth, normal, prim, obj = targets
        into = _reusable_color(out, h, w)
    elif out is None and fill_bg:   # every element written by finalize
        eye_depth = OUTPUTS.empty((h, w), np.float32)
        normal = OUTPUTS.empty((h, w, 3), np.float32)
        prim = _NO_IDS if share_ids else OUTPUTS.empty((h, w), np.int32)
        obj = OUTPUTS.empty((h, w), np.int32)
        into = None
    elif out is None:
        eye_depth = OUTPUTS.full((h, w), np.inf, np.float32)
        normal = OUTPUTS.full((h, w, 3), 0.0, np.float32)
        prim = _NO_IDS if share_ids else OUTPUTS.full((h, w), -1, np.int32)
        obj = OUTPUTS.full((h, w), -1, np.int32)
        into = None
    else:
        eye_depth, normal, prim, obj = out.eye_depth, out.normal, out.prim_id, out.object_id
        if not fill_bg:
            eye_depth.fill(np.inf)
            normal.fill(0.0)
            prim.fill(-1)
            obj.fill(-1)
        into = _reusable_color(out, h, w)
    # every input read-only (views): one specialisation of each kernel for all callers
    args = (readonly(prim_global), readonly(bary), readonly(vertices), readonly(faces),
            readonly(vnormals), smooth, readonly(offsets), readonly(mv), readonly(nmat))
    rbg = _NO_RASTER
    if raster_bg is not None:
        bg_depth = np.float32(raster_bg)
        if fill_bg:
            rbg = (depth, front, bary, bg_depth)
        else:
            _fill_background(prim_global < 0, depth, front, bary, bg_depth)
    work = frame_work(offsets[-1], w, h)
    filled = eye_depth.nbytes + normal.nbytes + obj.nbytes + (prim.nbytes if prim.size else 0)
    if rbg is not _NO_RASTER:
        filled += depth.nbytes + front.nbytes + bary.nbytes
    stream = fill_bg and filled >= STREAM_FROM_BYTES
    with threads_for(work):
        tiered(finalize)(*args, fnormal, per_face, fill_bg, stream, eye_depth, normal, prim, obj,
                         spans, *rbg)
    color = _PendingShade(*args, _NO_FACE_NORMALS, per_face,
                          int(offsets[-1]) if n_shaded is None else int(n_shaded),
                          readonly(PALETTE), readonly(np.asarray(background, np.float64)),
                          work=work, into=into)
    if out is not None:
        out.color = color
        out.view, out.proj, out.meshes, out.models = view, proj, meshes, models
        return out
    if share_ids:
        prim = prim_global
    return Framebuffer(depth=depth, eye_depth=eye_depth, normal=normal, prim_id=prim,
                       object_id=obj, front_facing=front, barycentric=bary, color=color,
                       view=view, proj=proj, meshes=meshes, models=models)


#: The arrays of a framebuffer ``render(out=…)`` reuses: (name, trailing shape, dtype).
_OUT_ARRAYS = (("depth", (), np.float32), ("eye_depth", (), np.float32),
               ("normal", (3,), np.float32), ("prim_id", (), np.int32),
               ("object_id", (), np.int32), ("front_facing", (), np.bool_),
               ("barycentric", (3,), np.float32))
#: Their background values (the depth's is the frame's clear depth; 1 for a new one).
_BACKGROUND = dict(depth=1.0, eye_depth=np.inf, normal=0.0, prim_id=-1, object_id=-1,
                   front_facing=False, barycentric=0.0)


def _owned(fb):
    """``{name: private array}`` of the arrays of ``fb`` that are still the read-only views a
    :meth:`Framebuffer.reusable` handed out, and whether the clear record may be trusted:
    every array is such a view and no private array was made writeable since the last frame
    (that taints the framebuffer for good: a writeable view of it may exist)."""
    owners = fb.__dict__.get("_owners") if type(fb) is Framebuffer else None
    if owners and fb.__dict__.get("_owner_id") != id(fb):
        # a copy of a reusable framebuffer: its views are read-only and not backed by memory
        # it owns alone (a shallow copy shares the original's, with a record that goes stale)
        raise ValueError("out is a copy of a Framebuffer.reusable: reuse the original, or make "
                         "a new one with Framebuffer.reusable(width, height)")
    if not owners:   # (not a Framebuffer: _check_out says so)
        return {}, False
    got = {}
    for name, (view, own) in owners.items():
        if own.flags.writeable:
            fb.__dict__["_tainted"] = True
        if getattr(fb, name) is view:
            got[name] = own
    trusted = len(got) == len(owners) and not fb.__dict__.get("_tainted", False)
    return got, trusted


class _Unlocked:
    """The private arrays writeable for the body of a ``with`` (a frame's writes), read-only
    again after it, whatever happens."""

    def __init__(self, arrays):
        self.arrays = arrays

    def __enter__(self):
        for a in self.arrays:
            a.flags.writeable = True

    def __exit__(self, *exc):
        for a in self.arrays:
            a.flags.writeable = False
        return False


def _reusable_color(fb, h, w):
    """``fb``'s shaded colour array when it can take the next shade, else None (a new one is
    made on read)."""
    c = fb.__dict__.get("_color")
    if (isinstance(c, _PendingShade)):
        c = c.into
    if (isinstance(c, np.ndarray) and c.shape == (h, w, 3) and c.dtype == np.float32
            and c.flags.c_contiguous and c.flags.writeable):
        return c
    return None


def _input_arrays(meshes, normals, view, proj, model, background):
    arrs = [view, proj, background]
    for m in meshes:
        arrs += [m.vertices, m.faces]
        if m.vertex_normals is not None:
            arrs.append(m.vertex_normals)
    for x in (normals, model):
        if isinstance(x, np.ndarray):
            arrs.append(x)
        elif isinstance(x, (list, tuple)):
            arrs += [a for a in x if isinstance(a, np.ndarray)]
    return [a for a in arrs if isinstance(a, np.ndarray)]


def _check_out(out, h, w, inputs, owners=None):
    """``out`` must be a :class:`Framebuffer` whose arrays have this frame's shapes and dtypes,
    are C-contiguous, writeable (or the read-only views of ``owners``, ``{name: private
    array}``, which are written through the private array), do not overlap each other and
    do not overlap any input. Returns the seven arrays to write, in :data:`_OUT_ARRAYS`'
    order."""
    if type(out) is not Framebuffer:
        raise TypeError(f"out must be a Framebuffer returned by refraster.render, got "
                        f"{type(out).__name__}")
    owners = owners or {}
    arrays = []
    for name, tail, dtype in _OUT_ARRAYS:
        a = getattr(out, name)
        if not isinstance(a, np.ndarray):
            raise TypeError(f"out.{name} must be a numpy array, got {type(a).__name__}")
        if a.shape != (h, w) + tail or a.dtype != dtype:
            raise ValueError(f"out.{name} must be {np.dtype(dtype).name} of shape "
                             f"{(h, w) + tail} for this frame, got {a.dtype} {a.shape}")
        a = owners.get(name, a)
        if not (a.flags.c_contiguous and (a.flags.writeable or name in owners)):
            raise ValueError(f"out.{name} must be a C-contiguous, writeable array")
        arrays.append((name, a))
    c = _reusable_color(out, h, w)
    if c is not None:
        arrays.append(("color", c))
    # the same array objects as at the last successful check of this framebuffer (held here,
    # so an id is never reused): their memory has not moved, no need to compare them again
    ident = tuple(a for _, a in arrays)
    last = out.__dict__.get("_checked_arrays")
    same = last is not None and len(last) == len(ident) and all(
        x is y for x, y in zip(last, ident))
    # likewise an input that is the very array object checked against these arrays before
    # (held too; a loop of frames passes the same mesh and matrices): only new inputs are
    # compared (a background given as a tuple is a new array every frame)
    seen = out.__dict__.get("_checked_inputs", ()) if same else ()
    fresh = [x for x in inputs if not any(x is y for y in seen)]
    for i, (na, a) in enumerate(arrays):
        if not same:
            for nb, b in arrays[i + 1:]:
                if np.may_share_memory(a, b):
                    raise ValueError(f"out.{na} and out.{nb} share memory")
        for x in fresh:
            if np.may_share_memory(a, x):
                raise ValueError(f"out.{na} shares memory with an input array (a mesh, "
                                 "normals, matrix or background): render would overwrite it")
    out.__dict__["_checked_arrays"] = ident
    out.__dict__["_checked_inputs"] = tuple(inputs)
    return [a for _, a in arrays[:len(_OUT_ARRAYS)]]


def render(meshes, *, view, proj, width, height, raster=None, model=None, fragment_stage=None,
           background=(1.0, 1.0, 1.0), out=None):
    """Render meshes to a :class:`Framebuffer` (G-buffer plus a simple shaded colour).

    Parameters
    ----------
    meshes : mesh or sequence of meshes
        One mesh or several draw calls, drawn in order; a mesh is ``(vertices, faces)`` or a
        ``trimesh.Trimesh``.
    view, proj : (4, 4) float
        World → eye and eye → clip matrices (:mod:`refraster.camera`).
    width, height : int
    raster : RasterState, optional
        The fixed-function state (:class:`refraster.RasterState`): depth function, depth
        writes, clear depth, culling, front face, sub-pixel bits, fill rule, vertex-stage
        precision, the API conventions (depth range, window origin, NDC y, depth clamp;
        ``docs/architecture.md``, "Conventions"), and ``normals``: flat face normals (default) or smooth per-vertex normals
        (a mesh's own, given as ``Mesh.vertex_normals`` or a ``(vertices, faces, normals)``
        triple, else area-weighted ones), interpolated perspective-correctly and
        renormalized. None: OpenGL's defaults.
    model : (4, 4) or list of (4, 4), optional
    fragment_stage : callable, optional
        ``fragment_stage(frags) -> keep (N,) bool``, applied before the depth test (fragments
        with False are discarded, as GLSL ``discard``).
    background : (3,) float
        Colour of uncovered pixels in ``color``.
    out : Framebuffer, optional
        A framebuffer of an earlier ``render`` of the same size to overwrite instead of
        allocating new arrays (a loop of frames then skips allocating and page-faulting ~50
        bytes per pixel). Its arrays (and any array taken from it earlier, ``color``
        included) are written in place; it is returned. Its arrays must have this frame's
        shapes and dtypes, be C-contiguous and writeable, and share no memory with each other
        or with any input (ValueError otherwise). Not with ``fragment_stage``. Every byte is
        written each frame (the user may have written into the arrays), unless ``out`` is a
        :meth:`Framebuffer.reusable`: its arrays are read-only views, and a frame clears only
        the pixels the previous one covered. A framebuffer (or a copy sharing its memory)
        that another ``render`` is writing at that moment — in another thread, or in this
        one when called from a finalizer or a signal handler — is refused (ValueError)
        before anything is written (docs/reliability.md).

    Returns
    -------
    Framebuffer
        ``out`` when given.

    Notes
    -----
    Without a fragment stage, a fused tile kernel rasterizes and depth-tests in one pass; it
    gives the same bits as ``draw`` + ``resolve`` (tested). Small frames run on one thread, and
    so do frames on cores other processes are using (:mod:`refraster._threads`;
    ``REFRASTER_THREADS`` overrides); the bytes are the same for any thread count. Without
    ``out``, the arrays are new to the caller: their memory may be that of an earlier frame
    nobody holds any more (no framebuffer, view or memoryview of it), recycled and written
    whole (:class:`refraster._scratch.OutputPool`; ``REFRASTER_POOL_MB=0`` turns it off).
    Safe to call from several threads at once and from a finalizer or a signal handler while
    a frame of the same thread is in progress: each call makes its own frame
    (docs/reliability.md).
    """
    state = require_single_sample(as_raster_state(raster), "render")
    bg = as_float_array(background, "background", shape=(3,))
    if fragment_stage is not None and not callable(fragment_stage):
        raise TypeError("fragment_stage must be callable: frags -> keep mask")
    if out is not None and fragment_stage is not None:
        raise ValueError("out= cannot be combined with fragment_stage")
    meshes = as_meshes(meshes)
    w, h = as_image_size(width, height)
    n_faces = sum(m.n_faces for m in meshes)
    if n_faces > MAX_FACES:
        raise ValueError(f"meshes: {n_faces:,} faces in all; render takes at most "
                         f"{MAX_FACES:,} (its face image is int32)")
    with threads_for(frame_work(n_faces, w, h)):
        return _render(meshes, view, proj, w, h, state, model, fragment_stage, bg, out)


def _render(meshes, view, proj, width, height, state, model, fragment_stage, bg, out):
    # the fused path's intermediates come from this thread's reused buffers (none of them is
    # returned or kept by the framebuffer); the fragment-stream path hands its stream to user
    # code, so it allocates
    # (from SCRATCH_FACES faces up: smaller frames' arrays are below malloc's mmap threshold,
    # reused by malloc anyway, and np.zeros is cheaper for them than the scratch's bookkeeping)
    # without depth writes the depth test is not a minimum over the fragments: only the
    # fragment stream's resolve has it (the fused tile pass assumes writes)
    fused_path = fragment_stage is None and state.depth_write
    # (None when a frame of this thread is in progress: re-entered from a finalizer or a signal
    # handler, this frame allocates its own)
    with scratch_lease(fused_path and sum(m.n_faces for m in meshes) >= SCRATCH_FACES) \
            as scratch:
        return _render_frame(meshes, view, proj, width, height, state, model, fragment_stage,
                             bg, out, fused_path, scratch)


def _render_frame(meshes, view, proj, width, height, state, model, fragment_stage, bg, out,
                  fused_path, scratch):
    prep = prepare(meshes, view=view, proj=proj, width=width, height=height, model=model,
                   raster=state, scratch=scratch)
    normals = state.normals
    clear = state.clear_depth
    depth_func = state.depth_func
    if fused_path and out is not None:
        # the framebuffer's memory is this frame's until it returns: another render into it
        # meanwhile (another thread, or a finalizer or signal handler of this one) is refused
        with WRITING.claim(out):
            return _render_into(prep, out, model, bg, scratch)
    if fused_path:
        h, w = height, width
        depth, prim_global, front, bary = fused(
            prep.triangles, fill_rule=prep.fill_rule, depth_func=DEPTH_FUNCS[depth_func],
            clear_depth=clear, scratch=scratch, fill=False)
        facing(state, front, prim_global)
        return _build(prep.meshes, prep.models, prep.view, prep.proj, depth, prim_global,
                      prep.face_offsets, front, bary.reshape(h, w, 3), normals, bg,
                      share_ids=True, raster_bg=clear)
    from .raster import _fragments_of
    from .raster.rasterizer import stream
    pixel, depth, obj, prim, front, bary, _ = stream(prep.triangles, fill_rule=prep.fill_rule,
                                                     face_offsets=prep.face_offsets)
    frags = _fragments_of(prep, pixel, depth, obj, prim, front, bary)
    if fragment_stage is None:
        keep = None
    else:
        keep = np.asarray(fragment_stage(frags))
        if keep.dtype != np.bool_ or keep.shape != (len(frags),):
            raise ValueError(f"fragment_stage must return a bool array of shape "
                             f"({len(frags)},), got {keep.dtype} {keep.shape}")
    res = resolve(frags, raster=state, keep=keep)
    return Framebuffer.from_fragments(frags, res, raster=state, background=bg)


def _render_into(prep, out, model, bg, scratch):
    """The fused path into ``render(out=…)``'s framebuffer (checked here)."""
    state = prep.state
    normals, clear, depth_func = state.normals, state.clear_depth, state.depth_func
    h, w = prep.height, prep.width
    owners, trusted = _owned(out)
    arrays = _check_out(out, h, w, _input_arrays(prep.meshes, normals, prep.view, prep.proj,
                                                 model, bg), owners)
    faces = out.__dict__.get("_prim_scratch")
    if not (isinstance(faces, np.ndarray) and faces.shape == (h, w)):
        faces = np.empty((h, w), np.int32)   # private: never handed out
    out.__dict__["_prim_scratch"] = faces
    if owners:
        return _render_reusable(prep, out, owners, trusted, arrays, faces, normals,
                                depth_func, clear, bg, scratch)
    buffers = (out.depth, faces, out.front_facing, out.barycentric.reshape(h * w, 3))
    depth, prim_global, front, bary = fused(
        prep.triangles, fill_rule=prep.fill_rule, depth_func=DEPTH_FUNCS[depth_func],
        clear_depth=clear, buffers=buffers, scratch=scratch)
    facing(state, front, prim_global)
    return _build(prep.meshes, prep.models, prep.view, prep.proj, depth, prim_global,
                  prep.face_offsets, front, bary.reshape(h, w, 3), normals, bg, out=out)


class _Token:
    __slots__ = ("__weakref__",)


def _memory_of(fb):
    """``(low, high)`` byte bounds of every array a render into ``fb`` may write: its seven
    arrays (a :meth:`Framebuffer.reusable`'s private ones are the same memory as its views),
    its colour array and its private face image."""
    arrays = [getattr(fb, name, None) for name, _, _ in _OUT_ARRAYS]
    arrays += [fb.__dict__.get("_prim_scratch"), _reusable_color(fb, *fb.depth.shape[:2])
               if isinstance(getattr(fb, "depth", None), np.ndarray)
               and fb.depth.ndim == 2 else None]
    return [_byte_bounds(a) for a in arrays if isinstance(a, np.ndarray) and a.size]


def _byte_bounds(a):
    """The first and one past the last byte of ``a``'s memory (as NumPy's ``byte_bounds``,
    which moved between NumPy 1 and 2)."""
    low = high = a.__array_interface__["data"][0]
    for n, stride in zip(a.shape, a.strides):
        if stride < 0:
            low += stride * (n - 1)
        else:
            high += stride * (n - 1)
    return low, high + a.itemsize


class _Writing:
    """The memory each ``render(out=…)`` in progress is writing (docs/reliability.md,
    threads): a render into a framebuffer any of whose memory another render is writing —
    from another thread, or re-entered on this one from a finalizer or a signal handler — is
    refused with one line, before it writes anything. Two threads writing one framebuffer
    crashed in ``finalize`` (one thread's face image indexing the other's mesh); refusing,
    rather than waiting, also tells the program that the frame it would read back is not
    its own. A claim lasts while the frame's token lives: released when the frame ends,
    however it ends (a token left in a frame kept by a traceback is cleared on the way out)."""

    def __init__(self):
        self._lock = threading.RLock()   # a finalizer may claim while this thread holds it
        self._live = []                  # (weak reference to a frame's token, thread, bounds)

    @contextmanager
    def claim(self, fb):
        if type(fb) is not Framebuffer:   # (_check_out says so)
            yield
            return
        bounds = _memory_of(fb)
        me = threading.get_ident()
        token = _Token()
        with self._lock:
            self._live = [c for c in self._live if c[0]() is not None]
            for ref, who, theirs in self._live:
                if any(lo < hi2 and lo2 < hi for lo, hi in bounds for lo2, hi2 in theirs):
                    if who == me:
                        raise ValueError(
                            "out is being written by a render in progress on this thread "
                            "(render called again from a finalizer or a signal handler): "
                            "give the nested render its own framebuffer")
                    raise ValueError(
                        "out is being written by a render in another thread: give each "
                        "thread its own framebuffer (render(out=...) into one framebuffer "
                        "from several threads at once is refused)")
            self._live.append((weakref.ref(token), me, bounds))
        try:
            yield
        finally:
            token = None   # noqa: F841 (the claim ends with the token)


#: The claims of the renders into framebuffers in progress (one for the process).
WRITING = _Writing()


def _render_reusable(prep, out, owners, trusted, arrays, faces, normals, depth_func, clear,
                     bg, scratch):
    """A frame into a :meth:`Framebuffer.reusable`: clear what the previous frame covered
    (its record: each row's covered span, the clear depth and the face image it used) or,
    without a record to trust, everything; rasterize; finalize, recording this frame's spans.
    The record is dropped first and stored last, so a frame that fails midway leaves none."""
    h, w = prep.height, prep.width
    depth, eye_depth, normal, prim, obj, front, bary = arrays
    record = out.__dict__.pop("_record", None)
    if not (trusted and record is not None and record[2] is faces
            and record[0].shape == (h, 2)):
        record = None
    with _Unlocked(owners.values()):
        if record is None:
            spans = np.empty((h, 2), np.int64)
            for a, name in ((depth, None), (eye_depth, "eye_depth"), (normal, "normal"),
                            (prim, "prim_id"), (obj, "object_id"), (front, "front_facing"),
                            (bary, "barycentric")):
                a.fill(np.float32(clear) if name is None else _BACKGROUND[name])
            faces.fill(-1)
        else:
            spans = record[0]
            if record[1] != clear:
                depth.fill(np.float32(clear))
            clears = (spans, np.float32(clear), depth, faces, front, bary.reshape(h, 3 * w),
                      eye_depth, normal.reshape(h, 3 * w), prim, obj)
            clear_spans(clears[0], False, *clears[1:])
            old_spans, spans = spans, np.empty((h, 2), np.int64)
        fused(prep.triangles, fill_rule=prep.fill_rule,
              depth_func=DEPTH_FUNCS[depth_func], clear_depth=clear,
              buffers=(depth, faces, front, bary.reshape(h * w, 3)), scratch=scratch,
              cleared=True)
        facing(prep.state, front, faces)
        _build(prep.meshes, prep.models, prep.view, prep.proj, depth, faces,
               prep.face_offsets, front, bary, normals, bg, out=out,
               targets=(eye_depth, normal, prim, obj), spans=spans)
        if record is not None:   # the previous frame's pixels this one left uncovered
            clear_spans(old_spans, True, *clears[1:])
    if trusted:
        out.__dict__["_record"] = (spans, clear, faces)
    return out


def normalized_linear_depth(fb, near, far):
    """The papers' W-buffer depth: ``(eye_depth − near) / (far − near)`` clipped to [0, 1];
    1 in the background. ``near`` and ``far`` are usually fitted to the objects' bounds."""
    near = as_real(near, "near")
    far = as_real(far, "far")
    if not far > near:
        raise ValueError(f"far must be greater than near, got near={near}, far={far}")
    ed = np.asarray(fb.eye_depth, np.float64)
    out = np.ones(ed.shape, np.float32)
    m = np.isfinite(ed)
    out[m] = np.clip((ed[m] - near) / (far - near), 0.0, 1.0)
    return out
