"""The documents under ``docs/`` are references of now, not diaries (issue 38, item 5).

* ``docs/performance.md`` stays under 400 lines: one current table per benchmark and the
  reasoning that still applies; how the figures got there belongs in ``docs/changelog.md``.
* No document but the changelog narrates passes or sessions ("the fifth pass", "third
  session").
* Every table of ``docs/performance.md`` is dated: a date (YYYY-MM-DD) in the heading of its
  section, in the prose between that heading (or the previous table) and the table, in the
  table's header row, or in every one of its rows.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parent.parent / "docs"
PERFORMANCE = DOCS / "performance.md"
CHANGELOG = DOCS / "changelog.md"
MAX_PERFORMANCE_LINES = 400

DIARY = re.compile(
    r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth)"
    r" (pass|passes|session|sessions)\b",
    re.IGNORECASE,
)
DATE = re.compile(r"\b\d{4}-\d{2}-\d{2}\b")


def _reference_docs():
    return sorted(p for p in DOCS.rglob("*.md") if p.resolve() != CHANGELOG.resolve())


def diary_phrases(text):
    """``[(line number, phrase)]`` of every diary phrase in ``text``."""
    return [(n, m.group(0)) for n, line in enumerate(text.splitlines(), 1)
            for m in DIARY.finditer(line)]


def _tables(lines):
    """``[(start, end)]`` line index ranges of the Markdown tables outside code fences."""
    tables, fenced, i = [], False, 0
    while i < len(lines):
        if lines[i].lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced and lines[i].lstrip().startswith("|"):
            start = i
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                i += 1
            tables.append((start, i))
            continue
        i += 1
    return tables


def undated_tables(text):
    """Line numbers (1-based) of the tables of ``text`` that no date covers.

    A table is dated by a date in the heading of its section, in the lines between that heading
    (or the end of the previous table of the section, whichever is nearer) and the table, in its
    header row, or in every one of its body rows (a date column)."""
    lines = text.splitlines()
    undated, previous_end = [], 0
    for start, end in _tables(lines):
        heading = next((lines[j] for j in range(start - 1, -1, -1)
                        if lines[j].startswith("#")), "")
        heading_at = next((j for j in range(start - 1, -1, -1) if lines[j].startswith("#")), -1)
        prose = lines[max(previous_end, heading_at + 1):start]
        body = lines[start + 2:end]
        dated = (DATE.search(heading) or any(DATE.search(line) for line in prose)
                 or DATE.search(lines[start])
                 or (body and all(DATE.search(row) for row in body)))
        if not dated:
            undated.append(start + 1)
        previous_end = end
    return undated


def test_performance_md_is_under_400_lines():
    n = len(PERFORMANCE.read_text(encoding="utf-8").splitlines())
    assert n < MAX_PERFORMANCE_LINES, (
        f"docs/performance.md has {n} lines (at most {MAX_PERFORMANCE_LINES - 1}): keep one "
        f"current table per benchmark and move history to docs/changelog.md")


@pytest.mark.parametrize("doc", _reference_docs(), ids=lambda p: str(p.relative_to(DOCS)))
def test_no_diary_phrases_outside_the_changelog(doc):
    found = diary_phrases(doc.read_text(encoding="utf-8"))
    assert not found, (
        f"docs/{doc.relative_to(DOCS)} narrates passes or sessions (history goes to "
        f"docs/changelog.md): " + "; ".join(f"line {n}: {p!r}" for n, p in found))


def test_every_performance_table_is_dated():
    undated = undated_tables(PERFORMANCE.read_text(encoding="utf-8"))
    assert not undated, (
        f"docs/performance.md: tables without a date (YYYY-MM-DD) in their heading, the prose "
        f"above them, their header or every row, at lines {undated}")


def test_the_checks_see_what_they_look_for():
    """Both directions of the helpers on small texts, so a check that finds nothing is seen to
    be able to find something."""
    assert diary_phrases("In the Fifth pass we tried\nthird sessions") == [
        (1, "Fifth pass"), (2, "third sessions")]
    assert diary_phrases("a fourth render pass; the first three passes; a first run") == []
    doc = "\n".join([
        "# Title",
        "## Dated section (2026-12-02)",
        "| a | b |", "|---|---|", "| 1 | 2 |",
        "Prose without a date.",
        "| a | b |", "|---|---|", "| 3 | 4 |",
        "## Undated section",
        "Run of 2026-12-01:",
        "| a | b |", "|---|---|", "| 5 | 6 |",
        "More prose.",
        "| a | b |", "|---|---|", "| 7 | 8 |",
        "",
        "| when | b |", "|---|---|", "| 9 | 10 |",
        "",
        "| a | when |", "|---|---|", "| 11 | 2026-11-22 |", "| 12 | 2026-12-01 |",
        "```", "| not | a table |", "```",
    ])
    assert undated_tables(doc) == [16, 20]


def _golden_scene_table():
    import importlib.util
    path = DOCS / "scripts" / "golden_scene_table.py"
    spec = importlib.util.spec_from_file_location("golden_scene_table", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_golden_scene_table_is_the_registry():
    """docs/golden.md lists exactly the registered golden scenes (issue 42: the list went stale)."""
    mod = _golden_scene_table()
    text = (DOCS / "golden.md").read_text(encoding="utf-8")
    assert mod.replaced(text) == text, (
        "docs/golden.md's scene table is stale: run python docs/scripts/golden_scene_table.py")


def test_golden_scene_table_check_catches_a_missing_row():
    mod = _golden_scene_table()
    text = (DOCS / "golden.md").read_text(encoding="utf-8")
    row = next(ln for ln in text.splitlines() if ln.startswith("| `render_cube`"))
    assert mod.replaced(text.replace(row + "\n", "")) != text.replace(row + "\n", "")


def test_golden_scene_order_does_not_depend_on_import_order():
    """The registry's order is fixed (this module's scenes, then SCENE_MODULES'), not the order in
    which a program happened to import the scene modules: importing the multisample scene modules
    first used to reorder it and stale docs/golden.md's table."""
    code = ("import refraster.golden.msaa_clip_scenes, refraster.golden.msaa_scenes\n"
            "from refraster.golden import available_scenes\n"
            "print(','.join(available_scenes()))")
    import subprocess
    import sys
    first = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           check=True).stdout.strip()
    from refraster.golden import available_scenes
    assert first == ",".join(available_scenes())
