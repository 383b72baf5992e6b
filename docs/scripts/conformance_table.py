"""Measure the catalogue of GPU bug classes (refraster/gl/catalogue.py) and write its table into
docs/conformance.md.

    python docs/scripts/conformance_table.py          # measure every class, rewrite the table
    python docs/scripts/conformance_table.py --check  # exit 1 if the table is stale

Every class's scenes are generated (refraster), rendered by refraster.gl once correct and once
with the class's planted fault (``golden candidate --backend gl``), and compared tolerantly
(``golden compare``). A row: the class, its planted fault, the scenes that caught it with the
buffers the report names, the listed scenes that did not. The table sits between the markers
``<!-- conformance:begin ... -->`` and ``<!-- conformance:end -->``;
``tests/test_conformance_catalogue.py`` measures the same way and fails when a class is caught by
no scene, when the correct backend fails a scene, or when the table differs from its run. Needs
a headless EGL context (Mesa llvmpipe through moderngl); a full run takes several minutes (the
technique scenes' goldens).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

CONFORMANCE_MD = Path(__file__).resolve().parents[1] / "conformance.md"
BEGIN = "<!-- conformance:begin (docs/scripts/conformance_table.py) -->"
END = "<!-- conformance:end -->"
CORRECT = "correct"


def scenes_of(classes):
    """The scenes of ``classes``, each once, in catalogue order."""
    out = []
    for c in classes:
        out += [s for s in c.scenes if s not in out]
    return out


def measure(golden_dir, work_dir, classes):
    """Render ``golden_dir``'s scenes of ``classes`` correct and with each class's fault, and
    compare → ``{"correct" or class name: {scene: SceneResult}}``."""
    from refraster import golden
    from refraster.golden.candidate import candidate
    golden_dir, work_dir = Path(golden_dir), Path(work_dir)
    runs = [(CORRECT, (), scenes_of(classes))] + [(c.name, (c.fault,), list(c.scenes))
                                                  for c in classes]
    results = {}
    for key, faults, scenes in runs:
        out = work_dir / f"cand_{faults[0] if faults else CORRECT}"
        r = candidate(golden_dir, out, faults=faults, scenes=scenes)
        if r["skipped"]:
            raise RuntimeError(f"{key}: scenes skipped by the gl backend: {r['skipped']}")
        marker = json.loads((out / ".refraster-candidate").read_text())
        if marker["faults"] != list(faults):
            raise RuntimeError(f"{key}: the candidate's marker lists faults {marker['faults']}")
        cmp = golden.compare(golden_dir, out, mode="tolerant", scenes=r["rendered"])
        results[key] = {s.name: s for s in cmp.scenes}
    return results


def _buffers(scene_result):
    failing = [b.name for b in scene_result.buffers if not b.passed]
    if len(failing) == len(scene_result.buffers):
        return f"all {len(failing)}"
    return ", ".join(f"`{b}`" for b in failing)


def rows(classes, results):
    """One row per class: ``(class, fault, [(scene, buffers named)], [scenes that passed])``."""
    out = []
    for c in classes:
        caught, missed = [], []
        for scene in c.scenes:
            r = results[c.name][scene]
            if r.status == "fail":
                caught.append((scene, _buffers(r)))
            else:
                missed.append(scene)
        out.append((c, caught, missed))
    return out


def row_lines(table_rows):
    """The Markdown lines of ``table_rows`` (one per class)."""
    lines = []
    for c, caught, missed in table_rows:
        cells = "<br>".join(f"{s}: {b}" for s, b in caught) or "**none**"
        lines.append(f"| {c.group} | {c.name} | `{c.fault}` | {cells} | "
                     f"{', '.join(missed) or '—'} |")
    return lines


HEAD = ["| group | class | planted fault | caught by (scene: buffers the report names) | "
        "listed, not caught |", "|---|---|---|---|---|"]


def table(table_rows):
    return "\n".join(HEAD + row_lines(table_rows))


def replaced(text, new_table):
    """``text`` with the table between the markers rewritten."""
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:i] + "\n" + new_table + "\n" + text[j:]


def current_lines(text=None):
    """The row lines of the table docs/conformance.md holds now."""
    text = CONFORMANCE_MD.read_text(encoding="utf-8") if text is None else text
    i, j = text.index(BEGIN) + len(BEGIN), text.index(END)
    return [line for line in text[i:j].strip().splitlines()[len(HEAD):]]


CAT_BEGIN = "<!-- catalogue:begin (docs/scripts/conformance_table.py) -->"
CAT_END = "<!-- catalogue:end -->"


def catalogue_text(classes=None):
    """The catalogue by group (from refraster/gl/catalogue.py, no rendering): each class with
    its bug, what the golden allows by design where it does, its planted fault, its scenes."""
    from refraster.gl import FAULTS
    from refraster.gl.catalogue import CLASSES, GROUPS
    classes = CLASSES if classes is None else classes
    out = []
    for group in GROUPS:
        members = [c for c in classes if c.group == group]
        out += [f"### {group[0].upper()}{group[1:]} ({len(members)})", ""]
        for c in members:
            scenes = ", ".join(f"`{s}`" for s in c.scenes)
            text = (f"- **{c.name}**: {c.bug}. Planted: `{c.fault}` "
                    f"({FAULTS[c.fault][1]}). Scenes: {scenes}.")
            if c.allowance:
                text += f" *Allowed by design:* {c.allowance}."
            out.append(text)
        out.append("")
    return "\n".join(out).strip()


def with_catalogue(text):
    """``text`` with the catalogue section between its markers rewritten."""
    i, j = text.index(CAT_BEGIN) + len(CAT_BEGIN), text.index(CAT_END)
    return text[:i] + "\n" + catalogue_text() + "\n" + text[j:]


def main(argv):
    from refraster import golden
    from refraster.gl.catalogue import CLASSES
    with tempfile.TemporaryDirectory() as tmp:
        golden.generate(Path(tmp) / "golden", scenes_of(CLASSES))
        results = measure(Path(tmp) / "golden", tmp, CLASSES)
    new_table = table(rows(CLASSES, results))
    text = CONFORMANCE_MD.read_text(encoding="utf-8")
    new = with_catalogue(replaced(text, new_table))
    if "--check" in argv:
        if new != text:
            print("docs/conformance.md's table is stale: run python "
                  "docs/scripts/conformance_table.py", file=sys.stderr)
            return 1
        return 0
    CONFORMANCE_MD.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
