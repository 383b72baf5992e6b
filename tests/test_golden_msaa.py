"""Multisampled goldens (issue 43, item 3): per-sample buffers and the resolved colour, per-sample
allowances, the declared sample pattern; refraster's own frame passes, the planted MSAA bugs of
``tests/faults_msaa.py`` fail naming the buffer, a candidate of another pattern is refused in
one line. The fault harness's matrix is in docs/backends.md ("Multisampled goldens")."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

import faults_msaa as fm
from conftest import check_backends_matrix, generate_gold
from refraster.golden.compare.run import compare
from refraster.golden.io.read import PATTERN_FILE
from refraster.golden.msaa_scenes import SAMPLE_CHANNELS, msaa_scene_names, sample_buffer
from refraster.golden.scenes import available_scenes

SCENES = msaa_scene_names() if available_scenes() else []
BEGIN = "<!-- msaa-harness-matrix:begin (tests/test_golden_msaa.py) -->"
END = "<!-- msaa-harness-matrix:end -->"
_SAMPLE = re.compile(r"^sample([0-9]+)_(.+)$")


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "msaa", SCENES)


def _candidate(gold, tag, names, fault="none", **kw):
    out = gold / f"cand_{tag}"
    shutil.rmtree(out, ignore_errors=True)
    return fm.write_candidate(out, names, fault, **kw)


def msaa_cell(scene_result):
    """``pass``, or ``**FAIL**`` with each failing channel and on how many samples it failed
    (``color`` alone: the resolved colour)."""
    if scene_result.status != "pass" and not scene_result.buffers:
        return f"**ERROR** {scene_result.error}"
    if scene_result.status == "pass":
        return "pass"
    per = {}
    n = 0
    for b in scene_result.buffers:
        m = _SAMPLE.match(b.name)
        if m:
            n = max(n, int(m.group(1)) + 1)
        if b.passed:
            continue
        ch = m.group(2) if m else f"{b.name} (resolve)"
        per[ch] = per.get(ch, 0) + (1 if m else 0)
    order = [*SAMPLE_CHANNELS, "color (resolve)"]
    cells = [f"`{ch}` {k}/{n}" if k else f"`{ch.split()[0]}` resolve"
             for ch, k in sorted(per.items(), key=lambda kv: order.index(kv[0]))]
    return "**FAIL** " + ", ".join(cells)


def test_the_golden_declares_its_pattern_and_stores_every_sample(gold):
    manifest = json.loads((gold / "golden" / "manifest.json").read_text())
    entry = manifest["scenes"]["msaa8_cube"]
    pattern = entry["parameters"]["technique"]["sample_pattern"]
    assert pattern == {"samples": 8, "positions": [[9, 5], [7, 11], [13, 9], [5, 3], [3, 13],
                                                   [1, 7], [11, 15], [15, 1]]}
    gl = manifest["scenes"]["msaa4gl_cube"]["parameters"]["technique"]["sample_pattern"]
    assert gl["positions"] == [[6, 14], [14, 10], [2, 6], [10, 2]]
    scene = json.loads((gold / "golden" / "msaa8_cube" / "package" / "scene.json").read_text())
    assert scene["raster"]["samples"] == 8 and scene["raster"]["sample_locations"] == "standard"
    names = set(entry["buffers"])
    assert names == {sample_buffer(s, ch) for s in range(8) for ch in SAMPLE_CHANNELS} | {"color"}
    for s in range(8):
        assert entry["buffers"][sample_buffer(s, "depth")]["tolerant"]["sample"] == s
    assert entry["buffers"]["color"]["tolerant"] == {
        "checks": ["bounds"], "lo": "resolve_color_lo", "hi": "resolve_color_hi"}
    with np.load(gold / "golden" / "msaa8_cube" / "buffers.npz") as z:
        mean = np.mean([z[sample_buffer(s, "color")].astype(np.float64) for s in range(8)], 0)
        np.testing.assert_allclose(z["color"], mean, atol=1e-6)


def test_refraster_passes_its_own_goldens(gold):
    cand = _candidate(gold, "none", SCENES)
    r = compare(gold / "golden", cand, mode="tolerant")
    assert r.exit_code == 0, r.failures()[:5]
    # and the golden passes itself exactly
    assert compare(gold / "golden", cand, mode="exact").exit_code == 0


@pytest.mark.parametrize("fault", [f for f in fm.FAULTS if f != "none"])
def test_a_planted_fault_fails_naming_the_buffer(gold, fault):
    names = ["msaa4_cube", "msaa8_cube", "msaa4_asymmetric"]
    r = compare(gold / "golden", _candidate(gold, fault, names, fault), mode="tolerant",
                scenes=names)
    assert r.exit_code == 1
    expect = fm.NAMES[fault]
    for s in r.scenes:
        assert s.status == "fail", (fault, s.name)
        lines = [line for line in r.failures() if line.startswith(f"{s.name}/")]
        if expect == "color":
            assert any(line.startswith(f"{s.name}/color: bounds") for line in lines), lines[:3]
        else:
            assert any(re.match(rf"{s.name}/sample[0-9]+_{expect}: ", line) for line in lines), \
                lines[:3]


def test_the_mirrored_pattern_fails_the_asymmetric_triangle_and_the_ties(gold):
    names = ["msaa4_asymmetric", "msaa4_ties"]
    r = compare(gold / "golden", _candidate(gold, "mirror", names, "pattern_mirrored"),
                mode="tolerant", scenes=names)
    for s in r.scenes:
        failing = {b.name for b in s.buffers if not b.passed}
        assert {sample_buffer(k, "prim_id") for k in range(4)} <= failing, (s.name, failing)


def test_a_candidate_of_another_pattern_is_refused_in_one_line(gold):
    mirrored = {"samples": 4, "positions": [[6, 14], [14, 10], [2, 6], [10, 2]]}
    cand = _candidate(gold, "other", ["msaa4_cube"], pattern=mirrored)
    r = compare(gold / "golden", cand, mode="tolerant", scenes=["msaa4_cube"])
    assert r.exit_code == 2
    (line,) = r.failures()
    assert line == ("msaa4_cube: unusable candidate: sample pattern mismatch: the golden "
                    "declares 4 samples at (6, 2) (14, 6) (2, 10) (10, 14), the candidate "
                    "states 4 samples at (6, 14) (14, 10) (2, 6) (10, 2) (1/16 pixel, y down); "
                    "compare it against a golden of its pattern")
    # the llvmpipe golden of the same cube takes it
    cand = _candidate(gold, "gl", ["msaa4gl_cube"])
    assert compare(gold / "golden", cand, mode="tolerant",
                   scenes=["msaa4gl_cube"]).exit_code == 0
    (cand / "msaa4gl_cube" / PATTERN_FILE).unlink()
    r = compare(gold / "golden", cand, mode="tolerant", scenes=["msaa4gl_cube"])
    assert r.exit_code == 2 and "states no sample pattern (write msaa4gl_cube/" \
        "sample_pattern.json)" in r.failures()[0]
    (cand / "msaa4gl_cube" / PATTERN_FILE).write_text('{"samples": 4, "positions": [[1, 2]]}')
    r = compare(gold / "golden", cand, mode="tolerant", scenes=["msaa4gl_cube"])
    assert r.exit_code == 2 and "must hold" in r.failures()[0]


@pytest.mark.parametrize("scene, interpolation, passes", [
    ("msaa4_centroid_cube", "sample", True),      # a covered sample: inside pixel and primitive
    ("msaa4_centroid_cube", "center", False),     # the centre extrapolates outside the primitive
    ("msaa4_cube", "centroid", False),            # the golden interpolates at the centre
])
def test_centroid_any_point_inside_pixel_and_primitive(gold, scene, interpolation, passes):
    cand = _candidate(gold, f"interp_{interpolation}", [scene], interpolation=interpolation)
    r = compare(gold / "golden", cand, mode="tolerant", scenes=[scene])
    assert (r.exit_code == 0) == passes, r.failures()[:3]
    if not passes:
        failing = {b.name for b in r.scenes[0].buffers if not b.passed}
        assert failing and all(n.endswith("_barycentric") for n in failing), failing


def test_resolve_interval_contains_every_mean_of_allowed_samples(gold):
    """The resolve's interval is the mean of the samples' intervals: the golden's resolved
    colour is inside, and so is the resolve of any colours at the samples' interval ends."""
    from refraster.golden.allowances.samples import resolve_bounds
    from refraster.conformance import MAY, MUST, MUST_NOT
    h, w = 2, 3
    a0 = {"coverage": np.full((h, w), MUST, np.int8), "id_may": np.zeros((h, w), bool),
          "color_lo": np.full((h, w, 3), 0.2, np.float32),
          "color_hi": np.full((h, w, 3), 0.3, np.float32)}
    a1 = {**a0, "coverage": np.full((h, w), MUST_NOT, np.int8)}
    a2 = {**a0, "coverage": np.full((h, w), MAY, np.int8)}
    lo, hi = resolve_bounds([a0, a1, a2], (1.0, 1.0, 1.0))
    # MUST: [0.2, 0.3]; MUST_NOT: 1; MAY without a set: anything in [0, 1] with the background
    np.testing.assert_allclose(lo, (0.2 + 1.0 + 0.0) / 3, atol=1e-5)
    np.testing.assert_allclose(hi, (0.3 + 1.0 + 1.0) / 3, atol=1e-5)


def harness_table(results, scenes):
    columns = list(results)
    head = ["scene"] + [c if c == "correct" else f"`{c}`" for c in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene in scenes:
        lines.append(f"| {scene} | " + " | ".join(msaa_cell(results[c][scene])
                                                  for c in columns) + " |")
    return "\n".join(lines)


def test_fault_harness_matrix(gold):
    """Every scene × refraster's frame and each planted fault: the correct column passes
    everywhere, every fault fails every scene, naming its buffer (docs/backends.md)."""
    results = {}
    for fault in fm.FAULTS:
        r = compare(gold / "golden", _candidate(gold, f"matrix_{fault}", SCENES, fault),
                    mode="tolerant")
        results["correct" if fault == "none" else fault] = {s.name: s for s in r.scenes}
    for name in SCENES:
        assert results["correct"][name].status == "pass", name
        for fault in fm.FAULTS[1:]:
            s = results[fault][name]
            assert s.status == "fail", (fault, name)
            failing = {b.name for b in s.buffers if not b.passed}
            expect = fm.NAMES[fault]
            assert (expect == "color" and "color" in failing) or any(
                n.endswith(f"_{expect}") for n in failing), (fault, name, failing)
    check_backends_matrix(BEGIN, END, harness_table(results, SCENES),
                          "multisampled goldens' fault-harness matrix")


def _shade_at(beta, corners, vnormals, base):
    """The default colour (raster.gbuffer.shade's formula, float64) at barycentrics ``beta``
    (N, 3) of a face with eye-space corners and eye-space vertex normals (3, 3)."""
    from refraster.raster.gbuffer import AMBIENT, DIFFUSE, SHININESS, SPECULAR
    e = beta @ corners
    n = beta @ vnormals
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = np.minimum(np.abs((n * e).sum(axis=1)) / np.linalg.norm(e, axis=1), 1.0)[:, None]
    return np.clip(base * (AMBIENT + DIFFUSE * d) + SPECULAR * d ** SHININESS, 0.0, 1.0), n, e


@pytest.mark.parametrize("smooth", [True, False])
def test_centroid_colour_bounds_hold_at_every_point_of_the_polygon(smooth):
    """headlight_bounds from a polygon's vertices contains the colour at 400 points inside
    it (convex combinations, brute force in float64), on 100 random faces and polygons
    small and large (so the eye position's components change sign inside some); and it is not vacuous: never wider than 0.15 where the colour varies by less
    than 0.03 over the polygon."""
    from refraster.golden.allowances.samples import headlight_bounds
    rng = np.random.default_rng(7)
    base = np.array([0.8, 0.5, 0.3])
    for k in range(100):
        corners = rng.uniform([-1, -1, -4], [1, 1, -1.5], (3, 3))
        facing = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        facing /= np.linalg.norm(facing)
        vn = facing + (rng.normal(0, 0.3, (3, 3)) if smooth else np.zeros((3, 3)))
        centre = rng.dirichlet([4, 4, 4])
        verts = centre + rng.normal(0, 0.02 if k % 2 else 0.3, (6, 3))   # pixel- / face-sized
        verts = np.abs(verts) / np.abs(verts).sum(axis=1, keepdims=True)
        _, n_v, e_v = _shade_at(verts, corners, vn, base)
        lo, hi = headlight_bounds(n_v[None], e_v[None], base[None])
        lam = rng.dirichlet(np.ones(len(verts)) * 0.3, 400)
        inside = lam @ verts
        truth, _, _ = _shade_at(inside, corners, vn, base)
        assert np.all(truth >= lo - 1e-12) and np.all(truth <= hi + 1e-12)
        spread = truth.max(axis=0) - truth.min(axis=0)
        if k % 2 and spread.max() < 0.03:
            assert (hi - lo).max() < 0.15, (hi - lo, spread)


def test_interval_products_and_squares_are_exact_ranges():
    """The interval arithmetic under headlight_bounds, against brute force on a grid of each
    interval (endpoints included): the ranges contain every product and square and are
    attained (exact, not merely safe) — intervals of either sign and straddling 0."""
    from refraster.golden.allowances.samples import _product_range, _square_range
    rng = np.random.default_rng(3)
    ends = np.sort(rng.uniform(-2, 2, (200, 2, 2)), axis=2)
    grid = np.linspace(0.0, 1.0, 41)
    for (a_lo, a_hi), (b_lo, b_hi) in ends:
        a = a_lo + (a_hi - a_lo) * grid
        b = b_lo + (b_hi - b_lo) * grid
        lo, hi = _product_range(a_lo, a_hi, b_lo, b_hi)
        prod = np.outer(a, b)
        assert lo == prod.min() and hi == prod.max()
        s_lo, s_hi = _square_range(a_lo, a_hi)
        sq = np.concatenate([a * a, [0.0] if a_lo <= 0 <= a_hi else []])
        assert s_lo == sq.min() and s_hi == sq.max()
