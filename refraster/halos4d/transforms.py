"""4D rotations and the 4D → 3D projection with a 4D depth (Wang et al. Sec. 4.2; MATH.md §5.1–5.2).

Rotations act on column vectors; ``rotation("xw", θ)`` turns +x toward +w. The eye sits on the
w-axis at ``w = e`` looking toward −w, so the **4D depth** of a point is ``δ = e − w`` (smaller is
nearer) under both projections:

* orthographic: ``p = s·(x, y, z)``, tangents ``t3 = s·t_xyz``;
* perspective: ``p = f·(x, y, z)/(e − w)``,
  ``t3 = f·(t_xyz·(e − w) + (x, y, z)·t_w)/(e − w)²`` (MATH.md §5.2; the paper's "no surviving
  4D component" holds only for the orthographic case).

The 3D result is the paper's "3D screen space": it is then viewed along −z by an orthographic
3D camera and sliced perpendicular to z.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_choice, as_float_array, as_matrix, as_real

__all__ = ["PLANES", "rotation", "compose", "hanson_view", "Projection", "project",
           "rotate_3d"]

#: The six rotation planes (a, b): +a turns toward +b.
PLANES = {"xy": (0, 1), "yz": (1, 2), "zx": (2, 0), "xw": (0, 3), "yw": (1, 3), "zw": (2, 3)}
PROJECTIONS = ("orthographic", "perspective")
#: Smallest 4D depth e − w accepted under perspective (relative to the eye distance).
DELTA_MIN = 1e-3


def rotation(plane, angle):
    """Rotation by ``angle`` (radians) in one of the six coordinate planes of R⁴ (MATH.md §5.1).

    Parameters
    ----------
    plane : {"xy", "yz", "zx", "xw", "yw", "zw"}
    angle : float

    Returns
    -------
    (4, 4) float64 ``R`` with ``R[a,a] = R[b,b] = cos θ``, ``R[a,b] = −sin θ``,
    ``R[b,a] = sin θ`` (column vectors; +a turns toward +b).
    """
    a, b = as_choice(plane, "plane", PLANES)
    angle = as_real(angle, "angle")
    r = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    r[a, a] = c
    r[b, b] = c
    r[a, b] = -s
    r[b, a] = s
    return r


def compose(*steps):
    """Product of rotations applied in the order given.

    Each step is a ``(plane, angle)`` pair or a (4, 4) matrix; ``compose(A, B)`` applies A first,
    so it returns ``B @ A``.
    """
    out = np.eye(4)
    for i, st in enumerate(steps):
        if isinstance(st, tuple) and len(st) == 2 and isinstance(st[0], str):
            m = rotation(*st)
        else:
            m = as_matrix(st, f"steps[{i}]")
        out = m @ out
    return out


def hanson_view(alpha=0.0):
    """Hanson's view of a complex curve: 3D = (Re z1, Re z2, cos α Im z1 + sin α Im z2).

    Returns the (4, 4) orthogonal matrix, determinant +1, taking
    ``(Re z1, Im z1, Re z2, Im z2)`` to ``(Re z1, Re z2, cos α Im z1 + sin α Im z2,
    sin α Im z1 − cos α Im z2)``; the last coordinate is the one the projection drops.
    """
    alpha = as_real(alpha, "alpha")
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, c, 0, s], [0, s, 0, -c]])


def rotate_3d(points, axis, angle):
    """Rotate 3D screen-space points ``(V, 3)`` by ``angle`` (radians) about the x (``"x"``) or
    y (``"y"``) axis through the origin (used for the stereo pair)."""
    axis = as_choice(axis, "axis", {"x": 0, "y": 1})
    angle = as_real(angle, "angle")
    c, s = np.cos(angle), np.sin(angle)
    if axis == 1:
        m = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    else:
        m = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.asarray(points) @ m.T


@dataclass(frozen=True, eq=False)
class Projection:
    """A projected surface: ``points (V, 3)``, ``depth (V,)`` 4D depth δ = e − w,
    ``tangents (V, 2, 3)`` projected tangents."""

    points: np.ndarray
    depth: np.ndarray
    tangents: np.ndarray


def project(vertices, tangents, rotation=None, *, projection="orthographic", eye=None,
            scale=1.0):
    """4D → 3D projection keeping the 4D depth (MATH.md §5.2, simplified form).

    Parameters
    ----------
    vertices : (V, 4) float
    tangents : (V, 2, 4) float
    rotation : (4, 4) float, optional
        Applied first (``v ← R v``); identity by default. Must be orthogonal (checked to 1e-9).
    projection : {"orthographic", "perspective"}
    eye : float, optional
        Eye position on the w-axis. Default: ``3·max|v|`` (at least 1).
    scale : float
        ``s`` (orthographic) or ``f`` (perspective: ``f = scale·eye`` so that the plane w = 0
        keeps size ``scale``).

    Returns
    -------
    Projection

    Notes
    -----
    Under perspective every vertex must satisfy ``e − w > 1e-3·e``; otherwise a ``ValueError``
    says how many vertices are behind the eye (move the eye out rather than clip: a clipped
    surface would leave holes in the halo volume).
    """
    v = as_float_array(vertices, "vertices", shape=(None, 4))
    t = as_float_array(tangents, "tangents", shape=(v.shape[0], 2, 4))
    if rotation is not None:
        r = as_matrix(rotation, "rotation")
        if not np.allclose(r @ r.T, np.eye(4), atol=1e-9, rtol=0.0):
            raise ValueError("rotation must be orthogonal (R Rᵀ = I to 1e-9)")
        v = v @ r.T
        t = (t.reshape(-1, 4) @ r.T).reshape(t.shape)    # one product, not V stacked (2, 4) ones
    kind = as_choice(projection, "projection", PROJECTIONS)
    scale = as_real(scale, "scale", lo=0.0, lo_open=True)
    radius = float(np.abs(v).max()) if v.size else 1.0
    e = 3.0 * max(radius, 1.0 / 3.0) if eye is None else as_real(eye, "eye")
    depth = e - v[:, 3]
    if kind == "orthographic":
        return Projection(scale * v[:, :3], depth, scale * t[..., :3])
    if e <= 0.0:
        raise ValueError(f"eye must be positive under perspective, got {e}")
    bad = int(np.count_nonzero(depth <= DELTA_MIN * e))
    if bad:
        raise ValueError(f"{bad} vertices are at or behind the 4D eye (w ≥ eye = {e}); "
                         "increase eye")
    f = scale * e
    pts = f * v[:, :3] / depth[:, None]
    t3 = f * (t[..., :3] * depth[:, None, None] + v[:, None, :3] * t[..., 3:4]) \
        / (depth ** 2)[:, None, None]
    return Projection(pts, depth, t3)
