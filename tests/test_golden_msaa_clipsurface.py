"""Multisampled clip-surface goldens (issue 44, item 3): the building cut by a Perlin clip
surface with caps at 4 samples, at sample rate and at pixel rate, with per-sample allowances
derived from the single-sample clip-surface ones (``refraster.golden.allowances.samples``).
refraster's own frame passes both; the planted fault "discard at pixel rate where sample rate
is declared" (the candidate of the sample-rate golden rendered at pixel rate) fails naming a
per-sample id buffer."""

from __future__ import annotations

import json
import re
import shutil

import pytest

from conftest import generate_gold
from refraster.golden.compare.run import compare
from refraster.golden.io.package import npz_bytes
from refraster.golden.io.read import PATTERN_FILE
from refraster.golden.scenes import available_scenes

SCENES = ["msaa4_clipsurface_sample", "msaa4_clipsurface_pixel",
          "msaa4_clipsurface_centroid"] if available_scenes() else []


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "msaa_clip", SCENES)


def _candidate(gold, tag, names, **changes):
    """refraster's frame of each scene as a candidate, rendered with the raster fields
    ``changes`` instead of the scene's (its stated pattern the scene's)."""
    from refraster.golden.msaa_clip_scenes import _RATES, _clip_msaa_scene
    out = gold / f"cand_{tag}"
    shutil.rmtree(out, ignore_errors=True)
    for name in names:
        raster, _ = _RATES[name]
        scene = _clip_msaa_scene({**raster, **changes})
        d = out / name
        d.mkdir(parents=True)
        (d / "buffers.npz").write_bytes(npz_bytes(scene.buffers))
        (d / PATTERN_FILE).write_text(json.dumps(scene.parameters["sample_pattern"]))
    return out


def test_the_golden_declares_its_pattern_and_rate_and_stores_every_sample(gold):
    manifest = json.loads((gold / "golden" / "manifest.json").read_text())
    for name, interp in zip(SCENES, ("sample", "center", "centroid")):
        entry = manifest["scenes"][name]
        assert entry["parameters"]["technique"]["sample_pattern"] == {
            "samples": 4, "positions": [[6, 2], [14, 6], [2, 10], [10, 14]]}
        scene = json.loads((gold / "golden" / name / "package" / "scene.json").read_text())
        assert scene["raster"]["samples"] == 4
        assert scene["raster"].get("interpolation", "center") == interp
        for s in range(4):
            spec = entry["buffers"][f"sample{s}_prim_id"]["tolerant"]
            assert spec["sample"] == s and spec["checks"] == ["clip"]
        assert "color" not in entry["buffers"]


def test_refraster_passes_its_own_multisampled_clip_goldens(gold):
    cand = _candidate(gold, "own", SCENES)
    r = compare(gold / "golden", cand, mode="tolerant")
    assert r.exit_code == 0, r.failures()[:5]
    assert compare(gold / "golden", cand, mode="exact").exit_code == 0


def test_discard_at_pixel_rate_where_sample_rate_is_declared_fails(gold):
    name = "msaa4_clipsurface_sample"
    cand = _candidate(gold, "pixel_rate", [name], interpolation="center")
    r = compare(gold / "golden", cand, mode="tolerant", scenes=[name])
    assert r.exit_code == 1
    lines = r.failures()
    assert any(re.match(rf"{name}/sample[0-9]_(prim_id|object_id|cap_mask): ", line)
               for line in lines), lines[:5]


def test_sample_rate_where_pixel_rate_is_declared_fails(gold):
    name = "msaa4_clipsurface_pixel"
    cand = _candidate(gold, "sample_rate", [name], interpolation="sample")
    r = compare(gold / "golden", cand, mode="tolerant", scenes=[name])
    assert r.exit_code == 1
    assert any(re.match(rf"{name}/sample[0-9]_(prim_id|object_id): clip", line)
               for line in r.failures()), r.failures()[:5]


def test_the_centroid_golden_fails_the_pixel_centre_and_admits_the_samples(gold):
    """The centroid golden admits any point inside both the pixel and the primitive: the
    decision at the pixel centre (outside the primitive on partly covered pixels) fails it,
    naming a per-sample id buffer; the decision at each covered sample (a point inside both)
    passes — per-sample allowances do not see that sample rate splits a fragment's one
    decision (docs/tolerance.md, "Clip surfaces at a centroid point")."""
    name = "msaa4_clipsurface_centroid"
    cand = _candidate(gold, "centroid_center", [name], interpolation="center")
    r = compare(gold / "golden", cand, mode="tolerant", scenes=[name])
    assert r.exit_code == 1
    assert any(re.match(rf"{name}/sample[0-9]_(prim_id|object_id): clip", line)
               for line in r.failures()), r.failures()[:5]
    cand = _candidate(gold, "centroid_sample", [name], interpolation="sample")
    assert compare(gold / "golden", cand, mode="tolerant", scenes=[name]).exit_code == 0
