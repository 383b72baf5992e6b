"""Fork (issue 48 item 5, docs/reliability.md "Fork"): a process that forks after rendering
(``multiprocessing`` with the fork start method, the Linux default before Python 3.14) must get
frames from its children. Under GNU OpenMP the child was terminated at its first parallel
kernel ("fork() called from a process already using GNU OpenMP") and ``Pool.map`` never
returned. refraster depends on ``tbb``, Numba's first choice of threading layer, which is
fork-safe; a child forked from a parent that did run on GNU OpenMP gets one line
(``RuntimeError``) instead of being killed. Every run here is a child process with a timeout,
so a hang fails the test instead of hanging the run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import IN_CI, require

TESTS = Path(__file__).resolve().parent

POOL = textwrap.dedent("""
    import hashlib, json, multiprocessing as mp, sys
    sys.path.insert(0, {tests!r})
    import numba
    from conftest import camera_kw, mesh_of
    import refraster as rf
    from refraster.scenes import cube, icosphere, torus

    SCENES = {{"cube": cube, "ico": lambda: icosphere(5), "torus": torus}}
    KW = camera_kw(256, 192)

    def digest(name):
        fb = rf.render(mesh_of(SCENES[name]()), **KW)
        h = hashlib.sha256()
        for f in ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
                  "barycentric", "color"):
            h.update(getattr(fb, f).tobytes())
        return h.hexdigest()

    def child(name):
        try:
            return digest(name)
        except RuntimeError as exc:
            return "error: " + str(exc)

    if __name__ == "__main__":
        names = ["cube", "ico", "torus", "ico"]
        want = [digest(n) for n in names]   # the parent renders first: kernels launched
        with mp.get_context("fork").Pool(2) as pool:
            got = pool.map_async(child, names).get(timeout=120)
        print(json.dumps(dict(layer=numba.threading_layer(), want=want, got=got)))
""")


def _pool(env_extra=None, timeout=400):
    env = dict(os.environ, **(env_extra or {}))
    env.pop("REFRASTER_THREADS", None)
    proc = subprocess.run([sys.executable, "-c", POOL.format(tests=str(TESTS))],
                          capture_output=True, text=True, timeout=timeout, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _tbb_loads():
    """Whether Numba can load its TBB threading layer here."""
    proc = subprocess.run([sys.executable, "-c", "import numba, numpy as np\n"
                           "@numba.njit(parallel=True)\n"
                           "def f(a):\n"
                           "    for i in numba.prange(a.shape[0]):\n"
                           "        a[i] = i\n"
                           "f(np.zeros(8)); print(numba.threading_layer())"],
                          capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, NUMBA_THREADING_LAYER="tbb"))
    return proc.returncode == 0 and proc.stdout.strip() == "tbb"


@pytest.fixture(scope="module")
def tbb():
    if not _tbb_loads():
        msg = "Numba cannot load the tbb threading layer (pip install tbb)"
        if IN_CI:
            pytest.fail(f"CI=true but {msg}")
        pytest.skip(msg)


def test_an_ordinary_install_runs_on_tbb(tbb):
    """Numba's default choice, with refraster's dependencies installed, is TBB (unless the
    environment names another layer)."""
    if os.environ.get("NUMBA_THREADING_LAYER", "default").lower() not in ("default", "tbb"):
        pytest.skip("NUMBA_THREADING_LAYER names another layer")
    assert _pool()["layer"] == "tbb"


def test_a_pool_forked_after_rendering_gets_the_parents_frames(tbb):
    r = _pool({"NUMBA_THREADING_LAYER": "tbb"})
    assert r["layer"] == "tbb"
    assert r["got"] == r["want"]


def test_a_child_forked_from_gnu_openmp_gets_one_line():
    """The attack under the layer that cannot fork: the children answer with the one line
    (no child killed, the pool returns)."""
    r = _pool({"NUMBA_THREADING_LAYER": "omp"})
    if r["layer"] != "omp":
        pytest.skip("no OpenMP threading layer here")
    assert r["want"][0] != r["got"][0]
    assert set(r["got"]) == {
        "error: refraster cannot run in this process: it was forked after its parent ran "
        "Numba kernels on GNU OpenMP, which Numba terminates in a forked child; install tbb "
        "(a refraster dependency; Numba then uses it unless NUMBA_THREADING_LAYER says "
        "otherwise) or start processes with the 'spawn' or 'forkserver' method"}


def test_pytest_xdist_workers_render_and_fork(tbb, tmp_path):
    """A small pytest-xdist run (two workers), each test rendering and one forking a pool."""
    require("xdist")
    case = tmp_path / "test_xdist_case.py"
    case.write_text(textwrap.dedent(f"""
        import multiprocessing as mp, sys
        sys.path.insert(0, {str(TESTS)!r})
        import pytest
        from conftest import camera_kw, mesh_of
        import refraster as rf
        from refraster.scenes import cube, icosphere

        def _frame(n):
            return rf.render(mesh_of(icosphere(n)), **camera_kw(128, 96)).depth.tobytes()

        @pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
        def test_render(n):
            assert rf.render(mesh_of(icosphere(n)), **camera_kw(128, 96)).mask.any()

        def test_fork_inside_a_worker():
            want = _frame(5)
            with mp.get_context("fork").Pool(2) as pool:
                assert pool.map_async(_frame, [5, 5]).get(timeout=120) == [want, want]
    """))
    env = dict(os.environ, NUMBA_THREADING_LAYER="tbb")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "-p",
                           "no:cacheprovider", "--rootdir", str(tmp_path), str(case)],
                          capture_output=True, text=True, timeout=600, env=env,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert "6 passed" in proc.stdout
