"""The HTML report of a golden compare opens in headless Chromium with every image loaded and
no console errors."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import IN_CI
from refraster import golden

CHROMIUM = Path("/usr/bin/chromium")

# Injected (by the test only) into a copy of the page: records load errors of any element and,
# once the page has loaded, how many images decoded, into the title that --dump-dom prints.
CHECKER = """<script>
window.__errors = [];
window.addEventListener("error", e => window.__errors.push(
    (e.target && e.target.src) || e.message || "error"), true);
window.addEventListener("load", () => {
  const imgs = [...document.images];
  const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
  document.title = "CHECK " + JSON.stringify({images: imgs.length, loaded: ok,
                                               errors: window.__errors});
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
    assert len(srcs) == 8 * 4 + 1                    # 4 pictures per buffer, FLIP for colour
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
    assert status["images"] == 33 and status["loaded"] == 33 and status["errors"] == []
    assert console == []
    # the check can fail: a page with a missing picture is caught
    broken = rep / "_broken.html"
    broken.write_text(page.read_text().replace('src="img/', 'src="img/missing_', 1).replace(
        "</body>", "<script>console.error('planted')</script></body>"))
    status, console = page_check(broken, tmp_path / "u3")
    assert status["loaded"] == 32 and len(status["errors"]) == 1
    assert any("planted" in line for line in console)
    page.unlink()
    broken.unlink()
    shutil.copy(shot, root / "screenshot.png")
