"""The ``refraster`` command: render, gallery, info, errors, the quick start and the gallery page
in headless Chromium."""

import html.parser
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from urllib.parse import unquote

import imageio.v3 as iio
import numpy as np
import pytest
import trimesh

import refraster
from conftest import IN_CI
from refraster import cli
from refraster.camera import frame_bounds, look_at, perspective
from refraster.gallery import Item
from refraster.scenes import solids

REPO = Path(__file__).resolve().parents[1]


def _files(root):
    return sorted(p.relative_to(root) for p in Path(root).rglob("*"))


def _run(*args, cwd=None, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "refraster.cli", *map(str, args)], cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def crank_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("meshes")
    mesh = solids.crank(16)
    for ext in ("obj", "ply", "stl", "glb", "off"):
        mesh.export(root / f"crank.{ext}")
    return root, mesh


# ---------------------------------------------------------------------------------------------
# render

@pytest.mark.parametrize("ext", ["obj", "ply", "stl", "glb", "off"])
def test_render_formats_match_the_api(crank_files, tmp_path, capsys, ext):
    root, mesh = crank_files
    out, buf = tmp_path / "a.png", tmp_path / "a.npz"
    assert cli.main(["render", str(root / f"crank.{ext}"), "--out", str(out), "--buffers", str(buf),
                     "--width", "64", "--height", "48", "-q"]) == 0
    assert capsys.readouterr().err == ""
    image = iio.imread(out)
    assert image.shape == (48, 64, 3) and image.dtype == np.uint8
    with np.load(buf, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    # the framed camera is frame_bounds'; the CLI must give the API's picture bit for bit
    loaded = trimesh.load(root / f"crank.{ext}", force="mesh", process=False)
    assert len(loaded.faces) == len(mesh.faces)
    cam = frame_bounds(loaded.bounds, width=64, height=48)
    fb = refraster.render(loaded, **cam.kwargs)
    np.testing.assert_array_equal(arrays["prim_id"], fb.prim_id)
    np.testing.assert_array_equal(arrays["depth"], fb.depth)
    assert set(arrays) >= {"depth", "eye_depth", "normal", "prim_id", "object_id",
                           "front_facing", "barycentric", "color"}
    # framed: something covered, nothing touching the border
    covered = arrays["prim_id"] >= 0
    assert covered.sum() > 200
    assert not (covered[0].any() or covered[-1].any() or covered[:, 0].any()
                or covered[:, -1].any())


def test_render_explicit_camera(crank_files, tmp_path):
    root, mesh = crank_files
    buf = tmp_path / "b.npz"
    assert cli.main(["render", str(root / "crank.ply"), "--out", str(tmp_path / "b.png"),
                     "--buffers", str(buf), "--width", "80", "--height", "60",
                     "--eye", "2", "-3", "9", "--target", "2", "0", "0", "--fov", "40",
                     "--near", "1", "--far", "30", "--cull", "back", "-q"]) == 0
    fb = refraster.render(mesh, view=look_at((2, -3, 9), (2, 0, 0)),
                          proj=perspective(40, 80 / 60, 1, 30), width=80, height=60, raster=refraster.RasterState(cull="back"))
    with np.load(buf, allow_pickle=False) as z:
        np.testing.assert_array_equal(z["prim_id"], fb.prim_id)
        assert np.all(z["front_facing"][z["prim_id"] >= 0])


def test_render_smooth_normals_on_stl(crank_files, tmp_path):
    root, _ = crank_files
    flat, smooth = tmp_path / "f.npz", tmp_path / "s.npz"
    for mode, buf in (("flat", flat), ("smooth", smooth)):
        assert cli.main(["render", str(root / "crank.stl"), "--out", str(tmp_path / "x.png"),
                         "--buffers", str(buf), "--width", "64", "--height", "48",
                         "--normals", mode, "-q"]) == 0
    with np.load(flat) as f, np.load(smooth) as s:
        np.testing.assert_array_equal(f["prim_id"], s["prim_id"])  # merging keeps face order
        m = f["prim_id"] >= 0
        assert np.abs(f["normal"][m] - s["normal"][m]).max() > 0.05


def test_render_reports_one_line(crank_files, tmp_path, capsys):
    root, _ = crank_files
    assert cli.main(["render", str(root / "crank.off"), "--out", str(tmp_path / "x.png"),
                     "--width", "32", "--height", "24"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"wrote .*x\.png \(32x24, 2,996 faces", err)


# ---------------------------------------------------------------------------------------------
# bad input: one line, exit code 2, nothing written

def _write_bad_files(tmp):
    (tmp / "notes.obj").write_text("this is a shopping list\nmilk\neggs\n")
    (tmp / "empty.ply").write_bytes(b"")
    (tmp / "garbage.glb").write_bytes(b"not a glb at all")


def _bad_inputs(root, tmp):
    text, empty, garbage = tmp / "notes.obj", tmp / "empty.ply", tmp / "garbage.glb"
    ok = str(root / "crank.obj")
    out = str(tmp / "out" / "x.png")
    return {
        "missing file": ["render", str(tmp / "nope.obj"), "--out", out],
        "text named .obj": ["render", str(text), "--out", out],
        "zero-size file": ["render", str(empty), "--out", out],
        "unreadable glb": ["render", str(garbage), "--out", out, "--buffers", out + ".npz"],
        "a directory": ["render", str(root), "--out", out],
        "unknown option": ["render", ok, "--out", out, "--colour", "red"],
        "unknown command": ["paint", ok],
        "no command": [],
        "missing --out": ["render", ok],
        "zero width": ["render", ok, "--out", out, "--width", "0"],
        "huge size": ["render", ok, "--out", out, "--width", "100000", "--height", "100000"],
        "non-int height": ["render", ok, "--out", out, "--height", "4.5"],
        "not a png": ["render", ok, "--out", str(tmp / "out" / "x.jpg")],
        "not an npz": ["render", ok, "--out", out, "--buffers", str(tmp / "out" / "b.txt")],
        "bad cull": ["render", ok, "--out", out, "--cull", "sideways"],
        "zero fov": ["render", ok, "--out", out, "--fov", "0"],
        "far before near": ["render", ok, "--out", out, "--near", "5", "--far", "1"],
        "eye at target": ["render", ok, "--out", out, "--eye", "1", "2", "3",
                          "--target", "1", "2", "3"],
        "eye needs 3": ["render", ok, "--out", out, "--eye", "1", "2"],
        "nan eye": ["render", ok, "--out", out, "--eye", "nan", "0", "0"],
        "gallery without --out": ["gallery"],
        "gallery out is a file": ["gallery", "--out", str(text)],
    }


BAD = list(_bad_inputs(Path("/r"), Path("/t")))


@pytest.mark.parametrize("case", BAD)
def test_bad_input_one_line_exit_2_writes_nothing(crank_files, tmp_path, capsys, case):
    root, _ = crank_files
    _write_bad_files(tmp_path)
    argv = _bad_inputs(root, tmp_path)[case]
    before = _files(tmp_path)
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("refraster: error: ") and "Traceback" not in captured.err
    assert captured.out == ""
    assert _files(tmp_path) == before


def test_bad_input_as_a_process(tmp_path):
    # the real exit code and stderr of the command, not only main()'s return value
    text = tmp_path / "notes.obj"
    text.write_text("hello\n")
    proc = _run("render", text, "--out", tmp_path / "x.png")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"refraster: error: mesh file '{text}' has no triangles (not a mesh file, or "
        "an empty mesh)"]
    assert not (tmp_path / "x.png").exists()
    debug = _run("render", text, "--out", tmp_path / "x.png", "--debug")
    assert debug.returncode != 0 and "Traceback" in debug.stderr


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"refraster {refraster.__version__}"
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "--help"])
    assert exc.value.code == 0
    assert "--buffers" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------
# info

def test_info_reports_versions_threads_cache_and_llvmpipe(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_NUM_THREADS="1")
    proc = _run("info", env=env)
    assert proc.returncode == 0, proc.stderr
    rows = dict(line.split(":", 1) for line in proc.stdout.splitlines())
    rows = {k: v.strip() for k, v in rows.items()}
    assert rows["refraster"] == refraster.__version__
    assert rows["numpy"] == np.__version__
    assert rows["numba threads"].startswith("1 ")
    assert rows["kernel cache"] == f"{tmp_path / 'cache'} [NUMBA_CACHE_DIR]"
    assert rows["llvmpipe oracle"].split()[0] in ("available", "not")
    assert rows["fast compile"].split()[0] in ("on", "off")


def test_info_names_the_compile_speedup_switch(tmp_path):
    from refraster import _compile_speed
    env = dict(os.environ, REFRASTER_COMPILE_SPEEDUP="0")
    rows = dict(line.split(":", 1) for line in _run("info", env=env).stdout.splitlines())
    assert rows["fast compile"].strip() == "off (REFRASTER_COMPILE_SPEEDUP=0)"
    if _compile_speed.check() is None:
        env["REFRASTER_COMPILE_SPEEDUP"] = "1"
        rows = dict(line.split(":", 1) for line in _run("info", env=env).stdout.splitlines())
        assert rows["fast compile"].split()[0] == "on"


def test_info_names_the_output_pool_and_its_switch():
    env = {k: v for k, v in os.environ.items() if k != "REFRASTER_POOL_MB"}
    rows = dict(line.split(":", 1) for line in _run("info", env=env).stdout.splitlines())
    assert rows["output pool"].strip().startswith("up to 256 MiB")
    env["REFRASTER_POOL_MB"] = "0"
    rows = dict(line.split(":", 1) for line in _run("info", env=env).stdout.splitlines())
    assert rows["output pool"].strip().startswith("off (REFRASTER_POOL_MB=0")


def test_info_default_cache_is_beside_the_modules():
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    proc = _run("info", env=env)
    assert proc.returncode == 0, proc.stderr
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("kernel cache:"))
    package = Path(refraster.__file__).parent
    assert line == (f"kernel cache:    {package / 'raster' / '__pycache__'} "
                    "[Numba default: __pycache__ beside each module]")


def test_llvmpipe_probe_survives_hang_and_crash(monkeypatch):
    monkeypatch.setattr(cli, "_EGL_PROBE", "import time; time.sleep(30)")
    ok, detail = cli.llvmpipe_status(timeout=1.0)
    assert not ok and "did not answer" in detail
    monkeypatch.setattr(cli, "_EGL_PROBE", "import os; os.abort()")
    ok, detail = cli.llvmpipe_status(timeout=30.0)
    assert not ok
    monkeypatch.setattr(cli, "_EGL_PROBE", "raise RuntimeError('no EGL display')")
    assert cli.llvmpipe_status(timeout=30.0) == (False, "RuntimeError: no EGL display")


# ---------------------------------------------------------------------------------------------
# gallery page

class _StrictHTML(html.parser.HTMLParser):
    """Checks what a browser would forgive: every non-void element closed in order, one
    doctype, image sources relative and present."""

    VOID = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self, root):
        super().__init__()
        self.root, self.stack, self.images, self.problems, self.doctype = root, [], [], [], 0

    def handle_decl(self, decl):
        self.doctype += decl.lower() == "doctype html"

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            src = attrs.get("src", "")
            self.images.append(src)
            if re.match(r"^[a-z]+:|^/", src):
                self.problems.append(f"non-relative image {src}")
            elif not (self.root / unquote(src)).is_file():
                self.problems.append(f"missing image {src}")
            if not attrs.get("alt"):
                self.problems.append(f"image without alt {src}")
        for key in ("href", "src"):
            if key in attrs and re.match(r"^(https?:)?//", attrs[key]):
                self.problems.append(f"external resource {attrs[key]}")
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        if not self.stack or self.stack.pop() != tag:
            self.problems.append(f"misnested </{tag}>")


def _check_page(index):
    parser = _StrictHTML(index.parent)
    parser.feed(index.read_text(encoding="utf-8"))
    parser.close()
    if parser.stack:
        parser.problems.append(f"unclosed {parser.stack}")
    if parser.doctype != 1:
        parser.problems.append("missing <!DOCTYPE html>")
    return parser


def test_page_checker_can_fail(tmp_path):
    page = tmp_path / "index.html"
    page.write_text('<!DOCTYPE html><html><body><div><img src="nope.png" alt="x">'
                    '<img src="https://example.com/a.png"></body></html>')
    problems = " | ".join(_check_page(page).problems)
    for needle in ("missing image nope.png", "external resource", "misnested </body>",
                   "image without alt"):
        assert needle in problems


class _FakeSection:
    def __init__(self, name, render):
        self.__name__ = f"refraster.gallery.{name}"
        self.render = render


def test_gallery_section_failure_is_reported_and_page_still_written(tmp_path, monkeypatch,
                                                                    capsys):
    from refraster.io import write_png

    def good(out_dir, *, quick=False):
        write_png(out_dir / "good" / "a b.png", np.zeros((4, 6)))
        return [Item("good", "good/a b.png", "a <grey> picture")]

    def broken(out_dir, *, quick=False):
        raise ValueError("the kernel exploded")

    def liar(out_dir, *, quick=False):
        return [Item("liar", "liar/never.png", "never written")]

    sections = [("Good", _FakeSection("good", good)), ("Broken", _FakeSection("broken", broken)),
                ("Liar", _FakeSection("liar", liar))]
    monkeypatch.setattr("refraster.gallery.section_modules", lambda: iter(sections))
    assert cli.main(["gallery", "--out", str(tmp_path), "-q"]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1
    assert "2 gallery section(s) failed: broken (ValueError: the kernel exploded)" in lines[0]
    assert "liar" in lines[0]
    page = _check_page(tmp_path / "index.html")
    assert page.problems == [] and page.images == ["good/a%20b.png"]
    text = (tmp_path / "index.html").read_text()
    assert "a &lt;grey&gt; picture" in text and "the kernel exploded" in text


# ---------------------------------------------------------------------------------------------
# the quick start on a clean copy

def _clean_copy(dest, *, kernel_cache):
    """The files a fresh clone would have (tracked + untracked, not ignored), or a plain copy
    without caches when this is not a git checkout. With ``kernel_cache``, also this checkout's
    Numba cache files (``__pycache__/*.nbi, *.nbc``): copied with their sources' timestamps they
    stay valid, so the copy loads kernels instead of compiling them."""
    if (REPO / ".git").exists() and shutil.which("git"):
        listed = subprocess.run(
            ["git", "-C", str(REPO), "ls-files", "-z", "--cached", "--others",
             "--exclude-standard"], capture_output=True, check=True).stdout
        files = [REPO / rel for rel in filter(None, listed.decode().split("\0"))]
    else:
        skip = {"__pycache__", ".pytest_cache", ".hypothesis", "gallery", ".git"}
        files = [p for p in REPO.rglob("*") if not skip & set(p.relative_to(REPO).parts)]
    if kernel_cache:
        files += [p for p in (REPO / "refraster").rglob("__pycache__/*")
                  if p.suffix in (".nbi", ".nbc")]
    for src in files:
        if src.is_file():
            target = dest / src.relative_to(REPO)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, target)
    return dest


def _env_without_overrides():
    return {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}


@pytest.fixture(scope="module")
def quick_gallery(tmp_path_factory):
    """`refraster gallery --out gallery --quick` run in a clean copy of the repository.

    Under CI=true the copy compiles every kernel afresh, as a new clone does. Locally, to stay
    within the test time budget, the copy takes along whatever kernels this checkout has
    already compiled; the cold start itself is measured by ``benchmarks/cold_start.py``.
    """
    copy = _clean_copy(tmp_path_factory.mktemp("clone"), kernel_cache=not IN_CI)
    proc = _run("gallery", "--out", "gallery", "--quick", cwd=copy, env=_env_without_overrides(),
                timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return copy, proc


def test_quick_start_on_a_clean_copy(quick_gallery):
    copy, proc = quick_gallery
    gallery = copy / "gallery"
    index = gallery / "index.html"
    assert index.is_file()
    page = _check_page(index)
    assert page.problems == []
    pngs = sorted(p.relative_to(gallery).as_posix() for p in gallery.rglob("*.png"))
    assert len(pngs) >= 32 and sorted(page.images) == pngs
    for name in ("crank", "building", "nested_shells_cut"):
        for channel in ("shaded", "depth", "normal", "prim_id"):
            image = iio.imread(gallery / "basic" / f"{name}_{channel}.png")
            assert image.shape[:2] == (96, 128) and image.std() > 0
    # the code that ran was the copy's
    where = subprocess.run([sys.executable, "-c", "import refraster; print(refraster.__file__)"],
                           cwd=copy, env=_env_without_overrides(), capture_output=True,
                           text=True, check=True).stdout.strip()
    assert Path(where).is_relative_to(copy)
    # the second quick-start command: the test suite collects on the clean copy
    collect = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                              "-p", "no:cacheprovider"], cwd=copy, env=_env_without_overrides(),
                             capture_output=True, text=True, timeout=600,
                             stdin=subprocess.DEVNULL)
    assert collect.returncode == 0, collect.stdout[-2000:] + collect.stderr[-2000:]
    assert re.search(r"\d+ tests? collected", collect.stdout)


# ---------------------------------------------------------------------------------------------
# headless Chromium

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--enable-logging=stderr", "--v=0",
                  "--virtual-time-budget=10000", "--hide-scrollbars"]

# Appended to a copy of the page: reports, once everything has loaded, which images failed.
_PROBE = """<script>
window.addEventListener("load", function () {
  var images = Array.prototype.slice.call(document.images);
  var broken = images.filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
                     .map(function (i) { return i.getAttribute("src"); });
  console.log("REFRASTER-IMAGES " + JSON.stringify({total: images.length, broken: broken}));
});
</script>
"""
_CONSOLE = re.compile(r":CONSOLE[:(]\d+\)?\] \"(.*)\", source: (.*)$")


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if IN_CI:
            pytest.fail("CI=true but chromium is not installed (.ci/run installs it)")
        pytest.skip("chromium is not installed")
    return exe


def _browse(page, tmp, shot):
    """Open ``page`` (through a probed copy beside it) and return
    ``(image report, other console messages)``; save a screenshot to ``shot``."""
    probed = page.with_name("_probed_" + page.name)
    text = page.read_text(encoding="utf-8")
    assert "</body>" in text
    probed.write_text(text.replace("</body>", _PROBE + "</body>"), encoding="utf-8")
    try:
        proc = subprocess.run(
            [_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={tmp / 'chromium-profile'}",
             f"--screenshot={shot}", "--window-size=1280,2400", probed.as_uri()],
            capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL)
    finally:
        probed.unlink()
    messages = [m.group(1) for m in map(_CONSOLE.search, proc.stderr.splitlines()) if m]
    reports = [json.loads(m.split(" ", 1)[1]) for m in messages
               if m.startswith("REFRASTER-IMAGES ")]
    others = [m for m in messages if not m.startswith("REFRASTER-IMAGES ")]
    assert len(reports) == 1, proc.stderr[-3000:]
    return reports[0], others


def test_gallery_page_in_headless_chromium(quick_gallery, tmp_path):
    copy, _ = quick_gallery
    index = copy / "gallery" / "index.html"
    shot = tmp_path / "gallery.png"
    report, console = _browse(index, tmp_path, shot)
    assert console == []
    assert report["broken"] == []
    assert report["total"] == len(_check_page(index).images) >= 32
    image = iio.imread(shot)
    assert image.shape[:2] == (2400, 1280)
    # the screenshot shows pictures, not a blank page: many distinct colours
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 500


_FIRST_SCREEN = """JSON.stringify((function () {
  var vh = window.innerHeight, vw = window.innerWidth;
  function seen(el) { var r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0 && r.top >= 0 && r.left >= 0 && r.bottom <= vh &&
           r.right <= vw; }
  var toc = document.getElementById("toc");
  var papers = toc ? Array.prototype.map.call(toc.querySelectorAll("ol > li > a"),
                                              function (a) { return a.textContent; }) : [];
  var figLinks = toc ? toc.querySelectorAll(".figs a").length : 0;
  var sections = Array.prototype.map.call(document.querySelectorAll("main section h2"),
                                          function (h) { return h.textContent; });
  var shown = Array.prototype.filter.call(document.querySelectorAll("main figure img"),
    function (i) { return seen(i) && i.complete && i.naturalWidth > 0; })
    .map(function (i) { return {src: i.getAttribute("src"),
                                headline: i.parentNode.className === "headline",
                                section: i.closest("section").id}; });
  var firstPaper = document.querySelector("main section .paper");
  return {tocSeen: !!toc && seen(toc.querySelector("ol")), papers: papers, figLinks: figLinks,
          sections: sections, shown: shown,
          citationSeen: !!firstPaper && seen(firstPaper)};
})())"""


def first_screen(index, tmp):
    """What a 1280×800 browser window shows of the gallery page before any scrolling."""
    if not Path("/usr/bin/chromium").exists():
        _chromium()     # skips locally, fails under CI=true
    from chromium_cdp import Browser
    with Browser(tmp / "cdp", width=1280, height=800) as browser:
        browser.open(index.as_uri())
        return json.loads(browser.js(_FIRST_SCREEN)), browser.screenshot()


def _is_papers_first(screen):
    """The first screen holds the table of contents by paper and figure and a technique's
    headline figure with its citation; the plain G-buffer section comes last."""
    return (screen["tocSeen"] and len(screen["papers"]) >= 5 and screen["figLinks"] >= 20
            and screen["sections"][-1].startswith("Canonical solids")
            and any(s["headline"] and s["section"] != "s-basic" for s in screen["shown"])
            and screen["citationSeen"])


def test_gallery_first_screen_shows_the_papers(quick_gallery, tmp_path):
    copy, _ = quick_gallery
    index = copy / "gallery" / "index.html"
    screen, shot = first_screen(index, tmp_path)
    assert _is_papers_first(screen), screen
    assert screen["shown"][0]["headline"] and screen["shown"][0]["section"] == "s-clipsurface"
    assert len(np.unique(shot.reshape(-1, 3), axis=0)) > 200     # pictures, not a blank page
    # the other direction: the old page (G-buffer pictures first, no table of contents) fails
    old = index.with_name("old.html")
    text = index.read_text(encoding="utf-8")
    body = text[text.index("<main>"):]
    sections = re.findall(r"<section.*?</section>", body, flags=re.S)
    old.write_text(text[:text.index("<nav")] + "<main>" + sections[-1] + "".join(sections[:-1])
                   + "</main></body></html>", encoding="utf-8")
    old_screen, _ = first_screen(old, tmp_path / "old")
    assert not _is_papers_first(old_screen)


def test_chromium_check_fails_on_broken_image_and_script_error(tmp_path):
    from refraster.io import write_png
    write_png(tmp_path / "ok.png", np.full((8, 8, 3), 0.5))
    page = tmp_path / "index.html"
    page.write_text('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>t</title>'
                    '</head><body><img src="ok.png" alt="ok"><img src="missing.png" alt="gone">'
                    '<script>console.error("boom");</script></body></html>')
    report, console = _browse(page, tmp_path, tmp_path / "shot.png")
    assert report == {"total": 2, "broken": ["missing.png"]}
    assert console == ["boom"]


# ---------------------------------------------------------------------------------------------
# the "basic" gallery section

def test_basic_section_is_complete_and_deterministic(tmp_path):
    from refraster.gallery import basic
    from refraster.scenes import SOLIDS
    first = basic.render(tmp_path / "a", quick=True)
    second = basic.render(tmp_path / "b", quick=True)
    assert first == second
    stems = [s for name in SOLIDS
             for s in ([name, "nested_shells_cut"] if name == "nested_shells" else [name])]
    assert [i.filename for i in first] == [f"basic/{s}_{c}.png" for s in stems
                                           for c in ("shaded", "depth", "normal", "prim_id")]
    assert all(i.section == "basic" for i in first)
    for item in first:
        a = (tmp_path / "a" / item.filename).read_bytes()
        assert a == (tmp_path / "b" / item.filename).read_bytes(), item.filename
        assert iio.imread(tmp_path / "a" / item.filename).shape[:2] == basic.QUICK_SIZE[::-1]


def test_basic_channel_images_hand_worked():
    from refraster.gallery import basic
    ids = np.array([[-1, 0, 1, 1]], np.int32)
    img = basic.id_image(ids)
    assert img.shape == (1, 4, 3)
    np.testing.assert_array_equal(img[0, 0], 1.0)  # background white
    np.testing.assert_allclose(img[0, 1], 0.2)  # hash(0) = 0 → the darkest colour
    np.testing.assert_array_equal(img[0, 2], img[0, 3])
    # 2654435761 = 0x9E3779B1: bytes (low first) B1, 79, 37
    np.testing.assert_allclose(img[0, 2], 0.2 + 0.7 * np.array([0xB1, 0x79, 0x37]) / 255.0,
                               rtol=1e-6)
    # depth and normal images of a real render: nearest visible pixel black, farthest 0.85
    mesh = solids.cube()
    fb = refraster.render(mesh, **frame_bounds(mesh.bounds, width=48, height=36).kwargs)
    d = basic.depth_image(fb)
    assert d[fb.mask].min() == 0.0 and d[fb.mask].max() == pytest.approx(0.85)
    assert np.all(d[~fb.mask] == 1.0)
    n = basic.normal_image(fb)
    np.testing.assert_allclose(n[fb.mask], 0.5 * (fb.normal[fb.mask] + 1.0))
    assert np.all(n[~fb.mask] == 1.0)
