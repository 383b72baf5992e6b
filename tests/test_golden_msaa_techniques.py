"""Technique goldens at 4× (issue 44, item 4 and "What it must show"): the per-sample
allowances pass refraster's own frame and fail the planted sampling bugs of
``tests/faults_msaa_techniques.py``; the pass/fail matrix of every technique scene with
``samples > 1`` in the registry is docs/backends.md's "Technique scenes at 4×" section
(``REFRASTER_WRITE_BACKENDS_MATRIX=1`` rewrites it)."""

import shutil

import faults_msaa_techniques as fm
import pytest
from conftest import check_backends_matrix, generate_gold

from refraster.golden import available_scenes, compare
from refraster.golden.io.errors import GoldenError
from refraster.golden.msaa_technique_scenes import _SAMPLED, sampled_scene_names

available_scenes()
#: Every technique scene with more than one sample (the matrix's rows).
ROWS = sampled_scene_names()
#: Each scene's declared sampling.
_SAMPLING = {name: sampling for name, (_, sampling, _) in _SAMPLED.items()}
#: The techniques whose 4× frames the harness renders.
HARNESS = ("edges", "cutaway")
SCENES = [n for n in ROWS if available_scenes()[n].technique in HARNESS]
BEGIN = "<!-- msaa-techniques-matrix:begin (tests/test_golden_msaa_techniques.py) -->"
END = "<!-- msaa-techniques-matrix:end -->"
#: fault → {scene: a buffer its failure must name}
EXPECTED = {
    "resolved_for_per_sample": {"edges4gl_building_per_sample": "edge_map",
                                "cutaway4gl_shells_per_sample": "sample1_"},
    "per_sample_for_resolved": {"edges4gl_building_resolved": "edge_map",
                                "edges4gl_building_resolved_average": "edge_map",
                                "cutaway4gl_shells_resolved": "sample1_",
                                "cutaway4gl_shells_resolved_min": "sample1_",
                                "cutaway4gl_shells_resolved_max": "sample1_"},
    # the resolve faults (fm.RESOLVE_FAULTS) on the resolved scenes
    "other_resolve": {"edges4gl_building_resolved": "edge_map",
                      "edges4gl_building_resolved_average": "edge_map",
                      "cutaway4gl_shells_resolved": "sample",
                      "cutaway4gl_shells_resolved_min": "sample",
                      "cutaway4gl_shells_resolved_max": "sample"},
    "average_depth_resolve": {"cutaway4gl_shells_resolved_min": "sample",
                              "cutaway4gl_shells_resolved_max": "sample"},
    "wrong_sample": {"edges4gl_building_resolved": "edge_map",
                     "cutaway4gl_shells_resolved": "sample"},
}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "msaatech", SCENES)


def _run(gold, fault):
    """The compare of the candidates with ``fault`` (the resolve faults: on the scenes whose
    frame they change only)."""
    scenes = SCENES if fault not in fm.RESOLVE_FAULTS else [
        n for n in SCENES if n in EXPECTED[fault]]
    out = gold / f"cand_{fault}"
    shutil.rmtree(out, ignore_errors=True)
    fm.write_candidate(out, scenes, fault)
    return compare(gold / "golden", out, mode="tolerant", scenes=scenes)


def _gl_cell(gold, name, faults=()):
    """refraster.gl's answer for one scene: its candidate's compare, or its one-line refusal
    or skip."""
    from refraster.golden.candidate import candidate
    try:
        from refraster import gl  # noqa: F401
    except ImportError as exc:
        return f"not run ({exc})"
    out = gold / f"cand_gl_{'_'.join(faults) or 'correct'}_{name}"
    shutil.rmtree(out, ignore_errors=True)
    try:
        r = candidate(gold / "golden", out, backend="gl", scenes=[name], faults=faults)
    except GoldenError as exc:
        return "refused: " + str(exc).split(": ")[-1].split(" (")[0]
    if r["skipped"]:
        return "skipped: " + str(r["skipped"][name]).split(" (")[0]
    c = compare(gold / "golden", out, mode="tolerant", scenes=[name])
    return _cell(c.scenes[0])


def _cell(result):
    if result.status == "pass":
        return "pass"
    failing = sorted({b.name for b in result.buffers if not b.passed})
    samples = sorted({b.split("_", 1)[1] for b in failing if b.startswith("sample")})
    resolved = [b for b in failing if not b.startswith("sample")]
    parts = [f"`{b}` resolved" for b in resolved] + [f"`{c}` per sample" for c in samples]
    return "**FAIL** " + ", ".join(parts)


def test_the_scenes_are_registered_with_their_sample_count():
    assert SCENES == ["edges4gl_building_per_sample", "edges4gl_building_resolved",
                      "cutaway4gl_shells_per_sample", "cutaway4gl_shells_resolved",
                      "edges4gl_building_resolved_average", "cutaway4gl_shells_resolved_min",
                      "cutaway4gl_shells_resolved_max"]
    for name in ROWS:
        assert available_scenes()[name].build().raster["samples"] == \
            available_scenes()[name].samples
    # a technique scene whose name says it is multisampled registers its samples
    for name, e in available_scenes().items():
        if e.technique not in ("render", "msaa") and ("msaa" in name or "4gl" in name):
            assert e.samples > 1, name


def test_the_matrix_and_the_faults(gold):
    columns = ("none", "resolved_for_per_sample", "per_sample_for_resolved",
               *fm.RESOLVE_FAULTS)
    results = {}
    for fault in columns:
        cmp = _run(gold, fault)
        results[fault] = {s.name: s for s in cmp.scenes}
        if fault == "none":
            assert cmp.exit_code == 0, "\n".join(cmp.failures())
            continue
        assert cmp.exit_code == 1
        for scene, buffer in EXPECTED[fault].items():
            assert any(line.startswith(f"{scene}/{buffer}") for line in cmp.failures()), \
                (fault, scene, cmp.failures()[:5])
    gl_faults = ("msaa_edges_resolved_for_per_sample", "msaa_gbuffer_pixel_rate")
    head = ("| scene | technique | sampling | refraster | `resolved_for_per_sample` | "
            "`per_sample_for_resolved` | `other_resolve` | `average_depth_resolve` | "
            "`wrong_sample` | refraster.gl | "
            + " | ".join(f"refraster.gl `{f}`" for f in gl_faults) + " |")
    lines = [head, "|" + "---|" * (10 + len(gl_faults))]
    for name in ROWS:
        entry = available_scenes()[name]
        if name not in SCENES:
            lines.append(f"| {name} | {entry.technique} | | no harness here | | | | | | "
                         f"{_gl_cell(gold, name)} |")
            continue
        declared = _SAMPLING[name]
        sampling = ("per sample" if declared["mode"] == "per_sample"
                    else f"resolved, `{declared['resolve']}`")
        cells = [_cell(results[c][name]) if name in results[c] else "—" for c in columns]
        gl_cells = [_gl_cell(gold, name)] + [_gl_cell(gold, name, (f,)) for f in gl_faults]
        lines.append(f"| {name} | {entry.technique} | {sampling} | " + " | ".join(cells)
                     + " | " + " | ".join(gl_cells) + " |")
    # refraster.gl passes every scene on its multisample path; the edge operators reading
    # sample 0 fail the per-sample edge map, the G-buffer at pixel rate fails every scene
    if "refused" not in lines[2] and "not run" not in lines[2]:
        for line in lines[2:]:
            cells = line.split(" | ")
            if cells[9].startswith("skipped"):     # a resolve mode refraster.gl does not draw
                continue
            assert cells[9] == "pass" and cells[11].startswith("**FAIL**"), line
            assert cells[10].startswith("**FAIL**") == line.startswith(
                "| edges4gl_building_per_sample"), line
    check_backends_matrix(BEGIN, END, "\n".join(lines), "4x technique matrix")
