"""The fragment stream: what the rasterizer emits and every fragment stage consumes."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .._config import PJIT
from .._scratch import OUTPUTS
from .._threads import check_fork

__all__ = ["Fragments", "concat"]

_FIELDS = ("pixel", "depth", "prim_id", "object_id", "bary", "front_facing")


class Fragments:
    """A stream of ``N`` fragments as a struct of arrays.

    Attributes
    ----------
    pixel : (N,) int64
        Flat index into an ``(H, W)`` image, row-major, row 0 at the top.
    depth : (N,) float32
        Window depth in [0, 1], linear in screen space.
    prim_id : (N,) int32
        Face index within its mesh.
    object_id : (N,) int32
        Draw-call index (0 for :func:`refraster.rasterize`).
    bary : (N, 3) float32
        Perspective-correct barycentrics in the original face (clipped pieces included).
    front_facing : (N,) bool
        Counter-clockwise in window space, as the picture is seen.
    width, height : int
    meshes : list of Mesh or None
        The meshes drawn (set by :func:`refraster.draw`), for :meth:`interpolate`.
    models, view, proj : model matrices per mesh, view and projection (set by ``draw``).

    Within each pixel, fragments appear in draw order (draw call, then primitive index), which
    is the order :func:`refraster.resolve` needs. Across pixels the order is by tile, then
    primitive, then row and column, and is a documented implementation detail.
    """

    def __init__(self, pixel, depth, prim_id, object_id, bary, front_facing, width, height,
                 meshes=None, models=None, view=None, proj=None):
        self.pixel = pixel
        self.depth = depth
        self.prim_id = prim_id
        self.object_id = object_id
        self.bary = bary
        self.front_facing = front_facing
        self.width = int(width)
        self.height = int(height)
        self.meshes = meshes
        self.models = models
        self.view = view
        self.proj = proj

    def __len__(self):
        return int(self.pixel.shape[0])

    def __repr__(self):
        return f"Fragments(n={len(self)}, width={self.width}, height={self.height})"

    @property
    def row(self):
        return self.pixel // self.width

    @property
    def col(self):
        return self.pixel % self.width

    def _like(self, **arrays):
        return Fragments(**arrays, width=self.width, height=self.height, meshes=self.meshes,
                         models=self.models, view=self.view, proj=self.proj)

    def select(self, mask):
        """The sub-stream where ``mask`` (bool ``(N,)``, or an index array) holds; order kept."""
        mask = np.asarray(mask)
        if mask.dtype == np.bool_ and mask.shape != (len(self),):
            raise ValueError(f"mask must have shape ({len(self)},), got {mask.shape}")
        return self._like(**{f: getattr(self, f)[mask] for f in _FIELDS})

    def interpolate(self, attr):
        """Interpolate per-vertex attributes with the perspective-correct barycentrics.

        ``attr`` is one ``(V, C)`` or ``(V,)`` array (one mesh) or a list with one per mesh.
        Returns ``(N, C)`` (or ``(N,)``) float64.
        """
        if self.meshes is None:
            raise ValueError("these fragments carry no meshes; produce them with refraster.draw")
        return _interpolate(self.meshes, attr, self.object_id, self.prim_id,
                            self.bary.astype(np.float64))

    def world_position(self):
        """World-space position of every fragment, ``(N, 3)`` float64 (model matrices applied)."""
        return self._position(space="world")

    def eye_position(self):
        """Eye-space position of every fragment, ``(N, 3)`` float64."""
        return self._position(space="eye")

    def object_position(self):
        """Object-space position (the mesh's own coordinates), ``(N, 3)`` float64."""
        return self._position(space="object")

    def _position(self, space):
        if self.meshes is None:
            raise ValueError("these fragments carry no meshes; produce them with refraster.draw")
        attrs = vertices_in(self.meshes, self.models, self.view, space)
        return _interpolate(self.meshes, attrs, self.object_id, self.prim_id,
                            self.bary.astype(np.float64))


def vertices_in(meshes, models, view, space):
    """Each mesh's vertices in ``space`` ("object", "world" or "eye"): ``v·Lᵀ + t`` with
    ``M = model`` (world) or ``view @ model`` (eye); an identity M leaves them as they are
    (the product would give the same values)."""
    out = []
    for k, m in enumerate(meshes):
        v = m.vertices
        if space != "object":
            mat = models[k] if space == "world" else view @ models[k]
            if not np.array_equal(mat, _EYE4):
                v = v @ mat[:3, :3].T + mat[:3, 3]
        out.append(v)
    return out


_EYE4 = np.eye(4)


def _interpolate(meshes, attr, object_id, prim_id, bary):
    if not isinstance(attr, (list, tuple)):
        if len(meshes) != 1:
            raise ValueError(f"attr must be a list with one array per mesh ({len(meshes)} meshes)")
        attr = [attr]
    if len(attr) != len(meshes):
        raise ValueError(f"attr has {len(attr)} arrays for {len(meshes)} meshes")
    arrays = []
    for k, (a, m) in enumerate(zip(attr, meshes)):
        a = np.asarray(a, np.float64)
        if a.shape[0] != m.n_vertices or a.ndim not in (1, 2):
            raise ValueError(f"attr[{k}] must have shape ({m.n_vertices}, C), got {a.shape}")
        arrays.append(a)
    scalar = arrays[0].ndim == 1
    if any((a.ndim == 1) != scalar for a in arrays):
        raise ValueError("attr arrays must all be (V,) or all be (V, C)")
    arrays = [a[:, None] if scalar else a for a in arrays]
    c = arrays[0].shape[1]
    if any(a.shape[1] != c for a in arrays):
        raise ValueError("attr arrays must have the same number of components")
    values = np.ascontiguousarray(np.concatenate(arrays)) if arrays else np.zeros((0, c))
    vbase = np.cumsum([0] + [m.n_vertices for m in meshes])
    faces = np.ascontiguousarray(np.concatenate([m.faces + vbase[k] for k, m in enumerate(meshes)])
                                 if meshes else np.zeros((0, 3), np.int64))
    fbase = np.cumsum([0] + [m.n_faces for m in meshes]).astype(np.int64)
    out = np.zeros((len(prim_id), c))
    object_id = np.asarray(object_id)
    prim_id = np.asarray(prim_id)
    own = (object_id >= 0) & (object_id < len(meshes))
    if own.any():
        limit = np.diff(fbase)[object_id[own]]
        p = prim_id[own]
        if p.min() < 0 or np.any(p >= limit):
            raise ValueError("prim_id out of range for its mesh")
    check_fork()
    _interpolate_kernel(np.ascontiguousarray(object_id), np.ascontiguousarray(prim_id),
                        np.ascontiguousarray(bary, dtype=np.float64), faces, fbase, values, out)
    return out[:, 0] if scalar else out


@njit(**PJIT)
def _interpolate_kernel(object_id, prim_id, bary, faces, fbase, values, out):
    """``out[i] = (b0·a[v0] + b1·a[v1]) + b2·a[v2]`` for the vertices of fragment i's face;
    fragments of objects outside the mesh list are left 0."""
    nobj = fbase.shape[0] - 1
    for i in prange(prim_id.shape[0]):
        k = object_id[i]
        if k < 0 or k >= nobj:
            continue  # not one of these meshes (e.g. a cap drawn by another stage): left 0
        g = fbase[k] + prim_id[i]
        v0, v1, v2 = faces[g, 0], faces[g, 1], faces[g, 2]
        b0, b1, b2 = bary[i, 0], bary[i, 1], bary[i, 2]
        for j in range(values.shape[1]):
            out[i, j] = (b0 * values[v0, j] + b1 * values[v1, j]) + b2 * values[v2, j]


def split_ids(prim_global, face_offsets):
    """``(object_id, prim_id)`` (int32, the shape of ``prim_global``) of global primitive
    indices, given the draws' first faces ``face_offsets`` (``F + 1`` entries): as
    ``obj = numpy.searchsorted(face_offsets[1:], g, side="right")`` and ``g − face_offsets[obj]``,
    each cast to int32, in one parallel pass."""
    g = np.ascontiguousarray(prim_global, np.int64)
    offsets = np.ascontiguousarray(face_offsets, np.int64)
    obj = OUTPUTS.empty(g.shape, np.int32)    # every element written by the kernel
    prim = OUTPUTS.empty(g.shape, np.int32)
    _split_kernel(g.reshape(-1), offsets, obj.reshape(-1), prim.reshape(-1))
    return obj, prim


@njit(**PJIT)
def _split_kernel(g, offsets, obj, prim):
    """``obj[i]``: the first k with ``offsets[k + 1] > g[i]`` (``len(offsets) − 1`` if none),
    found by bisection; ``prim[i] = g[i] − offsets[obj[i]]``."""
    m = offsets.shape[0] - 1
    for i in prange(g.shape[0]):
        v = g[i]
        lo = 0
        hi = m
        while lo < hi:
            mid = (lo + hi) >> 1
            if offsets[mid + 1] <= v:
                lo = mid + 1
            else:
                hi = mid
        obj[i] = lo
        prim[i] = v - offsets[lo]


def concat(streams):
    """Concatenate fragment streams drawn one after another (the result keeps draw order).

    All streams must have the same size; mesh lists are concatenated and object ids offset so
    they stay unique when the streams carry meshes.
    """
    streams = list(streams)
    if not streams:
        raise ValueError("streams must not be empty")
    w, h = streams[0].width, streams[0].height
    for s in streams:
        if (s.width, s.height) != (w, h):
            raise ValueError("all streams must have the same width and height")
    have = all(s.meshes is not None for s in streams)
    arrays = {f: [] for f in _FIELDS}
    meshes, models = [], []
    offset = 0
    for s in streams:
        for f in _FIELDS:
            a = getattr(s, f)
            if f == "object_id" and have:
                a = a + np.int32(offset)
            arrays[f].append(a)
        if have:
            meshes += list(s.meshes)
            models += list(s.models)
            offset += len(s.meshes)
    out = {f: np.concatenate(v) for f, v in arrays.items()}
    first = streams[0]
    return Fragments(**out, width=w, height=h, meshes=meshes if have else None,
                     models=models if have else None, view=first.view, proj=first.proj)
