"""Bounds of what a face can show at a pixel centre under the allowed snappings
(`refraster.golden.allowances.core._snap_barycentrics`, `_sliver_bounds`), against brute force and
hand-worked cases ("Goldens with teeth (1)", item 4 on the crank)."""

import math

import numpy as np
import pytest

from refraster.golden.allowances.core import MAX_SNAP_BITS, MIN_SNAP_BITS, _snap_barycentrics
from refraster.conformance import edge_epsilon

EPS = edge_epsilon(160, 120)
DELTA = EPS - math.sqrt(2.0) * (2.0 ** -5 + 2.0 ** -9)      # the float part of ε


def _areas(X, Y, px, py):
    A = np.empty(3)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        A[i] = (X[j] - px) * (Y[k] - py) - (X[k] - px) * (Y[j] - py)
    return A


def _brute(X, Y, w, px, py, rng, n=400):
    """Barycentrics (β, perspective-correct) and facings that concrete rasterizers give:
    vertices moved by float noise up to δ, snapped to nearest at b = 4…8 bits and
    interpolated from the snapped vertices, or interpolated from the (noisy) unsnapped ones."""
    got, facings = [], set()
    for _ in range(n):
        Xn = X + rng.uniform(-DELTA, DELTA, 3)
        Yn = Y + rng.uniform(-DELTA, DELTA, 3)
        A = _areas(Xn, Yn, px, py)
        got.append(A / w / (A / w).sum())                      # unsnapped interpolation
        for b in range(MIN_SNAP_BITS, MAX_SNAP_BITS + 1):
            s = float(1 << b)
            A = _areas(np.round(Xn * s) / s, np.round(Yn * s) / s, px, py)
            t = A.sum()
            if t != 0 and ((A >= 0).all() or (A <= 0).all()):
                facings.add(bool(t > 0))
                got.append(A / w / (A / w).sum())
    return np.array(got), facings


@pytest.mark.parametrize("seed", range(12))
def test_every_concrete_snapping_lies_in_the_bounds(seed):
    """Random slivers (a needle and a cap) and small triangles around a pixel centre: every
    barycentric a concrete 4…8-bit rasterizer (snapped or unsnapped setup, float noise) gives
    lies in the bounds, and every facing it shows is allowed."""
    rng = np.random.default_rng(seed)
    px, py = 10.5, 7.5
    kind = seed % 3
    if kind == 0:      # a needle through the centre: two vertices 0.01 px apart
        a = rng.uniform(0, 2 * np.pi)
        d = np.array([math.cos(a), math.sin(a)])
        n = np.array([-d[1], d[0]])
        P = np.array([[px, py] - 1.5 * d, [px, py] + 0.8 * d + 0.005 * n,
                      [px, py] + 0.8 * d - 0.005 * n])
    elif kind == 1:    # a cap: three nearly collinear vertices
        a = rng.uniform(0, 2 * np.pi)
        d = np.array([math.cos(a), math.sin(a)])
        n = np.array([-d[1], d[0]])
        P = np.array([[px, py] - 0.7 * d - 0.003 * n, [px, py] + 0.02 * n + 0.1 * d,
                      [px, py] + 0.9 * d - 0.003 * n])
    else:              # a small, well-shaped triangle around the centre
        P = np.array([px, py]) + rng.uniform(-0.4, 0.4, (3, 2))
    X, Y = P[:, 0] + rng.uniform(-1e-3, 1e-3, 3), P[:, 1] + rng.uniform(-1e-3, 1e-3, 3)
    w = rng.uniform(1.0, 3.0, 3)
    (_, _), (lo, hi), can = _snap_barycentrics(X[None], Y[None], w[None], np.array([px]),
                                               np.array([py]), EPS,
                                               min_bits=MIN_SNAP_BITS)
    got, facings = _brute(X, Y, w, px, py, rng)
    tol = 1e-9 * (1.0 + np.abs(got))
    assert (got >= lo[0] - tol).all() and (got <= hi[0] + tol).all(), (lo, hi, got.min(0),
                                                                      got.max(0))
    assert all(can[0, 0 if f else 1] for f in facings), (facings, can)


def test_a_triangle_on_the_grid_has_one_answer():
    """Hand-worked: vertices (0, 0), (8, 0), (0, 6) lie on the 1/16 grid and snap to
    themselves at every b ≥ 4, so the barycentrics at (2.5, 1.5) are the exact ones,
    λ = (1 − 2.5/8 − 1.5/6, 2.5/8, 1.5/6) = (0.4375, 0.3125, 0.25), up to the float spread
    (δ = 1.4e-4 px on 48 px² of doubled area: < 5e-4); the facing is fixed (front)."""
    X = np.array([[0.0, 8.0, 0.0]])
    Y = np.array([[0.0, 0.0, 6.0]])
    w = np.ones((1, 3))
    (_, _), (lo, hi), can = _snap_barycentrics(X, Y, w, np.array([2.5]), np.array([1.5]), EPS,
                                               min_bits=MIN_SNAP_BITS)
    # λ1 = x/8 = 0.3125, λ2 = y/6 = 0.25, λ0 = 1 − λ1 − λ2
    want = np.array([1 - 0.3125 - 0.25, 0.3125, 0.25])
    assert (lo[0] <= want).all() and (want <= hi[0]).all()
    assert (hi[0] - lo[0]).max() < 5e-4
    assert can[0].tolist() == [True, False]


def test_a_needle_keeps_its_facing_a_cap_may_flip():
    """A needle 0.01 px thick through the centre, (8, 7.5), (11, 7.505), (11, 7.495) seen from
    (9.5, 7.5): rounding is monotone per axis, so no snapping reverses its two close vertices
    — its (back) facing is fixed — and the centre, on its axis halfway along, has
    λ = (1 − 1.5/3, 0.25, 0.25) up to what the snapping and extrapolation add (< 0.1). A cap
    (three nearly collinear vertices around the centre) may flip: brute force finds a
    snapping of each facing that covers the centre, and the bounds allow both."""
    w = np.ones((1, 3))
    X = np.array([[8.0, 11.0, 11.0]])
    Y = np.array([[7.5, 7.505, 7.495]])
    (_, _), (lo, hi), can = _snap_barycentrics(X, Y, w, np.array([9.5]), np.array([7.5]), EPS,
                                               min_bits=MIN_SNAP_BITS)
    assert can[0].tolist() == [False, True]
    want = np.array([0.5, 0.25, 0.25])
    assert (lo[0] <= want).all() and (want <= hi[0]).all() and (hi[0] - lo[0]).max() < 0.1
    X = np.array([[8.843301, 9.585050, 10.282229]])
    Y = np.array([[7.478784, 7.530125, 7.537891]])
    (_, _), (lo, hi), can = _snap_barycentrics(X, Y, w, np.array([9.5]), np.array([7.5]), EPS,
                                               min_bits=MIN_SNAP_BITS)
    assert can[0].tolist() == [True, True]
    _, facings = _brute(X[0], Y[0], w[0], 9.5, 7.5, np.random.default_rng(0), n=50)
    assert facings == {True, False}
