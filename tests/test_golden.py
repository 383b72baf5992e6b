"""Golden images: generation, scene packages, comparison metrics, bad input, CLI."""

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refraster import RasterState, golden
from refraster.golden import cli
from refraster.golden.compare import (GoldenError, buffer_metrics, compare, load_manifest,
                                      local_variation, pixel_error, position_deviation)
from refraster.golden.schema import (MANIFEST_SCHEMA, SCENE_SCHEMA, SchemaError, check_version,
                                     validate)
from refraster.golden.tolerance import parse_override

SCENES = ["render_cube", "render_multi_draw", "render_icosphere_smooth"]


def tree_digest(root):
    """sha256 of every file under root (paths relative): what must not change."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(root).rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "g"
    golden.generate(out, SCENES)
    return out


def candidate_from(gold, tmp_path, edit=None, scenes=SCENES):
    """A candidate directory holding the golden's buffers, optionally edited:
    ``edit(scene, buffers_dict)`` changes arrays in place."""
    cand = tmp_path / "cand"
    for s in scenes:
        with np.load(gold / s / "buffers.npz", allow_pickle=False) as z:
            arrays = {k: z[k].copy() for k in z.files}
        if edit is not None:
            edit(s, arrays)
        (cand / s).mkdir(parents=True)
        np.savez(cand / s / "buffers.npz", **arrays)
    return cand


# --- generate and the manifest ------------------------------------------------------------------

def test_self_compare_passes_and_manifest_is_complete(gold):
    for profile in ("exact", "conformant"):
        result = compare(gold, gold, profile=profile)
        assert result.exit_code == 0, result.summary()
        assert result.failures() == []
    m = load_manifest(gold)
    from refraster.golden.schema import MANIFEST_SCHEMA_VERSION
    assert m["schema_version"] == MANIFEST_SCHEMA_VERSION == 3
    assert set(m["generator"]) >= {"refraster", "numpy", "numba", "python"}
    assert m["raster"] == {"subpixel_bits": 8, "fill_rule": "llvmpipe"}
    assert sorted(m["scenes"]) == sorted(SCENES)
    on_disk = tree_digest(gold)
    del on_disk["manifest.json"]
    assert on_disk == m["files"]  # every file listed with its sha256, nothing else
    cube = m["scenes"]["render_cube"]["buffers"]
    assert cube["depth"]["shape"] == [120, 160] and cube["depth"]["dtype"] == "float32"
    assert cube["normal"]["shape"] == [120, 160, 3]
    assert cube["prim_id"]["dtype"] == "int32" and cube["prim_id"]["kind"] == "id"
    assert cube["front_facing"]["dtype"] == "bool"
    assert set(cube["depth"]["tolerance"]) == {"exact", "conformant"}


def test_generate_is_deterministic_across_runs_and_thread_counts(gold, tmp_path):
    golden.generate(tmp_path / "again", ["render_multi_draw"])
    code = ("import sys; from refraster import golden; "
            "golden.generate(sys.argv[1], ['render_multi_draw'])")
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "one")], check=True, env=env)
    want = {k: v for k, v in load_manifest(gold)["files"].items()
            if k.startswith("render_multi_draw/")}
    assert load_manifest(tmp_path / "again")["files"] == want
    assert load_manifest(tmp_path / "one")["files"] == want


def test_generate_refuses_to_overwrite_and_update_keeps_other_scenes(gold, tmp_path):
    out = tmp_path / "g"
    golden.generate(out, ["render_cube", "render_multi_draw"])
    before = tree_digest(out)
    with pytest.raises(FileExistsError, match="update"):
        golden.generate(out, ["render_cube"])
    assert tree_digest(out) == before
    assert cli.main(["generate", "--out", str(out), "--scene", "render_cube"]) == 2
    assert tree_digest(out) == before
    golden.generate(out, ["render_cube"], update=True)
    after = tree_digest(out)
    assert {k for k in after if k != "manifest.json"} == {k for k in before
                                                           if k != "manifest.json"}
    assert sorted(load_manifest(out)["scenes"]) == ["render_cube", "render_multi_draw"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp left
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="not a golden directory"):
        golden.generate(plain, ["render_cube"], update=True)
    assert (plain / "notes.txt").read_text() == "mine"


def test_failing_scene_leaves_old_golden_untouched(tmp_path):
    out = tmp_path / "g"
    golden.generate(out, ["render_cube"])
    before = tree_digest(out)

    @golden.register_scene("test_broken_scene", technique="render")
    def broken():
        raise RuntimeError("scene exploded")

    try:
        with pytest.raises(RuntimeError, match="exploded"):
            golden.generate(out, ["render_multi_draw", "test_broken_scene"], update=True)
    finally:
        golden.SCENES.pop("test_broken_scene")
    assert tree_digest(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["g"]


def test_registry_rejects_bad_and_duplicate_names():
    with pytest.raises(ValueError, match="already registered"):
        golden.register_scene("render_cube", technique="render")
    with pytest.raises(ValueError, match="must match"):
        golden.register_scene("Bad Name", technique="render")
    with pytest.raises(ValueError, match="unknown golden scene"):
        golden.generate("/nonexistent/never-written", ["no_such_scene"])


# --- the scene package ---------------------------------------------------------------------------

def test_package_reloads_exactly_what_was_rendered(gold):
    import trimesh
    from refraster import render
    from refraster.camera import Camera
    for name in ("render_multi_draw", "render_icosphere_smooth"):
        pkg = gold / name / "package"
        doc = json.loads((pkg / "scene.json").read_text())
        validate(doc, SCENE_SCHEMA)
        meshes, normals = [], []
        for d in doc["draws"]:
            ply = trimesh.load(pkg / d["mesh"], process=False)
            assert len(ply.faces) == d["n_faces"] and len(ply.vertices) == d["n_vertices"]
            meshes.append((np.asarray(ply.vertices, np.float64), np.asarray(ply.faces)))
            if doc["raster"]["normals"] == "smooth":
                header = (pkg / d["mesh"]).read_bytes()[:400]
                assert b"property float nx" in header
                normals.append(np.asarray(ply.vertex_normals, np.float64))
        cam = Camera(doc["camera"]["view"], doc["camera"]["projection"],
                     doc["viewport"]["width"], doc["viewport"]["height"])
        if normals:
            meshes = [(v, f, n) for (v, f), n in zip(meshes, normals)]
        fb = render(meshes, **cam.kwargs, model=[d["model"] for d in doc["draws"]],
                    raster=RasterState(normals="smooth" if normals else "flat",
                                       cull=doc["raster"]["cull"]))
        with np.load(gold / name / "buffers.npz") as z:
            for key in ("depth", "prim_id", "object_id", "normal", "color"):
                assert np.array_equal(getattr(fb, key), z[key]), (name, key)


def test_scene_with_maps_exports_npy_and_png(tmp_path):
    from refraster.scenes import solid

    offset = np.linspace(0.0, 1.0, 12).reshape(3, 4)
    signed = np.linspace(-1.0, 1.0, 12).reshape(3, 4)

    @golden.register_scene("test_maps_scene", technique="test", description="maps")
    def scene():
        s = golden.render_scene([golden.Draw("cube", solid("cube"))],
                                golden.scenes._framed([solid("cube")], 32, 24, (1, 1, 1)))
        s.maps = {"offset_map": offset, "signed_map": signed}
        s.parameters = {"strength": 0.5, "offset_map": "offset_map"}
        return s

    try:
        golden.generate(tmp_path / "g", ["test_maps_scene"])
    finally:
        golden.SCENES.pop("test_maps_scene")
    pkg = tmp_path / "g" / "test_maps_scene" / "package"
    doc = json.loads((pkg / "scene.json").read_text())
    assert doc["parameters"] == {"strength": 0.5, "offset_map": "offset_map"}
    import imageio.v3 as iio
    for key, values, decode in (("offset_map", offset, lambda p: p / 65535),
                                ("signed_map", signed, lambda p: p / 65535 * 2 - 1)):
        entry = doc["maps"][key]
        assert np.array_equal(np.load(pkg / entry["npy"], allow_pickle=False), values)
        png = iio.imread(pkg / entry["png"])
        assert png.dtype == np.uint16
        assert np.abs(decode(png.astype(float)) - values).max() <= 1.0 / 65535
    assert doc["maps"]["signed_map"]["png_encoding"].startswith("snorm16")


def test_toml_scene(tmp_path):
    import trimesh
    trimesh.creation.box(extents=(1, 2, 1)).export(tmp_path / "part.ply")
    (tmp_path / "part.toml").write_text(
        'name = "my_part"\ndescription = "a box"\n[viewport]\nwidth = 48\nheight = 32\n'
        '[camera]\nkind = "perspective"\neye = [3.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\n'
        'fovy = 40.0\nnear = 1.0\nfar = 20.0\n[raster]\ncull = "back"\nnormals = "smooth"\n'
        '[[draw]]\nmesh = "part.ply"\n[[draw]]\nsolid = "cube"\n'
        'model = [[1,0,0,2],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n')
    out = tmp_path / "g"
    assert cli.main(["-q", "generate", "--out", str(out), "--scene-file",
                     str(tmp_path / "part.toml")]) == 0
    m = load_manifest(out)
    assert list(m["scenes"]) == ["my_part"]
    doc = json.loads((out / "my_part" / "package" / "scene.json").read_text())
    assert [d["name"] for d in doc["draws"]] == ["part", "cube_1"]
    assert doc["raster"]["cull"] == "back" and doc["camera"]["kind"] == "perspective"
    with np.load(out / "my_part" / "buffers.npz") as z:
        assert set(np.unique(z["object_id"])) == {-1, 0, 1}
    assert compare(out, out).exit_code == 0
    bad = tmp_path / "bad.toml"
    for text, message in (('name = "x"\n[[draw]]\nsolid = "cube"\nbogus = 1\n', "unknown"),
                          ('technique = "nope"\n[[draw]]\nsolid = "cube"\n', "technique"),
                          ('name = "x"\n', "draw"), ("name = \n", "cannot read")):
        bad.write_text(text)
        with pytest.raises(ValueError, match=message):
            golden.generate(tmp_path / "never", scene_files=[bad])
    assert not (tmp_path / "never").exists()


# --- metrics on hand-worked values ---------------------------------------------------------------

def test_pixel_error_and_metrics_hand_worked():
    ref = np.array([[0.0, 0.5], [1.0, np.inf]], np.float32)
    cand = np.array([[0.0, 0.75], [0.5, np.inf]], np.float32)
    assert pixel_error(ref, cand).tolist() == [[0.0, 0.25], [0.5, 0.0]]
    tol = dict(threshold=0.3, max_fraction=0.0, deviation_radius=0)
    m, checks, _ = buffer_metrics(ref, cand, "float", tol)
    assert m["max_abs"] == 0.5
    assert m["rmse"] == pytest.approx(np.sqrt((0.25 ** 2 + 0.5 ** 2) / 4))
    assert m["n_over"] == 1 and m["fraction_over"] == 0.25
    assert m["worst"]["row"] == 1 and m["worst"]["col"] == 0
    assert checks == [{"metric": "fraction_over", "value": 0.25, "limit": 0.0, "op": "<=",
                       "ok": False}]
    # PSNR with a peak of 1 (unorm): MSE = 0.01 → 20 dB
    m, _, _ = buffer_metrics(np.zeros((2, 2)), np.full((2, 2), 0.1), "unorm",
                             dict(tol, min_psnr=25.0))
    assert m["psnr"] == pytest.approx(20.0)
    nan = np.array([[np.nan]])
    assert pixel_error(np.zeros((1, 1)), nan)[0, 0] == np.inf
    assert pixel_error(np.array([[np.inf]]), np.array([[1.0]]))[0, 0] == np.inf


def test_position_deviation_hand_worked():
    ref = np.zeros((5, 5))
    ref[:, 2] = 1.0                                   # a vertical line
    shifted = np.roll(ref, 1, axis=1)                 # moved one pixel right
    assert not position_deviation(ref, shifted, 0.0, 0)[:, 2:4].any()
    assert position_deviation(ref, shifted, 0.0, 1).all()
    gone = np.zeros((5, 5))                           # the line dropped: each candidate
    one_sided = position_deviation(ref, gone, 0.0, 1)  # pixel has a match, the line does not
    assert not one_sided[:, 2].any() and one_sided[:, 0].all()
    ramp = np.arange(5.0)[None, :].repeat(3, axis=0)
    var = local_variation(ramp)
    assert var.tolist() == [[1.0] * 5] * 3
    steps = np.array([[0.0, 0.0, 4.0]])
    assert local_variation(steps).tolist() == [[0.0, 4.0, 4.0]]
    # slope: a 0.25 px shift of the ramp is forgiven with slope 0.3, not 0.2
    tol = dict(threshold=0.0, max_fraction=0.0, deviation_radius=0)
    _, checks, _ = buffer_metrics(ramp, ramp + 0.25, "float", dict(tol, slope=0.3))
    assert checks[0]["ok"]
    _, checks, _ = buffer_metrics(ramp, ramp + 0.25, "float", dict(tol, slope=0.2))
    assert not checks[0]["ok"]


# --- failing candidates name scene, buffer and metric --------------------------------------------

def _only_failure(result):
    lines = result.failures()
    assert result.exit_code == 1, result.summary()
    return lines


def test_flipped_id_fails(gold, tmp_path):
    def edit(scene, b):
        if scene == "render_multi_draw":
            r, c = np.argwhere(b["prim_id"] >= 0)[100]
            b["prim_id"][r, c] += 1

    result = compare(gold, candidate_from(gold, tmp_path, edit))
    lines = _only_failure(result)
    assert len(lines) == 1 and lines[0].startswith("render_multi_draw/prim_id: fraction_over")
    bad = [b for s in result.scenes for b in s.buffers if not b.passed]
    assert [(b.name, b.metrics["n_over"]) for b in bad] == [("prim_id", 1)]
    assert {s.name: s.status for s in result.scenes} == {
        "render_cube": "pass", "render_multi_draw": "fail", "render_icosphere_smooth": "pass"}


def test_one_pixel_shift_fails_exact_and_is_forgiven_by_position_deviation(gold, tmp_path):
    def edit(scene, b):
        if scene == "render_cube":
            b["color"] = np.roll(b["color"], 1, axis=1)

    cand = candidate_from(gold, tmp_path, edit)
    lines = _only_failure(compare(gold, cand))
    assert len(lines) == 1 and lines[0].startswith("render_cube/color: fraction_over")
    tolerant = compare(gold, cand, tolerances=["color.deviation_radius=1"])
    assert tolerant.exit_code == 0, tolerant.summary()
    cube = next(s for s in tolerant.scenes if s.name == "render_cube")
    color = next(b for b in cube.buffers if b.name == "color")
    assert color.metrics["n_over"] > 100 and color.metrics["n_unforgiven"] == 0


def test_noise_above_tolerance_fails(gold, tmp_path):
    rng = np.random.default_rng(7)

    def edit(scene, b):
        if scene == "render_icosphere_smooth":
            m = b["prim_id"] >= 0
            b["depth"][m] += rng.uniform(-1e-3, 1e-3, m.sum()).astype(np.float32)
            b["color"] = np.clip(b["color"] + rng.normal(0, 0.1, b["color"].shape), 0, 1)

    cand = candidate_from(gold, tmp_path, edit)
    for profile, depth_metric in (("exact", "fraction_over"),
                                  ("conformant", "position_deviation")):
        result = compare(gold, cand, profile=profile)
        lines = _only_failure(result)
        assert any(line.startswith(f"render_icosphere_smooth/depth: {depth_metric}")
                   for line in lines), lines
        assert all(line.startswith("render_icosphere_smooth/") for line in lines)
    conformant = compare(gold, cand, profile="conformant")
    assert any(line.startswith("render_icosphere_smooth/color: flip")
               for line in conformant.failures())
    relaxed = compare(gold, cand, profile="conformant", tolerances=[
        "render_icosphere_smooth:depth.threshold=2e-3", "color.threshold=1",
        "color.max_flip_mean=none"])
    assert relaxed.exit_code == 0, relaxed.summary()


def test_png_candidates(gold, tmp_path):
    import imageio.v3 as iio
    scene = "render_multi_draw"
    cand = tmp_path / "cand" / scene
    cand.mkdir(parents=True)
    with np.load(gold / scene / "buffers.npz") as z:
        b = {k: z[k] for k in z.files}
    iio.imwrite(cand / "color.png", (b["color"] * 255 + 0.5).astype(np.uint8))
    iio.imwrite(cand / "depth.png", (b["depth"] * 65535.0 + 0.5).astype(np.uint16))
    iio.imwrite(cand / "prim_id.png", (b["prim_id"] + 1).astype(np.uint16))
    iio.imwrite(cand / "front_facing.png", b["front_facing"].astype(np.uint8) * 255)
    for k in ("eye_depth", "normal", "object_id", "barycentric"):
        np.save(cand / f"{k}.npy", b[k])
    result = compare(gold, tmp_path / "cand", scenes=[scene])
    assert result.exit_code == 0, result.summary()
    depth = next(x for x in result.scenes[0].buffers if x.name == "depth")
    assert depth.source == f"{scene}/depth.png"
    assert depth.metrics["threshold"] == pytest.approx(1 / 65535)
    assert 0 < depth.metrics["max_abs"] <= 0.51 / 65535  # rounding (float32 product)
    # one id off in the PNG is caught exactly
    ids = (b["prim_id"] + 1).astype(np.uint16)
    ids[np.argwhere(ids > 0)[0][0], np.argwhere(ids > 0)[0][1]] += 1
    iio.imwrite(cand / "prim_id.png", ids)
    lines = compare(gold, tmp_path / "cand", scenes=[scene]).failures()
    assert lines and all(line.startswith(f"{scene}/prim_id: fraction_over") for line in lines)


# --- bad input: clear errors, nothing deleted or overwritten -------------------------------------

def test_bad_candidates_are_unusable_and_untouched(gold, tmp_path):
    scene = "render_cube"
    cases = {}

    def make(name, fn):
        d = tmp_path / name
        cand = candidate_from(gold, d, scenes=[scene])
        fn(cand / scene)
        cases[name] = cand

    make("missing", lambda p: (p / "buffers.npz").unlink())
    make("corrupt", lambda p: (p / "buffers.npz").write_bytes(b"PK\x03\x04 not a zip"))

    def reshape(p):
        with np.load(p / "buffers.npz") as z:
            b = {k: z[k] for k in z.files}
        b["depth"] = b["depth"][:-1]
        np.savez(p / "buffers.npz", **b)

    def float_ids(p):
        with np.load(p / "buffers.npz") as z:
            b = {k: z[k] for k in z.files}
        b["prim_id"] = b["prim_id"].astype(np.float32)
        np.savez(p / "buffers.npz", **b)

    def pickled(p):
        with np.load(p / "buffers.npz") as z:
            b = {k: z[k] for k in z.files}
        del b["normal"]
        np.savez(p / "buffers.npz", **b)
        np.save(p / "normal.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)

    def npy_in_npz(p):
        np.save(p / "arr.npy", np.zeros(3))
        (p / "arr.npy").replace(p / "buffers.npz")

    make("not_npz", npy_in_npz)
    make("shape", reshape)
    make("dtype", float_ids)
    make("pickle", pickled)
    expected = {"missing": "missing", "corrupt": "cannot read", "not_npz": "not an .npz",
                "shape": "shape (119, 160)",
                "dtype": "integer ids", "pickle": "cannot read"}
    golden_before = tree_digest(gold)
    for name, cand in cases.items():
        before = tree_digest(cand)
        result = compare(gold, cand, scenes=[scene])
        assert result.exit_code == 2, name
        assert expected[name] in result.scenes[0].error, (name, result.scenes[0].error)
        assert cli.main(["-q", "compare", str(gold), str(cand), "--scene", scene]) == 2
        assert tree_digest(cand) == before
    assert tree_digest(gold) == golden_before


def _copy_golden(gold, tmp_path):
    g = tmp_path / "g"
    shutil.copytree(gold, g)
    return g, json.loads((g / "manifest.json").read_text())


def _write_manifest(g, manifest):
    (g / "manifest.json").write_text(json.dumps(manifest))


def test_bad_manifests_are_refused(gold, tmp_path):
    g, m = _copy_golden(gold, tmp_path)
    (tmp_path / "outside.npz").write_bytes(b"secret")
    cases = []
    newer = dict(m, schema_version=4)
    cases.append((newer, "schema_version 4 is newer"))
    older = dict(m, schema_version=1)
    cases.append((older, "schema_version 1 is older .*regenerate the golden"))
    # version 2: technique scenes without allowances of their own (issue 20)
    cases.append((dict(m, schema_version=2), "schema_version 2 is older .*regenerate"))
    escape = json.loads(json.dumps(m))
    escape["scenes"]["render_cube"]["buffers_file"] = "../outside.npz"
    cases.append((escape, "leaves the golden directory"))
    absolute = json.loads(json.dumps(m))
    absolute["files"]["/etc/passwd"] = "0" * 64
    cases.append((absolute, "leaves the golden directory"))
    not_golden = dict(m, schema="something.else")
    cases.append((not_golden, "not a refraster.golden"))
    missing_field = {k: v for k, v in m.items() if k != "generator"}
    cases.append((missing_field, "missing required field 'generator'"))
    before = tree_digest(tmp_path)
    for manifest, message in cases:
        _write_manifest(g, manifest)
        with pytest.raises(GoldenError, match=message):
            compare(g, gold)
        assert cli.main(["-q", "compare", str(g), str(gold)]) == 2
    _write_manifest(g, m)
    assert {k: v for k, v in tree_digest(tmp_path).items() if k != "g/manifest.json"} == \
        {k: v for k, v in before.items() if k != "g/manifest.json"}
    # a symlink that points out of the golden directory
    link = g / "render_cube" / "buffers.npz"
    link.unlink()
    link.symlink_to(tmp_path / "outside.npz")
    with pytest.raises(GoldenError, match="outside the golden directory"):
        compare(g, gold)
    # a golden file edited after generation
    link.unlink()
    shutil.copy(gold / "render_cube" / "buffers.npz", link)
    (g / "render_cube" / "preview" / "depth.png").write_bytes(b"edited")
    with pytest.raises(GoldenError, match="sha256"):
        compare(g, gold)
    assert (tmp_path / "outside.npz").read_bytes() == b"secret"


def test_bad_arguments(gold, tmp_path):
    with pytest.raises(GoldenError, match="does not exist"):
        compare(gold, tmp_path / "nope")
    with pytest.raises(GoldenError, match="profile"):
        compare(gold, gold, profile="lenient")
    with pytest.raises(GoldenError, match="unknown tolerance key"):
        compare(gold, gold, tolerances=["depth.wiggle=1"])
    with pytest.raises(GoldenError, match="names buffer 'dpeth'"):
        compare(gold, gold, tolerances=["dpeth.threshold=1"])
    with pytest.raises(GoldenError, match="not in the golden"):
        compare(gold, gold, scenes=["render_torus_ortho"])
    with pytest.raises(GoldenError, match="overlaps"):
        compare(gold, gold, report=gold / "report")
    with pytest.raises(GoldenError, match="max_fraction"):
        compare(gold, gold, tolerances=["max_fraction=2"])
    assert parse_override("render_cube:depth.threshold=1e-3") == \
        ("render_cube", "depth", "threshold", 1e-3)
    assert parse_override("deviation_radius=2") == (None, None, "deviation_radius", 2)
    assert cli.main(["compare", str(gold)]) == 2
    assert cli.main(["generate"]) == 2


def test_schema_validation_messages():
    with pytest.raises(SchemaError, match=r"\$.viewport.width: must be >= 1"):
        validate({"viewport": {"width": 0, "height": 1}},
                 {"type": "object", "properties": SCENE_SCHEMA["properties"]})
    with pytest.raises(SchemaError, match="newer"):
        check_version({"schema": "refraster.golden", "schema_version": 9},
                      kind="refraster.golden", supported=1, what="m")
    with pytest.raises(SchemaError, match="must be finite"):
        validate(float("nan"), {"type": "number"})
    with pytest.raises(SchemaError, match="type object"):
        validate([], MANIFEST_SCHEMA)


# --- the command line ----------------------------------------------------------------------------

def test_cli_exit_codes_and_register(gold, tmp_path, capsys):
    import argparse
    parser = argparse.ArgumentParser(prog="refraster")
    cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["golden", "compare", str(gold), str(gold), "--tolerance",
                              "depth.threshold=0.1", "--profile", "conformant"])
    assert args.func(args) == 0
    assert "result: PASS" in capsys.readouterr().out

    def edit(scene, b):
        b["object_id"][b["object_id"] >= 0] += 1

    cand = candidate_from(gold, tmp_path, edit)
    assert cli.main(["compare", str(gold), str(cand), "--mode", "exact",
                     "--json", str(tmp_path / "m.json")]) == 1
    err = capsys.readouterr().err
    assert "FAIL render_cube/object_id: fraction_over" in err
    report = json.loads((tmp_path / "m.json").read_text())
    assert report["exit_code"] == 1
    assert report["scenes"]["render_cube"]["buffers"]["object_id"]["passed"] is False
    assert cli.main(["generate", "--list"]) == 0
    assert "render_crank" in capsys.readouterr().out


def test_every_stored_buffer_is_compared(gold, tmp_path):
    """Each buffer the manifest lists for a scene is compared: changing that buffer alone (every
    pixel, by far more than any tolerance) fails compare, and the failure names it (issue 30: a
    compare that skipped the barycentric buffer passed every other test)."""
    scene = "render_cube"
    keys = sorted(load_manifest(gold)["scenes"][scene]["buffers"])
    assert "barycentric" in keys
    for key in keys:
        def edit(s, b, key=key):
            if s != scene:
                return
            a = b[key]
            if a.dtype == np.bool_:
                b[key] = ~a
            elif np.issubdtype(a.dtype, np.integer):
                # covered pixels only: a background id turned into a face would also make the
                # zero normal there fail its domain check (a second buffer failing)
                b[key] = np.where(a >= 0, a + 7, a)
            else:
                b[key] = np.where(np.isfinite(a), a + 0.25, 0.5).astype(a.dtype)
        (tmp_path / key).mkdir()
        lines = _only_failure(compare(gold, candidate_from(gold, tmp_path / key, edit)))
        assert lines and all(line.startswith(f"{scene}/{key}") for line in lines), (key, lines)
