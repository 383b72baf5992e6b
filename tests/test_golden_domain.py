"""Goldens with teeth (1), items 1 and 2: domain checks in every mode, and "nothing compared"
is never a pass.

Every case plants garbage that the old tolerant compare let through (NaN on the background,
normals of length 1e30, ids of −7, background depth 7.0) and checks that the compare fails
with exit 1 naming scene, buffer, pixel and value; the golden itself (and an in-domain
candidate) must still pass.
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from refraster import golden
from refraster.golden.compare.run import EXIT_FAIL, EXIT_PASS, GoldenError, compare, load_manifest
from refraster.golden.compare.domain import NORMAL_LENGTH_TOL, domain_checks

SCENES = ["render_cube", "render_crank"]
MODES = ["tolerant", "exact", "conformant"]


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("domain") / "g"
    golden.generate(out, SCENES + ["clipsurface_building"])
    return out


def _buffers(gold, scene):
    with np.load(gold / scene / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def _write(root, scene, buffers):
    (root / scene).mkdir(parents=True, exist_ok=True)
    np.savez(root / scene / "buffers.npz", **buffers)


def _compare(gold, cand, scene, how):
    kw = {"profile": "conformant"} if how == "conformant" else {"mode": how}
    return compare(gold, cand, scenes=[scene], **kw)


def _background(b):
    return np.argwhere(b["prim_id"] < 0)


def _covered(b):
    return np.argwhere(b["prim_id"] >= 0)


# --- the golden itself passes in every mode (the other direction) ------------------------------

@pytest.mark.parametrize("how", MODES)
def test_golden_passes_its_own_domain_checks(gold, tmp_path, how):
    for scene in SCENES + ["clipsurface_building"]:
        _write(tmp_path, scene, _buffers(gold, scene))
        r = _compare(gold, tmp_path, scene, how)
        assert r.exit_code == EXIT_PASS, r.failures()


# --- garbage fails in every mode -----------------------------------------------------------------

def _plant(b, what):
    """(buffers with garbage, buffer name, pixel)."""
    b = {k: v.copy() for k, v in b.items()}
    bg = tuple(_background(b)[len(_background(b)) // 2])
    cov = tuple(_covered(b)[len(_covered(b)) // 3])
    if what == "nan_background":
        b["depth"][b["prim_id"] < 0] = np.nan
        b["normal"][b["prim_id"] < 0] = np.nan
        return b, "depth", None
    if what == "nan_one_pixel":
        b["depth"][cov] = np.nan
        return b, "depth", cov
    if what == "huge_normal":
        b["normal"][cov] = b["normal"][cov] * 1e30
        return b, "normal", cov
    if what == "short_normal":
        b["normal"][cov] = b["normal"][cov] * 0.9
        return b, "normal", cov
    if what == "background_normal":
        b["normal"][bg] = [0.0, 0.0, 0.5]
        return b, "normal", bg
    if what == "id_minus7":
        b["prim_id"][bg] = -7
        return b, "prim_id", bg
    if what == "object_id_minus7":
        b["object_id"][b["prim_id"] < 0] = -7
        return b, "object_id", None
    if what == "id_too_large":
        b["prim_id"][cov] = 10 ** 6
        return b, "prim_id", cov
    if what == "depth_7":
        b["depth"][b["prim_id"] < 0] = 7.0
        return b, "depth", None
    if what == "depth_negative":
        b["depth"][cov] = -0.25
        return b, "depth", cov
    if what == "eye_depth_neg_inf":
        b["eye_depth"][cov] = -np.inf
        return b, "eye_depth", cov
    if what == "eye_depth_inf_covered":
        b["eye_depth"][cov] = np.inf
        return b, "eye_depth", cov
    if what == "bool_two":
        b["front_facing"] = b["front_facing"].astype(np.uint8)
        b["front_facing"][cov] = 2
        return b, "front_facing", cov
    raise AssertionError(what)


GARBAGE = ["nan_background", "nan_one_pixel", "huge_normal", "short_normal",
           "background_normal", "id_minus7", "object_id_minus7", "id_too_large", "depth_7",
           "depth_negative", "eye_depth_neg_inf", "eye_depth_inf_covered", "bool_two"]


@pytest.mark.parametrize("how", MODES)
@pytest.mark.parametrize("what", GARBAGE)
@pytest.mark.parametrize("scene", SCENES)
def test_garbage_fails_naming_scene_buffer_pixel(gold, tmp_path, scene, what, how):
    b, key, pixel = _plant(_buffers(gold, scene), what)
    _write(tmp_path, scene, b)
    r = _compare(gold, tmp_path, scene, how)
    assert r.exit_code == EXIT_FAIL
    domain = [line for line in r.failures() if line.startswith(f"{scene}/{key}: domain:")]
    assert domain, r.failures()
    if pixel is not None:
        assert f"row {pixel[0]}, col {pixel[1]}" in domain[0], domain[0]


def test_png_candidate_normals_get_one_step(gold, tmp_path):
    """An 8-bit PNG of the golden's normals passes (its lengths are off by up to √3·step),
    a normal scaled by 0.9 in the same PNG fails."""
    from refraster import io as rio
    scene = "render_cube"
    b = _buffers(gold, scene)
    for planted in (False, True):
        n = b["normal"].copy()
        if planted:
            cov = tuple(_covered(b)[0])
            n[cov] *= 0.9
        png = np.clip(np.rint((n * 0.5 + 0.5) * 255), 0, 255).astype(np.uint8)
        d = tmp_path / str(planted) / scene
        d.mkdir(parents=True)
        rio.write_png(d / "normal.png", png)
        np.save(d / "prim_id.npy", b["prim_id"])
        r = compare(gold, d.parent, scenes=[scene], mode="tolerant",
                    buffers=["normal", "prim_id"])
        domain = [x for x in r.failures() if "domain:" in x]
        assert bool(domain) == planted, r.failures()


def test_domain_checks_hand_worked():
    ref = np.zeros((2, 3), np.float32)
    cand = ref.copy()
    cand[1, 2] = np.nan
    (c,) = domain_checks("depth", "unorm", ref, cand)
    assert c["metric"] == "domain:nan" and c["pixel"] == [1, 2] and c["value"] == 1
    cand = ref.copy()
    cand[0, 1] = 1.0 + 1e-6
    (c,) = domain_checks("depth", "unorm", ref, cand)
    assert c["metric"] == "domain:depth_range" and c["pixel"] == [0, 1]
    assert domain_checks("depth", "unorm", ref, np.ones_like(ref)) == []
    # normals: exactly at the slack passes, beyond it fails
    n = np.zeros((1, 2, 3))
    n[0, 0] = [0.0, 0.0, 1.0 + NORMAL_LENGTH_TOL * 0.99]
    assert domain_checks("normal", "snorm", n, n) == []
    n[0, 0] = [0.0, 0.0, 1.0 + NORMAL_LENGTH_TOL * 1.01]
    assert domain_checks("normal", "snorm", n, n)[0]["pixel"] == [0, 0]
    step = 2 / 255
    n[0, 0] = [0.0, 0.0, 1.0 + NORMAL_LENGTH_TOL + math.sqrt(3) * step * 0.99]
    assert domain_checks("normal", "snorm", n, n, step=step) == []
    # ids
    ids = np.array([[-1, 0, 5]])
    assert domain_checks("prim_id", "id", ids, ids, id_range=(-1, 5)) == []
    (c,) = domain_checks("prim_id", "id", ids, ids, id_range=(-1, 4))
    assert c["pixel"] == [0, 2] and c["candidate_value"] == 5
    (c,) = domain_checks("prim_id", "id", ids, ids - 1)
    assert c["pixel"] == [0, 0] and c["candidate_value"] == -2
    # +inf where the golden is finite: refused where the candidate says covered, allowed where
    # it says background
    e = np.array([[1.0, 2.0]])
    ce = np.array([[np.inf, np.inf]])
    (c,) = domain_checks("eye_depth", "float", e, ce, coverage=np.array([[False, True]]))
    assert c["pixel"] == [0, 1] and c["value"] == 1


def test_manifest_states_id_ranges(gold):
    m = load_manifest(gold)
    cube = m["scenes"]["render_cube"]["buffers"]
    assert cube["prim_id"]["ids"] == [-1, 11] and cube["object_id"]["ids"] == [-1, 0]
    for name, entry in m["scenes"].items():
        for key, spec in entry["buffers"].items():
            if spec["kind"] == "id":
                lo, hi = spec["ids"]
                b = _buffers(gold, name)[key]
                assert lo <= b.min() and b.max() <= hi, (name, key)


def test_scene_breaking_its_id_convention_is_refused():
    from refraster.golden.generate import _id_range
    from refraster.golden.scenes import GoldenScene
    cube = golden.available_scenes()["render_cube"].build()
    scene = GoldenScene(technique=cube.technique, camera=cube.camera, draws=cube.draws,
                        buffers=cube.buffers)
    a = np.array([[-1, 12]])
    with pytest.raises(ValueError, match=r"outside its convention \[-1, 11\]"):
        _id_range("x", "prim_id", scene, a)
    assert _id_range("x", "prim_id", scene, np.array([[-1, 11]])) == [-1, 11]
    scene.ids["prim_id"] = (-1, 40)
    assert _id_range("x", "prim_id", scene, a) == [-1, 40]
    with pytest.raises(ValueError, match="has no id convention"):
        _id_range("x", "mystery_id", scene, a)


# --- nothing compared is never a pass ------------------------------------------------------------

def test_nothing_compared_is_refused(gold, tmp_path):
    scene = "render_cube"
    _write(tmp_path, scene, _buffers(gold, scene))
    with pytest.raises(GoldenError, match="nothing to compare: no scene was selected"):
        compare(gold, tmp_path, scenes=[], mode="tolerant")
    with pytest.raises(GoldenError, match="every buffer was filtered out"):
        compare(gold, tmp_path, scenes=[scene], buffers=[], mode="tolerant")
    # a golden whose manifest lists no scenes (rewritten with its file list kept consistent)
    empty = tmp_path / "empty"
    empty.mkdir()
    m = load_manifest(gold)
    m["scenes"], m["files"] = {}, {}
    (empty / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(GoldenError, match="the golden has no scenes"):
        compare(empty, tmp_path, mode="exact")
    # a scene without buffers
    bare = tmp_path / "bare"
    bare.mkdir()
    m = load_manifest(gold)
    m["scenes"] = {scene: dict(m["scenes"][scene], buffers={})}
    keep = {f for f in m["files"] if f.startswith(f"{scene}/")}
    m["files"] = {f: d for f, d in m["files"].items() if f in keep}
    for f in keep:
        (bare / f).parent.mkdir(parents=True, exist_ok=True)
        (bare / f).write_bytes((gold / f).read_bytes())
    (bare / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(GoldenError, match="the golden stores no buffers"):
        compare(bare, tmp_path, mode="exact")


def test_command_exits_2_on_nothing_compared(gold, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    m = load_manifest(gold)
    m["scenes"], m["files"] = {}, {}
    (empty / "manifest.json").write_text(json.dumps(m))
    (tmp_path / "cand").mkdir()
    for args in ([], ["--mode", "exact"]):
        p = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "golden", "compare",
                            str(empty), str(tmp_path / "cand"), *args],
                           capture_output=True, text=True)
        assert p.returncode == 2, (p.stdout, p.stderr)
        assert "nothing to compare" in p.stderr and "Traceback" not in p.stderr, p.stderr
        assert "PASS" not in p.stdout


def test_command_names_pixel_of_a_one_pixel_garbage(gold, tmp_path):
    scene = "render_cube"
    b = _buffers(gold, scene)
    r, c = _covered(b)[5]
    b["depth"][r, c] = np.nan
    _write(tmp_path, scene, b)
    p = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "golden", "compare",
                        str(gold), str(tmp_path), "--scene", scene],
                       capture_output=True, text=True)
    assert p.returncode == 1, (p.stdout, p.stderr)
    out = p.stdout + p.stderr
    assert f"{scene}/depth: domain:nan" in out and f"row {r}, col {c}" in out, out
