"""The compare summary a team reads (issue 42, item 4): a passing line shows no word or number
that reads as failure; a failing candidate's lines come ordered by cause, the ids first.

Candidates: the golden itself (identical), refraster's own frame at 4 sub-pixel bits (differs,
admitted by the allowance), and the golden with ``prim_id`` off by one (the ids name faces that
cannot win; every value buffer then fails where the ids do).
"""

import re

import numpy as np
import pytest

from refraster import golden
from refraster.golden.compare.run import compare
from refraster.golden.scenes import raster_state, render_draws

SCENE = "render_cube"

#: Words and counts that read as failure on a line of the summary.
ALARM = re.compile(r"FAIL|\bfail|\bover\b|over=|unforgiven|outside|error|wrong|\bbad\b")


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("summary") / "g"
    golden.generate(out, [SCENE], candidate_subpixel_bits=4)    # four_bit's candidate
    return out


def _buffers(gold):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def _candidate(root, buffers):
    (root / SCENE).mkdir(parents=True, exist_ok=True)
    np.savez(root / SCENE / "buffers.npz", **buffers)
    return root


def _buffer_lines(summary):
    return [ln for ln in summary.splitlines() if ln.startswith("  ") and "skipped" not in ln]


def passing_alarms(summary):
    """The buffer lines marked ok that still show a word or count reading as failure."""
    return [ln for ln in _buffer_lines(summary) if ln.split()[1] == "ok" and ALARM.search(ln)]


@pytest.fixture(scope="module")
def four_bit(gold, tmp_path_factory):
    scene = golden.available_scenes()[SCENE].build()
    fb = render_draws(scene.draws, scene.camera, {**raster_state(scene.raster),
                                                   "subpixel_bits": 4})
    return _candidate(tmp_path_factory.mktemp("four_bit"), fb.arrays())


@pytest.mark.parametrize("mode", ["tolerant", "exact"])
def test_identical_candidate_reads_as_pass(gold, mode):
    result = compare(gold, gold, mode=mode) if mode == "tolerant" else compare(
        gold, gold, profile="exact")
    text = result.summary()
    assert result.exit_code == 0 and text.endswith("result: PASS")
    assert passing_alarms(text) == [], text
    assert all("differing" in ln for ln in _buffer_lines(text))


def test_admitted_differences_read_as_admitted(gold, four_bit):
    result = compare(gold, four_bit, mode="tolerant")
    text = result.summary()
    assert result.exit_code == 0, "\n".join(result.failures())
    assert any("(all admitted by the allowance)" in ln for ln in _buffer_lines(text)), text
    assert passing_alarms(text) == [], text
    # FLIP is computed in tolerant mode too (the report said "not installed" while it was)
    color = next(b for s in result.scenes for b in s.buffers if b.name == "color")
    assert color.metrics["flip_mean"] is not None and color.images["flip"] is not None
    assert re.search(r"^  color .* flip=0\.\d{4}$", text, re.M), text


def test_old_summary_columns_would_be_caught():
    """Both directions of the alarm check: the old columns on a passing line are flagged."""
    old = ("  depth          ok   max_abs=0.00012 rmse=1e-05 psnr=99.0 over=3.84e-01 "
           "unforgiven=0.00e+00")
    assert passing_alarms("x\n" + old) == [old]
    assert passing_alarms("x\n  depth          ok   max_abs=0 rmse=0 psnr=inf "
                          "differing=0/19200") == []


def test_failing_summary_and_failures_ordered_by_cause(gold, tmp_path):
    b = _buffers(gold)
    pid = b["prim_id"]
    b["prim_id"] = np.where(pid >= 0, (pid + 1) % (pid.max() + 1), pid).astype(pid.dtype)
    result = compare(gold, _candidate(tmp_path, b), mode="tolerant")
    assert result.exit_code == 1
    text = result.summary()
    assert re.search(r"^  prim_id\s+FAIL .* outside=[1-9]", text, re.M), text
    lines = result.failures()
    names = [ln.split(":")[0].split("/")[1] for ln in lines]
    assert names[0] == "prim_id", lines
    assert "names a face that cannot win here" in lines[0]
    values = [ln for ln in lines if ln.split(":")[0].split("/")[1] not in ("prim_id",
                                                                             "object_id")]
    assert values, lines
    # a value buffer failing where the ids fail says so; one failing only where the ids are
    # admitted (the named face may win there, its values do not fit it) carries no mark
    for ln in values:
        buf = ln.split(":")[0].split("/")[1]
        b = next(x for s in result.scenes for x in s.buffers if x.name == buf)
        ids = next(x for s in result.scenes for x in s.buffers if x.name == "prim_id")
        bad = b.images["over"] & ~b.images["forgiven"]
        id_bad = ids.images["over"] & ~ids.images["forgiven"]
        k = int((bad & id_bad).sum())
        assert ("[follows from the ids" in ln) == (k == bad.sum() and k > 0), ln
        assert ("failing pixels are where the ids fail]" in ln) == (0 < k < bad.sum()), ln


def _result(name, kind, bad, n_pixels=16):
    from refraster.golden.compare.run import BufferResult
    over = np.asarray(bad, bool)
    check = {"metric": "face" if kind == "id" else "interval", "value": int(over.sum()),
             "limit": 0, "op": "<=", "ok": not over.any(), "detail": "…"}
    metrics = {"max_abs": 1.0, "rmse": 0.1, "psnr": 20.0, "threshold": 0.0,
               "pixels": n_pixels, "n_over": int(over.sum()), "n_unforgiven": int(over.sum()),
               "fraction_over": over.mean(), "fraction_unforgiven": over.mean(), "worst": None}
    return BufferResult(name, kind, "buffers.npz", {}, metrics, [check], None, None,
                        {"over": over, "forgiven": np.zeros_like(over), "error": over * 1.0})


def test_value_failures_marked_by_where_the_ids_fail():
    from refraster.golden.compare.run import Comparison, SceneResult
    ids = np.zeros((4, 4), bool)
    ids[0, :] = True
    inside = ids.copy()
    inside[0, 3] = False                       # every failing pixel where the ids fail
    half = np.zeros((4, 4), bool)
    half[0, 0] = half[3, 3] = True             # one of two
    apart = np.zeros((4, 4), bool)
    apart[2, 2] = True                         # none
    scene = SceneResult("s", "fail", [_result("depth", "unorm", inside),
                                      _result("normal", "snorm", half),
                                      _result("color", "color", apart),
                                      _result("prim_id", "id", ids)])
    lines = Comparison(".", ".", "exact", [scene], mode="tolerant").failures()
    assert [ln.split(":")[0] for ln in lines] == ["s/prim_id", "s/depth", "s/normal", "s/color"]
    assert "cannot win here" in lines[0]
    assert "[follows from the ids" in lines[1]
    assert "[1 of its 2 failing pixels are where the ids fail]" in lines[2]
    assert "[" not in lines[3].split(")")[-1]
