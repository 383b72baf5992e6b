"""Perspective-correct barycentrics of faces at window points: a leaf module shared by the
allowances of plain scenes (:mod:`refraster.golden.allowances.core`) and of the techniques
(:mod:`refraster.golden.allowances.layers` and the modules built on it), so that none imports
another."""

from __future__ import annotations

import numpy as np

__all__ = ["face_barycentrics", "corner_samples", "pixel_triangle"]


def face_barycentrics(clip, px, py, width, height):
    """Perspective-correct barycentrics ``(E, S, 3)`` of faces with clip-space vertices
    ``clip (E, 3, 4)`` at window points ``px, py (E, S)`` (pixels, GL y-up, centres at +0.5).

    Homogeneous: a point of the face is ``Σ β_i V_i`` (Σ β = 1); its window position
    ``(Σ β_i X_i) / (Σ β_i w_i)`` with ``X_i = (x_i + w_i)·W/2`` (likewise y), so
    ``β ∝ M⁻¹ (px, py, 1)`` with M's columns ``(X_i, Y_i, w_i)`` — valid for faces crossing
    the eye plane too (the homogeneous rasterization of Olano & Greer)."""
    w = clip[:, :, 3]
    m = np.empty(clip.shape[:1] + (3, 3))
    m[:, 0, :] = (clip[:, :, 0] + w) * (0.5 * width)
    m[:, 1, :] = (clip[:, :, 1] + w) * (0.5 * height)
    m[:, 2, :] = w
    rhs = np.stack([px, py, np.ones_like(px)], axis=1)            # (E, 3, S)
    det = np.linalg.det(m)
    ok = np.abs(det) > 1e-300
    m[~ok] = np.eye(3)
    beta = np.linalg.solve(m, rhs)                                 # (E, 3, S)
    beta = np.moveaxis(beta, 1, 2)                                 # (E, S, 3)
    total = beta.sum(axis=2, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        beta = beta / total
    beta[~ok] = np.nan
    return beta


def corner_samples(clip, pix, width, height, eps):
    """Barycentrics and window depth of faces at the centre and the four corners of the
    ε-square around their pixels: ``clip (E, 3, 4)`` the faces' clip-space vertices, ``pix (E,)``
    the flat pixel index (row 0 at the top). Returns ``beta (E, 5, 3)``, ``depth (E, 5)``
    and the sample points ``px, py (E, 5)`` (window pixels, GL y-up; column 0 the centre) (NaN where the face is degenerate in the window; ±inf / NaN where a sample is on its eye
    plane). Every value that is affine or a ratio of affine functions of the sample point has its
    extremes over the square at these corners."""
    rows, cols = np.divmod(pix, width)
    d = np.array([[0.0, 0.0], [-1, -1], [1, -1], [-1, 1], [1, 1]]) * eps
    px = cols[:, None] + 0.5 + d[None, :, 0]
    py = (height - 1 - rows)[:, None] + 0.5 + d[None, :, 1]
    beta = face_barycentrics(clip, px, py, width, height)
    zc = np.einsum("esk,ek->es", beta, clip[:, :, 2])
    wc = np.einsum("esk,ek->es", beta, clip[:, :, 3])
    with np.errstate(invalid="ignore", divide="ignore"):
        depth = 0.5 * zc / wc + 0.5
    return beta, depth, px, py


def _clip_polygon(poly, a, b, c):
    """Clip convex polygons ``poly (m, k, 2)`` (NaN-padded) by ``a·x + b·y + c ≥ 0`` per row;
    returns ``(m, k + 1, 2)``."""
    m, k, _ = poly.shape
    out = np.full((m, k + 1, 2), np.nan)
    count = np.zeros(m, np.int64)
    valid = ~np.isnan(poly[:, :, 0])
    n = valid.sum(axis=1)
    for i in range(k):
        p = poly[:, i]
        q = np.where(((i + 1) >= n)[:, None], poly[:, 0], poly[:, min(i + 1, k - 1)])
        live = i < n
        dp = a * p[:, 0] + b * p[:, 1] + c
        dq = a * q[:, 0] + b * q[:, 1] + c
        keep = live & (dp >= 0)
        rows = np.flatnonzero(keep)
        out[rows, count[rows]] = p[rows]
        count[rows] += 1
        cross = live & ((dp >= 0) != (dq >= 0))
        rows = np.flatnonzero(cross)
        t = (dp[rows] / (dp[rows] - dq[rows]))[:, None]
        out[rows, count[rows]] = p[rows] + t * (q[rows] - p[rows])
        count[rows] += 1
    return out


def pixel_triangle(clip, pix, width, height, eps, offset=(0.0, 0.0)):
    """The vertices ``(E, 7, 2)`` (NaN-padded, window pixels, GL y up) of each entry's pixel
    square grown by ``eps`` clipped by its face's triangle with every edge moved out by
    ``eps``; ``ok (E,)`` where the face lies in front of the eye and is not degenerate.
    ``offset``: the square moved by this many pixels (GL y up; a sample's moved scene sees its
    pixel's square moved by minus the sample's offset)."""
    rows, cols = np.divmod(pix, width)
    y0 = (height - 1 - rows).astype(np.float64) + float(offset[1])
    x0 = cols.astype(np.float64) + float(offset[0])
    e = len(pix)
    poly = np.full((e, 4, 2), np.nan)
    poly[:, 0] = np.column_stack([x0 - eps, y0 - eps])
    poly[:, 1] = np.column_stack([x0 + 1 + eps, y0 - eps])
    poly[:, 2] = np.column_stack([x0 + 1 + eps, y0 + 1 + eps])
    poly[:, 3] = np.column_stack([x0 - eps, y0 + 1 + eps])
    w = clip[:, :, 3]
    ok = (w > 0).all(axis=1)
    ws = np.where(ok[:, None], w, 1.0)
    X = (clip[:, :, 0] / ws + 1.0) * 0.5 * width
    Y = (clip[:, :, 1] / ws + 1.0) * 0.5 * height
    area = (X[:, 1] - X[:, 0]) * (Y[:, 2] - Y[:, 0]) - (X[:, 2] - X[:, 0]) * (Y[:, 1] - Y[:, 0])
    ok &= area != 0
    sign = np.where(area < 0, -1.0, 1.0)
    for k in range(3):
        i, j = k, (k + 1) % 3
        # inside: sign·((Xj − Xi)(y − Yi) − (Yj − Yi)(x − Xi)) ≥ −eps·|edge|
        dx, dy = X[:, j] - X[:, i], Y[:, j] - Y[:, i]
        length = np.hypot(dx, dy)
        a = -sign * dy
        b = sign * dx
        c = sign * (dy * X[:, i] - dx * Y[:, i]) + eps * length
        poly = _clip_polygon(poly, a, b, c)
    return poly, ok
