"""Clip-surface and cutaway values (normal, barycentrics, colour) held per entry of the clip sets
(issue 20, "Goldens with teeth (2)"; docs/tolerance.md, "Clip-surface and cutaway values").

Both directions at a pixel where another face may win: a candidate naming that face passes with
values inside that face's own bounds (``cs_barycentric_lo/_hi``, ``cs_color_lo/_hi``,
``cs_normal`` + ``cs_normal_angle``) and fails, naming the pixel, with the golden's own values
where those lie outside the named face's bounds (before issue 20's item 1 they were free there).
"""

import subprocess
import sys

import numpy as np
import pytest

from refraster import golden
from refraster.golden.allowances.core import _angle

SCENES = ("cutaway_shells", "clipsurface_building")
KEYS = ("barycentric", "color", "normal")


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("clipvalues") / "g"
    # 4 bits: the shells hold slivers that may flip there (none at 8), which the sliver test needs
    golden.generate(out, list(SCENES), candidate_subpixel_bits=4)
    return out


def _load(gold, scene):
    with np.load(gold / scene / "buffers.npz", allow_pickle=False) as z:
        b = {k: z[k].copy() for k in z.files}
    with np.load(gold / scene / "tolerance.npz", allow_pickle=False) as z:
        a = {k: z[k].copy() for k in z.files}
    return b, a


def _write(root, scene, buffers):
    (root / scene).mkdir(parents=True)
    np.savez(root / scene / "buffers.npz", **buffers)
    return root


def _outside(key, b, a, r, c, e):
    """The golden's value at (r, c) lies clearly outside entry e's bounds."""
    if key == "normal":
        return float(_angle(b["normal"][r, c].astype(np.float64),
                            a["cs_normal"][e].astype(np.float64))) \
            > float(a["cs_normal_angle"][e]) + 0.05
    v = b[key][r, c].astype(np.float64)
    return bool(((v < a[f"cs_{key}_lo"][e] - 0.02) | (v > a[f"cs_{key}_hi"][e] + 0.02)).any())


def _other_entry(b, a, key):
    """(r, c, e): a covered pixel, an entry of its clip set other than the golden's face, not a
    sliver, with bounded values, and the golden's ``key`` outside that entry's bounds."""
    h, w = b["prim_id"].shape
    off = a["cs_offsets"].astype(np.int64)
    draws = a["cs_draw_offsets"].astype(np.int64)
    found = []
    for r, c in np.argwhere((b["prim_id"] >= 0) & a["face_may"]):
        g = int(draws[b["object_id"][r, c]] + b["prim_id"][r, c])
        for e in range(off[r * w + c], off[r * w + c + 1]):
            if int(a["cs_face"][e]) == g or int(a["cs_facing"][e]) < 0 \
                    or int(a["cs_flag"][e]) < 0 or a["cs_normal_angle"][e] >= 1.0 \
                    or not np.isfinite(a["cs_color_lo"][e]).all() \
                    or not np.isfinite(a["cs_barycentric_lo"][e]).all():
                continue
            if _outside(key, b, a, r, c, e):
                found.append((int(r), int(c), int(e)))
    assert found, key
    return found[len(found) // 2]


def _naming(b, a, r, c, e):
    """The golden's buffers with pixel (r, c) showing entry e: its ids, facing, mask flag,
    depths and values inside that entry's bounds."""
    out = {k: v.copy() for k, v in b.items()}
    draws = a["cs_draw_offsets"].astype(np.int64)
    f = int(a["cs_face"][e])
    o = int(np.searchsorted(draws[1:], f, side="right"))
    out["object_id"][r, c] = o
    out["prim_id"][r, c] = f - int(draws[o])
    out["front_facing"][r, c] = bool(a["cs_facing"][e] == 1)
    mask = "cut_mask" if "cut_mask" in out else "cap_mask"
    out[mask][r, c] = bool(a["cs_flag"][e] == 1)
    out["depth"][r, c] = 0.5 * (float(a["cs_depth_lo"][e]) + float(a["cs_depth_hi"][e]))
    out["eye_depth"][r, c] = 0.5 * (float(a["cs_eye_lo"][e]) + float(a["cs_eye_hi"][e]))
    out["barycentric"][r, c] = 0.5 * (a["cs_barycentric_lo"][e] + a["cs_barycentric_hi"][e])
    out["color"][r, c] = 0.5 * (a["cs_color_lo"][e] + a["cs_color_hi"][e])
    n = a["cs_normal"][e].astype(np.float64)
    out["normal"][r, c] = (n / np.linalg.norm(n)).astype(np.float32)
    return out


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("key", KEYS)
def test_other_allowed_face_is_held_to_its_own_values(gold, tmp_path, scene, key):
    """A candidate naming another face that may win there: with that face's values it passes
    (tolerant); with the golden's values — outside the named face's bounds — the buffer fails
    ``refraster golden compare`` naming the pixel, and nothing else fails."""
    from refraster.golden.compare.run import compare
    b, a = _load(gold, scene)
    r, c, e = _other_entry(b, a, key)
    good = _naming(b, a, r, c, e)
    res = compare(gold, _write(tmp_path / "good", scene, good), mode="tolerant", scenes=[scene])
    assert res.exit_code == 0, (key, r, c, e, res.failures()[:5])
    bad = {k: v.copy() for k, v in good.items()}
    bad[key][r, c] = b[key][r, c]
    p = subprocess.run([sys.executable, "-m", "refraster.golden.cli", "golden", "compare",
                        str(gold), str(_write(tmp_path / "bad", scene, bad)), "--scene", scene],
                       capture_output=True, text=True)
    out = p.stdout + p.stderr
    assert p.returncode == 1, out
    lines = [x for x in out.splitlines() if f"{scene}/{key}: clip" in x]
    assert lines and f"[[{r}, {c}]]" in lines[0], (key, out)
    others = {x.split()[1].rstrip(":") for x in out.splitlines() if x.startswith("FAIL ")}
    assert others <= {f"{scene}/{key}"}, out


def test_golden_sliver_is_held_to_its_sliver_bounds(gold):
    """Where the golden's own entry is a sliver that may flip (``face_sliver``) the value is no
    longer free: it is held to the entry's bounds from the snapped vertices, which hold the
    golden's own barycentrics."""
    b, a = _load(gold, "cutaway_shells")
    where = np.argwhere(a["face_sliver"] & (b["prim_id"] >= 0))
    assert len(where) >= 1
    w = b["prim_id"].shape[1]
    off = a["cs_offsets"].astype(np.int64)
    draws = a["cs_draw_offsets"].astype(np.int64)
    for r, c in where:
        g = int(draws[b["object_id"][r, c]] + b["prim_id"][r, c])
        faces = list(a["cs_face"][off[r * w + c]:off[r * w + c + 1]])
        e = int(off[r * w + c]) + faces.index(g)
        assert a["cs_facing"][e] == -1
        lo, hi = a["cs_barycentric_lo"][e], a["cs_barycentric_hi"][e]
        assert np.isfinite(lo).all() and np.isfinite(hi).all()
        assert ((b["barycentric"][r, c] >= lo) & (b["barycentric"][r, c] <= hi)).all()


@pytest.mark.parametrize("how", ["shape", "missing"])
def test_corrupt_value_arrays_are_refused(gold, tmp_path, how):
    """A tolerance.npz whose per-entry value arrays do not match the clip sets (hash rewritten
    to match), or lacks them, is refused with one line naming the array, never indexed with."""
    import hashlib
    import json
    import shutil
    from refraster.golden.compare.run import GoldenError, compare
    scene = "cutaway_shells"
    g = tmp_path / "g"
    shutil.copytree(gold, g)
    with np.load(g / scene / "tolerance.npz", allow_pickle=False) as z:
        a = {k: z[k].copy() for k in z.files}
    m = json.loads((g / "manifest.json").read_text())
    arrays = m["scenes"][scene]["allowances"]["arrays"]
    if how == "shape":   # the manifest rewritten to match too: the clip-set check refuses it
        a["cs_normal"] = a["cs_normal"][:-1]
        arrays["cs_normal"]["shape"] = list(a["cs_normal"].shape)
        match = r"cs_normal is not \(\d+, 3\)"
    else:
        del a["cs_color_lo"]
        del arrays["cs_color_lo"]
        match = r"buffer 'color' needs arrays \['cs_color_lo'\]"
    np.savez(g / scene / "tolerance.npz", **a)
    rel = f"{scene}/tolerance.npz"
    m["files"][rel] = hashlib.sha256((g / rel).read_bytes()).hexdigest()
    (g / "manifest.json").write_text(json.dumps(m))
    b, _ = _load(gold, scene)
    with pytest.raises(GoldenError, match=match):
        compare(g, _write(tmp_path / "cand", scene, b), mode="tolerant", scenes=[scene])
