"""Perspective-correct barycentrics of faces at window points: a leaf module shared by the
allowances of plain scenes (:mod:`refraster.golden.allowances.core`) and of the techniques
(:mod:`refraster.golden.allowances.layers` and the modules built on it), so that none imports
another."""

from __future__ import annotations

import numpy as np

__all__ = ["face_barycentrics", "corner_samples"]


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
