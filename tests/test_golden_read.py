"""Golden reads never trust a file (issue 18): no links followed, no memory bombs, every scene
package validated on every read."""

import hashlib
import json
import logging
import os
import shutil
import struct
import tracemalloc
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pytest

from refraster import golden
from refraster.golden import cli
from refraster.golden.compare.run import GoldenError, compare, load_manifest

SCENE = "render_cube"
MiB = 1 << 20


def tree_digest(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(root).rglob("*")) if p.is_file() and not p.is_symlink()}


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "g"
    golden.generate(out, [SCENE])
    return out


def golden_buffers(gold):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def copy_golden(gold, tmp_path):
    g = tmp_path / "g"
    shutil.copytree(gold, g)
    return g, json.loads((g / "manifest.json").read_text())


def rehash(g, manifest, rel):
    """Rewrite the manifest so that it matches an edited file (an attacker can do this)."""
    manifest["files"][rel] = hashlib.sha256((g / rel).read_bytes()).hexdigest()
    (g / "manifest.json").write_text(json.dumps(manifest))


# --- 2. candidates: headers first, bounded memory ------------------------------------------------

def budget(gold, scene=SCENE):
    """32 MiB + 10 × (the golden's buffers + allowances), the issue's bound."""
    entry = load_manifest(gold)["scenes"][scene]

    def nbytes(specs):
        return sum(int(np.prod(s["shape"])) * np.dtype(s["dtype"]).itemsize
                   for s in specs.values())
    return 32 * MiB + 10 * (nbytes(entry["buffers"]) + nbytes(entry["allowances"]["arrays"]))


def peak_memory(fn):
    """Peak traced memory (bytes) of ``fn()`` above what was allocated before it ran."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        result = fn()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return result, peak


def add_zero_member(path, name, nbytes):
    """Append a member of ``nbytes`` zeros (an .npy of float32) to a zip: a few hundred KB
    compressed."""
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf:
        with zf.open(name, "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f4", "fortran_order": False, "shape": (nbytes // 4,)})
            chunk = bytes(16 * MiB)
            for _ in range(nbytes // len(chunk)):
                fh.write(chunk)


def zero_png(width, height):
    """An 8-bit grey PNG of zeros, built row by row (tiny file, huge picture)."""
    def chunk(kind, data):
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    z = zlib.compressobj(9)
    row = bytes(width + 1)
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0,
                                                                0, 0, 0))
            + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


def test_unused_npz_member_is_skipped_unread_within_the_memory_budget(gold, tmp_path, caplog):
    cand = tmp_path / "cand"
    (cand / SCENE).mkdir(parents=True)
    np.savez(cand / SCENE / "buffers.npz", **golden_buffers(gold))
    compare(gold, cand, mode="tolerant")        # imports done: the baseline is post-import
    _, good_peak = peak_memory(lambda: compare(gold, cand, mode="tolerant"))
    limit = budget(gold)
    assert good_peak <= limit, (good_peak, limit)
    add_zero_member(cand / SCENE / "buffers.npz", "unused.npy", 256 * MiB)
    assert (cand / SCENE / "buffers.npz").stat().st_size < 2 * MiB
    with caplog.at_level(logging.WARNING, logger="refraster.golden"):
        result, peak = peak_memory(lambda: compare(gold, cand, mode="tolerant"))
    assert result.exit_code == 0, result.summary()
    assert peak <= limit, (peak, limit)
    assert result.scenes[0].skipped == [f"{SCENE}/buffers.npz:unused.npy"]
    assert "skipped (not in the golden, not read): render_cube/buffers.npz:unused.npy" in \
        result.summary()
    assert any("unused.npy" in r.getMessage() for r in caplog.records)


def test_headers_are_checked_before_data(gold, tmp_path):
    b = golden_buffers(gold)
    limit = budget(gold)

    def candidate(name, make):
        cand = tmp_path / name
        (cand / SCENE).mkdir(parents=True)
        rest = {k: v for k, v in b.items() if k != "depth"}
        np.savez(cand / SCENE / "buffers.npz", **rest)
        make(cand / SCENE)
        return cand

    def huge_npy(p):     # a header claiming 10^12 elements, 16 bytes of data
        with open(p / "depth.npy", "wb") as fh:
            np.lib.format.write_array_header_1_0(
                fh, {"descr": "<f4", "fortran_order": False, "shape": (10 ** 6, 10 ** 6)})
            fh.write(bytes(16))

    def huge_member(p):  # the same inside the npz
        with zipfile.ZipFile(p / "buffers.npz", "a") as zf:
            with zf.open("depth.npy", "w") as fh:
                np.lib.format.write_array_header_1_0(
                    fh, {"descr": "<f4", "fortran_order": False, "shape": (10 ** 6, 10 ** 6)})

    def png_bomb(p):     # 13000 x 13000 grey: 165 KB, 169 MB decoded
        (p / "depth.png").write_bytes(zero_png(13000, 13000))

    def trailing(p):     # right header, then 64 MiB more than it describes
        with zipfile.ZipFile(p / "buffers.npz", "a", compression=zipfile.ZIP_DEFLATED) as zf:
            with zf.open("depth.npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, b["depth"])
                fh.write(bytes(64 * MiB))

    cases = {"huge_npy": (huge_npy, "shape (1000000, 1000000) differs from the golden's "
                                    "(120, 160)"),
             "huge_member": (huge_member, "shape (1000000, 1000000) differs"),
             "png_bomb": (png_bomb, "the PNG is 13000x13000, the golden's buffer 160x120"),
             "trailing": (trailing, "data continues past the array")}
    for name, (make, message) in cases.items():
        cand = candidate(name, make)
        before = tree_digest(cand)
        result, peak = peak_memory(lambda: compare(gold, cand, scenes=[SCENE]))
        assert result.exit_code == 2, (name, result.summary())
        assert message in result.scenes[0].error, (name, result.scenes[0].error)
        assert peak <= limit, (name, peak, limit)
        assert cli.main(["-q", "compare", str(gold), str(cand)]) == 2
        assert tree_digest(cand) == before


# --- 3. scene packages are validated on every read ------------------------------------------------

def edit_scene_json(g, manifest, fn):
    rel = f"{SCENE}/package/scene.json"
    doc = json.loads((g / rel).read_text())
    fn(doc)
    (g / rel).write_text(json.dumps(doc))
    rehash(g, manifest, rel)


PACKAGE_CASES = {
    "mesh outside": (lambda d: d["draws"][0].update(mesh="../../../../etc/passwd"),
                     r"\$.draws\[0\].mesh: '../../../../etc/passwd' does not match"),
    "nan view": (lambda d: d["camera"]["view"][0].__setitem__(0, float("nan")),
                 r"\$.camera.view\[0\]\[0\]: must be finite"),
    "negative width": (lambda d: d["viewport"].update(width=-5),
                       r"\$.viewport.width: must be >= 1"),
    "unlisted mesh": (lambda d: d["draws"][0].update(mesh="meshes/other.ply"),
                      r"\$.draws\[0\].mesh: 'meshes/other.ply' is not listed"),
    "viewport": (lambda d: d["viewport"].update(width=16),
                 r"\$.viewport: 16x120 does not match buffer"),
    "newer": (lambda d: d.update(schema_version=7), "schema_version 7 is newer"),
}


def test_package_meshes_and_maps_match_scene_json(gold, tmp_path):
    g, manifest = copy_golden(gold, tmp_path)
    rel = f"{SCENE}/package/meshes/cube.ply"
    ply = (g / rel).read_bytes()
    (g / rel).write_bytes(ply.replace(b"element face 12", b"element face 13"))
    rehash(g, manifest, rel)
    with pytest.raises(GoldenError, match=r"n_faces 12 but cube.ply declares 8 vertices and "
                                          "13 faces"):
        compare(g, gold)
    (g / rel).write_bytes(ply.replace(b"binary_little_endian", b"binary_big_endian   "))
    rehash(g, manifest, rel)
    with pytest.raises(GoldenError, match="not a binary little-endian PLY"):
        compare(g, gold)
    (g / rel).write_bytes(ply)
    rehash(g, manifest, rel)
    assert compare(g, gold).exit_code == 0


def test_package_map_header_matches_scene_json(tmp_path):
    from refraster.scenes import solid

    @golden.register_scene("test_read_maps_scene", technique="test", description="maps")
    def scene():
        s = golden.render_scene([golden.Draw("cube", solid("cube"))],
                                golden.scenes._framed([solid("cube")], 16, 12, (1, 1, 1)))
        s.maps = {"offset_map": np.linspace(0.0, 1.0, 12).reshape(3, 4)}
        return s

    try:
        golden.generate(tmp_path / "g", ["test_read_maps_scene"])
    finally:
        golden.SCENES.pop("test_read_maps_scene")
    g = tmp_path / "g"
    manifest = json.loads((g / "manifest.json").read_text())
    assert compare(g, g).exit_code == 0
    rel = "test_read_maps_scene/package/maps/offset_map.npy"
    np.save(g / rel, np.zeros((3000, 4000)))
    rehash(g, manifest, rel)
    with pytest.raises(GoldenError, match=r"\$.maps.offset_map: float64 \[3, 4\] but "
                                          r"maps/offset_map.npy holds float64 \[3000, 4000\]"):
        compare(g, g)


@pytest.mark.parametrize("case", list(PACKAGE_CASES))
def test_scene_package_is_validated_by_compare_and_the_fixture(gold, tmp_path, case, capsys):
    from refraster.testing import GoldenFixture
    edit, message = PACKAGE_CASES[case]
    g, manifest = copy_golden(gold, tmp_path)
    (g / SCENE / "package" / "meshes" / "other.ply").write_bytes(b"ply\n")
    edit_scene_json(g, manifest, edit)
    with pytest.raises(GoldenError, match=message):
        compare(g, gold)
    assert cli.main(["-q", "compare", str(g), str(gold)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene.json" in err[0], err
    with pytest.raises(pytest.UsageError, match=message):
        GoldenFixture(g, tmp_path / "fixture")


def test_fixture_package_validates_again_on_every_call(gold, tmp_path):
    from refraster.testing import GoldenFixture
    g, manifest = copy_golden(gold, tmp_path)
    fixture = GoldenFixture(g, tmp_path / "fixture")
    assert fixture.package(SCENE) == g / SCENE / "package"
    edit_scene_json(g, manifest, PACKAGE_CASES["mesh outside"][0])
    with pytest.raises(pytest.fail.Exception, match="does not match"):
        fixture.package(SCENE)
    # a mesh edited after the fixture read the manifest: its sha256 no longer matches
    g2, _ = copy_golden(gold, tmp_path / "two")
    fixture = GoldenFixture(g2, tmp_path / "fixture2")
    with open(g2 / SCENE / "package" / "meshes" / "cube.ply", "ab") as fh:
        fh.write(b"\0")
    with pytest.raises(pytest.fail.Exception, match="sha256"):
        fixture.package(SCENE)


def test_listed_files_are_never_read_through_a_link(gold, tmp_path):
    g, manifest = copy_golden(gold, tmp_path)
    inner = g / SCENE / "preview" / "depth.png"
    keep = tmp_path / "depth.png"
    shutil.move(inner, keep)
    shutil.copy(keep, g / SCENE / "preview" / "copy.png")
    inner.symlink_to(g / SCENE / "preview" / "copy.png")     # stays inside, still refused
    with pytest.raises(GoldenError, match="symbolic link"):
        compare(g, gold)
    inner.unlink()
    os.mkfifo(inner)                                        # would block a plain open()
    with pytest.raises(GoldenError, match="not a regular file"):
        compare(g, gold)
    inner.unlink()
    shutil.move(keep, inner)
    os.rename(g / SCENE / "preview", tmp_path / "preview")
    (g / SCENE / "preview").symlink_to(tmp_path / "preview")  # a linked directory
    with pytest.raises(GoldenError, match="outside the golden directory|symbolic link"):
        compare(g, gold)


def test_deeply_nested_manifest_is_one_line(gold, tmp_path, capsys):
    g, _ = copy_golden(gold, tmp_path)
    (g / "manifest.json").write_text("[" * 100000 + "]" * 100000)
    with pytest.raises(GoldenError, match="nested too deeply"):
        load_manifest(g)
    assert cli.main(["compare", str(g), str(gold)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nested too deeply" in err[0], err


# --- 1. generate --update copies kept scenes from the manifest's file list only ----------------

def test_update_copies_kept_scenes_from_the_file_list_without_links(tmp_path, caplog, capsys):
    """Kept scenes are copied from the manifest's file list only, never through a link; and a
    golden holding files refraster did not write (a link to a private key, the user's notes)
    is not replaced at all: `--update` refuses, naming them, and nothing is lost (the write
    rules of docs/golden.md)."""
    from refraster.golden.io.read import copy_listed_scene
    from refraster.golden.io.write import RefusedError
    out = tmp_path / "g"
    golden.generate(out, [SCENE])
    secret = tmp_path / "private.key"
    secret.write_text("-----BEGIN PRIVATE KEY-----")
    (out / SCENE / "id_rsa").symlink_to(secret)
    (out / SCENE / "notes.txt").write_text("mine")
    (out / SCENE / "zero").symlink_to("/dev/zero")
    (out / SCENE / "home").symlink_to(tmp_path)
    manifest = load_manifest(out)
    before = {k: v for k, v in manifest["files"].items() if k.startswith(f"{SCENE}/")}
    # the copy: listed files only, each sha256 checked; unlisted ones and links skipped, named
    dest = tmp_path / "copy"
    with caplog.at_level(logging.WARNING, logger="refraster.golden"):
        copied = copy_listed_scene(out, manifest, SCENE, dest)
    assert sorted(copied) == sorted(before)
    got = {p.relative_to(dest).as_posix() for p in dest.rglob("*") if not p.is_dir()}
    assert got == set(before)
    assert not any(p.is_symlink() for p in dest.rglob("*"))
    warned = " ".join(r.getMessage() for r in caplog.records)
    for name in ("id_rsa", "notes.txt", "zero", "home"):
        assert f"{SCENE}/{name}" in warned, warned
    # the update refuses to replace a directory holding what refraster did not write
    with pytest.raises(RefusedError, match="id_rsa"):
        golden.generate(out, [SCENE], sizes=["16x12"], update=True)
    assert (out / SCENE / "notes.txt").read_text() == "mine"
    assert os.path.islink(out / SCENE / "id_rsa") and secret.exists()
    assert {k: v for k, v in load_manifest(out)["files"].items()
            if k.startswith(f"{SCENE}/")} == before
    capsys.readouterr()
    assert cli.main(["generate", "--out", str(out), "--scene", SCENE, "--size", "16x12",
                     "--update"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len([x for x in err if "error" in x]) == 1 and "notes.txt" in err[-1], err
    # without the foreign files, the update keeps the scene from its listed files
    for name in ("id_rsa", "notes.txt", "zero", "home"):
        os.unlink(out / SCENE / name)
    golden.generate(out, [SCENE], sizes=["16x12"], update=True)
    m = load_manifest(out)
    assert sorted(m["scenes"]) == [SCENE, f"{SCENE}__16x12"]
    assert {k: v for k, v in m["files"].items() if k.startswith(f"{SCENE}/")} == before


# --- 4. TOML scenes: exact types, messages naming table, key, type and value ---------------------

TOML_OK = ('[viewport]\nwidth = 32\nheight = 24\n[camera]\nkind = "perspective"\n'
           'eye = [3.0, 2.0, 4.0]\ntarget = [0.0, 0.0, 0.0]\nfovy = 40.0\nnear = 1.0\n'
           'far = 20.0\n[[draw]]\nsolid = "cube"\n')

TOML_CASES = {
    "width string": (("width = 32", 'width = "32"'),
                     "[viewport] width must be an integer, got a string '32'"),
    "width float": (("width = 32", "width = 32.9"),
                    "[viewport] width must be an integer, got a float 32.9"),
    "width bool": (("width = 32", "width = true"),
                   "[viewport] width must be an integer, got a boolean true"),
    "width zero": (("width = 32", "width = 0"),
                   "[viewport] width must be between 1 and 32768, got an integer 0"),
    "viewport int": (("[viewport]\nwidth = 32\nheight = 24\n", "viewport = 5\n"),
                     "viewport must be a table, got an integer 5"),
    "mesh int": (('solid = "cube"', "mesh = 5"),
                 "[[draw]] 0: mesh must be a string (a path relative to the scene file), got "
                 "an integer 5"),
    "kind fisheye": (('kind = "perspective"', 'kind = "fisheye"'),
                     "[camera] kind must be one of ['frame', 'perspective', 'orthographic'], "
                     "got a string 'fisheye'"),
    "eye short": (("eye = [3.0, 2.0, 4.0]", "eye = [3.0, 2.0]"),
                  "[camera] eye must be an array of 3 finite numbers, got an array [3.0, 2.0]"),
    "fovy string": (("fovy = 40.0", 'fovy = "wide"'),
                    "[camera] fovy must be a finite number, got a string 'wide'"),
    "near inf": (("near = 1.0", "near = inf"),
                 "[camera] near must be a finite number, got a float inf"),
    "cull": (("[[draw]]", '[raster]\ncull = "sideways"\n[[draw]]'),
             "[raster] cull must be one of ['none', 'back', 'front'], got a string 'sideways'"),
    "bits float": (("[[draw]]", "[raster]\nsubpixel_bits = 8.0\n[[draw]]"),
                   "[raster] subpixel_bits must be an integer, got a float 8.0"),
    "depth_range": (("[[draw]]", '[raster]\ndepth_range = "minus_one_to_one"\n[[draw]]'),
                    "[raster] depth_range must be one of ['negative_one_to_one', "
                    "'zero_to_one'], got a string 'minus_one_to_one'"),
    "depth_clamp string": (("[[draw]]", '[raster]\ndepth_clamp = "yes"\n[[draw]]'),
                           "[raster] depth_clamp must be a boolean, got a string 'yes'"),
    "depth_format": (("[[draw]]", '[raster]\ndepth_format = "unorm32"\n[[draw]]'),
                     "[raster] depth_format must be one of ['float32', 'unorm24', 'unorm16'], "
                     "got a string 'unorm32'"),
    "reversed string": (("far = 20.0", 'far = 20.0\nreversed = "yes"'),
                        "[camera] reversed must be a boolean, got a string 'yes'"),
    "model": (('solid = "cube"', 'solid = "cube"\nmodel = [[1, 0, 0], [0, 1, 0]]'),
              "[[draw]] 0: model must be a 4x4 array of finite numbers"),
    "name int": (("[viewport]", "name = 7\n[viewport]"), "name must be a string, got an "
                                                         "integer 7"),
}


@pytest.mark.parametrize("case", list(TOML_CASES))
def test_toml_types_are_exact(tmp_path, case):
    (old, new), message = TOML_CASES[case]
    assert old in TOML_OK
    path = tmp_path / "scene.toml"
    path.write_text(TOML_OK.replace(old, new, 1))
    with pytest.raises(ValueError) as err:
        golden.generate(tmp_path / "never", scene_files=[path])
    assert str(err.value) == f"{path}: {message}" or str(err.value).startswith(
        f"{path}: {message}"), str(err.value)
    assert cli.main(["-q", "generate", "--out", str(tmp_path / "never"), "--scene-file",
                     str(path)]) == 2
    assert not (tmp_path / "never").exists()


# --- 5. a mesh with no triangles -----------------------------------------------------------------

def test_mesh_without_triangles_is_an_error(tmp_path, capsys):
    header = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nelement face {n}\nproperty list uchar int vertex_indices\n"
              "end_header\n0 0 0\n1 0 0\n0 1 0\n")
    (tmp_path / "empty.ply").write_text(header.format(n=0))
    (tmp_path / "lying.ply").write_text(header.format(n=0) + "3 0 1 2\n")   # face not declared
    for mesh in ("empty.ply", "lying.ply"):
        path = tmp_path / f"{mesh[:-4]}.toml"
        path.write_text(f'[viewport]\nwidth = 32\nheight = 24\n[[draw]]\nmesh = "{mesh}"\n')
        out = tmp_path / "g"
        assert cli.main(["-q", "generate", "--out", str(out), "--scene-file", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"mesh file '{tmp_path / mesh}' has no triangles" in err[0], err
        assert not out.exists()


# --- 7. every failure of the command line is one line, exit 2, whichever entry point -------------

def test_png_bomb_and_memory_error_are_one_line_in_both_entry_points(gold, tmp_path,
                                                                     monkeypatch, capsys):
    import subprocess
    import sys
    cand = tmp_path / "cand"
    (cand / SCENE).mkdir(parents=True)
    np.savez(cand / SCENE / "buffers.npz",
             **{k: v for k, v in golden_buffers(gold).items() if k != "depth"})
    (cand / SCENE / "depth.png").write_bytes(zero_png(14000, 14000))  # Pillow's bomb guard
    for entry in (["refraster.golden.cli", "compare"], ["refraster.cli", "golden", "compare"]):
        proc = subprocess.run([sys.executable, "-m", entry[0], "-q", *entry[1:], str(gold),
                               str(cand)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()     # -q: still the scene's error, one line
        assert len(lines) == 1 and lines[0].startswith(
            "golden compare: error: render_cube: cannot use candidate render_cube/depth.png: "
            "the PNG is 14000x14000"), proc.stderr
        proc = subprocess.run([sys.executable, "-m", *entry, str(gold), str(cand)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert "the PNG is 14000x14000" in proc.stderr, proc.stderr
    compare_module = __import__("sys").modules["refraster.golden.compare.run"]

    def boom(*args, **kwargs):
        raise MemoryError()
    monkeypatch.setattr(compare_module, "compare", boom)
    assert cli.main(["compare", str(gold), str(gold)]) == 2
    assert capsys.readouterr().err.splitlines() == ["golden compare: error: out of memory "
                                                    "(MemoryError)"]
    from refraster import cli as top
    assert top.main(["golden", "compare", str(gold), str(gold)]) == 2
    assert capsys.readouterr().err.splitlines() == ["golden compare: error: out of memory "
                                                    "(MemoryError)"]


def test_scene_file_must_be_a_regular_file(tmp_path):
    link = tmp_path / "zero.toml"
    link.symlink_to("/dev/zero")                  # read_text() would never end
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 100000 + "]" * 100000 + "\n")
    for path, message in ((link, "is not a regular file"), (tmp_path / "none.toml",
                                                             "does not exist"),
                          (deep, "cannot read scene file")):
        with pytest.raises(ValueError, match=message):
            golden.generate(tmp_path / "never", scene_files=[path])
        assert cli.main(["-q", "generate", "--out", str(tmp_path / "never"), "--scene-file",
                         str(path)]) == 2


def test_usage_errors_of_the_golden_command_are_one_line(gold, capsys):
    for argv in (["compare", str(gold)], ["compare", str(gold), str(gold), "--mode", "fuzzy"],
                 ["generate", "--workers", "two"]):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("refraster golden"), (argv, err)
