"""Seeded random scenes for comparing refraster with an outside rasterizer.

:func:`random_scenes` cycles through :data:`KINDS`, each a recipe for the cases a rasterizer gets
wrong first: closed meshes (jittered icospheres, boxes, tori) and open ones (triangle soups,
height-field grids with shared edges), random perspective and orthographic cameras, triangles
crossing the near plane, slivers, sub-pixel triangles, huge triangles with vertices at 1e6 and
1e30, edges and vertices exactly on pixel centres, and coincident faces in several draw calls
(ties broken by draw order). Every scene is a pure function of ``(seed, index)``.

The camera matrices are written out here (``gluLookAt`` / ``gluPerspective`` / ``glOrtho``)
rather than taken from refraster, so a scene does not depend on the code it tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

__all__ = ["Scene", "KINDS", "random_scene", "random_scenes", "look_at", "perspective",
           "orthographic", "clip_positions"]


@dataclass
class Scene:
    """Meshes (draw calls in order) and a camera. ``vertices``/``faces`` are the first mesh's."""

    name: str
    meshes: list            #: [(vertices (V, 3) float64, faces (F, 3) int64), ...]
    view: np.ndarray        #: (4, 4) float64
    proj: np.ndarray        #: (4, 4) float64
    width: int
    height: int
    closed: bool = False    #: every mesh is a closed, consistently oriented (outward) surface
    notes: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def vertices(self):
        return self.meshes[0][0]

    @property
    def faces(self):
        return self.meshes[0][1]

    @property
    def mvp(self):
        return self.proj @ self.view

    @property
    def n_faces(self):
        return sum(len(f) for _, f in self.meshes)


def look_at(eye, target, up=(0.0, 1.0, 0.0)):
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fovy_deg, aspect, near, far):
    f = 1.0 / np.tan(np.radians(fovy_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(left, right, bottom, top, near, far):
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = 2.0 / (right - left), 2.0 / (top - bottom), -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def clip_positions(vertices, mvp):
    """Clip coordinates ``(V, 4) float32`` of ``vertices (V, 3)`` under one float32 ``mvp``: the
    clip positions the oracles draw (``oracles.llvmpipe``, ``oracles.lavapipe``).

    Evaluates ``((m0·x + m1·y) + m2·z) + m3`` in float32 with no fused multiply-add, the order
    refraster's float32 vertex stage uses, so the two renderers see the same clip coordinates.
    """
    v = np.asarray(vertices, dtype=np.float64).astype(np.float32)
    m = np.asarray(mvp, dtype=np.float64).astype(np.float32)
    out = np.zeros((len(v), 4), np.float32)
    for r in range(4):
        out[:, r] = ((m[r, 0] * v[:, 0] + m[r, 1] * v[:, 1]) + m[r, 2] * v[:, 2]) + m[r, 3]
    return out


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _orbit_camera(rng, center, radius, width, height, *, fill=(0.6, 1.3), ortho=False):
    """A camera on a random direction around ``center`` looking at it; the bounding sphere
    spans about ``1 / fill`` of the smaller image side."""
    d = _unit(rng)
    up = (0.0, 1.0, 0.0) if abs(d[1]) < 0.95 else (1.0, 0.0, 0.0)
    aspect = width / height
    fovy = rng.uniform(30.0, 70.0)
    half = radius * rng.uniform(*fill) / min(1.0, aspect)
    dist = max(half / np.tan(np.radians(fovy) / 2.0), 1.2 * radius)
    view = look_at(center + dist * d, center, up)
    if ortho:
        proj = orthographic(-half * aspect, half * aspect, -half, half, dist - 2 * radius,
                            dist + 2 * radius)
    else:
        proj = perspective(fovy, aspect, dist * rng.uniform(0.05, 0.3),
                           dist + radius * rng.uniform(1.5, 4.0))
    return view, proj


def _size(rng):
    return int(rng.integers(48, 129)), int(rng.integers(40, 113))


def _jitter_closed(mesh, rng, amount):
    """Move each vertex radially (keeps the surface closed and oriented)."""
    v = mesh.vertices.copy()
    c = v.mean(axis=0)
    r = v - c
    v = c + r * (1.0 + amount * rng.uniform(-1.0, 1.0, size=(len(v), 1)))
    return v, np.asarray(mesh.faces, np.int64)


def _random_rigid(rng, scale=1.0):
    q = trimesh.transformations.random_rotation_matrix(rng.random(3))
    q[:3, :3] *= scale
    return q


def _apply(m, v):
    return v @ m[:3, :3].T + m[:3, 3]


# --------------------------------------------------------------------------------------- kinds

def _icosphere(rng):
    w, h = _size(rng)
    v, f = _jitter_closed(trimesh.creation.icosphere(int(rng.integers(1, 4))), rng, 0.15)
    v = _apply(_random_rigid(rng), v)
    view, proj = _orbit_camera(rng, v.mean(0), 1.0, w, h)
    return dict(meshes=[(v, f)], view=view, proj=proj, width=w, height=h, closed=True,
                notes="jittered icosphere, perspective")


def _boxes(rng):
    w, h = _size(rng)
    meshes = []
    for _ in range(int(rng.integers(2, 5))):
        b = trimesh.creation.box(extents=rng.uniform(0.3, 1.2, 3),
                                 transform=_random_rigid(rng))
        b.apply_translation(rng.uniform(-0.8, 0.8, 3))
        meshes.append((np.asarray(b.vertices), np.asarray(b.faces, np.int64)))
    view, proj = _orbit_camera(rng, np.zeros(3), 1.6, w, h, ortho=bool(rng.integers(2)))
    return dict(meshes=meshes, view=view, proj=proj, width=w, height=h, closed=True,
                notes="interpenetrating boxes, one draw call each")


def _torus(rng):
    w, h = _size(rng)
    t = trimesh.creation.torus(1.0, rng.uniform(0.2, 0.5), int(rng.integers(12, 40)),
                               int(rng.integers(8, 24)))
    v, f = _jitter_closed(t, rng, 0.05)
    v = _apply(_random_rigid(rng), v)
    view, proj = _orbit_camera(rng, np.zeros(3), 1.5, w, h, ortho=bool(rng.integers(2)))
    return dict(meshes=[(v, f)], view=view, proj=proj, width=w, height=h, closed=True,
                notes="jittered torus (self-occluding)")


def _soup(rng):
    w, h = _size(rng)
    n = int(rng.integers(20, 200))
    centers = rng.uniform(-1, 1, size=(n, 1, 3))
    v = (centers + rng.normal(scale=rng.uniform(0.05, 0.5), size=(n, 3, 3))).reshape(-1, 3)
    f = np.arange(3 * n, dtype=np.int64).reshape(n, 3)
    view, proj = _orbit_camera(rng, np.zeros(3), 1.5, w, h)
    return dict(meshes=[(v, f)], view=view, proj=proj, width=w, height=h,
                notes="random triangle soup (open, intersecting)")


def _grid(rng):
    w, h = _size(rng)
    n = int(rng.integers(4, 24))
    x, y = np.meshgrid(np.linspace(-1, 1, n + 1), np.linspace(-1, 1, n + 1))
    z = 0.3 * rng.normal(size=x.shape)
    v = np.stack([x.ravel(), z.ravel(), y.ravel()], axis=1)
    i = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    f = np.concatenate([np.stack([i, i + n + 1, i + 1], 1),
                        np.stack([i + 1, i + n + 1, i + n + 2], 1)]).astype(np.int64)
    view, proj = _orbit_camera(rng, np.zeros(3), 1.4, w, h, ortho=bool(rng.integers(2)))
    return dict(meshes=[(v, f)], view=view, proj=proj, width=w, height=h,
                notes="height-field grid: shared edges and vertices")


def _near_crossing(rng):
    """Camera close to (or inside) geometry: many triangles cross the near plane."""
    w, h = _size(rng)
    n = 16
    x, y = np.meshgrid(np.linspace(-3, 3, n + 1), np.linspace(-3, 3, n + 1))
    v = np.stack([x.ravel(), 0.1 * rng.normal(size=x.size), y.ravel()], axis=1)
    i = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    f = np.concatenate([np.stack([i, i + n + 1, i + 1], 1),
                        np.stack([i + 1, i + n + 1, i + n + 2], 1)]).astype(np.int64)
    s, sf = _jitter_closed(trimesh.creation.icosphere(2, radius=1.2), rng, 0.1)
    eye = np.array([rng.uniform(-0.3, 0.3), rng.uniform(0.15, 0.6), rng.uniform(-0.3, 0.3)])
    target = eye + np.array([rng.uniform(-1, 1), -rng.uniform(0.2, 0.8), rng.uniform(-1, 1)])
    view = look_at(eye, target)
    proj = perspective(rng.uniform(50, 90), w / h, rng.uniform(0.05, 0.4), 20.0)
    return dict(meshes=[(v, f), (s, sf)], view=view, proj=proj, width=w, height=h,
                notes="camera inside a sphere above a ground grid: near-plane crossings")


def _slivers(rng):
    w, h = _size(rng)
    n = int(rng.integers(100, 300))
    a = rng.uniform(-1, 1, size=(n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = a + rng.uniform(0.5, 2.0, (n, 1)) * d
    c = 0.5 * (a + b) + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-4, -1.5, (n, 1))
    v = np.stack([a, b, c], 1).reshape(-1, 3)
    f = np.arange(3 * n, dtype=np.int64).reshape(n, 3)
    view, proj = _orbit_camera(rng, np.zeros(3), 1.5, w, h)
    return dict(meshes=[(v, f)], view=view, proj=proj, width=w, height=h,
                notes="long sliver triangles (widths 1e-4 to 3e-2)")


def _subpixel(rng):
    w, h = _size(rng)
    v, f = _jitter_closed(trimesh.creation.icosphere(5), rng, 0.02)
    n = 400
    c = rng.uniform(-1.5, 1.5, size=(n, 1, 3))
    tiny = (c + rng.normal(scale=0.004, size=(n, 3, 3))).reshape(-1, 3)
    tf = np.arange(3 * n, dtype=np.int64).reshape(n, 3)
    view, proj = _orbit_camera(rng, np.zeros(3), 1.5, w, h, fill=(1.5, 3.0))
    return dict(meshes=[(v, f), (tiny, tf)], view=view, proj=proj, width=w, height=h,
                closed=False, notes="fine icosphere (20k faces) far away + sub-pixel triangles")


def _huge(rng, s):
    """Triangles with vertices at ``s`` (1e6 or 1e30) around a small object."""
    w, h = _size(rng)
    v = np.array([[-s, -1.0, -s], [s, -1.0, -s], [0.0, -1.0, s],         # ground
                  [-s, -s, -3.0], [s, -s, -3.0], [0.0, s, -3.0],         # back wall
                  [0.3, 0.2, -s], [0.5, 0.1, 0.5], [0.2, 0.4, 0.4]])     # a spike into the far
    f = np.array([[0, 2, 1], [3, 4, 5], [6, 7, 8]], np.int64)
    b, bf = _jitter_closed(trimesh.creation.icosphere(2, radius=0.5), rng, 0.1)
    eye = np.array([rng.uniform(-1, 1), rng.uniform(0.0, 1.0), 3.0])
    view = look_at(eye, (0.0, 0.0, 0.0))
    proj = perspective(rng.uniform(40, 70), w / h, 0.1, 50.0)
    return dict(meshes=[(v, f), (b, bf)], view=view, proj=proj, width=w, height=h,
                notes=f"huge triangles with vertices at {s:g}")


def _pixel_aligned(rng):
    """Orthographic, one unit per pixel: vertices on pixel centres and corners (fill-rule ties)."""
    w, h = _size(rng)
    n = 60
    # positions in pixels, on the 1/2-pixel lattice so edges run through pixel centres
    p = rng.integers(0, 2 * max(w, h) + 1, size=(n, 3, 2)) / 2.0
    z = rng.uniform(-0.9, 0.9, size=(n, 1, 1)) * np.ones((n, 3, 1))
    v = np.concatenate([p, z], axis=2).reshape(-1, 3)
    f = np.arange(3 * n, dtype=np.int64).reshape(n, 3)
    # a fan around a vertex on a pixel centre: every pixel there is owned exactly once
    cx, cy = np.floor(w / 2) + 0.5, np.floor(h / 2) + 0.5
    ang = np.linspace(0, 2 * np.pi, 13)[:-1]
    ring = np.stack([cx + 10 * np.cos(ang), cy + 10 * np.sin(ang), np.zeros(12)], 1)
    fv = np.concatenate([[[cx, cy, 0.95]], ring])
    ff = np.array([[0, 1 + k, 1 + (k + 1) % 12] for k in range(12)], np.int64)
    view = np.eye(4)
    proj = orthographic(0, w, 0, h, -1.0, 1.0)
    return dict(meshes=[(fv, ff), (v, f)], view=view, proj=proj, width=w, height=h,
                notes="pixel-lattice vertices: edges through pixel centres, a 12-triangle fan")


def _coincident(rng):
    """The same faces in several draw calls: equal depths, resolved by draw order."""
    w, h = _size(rng)
    m = trimesh.creation.icosphere(2)
    v, f = _jitter_closed(m, rng, 0.1)
    g = trimesh.creation.box(extents=(1.5, 1.5, 1.5))
    gv, gf = np.asarray(g.vertices), np.asarray(g.faces, np.int64)
    meshes = [(v, f), (v.copy(), f[rng.permutation(len(f))]), (gv, gf), (gv.copy(), gf)]
    view, proj = _orbit_camera(rng, np.zeros(3), 1.2, w, h, ortho=bool(rng.integers(2)))
    return dict(meshes=meshes, view=view, proj=proj, width=w, height=h, closed=True,
                notes="duplicated meshes in later draw calls (coincident fragments)")


def _nested(rng):
    """Concentric jittered shells: a depth complexity of up to eight."""
    w, h = _size(rng)
    meshes = []
    for r in (1.0, 0.8, 0.6, 0.4):
        v, f = _jitter_closed(trimesh.creation.icosphere(2, radius=r), rng, 0.05)
        meshes.append((v, f))
    view, proj = _orbit_camera(rng, np.zeros(3), 1.0, w, h, ortho=bool(rng.integers(2)))
    return dict(meshes=meshes, view=view, proj=proj, width=w, height=h, closed=True,
                notes="four nested spheres")


#: (name, recipe) in the order :func:`random_scenes` cycles through them.
KINDS = [
    ("icosphere", _icosphere), ("boxes", _boxes), ("torus", _torus), ("soup", _soup),
    ("grid", _grid), ("near_crossing", _near_crossing), ("slivers", _slivers),
    ("subpixel", _subpixel), ("huge_1e6", lambda rng: _huge(rng, 1e6)),
    ("huge_1e30", lambda rng: _huge(rng, 1e30)), ("pixel_aligned", _pixel_aligned),
    ("coincident", _coincident), ("nested", _nested),
]


def random_scene(index, seed=2026):
    """Scene ``index`` of the sequence: kind ``KINDS[index % len(KINDS)]``, seeded by both."""
    name, recipe = KINDS[index % len(KINDS)]
    rng = np.random.default_rng([seed, index])
    d = recipe(rng)
    d["meshes"] = [(np.ascontiguousarray(v, np.float64), np.ascontiguousarray(f, np.int64))
                   for v, f in d["meshes"]]
    return Scene(name=f"{index:02d}-{name}", **d)


def random_scenes(n=26, seed=2026):
    """``n`` scenes (two of each kind for ``n = 26``)."""
    return [random_scene(i, seed) for i in range(n)]
