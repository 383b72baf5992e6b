"""The read side of the golden files under attack (issue 48 items 2, 7, 8, 11, 12, 13, 19;
docs/reliability.md "Files and the golden commands").

Every attack ends in one line naming the file (and the key or member) and exit status 2:
never a pass, a traceback, a hang or a read of gigabytes. Commands that could block on a FIFO
run in a child process with a timeout, so that a regression fails instead of hanging the run.
"""

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from refraster import golden
from refraster.golden import cli
from refraster.golden.compare.run import CandidateError, GoldenError, compare, load_manifest

SCENE = "render_cube"
HUGE = "9" * 5000          # beyond Python's int-string conversion limit (4300 digits)
DEEP = 200_000             # nesting far past the interpreter's recursion limit
#: A command refusing a special file answers in well under this (it blocked for ever before).
BLOCK_TIMEOUT = 60


@pytest.fixture(scope="module")
def gold(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden") / "g"
    golden.generate(out, [SCENE])
    return out


@pytest.fixture(scope="module")
def cand(gold, tmp_path_factory):
    """A candidate directory ``golden candidate`` wrote (with its marker)."""
    from conftest import gl_backend_or_skip
    gl_backend_or_skip().release()
    out = tmp_path_factory.mktemp("cand") / "c"
    from refraster.golden.candidate import candidate
    candidate(gold, out)
    return out


def golden_buffers(gold):
    with np.load(gold / SCENE / "buffers.npz", allow_pickle=False) as z:
        return {k: z[k].copy() for k in z.files}


def copy_tree(src, tmp_path, name):
    dst = tmp_path / name
    shutil.copytree(src, dst)
    return dst


def rehash(g, rel):
    """Make the manifest match an edited file (an attacker can do this)."""
    manifest = json.loads((g / "manifest.json").read_text())
    manifest["files"][rel] = hashlib.sha256((g / rel).read_bytes()).hexdigest()
    (g / "manifest.json").write_text(json.dumps(manifest))


def with_huge_int(doc, path):
    """``doc`` as JSON text with the value at ``path`` (keys and indices) a 5,000-digit
    integer (``json.dumps`` cannot write one)."""
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = "@HUGE@"
    return json.dumps(doc, indent=1).replace('"@HUGE@"', HUGE)


def peak_memory(fn):
    """``(fn(), peak traced memory in bytes above what was allocated before it ran)``."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        result = fn()
        return result, tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def one_line(text):
    lines = text.strip().splitlines()
    assert len(lines) == 1, lines[:5]
    return lines[0]


def cli_one_line(argv, capsys):
    """Run the golden command in this process: exit 2 and one line on stderr."""
    code = cli.main(argv)
    err = capsys.readouterr().err
    assert code == 2, (code, err[-2000:])
    line = one_line(err)
    assert "Traceback" not in line and "RecursionError" not in line, line
    return line


def cli_child(argv, timeout=BLOCK_TIMEOUT):
    """Run the golden command in a child process; a hang fails the test."""
    try:
        proc = subprocess.run([sys.executable, "-m", "refraster.golden.cli", *map(str, argv)],
                              capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail(f"golden {argv[0]} blocked for {timeout} s (a special file was opened)")
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    return one_line(proc.stderr)


def special_file(path, kind):
    """Put a FIFO or a listening socket at ``path``."""
    if kind == "fifo":
        os.mkfifo(path)
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(path))
    sock.listen(1)
    return sock


# --- 2. an npz member held twice ---------------------------------------------------------------

def write_npz_with_duplicate(path, arrays, key, second):
    """An npz holding ``key`` twice: the right values first, ``second`` after (``np.load``
    returns the second)."""
    np.savez(path, **arrays)
    data = path.read_bytes()
    extra = path.with_suffix(".extra.npz")
    np.savez(extra, **{key: second})
    with zipfile.ZipFile(extra) as src, zipfile.ZipFile(path, "a") as zf:
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")       # zipfile's "Duplicate name" warning
            zf.writestr(src.infolist()[0], src.read(src.infolist()[0]))
    extra.unlink()
    assert len(path.read_bytes()) > len(data)


def test_a_candidate_npz_holding_a_member_twice_is_refused_naming_it(gold, tmp_path, capsys):
    b = golden_buffers(gold)
    cand = tmp_path / "c"
    (cand / SCENE).mkdir(parents=True)
    npz = cand / SCENE / "buffers.npz"
    write_npz_with_duplicate(npz, b, "depth", np.zeros_like(b["depth"]))
    with np.load(npz, allow_pickle=False) as z:       # what a plain reader would take
        assert not np.array_equal(z["depth"], b["depth"])
    result = compare(gold, cand)
    assert result.exit_code == 2, result.summary()
    assert result.scenes[0].status == "error"
    message = result.scenes[0].error
    assert "buffers.npz" in message and "'depth'" in message and "twice" in message, message
    assert "does not have" not in result.summary()
    line = cli_one_line(["-q", "compare", str(gold), str(cand)], capsys)
    assert "buffers.npz" in line and "'depth'" in line and "twice" in line, line


def test_a_golden_npz_holding_a_member_twice_is_refused(gold, tmp_path):
    g = copy_tree(gold, tmp_path, "g")
    b = golden_buffers(gold)
    write_npz_with_duplicate(g / SCENE / "buffers.npz", b, "prim_id",
                             np.zeros_like(b["prim_id"]))
    rehash(g, f"{SCENE}/buffers.npz")
    with pytest.raises(GoldenError, match=r"buffers\.npz.*'prim_id'.*twice"):
        compare(g, gold)


# --- 13. an npz with 200,000 extra members -------------------------------------------------------

def add_empty_members(path, count):
    """Append ``count`` empty stored members (a zip64 central directory past 65,535)."""
    with zipfile.ZipFile(path, "a", allowZip64=True) as zf:
        for i in range(count):
            zf.writestr(f"x{i}", b"")


def test_an_npz_with_200000_extra_members_is_refused_in_one_short_line(gold, tmp_path, capsys):
    cand = tmp_path / "c"
    (cand / SCENE).mkdir(parents=True)
    npz = cand / SCENE / "buffers.npz"
    np.savez(npz, **golden_buffers(gold))
    assert compare(gold, cand).exit_code == 0
    _, clean_peak = peak_memory(lambda: compare(gold, cand))
    add_empty_members(npz, 200_000)
    started = time.monotonic()
    result, peak = peak_memory(lambda: compare(gold, cand))
    assert result.exit_code == 2, result.summary()[:2000]
    message = result.scenes[0].error
    assert "members" in message and "buffers.npz" in message and len(message) < 300, \
        message[:2000]
    assert peak < clean_peak + (16 << 20), (peak, clean_peak)   # 339 MB more before
    assert time.monotonic() - started < 30
    line = cli_one_line(["-q", "compare", str(gold), str(cand)], capsys)
    assert "members" in line and len(line) < 400, line[:2000]


def test_extra_npz_members_below_the_cap_are_named_in_a_short_warning(gold, tmp_path, caplog):
    cand = tmp_path / "c"
    (cand / SCENE).mkdir(parents=True)
    npz = cand / SCENE / "buffers.npz"
    np.savez(npz, **golden_buffers(gold))
    add_empty_members(npz, 300)
    import logging
    with caplog.at_level(logging.WARNING, logger="refraster.golden"):
        result = compare(gold, cand)
    assert result.exit_code == 0, result.summary()
    assert len(result.scenes[0].skipped) == 300
    warnings = [r.getMessage() for r in caplog.records if "skipped" in r.getMessage()]
    assert warnings and all(len(w) < 1000 for w in warnings), [len(w) for w in warnings]
    assert "300" in warnings[0] and "x0" in warnings[0]
    assert all(len(line) < 1000 for line in result.summary().splitlines())


# --- 7. integers beyond the int-string conversion limit ------------------------------------------

def test_a_huge_integer_in_the_manifest_is_one_line_naming_file_and_key(gold, tmp_path, capsys):
    g = copy_tree(gold, tmp_path, "g")
    doc = json.loads((g / "manifest.json").read_text())
    (g / "manifest.json").write_text(
        with_huge_int(doc, ["scenes", SCENE, "buffers", "depth", "shape", 0]))
    with pytest.raises(GoldenError) as info:
        load_manifest(g)
    message = str(info.value)
    assert "manifest.json" in message and "$.scenes.render_cube.buffers.depth.shape[0]" \
        in message and "5000 digits" in message, message
    line = cli_one_line(["compare", str(g), str(gold)], capsys)
    assert "manifest.json" in line and "shape[0]" in line, line


def test_a_huge_integer_in_scene_json_is_one_line_naming_file_and_key(gold, tmp_path, capsys):
    g = copy_tree(gold, tmp_path, "g")
    rel = f"{SCENE}/package/scene.json"
    doc = json.loads((g / rel).read_text())
    (g / rel).write_text(with_huge_int(doc, ["viewport", "width"]))
    rehash(g, rel)
    with pytest.raises(GoldenError) as info:
        compare(g, gold)
    message = str(info.value)
    assert "scene.json" in message and "$.viewport.width" in message, message
    line = cli_one_line(["compare", str(g), str(gold)], capsys)
    assert "scene.json" in line and "$.viewport.width" in line, line


def test_a_huge_integer_in_scene_json_read_by_the_gl_package_reader(gold, tmp_path):
    from refraster.gl.package import PackageError, read_scene
    pkg = copy_tree(gold / SCENE / "package", tmp_path, "pkg")
    doc = json.loads((pkg / "scene.json").read_text())
    (pkg / "scene.json").write_text(with_huge_int(doc, ["draws", 0, "object_id"]))
    with pytest.raises(PackageError) as info:
        read_scene(pkg)
    message = str(info.value)
    assert "scene.json" in message and "draws[0].object_id" in message, message
    assert "\n" not in message


def test_a_huge_integer_in_a_candidate_marker_is_one_line(gold, cand, tmp_path, capsys):
    c = copy_tree(cand, tmp_path, "c")
    doc = json.loads((c / ".refraster-candidate").read_text())
    (c / ".refraster-candidate").write_text(with_huge_int(doc, ["faults"]))
    line = cli_one_line(["candidate", str(gold), "--out", str(c)], capsys)
    assert ".refraster-candidate" in line and "$.faults" in line and "5000 digits" in line, line


def test_a_huge_integer_in_a_report_marker_is_one_line(gold, tmp_path, capsys):
    report = tmp_path / "r"
    assert cli.main(["-q", "compare", str(gold), str(gold), "--report", str(report)]) == 0
    capsys.readouterr()
    doc = json.loads((report / ".refraster-report").read_text())
    doc["files"] = dict(doc["files"])
    (report / ".refraster-report").write_text(with_huge_int(doc, ["written_at"]))
    line = cli_one_line(["compare", str(gold), str(gold), "--report", str(report)], capsys)
    assert ".refraster-report" in line and "$.written_at" in line, line


def test_a_huge_integer_in_a_toml_scene_is_one_line_naming_file_and_key(tmp_path, capsys):
    from refraster.golden.scenes import load_scene_file
    path = tmp_path / "s.toml"
    path.write_text(f'name = "s"\n[viewport]\nwidth = {HUGE}\n[[draw]]\nsolid = "cube"\n')
    with pytest.raises(ValueError) as info:
        load_scene_file(path)
    message = str(info.value)
    assert str(path) in message and "width" in message and "5000 digits" in message, message
    line = cli_one_line(["generate", "--out", str(tmp_path / "g"), "--scene-file", str(path)],
                        capsys)
    assert str(path) in line and "width" in line, line
    path.write_text('name = "s"\n[[draw]]\nsolid = "cube"\nmodel = [[1, 0, 0, 0],\n'
                    f'  [0, {HUGE}, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n')
    with pytest.raises(ValueError, match=r"s\.toml.*model.*5000 digits"):
        load_scene_file(path)


# --- 8. a marker nested 200,000 deep --------------------------------------------------------------

def test_a_deeply_nested_candidate_marker_is_one_line(gold, cand, tmp_path, capsys):
    c = copy_tree(cand, tmp_path, "c")
    (c / ".refraster-candidate").write_text("[" * DEEP + "]" * DEEP)
    line = cli_one_line(["candidate", str(gold), "--out", str(c)], capsys)
    assert ".refraster-candidate" in line and "nested too deeply" in line, line
    (c / ".refraster-candidate").write_text('{"files": ' + "{\"a\": " * DEEP + "1"
                                            + "}" * DEEP + "}")
    line = cli_one_line(["candidate", str(gold), "--out", str(c)], capsys)
    assert ".refraster-candidate" in line and "nested too deeply" in line, line


def test_a_deeply_nested_report_marker_is_one_line(gold, tmp_path, capsys):
    report = tmp_path / "r"
    report.mkdir()
    (report / ".refraster-report").write_text("{\"a\": " * DEEP + "1" + "}" * DEEP)
    line = cli_one_line(["compare", str(gold), str(gold), "--report", str(report)], capsys)
    assert ".refraster-report" in line and "nested too deeply" in line, line


# --- 12. side files size-capped and schema-checked -----------------------------------------------

def test_a_2gb_marker_is_refused_quickly_without_reading_it(gold, cand, tmp_path, capsys):
    c = copy_tree(cand, tmp_path, "c")
    with open(c / ".refraster-candidate", "r+b") as fh:
        fh.truncate(2 << 30)                           # sparse: nothing on disk
    started = time.monotonic()
    line, peak = peak_memory(lambda: cli_one_line(["candidate", str(gold), "--out", str(c)],
                                                  capsys))
    assert ".refraster-candidate" in line and "larger than" in line, line
    assert peak < 32 << 20, peak                        # 2.8 GB before
    assert time.monotonic() - started < 30              # 13.8 s before


def test_a_2gb_report_marker_is_refused_quickly(gold, tmp_path, capsys):
    _, clean_peak = peak_memory(lambda: cli.main(["-q", "compare", str(gold), str(gold)]))
    report = tmp_path / "r"
    report.mkdir()
    with open(report / ".refraster-report", "wb") as fh:
        fh.truncate(2 << 30)
    line, peak = peak_memory(lambda: cli_one_line(
        ["compare", str(gold), str(gold), "--report", str(report)], capsys))
    assert ".refraster-report" in line and "larger than" in line, line
    assert peak < clean_peak + (16 << 20), (peak, clean_peak)


@pytest.mark.parametrize("edit, key", [
    (lambda d: d.update(files=["render_cube/buffers.npz"]), "$.files"),
    (lambda d: d["files"].update({"render_cube/buffers.npz": 5}),
     "$.files.render_cube/buffers.npz"),
    (lambda d: d["files"].update({"render_cube/buffers.npz": "not a digest"}),
     "$.files.render_cube/buffers.npz"),
    (lambda d: d["files"].update({"../outside": "0" * 64}), "$.files"),
    (lambda d: d.update(rendered="render_cube"), "$.rendered"),
    (lambda d: d.update(skipped={"render_cube": 3}), "$.skipped.render_cube"),
], ids=["files-list", "digest-int", "digest-text", "path-leaves", "rendered-str",
        "skipped-int"])
def test_a_candidate_marker_breaking_its_schema_is_refused_naming_the_key(gold, cand, tmp_path,
                                                                         capsys, edit, key):
    c = copy_tree(cand, tmp_path, "c")
    doc = json.loads((c / ".refraster-candidate").read_text())
    edit(doc)
    (c / ".refraster-candidate").write_text(json.dumps(doc))
    line = cli_one_line(["candidate", str(gold), "--out", str(c)], capsys)
    assert ".refraster-candidate" in line and key in line, line
    assert (c / SCENE / "buffers.npz").is_file()        # nothing deleted


# --- 11. special files listed in a marker or a manifest, or as scene.json -------------------------

@pytest.mark.parametrize("kind", ["fifo", "socket"])
def test_golden_candidate_refuses_a_special_file_its_marker_lists(gold, cand, tmp_path, kind):
    c = copy_tree(cand, tmp_path, "c")
    (c / SCENE / "buffers.npz").unlink()
    sock = special_file(c / SCENE / "buffers.npz", kind)
    try:
        line = cli_child(["candidate", gold, "--out", c])
    finally:
        if sock is not None:
            sock.close()
    assert "buffers.npz" in line and "not a regular file" in line, line


def test_golden_candidate_refuses_a_fifo_marker(gold, cand, tmp_path):
    c = copy_tree(cand, tmp_path, "c")
    (c / ".refraster-candidate").unlink()
    os.mkfifo(c / ".refraster-candidate")
    line = cli_child(["candidate", gold, "--out", c])
    assert ".refraster-candidate" in line and "not a regular file" in line, line


def test_compare_report_refuses_a_fifo_its_marker_lists(gold, tmp_path, capsys):
    report = tmp_path / "r"
    assert cli.main(["-q", "compare", str(gold), str(gold), "--report", str(report)]) == 0
    capsys.readouterr()
    listed = json.loads((report / ".refraster-report").read_text())["files"]
    victim = report / sorted(listed)[0]
    victim.unlink()
    os.mkfifo(victim)
    line = cli_child(["compare", gold, gold, "--report", report])
    assert victim.name in line and "not a regular file" in line, line


def test_generate_update_refuses_a_fifo_its_manifest_lists(gold, tmp_path):
    g = copy_tree(gold, tmp_path, "g")
    victim = g / SCENE / "preview" / "depth.png"
    victim.unlink()
    os.mkfifo(victim)
    line = cli_child(["generate", "--out", g, "--update", "--scene", SCENE])
    assert "depth.png" in line and "not a regular file" in line, line


def test_the_gl_package_reader_refuses_a_fifo_scene_json(gold, tmp_path):
    pkg = copy_tree(gold / SCENE / "package", tmp_path, "pkg")
    (pkg / "scene.json").unlink()
    os.mkfifo(pkg / "scene.json")
    code = ("import sys\nfrom refraster.gl.package import PackageError, read_scene\n"
            f"try:\n    read_scene({str(pkg)!r})\n"
            "except PackageError as exc:\n    print(exc, file=sys.stderr)\n    sys.exit(2)\n")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=BLOCK_TIMEOUT, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail("read_scene blocked on a FIFO scene.json")
    assert proc.returncode == 2, proc.stderr
    line = one_line(proc.stderr)
    assert "scene.json" in line and "not a regular file" in line, line


def test_the_gl_package_reader_refuses_a_linked_scene_json(gold, tmp_path):
    from refraster.gl.package import PackageError, read_scene
    pkg = copy_tree(gold / SCENE / "package", tmp_path, "pkg")
    os.rename(pkg / "scene.json", tmp_path / "real.json")
    (pkg / "scene.json").symlink_to(tmp_path / "real.json")
    with pytest.raises(PackageError, match="scene.json"):
        read_scene(pkg)


# --- 19. candidate reads follow no link ----------------------------------------------------------

def test_a_linked_candidate_scene_directory_is_refused(gold, tmp_path, capsys):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    np.savez(elsewhere / "buffers.npz", **golden_buffers(gold))
    cand = tmp_path / "c"
    cand.mkdir()
    (cand / SCENE).symlink_to(elsewhere)
    result = compare(gold, cand)
    assert result.exit_code == 2, result.summary()
    message = result.scenes[0].error
    assert SCENE in message and "symbolic link" in message, message
    line = cli_one_line(["-q", "compare", str(gold), str(cand)], capsys)
    assert "symbolic link" in line, line


@pytest.mark.parametrize("name", ["buffers.npz", "depth.npy"])
def test_a_linked_candidate_file_is_refused(gold, tmp_path, name):
    b = golden_buffers(gold)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    if name == "buffers.npz":
        np.savez(elsewhere / name, **b)
    else:
        np.save(elsewhere / name, b["depth"])
        np.savez(tmp_path / "rest.npz", **{k: v for k, v in b.items() if k != "depth"})
    cand = tmp_path / "c"
    (cand / SCENE).mkdir(parents=True)
    if name == "depth.npy":
        shutil.move(tmp_path / "rest.npz", cand / SCENE / "buffers.npz")
    (cand / SCENE / name).symlink_to(elsewhere / name)
    result = compare(gold, cand)
    assert result.exit_code == 2, result.summary()
    assert "symbolic link" in result.scenes[0].error, result.scenes[0].error


def test_a_candidate_scene_that_is_a_fifo_is_refused_without_blocking(gold, tmp_path):
    cand = tmp_path / "c"
    (cand / SCENE).mkdir(parents=True)
    os.mkfifo(cand / SCENE / "buffers.npz")
    line = cli_child(["-q", "compare", gold, cand])
    assert "buffers.npz" in line and "not a regular file" in line, line


def test_candidate_error_is_a_value_error():
    assert issubclass(CandidateError, ValueError)
