"""refraster.gl at 4 samples on the multisampled clip-surface goldens (issue 44, item 3): the
building cut by a Perlin clip surface with caps, at llvmpipe's GL positions, drawn by
``refraster.gl.clipsurface.draw_samples`` into multisample targets — at sample rate with
``GL_SAMPLE_SHADING`` (``glMinSampleShading(1.0)``), at pixel rate without — passes the
pixel-rate golden; the sample-rate golden is an open anomaly (xfail, below); a golden of
Vulkan's standard positions is skipped with one line. The pass/fail matrix of the four scenes
(refraster, the other rate's frame, refraster.gl) is in docs/backends.md ("Technique scenes at
4×"), checked against this run."""

from __future__ import annotations

import pytest

from conftest import check_backends_matrix, generate_gold, gl_backend_or_skip
from refraster.golden.compare.run import compare

GL = ["msaa4gl_clipsurface_sample", "msaa4gl_clipsurface_pixel"]
OTHER = ["msaa4_clipsurface_sample"]
ALL = ["msaa4_clipsurface_sample", "msaa4_clipsurface_pixel"] + GL
BEGIN = "<!-- msaa-clip-matrix:begin (tests/test_gl_golden_msaa_clipsurface.py) -->"
END = "<!-- msaa-clip-matrix:end -->"


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "gl_msaa_clip", ALL)


def test_gl_passes_the_4x_pixel_rate_clip_surface_golden(gold):
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    out = gold / "cand_gl"
    r = candidate(gold / "golden", out, backend="gl", scenes=GL + OTHER)
    assert sorted(r["rendered"]) == sorted(GL), r
    assert r["skipped"]["msaa4_clipsurface_sample"].startswith(
        "clipsurface: this OpenGL's 4x sample positions are (6, 14) (14, 10) (2, 6) (10, 2), "
        "the scene declares (6, 2) (14, 6) (2, 10) (10, 14)")
    res = compare(gold / "golden", out, mode="tolerant", scenes=["msaa4gl_clipsurface_pixel"])
    assert res.exit_code == 0, res.failures()[:5]


@pytest.mark.xfail(strict=True, reason="open (2026-12-04): llvmpipe's sample-rate frame of the "
                   "clip program differs from refraster's on 68 of 27,648 samples outside the "
                   "allowance, each at a cap's rim (the parity test); not yet explained")
def test_gl_passes_the_4x_sample_rate_clip_surface_golden(gold):
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    out = gold / "cand_gl_sample"
    candidate(gold / "golden", out, backend="gl", scenes=["msaa4gl_clipsurface_sample"])
    res = compare(gold / "golden", out, mode="tolerant", scenes=["msaa4gl_clipsurface_sample"])
    assert res.exit_code == 0, res.failures()[:5]


def _cell(result):
    if result.status == "pass":
        return "pass"
    failing = sorted({b.name for b in result.buffers if not b.passed})
    samples = sorted({b.split("_", 1)[1] for b in failing if b.startswith("sample")})
    whole = [f"`{b}`" for b in failing if not b.startswith("sample")]
    return "**FAIL** " + ", ".join(whole + [f"`{c}` per sample" for c in samples])


def test_the_clip_surface_matrix_at_4x(gold):
    """refraster's own frame passes each scene; the frame of the other rate (the discard and
    parity at pixel rate where sample rate is declared, and the reverse) fails it; refraster.gl
    draws the scenes of its own positions (skipping the others in one line)."""
    from refraster.golden.candidate import candidate
    from test_golden_msaa_clipsurface import _candidate
    gl_backend_or_skip().release()
    other = {"sample": "center", "center": "sample"}
    rows = ["| scene | rate | refraster | the other rate's frame | refraster.gl |",
            "|---|---|---|---|---|"]
    own = compare(gold / "golden", _candidate(gold, "m_own", ALL), mode="tolerant")
    by_name = {r.name: r for r in own.scenes}
    gl_out = gold / "cand_gl_matrix"
    made = candidate(gold / "golden", gl_out, backend="gl", scenes=ALL)
    gl = {r.name: r for r in compare(gold / "golden", gl_out, mode="tolerant",
                                     scenes=sorted(made["rendered"])).scenes}
    for name in ALL:
        rate = "sample" if name.endswith("_sample") else "center"
        flip = compare(gold / "golden", _candidate(gold, f"m_{name}", [name],
                                                   interpolation=other[rate]),
                       mode="tolerant", scenes=[name]).scenes[0]
        gl_cell = _cell(gl[name]) if name in gl else "skipped: another sample pattern"
        rows.append(f"| {name} | {'sample' if rate == 'sample' else 'pixel'} | "
                    f"{_cell(by_name[name])} | {_cell(flip)} | {gl_cell} |")
        assert by_name[name].status == "pass"
        assert flip.status != "pass", name
    check_backends_matrix(BEGIN, END, "\n".join(rows), "multisampled clip-surface matrix")
