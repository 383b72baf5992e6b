"""Write the table of built-in golden scenes into docs/golden.md from the registry.

    python docs/scripts/golden_scene_table.py          # rewrite the table in place
    python docs/scripts/golden_scene_table.py --check  # exit 1 if the table is stale

The table sits between the markers ``<!-- scenes:begin -->`` and ``<!-- scenes:end -->``; one
row per scene of :func:`refraster.golden.available_scenes` (name, technique, description), in
registration order. ``tests/test_docs_reference.py`` fails when the table and the registry
disagree.
"""

from __future__ import annotations

import sys
from pathlib import Path

GOLDEN_MD = Path(__file__).resolve().parents[1] / "golden.md"
BEGIN, END = "<!-- scenes:begin -->", "<!-- scenes:end -->"


def table():
    from refraster.golden import available_scenes
    rows = ["| scene | technique | what it shows |", "|---|---|---|"]
    for name, s in available_scenes().items():
        text = " ".join(str(s.description).split()).replace("|", "\\|")
        rows.append(f"| `{name}` | {s.technique} | {text} |")
    return "\n".join(rows)


def replaced(text):
    """``text`` with the table between the markers rewritten."""
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:i] + "\n" + table() + "\n" + text[j:]


def main(argv):
    text = GOLDEN_MD.read_text(encoding="utf-8")
    new = replaced(text)
    if "--check" in argv:
        if new != text:
            print("docs/golden.md: the scene table is stale; run docs/scripts/golden_scene_table.py")
            return 1
        return 0
    GOLDEN_MD.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
