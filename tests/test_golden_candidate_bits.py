"""The candidate's declared sub-pixel precision (issue 42 item 2): ``golden generate
--candidate-subpixel-bits N`` (4 to 8, default 8), recorded in the manifest and used by the
allowances (docs/tolerance.md, "How each ε is derived").

Both directions: a candidate of 4 sub-pixel bits passes a golden declared for 4 and fails one
declared for 8, at pixels inside the 4-bit may-band and outside the narrower 8-bit one.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from refraster import golden
from refraster.conformance import MAY, MUST, MUST_NOT, edge_epsilon
from refraster.golden.allowances.halos import halo_variants, xy_shift
from refraster.golden.allowances.precision import (LEGACY_CANDIDATE_BITS, as_candidate_bits,
                                                   manifest_candidate_bits)
from refraster.golden.compare.run import compare
from refraster.golden.scenes import raster_state, render_draws

SCENE = "render_cube"


@pytest.fixture(scope="module")
def golds(tmp_path_factory):
    root = tmp_path_factory.mktemp("bits")
    out = {}
    for bits in (4, 8):
        out[bits] = root / f"g{bits}"
        golden.generate(out[bits], [SCENE], candidate_subpixel_bits=bits)
    out["default"] = root / "gdefault"
    golden.generate(out["default"], [SCENE])
    return out


def _tolerance(gold):
    with np.load(gold / SCENE / "tolerance.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


@pytest.fixture(scope="module")
def four_bit(tmp_path_factory):
    """refraster itself with 4 sub-pixel bits instead of 8."""
    scene = golden.available_scenes()[SCENE].build()
    fb = render_draws(scene.draws, scene.camera, {**raster_state(scene.raster),
                                                   "subpixel_bits": 4})
    root = tmp_path_factory.mktemp("four_bit")
    (root / SCENE).mkdir()
    np.savez(root / SCENE / "buffers.npz", **fb.arrays())
    return root


def test_manifest_records_the_declared_bits(golds):
    for key, bits in ((4, 4), (8, 8), ("default", 8)):
        m = json.loads((golds[key] / "manifest.json").read_text())
        assert m["candidate"] == {"subpixel_bits": bits}
        assert manifest_candidate_bits(m) == bits
        info = m["scenes"][SCENE]["allowances"]
        assert info["min_subpixel_bits"] == bits
        assert info["eps"] == pytest.approx(edge_epsilon(160, 120, min_bits=bits))
    # the default is the 8-bit declaration, byte for byte
    for name in ("tolerance.npz", "buffers.npz"):
        assert (golds["default"] / SCENE / name).read_bytes() == \
            (golds[8] / SCENE / name).read_bytes()
    # the reference images do not depend on the declaration; the allowances do
    assert (golds[4] / SCENE / "buffers.npz").read_bytes() == \
        (golds[8] / SCENE / "buffers.npz").read_bytes()
    assert (golds[4] / SCENE / "tolerance.npz").read_bytes() != \
        (golds[8] / SCENE / "tolerance.npz").read_bytes()


def test_the_8_bit_band_lies_inside_the_4_bit_band(golds):
    t4, t8 = _tolerance(golds[4]), _tolerance(golds[8])
    may4, may8 = t4["coverage"] == MAY, t8["coverage"] == MAY
    assert not (may8 & ~may4).any() and may8.sum() < may4.sum()
    both = (t4["coverage"] == MUST) & (t8["coverage"] == MUST) & ~t4["id_may"] & ~t8["id_may"]
    assert (t8["depth_lo"][both] >= t4["depth_lo"][both]).all()
    assert (t8["depth_hi"][both] <= t4["depth_hi"][both]).all()


def test_a_4_bit_candidate_passes_4_and_fails_8_outside_the_band(golds, four_bit):
    ok = compare(golds[4], four_bit, mode="tolerant", scenes=[SCENE])
    assert ok.exit_code == 0, "\n".join(ok.failures())
    bad = compare(golds[8], four_bit, mode="tolerant", scenes=[SCENE])
    assert bad.exit_code == 1
    assert any(f.startswith(f"{SCENE}/prim_id: coverage") for f in bad.failures())
    # the failing pixels: the 4-bit candidate's coverage differs from the golden's where the
    # 4-bit band allows it (MAY) and the 8-bit one does not
    with np.load(four_bit / SCENE / "buffers.npz") as z:
        cand = z["prim_id"] >= 0
    with np.load(golds[8] / SCENE / "buffers.npz") as z:
        ref = z["prim_id"] >= 0
    t4, t8 = _tolerance(golds[4]), _tolerance(golds[8])
    diff = cand != ref
    outside8 = diff & (t8["coverage"] != MAY)
    assert outside8.any()
    assert (t4["coverage"][outside8] == MAY).all()
    assert set(np.unique(t8["coverage"][outside8]).tolist()) <= {MUST, MUST_NOT}


def test_a_golden_without_the_field_reads_as_4_bits(golds, four_bit, tmp_path):
    import shutil
    g = tmp_path / "old"
    shutil.copytree(golds[4], g)
    m = json.loads((g / "manifest.json").read_text())
    del m["candidate"]
    (g / "manifest.json").write_text(json.dumps(m))
    assert manifest_candidate_bits(m) == LEGACY_CANDIDATE_BITS == 4
    r = compare(g, four_bit, mode="tolerant", scenes=[SCENE], report=tmp_path / "rep")
    assert r.exit_code == 0, "\n".join(r.failures())
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "allowances for a candidate of 4 sub-pixel bits" in html


def test_update_refuses_to_mix_declarations(golds, tmp_path):
    import shutil
    g = tmp_path / "g"
    shutil.copytree(golds[4], g)
    with pytest.raises(ValueError, match="candidate_subpixel_bits is 8 but the golden .* "
                                         "was generated for 4"):
        golden.generate(g, ["render_torus_ortho"], update=True, sizes=["16x12"])


@pytest.mark.parametrize("value, exc", [(3, ValueError), (9, ValueError), (True, TypeError),
                                        (8.0, TypeError), ("8", TypeError)])
def test_bad_declarations_are_refused_in_one_line(value, exc, tmp_path):
    with pytest.raises(exc, match="candidate_subpixel_bits must be") as info:
        golden.generate(tmp_path / "g", [SCENE], candidate_subpixel_bits=value)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "g").exists()
    assert as_candidate_bits(np.int64(5)) == 5


@pytest.mark.parametrize("text", ["3", "9", "x", "4.5"])
def test_command_refuses_bad_bits_in_one_line(text, tmp_path):
    r = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "generate", "--out",
                        str(tmp_path / "g"), "--scene", SCENE, "--candidate-subpixel-bits",
                        text], capture_output=True, text=True)
    assert r.returncode == 2
    line = [ln for ln in r.stderr.splitlines() if "--candidate-subpixel-bits" in ln
            and "must be an integer from 4 to 8" in ln]
    assert len(line) == 1, r.stderr
    assert not (tmp_path / "g").exists()


def test_halo_shifts_follow_the_declaration():
    p = {"screen_bounds": [[0.0, 0.0, -1.0], [1.0, 1.0, 1.0]]}
    assert xy_shift(4) == 1 / 16 and xy_shift(8) == 1 / 256
    v4, v8 = halo_variants(p, 4), halo_variants(p, 8)
    assert {"bits": 4} in v4 and not any("bits" in v for v in v8)
    assert max(abs(v["dxy"][0]) for v in v8 if "dxy" in v) == 1 / 256
    assert max(abs(v["dxy"][0]) for v in v4 if "dxy" in v) == 1 / 16
