"""The clip-surface package: its public names importable from ``refraster.clipsurface``,
and the modules it replaced (``refraster.capping``, ``refraster.offsetmaps``) gone: their
code lives in ``refraster.clipsurface.capping`` and ``refraster.clipsurface.offsetmaps``
only. Its imports (no circle, the core never imports it) are checked with every other
module's in tests/test_architecture.py."""

import importlib
import importlib.machinery

import pytest

PUBLIC_NAMES = ["Caps", "ClipSurface", "ReliefClipPlane", "ClippedFramebuffer", "as_surfaces",
                "clip_function", "clip_mask", "render_clipped", "clipped_at",
                "ORTHOGONALITY_TOLERANCE"]


def test_the_package_exports_its_public_names():
    mod = importlib.import_module("refraster.clipsurface")
    for name in PUBLIC_NAMES + list(mod.__all__):
        assert hasattr(mod, name), f"refraster.clipsurface.{name}"


def _package_spec(module):
    """The module's spec as found in its package's own directories (``None``: not there). Asked
    of the package's path, not of ``sys.meta_path``: an editable install of another checkout
    adds a finder there that answers with that checkout's files."""
    parent = module.rpartition(".")[0]
    return importlib.machinery.PathFinder.find_spec(
        module, importlib.import_module(parent).__path__)


@pytest.mark.parametrize("module", ["refraster.capping", "refraster.offsetmaps"])
def test_the_removed_re_export_modules_are_gone(module):
    assert _package_spec(module) is None, f"{module} is back"
    assert _package_spec(module.replace("refraster.", "refraster.clipsurface.")) is not None
