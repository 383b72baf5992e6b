"""refraster.gl at 4 samples on the multisampled clip-surface goldens (issue 44, item 3): the
building cut by a Perlin clip surface with caps, at llvmpipe's GL positions, drawn by
``refraster.gl.clipsurface.draw_samples`` into multisample targets — at sample rate with
``GL_SAMPLE_SHADING`` (``glMinSampleShading(1.0)``), at pixel rate without — passes the
pixel-rate golden; the sample-rate golden is an open anomaly (xfail, below); a golden of
Vulkan's standard positions is skipped with one line."""

from __future__ import annotations

import pytest

from conftest import generate_gold, gl_backend_or_skip
from refraster.golden.compare.run import compare

GL = ["msaa4gl_clipsurface_sample", "msaa4gl_clipsurface_pixel"]
OTHER = ["msaa4_clipsurface_sample"]


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "gl_msaa_clip", GL + OTHER)


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


@pytest.mark.xfail(strict=True, reason="open (2026-12-04): llvmpipe's frame of the clip program "
                   "is the same with and without GL_SAMPLE_SHADING, and differs from "
                   "refraster's sample-rate frame on 77 of 27,648 samples, every one a cap "
                   "sample (the parity test); not yet explained")
def test_gl_passes_the_4x_sample_rate_clip_surface_golden(gold):
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    out = gold / "cand_gl_sample"
    candidate(gold / "golden", out, backend="gl", scenes=["msaa4gl_clipsurface_sample"])
    res = compare(gold / "golden", out, mode="tolerant", scenes=["msaa4gl_clipsurface_sample"])
    assert res.exit_code == 0, res.failures()[:5]
