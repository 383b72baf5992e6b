"""Ghost lines of the removed structure (Burns & Finkelstein 2008, Sec. 4.3; MATH.md D-C11).

The paper draws feature lines as line primitives (Table 1 counts the models' lines beside
their triangles) and lets the lines of carved secondary objects "extend into the cutaway
region" up to a user-given distance in front of the cutaway surface, faded out. Here:

* :func:`feature_segments` — the creases, silhouettes and borders of the secondary meshes for
  the current view (:func:`refraster.edges.classify_edges`, vertices merged by position first),
  as world-space segments. Hidden silhouettes count: the structure that the cut removes is
  exactly what the first visible surface hides.
* :func:`segment_pieces` — each segment clipped to the view volume in clip space, projected and
  split into its chords through the pixels it crosses (a supercover line), with the exact NDC
  depth at both ends of each chord (perspective-correct).
* :func:`ghost_alpha` — per pixel, the largest opacity over the points of its chords that lie in
  the removed region (z < D), within g_max of the surface, and are not hidden by an object of
  interest: α = 1 − (d(D) − d(z))/g_max with d the eye depth (D-C11). Depth is monotone along a
  chord, so the largest α is at the chord point nearest D (the chord's far end, or the point
  where it meets D); D is taken at the pixel centre, as a fragment test does.

Every secondary fragment with z < D was discarded, so the only surfaces that can hide a
removed line are the objects of interest (the cut surfaces lie at D_dil ≤ z ≤ D, where the line
meets the cut); a line sample is hidden iff the visible fragment at its pixel belongs to an
object of interest and is nearer.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_real
from ..mesh import as_meshes
from .surface import ndc_to_eye_depth

__all__ = ["feature_segments", "segment_pieces", "ghost_alpha", "GHOST_CREASE_ANGLE"]

#: Dihedral angle (degrees) above which an edge is a crease (as refraster.edges) [guess].
GHOST_CREASE_ANGLE = 30.0


def _merged(vertices, faces):
    """Vertices merged by exact position, so that per-face copies make manifold edges."""
    uniq, inverse = np.unique(np.asarray(vertices, np.float64), axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)[np.asarray(faces, np.int64)]


def feature_segments(meshes, *, view, proj, crease_angle=GHOST_CREASE_ANGLE):
    """World-space feature-line segments ``(N, 2, 3)`` of meshes for one view.

    Silhouettes (a front- and a back-facing face meet), borders (an edge of one face) and
    creases (dihedral angle > ``crease_angle`` degrees; for an edge of more than two faces, the
    largest angle between them) of every mesh, visible or not. Vertices are merged by exact
    position first, so meshes stored with per-face vertex copies give the same lines.
    """
    from ..edges import classify_edges
    out = []
    for m in as_meshes(meshes, "meshes") if len(meshes) else []:
        if m.n_faces == 0:
            continue
        v, f = _merged(m.vertices, m.faces)
        es = classify_edges((v, f), view=view, proj=proj, crease_angle=crease_angle)
        # non-manifold edges (more than two faces, e.g. touching parts merged by position)
        # count when their faces meet at more than the crease angle
        keep = es.silhouette | es.border | es.crease | \
            ((es.n_faces > 2) & (es.dihedral > crease_angle))
        out.append(v[es.edges[keep]])
    if not out:
        return np.zeros((0, 2, 3))
    return np.concatenate(out)


def _clip_range(ca, cb):
    """Parameter interval [t0, t1] of the clip-space segment ca → cb inside the view volume
    (−w ≤ x, y, z ≤ w), Liang–Barsky style; t0 > t1 where it misses."""
    t0 = np.zeros(len(ca))
    t1 = np.ones(len(ca))
    for axis in range(3):
        for sign in (1.0, -1.0):
            # inside iff w − sign·c ≥ 0, linear in t
            fa = ca[:, 3] - sign * ca[:, axis]
            fb = cb[:, 3] - sign * cb[:, axis]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = fa / (fa - fb)
            entering = (fa < 0) & (fb >= 0)
            leaving = (fa >= 0) & (fb < 0)
            t0 = np.where(entering, np.maximum(t0, t), t0)
            t1 = np.where(leaving, np.minimum(t1, t), t1)
            t1 = np.where((fa < 0) & (fb < 0), -1.0, t1)
    return t0, t1


def segment_pieces(segments, *, view, proj, width, height, window=False):
    """Split world-space segments into their pixel chords (supercover traversal).

    Each segment is clipped to the view volume in clip space, projected, and cut where it
    crosses a pixel boundary; every chord of positive length becomes one piece. Returns
    ``(pixel, z_a, z_b, segment index)``: the flat pixel index (row-major, row 0 at the top) and
    the NDC depths at the chord's two ends, obtained perspective-correctly from the segment's own
    3D parameter, so a piece's depth is exactly that of its segment. With ``window=True`` a fifth
    item ``(x_a, y_a, x_b, y_b)``: the chords' ends in window coordinates (x right, y down from
    the top row), and a sixth, the clipped segments' window ends ``(N', 4)`` with their NDC
    depths ``(N', 2)`` and indices (for the golden's line allowance).
    """
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    empty_i = np.zeros(0, np.int64)
    if len(seg) == 0:
        if window:
            z0 = np.zeros(0)
            return (empty_i, z0, z0, empty_i, (z0, z0, z0, z0),
                    (np.zeros((0, 4)), np.zeros((0, 2)), empty_i))
        return empty_i, np.zeros(0), np.zeros(0), empty_i
    mvp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
    hom = np.concatenate([seg, np.ones(seg.shape[:2] + (1,))], axis=-1)
    clip = hom @ mvp.T                                        # (N, 2, 4)
    ca, cb = clip[:, 0], clip[:, 1]
    t0, t1 = _clip_range(ca, cb)
    ok = t1 > t0
    ca, cb, t0, t1, idx = ca[ok], cb[ok], t0[ok], t1[ok], np.flatnonzero(ok)
    pa = ca + t0[:, None] * (cb - ca)
    pb = ca + t1[:, None] * (cb - ca)
    wa, wb = pa[:, 3], pb[:, 3]
    # window coordinates: x to the right, y down from the top row
    xa = (pa[:, 0] / wa + 1.0) * (0.5 * width)
    ya = (1.0 - pa[:, 1] / wa) * (0.5 * height)
    xb = (pb[:, 0] / wb + 1.0) * (0.5 * width)
    yb = (1.0 - pb[:, 1] / wb) * (0.5 * height)
    # screen parameters s ∈ (0, 1) where the chord crosses a pixel boundary
    cuts_s, cuts_seg = [np.zeros(len(xa)), np.ones(len(xa))], [np.arange(len(xa))] * 2
    for a, b in ((xa, xb), (ya, yb)):
        lo = np.floor(np.minimum(a, b)) + 1.0
        hi = np.ceil(np.maximum(a, b)) - 1.0
        n = np.maximum(hi - lo + 1.0, 0.0).astype(np.int64)
        rep = np.repeat(np.arange(len(a)), n)
        k = lo[rep] + (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n))
        with np.errstate(divide="ignore", invalid="ignore"):
            cuts_s.append((k - a[rep]) / (b[rep] - a[rep]))
        cuts_seg.append(rep)
    s_all = np.concatenate(cuts_s)
    g_all = np.concatenate(cuts_seg)
    order = np.lexsort((s_all, g_all))
    s_all, g_all = s_all[order], g_all[order]
    same = g_all[1:] == g_all[:-1]
    s0, s1, g = s_all[:-1][same], s_all[1:][same], g_all[:-1][same]
    keep = s1 > s0
    s0, s1, g = s0[keep], s1[keep], g[keep]
    sm = 0.5 * (s0 + s1)
    col = np.floor(xa[g] + sm * (xb[g] - xa[g])).astype(np.int64)
    row = np.floor(ya[g] + sm * (yb[g] - ya[g])).astype(np.int64)
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    s0, s1, g, col, row = s0[inside], s1[inside], g[inside], col[inside], row[inside]

    def depth_at(s):
        # screen fraction s → parameter fraction u between the clipped ends (perspective-correct)
        u = s * wa[g] / ((1.0 - s) * wb[g] + s * wa[g])
        t = t0[g] + u * (t1[g] - t0[g])
        c = ca[g] + t[:, None] * (cb[g] - ca[g])
        return np.clip(c[:, 2] / c[:, 3], -1.0, 1.0)

    if window:
        ends = (xa[g] + s0 * (xb[g] - xa[g]), ya[g] + s0 * (yb[g] - ya[g]),
                xa[g] + s1 * (xb[g] - xa[g]), ya[g] + s1 * (yb[g] - ya[g]))
        whole = (np.stack([xa, ya, xb, yb], axis=1),
                 np.clip(np.stack([pa[:, 2] / wa, pb[:, 2] / wb], axis=1), -1.0, 1.0), idx)
        return row * width + col, depth_at(s0), depth_at(s1), idx[g], ends, whole
    return row * width + col, depth_at(s0), depth_at(s1), idx[g]


def ghost_alpha(segments, *, view, proj, width, height, cutaway_ndc, g_max, fade=True,
                occluder_depth=None):
    """Ghost-line opacity ``(H, W)`` float32 of feature segments (MATH.md D-C11).

    Parameters
    ----------
    segments : (N, 2, 3) float
        World-space line segments (:func:`feature_segments`).
    cutaway_ndc : (H, W) float
        The cutaway surface D in NDC depth at frame resolution.
    g_max : float
        Largest eye-space distance in front of D at which a line is drawn.
    fade : bool
        α = 1 − (d(D) − d(z))/g_max (Fig. 4e, the default) or α = 1 (Fig. 4d).
    occluder_depth : (H, W) float, optional
        NDC depth of what may hide a removed line (the objects of interest); +inf or absent:
        nothing.

    Returns
    -------
    (H, W) float32: per pixel the largest α over its chord points with z < D(x), not behind
    the occluder, and d(D) − d(z) < g_max; 0 elsewhere. Order-independent (a maximum).
    """
    g_max = as_real(g_max, "ghost_distance", lo=0.0)
    alpha = np.zeros(height * width)
    if g_max == 0:
        return alpha.reshape(height, width).astype(np.float32)
    pix, za, zb, _ = segment_pieces(segments, view=view, proj=proj, width=width,
                                    height=height)
    limit = np.asarray(cutaway_ndc, np.float64).reshape(-1)[pix]
    d = limit
    if occluder_depth is not None:
        limit = np.minimum(limit, np.asarray(occluder_depth, np.float64).reshape(-1)[pix])
    z_lo, z_hi = np.minimum(za, zb), np.maximum(za, zb)
    # the removed, unhidden part of the chord is where z < limit; its largest α is at the
    # point nearest the surface: z* = min(z_hi, limit)
    hit = z_lo < limit
    pix, d = pix[hit], d[hit]
    z_star = np.minimum(z_hi[hit], limit[hit])
    gap = np.maximum(ndc_to_eye_depth(d, proj) - ndc_to_eye_depth(z_star, proj), 0.0)
    near = gap < g_max
    a = 1.0 - gap[near] / g_max if fade else np.ones(int(near.sum()))
    np.maximum.at(alpha, pix[near], np.clip(a, 0.0, 1.0))
    return alpha.reshape(height, width).astype(np.float32)
