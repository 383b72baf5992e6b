"""The compare report of a 50-scene golden: its size and how fast headless Chromium opens it.

A golden of 50 scenes (``render_cube`` and ``render_multi_draw`` at 25 sizes each, 160×120 to
208×120) is compared, in tolerant mode, against three candidates:

* ``pass``: the golden's own buffers (every scene passes, collapsed);
* ``issue``: per scene the faults of issue 29 — a 10×20 depth patch (+0.01) and a 10×10 patch of
  swizzled normals — so two failing buffers per scene;
* ``all``: every buffer of every scene moved by one column — every buffer fails, over the whole
  frame, so each crop is cut to its largest size: the most embedded data a report can hold.

For each: the compare's wall time with ``--report``, the report's size (every file), and the
time headless Chromium (DevTools protocol over a pipe, fresh profile) takes from the navigation
command to the load event (median and largest of ``--runs`` loads, each after ``about:blank``),
then the time until hovering the first failing pixel shows its values (the first decode).

Run from the repository root: ``python -m benchmarks.golden_report [--golden DIR] [--runs N]``
(``--golden`` keeps the generated golden for the next run).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = [f"{160 + 2 * k}x120" for k in range(25)]


def _golden(path):
    from refraster import golden
    if not (path / "manifest.json").is_file():
        t0 = time.perf_counter()
        golden.generate(path, ["render_cube", "render_multi_draw"], sizes=SIZES)
        print(f"generated the 50-scene golden in {time.perf_counter() - t0:.0f} s",
              file=sys.stderr)
    return path


def _candidate(gold, out, kind):
    import json
    manifest = json.loads((gold / "manifest.json").read_text())
    for scene in manifest["scenes"]:
        (out / scene).mkdir(parents=True)
        with np.load(gold / scene / "buffers.npz") as z:
            b = {k: z[k] for k in z.files}
        if kind == "issue":
            b["depth"][50:60, 70:90] += 0.01
            b["normal"][40:50, 60:70] = b["normal"][40:50, 60:70][..., ::-1]
        elif kind == "all":
            b = {k: np.roll(v, 1, axis=1) for k, v in b.items()}
        np.savez(out / scene / "buffers.npz", **b)
    return out


def _size(path):
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _hover_first(b):
    """Seconds from moving the mouse onto the first failing pixel to its values showing."""
    info = b.js("""(() => { const i = document.querySelector('.crop img');
        if (!i) return null;
        const r = i.getBoundingClientRect();
        return {left: r.left + i.clientLeft, top: r.top + i.clientTop, w: i.clientWidth,
                h: i.clientHeight, rows: +i.dataset.rows, cols: +i.dataset.cols}; })()""")
    if info is None:
        return None
    t0 = time.perf_counter()
    b.mouse_move(info["left"] + info["w"] / 2, info["top"] + info["h"] / 2)
    while time.perf_counter() - t0 < 10:
        text = b.js("document.getElementById('tip').textContent")
        if "status:" in text:
            return time.perf_counter() - t0
        time.sleep(0.01)
    return float("nan")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--golden", type=Path, help="where to keep the 50-scene golden")
    ap.add_argument("--runs", type=int, default=3, help="page loads per report")
    ap.add_argument("--only", nargs="*", default=("pass", "issue", "all"),
                    help="candidates to run (pass, issue, all)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from chromium_cdp import Browser
    from refraster import golden
    with tempfile.TemporaryDirectory(prefix="refraster-report-bench-") as tmp:
        tmp = Path(tmp)
        gold = _golden(args.golden or tmp / "golden")
        rows = []
        with Browser(tmp / "chromium", 1280, 800) as browser:
            for kind in args.only:
                cand = _candidate(gold, tmp / f"cand-{kind}", kind)
                rep = tmp / f"report-{kind}"
                t0 = time.perf_counter()
                result = golden.compare(gold, cand, report=rep, mode="tolerant")
                t_compare = time.perf_counter() - t0
                loads = []
                for _ in range(args.runs):
                    browser.open("about:blank")
                    loads.append(browser.open((rep / "index.html").as_uri()))
                hover = _hover_first(browser)
                failing = sum(s.status != "pass" for s in result.scenes)
                n_crops = sum(1 for p in (rep / "img").iterdir() if "__crop_" in p.name) // 4
                rows.append((kind, failing, n_crops, _size(rep), (rep / "index.html").stat().st_size,
                             t_compare, float(np.median(loads)), max(loads), hover,
                             browser.console()))
                shutil.rmtree(cand)
    print(f"50-scene golden ({', '.join(['render_cube', 'render_multi_draw'])} × 25 sizes), "
          f"tolerant compare, Chromium 1280×800 headless, {args.runs} loads each")
    print("| candidate | failing scenes | crops | report size MB | index.html MB | compare + "
          "report s | load median s | load max s | first hover s | console |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for kind, failing, crops, size, page, tc, med, mx, hover, console in rows:
        hv = "—" if hover is None else f"{hover:.2f}"
        print(f"| {kind} | {failing} | {crops} | {size / 1e6:.2f} | {page / 1e6:.2f} | {tc:.1f} | "
              f"{med:.2f} | {mx:.2f} | {hv} | {len(console)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
