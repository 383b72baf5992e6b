"""Surfaces in 4D: uv-sampled, triangulated, with per-vertex 4D tangents (Wang et al. Sec. 4.1).

4D coordinates are ``(x, y, z, w)``; for complex curves they are
``(Re z1, Im z1, Re z2, Im z2)`` (MATH.md §5.7). Every surface is a :class:`Surface4D`:
``vertices (V, 4)``, ``faces (F, 3)``, ``tangents (V, 2, 4)`` (∂/∂u, ∂/∂v per vertex, zero where
the parametrization is singular, e.g. at the poles of a spun knot) and ``colors (V, 3)``.

Tangents are central differences of the exact parametrization (one-sided at a non-periodic
border so a branch cut just outside the domain is never crossed), with a step of 1e-6 of the
parameter range: only the directions of the tangents matter (they feed the thickening normal of
Eq. 1), and differences keep every surface, including the arc-length-sampled knot, on one code
path.

Curvature-adaptive sampling (``adaptive=True``) follows the paper's "two lists of u and v
coordinates": each parameter list is placed by equidistributing, on a 4× finer grid, the sum of
the normalized chord length and the normalized turning angle of the parameter lines (maximum
over the other parameter), so the grid stays a tensor product and densifies where the surface
bends.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from .._validate import as_float_array, as_index_array, as_real

__all__ = [
    "Surface4D", "uv_surface", "merge", "spun_trefoil", "twist_spun_trefoil", "fermat_surface",
    "quadratic_fermat", "calabi_yau_quartic", "product_polynomial", "figure1_scene",
    "trefoil_arc", "colored_by_depth",
]

_FD_STEP = 1e-6
_MAX_SAMPLES = 4096


@dataclass(frozen=True, eq=False)
class Surface4D:
    """A triangulated surface in 4D.

    Attributes
    ----------
    vertices : (V, 4) float64
    faces : (F, 3) int64, oriented so that the face normal of the uv grid is t_u × t_v.
    tangents : (V, 2, 4) float64, (∂/∂u, ∂/∂v); zero rows where the parametrization is singular.
    colors : (V, 3) float64 in [0, 1].
    name : str
    """

    vertices: np.ndarray
    faces: np.ndarray
    tangents: np.ndarray
    colors: np.ndarray
    name: str = "surface"

    def __post_init__(self):
        v = as_float_array(self.vertices, "vertices", shape=(None, 4))
        n = v.shape[0]
        f = as_index_array(self.faces, "faces", shape=(None, 3), upper=max(n, 1))
        t = as_float_array(self.tangents, "tangents", shape=(n, 2, 4))
        c = as_float_array(self.colors, "colors", shape=(n, 3))
        if c.size and (c.min() < 0.0 or c.max() > 1.0):
            raise ValueError("colors must lie in [0, 1]")
        for k, a in (("vertices", v), ("faces", f), ("tangents", t), ("colors", c)):
            object.__setattr__(self, k, a)

    @property
    def n_vertices(self):
        return int(self.vertices.shape[0])

    @property
    def n_faces(self):
        return int(self.faces.shape[0])


def merge(surfaces, name="scene"):
    """Concatenate surfaces into one (faces re-indexed, order kept)."""
    vs, fs, ts, cs = [], [], [], []
    off = 0
    for s in surfaces:
        vs.append(s.vertices)
        fs.append(s.faces + off)
        ts.append(s.tangents)
        cs.append(s.colors)
        off += s.n_vertices
    return Surface4D(np.concatenate(vs), np.concatenate(fs), np.concatenate(ts),
                     np.concatenate(cs), name)


def _count(value, name, lo=2):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if not lo <= value <= _MAX_SAMPLES:
        raise ValueError(f"{name} must lie in [{lo}, {_MAX_SAMPLES}], got {value}")
    return int(value)


def _range(value, name):
    r = as_float_array(value, name, shape=(2,))
    if not r[1] > r[0]:
        raise ValueError(f"{name} must be increasing, got {tuple(r)}")
    return r


def _adaptive_params(func, lo, hi, n, other, periodic, axis):
    """n parameter values in [lo, hi] equidistributing chord length + turning angle."""
    fine = 4 * n
    s = np.linspace(lo, hi, fine + 1)
    uu, vv = (np.meshgrid(s, other, indexing="ij") if axis == 0
              else np.meshgrid(other, s, indexing="ij"))
    p = func(uu, vv)
    if axis == 1:
        p = p.transpose(1, 0, 2)
    seg = np.diff(p, axis=0)                       # (fine, M, 4)
    length = np.linalg.norm(seg, axis=2)
    cosang = np.einsum("ijk,ijk->ij", seg[1:], seg[:-1]) / np.maximum(
        length[1:] * length[:-1], 1e-300)
    ang = np.arccos(np.clip(cosang, -1.0, 1.0))   # (fine - 1, M), at interior fine nodes
    turn = np.zeros(fine)
    turn[:-1] += 0.5 * ang.max(axis=1)
    turn[1:] += 0.5 * ang.max(axis=1)
    chord = length.max(axis=1)
    w = chord / max(chord.sum(), 1e-300) + turn / max(turn.sum(), 1e-300)
    cum = np.concatenate([[0.0], np.cumsum(w)])
    m = n if periodic else n - 1
    target = np.linspace(0.0, cum[-1], m + 1)
    out = np.interp(target, cum, s)
    return out[:-1] if periodic else out


def _params(func, rng, n, periodic, adaptive, other_rng, n_other, axis):
    if adaptive:
        other = np.linspace(other_rng[0], other_rng[1], 2 * n_other + 1)
        return _adaptive_params(func, rng[0], rng[1], n, other, periodic, axis)
    return np.linspace(rng[0], rng[1], n, endpoint=not periodic)


def _fd(func, uu, vv, h, lo, hi, periodic, axis):
    """Central difference along one parameter; one-sided at a non-periodic border."""
    a = uu if axis == 0 else vv
    plus = a + h
    minus = a - h
    if not periodic:
        plus = np.minimum(plus, hi)
        minus = np.maximum(minus, lo)
    if axis == 0:
        fp, fm = func(plus, vv), func(minus, vv)
    else:
        fp, fm = func(uu, plus), func(uu, minus)
    return (fp - fm) / (plus - minus)[..., None]


def uv_surface(func, u_range, v_range, nu, nv, *, periodic_u=False, periodic_v=False,
               poles=False, adaptive=False, color=None, name="surface"):
    """Sample and triangulate a parametrized surface ``func(u, v) -> (..., 4)``.

    Parameters
    ----------
    func : callable
        Vectorized parametrization: arrays ``u, v`` of one shape → positions ``(..., 4)``.
    u_range, v_range : (2,) float
        Parameter intervals (the end is excluded on a periodic parameter).
    nu, nv : int
        Samples per parameter (2 … 4096).
    periodic_u, periodic_v : bool
        Close the grid in u / v.
    poles : bool
        The rows ``u = u_range[0]`` and ``u = u_range[1]`` each collapse to one point (a spun
        arc's endpoints): they become one vertex each with zero tangents, meshed as triangle
        fans, so no degenerate triangle is produced.
    adaptive : bool
        Curvature-adaptive parameter lists (module docstring).
    color : callable or (3,) float, optional
        ``color(u, v) -> (..., 3)`` in [0, 1], or one colour; white by default.

    Returns
    -------
    Surface4D
    """
    u_range = _range(u_range, "u_range")
    v_range = _range(v_range, "v_range")
    nu = _count(nu, "nu", 3 if poles else 2)
    nv = _count(nv, "nv", 3 if periodic_v else 2)
    if poles and periodic_u:
        raise ValueError("poles and periodic_u exclude each other")
    us = _params(func, u_range, nu, periodic_u, adaptive, v_range, nv, 0)
    vs = _params(func, v_range, nv, periodic_v, adaptive, u_range, nu, 1)
    uu, vv = np.meshgrid(us, vs, indexing="ij")
    pos = np.asarray(func(uu, vv), dtype=np.float64)
    hu = _FD_STEP * (u_range[1] - u_range[0])
    hv = _FD_STEP * (v_range[1] - v_range[0])
    tu = _fd(func, uu, vv, hu, *u_range, periodic_u, 0)
    tv = _fd(func, uu, vv, hv, *v_range, periodic_v, 1)
    if color is None:
        col = np.ones(uu.shape + (3,))
    elif callable(color):
        col = np.asarray(color(uu, vv), dtype=np.float64)
    else:
        col = np.broadcast_to(as_float_array(color, "color", shape=(3,)), uu.shape + (3,))
    idx = np.arange(nu * nv).reshape(nu, nv)
    cu = nu if periodic_u else nu - 1
    cv = nv if periodic_v else nv - 1
    i, j = np.meshgrid(np.arange(cu), np.arange(cv), indexing="ij")
    a = idx[i, j]
    b = idx[(i + 1) % nu, j]
    c = idx[(i + 1) % nu, (j + 1) % nv]
    d = idx[i, (j + 1) % nv]
    # (a, b, c) with b along +u and c diagonal: counter-clockwise in (u, v), normal t_u × t_v
    quads = np.stack([a, b, c, d], axis=-1).reshape(-1, 4)
    rows = i.reshape(-1)
    vert = pos.reshape(-1, 4)
    tang = np.stack([tu, tv], axis=2).reshape(-1, 2, 4)
    cols = np.array(col, dtype=np.float64).reshape(-1, 3)
    if not poles:
        faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        return Surface4D(vert, faces, tang, cols, name)
    # poles: rows 0 and nu-1 become single vertices; quads touching them become fan triangles
    interior = np.arange(nv, (nu - 1) * nv)
    remap = np.full(nu * nv, -1, np.int64)
    remap[interior] = np.arange(interior.size)
    p0, p1 = interior.size, interior.size + 1
    remap[:nv] = p0
    remap[(nu - 1) * nv:] = p1
    first = rows == 0
    last = rows == nu - 2
    mid = ~(first | last)
    q = remap[quads]
    faces = np.concatenate([
        q[first][:, [0, 1, 2]],                 # pole, b, c
        q[mid][:, [0, 1, 2]], q[mid][:, [0, 2, 3]],
        q[last][:, [0, 2, 3]],                  # a, pole, d
    ])
    vert_out = np.concatenate([vert[interior], vert[[0]], vert[[(nu - 1) * nv]]])
    tang_out = np.concatenate([tang[interior], np.zeros((2, 2, 4))])
    col_out = np.concatenate([cols[interior], cols[[0]], cols[[(nu - 1) * nv]]])
    return Surface4D(vert_out, faces, tang_out, col_out, name)


def _hue(h, s=0.75, v=1.0):
    return np.array(colorsys.hsv_to_rgb(h % 1.0, s, v))


def _hsv(h, s):
    """Vectorized HSV → RGB at value 1 (the hue ramp of the knots)."""
    h6 = (np.asarray(h) % 1.0) * 6.0
    k = np.stack([(5.0 + h6) % 6.0, (3.0 + h6) % 6.0, (1.0 + h6) % 6.0], axis=-1)
    return 1.0 - s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


# ----------------------------------------------------------------------------- knots (§5.7)
# Revised construction (MATH.md §5.7, "keep the knot next to the spinning plane").
_DELTA = 0.15      # the trefoil K(u) is cut open for u ∈ (−δ, δ), around its maximum x = 3
_EPS = 0.2         # clearance between the knotted part and the spinning plane
#: spun trefoil: the plane x = Xp just beyond the cut (max x of the trefoil is 3)
SPUN_XP = 3.0 + _EPS
#: twist-spun trefoil: the knot body is the trefoil scaled by TWIST_SCALE (|K| ≤ 2.7), held
#: by the ball |p| ≤ RB = 2.9 that turns; the connector circle (radius 2.8) inside it; the plane
#: tangent to the ball plus the clearance, Xp = 3.1. Each leg runs from an exit point on the
#: turning axis to the plane, so it is Xp = RB + ε long: it cannot be shorter than RB (the ball
#: must clear the plane), and the scale keeps it ≤ 3.2 (issue 21).
TWIST_SCALE = 0.9
TWIST_RB = 2.9
_RC = 2.8
TWIST_XP = TWIST_RB + _EPS


def _trefoil(u):
    u = np.asarray(u, dtype=np.float64)
    return np.stack([(2 + np.cos(3 * u)) * np.cos(2 * u), (2 + np.cos(3 * u)) * np.sin(2 * u),
                     np.sin(3 * u)], axis=-1)


def _trefoil_d(u):
    u = np.asarray(u, dtype=np.float64)
    r, dr = 2 + np.cos(3 * u), -3 * np.sin(3 * u)
    return np.stack([dr * np.cos(2 * u) - 2 * r * np.sin(2 * u),
                     dr * np.sin(2 * u) + 2 * r * np.cos(2 * u), 3 * np.cos(3 * u)], axis=-1)


def _hermite(p0, t0, p1, t1, m=120):
    s = np.linspace(0.0, 1.0, m)[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * p0 + h10 * t0 + h01 * p1 + h11 * t1


def _densify(pts, step=0.01):
    """Insert points so that no segment is longer than ``step`` (uniform arc-length lookup)."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    out = [pts[:1]]
    for p, q, s in zip(pts[:-1], pts[1:], seg):
        if s == 0.0:
            continue
        k = max(1, int(np.ceil(s / step)))
        out.append(p + (q - p) * (np.arange(1, k + 1) / k)[:, None])
    return np.vstack(out)


def _spun_polyline(m=6000):
    """Knotted arc of the spun trefoil: K on [δ, 2π − δ], joined at both cut ends to the plane
    x = Xp by a fillet that leaves K along its tangent and arrives along +x (perpendicular to
    the plane, so the spun surface is smooth at its poles). From (Xp, y(δ), z(δ)) to
    (Xp, −y(δ), −z(δ))."""
    u = np.linspace(_DELTA, 2 * np.pi - _DELTA, m)
    body = _trefoil(u)

    def fillet(uu, sign):
        p0 = _trefoil(uu)
        t0 = _trefoil_d(uu)
        t0 = -sign * t0 / np.linalg.norm(t0)          # pointing away from the body
        p1 = np.array([SPUN_XP, p0[1], p0[2]])
        gap = SPUN_XP - p0[0]
        return _hermite(p0, 1.5 * gap * t0, p1, np.array([1.5 * gap, 0.0, 0.0]))

    head = fillet(_DELTA, 1.0)[::-1]
    tail = fillet(2 * np.pi - _DELTA, -1.0)
    return _densify(np.concatenate([head[:-1], body, tail[1:]]))


def _twist_polyline(m=6000):
    """Knotted arc of the twist-spun trefoil: 0.9·K on [δ, 2π − δ]; inside the ball |p| ≤ RB
    each cut end goes radially out to the circle of radius Rc in z = 0, along it to the y-axis
    and out to the exit point (0, ±RB, 0); outside the ball a straight leg of length RB + ε
    runs along +x to the plane x = Xp."""
    u = np.linspace(_DELTA, 2 * np.pi - _DELTA, m)
    body = TWIST_SCALE * _trefoil(u)

    def connector(end, sign):
        th0 = np.arctan2(end[1], end[0])
        r0 = np.hypot(end[0], end[1])
        k = np.linspace(0.0, 1.0, 200)
        radial = np.stack([(r0 + k * (_RC - r0)) * np.cos(th0), (r0 + k * (_RC - r0)) * np.sin(th0),
                           (1 - k) * end[2]], axis=1)
        th = np.linspace(th0, sign * np.pi / 2, 400)
        circle = np.stack([_RC * np.cos(th), _RC * np.sin(th), np.zeros_like(th)], axis=1)
        out = np.array([[0.0, sign * TWIST_RB, 0.0], [TWIST_XP, sign * TWIST_RB, 0.0]])
        return np.concatenate([radial, circle[1:], out])

    head = connector(body[0], 1.0)[::-1]
    tail = connector(body[-1], -1.0)
    return _densify(np.concatenate([head[:-1], body, tail[1:]]))


_ARCS = {}


def trefoil_arc(twist=False):
    """``(points (M, 3), arclength (M,))`` of the knotted arc α: of the spun trefoil, or with
    ``twist=True`` of the twist-spun one (MATH.md §5.7, revised construction)."""
    key = bool(twist)
    if key not in _ARCS:
        p = _twist_polyline() if key else _spun_polyline()
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        _ARCS[key] = (p, s)
    return _ARCS[key]


def _spin(k, twist):
    p, cum = trefoil_arc(twist)
    xp = TWIST_XP if twist else SPUN_XP

    def func(s, phi):
        a = np.stack([np.interp(s, cum, p[:, j]) for j in range(3)], axis=-1)
        x, y, z = a[..., 0], a[..., 1], a[..., 2]
        if k:
            inside = x * x + y * y + z * z <= TWIST_RB * TWIST_RB
            c, sn = np.cos(k * phi), np.sin(k * phi)
            xr = np.where(inside, x * c + z * sn, x)
            zr = np.where(inside, -x * sn + z * c, z)
            x, z = xr, zr
        r = xp - x
        return np.stack([xp - r * np.cos(phi), y, z, r * np.sin(phi)], axis=-1)
    return func


def _knot_color(total):
    def color(s, phi):
        return _hsv(0.6 - 0.6 * s / total, 0.65)
    return color


def twist_spun_trefoil(n_s=200, n_phi=50, *, k=2, adaptive=False):
    """Zeeman's k-twist-spun trefoil (MATH.md §5.7; k = 2 default [guess]); a 2-sphere in 4D.

    The knotted arc α (the trefoil scaled by 0.9 and cut open; inside the ball |p| ≤ RB = 2.9
    connectors to the exit points (0, ±RB, 0); legs of length RB + ε = 3.1 to the plane
    x = Xp = RB + 0.2) is spun
    about that plane: ``S(s, φ) = (Xp − r cos φ, y, z, r sin φ)`` with ``r = Xp − x``; inside
    the ball the arc is first rotated by kφ about the y-axis (the line through the exit points).
    ``s`` is arc length; the two ends (r = 0) are the sphere's poles, meshed as fans.
    ``2·(n_s − 2)·n_phi`` triangles (n_s = 200, n_phi = 50 → 19 800).
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"k must be an int (the surface closes only for integer k), got {k!r}")
    total = trefoil_arc(True)[1][-1]
    name = "ball-spun trefoil" if k == 0 else f"{k}-twist-spun trefoil"
    return uv_surface(_spin(int(k), True), (0.0, total), (0.0, 2 * np.pi), n_s, n_phi,
                      periodic_v=True, poles=True, adaptive=adaptive, color=_knot_color(total),
                      name=name)


def spun_trefoil(n_s=200, n_phi=50, *, adaptive=False, cut_open=False, band=None):
    """Artin's spun trefoil (Wang et al. Fig. 5), a knotted 2-sphere in 4D.

    The trefoil, cut open at its maximum x, is joined by two short fillets to the plane
    x = Xp = 3.2 and spun about it: ``S(s, φ) = (Xp − r cos φ, y, z, r sin φ)``, ``r = Xp − x``
    (MATH.md §5.7, revised construction: no ball, no legs; the knot is spun at radius
    0.2 … 5.6). ``2·(n_s − 2)·n_phi`` triangles. ``cut_open=True`` keeps half of the sphere,
    φ ∈ [0, π] (a disc whose boundary is the knotted arc and its mirror image, for pictures
    that show the inside). ``band=b`` (not in the paper) keeps the band φ ∈ [−b, b] around
    the meridian φ = 0: a ribbon whose centre line is the knotted arc, so that a view along
    the spin direction shows the knot's diagram with the halos' gaps at its three crossings
    (``2·(n_s − 2)·(n_phi − 1)`` triangles).
    """
    total = trefoil_arc(False)[1][-1]
    if band is not None:
        if cut_open:
            raise ValueError("band and cut_open exclude each other")
        band = as_real(band, "band", lo=0.0, hi=np.pi / 2, lo_open=True)
        return uv_surface(_spin(0, False), (0.0, total), (-band, band), n_s, n_phi, poles=True,
                          adaptive=adaptive, color=_knot_color(total),
                          name="spun trefoil, band")
    if cut_open:
        return uv_surface(_spin(0, False), (0.0, total), (0.0, np.pi), n_s, n_phi, poles=True,
                          adaptive=adaptive, color=_knot_color(total),
                          name="spun trefoil, cut open")
    return uv_surface(_spin(0, False), (0.0, total), (0.0, 2 * np.pi), n_s, n_phi,
                      periodic_v=True, poles=True, adaptive=adaptive, color=_knot_color(total),
                      name="spun trefoil")


def colored_by_depth(surface, rotation=None, saturation=0.85):
    """``surface`` with its vertices coloured by their 4D depth in the view ``rotation``
    (orthographic: δ = e − w of the rotated vertex): a hue ramp from red (nearest in 4D)
    through yellow and green to blue (farthest), spread over the surface's depth range."""
    if not isinstance(surface, Surface4D):
        raise TypeError(f"surface must be a Surface4D, got {type(surface).__name__}")
    saturation = as_real(saturation, "saturation", lo=0.0, hi=1.0)
    r = np.eye(4) if rotation is None else as_float_array(rotation, "rotation", shape=(4, 4))
    w = surface.vertices @ r[3]
    span = float(w.max() - w.min())
    q = (w - w.min()) / span if span > 0 else np.full_like(w, 0.5)
    cols = _hsv(0.66 * (1.0 - q), saturation)
    return Surface4D(surface.vertices, surface.faces, surface.tangents, cols,
                     f"{surface.name}, coloured by 4D depth")


# ----------------------------------------------------------------------------- CP² curves
def _fermat_patch(n, k1, k2):
    e1 = np.exp(2j * np.pi * k1 / n)
    e2 = np.exp(2j * np.pi * k2 / n)

    def func(x, y):
        zeta = x + 1j * y
        z1 = e1 * np.cos(zeta) ** (2.0 / n)
        z2 = e2 * np.sin(zeta) ** (2.0 / n)
        return np.stack([z1.real, z1.imag, z2.real, z2.imag], axis=-1)
    return func


def fermat_surface(n, n_x=24, n_y=24, *, a=1.2, adaptive=False):
    """Fermat curve z1ⁿ + z2ⁿ = 1 in C² (Hanson 1994; MATH.md §5.7), n² patches.

    Patch (k1, k2): ``z1 = e^{2πik1/n} cos(ζ)^{2/n}``, ``z2 = e^{2πik2/n} sin(ζ)^{2/n}``,
    ``ζ = x + iy``, ``x ∈ [0, π/2]``, ``y ∈ [−a, a]`` (principal powers; the branch cut is never
    crossed on the patch). Coordinates ``(Re z1, Im z1, Re z2, Im z2)``; each patch has its own
    hue.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 2 <= n <= 8:
        raise ValueError(f"n must be an int in [2, 8], got {n!r}")
    a = as_real(a, "a", lo=0.0, hi=5.0, lo_open=True)
    parts = []
    for k1 in range(n):
        for k2 in range(n):
            col = _hue((k1 * n + k2) / (n * n), 0.6)
            parts.append(uv_surface(_fermat_patch(n, k1, k2), (0.0, np.pi / 2), (-a, a), n_x, n_y,
                                    adaptive=adaptive, color=col))
    return merge(parts, f"Fermat n={n}")


def quadratic_fermat(n_x=32, n_y=32, *, a=1.2, adaptive=False):
    """z1² + z2² = 1 (Wang et al. Fig. 6a): 4 patches."""
    return fermat_surface(2, n_x, n_y, a=a, adaptive=adaptive)


def calabi_yau_quartic(n_x=16, n_y=16, *, a=1.2, adaptive=False):
    """The Calabi–Yau (K3) quartic cross-section z1⁴ + z2⁴ = 1 (Fig. 6b): 16 patches."""
    return fermat_surface(4, n_x, n_y, a=a, adaptive=adaptive)


def product_polynomial(n_xi=24, n_theta=48, *, a=1.2, adaptive=False):
    """z1² z2² = 1 (Fig. 7), MATH.md §5.7 [derived]: 4 patches (k1, k2) ∈ {0, 1}².

    ``z1 = e^{πik1} e^{ω/2}``, ``z2 = e^{πik2} e^{−ω/2}``, ``ω = ξ + iθ``, ``ξ ∈ [−a, a]``,
    ``θ ∈ [0, 2π]``. (0,0)+(1,1) tile the cylinder z1 z2 = 1, (0,1)+(1,0) the cylinder
    z1 z2 = −1.
    """
    a = as_real(a, "a", lo=0.0, hi=5.0, lo_open=True)
    parts = []
    for k1 in range(2):
        for k2 in range(2):
            def func(xi, th, k1=k1, k2=k2):
                om = xi + 1j * th
                z1 = np.exp(1j * np.pi * k1) * np.exp(om / 2)
                z2 = np.exp(1j * np.pi * k2) * np.exp(-om / 2)
                return np.stack([z1.real, z1.imag, z2.real, z2.imag], axis=-1)
            parts.append(uv_surface(func, (-a, a), (0.0, 2 * np.pi), n_xi, n_theta,
                                    adaptive=adaptive, color=_hue(0.1 + 0.25 * (2 * k1 + k2), 0.6)))
    return merge(parts, "z1² z2² = 1")


# ----------------------------------------------------------------------------- Fig. 1
FIGURE1_W = (0.1, 0.2, 0.3, 0.4, 0.5)
FIGURE1_X = (-0.8, -0.4, 0.0, 0.4, 0.8)
_FIG1_COLORS = ((0.95, 0.25, 0.2), (1.0, 0.6, 0.1), (0.95, 0.9, 0.2), (0.3, 0.85, 0.3),
                (0.3, 0.5, 1.0))


def figure1_scene(n=24, *, w_values=FIGURE1_W):
    """Wang et al. Fig. 1: a white square at w = 0 crossed by five coloured strips.

    The white patch is ``(u, v, 0, 0)`` for ``u, v ∈ [−1, 1]``. Strip i is the tilted rectangle
    ``(x_i + 0.35·a, 0.7·b, 0.94·a, w_i)`` for ``a ∈ [−0.5, 0.5]``, ``b ∈ [−1, 1]``, with
    ``x_i = −0.8, −0.4, 0, 0.4, 0.8`` and ``w_i = 0.1 … 0.5``: in the projection along w it
    pierces the white patch along the line ``x = x_i``, while in 4D it lies ``w_i`` above it
    (nearer the eye, which looks along −w). Colours: red, orange, yellow, green, blue.
    """
    w_values = as_float_array(w_values, "w_values", shape=(None,))
    if not 1 <= w_values.size <= 5:
        raise ValueError(f"w_values must hold 1 to 5 values, got {w_values.size}")
    parts = [uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1), (-1, 1),
                        n, n, color=(1.0, 1.0, 1.0))]
    for i, w in enumerate(w_values):
        def func(a, b, x0=FIGURE1_X[i], w=float(w)):
            return np.stack([x0 + 0.35 * a, 0.7 * b, 0.94 * a, np.full_like(a, w)], axis=-1)
        parts.append(uv_surface(func, (-0.5, 0.5), (-1, 1), max(2, n // 3), n,
                                color=_FIG1_COLORS[i]))
    return merge(parts, "Fig. 1 scene")
