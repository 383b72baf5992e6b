"""A warm gallery's work balanced over its workers (issue 27): the halo section in two parts,
the work items handed out longest first, the parts' pictures those of the whole section."""

import itertools
import json

import pytest

from refraster.gallery import (PARTS, SECTIONS, WARM_SECONDS, merge_parts, split_item, warm_plan,
                               work_items)

ITEMS = work_items([name for name, _ in SECTIONS])


def _loads(plan):
    return [sum(WARM_SECONDS.get(i, 1.0) for i in p) for p in plan]


def _check(plan, items, jobs):
    """Each item in exactly one list, at most ``jobs`` lists; the longest list (the wall time)
    within 10 % of the best split, found by trying every assignment."""
    assert len(plan) <= jobs
    assert sorted(i for p in plan for i in p) == sorted(items)
    best = min(max(sum(WARM_SECONDS.get(i, 1.0) for i, w in zip(items, ws) if w == k)
                   for k in range(jobs))
               for ws in itertools.product(range(jobs), repeat=len(items)))
    assert max(_loads(plan)) <= 1.1 * best, (plan, best)


def test_the_halo_section_is_two_work_items():
    assert PARTS == {"halos4d": 2}
    assert ITEMS.count("halos4d#0") == ITEMS.count("halos4d#1") == 1 and "halos4d" not in ITEMS
    assert split_item("halos4d#1") == ("halos4d", 1) and split_item("edges") == ("edges", None)


@pytest.mark.parametrize("jobs", [1, 2, 3])
def test_warm_plan_balances_the_workers(jobs):
    plan = warm_plan(ITEMS, jobs)
    _check(plan, ITEMS, jobs)
    if jobs == 2:   # the two halves of the longest section go to different workers
        assert sorted(p[0] for p in plan) == ["halos4d#0", "halos4d#1"]


def test_the_check_catches_a_bad_plan():
    """Planted faults: the old section order (the halo section after the others in one
    worker), an item left out, an item given twice — each fails the check."""
    old = [["ldi", "clipsurface", "halos4d#0", "halos4d#1"], ["edges", "cutaway", "basic"]]
    for bad in (old, warm_plan(ITEMS, 2)[:1] + [warm_plan(ITEMS, 2)[1][1:]],
                [warm_plan(ITEMS, 2)[0] + ["edges"], warm_plan(ITEMS, 2)[1]]):
        with pytest.raises(AssertionError):
            _check(bad, ITEMS, 2)


def test_merge_parts_joins_in_part_order_and_names_a_missing_part():
    results = {"halos4d#1": (["c", "d"], None), "edges": (["e"], None),
               "halos4d#0": (["a", "b"], None)}
    assert merge_parts(results) == {"halos4d": (["a", "b", "c", "d"], None),
                                    "edges": (["e"], None)}
    failed = merge_parts({"halos4d#1": (["c"], "ValueError: x")})
    assert failed["halos4d"][1] == "work item halos4d#0 did not answer"
    assert merge_parts({"halos4d#0": ([], None), "halos4d#1": ([], "boom")})["halos4d"] == \
        ([], "boom")


def test_the_parts_render_the_whole_section(tmp_path, capsys):
    """The two work items, run by the worker in the wrong order, give the whole section's
    pictures (the same bytes) and items in its order."""
    from refraster.gallery import halos4d
    from refraster.gallery import worker
    whole = halos4d.render(tmp_path / "whole", quick=True)
    assert worker.main([str(tmp_path / "parts"), "--quick", "halos4d#1", "halos4d#0"]) == 0
    out = {r["section"]: ([tuple(i) for i in r["items"]], r["error"])
           for r in map(json.loads, capsys.readouterr().out.splitlines())}
    assert out["halos4d#0"][0] and out["halos4d#1"][0]
    items, error = merge_parts(out)["halos4d"]
    assert error is None
    assert items == [(i.section, i.filename, i.caption) for i in whole]
    for i in whole:
        assert (tmp_path / "parts" / i.filename).read_bytes() == \
            (tmp_path / "whole" / i.filename).read_bytes(), i.filename
    with pytest.raises(ValueError, match="part must be 0 or 1"):
        halos4d.render(tmp_path, quick=True, part=2)
