import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

# The same examples on every run and machine: a property test that passes here passes in CI
# (a new counter-example is found by widening a test, not by luck).
settings.register_profile("refraster", derandomize=True, print_blob=True)
settings.load_profile("refraster")

IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require(module_name, reason=None):
    """Import an optional oracle; skip the test when it is missing, fail under CI=true."""
    try:
        return importlib.import_module(module_name)
    except Exception as exc:  # ImportError, or an EGL/driver failure inside the import
        msg = reason or f"optional oracle {module_name!r} is not available: {exc}"
        if IN_CI:
            pytest.fail(f"CI=true but {msg}")
        pytest.skip(msg)


@pytest.fixture
def oracle():
    return require


LLVMPIPE_BACKEND = Path(__file__).with_name("golden_llvmpipe_backend.py")


def llvmpipe_frames(gold, out, *, timeout=600):
    """Render every scene of the golden ``gold`` with llvmpipe into the candidate directory
    ``out`` (``tests/golden_llvmpipe_backend.py`` in an isolated interpreter, so that it cannot
    import refraster); returns the backend's JSON line (``renderer``, ``scenes``). Skips when
    EGL is missing locally, fails under CI=true or on any other backend failure."""
    proc = subprocess.run([sys.executable, "-I", str(LLVMPIPE_BACKEND), str(gold), str(out)],
                          capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        if IN_CI or "EGL" not in proc.stderr:
            pytest.fail(f"llvmpipe backend failed: {proc.stderr[-2000:]}")
        pytest.skip(f"llvmpipe backend failed: {proc.stderr[-500:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def gl_backend_or_skip():
    """A :class:`refraster.gl.driver.Backend` on a headless context; skips without one (a
    failure under ``CI=true``)."""
    from refraster.gl.driver import Backend, GLUnavailable
    try:
        return Backend()
    except GLUnavailable as exc:
        if IN_CI:
            pytest.fail(f"CI=true but the gl backend has no context: {exc}")
        pytest.skip(f"no headless OpenGL context (EGL/llvmpipe): {exc}")
