"""Canonical solids: procedural, deterministic, watertight test meshes.

Every function returns a :class:`trimesh.Trimesh` built with ``process=False`` (so trimesh never
merges, reorders or drops anything behind our back) whose faces are wound counter-clockwise seen
from outside (front = CCW, OpenGL's default). Each solid is a closed 2-manifold with positive
volume (``mesh.is_watertight`` and ``mesh.is_volume``), and the same call always returns
bit-identical ``vertices`` and ``faces`` arrays.

Face counts at the default parameters (pinned by ``tests/test_scenes.py``):

=====================  ==========  ===================================================
solid                  faces       how it is made
=====================  ==========  ===================================================
:func:`cube`                   12  ``trimesh.creation.box``
:func:`icosphere`           1 280  ``trimesh.creation.icosphere``, 20·4^s faces
:func:`torus`               2 304  (u, v) grid, 2·M·N faces
:func:`fluted_column`      13 760  revolved profile with flutes, hand-built grid
:func:`nested_shells`       5 120  icospheres, inner surfaces reversed
:func:`building`              260  boxes subtracted with manifold3d
:func:`crank`              99 404  revolved journals, extruded webs, manifold3d booleans
=====================  ==========  ===================================================

The two manifold3d solids (:func:`building`, :func:`crank`) depend on manifold3d's boolean
triangulation; their face counts are pinned for the manifold3d version the tests ran with.
"""

from __future__ import annotations

import numbers

import numpy as np

__all__ = [
    "cube", "icosphere", "torus", "fluted_column", "nested_shells", "building", "crank",
]


def _as_int(value, name, lo, hi):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    value = int(value)
    if not lo <= value <= hi:
        raise ValueError(f"{name} must lie in [{lo}, {hi}], got {value}")
    return value


def _as_positive(value, name):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be finite and positive, got {value}")
    return value


def _trimesh(vertices, faces):
    import trimesh
    return trimesh.Trimesh(
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64), process=False)


def _from_manifold(solid):
    # to_mesh64 keeps double-precision vertices (to_mesh rounds them to float32).
    mesh = solid.to_mesh64()
    return _trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def _grid_faces(rows, cols):
    """Quads of a (rows × cols) vertex grid, periodic in the column direction, as triangles.

    Vertex ``(i, j)`` has index ``i·cols + j``; with rows going "up" and columns going CCW
    around the outward normal, triangles come out CCW seen from outside.
    """
    i, j = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    a = i * cols + j
    b = i * cols + (j + 1) % cols
    c = (i + 1) * cols + (j + 1) % cols
    d = (i + 1) * cols + j
    lower = np.stack([a, b, c], axis=-1).reshape(-1, 3)
    upper = np.stack([a, c, d], axis=-1).reshape(-1, 3)
    return np.stack([lower, upper], axis=1).reshape(-1, 3)


def cube(size=1.0):
    """An axis-aligned cube centred on the origin.

    Parameters
    ----------
    size : float
        Edge length.

    Returns
    -------
    trimesh.Trimesh
        8 vertices, 12 faces.
    """
    import trimesh
    size = _as_positive(size, "size")
    box = trimesh.creation.box(extents=(size, size, size))
    return _trimesh(box.vertices, box.faces)


def icosphere(subdivisions=3, radius=1.0):
    """A geodesic sphere: the icosahedron subdivided ``subdivisions`` times.

    Parameters
    ----------
    subdivisions : int in [0, 7]
        Each level splits every triangle into four.
    radius : float

    Returns
    -------
    trimesh.Trimesh
        ``20·4^subdivisions`` faces (1 280 for the default 3) and ``10·4^s + 2`` vertices.
    """
    import trimesh
    subdivisions = _as_int(subdivisions, "subdivisions", 0, 7)
    radius = _as_positive(radius, "radius")
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return _trimesh(s.vertices, s.faces)


def torus(major_radius=1.0, minor_radius=0.35, major_segments=64, minor_segments=18):
    """A ring torus around the +Y axis.

    Parameters
    ----------
    major_radius : float
        Distance from the axis to the centre of the tube.
    minor_radius : float
        Tube radius, smaller than ``major_radius``.
    major_segments, minor_segments : int
        Samples around the axis and around the tube.

    Returns
    -------
    trimesh.Trimesh
        ``2·major_segments·minor_segments`` faces (2 304 by default), genus 1.
    """
    big = _as_positive(major_radius, "major_radius")
    small = _as_positive(minor_radius, "minor_radius")
    if not small < big:
        raise ValueError(
            f"minor_radius must be smaller than major_radius, got {small} >= {big}")
    m = _as_int(major_segments, "major_segments", 3, 4096)
    n = _as_int(minor_segments, "minor_segments", 3, 4096)
    # Rows run around the tube (v), columns around the axis (u); with z = −ρ·sin(u) the grid's
    # triangles come out CCW seen from outside (the tests check is_volume).
    v = 2.0 * np.pi * np.arange(n + 1) / n
    u = 2.0 * np.pi * np.arange(m) / m
    rho = big + small * np.cos(v)[:, None]
    x = rho * np.cos(u)[None, :]
    z = -rho * np.sin(u)[None, :]
    y = np.broadcast_to(small * np.sin(v)[:, None], x.shape)
    vertices = np.stack([x, y, z], axis=-1)[:n].reshape(-1, 3)
    faces = _grid_faces(n + 1, m) % (n * m)
    return _trimesh(vertices, faces)


# Profile of the column: (radius, height) breakpoints from the bottom of the plinth to the top of
# the abacus, with a torus moulding at the base and an echinus at the top.
def _column_profile(height, radius, rings):
    base_h, cap_h = 0.12 * height, 0.10 * height
    shaft_lo, shaft_hi = base_h, height - cap_h
    # plinth (a squat drum) and a half-round torus moulding
    t = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 9)
    torus_r = radius * 1.05 + 0.04 * height * np.cos(t)
    torus_z = 0.06 * height + 0.04 * height * (1.0 + np.sin(t)) * 0.5 + 0.02 * height
    plinth = [(radius * 1.3, 0.0), (radius * 1.3, 0.06 * height)]
    # shaft with entasis: a slight bulge and a taper to 0.85 r at the top
    s = np.linspace(0.0, 1.0, rings)
    shaft_r = radius * (1.0 - 0.15 * s + 0.06 * np.sin(np.pi * s))
    shaft_z = shaft_lo + s * (shaft_hi - shaft_lo)
    # echinus: a quarter-round flaring out to the abacus
    e = np.linspace(0.0, 0.5 * np.pi, 7)[1:]
    ech_r = shaft_r[-1] + (1.3 * radius - shaft_r[-1]) * np.sin(e)
    ech_z = shaft_hi + 0.6 * cap_h * (1.0 - np.cos(e))
    abacus = [(1.35 * radius, shaft_hi + 0.6 * cap_h), (1.35 * radius, height)]
    r = np.concatenate([[p[0] for p in plinth], torus_r, shaft_r, ech_r,
                        [p[0] for p in abacus]])
    z = np.concatenate([[p[1] for p in plinth], torus_z, shaft_z, ech_z,
                        [p[1] for p in abacus]])
    in_shaft = np.zeros(len(r), dtype=bool)
    first = len(plinth) + len(torus_r)
    in_shaft[first:first + rings] = True
    flute_depth = np.zeros(len(r))
    # flutes fade in and out over the lowest and highest tenth of the shaft (rounded ends)
    fade = np.clip(np.minimum(s, 1.0 - s) / 0.1, 0.0, 1.0)
    flute_depth[first:first + rings] = np.sqrt(fade * (2.0 - fade))
    return r, z, flute_depth


def fluted_column(flutes=20, height=4.0, radius=0.4, samples_per_flute=8, rings=24):
    """A classical column: plinth, torus moulding, fluted shaft with entasis, echinus, abacus.

    The surface is a revolved profile ``r(z)`` whose shaft radius is cut by ``flutes``
    semicircular grooves separated by flat fillets; each groove's depth fades to zero at the
    ends of the shaft. The column stands on ``y = 0`` around the +Y axis.

    Parameters
    ----------
    flutes : int
        Number of flutes (Doric 20, Ionic 24).
    height, radius : float
        Total height and the shaft radius at its foot.
    samples_per_flute : int
        Angular samples per flute (groove plus fillet).
    rings : int
        Profile samples along the shaft.

    Returns
    -------
    trimesh.Trimesh
        With ``P = rings + 19`` profile rings and ``M = flutes·samples_per_flute`` angular
        samples: ``2·M·P`` faces (side quads plus two cap fans); 13 760 by default
        (``P = 43``, ``M = 160``).
    """
    flutes = _as_int(flutes, "flutes", 3, 256)
    height = _as_positive(height, "height")
    radius = _as_positive(radius, "radius")
    k = _as_int(samples_per_flute, "samples_per_flute", 4, 256)
    rings = _as_int(rings, "rings", 2, 4096)
    r, z, depth = _column_profile(height, radius, rings)
    m = flutes * k
    theta = 2.0 * np.pi * np.arange(m) / m
    # Within one flute, phase in [0, 1): the groove occupies the middle 80 %, fillets the rest.
    phase = (np.arange(m) % k) / k
    g = np.clip((phase - 0.1) / 0.8, 0.0, 1.0)
    groove = np.sqrt(np.clip(1.0 - (2.0 * g - 1.0) ** 2, 0.0, 1.0))
    flute_radius = 0.8 * np.pi * radius / flutes  # half the groove's chord
    rr = r[:, None] - 0.6 * flute_radius * depth[:, None] * groove[None, :]
    x = rr * np.cos(theta)[None, :]
    zz = -rr * np.sin(theta)[None, :]
    yy = np.broadcast_to(z[:, None], x.shape)
    ring_vertices = np.stack([x, yy, zz], axis=-1).reshape(-1, 3)
    p = len(r)
    side = _grid_faces(p, m)
    bottom_c, top_c = p * m, p * m + 1
    j = np.arange(m)
    bottom = np.stack([np.full(m, bottom_c), (j + 1) % m, j], axis=-1)
    top = np.stack([np.full(m, top_c), (p - 1) * m + j, (p - 1) * m + (j + 1) % m], axis=-1)
    vertices = np.concatenate([ring_vertices, [[0.0, z[0], 0.0], [0.0, z[-1], 0.0]]])
    return _trimesh(vertices, np.concatenate([side, bottom, top]))


def nested_shells(radii=(1.0, 0.8, 0.6, 0.4), subdivisions=3):
    """Concentric spherical shells as one watertight solid with cavities.

    ``radii`` are decreasing and come in pairs: each pair ``(outer, inner)`` is a shell whose
    outer sphere faces outwards and whose inner sphere is reversed (faces inwards, into the
    cavity). The default gives two shells: 0.8 < |p| < 1 and 0.4 < |p| < 0.6. A ray from outside
    through the centre crosses 2·len(radii) surfaces, alternating front and back faces — the
    depth complexity the layered-depth-image techniques need.

    Parameters
    ----------
    radii : sequence of float
        Even count, strictly decreasing, positive.
    subdivisions : int
        Icosphere subdivisions of every sphere.

    Returns
    -------
    trimesh.Trimesh
        ``len(radii)·20·4^subdivisions`` faces (5 120 by default); the spheres are stored outermost
        first, so face ``f`` belongs to sphere ``f // (20·4^s)``.
    """
    radii = [_as_positive(r, f"radii[{i}]") for i, r in enumerate(radii)]
    if len(radii) == 0 or len(radii) % 2:
        raise ValueError(f"radii must have an even, non-zero count, got {len(radii)}")
    if any(b >= a for a, b in zip(radii, radii[1:])):
        raise ValueError(f"radii must be strictly decreasing, got {radii}")
    unit = icosphere(subdivisions)
    vertices, faces = [], []
    for i, rad in enumerate(radii):
        f = unit.faces if i % 2 == 0 else unit.faces[:, ::-1]
        vertices.append(unit.vertices * rad)
        faces.append(f + i * len(unit.vertices))
    return _trimesh(np.concatenate(vertices), np.concatenate(faces))


def _box(lo, hi):
    import manifold3d
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return manifold3d.Manifold.cube(list(hi - lo)).translate(list(lo))


# Openings of the building: (lo, hi) corners. Sills sit 5 cm above the floors so that no cut is
# coplanar with a room's floor (booleans on coplanar faces are exact in manifold3d, but slivers
# would make the face count fragile).
_ROOMS = [  # ground: A, B; upper: C, D
    ((0.25, 0.25, 0.25), (5.875, 3.0, 6.75)),
    ((6.125, 0.25, 0.25), (9.75, 3.0, 6.75)),
    ((0.25, 3.25, 0.25), (3.875, 6.0, 6.75)),
    ((4.125, 3.25, 0.25), (9.75, 6.0, 6.75)),
]
_DOORS = [
    ((2.0, 0.3, -0.1), (3.0, 2.35, 0.35)),     # front door into A
    ((5.8, 0.3, 3.0), (6.2, 2.35, 4.0)),       # A ↔ B
    ((3.8, 3.3, 1.0), (4.2, 5.35, 2.0)),       # C ↔ D
    ((7.0, 3.3, 6.65), (8.0, 5.35, 7.1)),      # D → back balcony
]
_WINDOWS = [
    ((7.0, 1.0, -0.1), (8.8, 2.2, 0.35)),
    ((1.2, 4.0, -0.1), (2.8, 5.2, 0.35)),
    ((5.5, 4.0, -0.1), (7.0, 5.2, 0.35)),
    ((7.8, 4.0, -0.1), (9.3, 5.2, 0.35)),
    ((-0.1, 1.0, 2.5), (0.35, 2.2, 4.5)),
]
_STAIRWELL = ((7.0, 2.9, 5.0), (9.0, 3.35, 6.5))  # B ↔ D through the floor slab


def building():
    """A two-storey house: walls and floor slabs with four rooms, doors, windows, a stairwell.

    Footprint [0, 10] × [0, 7] (x, z), height 6.25 (y up), walls and slabs 0.25 thick; the
    front door and most windows face +Z, one window faces +X. Ground floor: rooms
    A and B joined by a door, a front door into A; upper floor: rooms C and D joined by a door,
    a back door from D; a stairwell through the slab joins B and D; five windows. Every room is
    reachable from outside, so the solid has no sealed cavity, and its genus is the number of
    openings.

    Returns
    -------
    trimesh.Trimesh
        Built with manifold3d (outer box minus rooms and openings): 260 faces, volume 101.4925,
        genus 6.
    """
    import manifold3d
    solid = _box((0.0, 0.0, 0.0), (10.0, 6.25, 7.0))
    cuts = [_box(lo, hi) for lo, hi in _ROOMS + _DOORS + _WINDOWS + [_STAIRWELL]]
    solid = solid - manifold3d.Manifold.batch_boolean(cuts, manifold3d.OpType.Add)
    # Turn the front (drawn at z = 0 above) to face +Z, towards the default gallery camera.
    solid = solid.rotate([0.0, 180.0, 0.0]).translate([10.0, 0.0, 7.0])
    return _from_manifold(solid)


def _revolved(profile, segments):
    """Revolve a closed (r, z) polygon around the z axis."""
    import manifold3d
    return manifold3d.Manifold.revolve(manifold3d.CrossSection([profile]), segments)


def _journal(radius, length, fillet, segments, steps=6, overlap=0.05):
    """A cylinder along z from 0 to ``length`` whose ends flare by a quarter-round fillet.

    It reaches ``overlap`` further at both ends, into the webs it joins: solids that only touch
    are not merged by a boolean union (manifold3d's symbolic perturbation keeps them apart).
    """
    t = np.linspace(0.0, 0.5 * np.pi, steps + 1)
    # lower fillet: from (radius + fillet, 0) curving in to (radius, fillet)
    lower = np.stack([radius + fillet - fillet * np.sin(t), fillet - fillet * np.cos(t)], -1)
    upper = np.stack([radius + fillet - fillet * np.sin(t[::-1]),
                      length - fillet + fillet * np.cos(t[::-1])], -1)
    profile = np.concatenate([[[0.0, -overlap], [radius + fillet, -overlap]], lower, upper,
                              [[radius + fillet, length + overlap], [0.0, length + overlap]]])
    return _revolved(profile, segments)


def _web(throw, thickness, segments, side):
    """A crank web: the hull of a disc round the main axis and one round the pin, plus a
    counterweight sector on the opposite side; extruded along z from 0 to ``thickness``."""
    import manifold3d
    cs = manifold3d.CrossSection
    hub = cs.circle(0.85, segments)
    boss = cs.circle(0.62, segments).translate([0.0, side * throw])
    arm = cs.batch_hull([hub, boss])
    counter = cs.circle(1.35, segments) ^ cs.square([3.0, 1.5]).translate(
        [-1.5, -1.5 if side > 0 else 0.0])
    return manifold3d.Manifold.extrude(arm + counter, thickness)


def crank(segments=576):
    """A two-throw crankshaft along +X: nose with keyway, three main journals, two crankpins at
    180°, four webs with counterweights, a flange with six bolt holes, oil holes through the
    journals.

    Journals and pins are revolved profiles with filleted ends; webs are extruded 2D hulls;
    everything is unioned and drilled with manifold3d.

    Parameters
    ----------
    segments : int in [8, 1024]
        Circular segments of every round part (bolt and oil holes use a quarter of them, at
        least 8). The face count grows about linearly, ~172 faces per segment: 99 404 at the
        default 576, 2 996 at 16.

    Returns
    -------
    trimesh.Trimesh
        Axis along +X from x = −1.5 (nose) to x = 6.6 (flange face), see the tests for pinned
        face counts.
    """
    import manifold3d
    segments = _as_int(segments, "segments", 8, 1024)
    small = max(8, segments // 4)
    M = manifold3d.Manifold
    throw, web_t = 1.1, 0.35
    parts = [
        M.cylinder(1.55, 0.35, -1.0, segments).translate([0.0, 0.0, -1.5]),  # nose
        _journal(0.55, 1.0, 0.08, segments),
        _journal(0.55, 1.0, 0.08, segments).translate([0.0, 0.0, 2.6]),
        _journal(0.55, 1.0, 0.08, segments).translate([0.0, 0.0, 5.2]),
        _journal(0.5, 0.9, 0.08, segments).translate([0.0, throw, 1.35]),
        _journal(0.5, 0.9, 0.08, segments).translate([0.0, -throw, 3.95]),
        _web(throw, web_t, segments, +1).translate([0.0, 0.0, 1.0]),
        _web(throw, web_t, segments, +1).translate([0.0, 0.0, 2.25]),
        _web(throw, web_t, segments, -1).translate([0.0, 0.0, 3.6]),
        _web(throw, web_t, segments, -1).translate([0.0, 0.0, 4.85]),
        M.cylinder(0.45, 1.2, -1.0, segments).translate([0.0, 0.0, 6.15]),  # flange
    ]
    solid = M.batch_boolean(parts, manifold3d.OpType.Add)
    holes = [_box((-0.08, 0.2, -1.2), (0.08, 0.5, -0.2))]  # keyway
    for k in range(6):
        a = 2.0 * np.pi * (k + 0.5) / 6
        holes.append(M.cylinder(0.6, 0.12, -1.0, small).translate(
            [0.85 * np.cos(a), 0.85 * np.sin(a), 6.1]))
    for zc in (0.5, 3.1, 5.7):  # oil holes: drilled across each main journal
        holes.append(M.cylinder(1.4, 0.08, -1.0, small, True).rotate([90.0, 0.0, 0.0])
                     .translate([0.0, 0.0, zc]))
    solid = solid - M.batch_boolean(holes, manifold3d.OpType.Add)
    # The revolve axis z becomes +X; the throws stay along ±Y.
    solid = solid.rotate([0.0, 90.0, 0.0])
    return _from_manifold(solid)
