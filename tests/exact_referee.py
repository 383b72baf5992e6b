"""The exact referee of the oracle comparisons (``test_llvmpipe_oracle``, ``test_lavapipe_oracle``,
``test_msaa``, ``test_lavapipe_msaa``): where refraster and an outside rasterizer disagree, the
float32 clip coordinates are taken as exact and the question is decided in rational arithmetic
(:class:`fractions.Fraction`), so no rounding of the referee's own can side with either.

A point is a pixel centre or sample ``q = (x_ndc, y_ndc, 1)`` in Fractions; a triangle ``tri`` its
three clip vertices ``(x, y, z, w)`` (float32 values, converted exactly); a clipped polygon a list
of Fraction ``[x, y, z, w]``.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

#: OpenGL's near and far planes, ``w + z ≥ 0`` and ``w − z ≥ 0`` (clip volume −w ≤ z ≤ w).
GL_NEAR_FAR = (lambda p: p[3] + p[2], lambda p: p[3] - p[2])


def clip_polygon(tri, planes):
    """Sutherland–Hodgman in rational arithmetic against ``planes`` (functions of a clip point
    ``(x, y, z, w)``, inside where ≥ 0, applied in order) → polygon ``[[x, y, z, w]]``."""
    poly = [[Fraction(float(x)) for x in p] for p in tri]
    for dist in planes:
        out = []
        for i in range(len(poly)):
            a, b = poly[i], poly[(i + 1) % len(poly)]
            da, db = dist(a), dist(b)
            if da >= 0:
                out.append(a)
            if (da >= 0) != (db >= 0):
                t = da / (da - db)
                out.append([a[j] + t * (b[j] - a[j]) for j in range(4)])
        poly = out
        if not poly:
            break
    return poly


def det3(a, b, c):
    """The determinant of the 3 × 3 matrix with columns ``a``, ``b``, ``c``."""
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))


def covers(poly, q):
    """Whether the cone over ``poly`` (its ``(x, y, w)``) holds ``q``; None exactly on an edge
    line. Fewer than three vertices cover nothing."""
    v = [(p[0], p[1], p[3]) for p in poly]
    signs = set()
    for i in range(len(v)):
        a, b = v[i], v[(i + 1) % len(v)]
        if a == b:
            continue
        d = det3(a, b, q)
        if d == 0:
            return None
        signs.add(d > 0)
    return len(v) >= 3 and len(signs) == 1


def ndc_depth(tri, q):
    """``z/w`` of the triangle's plane through ``q`` (its barycentrics in ``(x, y, w)``), exactly;
    None when the plane passes through the eye (the three ``(x, y, w)`` are dependent)."""
    v = [[Fraction(float(x)) for x in p] for p in tri]
    cols = [(p[0], p[1], p[3]) for p in v]
    d = det3(*cols)
    if d == 0:
        return None
    lam = [det3(q, cols[1], cols[2]) / d, det3(cols[0], q, cols[2]) / d,
           det3(cols[0], cols[1], q) / d]
    return sum(k * p[2] for k, p in zip(lam, v)) / sum(k * p[3] for k, p in zip(lam, v))


def gl_window_depth(tri, q):
    """OpenGL's window depth ``(z/w + 1)/2`` of :func:`ndc_depth` (None where it is None)."""
    z = ndc_depth(tri, q)
    return None if z is None else z / 2 + Fraction(1, 2)


def edge_distance(points, x, y):
    """Smallest distance from the window point ``(x, y)`` to the line through an edge of the
    polygon ``points`` (window ``(x, y)`` pairs, in order, in the same frame as the point)."""
    best = np.inf
    for i in range(len(points)):
        (ax, ay), (bx, by) = points[i], points[(i + 1) % len(points)]
        n = np.hypot(bx - ax, by - ay)
        if n > 0:
            best = min(best, abs((bx - ax) * (y - ay) - (by - ay) * (x - ax)) / n)
    return best
