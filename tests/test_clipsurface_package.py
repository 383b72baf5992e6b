"""The clip-surface package: its public names importable from ``refraster.clipsurface``,
and the modules it replaced (``refraster.capping``, ``refraster.offsetmaps``) gone: their
code lives in ``refraster.clipsurface.capping`` and ``refraster.clipsurface.offsetmaps``
only. Its imports (no circle, the core never imports it) are checked with every other
module's in tests/test_architecture.py."""

import importlib

import pytest

from conftest import package_spec

PUBLIC_NAMES = ["Caps", "ClipSurface", "ReliefClipPlane", "ClippedFramebuffer", "as_surfaces",
                "clip_function", "clip_mask", "render_clipped", "clipped_at",
                "ORTHOGONALITY_TOLERANCE"]


def test_the_package_exports_its_public_names():
    mod = importlib.import_module("refraster.clipsurface")
    for name in PUBLIC_NAMES + list(mod.__all__):
        assert hasattr(mod, name), f"refraster.clipsurface.{name}"


@pytest.mark.parametrize("module", ["refraster.capping", "refraster.offsetmaps"])
def test_the_removed_re_export_modules_are_gone(module):
    assert package_spec(module) is None, f"{module} is back"
    assert package_spec(module.replace("refraster.", "refraster.clipsurface.")) is not None
