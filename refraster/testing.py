"""A pytest plugin: check another backend's buffers against refraster goldens in one call.

Enable it with ``-p refraster.testing`` or, once refraster is installed, automatically (entry
point ``pytest11``)::

    # test_my_backend.py
    def test_cube(golden):
        buffers = my_gpu_render(golden.package("render_cube"))   # scene.json + PLY meshes
        golden.check("render_cube", {"depth": depth, "prim_id": ids, "color": rgb})

    $ pytest --refraster-goldens path/to/golden

``golden.check(scene, buffers)`` compares the given buffers (a dict name → array; a subset of
the scene's is fine) against the golden directory — tolerant (coverage masks and value
intervals) when the golden stores allowances, bit-exact otherwise — and fails the test with a
message naming the scene, the buffer, the metric and the HTML report it wrote into the test's
``tmp_path``.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

__all__ = ["GoldenFixture", "pytest_addoption", "golden"]

OPTION = "--refraster-goldens"


def pytest_addoption(parser):
    group = parser.getgroup("refraster", "refraster golden images")
    group.addoption(OPTION, metavar="DIR", default=None,
                    help="golden directory written by `refraster golden generate` for the "
                         "`golden` fixture")
    parser.addini("refraster_goldens", "golden directory for the `golden` fixture (the "
                  f"{OPTION} option wins)", default=None)


class GoldenFixture:
    """What the ``golden`` fixture returns (one per test)."""

    def __init__(self, golden_dir, tmp_path):
        from .golden.compare.run import GoldenError, has_allowances, load_manifest
        self.dir = Path(golden_dir)
        try:
            self.manifest = load_manifest(self.dir)
        except GoldenError as exc:
            raise pytest.UsageError(f"{OPTION}: {exc}") from None
        self._has_allowances = has_allowances
        self._tmp = Path(tmp_path)
        self._count = itertools.count()

    @property
    def scenes(self):
        """Names of the golden's scenes."""
        return sorted(self.manifest["scenes"])

    def package(self, scene):
        """Directory of ``scene``'s package (``scene.json``, ``meshes/``, ``maps/``), validated
        again on every call: ``scene.json`` against its schema, every file it names listed in
        the manifest and matching its sha256 (:func:`refraster.golden.io.read.check_package`)."""
        from .golden.io.read import GoldenError, check_package
        entry = self._entry(scene)
        try:
            check_package(self.dir, self.manifest, scene)
        except GoldenError as exc:
            pytest.fail(f"golden.package({scene!r}): {exc}", pytrace=False)
        return (self.dir / entry["package"]).parent

    def reference(self, scene):
        """The golden buffers of ``scene`` (dict name → array)."""
        from .golden.io.read import GoldenError, reference_buffers
        self._entry(scene)
        try:
            return reference_buffers(self.dir, self.manifest, scene)
        except GoldenError as exc:
            pytest.fail(f"golden.reference({scene!r}): {exc}", pytrace=False)

    def _entry(self, scene):
        if scene not in self.manifest["scenes"]:
            pytest.fail(f"golden.check: scene {scene!r} is not in {self.dir}; it has "
                        f"{self.scenes}", pytrace=False)
        return self.manifest["scenes"][scene]

    def check(self, scene, buffers, *, mode=None, tolerances=()):
        """Assert that ``buffers`` match ``scene`` of the golden.

        Parameters
        ----------
        scene : str
        buffers : dict of str → array
            Candidate buffers, ``(H, W)`` or ``(H, W, C)``, row 0 at the top.
        mode : {"tolerant", "exact"}, optional
            Default: tolerant when the golden stores allowances, else exact.
        tolerances : sequence of str
            ``[SCENE:][BUFFER.]KEY=VALUE`` overrides (:func:`refraster.golden.compare`).

        Returns
        -------
        refraster.golden.Comparison
            When it passes; otherwise the test fails.
        """
        from .golden.compare.run import GoldenError, compare
        from .golden.io.package import npz_bytes
        from .io import atomic_write_bytes
        self._entry(scene)
        if not isinstance(buffers, dict) or not buffers:
            pytest.fail("golden.check: buffers must be a non-empty dict name → array",
                        pytrace=False)
        if mode is None:
            mode = "tolerant" if self._has_allowances(self.manifest, [scene]) else "exact"
        n = next(self._count)
        cand = self._tmp / f"refraster-candidate-{n}"
        arrays = {}
        for key, value in buffers.items():
            a = np.asarray(value)
            if a.dtype == object:
                pytest.fail(f"golden.check: buffer {key!r} is not a numeric array",
                            pytrace=False)
            arrays[str(key)] = a
        atomic_write_bytes(cand / scene / "buffers.npz", npz_bytes(arrays))
        report = self._tmp / f"refraster-report-{n}"
        try:
            result = compare(self.dir, cand, report=report, mode=mode, tolerances=tolerances,
                             scenes=[scene], buffers=sorted(arrays))
        except GoldenError as exc:
            pytest.fail(f"golden.check({scene!r}): {exc}", pytrace=False)
        if result.exit_code != 0:
            index = result.report_dir / "index.html"
            lines = result.failures()
            pytest.fail(f"golden.check({scene!r}) failed ({mode}): " + "; ".join(lines[:8])
                        + (f"; … {len(lines) - 8} more" if len(lines) > 8 else "")
                        + f"\nHTML report: {index}", pytrace=False)
        return result


@pytest.fixture
def golden(request, tmp_path):
    """A :class:`GoldenFixture` on the directory given by ``--refraster-goldens DIR``."""
    where = request.config.getoption(OPTION) or request.config.getini("refraster_goldens")
    if not where:
        pytest.fail(f"the `golden` fixture needs {OPTION} DIR (or the refraster_goldens ini "
                    "option)", pytrace=False)
    return GoldenFixture(Path(str(where)).expanduser(), tmp_path)
