"""The 4D-halo allowance ("Goldens with teeth (2)", item 5; refraster/golden/allowances/halos.py)
in both directions.

Specificity: conformant halo renders that the allowance was *not* built from pass the golden
(tolerant): the reference engine, and combinations of the shifts (4 sub-pixel bits with float32
vertices and a diagonal sample shift, a slice plane and both t thresholds moved at once, …).
Sensitivity: one pixel's halo class flipped, one pixel's opacity moved, a renderer whose
thresholds are off by a real amount (w_s, δt of Eq. 3, the halo's δd) each fail ``compare``,
naming the pixel.
"""

import subprocess
import sys

import numpy as np
import pytest

from refraster import golden
from refraster.golden.allowances import halos as H
from refraster.golden.compare.run import compare
from refraster.golden.generate import generate

SCENE = "halos4d_figure1"


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("halo") / "g"
    generate(out, [SCENE], candidate_subpixel_bits=4)     # the "4bit" variants plant them
    return out


@pytest.fixture(scope="module")
def scene():
    return golden.available_scenes()[SCENE].build()


def _buffers(gold):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def _write(root, buffers):
    (root / SCENE).mkdir(parents=True)
    np.savez(root / SCENE / "buffers.npz", **buffers)
    return root


def _candidate(scene, **kw):
    rgb, a, vol = H.render_variant(H._surface(scene.maps), scene.parameters, **kw)
    return {"color": rgb.astype(np.float32), "alpha": a.astype(np.float32),
            "halo_class": H.column_class(vol)}


#: Conformant variants not among the allowance's own shifts (combinations, other amounts).
VARIANTS = {
    "4bit_f32_diagonal": dict(bits=4, f32=True, dxy=(1 / 32, -1 / 32)),
    "4bit_f32_planes": dict(bits=4, f32=True, dz=-1e-7),
    "thresholds_together": dict(dsw=5e-7, ddt=-5e-7, eps_scale=1.5),
    "f32_thresholds_shift": dict(f32=True, dsw=-5e-7, ddt=5e-7, dxy=(-1 / 40, 1 / 40)),
    "4bit_top_left_like": dict(bits=4, dxy=(1 / 64, 1 / 64)),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_conformant_halo_variants_pass(gold, scene, tmp_path, variant):
    cand = _candidate(scene, **VARIANTS[variant])
    result = compare(gold, _write(tmp_path, cand), mode="tolerant", scenes=[SCENE])
    assert result.exit_code == 0, "\n".join(result.failures()[:10])


def test_a_conformant_variant_differs_from_the_golden(gold, scene, tmp_path):
    """The 4-bit variant is not the golden's bits (exact fails): its pass is the allowance's."""
    cand = _candidate(scene, **VARIANTS["4bit_f32_diagonal"])
    assert compare(gold, _write(tmp_path, cand), mode="exact", scenes=[SCENE]).exit_code == 1


def test_reference_engine_passes(gold, scene, tmp_path):
    from refraster.golden.technique_scenes import halo_options
    from refraster.halos4d import render_halos
    out = render_halos(H._surface(scene.maps), **halo_options(scene.parameters), volume=True,
                       engine="reference")
    cand = {"color": out.image, "alpha": out.alpha, "halo_class": H.column_class(out.volume)}
    result = compare(gold, _write(tmp_path, cand), mode="tolerant", scenes=[SCENE])
    assert result.exit_code == 0, "\n".join(result.failures()[:10])


def _run(gold, cand):
    p = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "golden", "compare",
                        str(gold), str(cand), "--scene", SCENE], capture_output=True, text=True)
    return p.returncode, p.stdout + p.stderr


def test_one_pixel_halo_class_flipped_fails_naming_the_pixel(gold, tmp_path):
    """A carved column shown as plain surface (the halo voxel's class flipped) at one pixel."""
    b = _buffers(gold)
    with np.load(gold / SCENE / "tolerance.npz", allow_pickle=False) as z:
        fixed = z["halo_class_lo"] == z["halo_class_hi"]
    pix = np.argwhere((b["halo_class"] == 2) & fixed)
    r, c = pix[len(pix) // 2]
    b["halo_class"][r, c] = 1
    code, out = _run(gold, _write(tmp_path, b))
    assert code == 1 and "FAIL" in out, out
    line = [x for x in out.splitlines() if f"{SCENE}/halo_class: bounds" in x][0]
    assert f"[[{r}, {c}]]" in line, line


def test_one_pixel_alpha_moved_fails_naming_the_pixel(gold, tmp_path):
    b = _buffers(gold)
    pix = np.argwhere(b["alpha"] > 0.5)
    r, c = pix[len(pix) // 3]
    b["alpha"][r, c] -= np.float32(0.1)
    code, out = _run(gold, _write(tmp_path, b))
    line = [x for x in out.splitlines() if f"{SCENE}/alpha: bounds" in x][0]
    assert code == 1 and f"[[{r}, {c}]]" in line, out


@pytest.mark.parametrize("wrong", [dict(dsw=-0.05), dict(ddt=0.05), dict(eps_scale=1e4),
                                   dict(dxy=(0.25, 0.0))])
def test_wrong_thresholds_fail(gold, scene, tmp_path, wrong):
    """A renderer whose w_s or δt is off by 0.05, whose occlusion ε is 10⁴ times the rule's,
    or whose sample positions are a quarter pixel off, fails on the class. (w_s or δt off by
    0.02 passes: in this scene the core is thinner than a slice and the slice opacity ~0.9, so
    no voxel centre lies in the 0.02 band of |2t − 1| — measured.)"""
    cand = _candidate(scene, **wrong)
    result = compare(gold, _write(tmp_path, cand), mode="tolerant", scenes=[SCENE])
    failing = {f.split(":")[0] for f in result.failures()}
    assert result.exit_code == 1 and f"{SCENE}/halo_class" in failing, result.failures()
