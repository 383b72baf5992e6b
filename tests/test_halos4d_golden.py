"""The halo golden scene carries the halo class and the composited colour (issue 21 item 5):
a backend whose halos do not carve fails on ``halo_class`` and ``color``."""

import numpy as np

from refraster.golden.compare.run import compare, load_manifest
from refraster.golden.generate import generate

from test_golden import candidate_from

SCENE = "halos4d_figure1"


def test_halo_golden_carries_class_and_colour(tmp_path):
    gold = tmp_path / "g"
    generate(gold, [SCENE])
    m = load_manifest(gold)
    assert {"color", "alpha", "halo_class"} <= set(m["scenes"][SCENE]["buffers"])
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        cls = z["halo_class"]
    assert {0, 1, 2, 3} <= set(np.unique(cls).tolist())
    assert compare(gold, gold, mode="exact").exit_code == 0
    with np.load(gold / SCENE / "tolerance.npz", allow_pickle=False) as z:
        must = ~z["may"]
    carved = (cls == 2) & must
    assert carved.sum() > 0

    # a backend without halo carving: carved pixels show the surface
    def edit(scene, b):
        b["halo_class"][carved] = 1
        b["color"][carved] = np.minimum(b["color"][carved] + 0.3, 1.0)

    cand = candidate_from(gold, tmp_path, edit, scenes=[SCENE])
    result = compare(gold, cand, mode="exact")
    assert result.exit_code == 1
    failing = {line.split(" ")[0].split(":")[0] for line in result.failures()}
    assert any(f.startswith(f"{SCENE}/halo_class") for f in failing), result.failures()
