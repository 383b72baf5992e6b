"""Mesh arrays and trimesh interop.

A mesh is given either as a ``(vertices, faces)`` pair — ``vertices (V, 3)`` float,
``faces (F, 3)`` int — or as a :class:`trimesh.Trimesh`. :func:`as_mesh` turns both into a
validated :class:`Mesh`.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np
from numba import njit

from ._config import JIT
from ._validate import as_float_array, as_index_array

__all__ = ["Mesh", "as_mesh", "as_meshes", "bounds", "face_normals", "vertex_normals",
           "smooth_normals", "split_creases", "load_mesh_file"]


@dataclass(frozen=True, eq=False)
class Mesh:
    """Validated triangle mesh: ``vertices (V, 3) float64``, ``faces (F, 3) int64``."""

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = field(default=None)

    @property
    def n_faces(self):
        return int(self.faces.shape[0])

    @property
    def n_vertices(self):
        return int(self.vertices.shape[0])

    def to_trimesh(self):
        import trimesh
        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    def with_smooth_normals(self, crease_angle=30.0):
        """This mesh with smooth per-vertex normals, split at creases.

        Vertices are duplicated where faces meeting at them are separated by an edge whose
        dihedral angle (between the face normals) exceeds ``crease_angle`` degrees, and every
        copy gets the angle-weighted normal of its own faces (:func:`split_creases`). Faces
        keep their order and winding (face ids do not change); render with
        ``normals="smooth"`` to use the normals. ``crease_angle=180`` never splits.
        """
        v, f, n, _ = split_creases(self.vertices, self.faces, crease_angle)
        return Mesh(v, f, n)


def as_mesh(mesh, name="mesh"):
    """Validate one mesh (``(vertices, faces)``, a :class:`Mesh` or a ``trimesh.Trimesh``)."""
    if isinstance(mesh, Mesh):
        return mesh
    normals = None
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        vertices, faces = mesh.vertices, mesh.faces
    elif isinstance(mesh, (tuple, list)) and len(mesh) in (2, 3):
        vertices, faces = mesh[0], mesh[1]
        if len(mesh) == 3:
            normals = mesh[2]
    else:
        raise TypeError(
            f"{name} must be a (vertices, faces) pair or a trimesh.Trimesh, "
            f"got {type(mesh).__name__}")
    v = as_float_array(vertices, f"{name}.vertices", shape=(None, 3))
    f = np.asarray(faces)
    if f.size == 0:
        f = np.zeros((0, 3), np.int64)
    f = as_index_array(f, f"{name}.faces", shape=(None, 3), upper=len(v))
    if normals is not None:
        normals = as_float_array(normals, f"{name}.normals", shape=(len(v), 3))
    return Mesh(v, f, normals)


def as_meshes(meshes, name="meshes"):
    """One mesh or a sequence of meshes (draw calls, drawn in order) → list of :class:`Mesh`."""
    if isinstance(meshes, Mesh) or hasattr(meshes, "faces"):
        return [as_mesh(meshes, name)]
    if isinstance(meshes, tuple) and len(meshes) in (2, 3) and not _looks_like_mesh(meshes[0]):
        return [as_mesh(meshes, name)]
    if isinstance(meshes, (list, tuple)):
        return [as_mesh(m, f"{name}[{i}]") for i, m in enumerate(meshes)]
    raise TypeError(f"{name} must be a mesh or a sequence of meshes, got {type(meshes).__name__}")


def _looks_like_mesh(x):
    return isinstance(x, Mesh) or hasattr(x, "faces") or (
        isinstance(x, (tuple, list)) and len(x) in (2, 3)
        and np.asarray(x[0], dtype=object).ndim >= 1 and np.ndim(x[0]) == 2)


def face_normals(vertices, faces):
    """Unit face normals ``(F, 3)`` from the right-hand rule (CCW = front); 0 for degenerate faces."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)
    return n


def vertex_normals(vertices, faces):
    """Area-weighted vertex normals ``(V, 3)`` (unit; 0 for isolated vertices)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, f[:, k], n)
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, acc / np.where(length > 0, length, 1.0), 0.0)


#: Smooth vertex normals of recent meshes, keyed on a SHA-256 digest of their vertices and faces
#: (shapes, dtypes and bytes), most recent last; at most :data:`_NORMALS_CACHE_ENTRIES` entries
#: and :data:`_NORMALS_CACHE_BYTES` bytes of normals.
_NORMALS_CACHE = OrderedDict()
_NORMALS_CACHE_ENTRIES = 8
_NORMALS_CACHE_BYTES = 128 << 20
#: Reentrant, and held by this thread means re-entered: a garbage collection inside the cache
#: (an insertion can trigger one) may run a finalizer that renders with smooth normals here.
_NORMALS_LOCK = threading.RLock()


#: Meshes of at least this many bytes (vertices and faces) are hashed in two halves, the second
#: on a thread of its own (hashlib releases the GIL), when the frame runs on two threads or more
#: (Numba's count, which ``render`` sets per frame): SHA-256 runs at ~1.8 GB/s here, 26 ms a
#: frame for the 47 MB of a 1.3M-face mesh (docs/performance.md).
_DIGEST_SPLIT = 1 << 20


def _sha256(views):
    h = hashlib.sha256()
    for v in views:
        h.update(v)
    return h.digest()


def _mesh_digest(vertices, faces):
    """SHA-256 of the mesh's shapes, dtypes and bytes; from :data:`_DIGEST_SPLIT` bytes on, of
    the shapes and dtypes and the SHA-256 of each half of the bytes (a hash tree: equal only
    for equal bytes, as the flat digest), the halves hashed at once on two threads (one
    after the other when the frame has one thread: the same digest)."""
    h = hashlib.sha256()
    views = []
    for a in (vertices, faces):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape};".encode())
        if a.size:   # (a memoryview of an empty array cannot be cast)
            views.append(memoryview(a).cast("B"))
    total = sum(len(v) for v in views)
    if total < _DIGEST_SPLIT:
        for v in views:
            h.update(v)
        return h.digest()
    first, second, rest = [], [], total // 2   # the first half: the first total // 2 bytes
    for v in views:
        k = min(len(v), rest)
        first.append(v[:k])
        second.append(v[k:])
        rest -= k
    out = []   # the second half's digest, from a thread of its own on a frame of two or more
    t = None
    if numba.get_num_threads() >= 2:
        t = threading.Thread(target=lambda: out.append(_sha256(second)), daemon=True)
        t.start()
    h.update(_sha256(first))
    if t is not None:
        t.join()
    h.update(out[0] if out else _sha256(second))   # here on one thread (or if the thread failed)
    return h.digest()


def smooth_normals(mesh):
    """:func:`vertex_normals` of a :class:`Mesh`, cached on the content of its arrays.

    Recomputing them cost ~40 % of an 82k-face frame with ``normals="smooth"``; the cache
    returns the same array while the vertices and faces hold the same bytes (a SHA-256 digest
    of both, ~3 ms for that mesh, is taken on every call), so changing a mesh in place, or
    rendering another mesh, never gets stale normals. The returned array is shared with
    later calls for the same content: read it, never write it (``render`` only reads it).
    """
    if _NORMALS_LOCK._is_owned():   # re-entered inside the cache: computed, not cached
        return vertex_normals(mesh.vertices, mesh.faces)
    key = _mesh_digest(mesh.vertices, mesh.faces)
    with _NORMALS_LOCK:
        hit = _NORMALS_CACHE.get(key)
        if hit is not None:
            _NORMALS_CACHE.move_to_end(key)
            return hit
    n = vertex_normals(mesh.vertices, mesh.faces)
    with _NORMALS_LOCK:
        _NORMALS_CACHE[key] = n
        total = sum(a.nbytes for a in _NORMALS_CACHE.values())
        while len(_NORMALS_CACHE) > 1 and (len(_NORMALS_CACHE) > _NORMALS_CACHE_ENTRIES
                                           or total > _NORMALS_CACHE_BYTES):
            _, old = _NORMALS_CACHE.popitem(last=False)
            total -= old.nbytes
    return n


@njit(**JIT)
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(**JIT)
def _union_corners(n, a, b, parent):
    """Union-find over ``n`` corners joined by the pairs ``(a[k], b[k])``; the representative
    of each set is its smallest corner (so the result does not depend on the pair order)."""
    for i in range(n):
        parent[i] = i
    for k in range(a.shape[0]):
        ra = _find(parent, a[k])
        rb = _find(parent, b[k])
        if ra < rb:
            parent[rb] = ra
        elif rb < ra:
            parent[ra] = rb
    for i in range(n):
        parent[i] = _find(parent, i)


def split_creases(vertices, faces, crease_angle=30.0):
    """Smooth vertex normals with the vertices split along crease edges.

    Parameters
    ----------
    vertices : (V, 3) float
    faces : (F, 3) int
    crease_angle : float in [0, 180]
        An edge shared by exactly two faces is smooth when the angle between their normals is
        at most this (degrees); other edges (creases, borders, non-manifold edges, edges of
        degenerate faces) separate the faces at their end points.

    Returns
    -------
    vertices : (V', 3) float64
        One copy of a vertex per group of its faces that are joined around it by smooth edges
        (copies of one vertex are consecutive, in the order of their first face corner).
    faces : (F, 3) int64
        The same faces, in the same order, indexing the copies.
    normals : (V', 3) float64
        Unit normals: the sum of each group's face normals weighted by the face's corner angle
        at the vertex (Thürmer & Wüthrich 1998), so the normal does not depend on how a smooth
        region is triangulated; 0 where all the group's faces are degenerate.
    source : (V',) int64
        The original vertex of each copy. Unreferenced vertices are dropped.

    Notes
    -----
    The paper's G-buffer needs per-vertex normals (Nienhaus & Döllner Sec. 1: "the shapes must
    provide per-vertex normals"); with flat normals every facet of a tessellated curved surface
    shows in the normal buffer, with smooth normals across creases the crease disappears from
    it. Grouping is local to each vertex's fan: two faces at a vertex share a copy when a path
    of smooth edges through that vertex joins them.
    """
    v = as_float_array(vertices, "vertices", shape=(None, 3))
    f = as_index_array(np.asarray(faces) if np.size(faces) else np.zeros((0, 3), np.int64),
                       "faces", shape=(None, 3), upper=len(v))
    from ._validate import as_real
    angle = as_real(crease_angle, "crease_angle", lo=0.0, hi=180.0)
    nf = len(f)
    if nf == 0:
        return (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3)),
                np.zeros(0, np.int64))
    fn = face_normals(v, f)
    ok = np.any(fn != 0.0, axis=1)
    # corner c = 3·face + k holds vertex f[face, k]; edge slot k joins corners k and k + 1
    corner = np.arange(3 * nf, dtype=np.int64).reshape(nf, 3)
    a_c = corner.reshape(-1)
    b_c = corner[:, [1, 2, 0]].reshape(-1)
    a_v, b_v = f.reshape(-1), f[:, [1, 2, 0]].reshape(-1)
    swap = a_v > b_v
    lo_c, hi_c = np.where(swap, b_c, a_c), np.where(swap, a_c, b_c)
    key = np.stack([np.minimum(a_v, b_v), np.maximum(a_v, b_v)], axis=1)
    _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    first = order[np.r_[0, np.cumsum(count)[:-1]]]
    two = count == 2
    p, q = first[two], order[np.cumsum(count)[two] - 1]          # the two slots of the edge
    fp, fq = p // 3, q // 3
    n1, n2 = fn[fp], fn[fq]
    dihedral = np.degrees(np.arctan2(np.linalg.norm(np.cross(n1, n2), axis=1),
                                     np.einsum("ij,ij->i", n1, n2)))
    smooth = (dihedral <= angle) & ok[fp] & ok[fq] & (fp != fq)
    a = np.concatenate([lo_c[p[smooth]], hi_c[p[smooth]]])
    b = np.concatenate([lo_c[q[smooth]], hi_c[q[smooth]]])
    parent = np.empty(3 * nf, np.int64)
    _union_corners(3 * nf, a, b, parent)
    # number the groups by (original vertex, representative corner)
    reps = np.unique(parent)
    rep_vertex = f.reshape(-1)[reps]
    rank = np.lexsort((reps, rep_vertex))
    new_id = np.empty(3 * nf, np.int64)
    new_id[reps[rank]] = np.arange(len(reps))
    label = new_id[parent]
    source = rep_vertex[rank]
    # corner angles
    tri = v[f]
    e1 = tri[:, [1, 2, 0]] - tri
    e2 = tri[:, [2, 0, 1]] - tri
    corner_angle = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=2),
                              np.einsum("ijk,ijk->ij", e1, e2))
    weights = (corner_angle * ok[:, None]).reshape(-1)
    acc = np.zeros((len(reps), 3))
    np.add.at(acc, label, weights[:, None] * np.repeat(fn, 3, axis=0))
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = np.where(length > 0, acc / np.where(length > 0, length, 1.0), 0.0)
    return v[source], label.reshape(nf, 3), normals, source


@njit(**JIT)
def _bounds(v, out):
    for j in range(3):
        out[0, j] = v[0, j]
        out[1, j] = v[0, j]
    for i in range(1, v.shape[0]):
        for j in range(3):
            x = v[i, j]
            if x < out[0, j]:
                out[0, j] = x
            if x > out[1, j]:
                out[1, j] = x


def bounds(vertices):
    """Axis-aligned bounding box ``(2, 3)`` (min, max) of ``(V, 3)`` vertices, V ≥ 1 (one
    pass; NumPy's ``min(axis=0)`` on an ``(V, 3)`` array is several times slower)."""
    v = np.ascontiguousarray(vertices, np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError(f"vertices must be a non-empty (V, 3) array, got shape {v.shape}")
    out = np.zeros((2, 3))
    if v.flags.writeable:   # a read-only view: one _bounds specialisation for both kinds
        v = v.view()
        v.setflags(write=False)
    _bounds(v, out)
    return out


def _one_line(exc):
    return " ".join(str(exc).split()) or type(exc).__name__


def _check_stl(path, size):
    """A binary STL is ``84 + 50·n`` bytes with ``n`` in bytes 80–84; an ASCII STL starts with
    ``solid``. Anything else is refused here, before trimesh guesses text encodings."""
    with open(path, "rb") as fh:
        head = fh.read(84)
    if len(head) == 84 and 84 + 50 * int.from_bytes(head[80:84], "little") == size:
        return
    if head.lstrip()[:5].lower() == b"solid":
        return
    n = int.from_bytes(head[80:84], "little") if len(head) == 84 else 0
    raise ValueError(f"mesh file '{path}' is not an STL file: not binary ({size} bytes, but its "
                     f"header's {n} triangles need {84 + 50 * n}) and not ASCII (does not "
                     "start with 'solid')")


def load_mesh_file(path):
    """Read a mesh file with trimesh (any format it reads; a scene is concatenated with its
    transforms applied) and check it: a regular, non-empty file that holds triangles with
    finite vertices and face indices in range.

    Returns
    -------
    trimesh.Trimesh

    Raises
    ------
    ValueError
        One line naming the file and the real cause: missing, not a file, empty, not a file
        of its format, an optional package trimesh needs for it, "mesh FILE has no
        triangles", non-finite vertices, faces beyond the vertices.
    """
    import trimesh
    path = Path(path)
    if not path.exists():
        raise ValueError(f"mesh file '{path}' does not exist")
    if not path.is_file():
        raise ValueError(f"mesh file '{path}' is not a regular file")
    size = path.stat().st_size
    if size == 0:
        raise ValueError(f"mesh file '{path}' is empty")
    if path.suffix.lower() == ".stl":
        _check_stl(path, size)
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except ImportError as exc:
        raise ValueError(f"cannot read a mesh from '{path}': trimesh needs the optional package "
                         f"'{exc.name or _one_line(exc)}' for this file, and it is not "
                         "installed") from exc
    except MemoryError as exc:
        raise ValueError(f"cannot read a mesh from '{path}': out of memory") from exc
    except Exception as exc:   # trimesh raises many kinds for unreadable files
        raise ValueError(f"cannot read a mesh from '{path}': {_one_line(exc)}") from exc
    faces = getattr(mesh, "faces", None)
    vertices = getattr(mesh, "vertices", None)
    if faces is None or vertices is None or len(faces) == 0:
        raise ValueError(f"mesh file '{path}' has no triangles (not a mesh file, or an empty "
                         "mesh)")
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"mesh file '{path}' has non-finite vertex coordinates")
    f = np.asarray(faces)
    if f.min() < 0 or f.max() >= len(vertices):
        raise ValueError(f"mesh file '{path}' has faces that refer to vertices it does not have "
                         f"(indices {int(f.min())}..{int(f.max())}, {len(vertices)} vertices)")
    return mesh
