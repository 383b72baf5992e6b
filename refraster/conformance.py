"""What a conformant GPU may do differently: coverage masks and value intervals.

A golden image that a conformant GPU fails is a flaky test. This module derives, from the
geometry, where another implementation is allowed to differ from refraster, in the spirit of the
Khronos conformance verifier's full / partial / none coverage:

**Coverage** ``(H, W) int8``: ``MUST`` (2) — every allowed rasterizer covers the pixel centre;
``MAY`` (1) — some allowed rasterizer does and some does not; ``MUST_NOT`` (0) — none does.
**Ids** ``id_may (H, W) bool``: the visible primitive may differ (near an edge between two
visible triangles, or where two surfaces are within the depth tolerance of each other).

Allowed variation (documented in ``docs/tolerance.md``): 4 to 8 sub-pixel bits, either fill
rule (bottom-left or top-left), float32 vertex and viewport arithmetic in any order (with or
without FMA, division or reciprocal). A pixel centre is "may" when it lies within ``ε`` of an
edge of a triangle that is relevant there (in front of, or within ``depth_eps`` of, the visible
surface; or anywhere on the background), where

``ε = √2 · (2^−(b_min+1) + 2^−(b_ref+1)) + ε_float``

is the largest distance an edge can move: each vertex is snapped to within half a grid step,
by the candidate (``b_min``: ``min_bits``, 4 by default; a golden passes the bits its
candidates are declared with, ``golden generate --candidate-subpixel-bits``, 8 by default) and
by the reference (``b_ref = 8``), and
``ε_float = 4 ulp_f32(max window coordinate) + 8 · 2^−24 · max(W, H)`` covers float32 viewport
and transform rounding; an edge with an endpoint far from the origin (a huge triangle) adds
``4 ulp_f32`` of that endpoint's coordinate, and a piece of a clipped face adds the float32
rounding of clipping its original clip coordinates (``4 ulp_f32(R)·max(W, H)/2 / w``), so an
edge between two vertices at 1e30 — which no float renderer can place — makes its whole
neighbourhood "may". Coverage is "may" only near edges that can change coverage: border
edges (one face), fold and silhouette edges (two faces of opposite facing) and edges of
non-manifold fans; an edge shared by two faces of the same facing keeps the pixel covered
whatever the snapping (shared vertices snap identically), so there only the id is "may".

Two surfaces are a depth tie (the id "may" differ) when their depths at a pixel differ by at
most the larger of their faces' depth slacks ``depth_eps + 16·2^−24·|∇z|·R``, ``R`` the largest
window coordinate of the face's vertices: a float32 plane equation set up from vertices ``R``
pixels away carries that much rounding (huge triangles).

**Value intervals**: depth ``[lo, hi]`` = ``z ∓ (slack + 1.5 · g · ε)`` with ``g`` the
visible face's depth gradient ``|∇z|`` per pixel (or, for clipped faces, the largest depth step
to a 4-neighbour of the same primitive): moving the vertices by up to ε moves the plane's depth
at a pixel by up to ``|∇z| · ε`` to first order;
normals: ``normal_tol`` radians; colour: ``color_tol`` per channel. Where the id may differ the
intervals are unbounded.

Technique boundaries (a clip surface, the cutaway surface, a parity decision) are handled by
:func:`decision_may`: a pixel is "may" where a fragment in front of (or within ``depth_eps`` of)
the visible surface has a decision value within ``eps`` of its threshold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ._config import JIT
from ._validate import as_real
from .raster import prepare, resolve
from .raster.state import RasterState
from .raster.primitive import CLIPPED, SIMPLE
from .raster.rasterizer import stream

__all__ = ["MUST_NOT", "MAY", "MUST", "Tolerance", "tolerance", "decision_may", "edge_epsilon",
           "edge_may", "facing_may", "may_faces", "check"]

MUST_NOT, MAY, MUST = 0, 1, 2
#: Depth difference two surfaces need to be ordered the same by any conformant depth buffer
#: (float32 transform + interpolation; refraster vs llvmpipe agree within 2e-5, docs/oracles.md).
DEPTH_EPS = 4e-5
#: Angle (radians) within which eye-space normals of the same face must agree.
NORMAL_TOL = 2e-3
#: Per-channel colour tolerance of the simple shade where the id must agree.
COLOR_TOL = 2.0 / 255.0


def _geometry_state(cull, raster):
    """The state the allowance functions prepare with: ``cull`` and, from ``raster`` (a
    :class:`RasterState` or None), the clip volume's ``depth_clamp``. The allowances are
    derived in OpenGL's conventions (counter-clockwise fronts, ``less``, −w ≤ z ≤ w, NDC y up);
    a scene in others is first mapped into them (:mod:`refraster.golden.allowances.conventions`,
    docs/tolerance.md, "Conventions"), so any other field away from its default is refused."""
    if raster is None:
        return RasterState(cull=cull)
    if not isinstance(raster, RasterState):
        raise TypeError(f"raster must be a refraster.RasterState or None, got "
                        f"{type(raster).__name__}")
    from .raster.state import require_default
    require_default(raster, ("depth_func", "front_face", "depth_range", "origin", "ndc_y"),
                    "the conformance allowances (map the scene into OpenGL's conventions)")
    if raster.cull != cull:
        raise ValueError(f"raster.cull ({raster.cull!r}) and cull ({cull!r}) differ")
    # the reference's own rasterization (its bits, fill rule and precision): the masks'
    # "must" and "must not" are the reference's coverage, so they are made with its state
    return RasterState(cull=cull, depth_clamp=raster.depth_clamp,
                       subpixel_bits=raster.subpixel_bits, fill_rule=raster.fill_rule,
                       precision=raster.precision)


def edge_epsilon(width, height, *, min_bits=4, ref_bits=8):
    """The largest distance (pixels) an edge may move between allowed rasterizers."""
    snap = np.sqrt(2.0) * (2.0 ** -(min_bits + 1) + 2.0 ** -(ref_bits + 1))
    m = float(max(width, height))
    ulp = np.spacing(np.float32(m))
    return float(snap + 4.0 * ulp + 8.0 * 2.0 ** -24 * m)


@dataclass(eq=False)
class Tolerance:
    """Per-pixel allowances for one scene (all ``(H, W, …)``, row 0 at the top)."""

    coverage: np.ndarray      # int8: MUST_NOT / MAY / MUST
    id_may: np.ndarray        # bool
    depth_lo: np.ndarray      # float32
    depth_hi: np.ndarray      # float32
    eps: float
    depth_eps: float
    normal_tol: float = NORMAL_TOL
    color_tol: float = COLOR_TOL

    def arrays(self):
        return dict(coverage=self.coverage, id_may=self.id_may, depth_lo=self.depth_lo,
                    depth_hi=self.depth_hi)


@njit(**JIT)
def _plane_z(x0, y0, z0, x1, y1, z1, x2, y2, z2, px, py):
    """Depth of the triangle's plane at (px, py); the vertices' minimum when degenerate."""
    d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    if d == 0.0:
        return min(z0, z1, z2)
    a = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / d
    b = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / d
    return z0 + a * (z1 - z0) + b * (z2 - z0)


@njit(**JIT)
def _mark_edge(xa, ya, xb, yb, tri, eps, depth_eps, winz, covered, boundary, id_may, cov_may):
    """Mark pixel centres within eps (widened for far endpoints) of the segment a–b."""
    x0, y0, z0, x1, y1, z1, x2, y2, z2 = tri
    h, w = winz.shape
    # float32 window positions far from the origin carry rounding at their own scale
    big = min(max(abs(xa), abs(ya), abs(xb), abs(yb)), 1e30)
    eps = eps + 4.0 * np.float64(np.spacing(np.float32(big)))
    eps = min(eps, 2.0 * (w + h))  # beyond this everything is marked; keeps the ints in range
    ylo = max(int(np.floor(min(ya, yb) - eps)), 0)
    yhi = min(int(np.ceil(max(ya, yb) + eps)), h - 1)
    dx = xb - xa
    dy = yb - ya
    ll = dx * dx + dy * dy
    for y in range(ylo, yhi + 1):
        # x-range of the segment's part within eps of this row, widened by eps
        if dy != 0.0:
            t0 = min(max((y - eps - ya) / dy, 0.0), 1.0)
            t1 = min(max((y + eps - ya) / dy, 0.0), 1.0)
            xs0 = xa + t0 * dx
            xs1 = xa + t1 * dx
        else:
            xs0 = xa
            xs1 = xb
        xlo = max(int(np.floor(min(xs0, xs1) - eps)), 0)
        xhi = min(int(np.ceil(max(xs0, xs1) + eps)), w - 1)
        row = h - 1 - y
        for x in range(xlo, xhi + 1):
            t = 0.0
            if ll > 0.0:
                t = min(max(((x - xa) * dx + (y - ya) * dy) / ll, 0.0), 1.0)
            ex = xa + t * dx - x
            ey = ya + t * dy - y
            if ex * ex + ey * ey > eps * eps:
                continue
            if covered[row, x]:
                zt = _plane_z(x0, y0, z0, x1, y1, z1, x2, y2, z2, np.float64(x), np.float64(y))
                if zt > winz[row, x] + depth_eps:
                    continue
            id_may[row, x] = True
            if boundary:
                cov_may[row, x] = True


@njit(**JIT)
def _mark_faces(f, vX, vY, vZ, vcode, status, cull, edge_boundary, scale, sX, sY, sZ, sprim,
                seps, fslack, eps, winz, covered, id_may, cov_may, exact):
    tri = np.zeros(9)
    for i in range(f.shape[0]):
        if status[i] == CLIPPED or exact[i]:
            continue   # exact: every allowed candidate places the edges, the rule decides ties
        a, b, d = f[i, 0], f[i, 1], f[i, 2]
        if vcode[a] | vcode[b] | vcode[d]:
            continue
        x0, y0 = vX[a] / scale, vY[a] / scale
        x1, y1 = vX[b] / scale, vY[b] / scale
        x2, y2 = vX[d] / scale, vY[d] / scale
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if status[i] != SIMPLE and ((cull == 1 and area < 0) or (cull == 2 and area > 0)):
            continue  # culled, and not edge-on: no allowed rasterizer draws it
        tri[0], tri[1], tri[2] = x0, y0, vZ[a]
        tri[3], tri[4], tri[5] = x1, y1, vZ[b]
        tri[6], tri[7], tri[8] = x2, y2, vZ[d]
        xs = (x0, x1, x2)
        ys = (y0, y1, y2)
        for k in range(3):
            _mark_edge(xs[k], ys[k], xs[(k + 1) % 3], ys[(k + 1) % 3], tri, eps, fslack[i],
                       winz, covered, edge_boundary[i, k], id_may, cov_may)
    for k in range(sprim.shape[0]):
        for j in range(3):
            tri[3 * j] = sX[k, j] / scale
            tri[3 * j + 1] = sY[k, j] / scale
            tri[3 * j + 2] = sZ[k, j]
        for j in range(3):
            _mark_edge(tri[3 * j], tri[3 * j + 1], tri[3 * ((j + 1) % 3)],
                       tri[3 * ((j + 1) % 3) + 1], tri, eps + seps[k], fslack[sprim[k]],
                       winz, covered, True, id_may, cov_may)


#: Fill rules a golden declares as the candidate's own, exact at ties: Direct3D's top-left rule
#: (``fill_rule="top_left"``, the d3d12 convention). Under the others (OpenGL's, and Vulkan's
#: and WebGPU's, which leave ties to the implementation) a centre on an edge is "may".
EXACT_FILL_RULES = ("top-left",)


def exact_faces(prep, min_bits):
    """(F,) bool: faces that every allowed candidate places exactly — unclipped, and each vertex's
    exact window position (from the float64 matrices and positions) on the ``2^−min_bits``
    grid of the coarsest declared snapping, within ``2·max(W, H)`` of the origin, while the
    float32 rounding a candidate's transform and viewport may add (``ε_float`` of
    :func:`edge_epsilon`) stays below half a step of the finest allowed grid (``2^−9`` px):
    every candidate of 4…8 bits then snaps each vertex onto the same grid point, and a pixel
    centre on such an edge is decided by the declared rule (docs/tolerance.md, "Ties under
    Direct3D")."""
    p = prep.triangles
    f = p.faces
    out = np.zeros(len(f), np.bool_)
    w, h = prep.width, prep.height
    m = float(max(w, h))
    e_float = 4.0 * float(np.spacing(np.float32(m))) + 8.0 * 2.0 ** -24 * m
    if not len(f) or e_float >= 2.0 ** -9:
        return out
    clip = np.concatenate([
        np.column_stack([np.asarray(mesh.vertices, np.float64), np.ones(mesh.n_vertices)])
        @ (np.asarray(prep.proj, np.float64) @ np.asarray(prep.view, np.float64)
           @ np.asarray(model, np.float64)).T
        for mesh, model in zip(prep.meshes, prep.models)])
    cw = clip[:, 3]
    front = cw > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        X = (clip[:, 0] / cw + 1.0) * 0.5 * w
        Y = (clip[:, 1] / cw + 1.0) * 0.5 * h
    step = float(1 << min_bits)

    def on_grid(v):
        k = v * step
        return np.isfinite(k) & (np.abs(k - np.rint(k)) <= 1e-9 * np.maximum(1.0, np.abs(k))) \
            & (np.abs(v) <= 2.0 * m)

    ok = front & on_grid(X) & on_grid(Y)
    out = ok[f].all(axis=1) & (p.vcode[f].max(axis=1) == 0) & (p.status != CLIPPED)
    return out


def _edge_boundary(faces, front):
    """(F, 3) bool: may edge k (from vertex k to k+1) of each face change coverage?

    False only for an edge shared by exactly two faces of the same facing."""
    f = np.asarray(faces, np.int64)
    nf = len(f)
    if nf == 0:
        return np.zeros((0, 3), np.bool_)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    key = np.minimum(a, b) * (int(f.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.r_[True, ks[1:] != ks[:-1]]
    group = np.cumsum(start) - 1
    count = np.bincount(group)
    face_of = order % nf
    fr = front[face_of]
    nfront = np.bincount(group, weights=fr.astype(np.float64))
    interior = (count[group] == 2) & ((nfront[group] == 0) | (nfront[group] == 2))
    out = np.ones(3 * nf, np.bool_)
    out[order] = ~interior
    return out.reshape(3, nf).T.copy()


def tolerance(meshes, *, view, proj, width, height, model=None, cull="none", eps=None,
              depth_eps=DEPTH_EPS, min_bits=4, raster=None):
    """Coverage masks, id masks and depth intervals for rendering ``meshes`` (as
    :func:`refraster.render` would, with ``depth_func="less"``).

    Parameters
    ----------
    meshes, view, proj, width, height, model, cull
        As :func:`refraster.render`.
    eps : float, optional
        Edge tolerance in pixels; default :func:`edge_epsilon` (4 to 8 sub-pixel bits).
    depth_eps : float
        Window-depth tolerance for depth ties and depth intervals.
    min_bits : int
        Coarsest sub-pixel precision allowed (4 by default).
    raster : RasterState, optional
        Its ``depth_clamp`` sets the clip volume (no near/far clipping); its ``cull`` must be
        ``cull``. The allowances are OpenGL's: a state in other conventions is refused
        (``docs/tolerance.md``, "Conventions", maps a scene into them).

    Returns
    -------
    Tolerance
    """
    prep = prepare(meshes, view=view, proj=proj, width=width, height=height, model=model,
                   raster=_geometry_state(cull, raster))
    w, h = prep.width, prep.height
    eps = (edge_epsilon(w, h, min_bits=min_bits, ref_bits=prep.triangles.subpixel_bits)
           if eps is None else as_real(eps, "eps", lo=0.0))
    depth_eps = as_real(depth_eps, "depth_eps", lo=0.0)
    pixel, depth, obj, prim32, front, bary, _ = stream(prep.triangles, fill_rule=prep.fill_rule)
    prim = prim32.astype(np.int64)   # the global face index (one draw call for the stream)
    from .raster import Fragments
    frags = Fragments(pixel, depth, prim32, obj, bary, front, w, h)
    res = resolve(frags)
    win = res.winner
    covered = win >= 0
    winz = res.depth.astype(np.float64)
    vis_prim = (np.where(covered, prim[np.maximum(win, 0)], -1) if len(prim)
                else np.full(win.shape, -1, np.int64))
    p = prep.triangles
    face_front = _face_facing(p)
    fslack = _depth_slacks(prep, depth_eps)
    id_may = np.zeros((h, w), np.bool_)
    cov_may = np.zeros((h, w), np.bool_)
    _mark_faces(p.faces, p.vx, p.vy, p.vz, p.vcode, p.status, {"none": 0, "back": 1,
                "front": 2}[cull.lower()], _edge_boundary(p.faces, face_front),
                float(1 << p.subpixel_bits), p.clipped.x, p.clipped.y, p.clipped.z,
                p.clipped.prim, _piece_epsilon(prep), fslack, eps, winz, covered, id_may,
                cov_may, exact_faces(prep, min_bits) if raster is not None
                and raster.fill_rule in EXACT_FILL_RULES else np.zeros(len(p.faces), np.bool_))
    # depth ties: another primitive within the depth slack of the visible one, each slack at
    # the pixel (a clipped face's part falls with 1/w there: _clipped_slack_at)
    fbase = _face_depth_slack(p, depth_eps)
    vis_flat = vis_prim.ravel()[pixel]
    zw = res.depth.ravel()[pixel].astype(np.float64)
    px, py = pixel_centres(pixel, w, h)
    vis_all = vis_prim.ravel()
    cov_flat = np.flatnonzero(vis_all >= 0)
    vis_slack = np.full(h * w, depth_eps)
    vis_slack[cov_flat] = fbase[vis_all[cov_flat]] + _clipped_slack_at(
        prep, vis_all[cov_flat], *pixel_centres(cov_flat, w, h))
    frag_slack = fbase[prim] + _clipped_slack_at(prep, prim, px, py) if len(prim) else \
        np.zeros(0)
    slack_i = np.maximum(frag_slack, vis_slack[pixel])
    tie = (np.abs(depth.astype(np.float64) - zw) <= slack_i) & (prim != vis_flat)
    id_may.ravel()[pixel[tie]] = True
    coverage = np.where(covered, MUST, MUST_NOT).astype(np.int8)
    coverage[cov_may] = MAY
    g = np.maximum(_depth_step(res.depth, vis_prim), _plane_gradient(p, vis_prim))
    # moving the vertices by up to eps moves the plane's depth at a pixel by up to |∇z|·eps
    # (first order; 1.5× for the second-order terms)
    slack = vis_slack.reshape(h, w) + 1.5 * g * eps
    lo = np.where(covered, res.depth - slack, 0.0).astype(np.float32)
    hi = np.where(covered, res.depth + slack, 1.0).astype(np.float32)
    lo[id_may] = 0.0
    hi[id_may] = 1.0
    return Tolerance(coverage=coverage, id_may=id_may, depth_lo=lo, depth_hi=hi, eps=eps,
                     depth_eps=depth_eps)


def pixel_centres(pixel, width, height):
    """Window points ``px, py`` (pixels, GL y-up, centres at +0.5) of flat pixel indices (row 0
    at the top)."""
    rows, cols = np.divmod(np.asarray(pixel, np.int64), width)
    return cols + 0.5, (height - 1 - rows) + 0.5


def _clipped_slack_at(prep, faces, px, py):
    """Per entry — a global face ``faces[i]`` at the window point ``(px[i], py[i])`` (pixels,
    GL y-up) — the window-depth slack a clipped face's new vertices bring **at that point**
    (0 for a face not clipped; docs/tolerance.md, "Clipped pieces, per pixel").

    A new vertex ``V_k`` is placed by float32 clipping to ``4 ulp_f32(R)`` in each clip
    coordinate (``R`` the largest of the face's), which moves it off the face's plane by at
    most ``e_k = 4 ulp_f32(R)/w_k·(1 + g·max(W, H)/2)`` in window depth (``g`` the plane's
    depth gradient per pixel: the depth error, and the window position's error times the
    gradient). The plane through the moved vertices differs at a point by the weights of the
    piece's vertices there: ``Σ λ_k e_k``, and ``Σ λ_k / w_k = 1/w(p)`` (``1/w`` is affine in
    window coordinates over a plane), so the slack at the point is
    ``4 ulp_f32(R)·(1 + g·max(W, H)/2)/w(p)``, ``1/w(p)`` capped at the face's largest
    ``1/w`` over its pieces (the per-face worst case, where ``λ = 1`` at its nearest new
    vertex)."""
    faces = np.asarray(faces, np.int64)
    out = np.zeros(len(faces))
    st = prep.triangles.clipped
    if not len(st) or not len(faces):
        return out
    inv_max = np.zeros(len(prep.triangles.faces))
    np.maximum.at(inv_max, st.prim, st.inv_w.max(axis=1).astype(np.float64))
    sel = np.flatnonzero(inv_max[faces] > 0.0)
    if not len(sel):
        return out
    f = faces[sel]
    c = prep.clip[prep.triangles.faces[f]].astype(np.float64)             # (m, 3, 4)
    r = _clip_ulp(np.abs(c).max(axis=(1, 2)))
    m = c[:, :, [0, 1, 3]]
    ok = np.abs(np.linalg.det(m)) > 1e-300
    m[~ok] = np.eye(3)
    # a·x + b·y + c·w = 1 and α·x + β·y + δ·w = z at the vertices: 1/w and z/w over NDC x, y
    inv_c = np.linalg.solve(m, np.ones((len(f), 3, 1)))[:, :, 0]
    z_c = np.linalg.solve(m, c[:, :, 2:3])[:, :, 0]
    wd, ht = prep.width, prep.height
    xn = 2.0 * np.asarray(px, np.float64)[sel] / wd - 1.0
    yn = 2.0 * np.asarray(py, np.float64)[sel] / ht - 1.0
    inv = inv_c[:, 0] * xn + inv_c[:, 1] * yn + inv_c[:, 2]
    inv = np.where(ok & (inv > 0.0), np.minimum(inv, inv_max[f]), inv_max[f])
    # window depth ½·z/w + ½ per window pixel: ½·α·2/W, ½·β·2/H
    g = np.where(ok, np.hypot(z_c[:, 0] / wd, z_c[:, 1] / ht), 0.0)
    out[sel] = 4.0 * r * inv * (1.0 + g * max(wd, ht) / 2.0)
    return out


def _depth_slacks(prep, depth_eps):
    """Per-face depth slack (:func:`_face_depth_slack`); the depth of a clipped face's new
    vertex carries float32 clipping rounding too, here its worst case over the face (where it
    decides which faces may win; a visible pixel's own interval takes it at the pixel,
    :func:`_clipped_slack_at`)."""
    p = prep.triangles
    fslack = _face_depth_slack(p, depth_eps)
    if len(p.clipped):
        c = prep.clip[p.faces[p.clipped.prim]]
        w_min = 1.0 / p.clipped.inv_w.max(axis=1)
        extra = np.zeros(len(fslack))
        np.maximum.at(extra, p.clipped.prim, 4.0 * _clip_ulp(np.abs(c).max(axis=(1, 2))) / w_min)
        fslack += extra
    return fslack


@njit(**JIT)
def _seg_dist(px, py, ax, ay, bx, by):
    """Distance from (px, py) to the segment a–b."""
    dx = bx - ax
    dy = by - ay
    ll = dx * dx + dy * dy
    t = 0.0
    if ll > 0.0:
        t = min(max(((px - ax) * dx + (py - ay) * dy) / ll, 0.0), 1.0)
    ex = ax + t * dx - px
    ey = ay + t * dy - py
    return np.sqrt(ex * ex + ey * ey)


@njit(**JIT)
def _set_pass(mode, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets, out):
    """One pass over screen pieces (``X, Y, Z (T, 3)`` window coordinates in pixels, GL y-up,
    pixel centres at integers; ``face (T,)`` the global face of each piece).

    ``mode`` 0: ``zsure[r, c]`` = the least ``z + ε·|∇z| + slack`` of the pieces that surely
    cover the centre (inside and at least ``ε`` from every edge); 1: count, 2: write the pieces
    whose ε-dilated footprint covers the centre and whose least depth over the ε-disc, less
    their slack, is not behind ``zsure``. Only pixels of ``mask`` are visited."""
    h, w = mask.shape
    for t in range(X.shape[0]):
        x0, x1, x2 = X[t, 0], X[t, 1], X[t, 2]
        y0, y1, y2 = Y[t, 0], Y[t, 1], Y[t, 2]
        z0, z1, z2 = Z[t, 0], Z[t, 1], Z[t, 2]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if mode == 0 and (area == 0.0 or fragile[face[t]]):
            continue   # a sliver may vanish or flip: it covers nothing surely
        sgn = 1.0 if area > 0.0 else -1.0
        g = 0.0
        if area != 0.0:
            a = ((z1 - z0) * (y2 - y0) - (z2 - z0) * (y1 - y0)) / area
            b = ((x1 - x0) * (z2 - z0) - (x2 - x0) * (z1 - z0)) / area
            g = np.sqrt(a * a + b * b)
        cx0 = max(int(np.ceil(min(x0, x1, x2) - eps)), 0)
        cx1 = min(int(np.floor(max(x0, x1, x2) + eps)), w - 1)
        cy0 = max(int(np.ceil(min(y0, y1, y2) - eps)), 0)
        cy1 = min(int(np.floor(max(y0, y1, y2) + eps)), h - 1)
        sl = fslack[face[t]]
        weak = fragile[face[t]]
        reach = 5.0 * eps if weak else eps
        if weak:
            cx0 = max(int(np.ceil(min(x0, x1, x2) - reach)), 0)
            cx1 = min(int(np.floor(max(x0, x1, x2) + reach)), w - 1)
            cy0 = max(int(np.ceil(min(y0, y1, y2) - reach)), 0)
            cy1 = min(int(np.floor(max(y0, y1, y2) + reach)), h - 1)
        for gy in range(cy0, cy1 + 1):
            r = h - 1 - gy
            py = float(gy)
            for cc in range(cx0, cx1 + 1):
                if not mask[r, cc]:
                    continue
                px = float(cc)
                e0 = sgn * ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0))
                e1 = sgn * ((x2 - x1) * (py - y1) - (px - x1) * (y2 - y1))
                e2 = sgn * ((x0 - x2) * (py - y2) - (px - x2) * (y0 - y2))
                inside = area != 0.0 and e0 >= 0.0 and e1 >= 0.0 and e2 >= 0.0
                zc = _plane_z(x0, y0, z0, x1, y1, z1, x2, y2, z2, px, py)
                if mode == 0:
                    if not inside:
                        continue
                    l0 = np.hypot(x1 - x0, y1 - y0)
                    l1 = np.hypot(x2 - x1, y2 - y1)
                    l2 = np.hypot(x0 - x2, y0 - y2)
                    if e0 >= eps * l0 and e1 >= eps * l1 and e2 >= eps * l2:
                        zsure[r, cc] = min(zsure[r, cc], zc + eps * g + sl)
                    continue
                if not inside:
                    d = min(_seg_dist(px, py, x0, y0, x1, y1), _seg_dist(px, py, x1, y1, x2, y2),
                            _seg_dist(px, py, x2, y2, x0, y0))
                    if d > reach:
                        continue
                # a sliver's plane is ill-conditioned: snapped otherwise, its depth at the
                # centre can be anything, so it may win wherever it may cover
                if not weak and zc - eps * g - sl > zsure[r, cc]:
                    continue
                k = r * w + cc
                if mode == 1:
                    counts[k] += 1
                else:
                    out[offsets[k] + counts[k]] = face[t]
                    counts[k] += 1


def may_faces(meshes, *, view, proj, width, height, model=None, cull="none", mask=None,
              eps=None, depth_eps=DEPTH_EPS, min_bits=4, raster=None):
    """Per pixel, the faces that may be visible there in an allowed rasterizer.

    A face may win at a pixel centre when its footprint, dilated by the edge tolerance ``ε``
    (:func:`edge_epsilon`), covers the centre and its least depth over the ε-disc, less its
    depth slack, is not behind the farthest the nearest *surely covering* face can be there (a
    face whose footprint covers the centre with ``ε`` to spare, at its depth plus ``ε·|∇z|``
    plus its slack). Culled faces are left out, except slivers whose facing may flip
    (:func:`fragile_faces`); a sliver never counts as surely covering, and — its plane being
    ill-conditioned, so that another snapping can put its depth anywhere — may win wherever
    its footprint dilated by ``5ε`` (as in :func:`facing_may`) covers the centre.

    Parameters
    ----------
    meshes, view, proj, width, height, model, cull
        As :func:`refraster.render`.
    mask : (H, W) bool, optional
        Only these pixels (default: all).
    raster : RasterState, optional
        As :func:`tolerance` (its ``depth_clamp``).

    Returns
    -------
    offsets : (H·W + 1,) int64
        The faces of pixel ``k = row·W + col`` are ``faces[offsets[k]:offsets[k + 1]]``.
    faces : (N,) int64
        Global face indices (draw calls concatenated in draw order), ascending per pixel,
        without repeats.
    """
    prep = prepare(meshes, view=view, proj=proj, width=width, height=height, model=model,
                   raster=_geometry_state(cull, raster))
    w, h = prep.width, prep.height
    eps = (edge_epsilon(w, h, min_bits=min_bits, ref_bits=prep.triangles.subpixel_bits)
           if eps is None else as_real(eps, "eps", lo=0.0))
    mask = np.ones((h, w), np.bool_) if mask is None else np.ascontiguousarray(mask, np.bool_)
    p = prep.triangles
    scale = float(1 << p.subpixel_bits)
    fslack = _depth_slacks(prep, as_real(depth_eps, "depth_eps", lo=0.0))
    f = p.faces
    whole = np.flatnonzero(p.vcode[f].max(axis=1) == 0) if len(f) else np.zeros(0, np.int64)
    X = p.vx[f[whole]] / scale
    Y = p.vy[f[whole]] / scale
    area = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (X[:, 2] - X[:, 0]) * (Y[:, 1] - Y[:, 0])
    code = {"none": 0, "back": 1, "front": 2}[cull.lower()]
    fragile = fragile_faces(prep, eps)
    # culled faces are left out, but for slivers whose facing may flip
    keep = ~(((code == 1) & (area < 0)) | ((code == 2) & (area > 0))) | fragile[whole]
    whole = whole[keep]
    st = p.clipped
    X = np.concatenate([p.vx[f[whole]] / scale, st.x / scale])
    Y = np.concatenate([p.vy[f[whole]] / scale, st.y / scale])
    Z = np.concatenate([p.vz[f[whole]].astype(np.float64), st.z.astype(np.float64)])
    face = np.concatenate([whole, st.prim]).astype(np.int64)
    zsure = np.full((h, w), np.inf)
    counts = np.zeros(h * w, np.int64)
    offsets = np.zeros(h * w + 1, np.int64)
    out = np.zeros(0, np.int64)
    _set_pass(0, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets[:-1], out)
    _set_pass(1, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets[:-1], out)
    offsets[1:] = np.cumsum(counts)
    out = np.zeros(int(offsets[-1]), np.int64)
    counts[:] = 0
    _set_pass(2, X, Y, Z, face, fragile, eps, fslack, mask, zsure, counts, offsets[:-1], out)
    # pieces of one clipped face may both count: sort and drop repeats per pixel
    pix = np.repeat(np.arange(h * w), np.diff(offsets))
    order = np.lexsort((out, pix))
    pix, out = pix[order], out[order]
    keep = np.r_[True, (pix[1:] != pix[:-1]) | (out[1:] != out[:-1])] if len(out) else \
        np.zeros(0, np.bool_)
    pix, out = pix[keep], out[keep]
    offsets = np.zeros(h * w + 1, np.int64)
    np.add.at(offsets, pix + 1, 1)
    return np.cumsum(offsets), out


def _piece_epsilon(prep):
    """Extra edge tolerance (pixels) of each clipped piece: its new vertices were computed from
    clip coordinates of magnitude ``R``, which float32 clipping places only to
    ``ulp_f32(R) · max(W, H)/2 / w`` pixels (``w`` the piece's smallest clip w)."""
    st = prep.triangles.clipped
    if len(st) == 0:
        return np.zeros(0)
    c = prep.clip[prep.triangles.faces[st.prim]]          # (T, 3, 4)
    w_min = 1.0 / st.inv_w.max(axis=1)
    return (4.0 * _clip_ulp(np.abs(c).max(axis=(1, 2))) * max(prep.width, prep.height) / 2
            / w_min)


def _clip_ulp(r):
    """``ulp_f32(R)`` of clipped faces' largest clip coordinates ``R``; a face whose ``R`` is
    beyond float32's range (a float64 vertex stage carries it) is refused with one line: a
    float32 candidate cannot clip it, so no allowance can say what it draws."""
    r = np.asarray(r, np.float64)
    big = r > float(np.finfo(np.float32).max)
    if big.any():
        raise ValueError(f"a face crossing a clip plane has clip coordinates up to "
                         f"{float(r.max()):.3g}, beyond float32 (a float32 candidate cannot "
                         "clip it): scale the scene down")
    return np.spacing(r.astype(np.float32)).astype(np.float64)


def _face_depth_slack(prims, depth_eps):
    """Per-face window-depth tolerance: ``depth_eps + 16·2^−24 · |∇z| · R``.

    A GPU evaluates the depth plane in float32 from vertex positions of magnitude ``R`` (window
    pixels); the plane's constant term then carries rounding of ``|∇z| · R`` times a few ulp,
    which for a triangle with a vertex 1e6 px away is far above ``depth_eps``."""
    f = prims.faces
    nf = len(f)
    slack = np.full(nf, depth_eps)
    if nf == 0:
        return slack
    scale = float(1 << prims.subpixel_bits)

    def grad_radius(x, y, z):
        area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
        ok = area != 0
        area = np.where(ok, area, 1.0)
        zx = (z[:, 1] - z[:, 0]) * (y[:, 2] - y[:, 0]) - (z[:, 2] - z[:, 0]) * (y[:, 1] - y[:, 0])
        zy = (x[:, 1] - x[:, 0]) * (z[:, 2] - z[:, 0]) - (x[:, 2] - x[:, 0]) * (z[:, 1] - z[:, 0])
        g = np.where(ok, np.hypot(zx, zy) / np.abs(area), 0.0)
        r = np.maximum(np.abs(x).max(axis=1), np.abs(y).max(axis=1))
        return g * r

    simple = prims.vcode[f].max(axis=1) == 0
    fs = f[simple]
    gr = grad_radius(prims.vx[fs] / scale, prims.vy[fs] / scale, prims.vz[fs].astype(np.float64))
    slack[simple] += 16.0 * 2.0 ** -24 * gr
    st = prims.clipped
    if len(st):
        gr = grad_radius(st.x / scale, st.y / scale, st.z.astype(np.float64))
        extra = np.zeros(nf)
        np.maximum.at(extra, st.prim, 16.0 * 2.0 ** -24 * gr)
        slack += extra
    return slack


def _face_facing(prims):
    """Facing of every face from its snapped window area (clipped faces: their pieces')."""
    f = prims.faces
    X, Y = prims.vx, prims.vy
    area = (X[f[:, 1]] - X[f[:, 0]]) * (Y[f[:, 2]] - Y[f[:, 0]]) \
        - (X[f[:, 2]] - X[f[:, 0]]) * (Y[f[:, 1]] - Y[f[:, 0]])
    front = area > 0
    st = prims.clipped
    front[st.prim] = st.front
    return front


def _plane_gradient(prims, vis_prim):
    """|∇z| (window depth per pixel) of the visible face's plane; 0 for clipped faces."""
    g = np.zeros(vis_prim.shape)
    m = vis_prim >= 0
    face = vis_prim[m]
    f = prims.faces[face]
    ok = (prims.vcode[f].max(axis=1) == 0)
    scale = float(1 << prims.subpixel_bits)
    x = prims.vx[f] / scale
    y = prims.vy[f] / scale
    z = prims.vz[f].astype(np.float64)
    area = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    ok &= area != 0
    area = np.where(ok, area, 1.0)
    zx = ((z[:, 1] - z[:, 0]) * (y[:, 2] - y[:, 0]) - (z[:, 2] - z[:, 0]) * (y[:, 1] - y[:, 0]))
    zy = ((x[:, 1] - x[:, 0]) * (z[:, 2] - z[:, 0]) - (x[:, 2] - x[:, 0]) * (z[:, 1] - z[:, 0]))
    g[m] = np.where(ok, np.hypot(zx, zy) / np.abs(area), 0.0)
    return g


def _depth_step(depth, prim):
    d = depth.astype(np.float64)
    g = np.zeros_like(d)
    for axis in (0, 1):
        diff = np.abs(np.diff(d, axis=axis))
        same = (np.diff(prim, axis=axis) == 0) & (np.take(prim, range(prim.shape[axis] - 1),
                                                          axis=axis) >= 0)
        diff = np.where(same, diff, 0.0)
        pad_lo = [(0, 0), (0, 0)]
        pad_hi = [(0, 0), (0, 0)]
        pad_lo[axis] = (1, 0)
        pad_hi[axis] = (0, 1)
        g = np.maximum(g, np.maximum(np.pad(diff, pad_lo), np.pad(diff, pad_hi)))
    return g


def decision_may(frags, resolved, decision, eps, *, depth_eps=DEPTH_EPS):
    """Pixels where a technique's per-fragment decision is within ``eps`` of its threshold.

    ``decision (N,)``: a signed value whose sign decides the fragment's fate (a clip surface's
    g(P), the cutaway's ``z − D(x)``, the distance to the nearest LDI layer). A pixel is "may"
    where any fragment in front of, or within ``depth_eps`` of, the visible surface (or any
    fragment, on a background pixel) has ``|decision| ≤ eps``.
    """
    decision = np.asarray(decision, np.float64)
    if decision.shape != (len(frags),):
        raise ValueError(f"decision must have shape ({len(frags)},), got {decision.shape}")
    eps = as_real(eps, "eps", lo=0.0)
    zvis = resolved.depth.ravel()[frags.pixel].astype(np.float64)
    covered = resolved.winner.ravel()[frags.pixel] >= 0
    relevant = ~covered | (frags.depth <= zvis + depth_eps)
    near = relevant & (np.abs(decision) <= eps)
    out = np.zeros(frags.height * frags.width, np.bool_)
    out[frags.pixel[near]] = True
    return out.reshape(frags.height, frags.width)


def check(tol, *, prim_id=None, depth=None, reference_prim_id=None):
    """Pixels of a candidate outside the allowances: a dict of ``(H, W)`` bool masks.

    ``coverage``: covered where MUST_NOT or uncovered where MUST (from ``prim_id`` ≥ 0, or
    ``depth`` < 1 when no ids are given); ``prim_id``: differs from ``reference_prim_id`` where
    the id must agree; ``depth``: outside ``[depth_lo, depth_hi]`` where covered in both.
    """
    out = {}
    if prim_id is not None:
        cand_cov = np.asarray(prim_id) >= 0
    elif depth is not None:
        cand_cov = np.asarray(depth) < 1.0
    else:
        raise ValueError("check needs prim_id or depth")
    out["coverage"] = ((tol.coverage == MUST) & ~cand_cov) | ((tol.coverage == MUST_NOT) & cand_cov)
    if prim_id is not None and reference_prim_id is not None:
        both = cand_cov & (np.asarray(reference_prim_id) >= 0)
        out["prim_id"] = both & ~tol.id_may & (np.asarray(prim_id) != reference_prim_id)
    if depth is not None:
        d = np.asarray(depth, np.float32)
        ref_cov = tol.coverage == MUST
        out["depth"] = ref_cov & cand_cov & ((d < tol.depth_lo) | (d > tol.depth_hi))
    return out


def edge_may(meshes, *, view, proj, width, height, model=None, cull="none", eps=None,
             min_bits=4, raster=None):
    """Pixels within ``eps`` of *any* edge of a drawn triangle, whatever lies in front of it.

    For techniques that make hidden surfaces visible (a clip surface removes the front ones), the
    depth relevance of :func:`tolerance` does not hold; this is its conservative twin: every
    non-culled triangle's edges count. Returns ``(id_may, coverage_may)``, ``(H, W)`` bool each
    (``coverage_may`` only near border, fold and silhouette edges, as in :func:`tolerance`).
    ``raster``: as :func:`tolerance` (its ``depth_clamp``).
    """
    prep = prepare(meshes, view=view, proj=proj, width=width, height=height, model=model,
                   raster=_geometry_state(cull, raster))
    w, h = prep.width, prep.height
    eps = (edge_epsilon(w, h, min_bits=min_bits, ref_bits=prep.triangles.subpixel_bits)
           if eps is None else as_real(eps, "eps", lo=0.0))
    p = prep.triangles
    id_may = np.zeros((h, w), np.bool_)
    cov_may = np.zeros((h, w), np.bool_)
    nothing = np.zeros((h, w), np.bool_)   # no visible surface: every edge is relevant
    _mark_faces(p.faces, p.vx, p.vy, p.vz, p.vcode, p.status,
                {"none": 0, "back": 1, "front": 2}[cull.lower()],
                _edge_boundary(p.faces, _face_facing(p)), float(1 << p.subpixel_bits),
                p.clipped.x, p.clipped.y, p.clipped.z, p.clipped.prim, _piece_epsilon(prep),
                np.full(len(p.faces), DEPTH_EPS), eps, np.ones((h, w)), nothing, id_may,
                cov_may, np.zeros(len(p.faces), np.bool_))
    return id_may, cov_may


def fragile_faces(prep, eps):
    """(F,) bool: faces (all vertices in front of the eye) whose facing may flip — or that may
    become degenerate — at 4 sub-pixel bits: doubled window area within ``ε·P + 3ε²`` of zero
    (:func:`facing_may`). ``prep`` is :func:`refraster.raster.prepare`'s result."""
    w, h = prep.width, prep.height
    c = prep.clip
    f = prep.triangles.faces
    wc = c[:, 3]
    ok = np.all(wc[f] > 0, axis=1)
    safe = np.where(wc > 0, wc, 1.0)
    x = (c[:, 0] / safe + 1.0) * 0.5 * w
    y = (c[:, 1] / safe + 1.0) * 0.5 * h
    xf, yf = x[f], y[f]
    area = ((xf[:, 1] - xf[:, 0]) * (yf[:, 2] - yf[:, 0])
            - (xf[:, 2] - xf[:, 0]) * (yf[:, 1] - yf[:, 0]))
    perim = sum(np.hypot(xf[:, (k + 1) % 3] - xf[:, k], yf[:, (k + 1) % 3] - yf[:, k])
                for k in range(3))
    return ok & (np.abs(area) <= eps * perim + 3.0 * eps * eps)


def facing_may(meshes, *, view, proj, width, height, model=None, eps=None, min_bits=4,
               raster=None):
    """Pixels of faces whose facing may flip between allowed rasterizers, and near their edges.

    :func:`tolerance` keeps coverage "must" across an edge shared by two faces of the same
    facing, taken from the reference's snapped positions. A sliver whose doubled window area
    ``A`` is within ``ε·P + 3ε²`` of zero (``P`` its perimeter: the first-order change of ``A``
    when each vertex moves by up to ``ε``) can change facing — or become degenerate — at 4
    sub-pixel bits: it is culled, or folds over its neighbour, and the pixels it covered may be
    uncovered or show another primitive. Every point of such a face lies within its inradius
    ``A/P ≤ 4ε`` of an edge, so marking all of its edges with ``5ε`` covers it.

    Returns ``(id_may, coverage_may)`` ``(H, W)`` bool (faces with a vertex behind the eye are
    left to :func:`tolerance`'s clipped-piece handling).
    """
    if raster is not None:   # facing: no culling; the clip volume of raster
        raster = _geometry_state("none", _geometry_state(raster.cull, raster).replace(
            cull="none"))
    prep = prepare(meshes, view=view, proj=proj, width=width, height=height, model=model,
                   raster=raster)
    w, h = prep.width, prep.height
    eps = (edge_epsilon(w, h, min_bits=min_bits, ref_bits=prep.triangles.subpixel_bits)
           if eps is None else as_real(eps, "eps", lo=0.0))
    fragile = fragile_faces(prep, eps)
    id_may = np.zeros((h, w), np.bool_)
    cov_may = np.zeros((h, w), np.bool_)
    if not fragile.any():
        return id_may, cov_may
    from .mesh import Mesh
    obj, local = prep.split(np.flatnonzero(fragile))
    draws = np.unique(obj)
    # each fragile face on its own: all its edges are border edges (coverage may change)
    alone = []
    for o in draws:
        m = prep.meshes[o]
        corners = m.vertices[m.faces[local[obj == o]]].reshape(-1, 3)
        alone.append(Mesh(corners, np.arange(len(corners)).reshape(-1, 3)))
    return edge_may(alone, view=view, proj=proj, width=w, height=h,
                    model=[prep.models[o] for o in draws], cull="none", eps=5.0 * eps,
                    raster=raster)
