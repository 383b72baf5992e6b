"""The fused fill's off-core tests (issue 46): a row span or a whole triangle it defers holds
no core fragment.

``render._span_off_core`` decides, from the two ends of a row span and without a division,
that every fragment of the span has ``|2t − 1| ≥ w_s + a`` (so the fill may defer it to the
voxels that get a surface fragment); ``render._triangle_off_core`` decides it for every pixel
the fill covers, from the three snapped vertices. The oracle here is the fragment's own t,
computed the slow, obvious way at every pixel of the span or of the triangle's coverage (the
fill rule evaluated pixel by pixel; float64 λ from the unsnapped positions, the float32
roundings of ``λ_k / Σλ``): random triangles (slivers included), random spans, spans whose t
at a pixel centre sits a few float32 ulps beside the core's edge, and triangles that cover a
pixel centre just outside their unsnapped edge, where t extrapolates past every corner.
"""

from fractions import Fraction as Fr

import numpy as np
import pytest

from refraster.halos4d import render
from refraster.raster.rasterizer import _inv_float_area

RNG_SEED = 46


def fragment_t(fx, fy, inv_af, x, y, t):
    """The fill's t at pixel (x, y), one operation at a time (w = 1, stored vertex order)."""
    cx, cy = float(x) + 0.5, float(y) + 0.5
    l0 = ((fx[2] - fx[1]) * (cy - fy[1]) - (fy[2] - fy[1]) * (cx - fx[1])) * inv_af
    l1 = ((fx[0] - fx[2]) * (cy - fy[2]) - (fy[0] - fy[2]) * (cx - fx[2])) * inv_af
    l2 = ((fx[1] - fx[0]) * (cy - fy[0]) - (fy[1] - fy[0]) * (cx - fx[0])) * inv_af
    s = l0 + l1 + l2
    q = [float(np.float32(l / s)) for l in (l0, l1, l2)]
    return q[0] * t[0] + q[1] * t[1] + q[2] * t[2]


def random_triangle(rng):
    """Window-space vertices (float32 values, counter-clockwise), slivers one time in three."""
    while True:
        c = rng.uniform(20.0, 40.0, 2)
        size = rng.uniform(0.3, 12.0)
        p = c + rng.uniform(-size, size, (3, 2))
        if rng.random() < 1 / 3:    # a sliver: squash towards the line through two vertices
            p[2] = p[0] + rng.uniform(0.0, 1.0) * (p[1] - p[0]) + rng.uniform(-1e-2, 1e-2, 2)
        p = p.astype(np.float32).astype(np.float64)
        a = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        if a < 0:
            p = p[[0, 2, 1]]
        fx, fy = p[:, 0], p[:, 1]
        inv_af = _inv_float_area(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2])
        if inv_af > 0.0:
            return fx, fy, inv_af


def test_the_oracle_is_the_fills_t():
    rng = np.random.default_rng(RNG_SEED + 2)
    for _ in range(50):
        fx, fy, inv_af = random_triangle(rng)
        t = rng.uniform(0.0, 1.0, 3)
        x, y = int(fx.mean()), int(fy.mean())
        q = render._fragment_bary(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, x, y, 0, 0,
                                  0, 0.0, False)
        assert q[0] * t[0] + q[1] * t[1] + q[2] * t[2] == fragment_t(fx, fy, inv_af, x, y, t)


def claims(fx, fy, inv_af, t, xa, xb, y, lo, hi):
    return render._span_off_core(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, t[0], t[1],
                                 t[2], xa, xb, y, lo, hi)


def check_span(fx, fy, inv_af, t, xa, xb, y, core_w, lo, hi):
    """Whether the test claimed the span off the core; fails if a fragment of it is core."""
    if not claims(fx, fy, inv_af, t, xa, xb, y, lo, hi):
        return False
    for x in range(xa, xb + 1):
        u = abs(2.0 * fragment_t(fx, fy, inv_af, x, y, t) - 1.0)
        assert not u < core_w, (fx.tolist(), fy.tolist(), inv_af, list(t), xa, xb, y, x, u)
    return True


@pytest.mark.parametrize("surface_width, aa", [(0.3, 0.027533030000969332), (0.05, 0.0),
                                               (0.8, 0.1)])
def test_a_claimed_span_has_no_core_fragment(surface_width, aa):
    rng = np.random.default_rng(RNG_SEED)
    core_w = surface_width + aa
    lo, hi = render._off_core_limits(surface_width, aa)
    claimed = spans = 0
    for _ in range(150):
        fx, fy, inv_af = random_triangle(rng)
        t = rng.uniform(0.0, 1.0, 3)
        if not render._off_core_usable(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, *t):
            continue
        x_lo, x_hi = int(np.floor(fx.min())) - 1, int(np.ceil(fx.max())) + 1
        for y in range(int(np.floor(fy.min())) - 1, int(np.ceil(fy.max())) + 1):
            for _ in range(3):
                xa, xb = sorted(rng.integers(x_lo, x_hi + 1, 2))
                spans += 1
                claimed += check_span(fx, fy, inv_af, t, int(xa), int(xb), y, core_w, lo, hi)
    assert claimed > 200 and spans - claimed > 200, (claimed, spans)


def test_near_the_core_edge():
    # t at one pixel centre a few float32 ulps beside the core's edge (1 ± w_s ∓ a)/2, and
    # beside the edge widened by the margin: no claimed pixel may be core
    rng = np.random.default_rng(RNG_SEED + 1)
    surface_width, aa = 0.3, 0.027533030000969332
    core_w = surface_width + aa
    lo, hi = render._off_core_limits(surface_width, aa)
    edges = (0.5 * (1.0 + core_w), 0.5 * (1.0 - core_w), hi, lo)
    tried = 0
    while tried < 3000:
        fx, fy, inv_af = random_triangle(rng)
        x = int(np.floor(fx.mean()))
        y = int(np.floor(fy.mean()))
        cx, cy = x + 0.5, y + 0.5
        lam = [((fx[(k + 2) % 3] - fx[(k + 1) % 3]) * (cy - fy[(k + 1) % 3])
                - (fy[(k + 2) % 3] - fy[(k + 1) % 3]) * (cx - fx[(k + 1) % 3])) * inv_af
               for k in range(3)]
        if abs(lam[2]) < 0.05:
            continue
        edge = edges[tried % 4]
        target = edge + rng.uniform(-8.0, 8.0) * 2.0 ** -24
        t = list(rng.uniform(0.0, 1.0, 2))
        t.append((target * sum(lam) - lam[0] * t[0] - lam[1] * t[1]) / lam[2])
        if not (abs(t[2]) <= 1.0 and render._off_core_usable(fx[0], fy[0], fx[1], fy[1],
                                                             fx[2], fy[2], inv_af, *t)):
            continue
        tried += 1
        check_span(fx, fy, inv_af, t, x, x, y, core_w, lo, hi)
        check_span(fx, fy, inv_af, t, x - 2, x + 2, y, core_w, lo, hi)


def test_usable_refuses_ill_conditioned_triangles():
    # a flattened or near-degenerate triangle, or t outside [−1, 1], is never tested
    u = render._off_core_usable
    assert u(0.0, 0.0, 4.0, 0.0, 0.0, 4.0, 1 / 16, 0.0, 1.0, 0.5)
    assert not u(0.0, 0.0, 4.0, 0.0, 0.0, 4.0, 0.0, 0.0, 1.0, 0.5)
    assert not u(0.0, 0.0, 400.0, 0.0, 0.0, 400.0, 2.0 ** 20, 0.0, 1.0, 0.5)
    assert not u(0.0, 0.0, 4.0, 0.0, 0.0, 4.0, 1 / 16, 0.0, 1.5, 0.5)


# ----------------------------------------------------------------------------- whole triangles
SUB = 256    # 1 << SUBPIXEL_BITS


def snapped(fx, fy):
    """The fill's snapped window vertices (float32 ``rint((x − ½)·256)``, window_setup)."""
    f = np.float32
    return ([int(np.rint((f(x) - f(0.5)) * f(SUB))) for x in fx],
            [int(np.rint((f(y) - f(0.5)) * f(SUB))) for y in fy])


def covered_pixels(X, Y):
    """The pixels the fill covers, the slow obvious way: every biased edge function ≥ 0 at the
    pixel's centre (llvmpipe's rule: a left or bottom edge owns its centres), stored
    counter-clockwise vertices."""
    out = []
    for py in range(min(Y) // SUB - 1, max(Y) // SUB + 2):
        for px in range(min(X) // SUB - 1, max(X) // SUB + 2):
            ok = True
            for k in range(3):
                a, b = (k + 1) % 3, (k + 2) % 3
                dx, dy = X[b] - X[a], Y[b] - Y[a]
                bias = 0 if (dy < 0 or (dy == 0 and dx > 0)) else 1
                ok &= dx * (py * SUB - Y[a]) - dy * (px * SUB - X[a]) - bias >= 0
            if ok:
                out.append((px, py))
    return out


def triangle_claims(fx, fy, inv_af, t, X, Y, lo, hi):
    return render._triangle_off_core(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, t[0],
                                     t[1], t[2], X[0], X[1], X[2], Y[0], Y[1], Y[2], 8, lo, hi)


def snapped_triangle(rng, size=(0.3, 12.0)):
    """A random triangle (slivers one time in three) whose snapped and unsnapped vertices are
    both counter-clockwise (the fill's stored order; else its barycentrics are not usable)."""
    while True:
        c = rng.uniform(20.0, 40.0, 2)
        s = rng.uniform(*size)
        p = c + rng.uniform(-s, s, (3, 2))
        if rng.random() < 1 / 3:
            p[2] = p[0] + rng.uniform(0.0, 1.0) * (p[1] - p[0]) + rng.uniform(-1e-2, 1e-2, 2)
        p = p.astype(np.float32).astype(np.float64)
        if (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1]) < 0:
            p = p[[0, 2, 1]]
        fx, fy = p[:, 0], p[:, 1]
        X, Y = snapped(fx, fy)
        inv_af = _inv_float_area(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2])
        if inv_af > 0.0 and (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0]) > 0:
            return fx, fy, inv_af, X, Y


def check_triangle(fx, fy, inv_af, t, X, Y, core_w, lo, hi):
    """Whether the test claimed the triangle off the core; fails if a covered pixel is core."""
    if not triangle_claims(fx, fy, inv_af, t, X, Y, lo, hi):
        return False
    for x, y in covered_pixels(X, Y):
        u = abs(2.0 * fragment_t(fx, fy, inv_af, x, y, t) - 1.0)
        assert not u < core_w, (fx.tolist(), fy.tolist(), list(t), x, y, u)
    return True


@pytest.mark.parametrize("surface_width, aa", [(0.3, 0.027533030000969332), (0.05, 0.0)])
def test_a_claimed_triangle_has_no_core_fragment(surface_width, aa):
    rng = np.random.default_rng(RNG_SEED + 3)
    core_w = surface_width + aa
    lo, hi = render._off_core_limits(surface_width, aa)
    claimed = tried = 0
    while tried < 600:
        fx, fy, inv_af, X, Y = snapped_triangle(rng)
        # corners on one side of the core, a few of them just beyond its widened edge
        side = rng.choice([-1.0, 1.0])
        edge = hi if side > 0 else lo
        t = edge + side * rng.choice([rng.uniform(0.0, 0.3, 3), rng.uniform(0.0, 2e-3, 3)])
        if rng.random() < 0.2:
            t[rng.integers(3)] = edge - side * rng.uniform(0.0, 2e-3)   # one corner inside
        if not render._off_core_usable(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, *t):
            continue
        tried += 1
        claimed += check_triangle(fx, fy, inv_af, t, X, Y, core_w, lo, hi)
    assert 150 < claimed < tried - 100, (claimed, tried)


def trap_triangle(rng):
    """A triangle with an edge passing within 1/256 px of a pixel centre P, P outside the
    unsnapped triangle: ``(fx, fy, P)`` (float32 vertices, counter-clockwise)."""
    x, y = int(rng.integers(20, 40)), int(rng.integers(20, 40))
    p = np.array([x + 0.5, y + 0.5])
    a = rng.uniform(0.0, 2.0 * np.pi)
    d = np.array([np.cos(a), np.sin(a)])           # the edge's direction
    n = np.array([-d[1], d[0]])                    # towards the inside
    foot = p + rng.uniform(1e-4, 4e-3) * n         # P lies outside, beside the edge
    v = np.array([foot - rng.uniform(0.3, 3.0) * d, foot + rng.uniform(0.3, 3.0) * d,
                  foot + rng.uniform(-1.0, 1.0) * d + rng.uniform(0.3, 1.5) * n])
    v = v.astype(np.float32).astype(np.float64)
    return v[:, 0], v[:, 1], (x, y)


def test_pixels_outside_the_unsnapped_triangle():
    # a pixel centre inside the snapped triangle but outside the unsnapped one extrapolates t
    # past every corner: corners just beyond the core's widened edge, t at that centre inside
    # the core. Tested at the unsnapped vertices such a triangle would be claimed (counted
    # below: the cases are real); at the snapped ones it must not be.
    rng = np.random.default_rng(RNG_SEED + 4)
    surface_width, aa = 0.3, 0.027533030000969332
    core_w = surface_width + aa
    lo, hi = render._off_core_limits(surface_width, aa)
    traps = 0
    for _ in range(1500):
        fx, fy, (x, y) = trap_triangle(rng)
        X, Y = snapped(fx, fy)
        inv_af = _inv_float_area(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2])
        if (inv_af <= 0.0 or (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0]) <= 0
                or (x, y) not in covered_pixels(X, Y)):
            continue
        cx, cy = x + 0.5, y + 0.5
        lam = [((fx[(k + 2) % 3] - fx[(k + 1) % 3]) * (cy - fy[(k + 1) % 3])
                - (fy[(k + 2) % 3] - fy[(k + 1) % 3]) * (cx - fx[(k + 1) % 3])) * inv_af
               for k in range(3)]
        # corners at lo − 2^-14, vertex 2 (opposite the edge) lower, so that t at the centre
        # is the core's edge plus 2^-12
        c = lo - 2.0 ** -14
        t = [c, c, c - (0.5 * (1.0 - core_w) + 2.0 ** -12 - c) / -lam[2]]
        if not render._off_core_usable(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, *t):
            continue
        assert abs(2.0 * fragment_t(fx, fy, inv_af, x, y, t) - 1.0) < core_w
        traps += all(render._off_core_side(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, *t,
                                           fx[m] - 0.5, fy[m] - 0.5, lo, hi) == -1
                     for m in range(3))
        check_triangle(fx, fy, inv_af, t, X, Y, core_w, lo, hi)
    assert traps > 30, traps


# ----------------------------------------------------------------------------- the plane of t
def exact_at(fx, fy, inv_af, t, x, y):
    """``(D, Σ|λ_k|, N / D)`` in exact rational arithmetic at the point ``(x + ½, y + ½)``:
    λ_k from the unsnapped vertices with exact edge vectors, ``inv_af`` as given (the
    quantities of the proof in docs/halos4d.md, "Off-core spans")."""
    X, Y = [Fr(v) for v in fx], [Fr(v) for v in fy]
    cx, cy = Fr(x) + Fr(1, 2), Fr(y) + Fr(1, 2)
    lam = [((X[(k + 2) % 3] - X[(k + 1) % 3]) * (cy - Y[(k + 1) % 3])
            - (Y[(k + 2) % 3] - Y[(k + 1) % 3]) * (cx - X[(k + 1) % 3])) * Fr(inv_af)
           for k in range(3)]
    d = sum(lam)
    return d, sum(abs(v) for v in lam), sum(v * Fr(tk) for v, tk in zip(lam, t)) / d


def plane_of(fx, fy, inv_af, t):
    return render._off_core_plane(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af, *t)


def span_claim(plane, fx, fy, inv_af, t, xa, xb, y, lo, hi):
    return render._claim_span(plane[0], plane[1], plane[2], fx[0], fy[0], fx[1], fy[1], fx[2],
                              fy[2], inv_af, t[0], t[1], t[2], xa, xb, y, lo, hi)


def whole_claim(plane, fx, fy, inv_af, t, X, Y, lo, hi):
    return render._claim_triangle(plane[0], plane[1], plane[2], fx[0], fy[0], fx[1], fy[1],
                                  fx[2], fy[2], inv_af, t[0], t[1], t[2], X[0], X[1], X[2], Y[0],
                                  Y[1], Y[2], 8, lo, hi)


def beyond(values, lo, hi):
    """+1 (−1) when every exact value is ≥ hi (≤ lo), else 0."""
    return 1 if all(v >= Fr(hi) for v in values) else (-1 if all(v <= Fr(lo) for v in values)
                                                       else 0)


def test_the_planes_claims_hold_in_exact_arithmetic():
    # where the plane vouches for a triangle, every covered pixel has D in [1/2, 2] and
    # Σ|λ_k| ≤ 16 (exactly), and a claimed span (triangle) has the exact N / D beyond the
    # widened core's edge at both ends (the three snapped vertices), no fragment in the core.
    # Half the triangles get corner t that put N / D at a covered pixel centre on that edge up
    # to the float64 rounding of a corner: without the slack the plane's rounding claims some.
    rng = np.random.default_rng(RNG_SEED + 5)
    surface_width, aa = 0.3, 0.027533030000969332
    core_w = surface_width + aa
    lo, hi = render._off_core_limits(surface_width, aa)
    spans = whole = near = 0
    while near < 150:
        fx, fy, inv_af, X, Y = snapped_triangle(rng)
        pixels = covered_pixels(X, Y)
        if not pixels:
            continue
        side = rng.choice([-1.0, 1.0])
        edge = hi if side > 0 else lo
        t = list(edge + side * rng.uniform(-0.1, 0.3, 3))
        on_edge = rng.random() < 0.5
        if on_edge:    # N / D on the edge at a covered pixel (or at snapped vertex 2)
            x, y = pixels[rng.integers(len(pixels))] if rng.random() < 0.7 else \
                (Fr(X[2], SUB), Fr(Y[2], SUB))
            cx, cy = Fr(x) + Fr(1, 2), Fr(y) + Fr(1, 2)
            lam = [((Fr(fx[(k + 2) % 3]) - Fr(fx[(k + 1) % 3])) * (cy - Fr(fy[(k + 1) % 3]))
                    - (Fr(fy[(k + 2) % 3]) - Fr(fy[(k + 1) % 3])) * (cx - Fr(fx[(k + 1) % 3])))
                   for k in range(3)]
            if abs(lam[2] / sum(lam)) < 0.05:
                continue
            t[2] = float((Fr(edge) * sum(lam) - lam[0] * Fr(t[0]) - lam[1] * Fr(t[1])) / lam[2])
        if not (max(abs(v) for v in t) <= 1.0
                and render._off_core_usable(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2], inv_af,
                                            *t)):
            continue
        plane = plane_of(fx, fy, inv_af, t)
        if not plane[0]:
            continue
        near += on_edge
        for x, y in pixels:
            d, spread, _ = exact_at(fx, fy, inv_af, t, x, y)
            assert Fr(1, 2) <= d <= 2 and spread <= 16, (fx.tolist(), fy.tolist(), x, y)
        if whole_claim(plane, fx, fy, inv_af, t, X, Y, lo, hi):
            whole += 1
            ends = [exact_at(fx, fy, inv_af, t, Fr(X[k], SUB), Fr(Y[k], SUB))[2] for k in range(3)]
            assert beyond(ends, lo, hi) != 0, (fx.tolist(), fy.tolist(), t, X, Y)
        for y in sorted({p[1] for p in pixels}):
            row = [p[0] for p in pixels if p[1] == y]
            for xa, xb in ((min(row), max(row)), (max(row), max(row)), (min(row), min(row))):
                if span_claim(plane, fx, fy, inv_af, t, xa, xb, y, lo, hi):
                    spans += 1
                    ends = [exact_at(fx, fy, inv_af, t, x, y)[2] for x in (xa, xb)]
                    assert beyond(ends, lo, hi) != 0, (fx.tolist(), fy.tolist(), t, xa, xb, y)
                    for x in range(xa, xb + 1):
                        assert abs(2.0 * fragment_t(fx, fy, inv_af, x, y, t) - 1.0) >= core_w
    assert spans > 300 and whole > 30, (spans, whole)


def sliver_near_a_centre(rng):
    """A float32 sliver (height 10^-6 … 10^-2 px, 3 … 16 px long) passing within 4·10^-3 px of
    a pixel centre, with its snapped vertices: ``(fx, fy, inv_af, X, Y)`` (both orders
    counter-clockwise), or None."""
    p = rng.integers(20, 40, 2) + 0.5
    a = rng.uniform(0.0, 2.0 * np.pi)
    d = np.array([np.cos(a), np.sin(a)])
    n = np.array([-d[1], d[0]])
    base = p + rng.uniform(-4e-3, 4e-3) * n
    v = np.array([base - rng.uniform(1.5, 8.0) * d, base + rng.uniform(1.5, 8.0) * d,
                  base + rng.uniform(-1.0, 1.0) * d + 10.0 ** rng.uniform(-6.0, -2.0) * n])
    v = v.astype(np.float32).astype(np.float64)
    fx, fy = v[:, 0], v[:, 1]
    X, Y = snapped(fx, fy)
    inv_af = _inv_float_area(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2])
    if inv_af > 0.0 and (X[1] - X[0]) * (Y[2] - Y[0]) - (X[2] - X[0]) * (Y[1] - Y[0]) > 0:
        return fx, fy, inv_af, X, Y
    return None


def test_the_plane_refuses_slivers_and_the_exact_test_takes_them():
    # slivers whose snapped triangle covers a pixel centre where the unsnapped λ extrapolate
    # (Σ|λ_k| > 16) pass _off_core_usable; the plane must refuse every one of them. Slivers it
    # refuses go to the exact test, which claims some of their spans.
    rng = np.random.default_rng(RNG_SEED + 6)
    lo, hi = render._off_core_limits(0.3, 0.027533030000969332)
    traps = refused_claims = 0
    for _ in range(2500):
        got = sliver_near_a_centre(rng)
        if got is None:
            continue
        fx, fy, inv_af, X, Y = got
        t = list(hi + rng.uniform(1e-3, 0.3, 3))
        pixels = covered_pixels(X, Y)
        if not (pixels and render._off_core_usable(fx[0], fy[0], fx[1], fy[1], fx[2], fy[2],
                                                   inv_af, *t)):
            continue
        plane = plane_of(fx, fy, inv_af, t)
        spread = max(exact_at(fx, fy, inv_af, t, x, y)[1] for x, y in pixels)
        if spread > 16:
            traps += 1
            assert not plane[0], (fx.tolist(), fy.tolist(), inv_af, float(spread))
        if not plane[0]:
            refused_claims += sum(span_claim(plane, fx, fy, inv_af, t, x, x, y, lo, hi)
                                  for x, y in pixels)
    assert traps > 20 and refused_claims > 20, (traps, refused_claims)


def test_the_plane_refuses_far_window_coordinates():
    # beyond ±2^14 px a float32 window coordinate's snapping may move it by more than 1/256 px
    p = render._off_core_plane
    assert p(100.0, 100.0, 104.0, 100.0, 100.0, 104.0, 1 / 16, 0.0, 1.0, 0.5)[0]
    assert not p(2.0 ** 15, 100.0, 2.0 ** 15 + 4.0, 100.0, 2.0 ** 15, 104.0, 1 / 16, 0.0, 1.0,
                 0.5)[0]
