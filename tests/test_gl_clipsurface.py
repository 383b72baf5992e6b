"""refraster.gl's 2.5D clip surfaces with caps (issue 26 item 1): from the scene package alone
(issue 25 item 2: the exported cap meshes, sprites and derived maps), every clip-surface scene
PASSES the tolerant compare on llvmpipe, and each planted fault of ``shaders/clip.frag`` (a
test-only ``#define``) FAILS it on every clip-surface scene naming the buffer it breaks. The
matrix is the one in docs/backends.md ("Clip surfaces").

Needs a headless EGL context (Mesa llvmpipe through moderngl): skips without one, fails under
CI=true (the project's optional-oracle rule).
"""

import json

import numpy as np
import pytest

from conftest import gl_backend_or_skip as _backend_or_skip
from conftest import check_backends_matrix, fault_matrix, generate_gold, matrix_table

BEGIN = "<!-- gl-clip-matrix:begin (tests/test_gl_clipsurface.py) -->"
END = "<!-- gl-clip-matrix:end -->"

SCENES = ["clipsurface_building", "clipsurface_textured_caps", "clipsurface_two_surfaces",
          "clipsurface_relief_plane"]

#: fault → {scene: a buffer that must be among the failing ones}
EXPECTED = {
    "clip_sign_flipped": {s: "object_id" for s in SCENES},
    "offset_t_flipped": {s: "prim_id" for s in SCENES},
    "cap_no_parity": {s: "cap_mask" for s in SCENES},
}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    return generate_gold(tmp_path_factory, "glclip", SCENES)


def test_clip_candidate_passes_and_every_clip_fault_fails(gold):
    from refraster.gl import FAULTS
    from refraster.gl.clipsurface import FAULT_NAMES
    _backend_or_skip().release()
    assert set(FAULT_NAMES) == set(EXPECTED) and set(FAULT_NAMES) <= set(FAULTS)
    columns = ["correct", *FAULT_NAMES]
    results = fault_matrix(gold, columns, SCENES, EXPECTED)
    table = matrix_table(columns, SCENES, results)
    check_backends_matrix(BEGIN, END, table, "clip-surface matrix")


def test_clip_ids_are_exact_and_frames_bit_identical(gold):
    """Where refraster and llvmpipe agree on everything discrete: the ids, the facing and the
    cap mask of both scenes are equal pixel for pixel (no pixel needed the allowance), and two
    runs give the same bytes."""
    with _backend_or_skip() as gl:
        for scene in SCENES:
            pkg = gold / "golden" / scene / "package"
            a, b = gl.render(pkg), gl.render(pkg)
            for key in a:
                np.testing.assert_array_equal(a[key], b[key], err_msg=f"{scene}/{key}")
            with np.load(gold / "golden" / scene / "buffers.npz") as z:
                for key in ("prim_id", "object_id", "front_facing", "cap_mask"):
                    np.testing.assert_array_equal(a[key], z[key], err_msg=f"{scene}/{key}")
                assert a["cap_mask"].sum() > 500, scene


def test_package_carries_what_the_caps_need(gold):
    """Issue 25 item 2 for the clip-surface scenes: the cap meshes, sprites and derived maps
    are in scene.json and the package; the caps' prim_id range is the exported mesh's faces."""
    for scene in SCENES:
        base = gold / "golden" / scene / "package"
        doc = json.loads((base / "scene.json").read_text())
        p = doc["parameters"]
        assert p["evaluation_space"] == "world" and p["cap_mode"] == "mesh"
        if scene == "clipsurface_two_surfaces":      # both surfaces' caps are seen
            with np.load(gold / "golden" / scene / "buffers.npz") as z:
                assert {1, 2} <= set(np.unique(z["object_id"]).tolist())
        assert len(p["sprites"]) == len(doc["draws"])
        assert len(p["cap_meshes"]) == len(doc["draws"]) * len(p["surfaces"])
        for s in p["surfaces"]:
            for name in [*s["normal_map"], s["occlusion_map"], s["offset_map"]]:
                assert (base / doc["maps"][name]["npy"]).is_file()
        with np.load(gold / "golden" / scene / "buffers.npz") as z:
            cap_prims = z["prim_id"][z["cap_mask"]]
        assert cap_prims.max() < max(c["n_faces"] for c in p["cap_meshes"])


def test_unsupported_clip_settings_are_named():
    from refraster.gl.clipsurface import supports
    base = {"parameters": {"surfaces": [{}], "caps": True, "cap_mode": "mesh",
                           "cap_meshes": [], "sprites": []}}
    assert "exact" in supports({"parameters": {**base["parameters"], "cap_mode": "exact"}})
    assert "eye" in supports({"parameters": {**base["parameters"], "space": "eye"}}) \
        or "world" in supports({"parameters": {**base["parameters"], "space": "eye"}})
    assert "lacks" in supports(base)          # a golden written before issue 25 item 2
    assert "3" in supports({"parameters": {**base["parameters"], "surfaces": [{}] * 3}})


# --- an outside oracle of what the GL frame shows (scipy.ndimage, trimesh) --------------------

_SCIPY_MODE = {"repeat": "grid-wrap", "mirrored_repeat": "reflect", "clamp_to_edge": "nearest"}


def _g_scipy(points, s, om):
    """Eq. 1 in float64 with the offset map filtered by scipy.ndimage.map_coordinates (order 1,
    the GL wrap mode as scipy's boundary mode) — not refraster's sampler."""
    from scipy import ndimage
    o, u, v = (np.asarray(s[k], np.float64) for k in ("origin", "u", "v"))
    uh, vh = u / np.linalg.norm(u), v / np.linalg.norm(v)
    n = np.cross(uh, vh)
    d = points - o
    ss = (d @ uh / np.linalg.norm(u)) * s["scale"][0]
    tt = (d @ vh / np.linalg.norm(v)) * s["scale"][1]
    h, w = om.shape
    hval = ndimage.map_coordinates(np.asarray(om, np.float64), [tt * h - 0.5, ss * w - 0.5],
                                   order=1, mode=_SCIPY_MODE[s["wrap"]])
    return d @ n + s["scale"][2] * hval


def _world_points(scene, eye_depth, rows, cols):
    view, proj = (np.array(scene["camera"][k], np.float64) for k in ("view", "projection"))
    h, w = eye_depth.shape
    assert proj[0, 2] == 0 and proj[1, 2] == 0 and proj[3, 2] == -1     # symmetric perspective
    x_ndc = (cols + 0.5) / w * 2 - 1
    y_ndc = 1 - (rows + 0.5) / h * 2
    ez = eye_depth[rows, cols].astype(np.float64)
    p = np.stack([x_ndc * ez / proj[0, 0], y_ndc * ez / proj[1, 1], -ez, np.ones_like(ez)])
    return (np.linalg.inv(view) @ p)[:3].T


@pytest.mark.parametrize("scene", SCENES)
def test_gl_clip_frame_against_scipy_and_trimesh(gold, scene):
    """Every solid pixel the GL backend keeps has g(P) ≥ 0 for every surface, and every cap
    pixel lies on its own surface (|g| small) with g ≥ 0 for the others, by Eq. 1 evaluated in
    float64 with scipy's bilinear filter; cap points well inside the solid are inside by
    trimesh's ray test. The relief clip plane is checked against the RCP's own inequality
    N·(X − P) − s·h ≤ 0 (MATH.md D8), not its equivalent surface. Tolerances: P is rebuilt from
    the float32 eye depth at the pixel centre (the fragment may sit up to ε pixel away), so
    |Δg| ≤ |∇g|·(a pixel's world size); 1.5 pixels is allowed."""
    import trimesh
    from refraster.gl.package import read_map, read_ply
    base = gold / "golden" / scene / "package"
    doc = json.loads((base / "scene.json").read_text())
    p = doc["parameters"]
    with _backend_or_skip() as gl:
        out = gl.render(base)
    obj, eye = out["object_id"], out["eye_depth"]
    n_solids = len(doc["draws"])
    proj = np.array(doc["camera"]["projection"])
    rows, cols = np.nonzero(obj >= 0)
    pts = _world_points(doc, eye, rows, cols)
    pixel = eye[rows, cols] * 2.0 / (proj[1, 1] * eye.shape[0])     # world size of a pixel
    maps = {s["offset_map"]: read_map(base, doc, s["offset_map"]) for s in p["surfaces"]}
    gs = []
    for s in p["surfaces"]:
        g = _g_scipy(pts, s, maps[s["offset_map"]])
        # |∇g| ≤ 1 + Sz·(largest texel step)·(texels per world unit)
        om = maps[s["offset_map"]]
        step = max(np.abs(np.diff(om, axis=0)).max(), np.abs(np.diff(om, axis=1)).max())
        dens = max(om.shape[1] * s["scale"][0] / np.linalg.norm(s["u"]),
                   om.shape[0] * s["scale"][1] / np.linalg.norm(s["v"]))
        gs.append((g, 1.5 * pixel * (1.0 + abs(s["scale"][2]) * step * dens)))
    cap = obj >= n_solids
    k_of = np.where(cap[rows, cols], (obj[rows, cols] - n_solids) % len(p["surfaces"]), -1)
    for k, (g, tol) in enumerate(gs):
        others = k_of != k
        assert np.all(g[others] >= -tol[others]), (scene, k, g[others].min())
        mine = k_of == k
        assert np.all(np.abs(g[mine]) <= tol[mine] + 0.02 * abs(p["surfaces"][k]["scale"][2])), \
            (scene, k, np.abs(g[mine]).max())
    assert np.count_nonzero(k_of >= 0) > 300 and np.count_nonzero(k_of < 0) > 1000
    if "relief_clip_plane" in p:
        # the RCP's own inequality from its own parameters: N·(X − P) − s·h(X) > 0 discards
        r = p["relief_clip_plane"]
        nrm = np.asarray(r["normal"], np.float64) / np.linalg.norm(r["normal"])
        u = np.asarray(r["u"], np.float64)
        u = u - (u @ nrm) * nrm
        uh = u / np.linalg.norm(u)
        vh = np.cross(-nrm, uh)
        own = dict(origin=r["point"], u=(r["extent"] * uh).tolist(),
                   v=(r["extent"] * vh).tolist(), scale=[1.0, 1.0, 0.0], wrap=r["wrap"])
        plane = _g_scipy(pts, own, maps["offset_map"])          # = (X − P)·(−N), Sz = 0
        hval = (_g_scipy(pts, {**own, "scale": [1.0, 1.0, 1.0]}, maps["offset_map"]) - plane)
        rcp = (pts - r["point"]) @ nrm - r["height_scale"] * hval
        np.testing.assert_allclose(rcp, -gs[0][0], atol=1e-9)
        solid_px = k_of < 0
        assert np.all(rcp[solid_px] <= gs[0][1][solid_px]), rcp[solid_px].max()
    # cap points: none clearly outside the solid, and those clearly inside are inside by
    # trimesh's ray test ("clearly": two sprite texels, the parity test's resolution)
    v, f, _ = read_ply(base / doc["draws"][0]["mesh"])
    mesh = trimesh.Trimesh(v.astype(np.float64), f, process=False)
    sel = np.flatnonzero(k_of >= 0)
    texel = float(np.ptp(v, axis=0).max()) / (p["vds_resolution"] - 4)
    depth_in = trimesh.proximity.signed_distance(mesh, pts[sel])     # > 0 inside
    assert np.all(depth_in > -2 * texel), (scene, depth_in.min(), texel)
    far = depth_in > 2 * texel
    inside = mesh.contains(pts[sel][far])
    assert far.sum() > 100 and inside.all(), (scene, int(far.sum()), int((~inside).sum()))


def test_malformed_clip_parameters_are_one_clear_error(gold, tmp_path):
    import shutil

    from refraster.gl.package import PackageError
    pkg = tmp_path / "pkg"
    shutil.copytree(gold / "golden" / "clipsurface_building" / "package", pkg)
    good = json.loads((pkg / "scene.json").read_text())
    with _backend_or_skip() as gl:
        for edit, words in ((lambda p: p["cap_meshes"][0].update(solid="zero"), "malformed"),
                            (lambda p: p["cap_meshes"][0].update(solid=5), "out of range"),
                            (lambda p: p["sprites"][0].pop("sprite_count"), "sprite_count"),
                            (lambda p: p["surfaces"][0].update(wrap="spiral"), "spiral"),
                            (lambda p: p["cap_meshes"][0].update(faces="../x"), "is missing")):
            doc = json.loads(json.dumps(good))
            edit(doc["parameters"])
            (pkg / "scene.json").write_text(json.dumps(doc))
            with pytest.raises(PackageError, match=words):
                gl.render(pkg)
