"""The HTML report of a golden compare opens in headless Chromium with every image loaded and
no console errors."""

import json
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import IN_CI
from refraster import golden

CHROMIUM = Path("/usr/bin/chromium")

# Injected (by the test only) into a copy of the page: records load errors of any element; once
# the page has loaded, opens every collapsed section (whose pictures the page then fills in),
# loads every (lazy) picture and writes how many images decoded into the title that --dump-dom
# prints.
CHECKER = """<script>
window.__errors = [];
window.addEventListener("error", e => window.__errors.push(
    (e.target && e.target.src) || e.message || "error"), true);
window.addEventListener("load", () => {
  for (const d of document.querySelectorAll("details")) d.open = true;
  setTimeout(() => {
    for (const i of document.images) i.loading = "eager";
    setTimeout(() => {
      const imgs = [...document.images];
      const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
      document.title = "CHECK " + JSON.stringify({images: imgs.length, loaded: ok,
                                                   errors: window.__errors});
    }, 1000);
  }, 0);
});
</script>"""


def chromium(*args, user_dir):
    if not CHROMIUM.exists():
        if IN_CI:
            pytest.fail("CI=true but /usr/bin/chromium is missing")
        pytest.skip("chromium is not installed")
    cmd = [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={user_dir}", "--enable-logging=stderr", "--v=0", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


def page_check(page, user_dir):
    proc = chromium("--virtual-time-budget=5000", "--dump-dom", page.as_uri(), user_dir=user_dir)
    match = re.search(r"<title>CHECK (.*?)</title>", proc.stdout)
    assert match, proc.stderr[-2000:]
    console = [line for line in proc.stderr.splitlines() if re.search(r":CONSOLE[:(]", line)]
    return json.loads(match.group(1).replace("&quot;", '"')), console


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    golden.generate(root / "g", ["render_multi_draw"])
    cand = root / "cand" / "render_multi_draw"
    cand.mkdir(parents=True)
    with np.load(root / "g" / "render_multi_draw" / "buffers.npz") as z:
        b = {k: z[k] for k in z.files}
    b["color"] = np.roll(b["color"], 1, axis=0)      # a failing buffer: red in the mask
    b["prim_id"][60, 40:44] = 7
    np.savez(cand / "buffers.npz", **b)
    result = golden.compare(root / "g", root / "cand", report=root / "report",
                            tolerances=["color.deviation_radius=1"])
    assert result.exit_code == 1
    return root, result


def test_report_files(report):
    root, result = report
    rep = root / "report"
    data = json.loads((rep / "report.json").read_text())
    assert data["exit_code"] == 1
    buffers = data["scenes"]["render_multi_draw"]["buffers"]
    assert buffers["prim_id"]["passed"] is False and buffers["depth"]["passed"] is True
    html = (rep / "index.html").read_text()
    srcs = re.findall(r'<img src="([^"]+)"', html)
    # 4 pictures per buffer, FLIP for colour, 4 magnified crops of the failing prim_id
    assert len(srcs) == 8 * 4 + 1 + 4
    assert sum("__crop_" in s for s in srcs) == 4
    assert all((rep / s).is_file() for s in srcs)
    assert "prim_id: fraction_over" in html
    # a second report replaces the first; a foreign non-empty directory is refused
    golden.compare(root / "g", root / "cand", report=rep)
    foreign = root / "foreign"
    foreign.mkdir()
    (foreign / "keep.txt").write_text("x")
    with pytest.raises(golden.GoldenError, match="not empty"):
        golden.compare(root / "g", root / "cand", report=foreign)
    assert (foreign / "keep.txt").read_text() == "x"


def test_report_opens_in_chromium(report, tmp_path):
    root, _ = report
    rep = root / "report"
    shot = tmp_path / "report.png"
    proc = chromium("--window-size=1400,1600", f"--screenshot={shot}",
                    (rep / "index.html").as_uri(), user_dir=tmp_path / "u1")
    assert shot.is_file() and shot.stat().st_size > 20000, proc.stderr[-2000:]
    assert not [line for line in proc.stderr.splitlines() if re.search(r":CONSOLE[:(]", line)]
    import imageio.v3 as iio
    img = iio.imread(shot)
    assert img.shape[:2] == (1600, 1400) and img.std() > 10   # not a blank page

    page = rep / "_check.html"
    page.write_text((rep / "index.html").read_text().replace("<head>", "<head>" + CHECKER, 1))
    status, console = page_check(page, tmp_path / "u2")
    # the report test_report_files wrote last (default tolerances: colour fails too, so 2 crops)
    assert status["images"] == 41 and status["loaded"] == 41 and status["errors"] == []
    assert console == []
    # the check can fail: a page with a missing picture is caught
    broken = rep / "_broken.html"
    broken.write_text(page.read_text().replace('src="img/', 'src="img/missing_', 1).replace(
        "</body>", "<script>console.error('planted')</script></body>"))
    status, console = page_check(broken, tmp_path / "u3")
    assert status["loaded"] == 40 and len(status["errors"]) == 1
    assert any("planted" in line for line in console)
    page.unlink()
    broken.unlink()
    shutil.copy(shot, root / "screenshot.png")


# --- the page a GPU developer reads first (issue 29) ----------------------------------------------

VIEW = (1280, 800)            # the first screen


@pytest.fixture(scope="module")
def two_scenes(tmp_path_factory):
    """A golden of a failing and a passing scene; the passing one is compared first."""
    root = tmp_path_factory.mktemp("report29")
    # 4 bits: the wrong id's pixel (id_pixel, in the id band) lies outside the depth patch
    golden.generate(root / "g", ["render_cube", "render_multi_draw"], candidate_subpixel_bits=4)
    for scene in ("render_cube", "render_multi_draw"):
        (root / "cand" / scene).mkdir(parents=True)
        with np.load(root / "g" / scene / "buffers.npz") as z:
            b = {k: z[k] for k in z.files}
        if scene == "render_cube":       # the faults: a 10×20 depth patch, swizzled normals
            b["depth"][50:60, 70:90] += 0.01
            b["normal"][40:50, 60:70] = b["normal"][40:50, 60:70][..., ::-1]
            with np.load(root / "g" / scene / "tolerance.npz") as z:   # and one wrong id
                r, c = id_pixel(z)
            b["prim_id"][r, c] += 1
        np.savez(root / "cand" / scene / "buffers.npz", **b)
    with np.load(root / "g" / "render_cube" / "tolerance.npz") as z:
        allow = {k: z[k] for k in z.files}
    with np.load(root / "g" / "render_cube" / "buffers.npz") as z:
        ref = {k: z[k] for k in z.files}
    return root, ref, allow


def id_pixel(allow):
    """A pixel of the cube's right face whose id must agree (covered, no edge near)."""
    must = (allow["coverage"] == 2) & ~allow["id_may"]
    r, c = np.argwhere(must[65:80, 95:115])[0]
    return int(r) + 65, int(c) + 95


def make_report(root, name, **patches):
    """Compare the two scenes (passing first) into ``root/name``, with report internals patched."""
    from refraster.golden.compare import report as rep
    saved = {k: getattr(rep, k) for k in patches}
    try:
        for k, v in patches.items():
            setattr(rep, k, v)
        result = golden.compare(root / "g", root / "cand", report=root / name, mode="tolerant",
                                scenes=["render_multi_draw", "render_cube"])
    finally:
        for k, v in saved.items():
            setattr(rep, k, v)
    assert result.exit_code == 1
    assert [s.status for s in result.scenes] == ["pass", "fail"]
    return root / name / "index.html"


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if not CHROMIUM.exists():
        if IN_CI:
            pytest.fail("CI=true but /usr/bin/chromium is missing")
        pytest.skip("chromium is not installed")
    from chromium_cdp import Browser
    with Browser(tmp_path_factory.mktemp("chromium"), *VIEW) as b:
        yield b


FIRST_SCREEN = """(() => {
  const scenes = [...document.querySelectorAll("section.scene, details.scene")];
  const crops = [...document.querySelectorAll(".crop img")];
  const links = [...document.querySelectorAll(".scenes a")].map(a => a.getAttribute("href"));
  const tableTop = document.querySelector(".scenes").getBoundingClientRect().top;
  return {
    scenes: scenes.map(s => [s.id, s.tagName, s.tagName === "DETAILS" ? s.open : true,
                             s.getBoundingClientRect().top]),
    links: links, tableTop: tableTop,
    crops: crops.slice(0, 4).map(i => {
      const r = i.getBoundingClientRect();
      return {scene: i.closest(".scene").id, buffer: i.dataset.name, src: i.getAttribute("src"),
              loaded: i.complete && i.naturalWidth > 0, top: r.top, bottom: r.bottom,
              left: r.left, right: r.right, width: i.clientWidth, height: i.clientHeight,
              rows: +i.dataset.rows, cols: +i.dataset.cols, r0: +i.dataset.r0,
              c0: +i.dataset.c0};
    }),
    view: [innerWidth, innerHeight]};
})()"""


def first_screen_problems(b, page, failing, passing, bad_pixel):
    """What is wrong with the first screen of ``page``: [] when the failing scene comes first,
    the passing one is collapsed, the scene table links to both, and the failing scene's four
    magnified crops (one pixel ≥ 8 screen pixels) are wholly on the first screen, with the
    ``bad_pixel`` (row, col) painted red in the error-mask crop of the screenshot."""
    b.open(page.as_uri())
    t0 = time.monotonic()
    while time.monotonic() - t0 < 2 and not b.js(
            "[...document.querySelectorAll('.crop img')].slice(0, 4).every(i => i.complete)"):
        time.sleep(0.05)
    s = b.js(FIRST_SCREEN)
    problems = []
    if not s["scenes"] or s["scenes"][0][0] != failing:
        problems.append(f"first scene is {s['scenes'][:1]}, not {failing}")
    if [x[0] for x in s["scenes"]] != [failing, passing]:
        problems.append(f"scenes {s['scenes']}")
    if not any(x[0] == passing and x[1] == "DETAILS" and not x[2] for x in s["scenes"]):
        problems.append(f"{passing} is not collapsed")
    if sorted(s["links"]) != sorted([f"#{failing}", f"#{passing}"]):
        problems.append(f"scene table links {s['links']}")
    if s["scenes"] and s["tableTop"] > s["scenes"][0][3]:
        problems.append("the scene table is not at the top")
    crops = s["crops"]
    if len(crops) < 4:
        return problems + [f"{len(crops)} crop pictures"]
    w, h = s["view"]
    labels = ("crop_reference", "crop_candidate", "crop_difference", "crop_error_mask")
    for c, label in zip(crops, labels):
        if c["scene"] != failing or label not in c["src"]:
            problems.append(f"crop {c['src']} of {c['scene']}")
        if not c["loaded"]:
            problems.append(f"{c['src']} did not load")
        if c["top"] < 0 or c["bottom"] > h or c["left"] < 0 or c["right"] > w:
            problems.append(f"{c['src']} is not wholly on the first screen: {c}")
        if c["width"] < 8 * c["cols"] or c["height"] < 8 * c["rows"]:
            problems.append(f"{c['src']}: {c['width']}×{c['height']} screen px for "
                            f"{c['cols']}×{c['rows']} pixels")
    shot = b.screenshot()
    mask = crops[3]
    r, col = bad_pixel
    if not (mask["r0"] <= r < mask["r0"] + mask["rows"]
            and mask["c0"] <= col < mask["c0"] + mask["cols"]):
        return problems + [f"pixel {bad_pixel} is not in the crop {mask}"]
    zy, zx = mask["height"] / mask["rows"], mask["width"] / mask["cols"]
    y = int(mask["top"] + 1 + (r - mask["r0"] + 0.5) * zy)
    x = int(mask["left"] + 1 + (col - mask["c0"] + 0.5) * zx)
    if not (0 <= y < shot.shape[0] and 0 <= x < shot.shape[1]) or \
            np.abs(shot[y, x].astype(int) - (220, 0, 0)).max() > 30:
        problems.append(f"the mask crop is not red at {bad_pixel} on the screenshot")
    return problems


def hover(b, selector, row, col):
    """Move the mouse over pixel (row, col) of the picture ``selector``; the tooltip's text."""
    sel = json.dumps(selector)
    b.js(f"document.querySelector({sel}).scrollIntoView({{block: 'center'}})")
    # let the scroll settle (the page hides its tooltip on scroll)
    b.js("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))",
         await_promise=True)
    info = b.js(f"""(() => {{ const i = document.querySelector({sel});
        const r = i.getBoundingClientRect();
        return {{left: r.left + i.clientLeft, top: r.top + i.clientTop, w: i.clientWidth,
                h: i.clientHeight, rows: +i.dataset.rows, cols: +i.dataset.cols,
                r0: +i.dataset.r0, c0: +i.dataset.c0}}; }})()""")
    x = info["left"] + (col - info["c0"] + 0.5) * info["w"] / info["cols"]
    y = info["top"] + (row - info["r0"] + 0.5) * info["h"] / info["rows"]
    b.mouse_move(x, y)
    for _ in range(100):
        text = b.js("(t => t.hidden ? '' : t.textContent)(document.getElementById('tip'))")
        if text and "..." not in text.splitlines()[-1]:
            return text
        time.sleep(0.05)
    return text


def value_text(v):
    """The page's spelling of a float32 value: the shortest that reads back the same."""
    s = np.format_float_positional(np.float32(v), unique=True, trim="-")
    return s if len(s) < 12 else np.format_float_scientific(np.float32(v), unique=True,
                                                            trim="-")


def hover_problems(b, page, ref, allow, candidate_depth):
    """What is wrong with the values the page shows on hover: [] when pixel (55, 80) — outside
    the depth allowance — shows its row, column, both values, the allowed interval and its
    status in all four crop pictures and in the full-size picture, and a normal pixel its
    vectors and angle."""
    b.open(page.as_uri())
    problems = []
    r, c = 55, 80
    want = ["row 55, col 80", "render_cube/depth",
            f"reference: {value_text(ref['depth'][r, c])}",
            f"candidate: {value_text(candidate_depth[r, c])}",
            f"allowed interval: [{value_text(allow['depth_lo'][r, c])}, "
            f"{value_text(allow['depth_hi'][r, c])}]",
            "status: OUTSIDE THE ALLOWANCE"]
    for pic in ("crop_reference", "crop_candidate", "crop_difference", "crop_error_mask",
                "reference.png"):
        text = hover(b, f"img[src*='render_cube__depth__{pic}']", r, c)
        missing = [w for w in want if w not in text]
        if missing:
            problems.append(f"{pic}: {missing} not in {text!r}")
    text = hover(b, "img[src*='render_cube__normal__crop_candidate']", 45, 65)
    n = ref["normal"][45, 65]
    for w in ("row 45, col 65", "(" + ", ".join(value_text(v) for v in n) + ")",
              "(" + ", ".join(value_text(v) for v in n[::-1]) + ")", "angle(reference, candidate)",
              "status: OUTSIDE THE ALLOWANCE"):
        if w not in text:
            problems.append(f"normal: {w!r} not in {text!r}")
    # a pixel in the crop's padding is equal
    text = hover(b, "img[src*='render_cube__depth__crop_reference']", 47, 67)
    if "row 47, col 67" not in text or "status: equal" not in text:
        problems.append(f"padding pixel: {text!r}")
    return problems


OPEN_BY_LINK = """(async () => {
  const d = document.getElementById("render_multi_draw");
  const before = [d.open, d.querySelectorAll("img").length];
  document.querySelector('.scenes a[href="#render_multi_draw"]').click();
  await new Promise(r => setTimeout(r, 200));
  const b = d.querySelector("details.buffer");
  b.open = true;
  await new Promise(r => setTimeout(r, 200));
  return {before: before, open: d.open, buffer_imgs: b.querySelectorAll("img").length,
          shown: d.getBoundingClientRect().top};
})()"""


def test_first_screen_shows_the_failing_crop(two_scenes, browser):
    root, ref, _ = two_scenes
    page = make_report(root, "report")
    assert first_screen_problems(browser, page, "render_cube", "render_multi_draw",
                                 (55, 80)) == []
    assert browser.console() == []
    # the scene table's link opens the collapsed passing scene; its pictures appear when opened
    state = browser.js(OPEN_BY_LINK, await_promise=True)
    assert state["before"] == [False, 0] and state["open"] is True
    assert state["buffer_imgs"] == 4 and 0 <= state["shown"] < VIEW[1]


def test_first_screen_check_catches_planted_faults(two_scenes, browser):
    root, _, _ = two_scenes
    from refraster.golden.compare import report as rep
    # the passing scene first (the compare's order kept)
    page = make_report(root, "plant_order", scene_order=lambda scenes: list(scenes))
    problems = first_screen_problems(browser, page, "render_cube", "render_multi_draw", (55, 80))
    assert any("first scene" in p for p in problems), problems
    # no crop
    page = make_report(root, "plant_nocrop", crop_box=lambda *a, **k: None)
    problems = first_screen_problems(browser, page, "render_cube", "render_multi_draw", (55, 80))
    assert problems == ["0 crop pictures"], problems
    # a crop magnified less than 8 screen pixels per pixel
    page = make_report(root, "plant_zoom", crop_zoom=lambda rows, cols: 4)
    problems = first_screen_problems(browser, page, "render_cube", "render_multi_draw", (55, 80))
    assert problems and all("screen px for" in p or "not red" in p for p in problems), problems
    # a crop of the wrong region (the failing pixel is not in it)
    # the pictures of an opened buffer never filled in
    page = make_report(root, "plant_template", _SCRIPT=rep._SCRIPT.replace(
        "if (ev.target.open) expand(ev.target);", ""))
    browser.open(page.as_uri())
    assert browser.js(OPEN_BY_LINK, await_promise=True)["buffer_imgs"] == 0
    box = rep.crop_box
    page = make_report(root, "plant_region",
                       crop_box=lambda bad, *a, **k: box(np.roll(bad, 30, axis=1), *a, **k))
    problems = first_screen_problems(browser, page, "render_cube", "render_multi_draw", (55, 80))
    assert problems and "is not in the crop" in problems[-1], problems


def test_hover_shows_the_values(two_scenes, browser):
    root, ref, allow = two_scenes
    page = make_report(root, "report_hover")
    with np.load(root / "cand" / "render_cube" / "buffers.npz") as z:
        cand = z["depth"]
    assert hover_problems(browser, page, ref, allow, cand) == []
    assert browser.console() == []
    # planted: the embedded values one column off, or missing
    from refraster.golden.compare import report as rep
    crop_data = rep._crop_data

    def shifted(b, box, bad):
        r0, r1, c0, c1 = box
        meta = crop_data(b, (r0, r1, c0 + 1, c1 + 1), bad)
        meta["origin"] = [r0, c0]
        return meta
    page = make_report(root, "plant_shift", _crop_data=shifted)
    problems = hover_problems(browser, page, ref, allow, cand)
    assert problems and all("reference:" in p or "padding" in p or "normal" in p
                            for p in problems), problems
    page = make_report(root, "plant_nodata", _json_script=lambda obj: "{}")
    problems = hover_problems(browser, page, ref, allow, cand)
    # 5 depth pictures, 4 of the normal's 5 items (its row and column still show), padding
    assert len(problems) == 10 and all("unreadable embedded data" in p for p in problems[:5])


def test_cells_that_do_not_apply_say_why(two_scenes):
    from html.parser import HTMLParser
    root, _, _ = two_scenes
    page = make_report(root, "report_cells").read_text()

    class Cells(HTMLParser):
        def __init__(self):
            super().__init__()
            self.cells, self.cur = [], None

        def handle_starttag(self, tag, attrs):
            if tag == "td":
                self.cur = [dict(attrs).get("title"), ""]

        def handle_data(self, data):
            if self.cur is not None:
                self.cur[1] += data

        def handle_endtag(self, tag):
            if tag == "td" and self.cur is not None:
                self.cells.append(tuple(self.cur))
                self.cur = None

    def unexplained(text):
        p = Cells()
        p.feed(text[text.index('<section class="scene"'):])     # the metric tables
        na = [(t, v) for t, v in p.cells if v.strip() in ("n/a", "—", "", "inf")]
        return na, [(t, v) for t, v in na if not t]

    na, bad = unexplained(page)
    assert len(na) >= 2 * 7 and bad == []         # FLIP of 7 non-colour buffers per scene, …
    assert any("FLIP" in t and "normal is a snorm buffer" in t for t, _ in na)
    assert any("tolerant mode" in t for t, _ in na)
    from refraster.golden.io.schema import MANIFEST_SCHEMA_VERSION
    assert "Compare mode <b>tolerant" in page and \
        f"version <b>{MANIFEST_SCHEMA_VERSION}</b>" in page
    # planted: a cell without its reason is found
    _, bad = unexplained(page.replace(' title="FLIP is', ' data-x="FLIP is', 1))
    assert len(bad) == 1


def test_report_escapes_what_it_shows(two_scenes, tmp_path):
    root, _, _ = two_scenes
    odd = tmp_path / 'g</script><b>"&x'
    shutil.copytree(root / "g", odd)
    result = golden.compare(odd, root / "cand", report=tmp_path / "rep", mode="tolerant")
    page = (tmp_path / "rep" / "index.html").read_text()
    assert result.exit_code == 1
    assert "<b>\"&x" not in page and "g&lt;/script&gt;&lt;b&gt;&quot;&amp;x" in page
    assert page.count("</script>") == page.count("<script")


def test_fifty_scene_report_is_small_and_opens_fast(two_scenes, browser, tmp_path):
    """The report of 50 scenes in which every buffer fails over the whole frame (the most
    embedded data: every crop at its largest) stays under 20 MB and opens in Chromium in under
    2 s. The 50 scenes are the two compared scenes, 25 copies each under new names (the real
    50-scene golden is measured by ``benchmarks/golden_report.py``, docs/performance.md)."""
    import copy
    from dataclasses import replace

    from refraster.golden.compare.run import load_manifest
    from refraster.golden.compare.report import write_report
    root, _, _ = two_scenes
    cand = tmp_path / "cand"
    for scene in ("render_cube", "render_multi_draw"):
        (cand / scene).mkdir(parents=True)
        with np.load(root / "g" / scene / "buffers.npz") as z:
            np.savez(cand / scene / "buffers.npz", **{k: np.roll(z[k], 1, axis=1)
                                                       for k in z.files})
    result = golden.compare(root / "g", cand, mode="tolerant")
    assert result.exit_code == 1 and all(not b.passed for s in result.scenes for b in s.buffers)
    manifest = load_manifest(root / "g", verify=False)
    many = copy.deepcopy(manifest)
    many["scenes"], scenes = {}, []
    for k in range(25):
        for s in result.scenes:
            name = f"{s.name}__copy{k:02d}"
            many["scenes"][name] = manifest["scenes"][s.name]
            scenes.append(replace(s, name=name))
    t0 = time.perf_counter()
    rep = write_report(tmp_path / "report", replace(result, scenes=scenes), many)
    t_write = time.perf_counter() - t0
    size = sum(p.stat().st_size for p in rep.rglob("*") if p.is_file())
    crops = sum("__crop_" in p.name for p in (rep / "img").iterdir())
    assert crops == 50 * 8 * 4
    loads = []
    for _ in range(3):
        browser.open("about:blank")
        loads.append(browser.open((rep / "index.html").as_uri()))
    print(f"50 scenes, every buffer failing: {size / 1e6:.2f} MB, written in {t_write:.1f} s, "
          f"loads {', '.join(f'{x:.2f}' for x in loads)} s")
    assert size < 20e6
    assert min(loads) < 2.0
    assert browser.console() == []


def test_crop_box_zoom_and_magnify():
    from refraster.golden.compare.report import CROP_MAX, crop_box, crop_zoom, magnify
    assert CROP_MAX == 32
    bad = np.zeros((120, 160), bool)
    err = np.zeros((120, 160))
    assert crop_box(bad, err) is None
    bad[50:60, 70:90] = True                       # the 10×20 patch: padded by 4
    assert crop_box(bad, err) == ((46, 64, 66, 94), (50, 60, 70, 90))
    bad[:] = False
    bad[0, 159] = True                             # clipped at the picture's edge
    assert crop_box(bad, err) == ((0, 5, 155, 160), (0, 1, 159, 160))
    bad[:] = True                                  # the whole frame: 32 around the worst pixel
    assert crop_box(bad, err, {"row": 60, "col": 80})[0] == (44, 76, 64, 96)
    assert crop_box(bad, err, {"row": 2, "col": 158})[0] == (0, 32, 128, 160)
    assert crop_box(bad, err)[0] == (44, 76, 64, 96)            # no worst pixel: the centre
    bad[:] = False
    err[7, 9] = 1e-9                               # nothing outside: the pixels that differ
    assert crop_box(bad, err) == ((3, 12, 5, 14), (7, 8, 9, 10))
    assert (crop_zoom(18, 28), crop_zoom(32, 32), crop_zoom(1, 1), crop_zoom(9, 9)) == (9, 8, 24,
                                                                                        24)
    img = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    big = magnify(img, 8)
    assert big.shape == (40, 56, 3)
    grid = np.zeros((40, 56), bool)
    grid[::8] = True
    grid[:, ::8] = True
    rows, cols = np.indices((40, 56)) // 8
    assert (big[~grid] == img[rows, cols][~grid]).all()          # nearest neighbour
    v = img[rows, cols][grid].astype(float)
    target = np.where(v.mean(axis=-1, keepdims=True) > 110, 0.0, 255.0)
    assert np.abs(big[grid] - (0.6 * v + 0.4 * target)).max() <= 0.5 + 1e-3   # the grid


def test_hover_in_profile_mode_shows_threshold_and_forgiven(two_scenes, browser, tmp_path):
    """Conformant profile: a colour pixel forgiven by the position-deviation compare reads
    "forgiven here", differs but allowed; an inverted pixel next to it is outside, with its
    per-pixel threshold ``threshold + slope · v(p)`` (v: the largest difference to a neighbour)."""
    from refraster.golden.compare.run import local_variation
    root, ref, _ = two_scenes
    scene = root / "cand" / "render_cube" / "buffers.npz"
    with np.load(scene) as z:
        b = {k: z[k] for k in z.files}
    b["color"] = np.roll(ref["color"], 1, axis=1)
    cand = tmp_path / "cand" / "render_cube"
    cand.mkdir(parents=True)
    np.savez(cand / "buffers.npz", **b)
    kw = dict(profile="conformant", scenes=["render_cube"], buffers=["color"])
    first = golden.compare(root / "g", tmp_path / "cand", **kw).scenes[0].buffers[0]
    assert first.images["forgiven"].any()            # (its FLIP mean fails already)
    forgiven = np.argwhere(first.images["forgiven"])
    r, c = next((int(r), int(c)) for r, c in forgiven if c + 3 < 160
                and not first.images["over"][r, c + 3])
    b["color"][r, c + 3] = 1.0 - b["color"][r, c + 3]
    np.savez(cand / "buffers.npz", **b)
    result = golden.compare(root / "g", tmp_path / "cand", report=tmp_path / "rep", **kw)
    buf = result.scenes[0].buffers[0]
    assert not buf.passed and buf.images["forgiven"][r, c]
    assert (buf.images["over"] & ~buf.images["forgiven"])[r, c + 3]
    page = tmp_path / "rep" / "index.html"
    browser.open(page.as_uri())
    text = hover(browser, "img[src*='render_cube__color__crop_candidate']", r, c)
    assert f"row {r}, col {c}" in text and "(position deviation): forgiven here" in text, text
    assert "status: differs, allowed" in text, text
    text = hover(browser, "img[src*='render_cube__color__crop_candidate']", r, c + 3)
    thr = buf.metrics["threshold"] + buf.tolerance["slope"] * local_variation(ref["color"])[r,
                                                                                         c + 3]
    assert f"|candidate - reference| <= {float(thr)!r} per channel" in text, text
    assert "forgiven here" not in text and "status: OUTSIDE THE ALLOWANCE" in text, text
    assert browser.console() == []


def test_hover_shows_the_allowed_id_set(two_scenes, browser):
    root, ref, allow = two_scenes
    page = make_report(root, "report_ids")
    r, c = id_pixel(allow)
    browser.open(page.as_uri())
    text = hover(browser, "img[src*='render_cube__prim_id__crop_candidate']", r, c)
    want = ref["prim_id"][r, c]
    assert f"row {r}, col {c}" in text and f"reference: {want}\ncandidate: {want + 1}" in text
    assert (f"allowed set: {{{want}}} (coverage: must be covered; the id must agree)" in text
            and "status: OUTSIDE THE ALLOWANCE" in text), text
    # its neighbour in the crop is unchanged
    text = hover(browser, "img[src*='render_cube__prim_id__crop_candidate']", r, c + 1)
    assert "status: equal" in text and "allowed set:" in text, text
