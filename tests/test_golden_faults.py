"""Goldens with teeth (1), item 4: the fault-injection harness over the plain-rendering scenes.

For every registered ``render_*`` scene and every buffer, an in-domain fault is injected at
every covered pixel (``tests/faults.py``) and the tolerant check must fail at that pixel
wherever the allowance does not admit the fault. The aims of the issue:

* ≥ 99 % caught where the allowance is narrower than the fault — asserted for every scene;
* ≤ 5 % of covered pixels whose allowance admits the fault — asserted where it holds today;
  the scenes where the id "may" differ over more than 5 % of covered pixels (dense meshes:
  the crank's sub-pixel triangles, the fluted column, curved surfaces whose every pixel is near
  an edge) are strict xfails until the per-face may-sets of item 3 replace the id-may region.

Set ``REFRASTER_FAULT_TABLE=FILE`` to write the measured table (Markdown) for
``docs/tolerance.md``.
"""

import os
from pathlib import Path

import numpy as np
import pytest

import faults
from refraster import golden

PLAIN = [n for n, e in golden.available_scenes().items() if e.technique == "render"]
#: Scenes whose id-may region admits the fault at more than 5 % of covered pixels today
#: (measured; item 3 of the issue is what brings them under the aim).
OVER_AIM = {"render_icosphere_smooth", "render_torus_ortho", "render_fluted_column",
            "render_nested_shells", "render_building", "render_crank", "render_multi_draw"}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("faults") / "g"
    golden.generate(out, PLAIN)
    return out


@pytest.fixture(scope="module")
def tables(gold):
    return {scene: faults.fault_table(gold, scene) for scene in PLAIN}


def test_write_table(tables):
    rows = [(s, k, r) for s, t in tables.items() for k, r in t.items()]
    text = faults.format_table(rows)
    path = os.environ.get("REFRASTER_FAULT_TABLE")
    if path:
        Path(path).write_text(text + "\n")
    assert len(rows) == sum(len(t) for t in tables.values()) and "| render_cube |" in text


@pytest.mark.parametrize("scene", PLAIN)
def test_faults_outside_the_allowance_are_caught(tables, scene):
    for key, r in tables[scene].items():
        assert r["covered"] > 0
        share = r["caught"] / r["eligible"] if r["eligible"] else 1.0
        assert share >= 0.99, (scene, key, r["caught"], r["eligible"], r["missed"][:10])


@pytest.mark.parametrize("scene", [
    pytest.param(s, marks=pytest.mark.xfail(
        reason="the id-may region admits any value; per-face may-sets (item 3) not built"))
    if s in OVER_AIM else s for s in PLAIN])
def test_allowance_admits_few_faults(tables, scene):
    for key, r in tables[scene].items():
        assert r["admitted"] <= 0.05 * r["covered"], (scene, key, r["admitted"], r["covered"])


def test_harness_sees_a_blind_check(gold, monkeypatch):
    """The other direction: a checker that forgives every depth fault (a skipped interval
    check) is reported as missing them; the other buffers stay caught."""
    from refraster.golden import allowance

    real = allowance.tolerant_metrics

    def blind(key, reference, candidate, kind, spec, arrays, **kw):
        metrics, checks, images = real(key, reference, candidate, kind, spec, arrays, **kw)
        if key != "depth":
            return metrics, checks, images
        images = dict(images, over=np.zeros_like(images["over"]))
        return metrics, [dict(c, ok=True) for c in checks], images

    monkeypatch.setattr(faults, "tolerant_metrics", blind)
    t = faults.fault_table(gold, "render_cube", buffers=["depth", "normal"])
    assert t["depth"]["caught"] == 0 < t["depth"]["eligible"]
    assert t["normal"]["caught"] == t["normal"]["eligible"] > 0


def test_faults_are_in_domain_and_where_asked():
    rng = np.random.default_rng(1)
    depth = np.full((3, 4), 0.9, np.float32)
    f = faults.inject("depth", "unorm", depth, [(1, 2)], rng, None)
    assert f[1, 2] == pytest.approx(2.0 - 1.15) and (f != depth).sum() == 1
    n = np.zeros((3, 4, 3))
    n[..., 2] = 1.0
    f = faults.inject("normal", "snorm", n, [(0, 0)], rng, None)
    assert np.linalg.norm(f[0, 0]) == pytest.approx(1.0)
    assert np.degrees(np.arccos(f[0, 0] @ n[0, 0])) == pytest.approx(20.0)
    ids = np.zeros((3, 4), np.int32)
    f = faults.inject("prim_id", "id", ids, [(2, 3)], rng, (-1, 5))
    assert 1 <= f[2, 3] <= 5
    b = np.tile([0.5, 0.3, 0.2], (3, 4, 1))
    f = faults.inject("barycentric", "unorm", b, [(1, 1)], rng, None)
    assert f[1, 1].sum() == pytest.approx(1.0) and f[1, 1].min() >= 0.0
    assert np.abs(f[1, 1] - b[1, 1]).max() == pytest.approx(0.25)
