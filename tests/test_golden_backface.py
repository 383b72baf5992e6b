"""Back-face normals (docs/backends.md, "Back faces"): the golden's ``normal`` is the face's own
normal, not flipped towards the viewer; a backend that flips it fails the ``normal`` buffer
where back faces are visible, and only there."""

import numpy as np
import pytest

from refraster import golden
from refraster.golden.compare.run import compare

SCENE = "render_nested_shells"   # front-face culling: the back faces show


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("backface") / "g"
    golden.generate(out, [SCENE])
    return out


def _write(root, buffers):
    (root / SCENE).mkdir(parents=True)
    np.savez(root / SCENE / "buffers.npz", **buffers)
    return root


def test_golden_normals_point_away_on_back_faces(gold):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        b = {k: z[k].copy() for k in z.files}
    back = (b["prim_id"] >= 0) & ~b["front_facing"].astype(bool)
    assert back.sum() > 1000
    # eye space: the viewer looks down −z, so a normal facing away has n_z < 0 on the whole
    assert np.median(b["normal"][back][:, 2]) < 0


def test_normals_flipped_towards_the_viewer_fail(gold, tmp_path):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        b = {k: z[k].copy() for k in z.files}
    assert compare(gold, _write(tmp_path / "same", dict(b)), mode="tolerant").exit_code == 0
    back = (b["prim_id"] >= 0) & ~b["front_facing"].astype(bool)
    b["normal"] = np.where(back[..., None], -b["normal"], b["normal"])
    result = compare(gold, _write(tmp_path / "flipped", b), mode="tolerant")
    failing = {ln.split(":")[0] for ln in result.failures()}
    assert result.exit_code == 1 and failing == {f"{SCENE}/normal"}, result.failures()
