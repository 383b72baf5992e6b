"""Golden scenes of the layered-depth-image, cutaway and 4D-halo techniques (issue 10)."""

import numpy as np
import pytest

from refraster.golden.compare.run import compare, load_manifest
from refraster.golden.generate import generate

from test_golden import candidate_from

SCENES = ["ldi_nested_shells", "cutaway_shells", "halos4d_figure1"]


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "g"
    generate(out, SCENES)
    return out


def test_generate_and_self_compare(gold):
    m = load_manifest(gold)
    assert sorted(m["scenes"]) == sorted(SCENES)
    assert {"layer_depth", "layer_prim_id", "layer_count"} <= set(m["scenes"]["ldi_nested_shells"]["buffers"])
    assert {"cutaway_depth", "cut_mask", "ghost"} <= set(m["scenes"]["cutaway_shells"]["buffers"])
    assert {"color", "alpha"} <= set(m["scenes"]["halos4d_figure1"]["buffers"])
    # the 4D surface travels in the package as exact .npy maps
    assert (gold / "halos4d_figure1" / "package" / "maps" / "surface_vertices4d.npy").exists() \
        or any(p.name == "surface_vertices4d.npy" for p in (gold / "halos4d_figure1").rglob("*"))
    for mode in ("exact", "tolerant"):
        result = compare(gold, gold, mode=mode)
        assert result.exit_code == 0, result.summary()


def test_a_changed_layer_fails_naming_scene_buffer_and_metric(gold, tmp_path):
    with np.load(gold / "ldi_nested_shells" / "tolerance.npz", allow_pickle=False) as z:
        must = ~z["id_may"] & ~z["may"]
    with np.load(gold / "ldi_nested_shells" / "buffers.npz", allow_pickle=False) as z:
        ids = z["layer_prim_id"]
    # a pixel with at least two layers, away from every edge
    r, c = np.argwhere(must & (ids[..., 1] >= 0))[0]

    def edit(scene, b):
        if scene == "ldi_nested_shells":
            b["layer_prim_id"][r, c, 1] += 1

    cand = candidate_from(gold, tmp_path, edit, scenes=SCENES)
    result = compare(gold, cand, mode="exact")
    assert result.exit_code == 1
    assert any(line.startswith("ldi_nested_shells/layer_prim_id") for line in result.failures())
