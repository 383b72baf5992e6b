"""Object-space edge classification (Nienhaus & Döllner, WSCG 2003, Sec. 3): a mesh's edges
as silhouette, border and crease edges for one view (:func:`classify_edges` → :class:`EdgeSet`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array, as_real
from ..camera import is_perspective

__all__ = ["EdgeSet", "classify_edges", "DEFAULT_CREASE_ANGLE"]

#: Dihedral angle (degrees between face normals) above which :func:`classify_edges` calls an
#: edge a crease.
DEFAULT_CREASE_ANGLE = 30.0


@dataclass(frozen=True, eq=False)
class EdgeSet:
    """The unique edges of a mesh, classified for one view (Nienhaus & Döllner Sec. 3).

    Attributes
    ----------
    edges : (E, 2) int64
        Vertex index pairs, ``edges[:, 0] < edges[:, 1]``, sorted lexicographically.
    faces : (E, 2) int64
        The first two adjacent faces (ascending); −1 for the missing one of a border edge.
    n_faces : (E,) int64
        Number of adjacent faces (1 border, 2 manifold, more non-manifold).
    dihedral : (E,) float64
        Largest angle in degrees between the normals of two adjacent faces (0 where flat,
        NaN on border edges).
    silhouette, border, crease : (E,) bool
        The classes: an edge between a front- and a back-facing face; an edge of exactly one
        face; an edge whose faces all face the same way with ``dihedral > crease_angle``.
        They are mutually exclusive.
    """

    edges: np.ndarray
    faces: np.ndarray
    n_faces: np.ndarray
    dihedral: np.ndarray
    silhouette: np.ndarray
    border: np.ndarray
    crease: np.ndarray

    def __len__(self):
        return int(self.edges.shape[0])

    @property
    def profile(self):
        """Silhouette or border edges: the outline of the object (the edge map's A)."""
        return self.silhouette | self.border


def _angle(n1, n2):
    """Angles in degrees between rows of unit vectors; atan2 stays accurate near 0 and 180°."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(n1, n2), axis=1),
                                 np.einsum("ij,ij->i", n1, n2)))


def classify_edges(mesh, *, view, proj=None, model=None, crease_angle=DEFAULT_CREASE_ANGLE):
    """Classify a mesh's edges into silhouette, border and crease edges for one view.

    Parameters
    ----------
    mesh : mesh
        ``(vertices, faces)``, :class:`refraster.Mesh` or ``trimesh.Trimesh``. Edges are
        vertex index pairs, so coincident but distinct vertices make border edges (merge them
        first, e.g. ``trimesh.Trimesh.merge_vertices``).
    view : (4, 4) float
        World → eye matrix.
    proj : (4, 4) float, optional
        Only its kind matters: with an orthographic projection faces are classified against the
        viewing direction, otherwise (and when omitted) against the eye position.
    model : (4, 4) float, optional
        Object → world matrix (identity when omitted).
    crease_angle : float in [0, 180]
        Dihedral threshold in degrees.

    Returns
    -------
    EdgeSet

    Notes
    -----
    Nienhaus & Döllner Sec. 3. A face is front-facing when its counter-clockwise normal points
    towards the eye (``n·(eye − v0) > 0``), the test OpenGL's facing makes in window space.
    Visibility is not considered: hidden silhouettes are silhouettes too.
    """
    from ..mesh import as_mesh, face_normals
    m = as_mesh(mesh)
    view = as_float_array(view, "view", shape=(4, 4))
    model = np.eye(4) if model is None else as_float_array(model, "model", shape=(4, 4))
    ortho = proj is not None and not is_perspective(as_float_array(proj, "proj", shape=(4, 4)))
    angle = as_real(crease_angle, "crease_angle", lo=0.0, hi=180.0)
    mv = view @ model
    if abs(np.linalg.det(mv[:3, :3])) < 1e-300:
        raise ValueError("view @ model is singular")
    inv = np.linalg.inv(mv)
    v, f = m.vertices, m.faces
    fn = face_normals(v, f)
    if ortho:
        towards_eye = np.broadcast_to(inv[:3, :3] @ np.array([0.0, 0.0, 1.0]), fn.shape)
    else:
        towards_eye = inv[:3, 3] - v[f[:, 0]]
    front = np.einsum("ij,ij->i", fn, towards_eye) > 0.0
    if np.linalg.det(mv[:3, :3]) < 0:
        front = ~front  # a mirroring transform swaps the winding seen on screen

    nf = len(f)
    pairs = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    face_of = np.tile(np.arange(nf, dtype=np.int64), 3)
    if nf == 0:
        edges = np.zeros((0, 2), np.int64)
        inverse = np.zeros(0, np.int64)
    else:
        edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
    ne = len(edges)
    count = np.bincount(inverse, minlength=ne).astype(np.int64)
    n_front = np.bincount(inverse, weights=front[face_of], minlength=ne)
    order = np.lexsort((face_of, inverse))
    start = np.cumsum(count) - count
    sorted_faces = face_of[order]
    faces = np.full((ne, 2), -1, np.int64)
    faces[:, 0] = sorted_faces[start]
    two = count >= 2
    faces[two, 1] = sorted_faces[start[two] + 1]

    dihedral = np.full(ne, np.nan)
    dihedral[two] = _angle(fn[faces[two, 0]], fn[faces[two, 1]])
    for e in np.flatnonzero(count > 2):
        adj = fn[sorted_faces[start[e]:start[e] + count[e]]]
        i, j = np.triu_indices(len(adj), 1)
        dihedral[e] = _angle(adj[i], adj[j]).max()

    border = count == 1
    silhouette = two & (n_front > 0) & (n_front < count)
    crease = two & ~silhouette & (dihedral > angle)
    return EdgeSet(edges=np.ascontiguousarray(edges, np.int64), faces=faces, n_faces=count,
                   dihedral=dihedral, silhouette=silhouette, border=border, crease=crease)
