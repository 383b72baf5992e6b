"""Issue 48, the write side and the messages (docs/reliability.md, "Files and the golden
commands"): special files as outputs (item 9), a planted journal (10), ``--debug`` and the exit
status (14), a duplicate ``--scene`` (15), control characters in names (16), an ``object_id``
beyond int32 (17), sizes and numbers beyond what the machinery holds (18). Each test is an
attack of the issue; each was seen failing on the code before its fix."""

import hashlib
import json
import os
import shutil
import socket
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refraster import cli as rcli
from refraster import golden
from refraster.golden import cli
from refraster.golden.candidate import candidate as run_candidate
from refraster.golden.io import schema, write

REPO = Path(__file__).resolve().parents[1]
CUBE, MULTI = "render_cube__32x24", "render_multi_draw__32x24"
PY = [sys.executable]


def _run(*args, timeout=600, **kw):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([*PY, *map(str, args)], capture_output=True, timeout=timeout,
                          stdin=subprocess.DEVNULL, env=env, **kw)


def names(directory):
    return sorted(p.name for p in Path(directory).iterdir())


def tree_digest(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(root).rglob("*")) if p.is_file() and not p.is_symlink()}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    out = tmp_path_factory.mktemp("relwrite") / "g"
    golden.generate(out, ["render_cube", "render_multi_draw"], sizes=["32x24"], jobs=1)
    return out


@pytest.fixture
def g(base, tmp_path):
    out = tmp_path / "g"
    shutil.copytree(base, out)
    return out


@pytest.fixture
def mesh_file(tmp_path):
    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return path


# --- special files ------------------------------------------------------------------------------

def _special(path, kind):
    """Make a FIFO, a socket or a character device (/dev/null's numbers) at ``path``;
    returns what keeps it alive (the socket) or skips when the system refuses."""
    if kind == "fifo":
        os.mkfifo(path)
        return None
    if kind == "socket":
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(path))
        return s
    try:
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod needs CAP_MKNOD here")
    return None


KIND = {"fifo": stat.S_ISFIFO, "socket": stat.S_ISSOCK, "device": stat.S_ISCHR}
WORD = {"fifo": "a FIFO", "socket": "a socket", "device": "a character device"}


@pytest.mark.parametrize("kind", ["fifo", "socket", "device"])
@pytest.mark.parametrize("option", ["--out", "--buffers"])
def test_render_output_that_is_a_special_file_is_refused_before_rendering(
        mesh_file, tmp_path, capsys, monkeypatch, kind, option):
    import refraster
    target = tmp_path / ("dev.png" if option == "--out" else "dev.npz")
    keep = _special(target, kind)
    before = names(tmp_path)
    monkeypatch.setattr(refraster, "render", lambda *a, **k: pytest.fail("rendered"))
    argv = ["render", str(mesh_file), "--out", str(tmp_path / "x.png"), "-q"]
    argv[3] = str(target) if option == "--out" else argv[3]
    if option == "--buffers":
        argv += ["--buffers", str(target)]
    assert rcli.main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"refraster: error: {option} '{target}' is {WORD[kind]}, not a regular "
                   "file; refraster writes only regular files (use '-' for standard output)"], err
    assert KIND[kind](os.lstat(target).st_mode)          # never replaced by a regular file
    assert names(tmp_path) == before                     # nothing staged beside it
    if keep is not None:
        keep.close()


def test_render_output_linked_to_a_device_is_refused(mesh_file, tmp_path, capsys):
    link = tmp_path / "null.png"
    link.symlink_to("/dev/null")
    assert rcli.main(["render", str(mesh_file), "--out", str(link), "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "is a character device" in err[0], err
    assert link.is_symlink() and os.readlink(link) == "/dev/null"


@pytest.mark.parametrize("kind", ["fifo", "socket", "device"])
def test_compare_json_to_a_special_file_is_refused_before_comparing(g, tmp_path, capsys,
                                                                     kind):
    w = tmp_path / "w"
    w.mkdir()
    target = w / "null"
    keep = _special(target, kind)
    assert cli.main(["compare", str(g), str(g), "--json", str(target), "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"golden compare: error: --json {target} is {WORD[kind]}, not a regular "
                   "file; refraster writes only regular files (use '-' for standard output)"], err
    assert KIND[kind](os.lstat(target).st_mode)
    assert names(w) == ["null"]
    if keep is not None:
        keep.close()


@pytest.mark.parametrize("argv", [
    ["golden", "generate", "--out", "{f}", "--scene", "render_cube", "--size", "32x24",
     "--jobs", "1", "--update"],
    ["golden", "candidate", "{g}", "--out", "{f}"],
    ["golden", "compare", "{g}", "{g}", "--report", "{f}"],
    ["gallery", "--out", "{f}", "--quick", "--jobs", "1"],
], ids=["generate", "candidate", "compare-report", "gallery"])
def test_directory_outputs_that_are_fifos_are_refused_and_kept(g, tmp_path, capsys, argv):
    fifo = tmp_path / "w" / "f"
    fifo.parent.mkdir()
    os.mkfifo(fifo)
    assert rcli.main([a.format(f=fifo, g=g) for a in argv] + ["-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and str(fifo) in err[0], err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and names(fifo.parent) == ["f"]


def test_a_fifo_planted_at_the_target_during_the_commit_is_kept(tmp_path, monkeypatch):
    """The check before the rename too: a FIFO that appears after staging is not replaced."""
    monkeypatch.setattr(write, "HOOKS", {})
    target = tmp_path / "m.json"
    write.HOOKS["commit_step"] = lambda index, target: os.mkfifo(target)
    outputs = write.Outputs()
    outputs.file(target, b"{}\n")
    with pytest.raises(write.RefusedError, match="is a FIFO, not a regular file"):
        outputs.commit()
    assert stat.S_ISFIFO(os.lstat(target).st_mode)
    assert names(tmp_path) == ["m.json"]


def test_atomic_write_bytes_refuses_a_special_file(tmp_path):
    from refraster.io import atomic_write_bytes
    target = tmp_path / "index.html"
    os.mkfifo(target)
    with pytest.raises(ValueError, match="is a FIFO, not a regular file"):
        atomic_write_bytes(target, b"<html>")
    assert stat.S_ISFIFO(os.lstat(target).st_mode) and names(tmp_path) == ["index.html"]


def test_dash_writes_the_json_to_standard_output(g, tmp_path):
    (tmp_path / "cwd").mkdir()
    proc = _run("-m", "refraster.golden.cli", "compare", g, g, "--json", "-",
                cwd=tmp_path / "cwd")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)                         # standard output is the JSON alone
    assert sorted(doc["scenes"]) == [CUBE, MULTI]
    assert b"result: PASS" in proc.stderr                # the summary moved to stderr
    assert names(tmp_path / "cwd") == []                  # no file named '-'


def test_dash_writes_the_png_to_standard_output(mesh_file, tmp_path):
    proc = _run("-m", "refraster.cli", "render", mesh_file, "--out", "-", "--width", "32",
                "--height", "24", "--buffers", tmp_path / "b.npz", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(b"\x89PNG\r\n\x1a\n")
    assert names(tmp_path) == ["b.npz", "tri.obj"]
    both = _run("-m", "refraster.cli", "render", mesh_file, "--out", "-", "--buffers", "-",
                cwd=tmp_path)
    assert both.returncode == 2 and both.stdout == b""
    assert both.stderr.decode().splitlines() == [
        "refraster: error: --out and --buffers cannot both be '-' (standard output)"]


# --- a planted journal --------------------------------------------------------------------------

def _victim(g):
    """A sibling tree refraster would remove file by file (its manifest lists its file)."""
    victim = g.parent / ".g.victim"
    victim.mkdir()
    (victim / "thesis.txt").write_text("four years")
    digest = hashlib.sha256(b"four years").hexdigest()
    (victim / "manifest.json").write_text(json.dumps({"files": {"thesis.txt": digest}}))
    return victim


def _journal(g, **doc):
    path = g.parent / ".g.journal"
    path.write_text(json.dumps({"target": "g", "new": ".g.x", "old": ".g.victim", **doc}))
    return path


def test_compare_never_acts_on_a_planted_journal(g, capsys):
    victim = _victim(g)
    journal = _journal(g)
    before = tree_digest(g.parent)
    assert cli.main(["compare", str(g), str(g), "-q"]) == 0
    assert golden.compare(g, g).exit_code == 0
    assert tree_digest(g.parent) == before               # victim, journal, golden: untouched
    assert (victim / "thesis.txt").read_text() == "four years" and journal.exists()


def test_compare_of_a_golden_in_mid_swap_names_the_journal(g, capsys):
    _victim(g)
    journal = _journal(g)
    g.rename(g.parent / ".g.x")                          # as a killed two-renames swap leaves
    before = tree_digest(g.parent)
    assert cli.main(["compare", str(g), str(g), "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and str(journal) in err[0] and "golden generate" in err[0], err
    assert tree_digest(g.parent) == before and not g.exists()


def test_candidate_never_acts_on_a_journal_beside_the_golden(g, tmp_path):
    _victim(g)
    _journal(g)
    before = tree_digest(g.parent)
    with pytest.raises(Exception):                       # whatever the backend says ...
        run_candidate(g, tmp_path / "c", scenes=["no_such_scene"])
    assert tree_digest(g.parent) == before               # ... the golden's side is untouched


@pytest.mark.parametrize("doc, why", [
    ({}, "old"),                                                  # old not an .old- tree
    ({"new": ".g.tmp-1-a", "old": ".g.old-1-b/../../x"}, "old"),
    ({"new": "../g.tmp-1-a", "old": ".g.old-1-b"}, "new"),
    ({"target": "h", "new": ".g.tmp-1-a", "old": ".g.old-1-b"}, "target"),
    ({"new": ".g.tmp-1-a", "old": ".g.old-1-b", "extra": 1}, "extra"),
    ({"new": ".g.tmp-1-a\n", "old": ".g.old-1-b"}, "new"),
])
def test_generate_refuses_a_journal_that_is_not_one_it_wrote(g, capsys, doc, why):
    victim = _victim(g)
    journal = _journal(g, **doc)
    before = tree_digest(g.parent)
    assert cli.main(["generate", "--out", str(g), "--update", "--scene", "render_cube",
                     "--size", "32x24", "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and str(journal) in err[0] and "refusing to act on it" in err[0], err
    assert tree_digest(g.parent) == before and victim.exists()


def test_generate_refuses_a_journal_too_large_linked_or_special(g, tmp_path):
    journal = g.parent / ".g.journal"
    journal.write_bytes(b" " * (1 << 20) + b"{}")
    with pytest.raises(write.RefusedError, match="larger than"):
        write.recover(g)
    journal.unlink()
    elsewhere = tmp_path / "elsewhere.json"
    elsewhere.write_text(json.dumps({"target": "g", "new": ".g.tmp-1-a", "old": ".g.old-1-b"}))
    journal.symlink_to(elsewhere)
    with pytest.raises(write.RefusedError, match="symbolic link"):
        write.recover(g)
    journal.unlink()
    os.mkfifo(journal)                                    # refused without blocking on it
    with pytest.raises(write.RefusedError, match="not a regular file"):
        write.recover(g)
    assert stat.S_ISFIFO(os.lstat(journal).st_mode)


def test_generate_refuses_a_journal_whose_trees_are_links(g, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("mine")
    name = ".g.tmp-1-a"
    (g.parent / name).symlink_to(elsewhere)
    g.rename(g.parent / ".g.old-1-b")
    _journal(g, new=name, old=".g.old-1-b")
    with pytest.raises(write.RefusedError, match="symbolic link"):
        write.recover(g)
    assert not g.exists() and (elsewhere / "keep.txt").read_text() == "mine"


def test_the_journal_of_a_real_killed_swap_is_still_rolled_forward(g):
    """What generate writes passes the checks: a swap stopped between its two renames."""
    new = write.make_tree(g)
    shutil.copytree(g, new, dirs_exist_ok=True)
    old = g.parent / f".g.old-{os.getpid()}-zz"
    (g.parent / ".g.journal").write_text(json.dumps({"target": "g", "new": new.name,
                                                     "old": old.name}))
    g.rename(old)
    assert write.recover(g) == "rolled forward"
    assert names(g.parent) == ["g"]


# --- --debug keeps the exit status --------------------------------------------------------------

def test_debug_keeps_exit_status_2_for_unusable_input(tmp_path):
    text = tmp_path / "notes.obj"
    text.write_text("hello\n")
    proc = _run("-m", "refraster.cli", "render", text, "--out", tmp_path / "x.png", "--debug")
    assert proc.returncode == 2 and b"Traceback" in proc.stderr, proc.stderr
    assert proc.stderr.decode().splitlines()[-1].startswith("refraster: error: mesh file")
    missing = tmp_path / "missing"
    for argv in (["-m", "refraster.cli", "golden", "compare", missing, missing, "--debug"],
                 ["-m", "refraster.golden.cli", "compare", missing, missing, "--debug"]):
        proc = _run(*argv)
        assert proc.returncode == 2 and b"Traceback" in proc.stderr, proc.stderr
        assert proc.stderr.decode().splitlines()[-1].startswith("golden compare: error:")


# --- a duplicate --scene ------------------------------------------------------------------------

def test_candidate_refuses_a_duplicate_scene_before_rendering(g, tmp_path, capsys, monkeypatch):
    from refraster.golden import candidate as cand
    monkeypatch.setattr(cand, "_open_backend", lambda *a: pytest.fail("backend opened"))
    assert cli.main(["candidate", str(g), "--out", str(tmp_path / "c"), "--scene", CUBE,
                     "--scene", MULTI, "--scene", CUBE]) == 2
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        f"golden candidate: error: --scene {CUBE} is given twice"], captured.err
    assert captured.out == "" and names(tmp_path) == ["g"]
    with pytest.raises(ValueError, match="given twice"):
        run_candidate(g, tmp_path / "c", scenes=[CUBE, CUBE])


# --- control characters in names ----------------------------------------------------------------

def _scene_doc(g, scene=CUBE):
    return json.loads((g / scene / "package" / "scene.json").read_text())


@pytest.mark.parametrize("bad", ["cube\n", "cube\r", "cu\tbe", "cube\x00", "cube\x7f"])
def test_schema_refuses_names_with_control_characters(g, bad):
    doc = _scene_doc(g)
    ctrl = next(c for c in bad if ord(c) < 32 or ord(c) == 127)
    for path, edit in (("$.name", lambda d: d.__setitem__("name", bad)),
                       ("$.draws[0].name", lambda d: d["draws"][0].__setitem__("name", bad)),
                       ("$.draws[0].mesh", lambda d: d["draws"][0].__setitem__(
                           "mesh", d["draws"][0]["mesh"] + ctrl))):
        d = json.loads(json.dumps(doc))
        edit(d)
        with pytest.raises(schema.SchemaError, match=r"control character") as exc:
            schema.validate(d, schema.SCENE_SCHEMA)
        assert str(exc.value).startswith(path), exc.value
    manifest = json.loads((g / "manifest.json").read_text())
    manifest["scenes"][CUBE + "\n"] = manifest["scenes"].pop(CUBE)
    with pytest.raises(schema.SchemaError, match="control character"):
        schema.validate(manifest, schema.MANIFEST_SCHEMA)


def _toml(tmp_path, text, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


TOML_BODY = '[viewport]\nwidth = 32\nheight = 24\n'


@pytest.mark.parametrize("text, key", [
    ('name = "cube\\n"\n' + TOML_BODY + '[[draw]]\nsolid = "cube"\n', "name"),
    ('name = "cu\\tbe"\n' + TOML_BODY + '[[draw]]\nsolid = "cube"\n', "name"),
    (TOML_BODY + '[[draw]]\nsolid = "cube"\nname = "x\\n"\n', "[[draw]] 0: name"),
    (TOML_BODY + '[[draw]]\nmesh = "tri.obj\\n"\n', "[[draw]] 0: mesh"),
])
def test_toml_names_with_control_characters_are_refused(tmp_path, text, key):
    from refraster.golden.scenes import load_scene_file
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError) as exc:
        load_scene_file(_toml(tmp_path, text)).fn()
    msg = str(exc.value)
    assert f": {key} must not contain control characters" in msg and "\n" not in msg, msg


def test_registered_and_draw_names_with_a_newline_are_refused():
    from refraster.golden.scenes import Draw, prepare_draws, register_scene
    with pytest.raises(ValueError, match="control characters"):
        register_scene("cube\n", technique="render")
    tri = (np.eye(3), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="control characters"):
        prepare_draws([Draw("x\n", tri)])


# --- object_id beyond int32 ---------------------------------------------------------------------

def _plant_scene(g, edit, scene=CUBE, size=None):
    """Edit a package's scene.json and its sha256 in the manifest (a golden someone altered);
    ``size``: the manifest's buffer shapes say that size too."""
    path = g / scene / "package" / "scene.json"
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    manifest = json.loads((g / "manifest.json").read_text())
    if size is not None:
        for b in manifest["scenes"][scene]["buffers"].values():
            b["shape"][:2] = [size[1], size[0]]
    manifest["files"][f"{scene}/package/scene.json"] = hashlib.sha256(
        path.read_bytes()).hexdigest()
    (g / "manifest.json").write_text(json.dumps(manifest))


def test_schema_caps_object_id_at_what_the_buffers_hold(g):
    doc = _scene_doc(g)
    doc["draws"][0]["object_id"] = 2 ** 31
    with pytest.raises(schema.SchemaError) as exc:
        schema.validate(doc, schema.SCENE_SCHEMA)
    assert str(exc.value) == "$.draws[0].object_id: must be <= 2147483646, got 2147483648"
    doc["draws"][0]["object_id"] = 2 ** 31 - 2
    schema.validate(doc, schema.SCENE_SCHEMA)


def test_candidate_with_a_huge_object_id_names_the_key(g, tmp_path, capsys):
    pytest.importorskip("moderngl")
    from conftest import gl_backend_or_skip
    gl_backend_or_skip().release()
    _plant_scene(g, lambda d: d["draws"][0].__setitem__("object_id", 2 ** 31))
    assert cli.main(["candidate", str(g), "--out", str(tmp_path / "c"), "--scene", CUBE,
                     "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "draws[0].object_id" in err[0] and "2147483646" in err[0], err
    assert "error: error:" not in err[0] and "format requires" not in err[0]


def test_an_error_class_named_error_is_not_doubled(capsys):
    import struct
    try:
        struct.pack("i", 2 ** 31)
    except struct.error as exc:
        assert cli._error(None, "golden candidate", exc) == 2
    err = capsys.readouterr().err
    assert err.startswith("golden candidate: error: struct.error: ") and \
        "error: error:" not in err, err


# --- sizes and numbers beyond the machinery -----------------------------------------------------

def test_gl_names_a_viewport_beyond_its_limit(g, tmp_path, capsys):
    pytest.importorskip("moderngl")
    from conftest import gl_backend_or_skip
    gl_backend_or_skip().release()
    _plant_scene(g, lambda d: d["viewport"].update(width=32768, height=2048),
                 size=(32768, 2048))
    assert cli.main(["candidate", str(g), "--out", str(tmp_path / "c"), "--scene",
                     CUBE]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith(f"skipped {CUBE}"))
    assert "32768x2048" in line and "GL_MAX_" in line and "0x501" not in line, out


def test_a_300_character_toml_name_names_the_key_and_the_limit(tmp_path, capsys):
    path = _toml(tmp_path, f'name = "{"a" * 300}"\n' + TOML_BODY + '[[draw]]\nsolid = "cube"\n')
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"golden generate: error: {path}: name must be at most 128 characters "
                   "(it names directories), got 300"], err


def test_a_toml_camera_beyond_float32_names_the_projection(tmp_path, capsys):
    path = _toml(tmp_path, TOML_BODY + '[camera]\nkind = "perspective"\neye = [3.0, 2.0, 4.0]\n'
                 'target = [0.0, 0.0, 0.0]\nfovy = 35.0\nnear = 1e-300\nfar = 1e300\n'
                 '[[draw]]\nsolid = "cube"\n')
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{path}: [camera]" in err[0] and "float32" in err[0], err
    assert "finite" not in err[0]


def test_perspective_refuses_terms_that_leave_float32():
    import refraster as rf
    with pytest.raises(ValueError, match=r"near=1e-300, far=1e\+300.*float32"):
        rf.perspective(35, 1.0, 1e-300, 1e300)
    with pytest.raises(ValueError, match=r"near=1e-300.*float32"):
        rf.perspective(35, 1.0, 1e-300, 10.0)
    with pytest.raises(ValueError, match=r"fovy=1e-38.*float32"):
        rf.perspective(1e-38, 1.0, 1.0, 10.0)
    with pytest.raises(ValueError, match=r"float32"):
        rf.orthographic(-1, 1, -1, 1, 0.0, 1e39)
    # the ordinary and the extreme-but-representable are unchanged
    rf.perspective(35, 1.0, 1e-6, 1e12)
    rf.perspective(35, 1.0, 0.1, float("inf"))


def test_render_fov_too_narrow_names_fov(mesh_file, tmp_path, capsys):
    assert rcli.main(["render", str(mesh_file), "--out", str(tmp_path / "x.png"),
                      "--fov", "1e-30", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("refraster: error: --fov 1e-30: too narrow"), err
    assert "far must be greater than near" not in err[0]
    assert not (tmp_path / "x.png").exists()


def test_render_near_far_beyond_float32_names_them(mesh_file, tmp_path, capsys):
    assert rcli.main(["render", str(mesh_file), "--out", str(tmp_path / "x.png"),
                      "--near", "1e-300", "--far", "1e300", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "--near 1e-300" in err[0] and "float32" in err[0], err


# --- found by the fuzz harness (tests/test_fuzz_scenes.py) --------------------------------------

def test_smooth_normals_never_merge_distinct_vertices_beyond_trimesh_rounding(tmp_path,
                                                                            monkeypatch):
    """trimesh merges vertices on coordinates rounded to 1e-8 as int64: beyond ~9.2e10 that
    overflows (a RuntimeWarning) and distinct vertices merge — (1e12, 0, 0) and (2e12, 0, 0)
    became one, and the triangle vanished from the smooth-shaded frame."""
    mesh = tmp_path / "far.obj"
    mesh.write_text("v 0 1e12 0\nv 1e12 0 0\nv 2e12 0 0\nf 1 2 3\n")
    masks = {}
    for normals in ("flat", "smooth"):
        out = tmp_path / f"{normals}.npz"
        assert rcli.main(["render", str(mesh), "--out", str(tmp_path / f"{normals}.png"),
                          "--buffers", str(out), "--width", "32", "--height", "24",
                          "--normals", normals, "-q"]) == 0
        masks[normals] = np.load(out)["prim_id"] >= 0
    assert masks["flat"].any() and (masks["flat"] == masks["smooth"]).all()


def test_look_at_far_away_or_close_by_has_no_overflow(mesh_file, tmp_path, capsys):
    """An eye at 1e300 overflowed the norm's squares (a RuntimeWarning, then "up must not be
    parallel …" from the zero direction it left); an eye 1e-200 from the target underflowed
    them ("eye and target must differ"). Found by the fuzz harness."""
    import refraster as rf
    far = rf.look_at([1e300, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert np.array_equal(far[2, :3], [1.0, 0.0, 0.0]) and np.isclose(far[2, 3], -1e300)
    near = rf.look_at([1e-200, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert np.array_equal(near[2, :3], [1.0, 0.0, 0.0])
    ordinary = rf.look_at([1.0, 2.0, 3.0], [0.0, 0.5, 0.0])
    f = np.array([-1.0, -1.5, -3.0])
    assert np.array_equal(ordinary[2, :3], -(f / np.linalg.norm(f)))   # the same bytes
    with pytest.raises(ValueError, match="too far apart"):
        rf.look_at([1.7e308, 0.0, 0.0], [-1.7e308, 0.0, 0.0])
    assert rcli.main(["render", str(mesh_file), "--out", str(tmp_path / "x.png"), "--eye",
                      "1e300", "0.5", "0", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("refraster: error: --eye 1e+300 0.5 0: "), err


def test_a_toml_frame_camera_with_a_zero_direction_names_it(tmp_path, capsys):
    """``direction = [0, 0, 0]`` divided by its zero norm: 'RuntimeWarning: invalid value
    encountered in divide' (found by the fuzz harness)."""
    path = _toml(tmp_path, TOML_BODY + '[camera]\ndirection = [0.0, 0.0, 0.0]\n'
                 '[[draw]]\nsolid = "cube"\n')
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"golden generate: error: {path}: [camera] direction must not be the zero "
                   "vector"], err



#: The fuzz harness's 10⁴-case run (2026-12-04): a triangle drawn twice each way round.
CANCELLING_OBJ = ("v -0.9182562204804083 -0.4598014730790345 1.3183565944521054\n"
                  "v 1.3332853637345776 -1.3992106289976538 -1.3232249303201957\n"
                  "v -1.495552267141217 0.4866507563791944 -0.17041779625766962\n"
                  "f 1 3 2\nf 3 2 1\nf 2 3 1\nf 2 3 1\n")


def test_a_toml_scene_whose_smooth_normals_cancel_names_the_draw(tmp_path, capsys):
    """Smooth normals summed from a face and its reverse are 0: the golden stored a zero
    normal on covered pixels and failed its own compare (found by the fuzz harness)."""
    (tmp_path / "m0.obj").write_text(CANCELLING_OBJ)
    path = _toml(tmp_path, TOML_BODY + '[raster]\nnormals = "smooth"\n[[draw]]\nmesh = "m0.obj"\n')
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"golden generate: error: {path}: draw[0].mesh: the smooth normal of vertex 0 is "
        "undefined"), err
    assert not (tmp_path / "g").exists() or not any((tmp_path / "g").iterdir())
    # flat normals are defined: the same mesh makes a golden that passes itself
    path.write_text(path.read_text().replace('normals = "smooth"', 'normals = "flat"'))
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 0
    for mode in (None, "tolerant"):   # the golden's own mode, then tolerant
        assert golden.compare(tmp_path / "g", tmp_path / "g", mode=mode).exit_code == 0


@pytest.mark.parametrize("raster", ['subpixel_bits = 4', 'fill_rule = "top_left"',
                                    'precision = "float64"'])
def test_a_golden_of_a_non_default_reference_raster_passes_itself(tmp_path, raster):
    """The allowance's coverage is the reference's own: with the scene's sub-pixel bits, fill
    rule and precision, not the defaults (at 4 bits it said "must be covered" at 4 pixels
    the reference left empty; found by the fuzz harness)."""
    (tmp_path / "m0.obj").write_text(CANCELLING_OBJ)
    path = _toml(tmp_path, 'name = "fz"\n[camera]\nkind = "frame"\nfovy = 5.35\n'
                 'direction = [-3.836815757877854, -6.0, 1.5179350005708705e-287]\n'
                 f'[raster]\n{raster}\n[[draw]]\nmesh = "m0.obj"\n'
                 'model = [[1.8075204463268892, 0.0, 0.0, 0.19342228198779066], '
                 '[0.0, 1.8075204463268892, 0.0, 0.0], '
                 '[0.0, 0.0, 1.8075204463268892, 0.39194114517104794], [0, 0, 0, 1]]\n')
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path),
                     "--jobs", "1", "-q"]) == 0
    for mode in (None, "tolerant"):   # the golden's own mode, then tolerant
        result = golden.compare(tmp_path / "g", tmp_path / "g", mode=mode)
        assert result.exit_code == 0, (mode, result.failures()[:3])


def test_a_golden_with_another_clear_depth_passes_itself_and_holds_its_cut(tmp_path):
    """``clear_depth = 0.5`` under ``less``: the reference drops the fragments behind 0.5, and
    the allowance follows its coverage (the geometric masks said "must be covered" there; found
    by the fuzz harness, 2026-12-04). A candidate that clears to 1 draws them and fails."""
    import numpy as np

    from refraster.golden.scenes import raster_state, render_draws
    for size in ((4, 4), (32, 24)):
        path = _toml(tmp_path, f'name = "c"\n[viewport]\nwidth = {size[0]}\nheight = {size[1]}\n'
                     '[raster]\nclear_depth = 0.5\n[[draw]]\nsolid = "cube"\n')
        out = tmp_path / f"g{size[0]}"
        assert cli.main(["generate", "--out", str(out), "--scene-file", str(path), "--jobs",
                         "1", "-q"]) == 0
        for mode in (None, "tolerant"):
            assert golden.compare(out, out, mode=mode).exit_code == 0, (size, mode)
    # the candidate that ignores the clear depth: the same draws cleared to 1
    from refraster.golden.scenes import load_scene_file
    built = load_scene_file(path).build()
    fb = render_draws(built.draws, built.camera, {**raster_state(built.raster),
                                                  "clear_depth": 1.0})
    cand = tmp_path / "cand" / "c"
    cand.mkdir(parents=True)
    np.savez(cand / "buffers.npz", **fb.arrays())
    assert (fb.prim_id >= 0).sum() > 0
    result = golden.compare(out, tmp_path / "cand", mode="tolerant")
    assert result.exit_code != 0


@pytest.mark.parametrize("func", ["always", "equal", "notequal", "never", "greater", "gequal"])
def test_a_golden_under_any_depth_function_with_another_clear_passes_itself(tmp_path, func):
    """``clear_depth = 0.5`` under a depth test with no direction (``always``, ``equal``,
    ``notequal``, ``never``) or the reversed one: the buffer's depths lie on both sides of the
    clear value, so coverage is not "in front of the clear depth" (the golden failed itself on
    ``depth`` at 9,831 pixels under ``always``; found by the fuzz harness, 2026-12-04)."""
    path = _toml(tmp_path, 'name = "c"\n[viewport]\nwidth = 32\nheight = 24\n'
                 f'[raster]\nclear_depth = 0.5\ndepth_func = "{func}"\n'
                 '[[draw]]\nsolid = "cube"\n')
    out = tmp_path / "g"
    assert cli.main(["generate", "--out", str(out), "--scene-file", str(path), "--jobs",
                     "1", "-q"]) == 0
    for mode in (None, "tolerant"):
        result = golden.compare(out, out, mode=mode)
        assert result.exit_code == 0, (mode, result.failures()[:3])
    # and a candidate that ignores the declared test (draws under "less") fails
    import numpy as np

    from refraster.golden.scenes import load_scene_file, raster_state, render_draws
    built = load_scene_file(path).build()
    fb = render_draws(built.draws, built.camera, {**raster_state(built.raster),
                                                  "depth_func": "less"})
    assert (fb.prim_id >= 0).sum() > 0
    cand = tmp_path / "cand" / "c"
    cand.mkdir(parents=True)
    np.savez(cand / "buffers.npz", **fb.arrays())
    assert golden.compare(out, tmp_path / "cand", mode="tolerant").exit_code != 0


@pytest.mark.parametrize("case", ["frame_fovy_zero", "clipped_beyond_float32"])
def test_fuzz_found_scenes_end_in_one_line_naming_the_cause(tmp_path, capsys, case):
    """Found by the 10⁴-case TOML run (2026-12-04): a ``frame`` camera with ``fovy = 0`` ended
    in ``RuntimeWarning: divide by zero`` and a float64-precision scene whose clipped face
    reaches clip coordinates beyond float32 in ``RuntimeWarning: overflow encountered in
    cast`` (the allowances' float32 ulp of them), not in lines naming the cause."""
    import warnings
    if case == "frame_fovy_zero":
        text = ('name = "c"\n[viewport]\nwidth = 4\nheight = 4\n[camera]\nkind = "frame"\n'
                'fovy = 0.0\n[[draw]]\nsolid = "cube"\n')
        want = "[camera] fovy must be > 0.0, got 0.0"
    else:
        (tmp_path / "m0.obj").write_text("v 0.39716795569590957 0.0 0.0\nv 0.0 0.0 0.0\n"
                                         "v 0.0 0.0 3e+38\nf 1 2 3\n")
        text = ('name = "z"\n[viewport]\nwidth = 4\nheight = 4\n[camera]\n'
                'kind = "perspective"\neye = [0.0, 3.35, 1.0]\ntarget = [0.0, 0.0, 0.0]\n'
                'near = 0.5325990817148879\nfar = 512.5248786281053\nfovy = 5.0\n'
                '[raster]\nprecision = "float64"\ncull = "none"\n[[draw]]\nmesh = "m0.obj"\n')
        want = "scene 'z': its allowances: a face crossing a clip plane has clip coordinates"
    path = _toml(tmp_path, text)
    out = tmp_path / "out"
    out.mkdir()
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = cli.main(["generate", "--out", str(out / "g"), "--scene-file", str(path),
                         "--jobs", "1", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and want in err, err
    assert os.listdir(out) == []
