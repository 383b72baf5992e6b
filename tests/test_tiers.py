"""The quick tier of the render kernels gives the full tier's bytes (``refraster._tiers``).

The digests are ``benchmarks/render_digests.json``, recorded from the full tier (17 renders:
sizes, normals, culling, depth functions, clear depth, two draw calls, float64, 4 sub-pixel
bits, top-left, near clipping, a fragment stage, ``out=`` and ``Framebuffer.reusable``); the
quick tier renders every case again and must match every buffer. The quick twins compile
once into the Numba cache (about a third of the full tier's compile).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from refraster import _tiers

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def tier():
    """Set the tier for a test; decided again by ``REFRASTER_TIER`` afterwards."""
    saved = dict(_tiers._st)
    yield _tiers.force
    _tiers._st.clear()
    _tiers._st.update(saved)


def test_quick_tier_gives_the_full_tier_s_bytes(tier):
    from benchmarks.render_digests import digests
    tier(_tiers.QUICK)
    got = digests()
    assert _tiers.state()[0] == _tiers.QUICK
    want = json.loads((REPO / "benchmarks" / "render_digests.json").read_text())
    differ = [(case, buf) for case in sorted(set(want) | set(got))
              for buf in sorted(set(want.get(case, {})) | set(got.get(case, {})))
              if want.get(case, {}).get(buf) != got.get(case, {}).get(buf)]
    assert not differ, f"quick tier differs from the full tier's digests: {differ[:8]}"


def test_quick_twins_are_serial_and_not_inlined():
    from refraster.raster.rasterizer import _fused_pass, _setup
    quick = _tiers.twin(_fused_pass)
    assert quick.py_func.__qualname__ == "_fused_pass__quick"
    assert not quick.targetoptions.get("parallel")
    helper = quick.py_func.__globals__["_setup"]
    assert helper is _tiers.twin(_setup, helper=True)
    assert helper.targetoptions.get("inline") != "always"
    assert _fused_pass.py_func.__globals__["_setup"] is _setup   # the full tier untouched


def test_kernel_follows_the_tier(tier):
    from refraster.raster.rasterizer import _fused_pass
    tier(_tiers.FULL)
    assert _tiers.kernel(_fused_pass) is _fused_pass
    assert _tiers.state() == (_tiers.FULL, "set by the program")
    tier(_tiers.QUICK)
    assert _tiers.kernel(_fused_pass) is _tiers.twin(_fused_pass)
    stand_in = lambda *a: None   # noqa: E731 (refraster.warmup's stubs pass through)
    assert _tiers.kernel(stand_in) is stand_in


def test_setting_read_from_the_environment(tier, monkeypatch):
    tier(None)
    monkeypatch.setenv("REFRASTER_TIER", "quick")
    assert _tiers.current() == _tiers.QUICK
    tier(None)
    monkeypatch.setenv("REFRASTER_TIER", "full")
    assert _tiers.current() == _tiers.FULL
    tier(None)
    monkeypatch.setenv("REFRASTER_TIER", "fast")
    with pytest.raises(ValueError, match=r"^REFRASTER_TIER: 'fast' is not one of auto, full, "
                                         r"quick$"):
        _tiers.current()
    with pytest.raises(ValueError, match="tier: 'fast'"):
        _tiers.force("fast")


def test_auto_runs_the_full_tier_when_cached_and_swaps_in_when_it_arrives(tier, monkeypatch):
    monkeypatch.delenv("REFRASTER_TIER", raising=False)
    monkeypatch.setenv("REFRASTER_TIER_SECOND", "0")   # no second process in a test
    tier(None)
    monkeypatch.setattr(_tiers, "_full_cached", lambda: True)
    assert _tiers.current() == _tiers.FULL
    assert _tiers.state()[1] == "its kernels are in the cache"
    tier(None)
    monkeypatch.setattr(_tiers, "_full_cached", lambda: False)
    assert _tiers.current() == _tiers.QUICK
    _tiers._st["next_poll"] = 0.0
    assert _tiers.current() == _tiers.QUICK   # still not in the cache
    monkeypatch.setattr(_tiers, "_full_cached", lambda: True)
    assert _tiers.current() == _tiers.QUICK   # looked less than a poll interval ago
    _tiers._st["next_poll"] = 0.0
    assert _tiers.current() == _tiers.FULL
    assert _tiers.state()[1].startswith("swapped in")
