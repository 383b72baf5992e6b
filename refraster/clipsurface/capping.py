"""Cap surfaces for 2.5D clip surfaces (Trapp & Döllner, Sec. 5; MATH.md §1.2).

A cap closes the cut a clip surface leaves in a solid. Two ways to make one:

* **Tessellated** (the paper's): a grid mesh over the part of the surface that crosses the
  solid's bounding box, one vertex per offset-map texel centre (or ``subdivision``² per texel),
  each vertex displaced exactly as the clip test displaces the surface,
  ``X = O + aU + bV − Sz·OM(a·Sx, b·Sy)·N`` (MATH.md §1.2, the −N sign). Its fragments are
  kept where the volumetric parity test says *inside* (MATH.md §2.2). Between vertices the
  triangles are flat while the clip test's bilinear surface is not: that is the mismatch the
  paper names in Sec. 6.3.
* **Exact**: per pixel, the view ray is intersected with the zero set ``g = 0`` of the clip
  function itself. Inside one texel cell the bilinear height along a ray is a quadratic in the
  ray parameter, so every crossing is a root of a quadratic; the first root inside the solid
  (and not clipped by another surface) is the cap point.

Shading (:func:`shade_caps`): the surface's normal map and occlusion map (MATH.md §1.2b) lit by
a headlight, over a flat colour, a section hatch, or a procedural solid texture (marble, wood,
noise) evaluated at the world position.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._config import IJIT, JIT, PJIT
from .._scratch import OUTPUTS
from .._validate import as_choice, as_float_array, as_real
from ..mesh import Mesh
from ..mesh import bounds as mesh_bounds
from .offsetmaps import WRAP_MODES, _wrap_texel, bilinear_taps, sample
from .surfaces import _Packed, clip_mask
from .textures import sample_texture

__all__ = ["CAP_STYLES", "check_watertight", "cap_mesh", "cull_cap", "exact_caps", "light_caps",
           "shade_cap_pixels", "shade_caps", "solid_texture", "surely_inside",
           "MAX_CAP_VERTICES", "texture_caps"]

#: Largest cap grid accepted (vertices); a larger one almost always means a surface whose
#: texture tile is far smaller than the solid.
MAX_CAP_VERTICES = 1 << 23
CAP_STYLES = ("diffuse", "hatch", "marble", "wood", "noise", "solid")
#: Styles that colour a cap by the surface's (s, t): only "diffuse" reads a user diffuse map.
_PROCEDURAL = ("hatch", "marble", "wood", "noise")


#: Copies of the meshes already found watertight, with their bounds, newest last. Rendering
#: the same solid frame after frame checks it once; a later mesh counts as checked only when its
#: arrays equal a copy's bit for bit (a memory comparison, far cheaper than the check or a
#: hash), and then has the copy's bounds.
_WATERTIGHT = []
_WATERTIGHT_SIZE = 8


@njit(**PJIT)
def _differing_words(a, b):
    """How many 64-bit words of two equal-length arrays differ (one parallel pass, no
    temporary: ``np.array_equal`` builds a boolean array first)."""
    n = 0
    for i in prange(a.shape[0]):
        n += a[i] != b[i]
    return n


def _same_bits(a, b):
    """``a`` and ``b`` have the same shape, dtype and bytes."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.size == 0:
        return True
    if a.dtype.itemsize != 8 or not (a.flags.c_contiguous and b.flags.c_contiguous):
        return bool(np.array_equal(a, b))   # the rare case: not a validated Mesh's arrays
    return _differing_words(_readonly(a.reshape(-1).view(np.int64)),
                            _readonly(b.reshape(-1).view(np.int64))) == 0


def _readonly(a):
    """``a`` as a read-only view: a kernel's read-only and writable arrays are distinct
    Numba types, so passing only read-only ones compiles the kernel once, not twice."""
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


def _known_watertight(v, f):
    """The bounds kept with the copy of a mesh found watertight whose arrays ``v``, ``f`` equal
    bit for bit, or None."""
    for kv, kf, box in _WATERTIGHT:
        if _same_bits(kv, v) and _same_bits(kf, f):
            return box
    return None


def check_watertight(mesh, name="mesh"):
    """Raise ``ValueError`` unless ``mesh`` is closed: after merging vertices at equal
    positions, every undirected edge must be shared by exactly two faces.

    Capping needs a closed solid: the parity test is meaningless for an open surface.
    Returns the mesh's bounds (:func:`refraster.mesh.bounds`, read-only), kept with the
    check: a solid seen before costs one comparison of its arrays for both.
    """
    v, f = mesh.vertices, mesh.faces
    box = _known_watertight(v, f)
    if box is not None:
        return box
    if f.shape[0] == 0:
        raise ValueError(f"{name} has no faces; caps need a closed (watertight) solid")
    # merge vertices at bit-equal positions; 1D keys keep the sorts cheap on large meshes
    rows = np.ascontiguousarray(v + 0.0).view(np.dtype((np.void, v.dtype.itemsize * 3)))
    _, ids = np.unique(rows.ravel(), return_inverse=True)
    ff = ids.reshape(-1)[f].astype(np.int64)
    edges = np.sort(np.concatenate([ff[:, [0, 1]], ff[:, [1, 2]], ff[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges[:, 0] * (int(ids.max()) + 1) + edges[:, 1], return_counts=True)
    bad = int(np.count_nonzero(counts != 2))
    if bad:
        raise ValueError(
            f"{name} is not watertight: {bad} edge(s) are not shared by exactly two faces; "
            "caps need a closed solid (render with caps=None, or repair the mesh)")
    if len(_WATERTIGHT) >= _WATERTIGHT_SIZE:
        _WATERTIGHT.pop(0)
    box = _readonly(mesh_bounds(v))
    _WATERTIGHT.append((np.array(v), np.array(f), box))
    return box


def _bounds_slab(surface, bounds):
    """(a, b, w) ranges of the box's corners in the surface frame: a, b as in MATH.md §1.2,
    w = N·(X − O)."""
    lo, hi = bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    d = corners - surface.origin
    a = d @ surface.u_hat / surface.u_length
    b = d @ surface.v_hat / surface.v_length
    w = d @ surface.normal
    return (a.min(), a.max()), (b.min(), b.max()), (w.min(), w.max())


def _displacement_range(surface):
    """[lo, hi] of −Sz·h over the map: where the surface can lie along N."""
    sz = surface.scale[2]
    h0, h1 = float(surface.offset_map.min()), float(surface.offset_map.max())
    vals = (-sz * h0, -sz * h1)
    return min(vals), max(vals)


def cap_mesh(surface, bounds, *, subdivision=1):
    """The tessellated cap of ``surface`` over a solid's bounding box.

    Parameters
    ----------
    surface : ClipSurface
    bounds : (2, 3) float
        World-space bounding box (min, max) of the solid.
    subdivision : int
        Grid vertices per texel along each axis (1: one vertex at every texel centre).

    Returns
    -------
    Mesh or None
        ``None`` when the box does not reach the surface. Vertices lie on the lattice
        ``a = (i/subdivision + ½) / (Sx·W)``, ``b = (j/subdivision + ½) / (Sy·H)`` covering the
        box's projection plus one cell, displaced by ``−Sz·OM(a·Sx, b·Sy)·N`` (the same sampler
        as the clip test). Each cell is split along its (i, j)–(i+1, j+1) diagonal; faces are
        counter-clockwise seen from −N (front-facing for a viewer of the cut).
    """
    bounds = as_float_array(bounds, "bounds", shape=(2, 3))
    if isinstance(subdivision, bool) or not isinstance(subdivision, (int, np.integer)) \
            or not 1 <= subdivision <= 64:
        raise ValueError(f"subdivision must be an int in [1, 64], got {subdivision!r}")
    (a0, a1), (b0, b1), (w0, w1) = _bounds_slab(surface, bounds)
    d0, d1 = _displacement_range(surface)
    if w1 < d0 or w0 > d1:
        return None
    rows, cols = surface.offset_map.shape
    sx, sy, sz = surface.scale
    ka = sx * cols * subdivision  # lattice steps per unit of a
    kb = sy * rows * subdivision
    i = np.arange(math.floor(a0 * ka - 0.5 * subdivision) - 1,
                  math.ceil(a1 * ka - 0.5 * subdivision) + 2)
    j = np.arange(math.floor(b0 * kb - 0.5 * subdivision) - 1,
                  math.ceil(b1 * kb - 0.5 * subdivision) + 2)
    if i.size * j.size > MAX_CAP_VERTICES:
        raise ValueError(
            f"the cap grid would have {i.size * j.size} vertices (> {MAX_CAP_VERTICES}): the "
            "offset map's texels are tiny against the solid; lower Sx, Sy or the map's size")
    a = (i / subdivision + 0.5) / (sx * cols)
    b = (j / subdivision + 0.5) / (sy * rows)
    bb, aa = np.meshgrid(b, a, indexing="ij")
    h = sample(surface.offset_map, np.stack([aa.ravel() * sx, bb.ravel() * sy], 1),
               wrap=surface.wrap)
    verts = (surface.origin + aa.reshape(-1, 1) * surface.u + bb.reshape(-1, 1) * surface.v
             - (sz * h)[:, None] * surface.normal)
    nj, ni = bb.shape
    idx = np.arange(nj * ni).reshape(nj, ni)
    v00, v10 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    v01, v11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    # (Û, V̂) is counter-clockwise seen from +N, so reverse it for the −N side.
    faces = np.concatenate([np.stack([v00, v11, v10], 1), np.stack([v00, v01, v11], 1)])
    return Mesh(np.ascontiguousarray(verts), np.ascontiguousarray(faces, np.int64))


@njit(**JIT)
def _face_box(verts, faces, fi, m, h, w, margin, rounding):
    """Face ``fi``'s box in an LDI's texture space (matrix ``m``, ``h × w`` texels), each axis
    widened by ``margin`` of its size, by a texel (s, t) or 1e-6 (r), and by ``rounding`` of
    the coordinates' magnitude: ``(s0, s1, t0, t1, r0, r1)``."""
    s0 = t0 = r0 = np.inf
    s1 = t1 = r1 = -np.inf
    ms = mt = mr = 0.0
    for c in range(3):
        v = faces[fi, c]
        x, y, z = verts[v, 0], verts[v, 1], verts[v, 2]
        ts = ((m[0, 0] * x + m[0, 1] * y) + m[0, 2] * z) + m[0, 3]
        tt = ((m[1, 0] * x + m[1, 1] * y) + m[1, 2] * z) + m[1, 3]
        tr = ((m[2, 0] * x + m[2, 1] * y) + m[2, 2] * z) + m[2, 3]
        s0, s1 = min(s0, ts), max(s1, ts)
        t0, t1 = min(t0, tt), max(t1, tt)
        r0, r1 = min(r0, tr), max(r1, tr)
        if rounding > 0.0:
            ms = max(ms, (abs(m[0, 0] * x) + abs(m[0, 1] * y)) + abs(m[0, 2] * z))
            mt = max(mt, (abs(m[1, 0] * x) + abs(m[1, 1] * y)) + abs(m[1, 2] * z))
            mr = max(mr, (abs(m[2, 0] * x) + abs(m[2, 1] * y)) + abs(m[2, 2] * z))
    ds = (margin * (s1 - s0) + 1.0 / w) + rounding * ms
    dt = (margin * (t1 - t0) + 1.0 / h) + rounding * mt
    dr = (margin * (r1 - r0) + 1e-6) + rounding * mr
    return s0 - ds, s1 + ds, t0 - dt, t1 + dt, r0 - dr, r1 + dr


@njit(**PJIT)
def _footprint_kernel(verts, faces, mats, depth, count, start, cstart, hw, margin, votes):
    """votes[f] = number of the sprite's LDIs in which face f may hold a point the parity
    test calls inside: at some texel of its (s, t) box, widened by one texel and ``margin``
    of its size, its r range (widened alike) meets an inside segment ``[d_2j, d_2j+1]`` of
    the layers (the last one open-ended for an odd count)."""
    for fu in prange(faces.shape[0]):
        fi = np.int64(fu)   # one _face_box specialisation (the parfor body's index is uint64)
        n_in = 0
        for ld in range(mats.shape[0]):
            h = hw[ld, 0]
            w = hw[ld, 1]
            s0, s1, t0, t1, r0, r1 = _face_box(verts, faces, fi, mats[ld], h, w, margin, 0.0)
            c0 = max(int(math.floor(s0 * w)), 0)
            c1 = min(int(math.floor(s1 * w)), w - 1)
            j0 = max(int(math.floor(t0 * h)), 0)
            j1 = min(int(math.floor(t1 * h)), h - 1)
            hit = False
            for j in range(j0, j1 + 1):
                row = h - 1 - j
                for col in range(c0, c1 + 1):
                    texel = row * w + col
                    k = count[cstart[ld] + texel]
                    # inside segments of the parity test: [d_2j, d_2j+1), and [d_k-1, ∞) for
                    # an odd count; the face may be inside where its r range meets one
                    for j in range(0, k, 2):
                        enter = depth[start[ld] + j * h * w + texel]
                        if enter > r1:
                            break
                        if j + 1 == k or depth[start[ld] + (j + 1) * h * w + texel] >= r0:
                            hit = True
                            break
                    if hit:
                        break
                if hit:
                    break
            if hit:
                n_in += 1
        votes[fi] = n_in


#: Widening of a cap face's box in the footprint test, as a fraction of its size: fragments
#: may be interpolated a little outside their triangle (a covered centre outside the unsnapped
#: triangle extrapolates).
FOOTPRINT_MARGIN = 0.05


def cull_cap(cap, sprite):
    """The faces of a cap mesh that can show anything: those whose box in the sprite's texture
    space (widened by one texel and :data:`FOOTPRINT_MARGIN`) meets an inside segment of the
    solid's layers in a majority of its axes. The others' fragments would all fail the parity
    test. Unused vertices are dropped. Returns a :class:`Mesh` (possibly without faces).

    The widening covers fragments interpolated a little beyond their triangle (a covered pixel
    centre outside the unsnapped triangle); only a fragment extrapolated further — from a
    sliver under ~0.01 pixel across, seen edge-on — could fall outside it, and would then be
    lost where the unculled grid might have kept it. No such pixel has been observed (the
    culled and unculled renders are compared in tests/test_clipsurface_fused.py)."""
    mats, depth, sign, count, start, cstart, hw = sprite.packed()
    votes = np.zeros(cap.n_faces, np.int64)
    _footprint_kernel(_readonly(np.ascontiguousarray(cap.vertices)),
                      _readonly(np.ascontiguousarray(cap.faces)), mats, depth, count, start, cstart, hw, FOOTPRINT_MARGIN, votes)
    faces = cap.faces[votes * 2 > len(mats)]
    used = np.unique(faces)
    remap = np.zeros(cap.n_vertices, np.int64)
    remap[used] = np.arange(used.size)
    return Mesh(np.ascontiguousarray(cap.vertices[used]), np.ascontiguousarray(remap[faces]))


#: Largest perspective-correct barycentric extrapolation (below 0) a fragment of a face may
#: have for the face's "surely inside" flag (:func:`surely_inside`) to stand in for its
#: parity tests: a quarter of :data:`FOOTPRINT_MARGIN` (a fragment lies within its face's box
#: widened by twice this fraction of the box; the rest is slack).
SURE_EXTRAPOLATION = FOOTPRINT_MARGIN / 4

#: Relative rounding of a fragment's position beyond its barycentrics' extrapolation: the
#: float32 barycentrics need not sum to 1 (by up to ~2e-7), which moves the interpolated
#: point by that fraction of its distance from the origin.
_SURE_ROUNDING = 1e-6


@njit(**IJIT)
def _leading_layers(depth, base, hw, k, r):
    """How many of a texel's first layers (``depth[base + j·hw]``, j < k) are ≤ r before the
    first that is not: the count :func:`refraster.ldi.parity_at` takes the parity of."""
    n = 0
    while n < k and depth[base + n * hw] <= r:
        n += 1
    return n


@njit(**PJIT)
def _sure_kernel(verts, faces, mats, depth, count, start, cstart, hw, margin, rounding, sure):
    """sure[f] = number of the sprite's LDIs in which *every* point of face f's box
    (:func:`_face_box`: widened as for :func:`_footprint_kernel` and by ``rounding`` of the
    coordinates' magnitude) lies in [0, 1]³ and at texels where the parity test says inside:
    the count of leading layers ≤ r is the same odd number at both ends of the r range (it
    is monotone in r, so it is that number in between)."""
    for fu in prange(faces.shape[0]):
        fi = np.int64(fu)   # one _face_box specialisation (the parfor body's index is uint64)
        n_in = 0
        for ld in range(mats.shape[0]):
            h = hw[ld, 0]
            w = hw[ld, 1]
            s0, s1, t0, t1, r0, r1 = _face_box(verts, faces, fi, mats[ld], h, w, margin,
                                               rounding)
            if not (s0 >= 0.0 and s1 <= 1.0 and t0 >= 0.0 and t1 <= 1.0 and r0 >= 0.0
                    and r1 <= 1.0):
                continue
            ok = True
            c0 = min(int(s0 * w), w - 1)
            c1 = min(int(s1 * w), w - 1)
            j0 = min(int(t0 * h), h - 1)
            j1 = min(int(t1 * h), h - 1)
            for j in range(j0, j1 + 1):
                row = h - 1 - j
                for col in range(c0, c1 + 1):
                    texel = row * w + col
                    k = count[cstart[ld] + texel]
                    base = start[ld] + texel
                    n0 = _leading_layers(depth, base, h * w, k, r0)
                    if n0 % 2 == 0 or _leading_layers(depth, base, h * w, k, r1) != n0:
                        ok = False
                        break
                if not ok:
                    break
            if ok:
                n_in += 1
        sure[fi] = n_in


def surely_inside(cap, sprite):
    """Per face of a cap mesh: True when a majority of the sprite's axes say inside at every
    point of the face's box widened by :data:`FOOTPRINT_MARGIN` (and a texel, as
    :func:`cull_cap` widens it), so the parity test passes every fragment that lies in it.

    A fragment interpolated from an unsnapped triangle lies in that box when its barycentrics
    extrapolate by less than :data:`SURE_EXTRAPOLATION`; the fused clip pass checks a bound on
    that per triangle (``_fragments_stay_near``) and runs the parity tests when it fails, so
    the flag never changes a pixel. Returns ``(F,) bool``."""
    mats, depth, sign, count, start, cstart, hw = sprite.packed()
    votes = np.zeros(cap.n_faces, np.int64)
    _sure_kernel(_readonly(np.ascontiguousarray(cap.vertices)),
                 _readonly(np.ascontiguousarray(cap.faces)), mats,
                 depth, count, start, cstart, hw, FOOTPRINT_MARGIN, _SURE_ROUNDING, votes)
    return votes * 2 > len(mats)


# --------------------------------------------------------------------------------------------
# exact caps: ray – height-field intersection


@njit(**JIT)
def _quadratic_roots(c0, c1, c2, length):
    """Roots of c0 + c1·x + c2·x² in [0, length]: ``(n, r1, r2)`` with r1 ≤ r2 the first n."""
    n = 0
    r_a = 0.0
    r_b = 0.0
    scale = abs(c0) + abs(c1) * length + abs(c2) * length * length
    if abs(c2) * length * length <= 1e-14 * scale:
        if c1 != 0.0:
            x = -c0 / c1
            if 0.0 <= x <= length:
                r_a = x
                n = 1
    else:
        disc = c1 * c1 - 4.0 * c2 * c0
        if disc >= 0.0:
            q = -0.5 * (c1 + math.copysign(math.sqrt(disc), c1))
            r1 = q / c2
            r2 = c0 / q if q != 0.0 else r1
            if r1 > r2:
                r1, r2 = r2, r1
            if 0.0 <= r1 <= length:
                r_a = r1
                n = 1
            if 0.0 <= r2 <= length and (n == 0 or r2 > r_a):
                if n == 0:
                    r_a = r2
                else:
                    r_b = r2
                n += 1
    g_end = c0 + (c1 + c2 * length) * length
    if n == 0 and (c0 < 0.0) != (g_end < 0.0):
        # A sign change the closed form lost to rounding: bisect.
        lo, hi = 0.0, length
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            gm = c0 + (c1 + c2 * mid) * mid
            if (gm < 0.0) == (c0 < 0.0):
                lo = mid
            else:
                hi = mid
        r_a = 0.5 * (lo + hi)
        n = 1
    return n, r_a, r_b


@njit(**PJIT)
def _ray_roots_kernel(origin, direction, tau_range, tau_start, params, tex, mode, w_lo, w_hi,
                      roots, count, finished):
    """For each ray, the next ``roots.shape[1]`` crossings of g = 0 after ``tau_start``.

    The ray X(τ) = origin + τ·direction is walked cell by cell through the lattice of texel
    centres (x = s·W − ½, y = t·H − ½); inside a cell g is quadratic in τ.
    """
    rows, cols = tex.shape
    max_roots = roots.shape[1]
    for r in prange(origin.shape[0]):
        count[r] = 0
        finished[r] = True
        ox = origin[r, 0] - params[0]
        oy = origin[r, 1] - params[1]
        oz = origin[r, 2] - params[2]
        dx, dy, dz = direction[r, 0], direction[r, 1], direction[r, 2]
        s0 = ((ox * params[3] + oy * params[4] + oz * params[5]) / params[12]) * params[14]
        s1 = ((dx * params[3] + dy * params[4] + dz * params[5]) / params[12]) * params[14]
        t0 = ((ox * params[6] + oy * params[7] + oz * params[8]) / params[13]) * params[15]
        t1 = ((dx * params[6] + dy * params[7] + dz * params[8]) / params[13]) * params[15]
        w0 = ox * params[9] + oy * params[10] + oz * params[11]
        w1 = dx * params[9] + dy * params[10] + dz * params[11]
        sz = params[16]
        lo = max(tau_range[r, 0], tau_start[r])
        hi = tau_range[r, 1]
        # Only the slab w ∈ [w_lo, w_hi] can hold g = 0.
        if w1 != 0.0:
            ta = (w_lo - w0) / w1
            tb = (w_hi - w0) / w1
            if ta > tb:
                ta, tb = tb, ta
            pad = 1e-9 * (abs(ta) + abs(tb) + 1.0)
            lo = max(lo, ta - pad)
            hi = min(hi, tb + pad)
        elif not (w_lo - 1e-12 <= w0 <= w_hi + 1e-12):
            continue
        if not lo < hi:
            continue
        x0 = s0 * cols - 0.5
        x1 = s1 * cols
        y0 = t0 * rows - 0.5
        y1 = t1 * rows
        tau = lo
        ci = np.int64(math.floor(min(max(x0 + x1 * tau, -4e15), 4e15)))
        cj = np.int64(math.floor(min(max(y0 + y1 * tau, -4e15), 4e15)))
        step_i = 1 if x1 > 0 else -1
        step_j = 1 if y1 > 0 else -1
        last = tau_start[r]
        steps_left = np.int64(abs(x1) * (hi - lo) + abs(y1) * (hi - lo)) + 4
        while tau < hi and steps_left > 0:
            steps_left -= 1
            tx = math.inf
            if x1 != 0.0:
                tx = ((ci + (1 if x1 > 0 else 0)) - x0) / x1
            ty = math.inf
            if y1 != 0.0:
                ty = ((cj + (1 if y1 > 0 else 0)) - y0) / y1
            tau_exit = min(tx, ty, hi)
            if tau_exit > tau:
                i0 = _wrap_texel(ci, cols, mode)
                i1 = _wrap_texel(ci + 1, cols, mode)
                j0 = _wrap_texel(cj, rows, mode)
                j1 = _wrap_texel(cj + 1, rows, mode)
                h00, h10 = tex[j0, i0], tex[j0, i1]
                h01, h11 = tex[j1, i0], tex[j1, i1]
                e1 = h10 - h00
                e2 = h01 - h00
                e3 = (h11 - h10) - (h01 - h00)
                a0 = (x0 + x1 * tau) - ci
                b0 = (y0 + y1 * tau) - cj
                k0 = h00 + e1 * a0 + e2 * b0 + e3 * a0 * b0
                k1 = e1 * x1 + e2 * y1 + e3 * (a0 * y1 + x1 * b0)
                k2 = e3 * x1 * y1
                c0 = (w0 + w1 * tau) + sz * k0
                c1 = w1 + sz * k1
                c2 = sz * k2
                n, x_a, x_b = _quadratic_roots(c0, c1, c2, tau_exit - tau)
                for q in range(n):
                    root = tau + (x_a if q == 0 else x_b)
                    if root - last > 1e-12 * (1.0 + abs(root)):
                        if count[r] == max_roots:
                            finished[r] = False
                            break
                        roots[r, count[r]] = root
                        count[r] += 1
                        last = root
                if not finished[r]:
                    break
            if tx <= ty:
                ci += step_i
            if ty <= tx:
                cj += step_j
            tau = max(tau, tau_exit)


def _ray_box(origin, direction, lo, hi, tau_max=1.0):
    """τ range of each ray inside the box and ``[0, tau_max]`` (empty: lo > hi), slab
    method."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / direction
        t1 = (lo - origin) * inv
        t2 = (hi - origin) * inv
    tmin = np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2))
    tmax = np.where(np.isnan(t1), np.inf, np.maximum(t1, t2))
    # a ray parallel to a slab: inside it for all τ or for none
    par = direction == 0.0
    inside = (origin >= lo) & (origin <= hi)
    tmin = np.where(par, np.where(inside, -np.inf, np.inf), tmin)
    tmax = np.where(par, np.where(inside, np.inf, -np.inf), tmax)
    return np.stack([np.maximum(tmin.max(axis=1), 0.0), np.minimum(tmax.min(axis=1), tau_max)], 1)


def pixel_rays(view, proj, width, height, raster=None):
    """World-space rays through the pixel centres: origin on the near plane, ``direction`` =
    far point − near point (so τ ∈ [0, 1] spans the view volume). Row 0 is the top.

    ``raster`` (a :class:`refraster.RasterState`; None: OpenGL's conventions) gives the clip
    volume the rays span: its NDC y direction (``ndc_y="down"``: a picture row's NDC y is
    negated), its depth range (the near and far planes at NDC depth −1 and 1, or 0 and 1) and
    its depth direction (under ``greater``/``gequal`` the near plane is at NDC depth 1). With
    a far plane at infinity (the far end unprojects to a direction, w = 0) the direction is a
    unit vector and the ray is unbounded. Returns ``(origin, direction, tau_max)``: τ ∈
    ``[0, tau_max]`` spans the view volume (``tau_max`` 1, or an (N,) array under another
    convention)."""
    from ..raster.state import as_raster_state, reverses
    state = as_raster_state(raster)
    inv = np.linalg.inv(proj @ view)
    rows, cols = np.mgrid[0:height, 0:width]
    x = 2.0 * (cols.ravel() + 0.5) / width - 1.0
    y = 2.0 * ((height - 1 - rows.ravel()) + 0.5) / height - 1.0
    if state.ndc_y == "up" and state.depth_range == "negative_one_to_one" \
            and not reverses(state):
        near = np.stack([x, y, -np.ones_like(x), np.ones_like(x)], 1) @ inv.T
        far = np.stack([x, y, np.ones_like(x), np.ones_like(x)], 1) @ inv.T
        near = near[:, :3] / near[:, 3:]
        far = far[:, :3] / far[:, 3:]
        return near, far - near, 1.0
    if state.ndc_y == "down":
        y = -y
    lo = 0.0 if state.depth_range == "zero_to_one" else -1.0
    z_near, z_far = (1.0, lo) if reverses(state) else (lo, 1.0)
    near = np.stack([x, y, np.full_like(x, z_near), np.ones_like(x)], 1) @ inv.T
    far = np.stack([x, y, np.full_like(x, z_far), np.ones_like(x)], 1) @ inv.T
    # homogeneous: the view volume's points between them have w of one sign (that of near)
    sign = np.where(near[:, 3:] < 0.0, -1.0, 1.0)
    near, far = near * sign, far * sign
    nw, fw = near[:, 3:], far[:, 3:]
    origin = near[:, :3] / nw
    # far/fw − near/nw = (far·nw − near·fw) / (nw·fw): the direction stays finite as fw → 0
    d = far[:, :3] * nw - near[:, :3] * fw
    length = np.linalg.norm(d, axis=1, keepdims=True)
    length = np.where(length > 0.0, length, 1.0)
    with np.errstate(divide="ignore"):
        tau_max = np.where(fw[:, 0] > 0.0, length[:, 0] / (nw[:, 0] * fw[:, 0]), np.inf)
    return origin, d / length, tau_max


def exact_caps(surfaces, solids, tests, *, view, proj, width, height, max_roots=8,
               raster=None):
    """Per-pixel exact caps by ray – height-field intersection (see the module docstring).

    Parameters
    ----------
    surfaces : list of ClipSurface (world space)
    solids : list of Mesh (world space)
    tests : list of objects with ``contains(points (N, 3)) -> (N,) bool`` (one per solid: the
        volumetric parity test)
    view, proj, width, height
        The camera.
    max_roots : int
        Crossings examined per ray and round (more rounds run where needed).
    raster : RasterState, optional
        The frame's conventions (NDC y, depth range, depth direction) the rays follow
        (:func:`pixel_rays`); None: OpenGL's.

    Returns
    -------
    tau : (H·W,) float64 ray parameter of the nearest cap point (inf: none)
    which : (H·W, 2) int64 (solid index, surface index) of that cap (−1: none)
    origin, direction : the rays (see :func:`pixel_rays`)
    """
    origin, direction, tau_max = pixel_rays(view, proj, width, height, raster)
    n = origin.shape[0]
    best = np.full(n, np.inf)
    which = np.full((n, 2), -1, np.int64)
    for m, (solid, test) in enumerate(zip(solids, tests)):
        lo, hi = solid.vertices.min(axis=0), solid.vertices.max(axis=0)
        pad = 1e-9 * (1.0 + np.abs(np.stack([lo, hi])).max())
        box = _ray_box(origin, direction, lo - pad, hi + pad, tau_max)
        hit = np.flatnonzero(box[:, 0] < box[:, 1])
        for k, surface in enumerate(surfaces):
            if not surface.enabled or hit.size == 0:
                continue
            w_lo, w_hi = _displacement_range(surface)
            params = surface.params
            tex = np.ascontiguousarray(surface.offset_map)
            mode = WRAP_MODES[surface.wrap]
            rays = hit
            start = np.full(rays.size, -np.inf)
            while rays.size:
                roots = np.full((rays.size, max_roots), np.inf)
                count = np.zeros(rays.size, np.int64)
                finished = np.zeros(rays.size, np.bool_)
                _ray_roots_kernel(origin[rays], direction[rays], box[rays], start, params, tex,
                                  mode, w_lo, w_hi, roots, count, finished)
                rr, cc = np.nonzero(np.isfinite(roots))
                pts = origin[rays[rr]] + roots[rr, cc, None] * direction[rays[rr]]
                ok = test.contains(pts) & ~clip_mask(pts, surfaces,
                                                     skip=np.full(len(pts), k, np.int64))
                accepted = np.full(rays.size, np.inf)
                # rr is ascending and cc ascending within a ray: the first accepted root wins
                np.minimum.at(accepted, rr[ok], roots[rr[ok], cc[ok]])
                got = np.isfinite(accepted)
                better = got & (accepted < best[rays])
                best[rays[better]] = accepted[better]
                which[rays[better]] = (m, k)
                again = ~got & ~finished
                start = np.where(count > 0, roots[np.arange(rays.size), np.maximum(count - 1, 0)],
                                 start)[again]
                rays = rays[again]
    return best, which, origin, direction


# --------------------------------------------------------------------------------------------
# shading


def _hash3(ix, iy, iz, seed):
    """Deterministic lattice hash → [0, 1) (integer mixing, no global state)."""
    h = (ix.astype(np.int64) * 73856093) ^ (iy.astype(np.int64) * 19349663) \
        ^ (iz.astype(np.int64) * 83492791) ^ (int(seed) * 2654435761)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(0x1000000)


def _value_noise3(p, seed=0):
    """Smooth 3D value noise in [0, 1] at points ``p (N, 3)`` (lattice spacing 1)."""
    f = np.floor(p)
    i = f.astype(np.int64)
    t = p - f
    t = t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
    out = np.zeros(len(p))
    for dx in (0, 1):
        wx = t[:, 0] if dx else 1.0 - t[:, 0]
        for dy in (0, 1):
            wy = t[:, 1] if dy else 1.0 - t[:, 1]
            for dz in (0, 1):
                wz = t[:, 2] if dz else 1.0 - t[:, 2]
                out += wx * wy * wz * _hash3(i[:, 0] + dx, i[:, 1] + dy, i[:, 2] + dz, seed)
    return out


def _turbulence(p, octaves=4, seed=0):
    total, amp, norm = np.zeros(len(p)), 1.0, 0.0
    for k in range(octaves):
        total += amp * _value_noise3(p * (2.0 ** k), seed + k)
        norm += amp
        amp *= 0.5
    return total / norm


def solid_texture(points, kind, *, frequency=4.0, color=(0.8, 0.3, 0.25), seed=0):
    """Procedural solid 3D textures (Trapp & Döllner Fig. 11; Perlin-style) at world points.

    Parameters
    ----------
    points : (N, 3) float
    kind : {"marble", "wood", "noise"}
        marble: ``½ + ½·sin(f·x + 6·turbulence)`` veins; wood: rings around the z axis,
        ``frac(f·r + 2·turbulence)``; noise: 4-octave value noise.
    frequency : float
        Features per world unit.
    color : (3,) float
        The texture's dark colour (mixed with white).

    Returns
    -------
    (N, 3) float64 colours in [0, 1].
    """
    p = as_float_array(points, "points", shape=(None, 3))
    kind = as_choice(kind, "kind", {"marble": "marble", "wood": "wood", "noise": "noise"})
    f = as_real(frequency, "frequency", lo=0.0, lo_open=True)
    c = as_float_array(color, "color", shape=(3,))
    q = p * f
    turb = _turbulence(q, seed=seed)
    if kind == "marble":
        v = 0.5 + 0.5 * np.sin(q[:, 0] + 6.0 * turb)
        v = v ** 0.5
    elif kind == "wood":
        r = np.hypot(q[:, 0], q[:, 1])
        v = (r + 2.0 * turb) % 1.0
        v = 0.35 + 0.65 * v ** 2
    else:
        v = turb
    return np.clip((1.0 - v)[:, None] * c + v[:, None] * np.ones(3), 0.0, 1.0)


@njit(**IJIT)
def _bilinear_column(maps, taps, c):
    """:func:`refraster.clipsurface.offsetmaps.bilinear` of column ``c`` of interleaved maps
    ``(n, 4)``."""
    a, b, cc, d, wa, wb, wc, wd = taps
    return wa * maps[a, c] + wb * maps[b, c] + wc * maps[cc, c] + wd * maps[d, c]


@njit(**IJIT)
def _light_at(x, y, z, k, params, wrap, shading, offset, shape, view, nmat):
    """One cap point on surface k: (s, t), the normal map sampled per component and
    renormalized, turned (Û, V̂, N) → world → eye; shade = occlusion·(0.25 + 0.75·|n·v|).
    ``shading`` holds the normal map's components and the occlusion map interleaved per
    texel (one cache line serves a tap). Returns the eye-space normal and the shade."""
    dx = x - params[k, 0]
    dy = y - params[k, 1]
    dz = z - params[k, 2]
    s = ((dx * params[k, 3] + dy * params[k, 4] + dz * params[k, 5]) / params[k, 12]) \
        * params[k, 14]
    t = ((dx * params[k, 6] + dy * params[k, 7] + dz * params[k, 8]) / params[k, 13]) \
        * params[k, 15]
    taps = bilinear_taps(offset[k], shape[k, 0], shape[k, 1], s, t, wrap[k])
    a = _bilinear_column(shading, taps, 0)
    b = _bilinear_column(shading, taps, 1)
    c = _bilinear_column(shading, taps, 2)
    # the map's normal needs no normalizing of its own: only the eye-space one's direction
    # is kept (the normal matrix is linear)
    wx = a * params[k, 3] + b * params[k, 6] + c * params[k, 9]
    wy = a * params[k, 4] + b * params[k, 7] + c * params[k, 10]
    wz = a * params[k, 5] + b * params[k, 8] + c * params[k, 11]
    ex = nmat[0, 0] * wx + nmat[0, 1] * wy + nmat[0, 2] * wz
    ey = nmat[1, 0] * wx + nmat[1, 1] * wy + nmat[1, 2] * wz
    ez = nmat[2, 0] * wx + nmat[2, 1] * wy + nmat[2, 2] * wz
    length = math.sqrt(ex * ex + ey * ey + ez * ez)
    if length > 0.0:
        inv = 1.0 / length
        ex *= inv
        ey *= inv
        ez *= inv
    px = view[0, 0] * x + view[0, 1] * y + view[0, 2] * z + view[0, 3]
    py = view[1, 0] * x + view[1, 1] * y + view[1, 2] * z + view[1, 3]
    pz = view[2, 0] * x + view[2, 1] * y + view[2, 2] * z + view[2, 3]
    vl = max(math.sqrt(px * px + py * py + pz * pz), 1e-300)
    ndv = abs(ex * px + ey * py + ez * pz) / vl
    return ex, ey, ez, _bilinear_column(shading, taps, 3) * (0.25 + 0.75 * ndv)


@njit(**IJIT)
def _hatch_at(x, y, z, k, params, spacing, shade):
    """45° section hatch in surface k's (Û, V̂) plane, thicker where the shade is dark: ink
    where frac((d·Û + d·V̂) / (√2·spacing)) < 0.15 + 0.6·(1 − shade), d = P − O."""
    dx = x - params[k, 0]
    dy = y - params[k, 1]
    dz = z - params[k, 2]
    u = ((dx * params[k, 3] + dy * params[k, 4] + dz * params[k, 5])
         + (dx * params[k, 6] + dy * params[k, 7] + dz * params[k, 8])) \
        / (math.sqrt(2.0) * spacing)
    return u - math.floor(u) < 0.15 + 0.6 * (1.0 - shade)


@njit(**IJIT)
def _style_color(style, ink, shade, color, c):
    """Channel c of a diffuse (0) or hatched (1) cap colour, clipped to [0, 1]."""
    if style == 0:
        v = color[c] * shade
    elif ink:
        v = color[c] * 0.35
    else:
        v = 0.55 + 0.45 * shade
    return min(max(v, 0.0), 1.0)


@njit(**PJIT)
def _cap_light_kernel(points, which, params, wrap, shading, offset, shape, view, nmat, shade,
                      normal):
    for i in prange(points.shape[0]):
        ex, ey, ez, sh = _light_at(points[i, 0], points[i, 1], points[i, 2], which[i], params,
                                   wrap, shading, offset, shape, view, nmat)
        shade[i] = sh
        normal[i, 0] = ex
        normal[i, 1] = ey
        normal[i, 2] = ez


@njit(**PJIT)
def _hatch_kernel(points, which, params, spacing, shade, color, out):
    for i in prange(points.shape[0]):
        ink = _hatch_at(points[i, 0], points[i, 1], points[i, 2], which[i], params, spacing,
                        shade[i])
        for c in range(3):
            out[i, c] = _style_color(1, ink, shade[i], color, c)


@njit(**PJIT)
def _cap_pixels_kernel(flat, obj, prim, bary, n_solids, n_surf, faces, face_offsets, verts,
                       params, wrap, shading, offset, shape, view, nmat, style, color,
                       spacing, points, shade, out_color, out_normal):
    """The mesh caps' pixels in one pass: world position interpolated from the cap face
    (``(b0·V0 + b1·V1) + b2·V2``, as :meth:`Fragments.world_position`), lighting, and for
    the diffuse and hatch styles the colour, written into the G-buffer (``flat`` pixels)."""
    for i in prange(flat.shape[0]):
        p = flat[i]
        g = face_offsets[obj[p]] + prim[p]
        v0 = faces[g, 0]
        v1 = faces[g, 1]
        v2 = faces[g, 2]
        b0 = np.float64(bary[p, 0])
        b1 = np.float64(bary[p, 1])
        b2 = np.float64(bary[p, 2])
        for j in range(3):
            points[i, j] = (b0 * verts[v0, j] + b1 * verts[v1, j]) + b2 * verts[v2, j]
        k = (obj[p] - n_solids) % n_surf
        ex, ey, ez, sh = _light_at(points[i, 0], points[i, 1], points[i, 2], k, params, wrap,
                                   shading, offset, shape, view, nmat)
        shade[i] = sh
        out_normal[p, 0] = ex
        out_normal[p, 1] = ey
        out_normal[p, 2] = ez
        if style <= 1:
            ink = style == 1 and _hatch_at(points[i, 0], points[i, 1], points[i, 2], k, params,
                                           spacing, sh)
            for c in range(3):
                out_color[p, c] = _style_color(style, ink, sh, color, c)


def _shading_maps(surface, radius):
    """The surface's normal-map components and occlusion map interleaved per texel,
    ``(H·W, 4)`` row-major, made once per surface."""
    key = ("shading", radius)
    if key not in surface._derived:
        n = surface.normal_map()
        maps = np.ascontiguousarray(np.concatenate(
            [n.reshape(-1, 3), surface.occlusion_map(radius=radius).reshape(-1, 1)], axis=1),
            np.float64)
        maps.setflags(write=False)
        surface._derived[key] = maps
    return surface._derived[key]


def _lighting_args(surfaces, view, occlusion_radius, packed=None):
    """Kernel arguments of the cap lighting: parameter table, wrap codes, the interleaved
    normal and occlusion maps of all surfaces, offsets, shapes, view and normal matrix."""
    if packed is None:
        packed = _Packed(surfaces)
    maps = [_shading_maps(s, occlusion_radius) if s.enabled else
            np.zeros((s.offset_map.size, 4)) for s in surfaces]
    shading = maps[0] if len(maps) == 1 else np.concatenate(maps)
    view = np.ascontiguousarray(view, np.float64)
    return (packed.params, packed.wrap, _readonly(shading), packed.offset, packed.shape, view,
            np.linalg.inv(view[:3, :3]).T)


def light_caps(points, surface_index, surfaces, *, view, occlusion_radius=None):
    """Eye-space normal ``(N, 3)`` and shade ``(N,)`` of cap points (see :func:`shade_caps`)."""
    n = len(points)
    shade = np.zeros(n)
    normal = np.zeros((n, 3))
    if n:
        _cap_light_kernel(np.ascontiguousarray(points, np.float64),
                          np.ascontiguousarray(surface_index, np.int64),
                          *_lighting_args(surfaces, view, occlusion_radius), shade, normal)
    return normal, shade


@njit(**PJIT)
def _cap_rows(obj, first, mask, counts):
    """``mask = obj >= first`` (an (H, W) image, as uint8), and each row's count of such
    pixels (a loop LLVM vectorizes)."""
    for r in prange(obj.shape[0]):
        n = 0
        for c in range(obj.shape[1]):
            m = np.uint8(obj[r, np.uint64(c)] >= first)
            mask[r, np.uint64(c)] = m
            n += np.int64(m)
        counts[r] = n


@njit(**PJIT)
def _cap_indices(mask, starts, counts, flat):
    """The row-major indices of ``mask``'s set pixels, row r's ``counts[r]`` from
    ``starts[r]``."""
    w = mask.shape[1]
    for r in prange(mask.shape[0]):
        k = starts[r]
        end = k + counts[r]
        c = 0
        while k < end:
            if mask[r, c]:
                flat[k] = r * w + c
                k += 1
            c += 1


def cap_pixels(object_id, n_solids):
    """``(mask, flat)``: the pixels of an ``(H, W)`` id image showing a cap
    (``object_id >= n_solids``) and their row-major indices, as ``np.flatnonzero(mask)``
    (two parallel passes over the rows instead of NumPy's three single-threaded ones)."""
    h, w = object_id.shape
    mask = OUTPUTS.empty((h, w), np.uint8)   # recycled: no page faults in a steady state
    counts = np.empty(h, np.int64)
    obj = _readonly(np.ascontiguousarray(object_id, np.int32))
    _cap_rows(obj, np.int32(n_solids), mask, counts)
    starts = np.zeros(h, np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    flat = np.empty(int(starts[-1] + counts[-1]), np.int64)
    _cap_indices(_readonly(mask), starts, counts, flat)
    return mask.view(np.bool_), flat


def shade_cap_pixels(flat, gbuffer, n_solids, n_surf, faces, face_offsets, vertices, surfaces,
                     *, view, style, color, hatch_spacing, frequency, occlusion_radius=None,
                     packed=None):
    """:func:`shade_caps` for the mesh caps' pixels of a G-buffer, in place: ``flat`` lists
    the cap pixels (row-major), ``faces``/``vertices`` are all draw calls' (world space for
    the caps), ``face_offsets`` the draw calls' first faces. Writes ``color`` and ``normal``
    and returns the cap points ``(C, 3)`` (world)."""
    n = len(flat)
    points = np.zeros((n, 3))
    shade = np.zeros(n)
    if n == 0:
        return points
    code = {"diffuse": 0, "hatch": 1}.get(style, 2)
    color_img = gbuffer.color.reshape(-1, 3)
    normal_img = gbuffer.normal.reshape(-1, 3)
    _cap_pixels_kernel(flat, gbuffer.object_id.reshape(-1), gbuffer.prim_id.reshape(-1),
                       gbuffer.barycentric.reshape(-1, 3), n_solids, n_surf, faces,
                       face_offsets, vertices,
                       *_lighting_args(surfaces, view, occlusion_radius, packed), code,
                       np.asarray(color, np.float64), float(hatch_spacing), points, shade,
                       color_img, normal_img)
    if code == 2:
        col = solid_texture(points, style, frequency=frequency, color=color) * shade[:, None]
        color_img[flat] = np.clip(col, 0.0, 1.0)
    return points


def shade_caps(points, surface_index, surfaces, *, view, style, color, hatch_spacing,
               frequency, occlusion_radius=None):
    """Colour and eye-space normal of cap points.

    Parameters
    ----------
    points : (N, 3) float world positions on the caps
    surface_index : (N,) int which surface each cap belongs to
    surfaces : list of ClipSurface (their normal and occlusion maps, MATH.md §1.2b, are used)
    view : (4, 4) world → eye
    style : one of :data:`CAP_STYLES`
    color : (3,) base colour; hatch_spacing : world distance of hatch lines; frequency : solid
        texture frequency
    occlusion_radius : float, optional
        Radius of the occlusion maps (:func:`refraster.clipsurface.offsetmaps.occlusion_map`).

    Returns
    -------
    color (N, 3) float64 and normal (N, 3) float64, eye space, unit.

    Notes
    -----
    The normal is the normal map sampled bilinearly (each component, with the surface's wrap
    mode) at ``(s, t)`` and renormalized, turned from the (Û, V̂, N) frame into eye space.
    Lighting: a headlight, ``shade = occlusion·(0.25 + 0.75·|n·v|)``. The hatch is a 45° section
    hatch in the surface's (Û, V̂) plane whose lines thicken where the shade is dark. The
    maps derived from the offset map only: a surface's user textures (``CapTextures``) and
    solid textures are applied by :func:`texture_caps` (``render_clipped`` calls both).
    """
    points = np.ascontiguousarray(points, np.float64)
    surface_index = np.asarray(surface_index, np.int64)
    normal, shade = light_caps(points, surface_index, surfaces, view=view,
                               occlusion_radius=occlusion_radius)
    color = np.asarray(color, np.float64)
    if style == "diffuse":
        col = color[None, :] * shade[:, None]
    elif style == "hatch":
        col = np.zeros((len(points), 3))
        if len(points):
            _hatch_kernel(points, surface_index, _Packed(surfaces).params, float(hatch_spacing),
                          shade, color, col)
    else:
        col = solid_texture(points, style, frequency=frequency, color=color) * shade[:, None]
    return np.clip(col, 0.0, 1.0), normal


def texture_caps(points, surface_index, surfaces, *, view, style, color, occlusion_radius=None,
                 solid_colors=None):
    """Colour and eye-space normal of cap points whose surfaces carry user textures
    (:class:`refraster.clipsurface.textures.CapTextures`) or that take a solid texture.

    Parameters
    ----------
    points : (N, 3) float world positions on the caps
    surface_index : (N,) int which surface each cap point belongs to
    surfaces : list of ClipSurface
    view : (4, 4) world → eye
    style : ``"diffuse"`` (base colour: the surface's diffuse map where it has one, else
        ``color``) or ``"solid"`` (base colour: ``solid_colors``)
    solid_colors : (N, 3) float, optional
        The solid texture sampled at each point in its solid's object space (style "solid").

    Returns
    -------
    color (N, 3) and normal (N, 3) float64 (eye space, unit).

    Notes
    -----
    As :func:`shade_caps`, with each map replaced by the user's where given, all sampled at
    the surface's ``(s, t)`` with ``GL_LINEAR`` and its wrap mode: normal = the user normal
    map decoded into (Û, V̂, N) (else the derived normal map), turned into eye space and
    normalized; ``shade = light·(0.25 + 0.75·|n·v|)`` with light = the user light map (else
    the derived occlusion map); colour = base · shade, clipped to [0, 1].
    """
    points = np.ascontiguousarray(points, np.float64)
    surface_index = np.asarray(surface_index, np.int64)
    n = len(points)
    view = np.asarray(view, np.float64)
    nmat = np.linalg.inv(view[:3, :3]).T
    frame = np.zeros((n, 3))
    light = np.zeros(n)
    base = np.broadcast_to(np.asarray(color, np.float64), (n, 3)).copy()
    for k, s in enumerate(surfaces):
        sel = np.flatnonzero(surface_index == k)
        if sel.size == 0:
            continue
        st = s.texcoords(points[sel])
        tex = s.textures
        if tex is not None and tex.normal is not None:
            frame[sel] = sample_texture(tex.normal_frame, st, wrap=s.wrap)
        else:
            frame[sel] = sample_texture(s.normal_map(), st, wrap=s.wrap)
        if tex is not None and tex.light is not None:
            light[sel] = sample_texture(tex.light, st, wrap=s.wrap)[:, 0]
        else:
            light[sel] = sample_texture(s.occlusion_map(radius=occlusion_radius), st,
                                        wrap=s.wrap)[:, 0]
        if style == "diffuse" and tex is not None and tex.diffuse is not None:
            base[sel] = sample_texture(tex.diffuse, st, wrap=s.wrap)
        world = (frame[sel, 0:1] * s.u_hat + frame[sel, 1:2] * s.v_hat
                 + frame[sel, 2:3] * s.normal)
        frame[sel] = world
    eye_n = frame @ nmat.T
    length = np.linalg.norm(eye_n, axis=1)
    eye_n = np.divide(eye_n, length[:, None], out=np.zeros_like(eye_n),
                      where=length[:, None] > 0)
    eye_p = points @ view[:3, :3].T + view[:3, 3]
    ndv = np.abs(np.einsum("ij,ij->i", eye_n, eye_p)) / np.maximum(
        np.linalg.norm(eye_p, axis=1), 1e-300)
    shade = light * (0.25 + 0.75 * ndv)
    if style == "solid":
        base = np.asarray(solid_colors, np.float64)
    return np.clip(base * shade[:, None], 0.0, 1.0), eye_n
