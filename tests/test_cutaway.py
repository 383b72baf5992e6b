"""Jump flooding of the cutaway function (refraster.cutaway.flood): MATH.md §4.1, D-C1, D-C5."""


import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from refraster.cutaway import VARIANTS, chamfer, exact, jump_flood
from refraster.cutaway.flood import step_schedule

from naive import jump_flood as jump_flood_twin
from determinism import outputs_by_thread_count


def naive(z, m, sampling=(1.0, 1.0), floor_slope=None, floor_normal=None):
    """max over seeds of z(s) − m(s)·‖x − s‖ by NumPy broadcasting (ties: first in row-major)."""
    h, w = z.shape
    seeds = np.flatnonzero(z > -np.inf)
    si, sj = np.divmod(seeds, w)
    i, j = np.indices((h, w))
    dy = (i[..., None] - si) * sampling[0]
    dx = (j[..., None] - sj) * sampling[1]
    d = np.sqrt(dy * dy + dx * dx)
    m = np.broadcast_to(m, z.shape).reshape(-1)[seeds]
    slope = np.broadcast_to(m, d.shape)
    if floor_slope is not None:
        nx = floor_normal[..., 0].reshape(-1)[seeds]
        ny = floor_normal[..., 1].reshape(-1)[seeds]
        with np.errstate(invalid="ignore", divide="ignore"):
            a = np.clip(-(dx * nx - dy * ny) / d, 0.0, 1.0)
        a = np.where(d == 0, 0.0, a)
        mf = floor_slope.reshape(-1)[seeds]
        slope = np.where(a > 0, (1.0 - a) * m + a * mf, m)
    c = np.where(d == 0, z.reshape(-1)[seeds], z.reshape(-1)[seeds] - slope * d)
    if len(seeds) == 0:
        return np.full((h, w), -np.inf), np.full((h, w, 2), -1)
    k = np.argmax(c, axis=-1)
    best = np.take_along_axis(c, k[..., None], -1)[..., 0]
    return best, np.stack([si[k], sj[k]], axis=-1)


def random_seeds(rng, h, w, density, constant=None):
    z = np.full((h, w), -np.inf)
    mask = rng.random((h, w)) < density
    mask.flat[rng.integers(h * w)] = True
    z[mask] = constant if constant is not None else rng.random(mask.sum())
    return z


# --------------------------------------------------------------------------------- hand-worked


def test_one_row_by_hand():
    z = np.array([[2.0, -np.inf, -np.inf, -np.inf, -np.inf]])
    for f in (exact, chamfer, *[lambda a, b, v=v: jump_flood(a, b, variant=v) for v in VARIANTS]):
        np.testing.assert_array_equal(f(z, 0.5), [[2.0, 1.5, 1.0, 0.5, 0.0]])


def test_no_seed_gives_minus_inf():
    z = np.full((3, 4), -np.inf)
    d, s = jump_flood(z, 1.0, return_seeds=True)
    assert np.all(d == -np.inf) and np.all(s == -1)
    d, s = exact(z, 1.0, return_seeds=True)
    assert np.all(d == -np.inf) and np.all(s == -1)


def test_tie_goes_to_smaller_flat_index():
    # two equal seeds symmetric about the middle column: the middle pixels tie
    z = np.full((3, 5), -np.inf)
    z[1, 0] = z[1, 4] = 1.0
    for f in (exact, lambda a, b, **k: jump_flood(a, b, variant="jfa+1", **k), chamfer):
        d, s = f(z, 1.0, return_seeds=True)
        assert tuple(s[1, 2]) == (1, 0)
        assert tuple(s[0, 2]) == (1, 0)
        assert tuple(s[1, 3]) == (1, 4)


def test_step_schedule():
    assert step_schedule(100, 60, "jfa") == [64, 32, 16, 8, 4, 2, 1]
    assert step_schedule(128, 128, "jfa+1")[-2:] == [1, 1]
    assert step_schedule(5, 3, "jfa+2") == [4, 2, 1, 2, 1]
    assert step_schedule(5, 3, "1+jfa") == [1, 4, 2, 1]
    assert step_schedule(1, 1, "jfa") == [1]


def test_sampling_scales_distances():
    z = np.full((3, 3), -np.inf)
    z[0, 0] = 0.0
    d = exact(z, 1.0, sampling=(2.0, 0.5))
    assert d[2, 0] == -4.0 and d[0, 2] == -1.0 and d[2, 2] == -np.hypot(4.0, 1.0)


def test_directional_slope_by_hand():
    # n_proj points up on screen: pixels below the seed (larger rows) use the floor slope
    z = np.full((5, 5), -np.inf)
    z[2, 2] = 0.0
    normal = np.zeros((5, 5, 2))
    normal[..., 1] = 1.0
    for f in (exact, jump_flood):
        d = f(z, 1.0, floor_slope=np.full((5, 5), 3.0), floor_normal=normal)
        assert d[4, 2] == -6.0      # straight down: α = 1
        assert d[0, 2] == -2.0      # straight up: α = 0
        assert d[2, 4] == -2.0      # sideways: α = 0
        a = 1.0 / np.sqrt(2.0)
        assert d[3, 3] == pytest.approx(-((1 - a) * 1.0 + a * 3.0) * np.sqrt(2.0), abs=1e-12)


# --------------------------------------------------------------------------------- oracles


def test_exact_matches_numpy_reference():
    rng = np.random.default_rng(1)
    z = random_seeds(rng, 23, 31, 0.05)
    m = rng.uniform(0.05, 2.0, z.shape)
    normal = rng.normal(size=z.shape + (2,))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    mf = m + rng.uniform(0, 3, z.shape)
    for kw in ({}, dict(sampling=(1.5, 0.7)), dict(floor_slope=mf, floor_normal=normal)):
        d, s = exact(z, m, return_seeds=True, **kw)
        rd, rs = naive(z, m, kw.get("sampling", (1.0, 1.0)), kw.get("floor_slope"),
                       kw.get("floor_normal"))
        np.testing.assert_allclose(d, rd, rtol=0, atol=1e-12)
        assert np.mean(np.all(s == rs, axis=-1)) > 0.999


@pytest.mark.parametrize("sampling", [(1.0, 1.0), (1.0, 1.7)])
def test_constant_depth_against_edt(oracle, sampling):
    ndimage = oracle("scipy.ndimage")
    rng = np.random.default_rng(7)
    z0, m = 0.25, 0.37
    agree = {v: [] for v in VARIANTS}
    for h, w, density in [(97, 64, 0.002), (128, 128, 0.001), (64, 100, 0.01), (80, 80, 0.0005)]:
        z = random_seeds(rng, h, w, density, constant=z0)
        ref = z0 - m * ndimage.distance_transform_edt(z == -np.inf, sampling=sampling)
        np.testing.assert_allclose(exact(z, m, sampling=sampling), ref, rtol=0, atol=1e-12)
        for v in VARIANTS:
            d = jump_flood(z, m, variant=v, sampling=sampling)
            assert np.all(d <= ref + 1e-12)  # JFA maximises over a subset of the seeds
            agree[v].append(np.isclose(d, ref, rtol=0, atol=1e-12))
    frac = {v: np.mean(np.concatenate([a.ravel() for a in agree[v]])) for v in VARIANTS}
    assert frac["jfa"] >= 0.99
    for v in ("jfa+1", "1+jfa", "jfa+2"):
        assert frac[v] >= 0.999, (v, frac[v])


def error_table(n_images=50, max_side=128, seed=2026):
    """Per variant: fraction of pixels differing from exact, and the largest error, over random
    seed images with random depths and per-seed slopes (also printed into docs/cutaway.md)."""
    rng = np.random.default_rng(seed)
    wrong = {v: 0 for v in VARIANTS + ("chamfer",)}
    worst = {v: 0.0 for v in wrong}
    total = 0
    for _ in range(n_images):
        h, w = rng.integers(16, max_side + 1, size=2)
        z = random_seeds(rng, h, w, rng.uniform(0.001, 0.03))
        m = rng.uniform(0.05, 2.0, z.shape)
        ref = exact(z, m)
        total += z.size
        for v in wrong:
            d = chamfer(z, m) if v == "chamfer" else jump_flood(z, m, variant=v)
            err = np.abs(d - ref)
            wrong[v] += int(np.count_nonzero(err > 1e-12))
            worst[v] = max(worst[v], float(err.max()))
    return {v: (wrong[v] / total, worst[v]) for v in wrong}


def test_random_images_error_table():
    table = error_table()
    assert table["jfa"][0] < 0.01
    for v in ("jfa+1", "jfa+2", "1+jfa"):
        assert table[v][0] < table["jfa"][0], table


def test_chamfer_error_is_bounded():
    z = np.full((41, 41), -np.inf)
    z[20, 20] = 0.0
    d = chamfer(z, 1.0)
    e = exact(z, 1.0)
    # exact along the axes, within Borgefors' 5-7-11 bound (≈2 %) elsewhere
    np.testing.assert_array_equal(d[20], e[20])
    np.testing.assert_array_equal(d[:, 20], e[:, 20])
    rel = np.abs(d - e)[e < 0] / -e[e < 0]
    assert 0 < rel.max() < 0.03


@settings(max_examples=15, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.integers(0, 2**31 - 1),
       st.sampled_from(VARIANTS))
def test_jfa_properties(h, w, seed, variant):
    rng = np.random.default_rng(seed)
    z = random_seeds(rng, h, w, 0.1)
    m = rng.uniform(0.0, 2.0, z.shape)
    d, s = jump_flood(z, m, variant=variant, return_seeds=True)
    e = exact(z, m)
    assert np.all(d <= e)
    seeded = z > -np.inf
    assert np.all(d[seeded] >= z[seeded])  # a pixel never loses its own seed
    # the returned seed explains the returned value
    i, j = np.indices(z.shape)
    dist = np.sqrt((i - s[..., 0]) ** 2 + (j - s[..., 1]) ** 2.0)
    np.testing.assert_allclose(d, z[s[..., 0], s[..., 1]] - m[s[..., 0], s[..., 1]] * dist,
                               atol=1e-12)


@pytest.mark.parametrize("variant", VARIANTS)
def test_jump_flood_matches_pixel_by_pixel_reference(variant):
    # the vectorized row sweeps against tests/naive.py's pixel-by-pixel loop, bit for bit: odd
    # sizes and 1×N, scalar and per-seed slopes, non-square pixels, the floor term, and a grid of
    # equal seeds with an integer slope (many exact ties)
    rng = np.random.default_rng(17)
    grid = np.full((15, 12), -np.inf)
    grid[1::4, 2::3] = 0.5
    cases = [(grid, 1.0, (1.0, 1.0), False)]
    for h, w in [(1, 9), (7, 1), (5, 6), (13, 10), (16, 16), (11, 23)]:
        z = random_seeds(rng, h, w, 0.15)
        cases += [(z, 0.37, (1.0, 1.0), False), (z, rng.uniform(0, 2, (h, w)), (1.0, 1.7), False),
                  (z, rng.uniform(0, 2, (h, w)), (0.4, 1.3), True)]
    for z, m, sampling, directional in cases:
        kw = dict(sampling=sampling)
        if directional:
            kw.update(floor_slope=rng.uniform(0, 4, z.shape),
                      floor_normal=rng.normal(size=z.shape + (2,)))
        ref_d, ref_s = jump_flood_twin(z, m, step_schedule(*z.shape, variant), **kw)
        d, s = jump_flood(z, m, variant=variant, return_seeds=True, **kw)
        assert d.tobytes() == ref_d.tobytes()
        assert s.tobytes() == ref_s.tobytes()
        assert jump_flood(z, m, variant=variant, **kw).tobytes() == ref_d.tobytes()


# --------------------------------------------------------------------------------- determinism

_SCRIPT = """
import hashlib, numpy as np
from refraster.cutaway import jump_flood, exact
rng = np.random.default_rng(3)
z = np.where(rng.random((150, 130)) < 0.01, rng.random((150, 130)), -np.inf)
m = rng.uniform(0.1, 2, z.shape)
n = rng.normal(size=z.shape + (2,))
out = [jump_flood(z, m, variant=v, return_seeds=True) for v in ("jfa", "jfa+1", "1+jfa")]
out.append(jump_flood(z, m, floor_slope=m * 3, floor_normal=n, return_seeds=True))
out.append(exact(z, m, return_seeds=True))
print(hashlib.sha256(b"".join(a.tobytes() + b.tobytes() for a, b in out)).hexdigest())
"""


def test_bit_identical_across_runs_and_threads():
    digests = set(outputs_by_thread_count(_SCRIPT))
    assert len(digests) == 1


# --------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("f", [jump_flood, exact, chamfer])
def test_bad_inputs(f):
    z = np.zeros((4, 4))
    with pytest.raises(ValueError, match="seed_depth"):
        f(np.full((4, 4), np.nan), 1.0)
    with pytest.raises(ValueError, match="seed_depth"):
        f(np.full((4, 4), np.inf), 1.0)
    with pytest.raises(ValueError, match="seed_depth"):
        f(np.zeros(4), 1.0)
    with pytest.raises(ValueError, match="seed_depth"):
        f(np.zeros((0, 4)), 1.0)
    with pytest.raises(ValueError, match="slope"):
        f(z, -1.0)
    with pytest.raises(ValueError, match="slope"):
        f(z, np.ones((3, 4)))
    with pytest.raises(ValueError, match="slope"):
        f(z, np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="sampling"):
        f(z, 1.0, sampling=(1.0, 0.0))
    with pytest.raises(TypeError, match="seed_depth"):
        f("abc", 1.0)


def test_bad_variant_and_floor_arguments():
    z = np.zeros((4, 4))
    with pytest.raises(ValueError, match="variant"):
        jump_flood(z, 1.0, variant="jfa+3")
    with pytest.raises(ValueError, match="together"):
        jump_flood(z, 1.0, floor_slope=np.ones((4, 4)))
    with pytest.raises(ValueError, match="floor_normal"):
        exact(z, 1.0, floor_slope=np.ones((4, 4)), floor_normal=np.ones((4, 4, 3)))
