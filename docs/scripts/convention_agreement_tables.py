"""Write the API-convention agreement tables of docs/backends.md from a measurement: refraster
against Mesa's lavapipe through wgpu (``tests/test_lavapipe_oracle.py``) and against Mesa's
llvmpipe through OpenGL 4.5 (``tests/test_llvmpipe_conventions.py``), one row per convention over
the counted held-out scenes.

    python docs/scripts/convention_agreement_tables.py          # measure, rewrite both tables
    python docs/scripts/convention_agreement_tables.py --check  # exit 1 if either is stale

Each table sits between its markers (:data:`TABLES`). The tests ``test_agreement_table_in_docs``
of both test modules fail when the table differs from their run (CI runs them with lavapipe and
llvmpipe installed; locally they skip without them). Needs the oracles' packages (wgpu-py and
``mesa-vulkan-drivers``; moderngl and EGL).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BACKENDS_MD = ROOT / "docs" / "backends.md"

#: oracle → (test module, begin marker, end marker, {convention: row label})
TABLES = {
    "lavapipe": ("test_lavapipe_oracle",
                 "<!-- lavapipe-agreement:begin (docs/scripts/convention_agreement_tables.py) -->",
                 "<!-- lavapipe-agreement:end -->",
                 {"webgpu": "WebGPU / D3D (`zero_to_one`, upper-left, y up)",
                  "vulkan": "Vulkan (NDC y down: the clip y negated in the shader)",
                  "reversed_z_infinite": "reversed-Z float32, infinite far (`greater`, clear 0)",
                  "vulkan_depth_clamp": "Vulkan with depth clamp (`unclippedDepth`)"}),
    "llvmpipe": ("test_llvmpipe_conventions",
                 "<!-- llvmpipe-agreement:begin (docs/scripts/convention_agreement_tables.py) -->",
                 "<!-- llvmpipe-agreement:end -->",
                 {"gl_upper_left_zero_to_one": "`glClipControl(GL_UPPER_LEFT, GL_ZERO_TO_ONE)`",
                  "gl_vulkan_ndc_y_down": "the same with `ndc_y = \"down\"` (clip y negated in "
                                          "the shader)",
                  "gl_reversed_z_infinite": "reversed-Z float32, infinite far (`greater`, "
                                            "clear 0)",
                  "gl_depth_clamp": "the first with `GL_DEPTH_CLAMP`"}),
}

HEAD = ("| convention | covered px | differ | ties (≤ 1/128 px) | {oracle} wrong (referee) | "
        "held against refraster | raw agreement | agreement | max \\|Δz\\| where ids agree | "
        "worst Δz / allowance | verdict |")


def _module(name):
    tests = str(ROOT / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)
    import importlib
    return importlib.import_module(name)


def table(oracle):
    """The Markdown table of ``oracle`` (``"lavapipe"`` or ``"llvmpipe"``), measured now
    (the test module's cached results when it has run in this process)."""
    mod_name, _, _, labels = TABLES[oracle]
    mod = _module(mod_name)
    lav = _module("test_lavapipe_oracle")
    rows = [HEAD.format(oracle=oracle), "|" + "---|" * 11]
    handle = mod._lav() if oracle == "lavapipe" else mod._gl()
    for name in mod.CONVENTIONS:
        counted = [r for r, sc in zip(mod._results(name, handle), lav.SCENES) if lav.counted(sc)]
        ok, agreement, why = lav._check(counted)
        covered = sum(r.covered for r in counted)
        differ = sum(r.differ for r in counted)
        raw = 1.0 - differ / max(covered, 1)
        verdict = "pass" if ok else "**FAIL**: " + "; ".join(why).replace("|", "\\|")
        rows.append(f"| {labels[name]} | {covered:,} | {differ:,} | "
                    f"{sum(r.ties for r in counted):,} | "
                    f"{sum(r.lavapipe_wrong for r in counted):,} | "
                    f"{sum(r.unexplained for r in counted):,} | {raw:.6f} | {agreement:.6f} | "
                    f"{max(r.max_dz for r in counted):.2e} | "
                    f"{max(r.depth_ratio for r in counted):.2f} | {verdict} |")
    return "\n".join(rows)


def replaced(text, oracle, new_table):
    """``text`` with ``oracle``'s table between its markers replaced by ``new_table``."""
    _, begin, end, _ = TABLES[oracle]
    i, j = text.index(begin) + len(begin), text.index(end)
    return text[:i] + "\n" + new_table + "\n" + text[j:]


def main(argv):
    text = BACKENDS_MD.read_text(encoding="utf-8")
    new = text
    for oracle in TABLES:
        new = replaced(new, oracle, table(oracle))
    if "--check" in argv:
        if new != text:
            print("docs/backends.md: a convention agreement table is stale; run "
                  "python docs/scripts/convention_agreement_tables.py")
            return 1
        return 0
    BACKENDS_MD.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
