"""The golden scene with user cap textures (issue 24): generated, self-compared, its maps and
parameters in the package, and a wrong texel on a cap fails the comparison."""

import json

import numpy as np
import pytest

from refraster.golden.compare.run import compare, load_manifest
from refraster.golden.generate import generate

from test_golden import candidate_from

SCENE = "clipsurface_textured_caps"


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "g"
    generate(out, [SCENE])
    return out


def test_generate_and_self_compare(gold):
    m = load_manifest(gold)
    assert sorted(m["scenes"]) == [SCENE]
    for mode in ("exact", "tolerant"):
        result = compare(gold, gold, mode=mode)
        assert result.exit_code == 0, result.summary()


def test_the_package_names_every_texture(gold):
    scene = json.loads(next(gold.glob(f"{SCENE}/**/scene.json")).read_text())
    surface = scene["parameters"]["surfaces"][0]
    assert surface["textures"] == {
        "diffuse": ["cap_diffuse_r", "cap_diffuse_g", "cap_diffuse_b"],
        "normal": ["cap_normal_x", "cap_normal_y", "cap_normal_z"], "light": ["cap_light"]}
    assert surface["wrap"] == "mirrored_repeat"
    for key, shape in (("cap_diffuse_g", [16, 24]), ("cap_normal_z", [32, 32]),
                       ("cap_light", [8, 8]), ("offset_map", [32, 32])):
        assert scene["maps"][key]["shape"] == shape
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        caps = z["cap_mask"]
        color = z["color"]
    assert caps.sum() > 500
    # the caps show the diffuse map's colours, not the plain cap colour
    assert len(np.unique(color[caps].round(3), axis=0)) > 100


def test_a_cap_pixel_with_a_wrong_texel_fails(gold, tmp_path):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        caps = z["cap_mask"]
    r, c = np.argwhere(caps)[len(np.argwhere(caps)) // 2]

    def edit(scene, b):
        b["color"][r, c] = 1.0 - b["color"][r, c]

    cand = candidate_from(gold, tmp_path, edit, scenes=[SCENE])
    result = compare(gold, cand, mode="exact")
    assert result.exit_code == 1
    assert any(line.startswith(f"{SCENE}/color") for line in result.failures())
