"""The pytest plugin `refraster.testing` used from a separate test project (issue 11)."""

import os
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

from refraster import golden

PROJECT_TESTS = '''
import numpy as np


def test_correct_candidate(golden):
    ref = golden.reference("render_cube")
    golden.check("render_cube", {"prim_id": ref["prim_id"], "depth": ref["depth"],
                                 "color": ref["color"]})


def test_wrong_candidate(golden):
    ref = golden.reference("render_cube")
    ids = ref["prim_id"].copy()
    rows, cols = np.nonzero(ids >= 0)
    ids[rows[len(rows) // 2], cols[len(cols) // 2]] = -1    # a hole in a "must" region
    golden.check("render_cube", {"prim_id": ids})
'''


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    root = tmp_path_factory.mktemp("plugin")
    golden.generate(root / "golden", ["render_cube"])
    (root / "project").mkdir()
    (root / "project" / "test_backend.py").write_text(PROJECT_TESTS)
    return root


def run(project, *args):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    return subprocess.run(
        [sys.executable, "-m", "pytest", *args, "--refraster-goldens", str(project / "golden"),
         "-p", "no:cacheprovider", "-q", "-rf", f"--basetemp={project / 'tmp'}",
         "test_backend.py"],
        cwd=project / "project", capture_output=True, text=True, timeout=120, env=env)


def test_plugin_from_a_separate_project(project):
    proc = run(project, "-p", "refraster.testing")
    out = proc.stdout
    assert proc.returncode == 1, out + proc.stderr
    assert "1 failed, 1 passed" in out
    fail = next(line for line in out.splitlines() if "golden.check('render_cube') failed" in line)
    # the message names the scene, the buffer, the metric and the HTML report
    assert "render_cube/prim_id: coverage = 1 > 0" in out, out
    assert "(tolerant)" in fail
    report = out.split("HTML report: ")[1].split()[0]
    assert report.endswith("index.html") and os.path.isfile(report)
    assert str(project / "tmp") in report


def test_entry_point_is_installed(project):
    names = {ep.value for ep in entry_points(group="pytest11")}
    assert "refraster.testing" in names, "run `pip install -e . --no-deps` after editing pyproject"
    proc = run(project)   # no -p: the pytest11 entry point loads the plugin
    assert "1 failed, 1 passed" in proc.stdout, proc.stdout + proc.stderr


def test_missing_option_is_a_clear_error(project, tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "refraster.testing", "-q",
                           "-p", "no:cacheprovider", f"--basetemp={tmp_path / 'b'}",
                           "test_backend.py::test_correct_candidate"],
                          cwd=project / "project", capture_output=True, text=True, timeout=120,
                          env=env)
    assert proc.returncode == 1
    assert "needs --refraster-goldens DIR" in proc.stdout
