"""Eq. 3 in the rendering engines, checked by hand (issue 30: an analytic check that shares no
code with the implementation).

Set-up: a white square A = (u, v, 0, 0) seen face-on, crossed by three sheets B_i = (x_i, b, a,
Δ_i) perpendicular to it, each nearer than A in 4D by Δ_i (orthographic projection, scale 1:
screen units are the 4D coordinates). B_i is thickened along ±x, so its t is linear in x and
``|2t − 1| = |x − x_i|/ρ``. By Eq. 3 (MATH.md §5.4) B_i's halo puts the depth
``δ_A − Δ_i + max(0, |x − x_i|/ρ − δt)·δd`` at distance |x − x_i| ≤ ρ, and A's surface fragment
is carved where that is below δ_A, i.e. where ``|x − x_i| < ρ·min(1, δt + Δ_i/δd)``.

With ρ = 0.2, δt = 0.3, δd = 1 and Δ = 0.1, 0.25, 0.4 the half-widths are 0.08, 0.11, 0.14
(Eq. 3 with δd halved: 0.10, 0.16, 0.20). The image covers x ∈ [−1.1, 1.1] (the square plus
5 % margins) in 220 columns of 0.01, so the gap edges x_i ± hw (multiples of 0.01) lie half a
pixel from the nearest pixel centre, and the set of columns that are not white is predicted
exactly: 16, 22 and 28 columns around x_i = −0.5, 0, 0.5. (B_i itself, edge-on, is drawn dark
red in its core |x − x_i| < w_s·ρ = 0.06, inside the gap.)
"""

import numpy as np
import pytest

import refraster.halos4d as h

RHO, DELTA_T, DELTA_D = 0.2, 0.3, 1.0
DELTAS = (0.1, 0.25, 0.4)
XS = (-0.5, 0.0, 0.5)
W = 220


def scene():
    parts = [h.uv_surface(lambda u, v: np.stack([u, v, 0 * u, 0 * u], axis=-1), (-1, 1),
                          (-1, 1), 9, 9, color=(1.0, 1.0, 1.0))]
    for x0, d in zip(XS, DELTAS):
        def f(a, b, x0=x0, d=d):
            return np.stack([np.full_like(a, x0), 0.7 * b, 0.25 * a, np.full_like(a, d)],
                            axis=-1)
        parts.append(h.uv_surface(f, (-1, 1), (-1, 1), 3, 5, color=(1.0, 0.2, 0.2)))
    return h.merge(parts)


def eq3_half_width(delta, rho=RHO, delta_t=DELTA_T, delta_d=DELTA_D):
    """Where B's halo depth δ_B + max(0, u − δt)·δd, u = |x − x_i|/ρ ≤ 1, is below δ_A."""
    return rho * min(1.0, delta_t + delta / delta_d)


def predicted_gap_columns(delta_d):
    xc = -1.1 + (np.arange(W) + 0.5) * (2.2 / W)
    gap = np.zeros(W, bool)
    for x0, d in zip(XS, DELTAS):
        gap |= np.abs(xc - x0) < eq3_half_width(d, delta_d=delta_d)
    return gap


def test_hand_predictions():
    # the numbers of the module docstring, and the pixel centres half a pixel from every edge
    assert [round(eq3_half_width(d), 12) for d in DELTAS] == [0.08, 0.11, 0.14]
    assert [round(eq3_half_width(d, delta_d=0.5), 12) for d in DELTAS] == [0.1, 0.16, 0.2]
    xc = -1.1 + (np.arange(W) + 0.5) * (2.2 / W)
    for x0, d in zip(XS, DELTAS):
        edge = x0 + eq3_half_width(d)
        assert np.abs(xc - edge).min() == pytest.approx(0.005, abs=1e-9)
    assert predicted_gap_columns(DELTA_D).sum() == 16 + 22 + 28
    assert predicted_gap_columns(0.5).sum() == 20 + 32 + 40


@pytest.mark.parametrize("engine", ["fused", "reference"])
def test_engines_carve_the_gap_eq3_predicts(engine):
    r = h.render_halos(scene(), width=W, height=W, slices=40, engine=engine,
                       halos=h.Halos(rho=RHO, delta_d=DELTA_D, delta_t=DELTA_T, antialias=0.0))
    # the image spans the square plus the 5 % margins, as the prediction assumes
    np.testing.assert_allclose(r.bounds[:, :2], [[-1.1, -1.1], [1.1, 1.1]], atol=1e-12)
    white = r.image.min(axis=2) > 0.6
    rows = np.arange(W // 2 - 30, W // 2 + 30)          # |y| < 0.3: inside the strips
    inside = slice(10, W - 10)                           # |x| < 1: the square's columns
    expected = predicted_gap_columns(DELTA_D)[inside]
    for row in rows:
        np.testing.assert_array_equal(~white[row, inside], expected, err_msg=f"row {row}")
    # away from the strips (|y| > 0.8, inside the square) nothing is carved
    for row in (12, W - 13):
        assert white[row, inside].all()
    assert not white[:, :10].any() and not white[:, W - 10:].any()     # the margins
