"""Mesh arrays and trimesh interop.

A mesh is given either as a ``(vertices, faces)`` pair — ``vertices (V, 3)`` float,
``faces (F, 3)`` int — or as a :class:`trimesh.Trimesh`. :func:`as_mesh` turns both into a
validated :class:`Mesh`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

from ._config import JIT
from ._validate import as_float_array, as_index_array

__all__ = ["Mesh", "as_mesh", "as_meshes", "bounds", "face_normals", "vertex_normals",
           "load_mesh_file"]


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
