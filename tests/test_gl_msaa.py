"""refraster.gl at 4 samples (issue 43, item 5): the multisampled plain scenes at llvmpipe's GL
positions drawn into a GL multisample framebuffer pass their goldens; each planted MSAA fault
(``refraster.gl.MSAA_FAULTS``) fails with the report naming the buffer; a golden whose
declared pattern is not the context's is skipped with one line saying so. The matrix is in
docs/backends.md ("Multisampling")."""

from __future__ import annotations

import json

import pytest

from conftest import check_backends_matrix, fault_matrix, generate_gold, gl_backend_or_skip
from test_golden_msaa import harness_table

GL_SCENES = ["msaa4gl_cube", "msaa4gl_icosphere_smooth", "msaa4gl_multi_draw"]
OTHER = ["msaa4_cube", "msaa8_cube"]
BEGIN = "<!-- gl-msaa-matrix:begin (tests/test_gl_msaa.py) -->"
END = "<!-- gl-msaa-matrix:end -->"
#: The buffer each planted fault's failure must name, on every scene.
NAMED = {"msaa_pattern_mirrored": "sample0_prim_id", "msaa_depth_per_pixel": "sample0_depth",
         "msaa_srgb_resolve": "color", "msaa_centre_coverage": "sample0_prim_id"}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "gl_msaa", GL_SCENES + OTHER)


def test_the_context_states_llvmpipes_pattern():
    with gl_backend_or_skip() as gl:
        pattern = gl.sample_pattern(4)
    assert pattern == {"samples": 4, "positions": [[6, 14], [14, 10], [2, 6], [10, 2]]}


def test_goldens_of_another_pattern_are_skipped_in_one_line(gold):
    from refraster.golden.candidate import candidate
    gl_backend_or_skip().release()
    out = gold / "cand_other"
    r = candidate(gold / "golden", out, backend="gl", scenes=OTHER)
    assert r["rendered"] == [] and sorted(r["skipped"]) == OTHER
    assert r["skipped"]["msaa4_cube"] == (
        "msaa: this OpenGL's 4x sample positions are (6, 14) (14, 10) (2, 6) (10, 2), the "
        "scene declares (6, 2) (14, 6) (2, 10) (10, 14) (1/16 pixel, y down)")
    assert "8" in r["skipped"]["msaa8_cube"] and "\n" not in r["skipped"]["msaa8_cube"]


def test_gl_passes_the_4x_goldens_and_every_planted_fault_fails(gold):
    from refraster.gl import MSAA_FAULTS
    gl_backend_or_skip().release()
    columns = ["correct", *MSAA_FAULTS]
    expected = {f: {s: NAMED[f] for s in GL_SCENES} for f in MSAA_FAULTS}
    results = fault_matrix(gold, columns, GL_SCENES, expected, only_scenes=True)
    stated = json.loads((gold / "cand_correct" / "msaa4gl_cube" / "sample_pattern.json")
                        .read_text())
    assert stated["positions"] == [[6, 14], [14, 10], [2, 6], [10, 2]]
    check_backends_matrix(BEGIN, END, harness_table(results, GL_SCENES), "GL multisample matrix")
