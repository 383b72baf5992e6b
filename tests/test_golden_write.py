"""Golden writes never destroy data (issue 17): every attack of the issue, the data that must
survive it, races made deterministic with the hooks of :mod:`refraster.golden.io.write` (no
sleeps) and crashes made by a hook that kills the process between two steps."""

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from refraster import cli as rcli
from refraster import golden
from refraster.golden import cli
from refraster.golden.io import write
from refraster.golden.compare.run import load_manifest

REPO = Path(__file__).resolve().parents[1]
SIZE = ["32x24"]
CUBE, MULTI, TORUS = "render_cube__32x24", "render_multi_draw__32x24", "render_torus_ortho__32x24"


def tree_digest(root):
    """sha256 of every file under root (relative paths): what must survive."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(root).rglob("*")) if p.is_file()}


def names(directory):
    return sorted(p.name for p in Path(directory).iterdir())


def gen(out, scene, **kw):
    return golden.generate(out, [scene], sizes=SIZE, **kw)


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A small golden holding render_cube at 32x24."""
    out = tmp_path_factory.mktemp("base") / "g"
    gen(out, "render_cube")
    return out


@pytest.fixture
def g(base, tmp_path):
    out = tmp_path / "g"
    shutil.copytree(base, out)
    return out


@pytest.fixture
def hooks(monkeypatch):
    monkeypatch.setattr(write, "HOOKS", {})
    return write.HOOKS


def candidate(gold, root):
    cand = root / "cand"
    for scene in load_manifest(gold)["scenes"]:
        (cand / scene).mkdir(parents=True)
        shutil.copy(gold / scene / "buffers.npz", cand / scene / "buffers.npz")
    return cand


class Paused:
    """Pause the thread named ``name`` at a hook until ``release``; records that it got there."""

    def __init__(self, name):
        self.name, self.reached, self.release = name, threading.Event(), threading.Event()

    def __call__(self, **info):
        if threading.current_thread().name == self.name:
            self.reached.set()
            assert self.release.wait(120)


def start(name, fn, *args, **kw):
    box = {}

    def run():
        try:
            box["result"] = fn(*args, **kw)
        except BaseException as exc:  # reported by the test
            box["error"] = exc
    t = threading.Thread(target=run, name=name)
    t.start()
    return t, box


# --- 1. the final step refuses unless --out is still what the run found -------------------------

@pytest.mark.parametrize("fallback", [False, True], ids=["renameat2", "no-renameat2"])
def test_directory_created_at_out_while_generating_survives(tmp_path, hooks, capsys,
                                                            monkeypatch, fallback):
    monkeypatch.setattr(write, "FORCE_FALLBACK", fallback)
    out = tmp_path / "g"

    def plant(**info):  # someone creates --out, with their thesis in it, while we render
        out.mkdir()
        (out / "thesis.txt").write_text("four years of work")
    hooks["before_commit"] = plant
    assert cli.main(["generate", "--out", str(out), "--scene", "render_cube", "--size", "32x24",
                     "-q"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "changed while golden generate ran" in err[0], err
    assert "found nothing, now a directory holding thesis.txt" in err[0], err
    assert names(out) == ["thesis.txt"]
    assert (out / "thesis.txt").read_text() == "four years of work"
    assert names(tmp_path) == ["g"]                       # no temporary tree, no lock file


@pytest.mark.parametrize("fallback", [False, True], ids=["renameat2", "journal"])
def test_golden_changed_while_updating_is_not_replaced(g, hooks, monkeypatch, fallback):
    monkeypatch.setattr(write, "FORCE_FALLBACK", fallback)

    def edit_manifest(**info):  # another tool rewrites the golden during our run
        (g / "manifest.json").write_bytes((g / "manifest.json").read_bytes() + b" ")
    hooks["before_commit"] = edit_manifest
    with pytest.raises(write.RefusedError, match="changed while"):
        gen(g, "render_multi_draw", update=True)
    hooks.clear()
    planted = tree_digest(g)

    # the gap between the final check and the swap: the swapped-out tree is checked again and
    # swapped back when it changed
    def add_file(**info):
        (g / "notes.txt").write_text("mine")
    hooks["before_swap"] = add_file
    with pytest.raises(write.RefusedError, match="notes.txt"):
        gen(g, "render_multi_draw", update=True)
    assert tree_digest(g) == dict(planted, **{"notes.txt": tree_digest(g)["notes.txt"]})
    assert (g / "notes.txt").read_text() == "mine"
    assert names(g.parent) == ["g"]


def test_update_refuses_a_golden_holding_foreign_files(g):
    (g / "render_cube__32x24" / "my_notes.txt").write_text("mine")
    before = tree_digest(g)
    with pytest.raises(write.RefusedError, match="my_notes.txt"):
        gen(g, "render_multi_draw", update=True)
    assert tree_digest(g) == before


def test_two_new_runs_into_one_path_the_second_refuses(tmp_path, hooks, capsys):
    out = tmp_path / "g"
    pause = Paused("A")
    hooks["before_commit"] = pause
    a, box = start("A", gen, out, "render_cube")
    assert pause.reached.wait(120)
    # --no-wait: exits 2 naming the run that holds the lock; A's temporary tree is untouched
    live = [p for p in tmp_path.iterdir() if p.name.startswith(".g.tmp-")]
    assert len(live) == 1
    assert cli.main(["generate", "--out", str(out), "--scene", "render_multi_draw", "--size",
                     "32x24", "--no-wait", "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert f"being written by process {os.getpid()}" in err and "golden generate" in err
    assert live[0].is_dir() and (live[0] / "manifest.json").is_file()
    # waiting: B says whom it waits for, then finds A's golden and refuses to replace it
    # without --update
    hooks["waiting"] = lambda **info: pause.release.set()
    assert cli.main(["generate", "--out", str(out), "--scene", "render_multi_draw", "--size",
                     "32x24"]) == 2
    a.join()
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"waiting for process {os.getpid()} on ") and \
        err[0].endswith(f"to finish writing {out}"), err
    assert "exists; pass update=True (--update)" in err[-1], err
    assert "error" not in box, box
    assert sorted(load_manifest(out)["scenes"]) == [CUBE]
    assert names(tmp_path) == ["g"]


HOLD = """
import sys
from refraster import golden
from refraster.golden.io import write
def hold(**info):
    print("locked", flush=True)
    sys.stdin.readline()
write.HOOKS["locked"] = hold
golden.generate(sys.argv[1], ["render_multi_draw"], sizes=["32x24"], update=True)
"""


def test_another_process_holding_the_lock_is_named(g, capsys):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(g)], env=env, text=True,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert cli.main(["generate", "--out", str(g), "--scene", "render_torus_ortho",
                         "--size", "32x24", "--update", "--no-wait"]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and f"being written by process {holder.pid} on " in err[0], err
    finally:
        holder.communicate("\n", timeout=600)
    assert holder.returncode == 0
    assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI]
    assert names(g.parent) == ["g"]


def test_concurrent_updates_keep_both_scenes(g, hooks):
    pause = Paused("A")
    hooks["locked"] = pause
    a, box = start("A", gen, g, "render_multi_draw", update=True)
    assert pause.reached.wait(120)
    gen(g, "render_torus_ortho", update=True, wait=lambda holder: pause.release.set())
    a.join()
    assert "error" not in box, box
    assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI, TORUS]
    assert golden.compare(g, g).exit_code == 0


# --- 2. --json never writes into the golden or the candidate -------------------------------------

def test_json_inside_golden_or_candidate_is_refused(g, tmp_path, capsys):
    cand = candidate(g, tmp_path)
    link = tmp_path / "link.json"
    link.symlink_to(g / "manifest.json")
    before = {"g": tree_digest(g), "cand": tree_digest(cand)}
    for target in (g / "manifest.json", g / "render_cube__32x24" / "buffers.npz", g,
                   cand / CUBE / "buffers.npz", cand / "new.json", link):
        assert cli.main(["compare", str(g), str(cand), "--json", str(target), "-q"]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and "--json" in err, err
    rep = tmp_path / "rep"
    assert cli.main(["compare", str(g), str(cand), "--report", str(rep), "--json",
                     str(rep / "report.json"), "-q"]) == 2
    assert "inside the report directory" in capsys.readouterr().err
    assert {"g": tree_digest(g), "cand": tree_digest(cand)} == before
    assert not rep.exists()
    assert cli.main(["compare", str(g), str(cand), "--json", str(tmp_path / "m.json"),
                     "-q"]) == 0
    assert json.loads((tmp_path / "m.json").read_text())["exit_code"] == 0


# --- 3. a report directory is replaced only if refraster wrote it --------------------------------

def test_report_directory_with_foreign_files_survives(g, tmp_path, hooks):
    cand = candidate(g, tmp_path)
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "report.json").write_text("{}")                # looks like a report
    (rep / "thesis.txt").write_text("four years of work")
    before = tree_digest(rep)
    assert cli.main(["compare", str(g), str(cand), "--report", str(rep), "-q"]) == 2
    assert tree_digest(rep) == before
    # a report refraster wrote is replaced; its marker lists every file
    ours = tmp_path / "ours"
    assert cli.main(["compare", str(g), str(cand), "--report", str(ours), "-q"]) == 0
    marker = json.loads((ours / write.REPORT_MARKER).read_text())
    assert set(marker["files"]) == set(tree_digest(ours)) - {write.REPORT_MARKER}
    assert cli.main(["compare", str(g), str(cand), "--report", str(ours), "-q"]) == 0
    # ... but not once the user has edited a file of it ...
    (ours / "index.html").write_text((ours / "index.html").read_text() + "<!-- my notes -->")
    before = tree_digest(ours)
    with pytest.raises(golden.GoldenError, match="changed since \\(index.html\\)"):
        golden.compare(g, cand, report=ours)
    assert tree_digest(ours) == before
    assert cli.main(["compare", str(g), str(cand), "--report", str(tmp_path / "fresh"),
                     "-q"]) == 0
    shutil.rmtree(ours)
    (tmp_path / "fresh").rename(ours)
    # ... or put a file of their own into it
    (ours / "thesis.txt").write_text("mine")
    before = tree_digest(ours)
    with pytest.raises(golden.GoldenError, match="thesis.txt"):
        golden.compare(g, cand, report=ours)
    assert tree_digest(ours) == before

    # a file planted between the start and the commit: refused at the commit, under the lock
    (ours / "thesis.txt").unlink()
    (tmp_path / "m.json").write_text("old metrics")

    def plant(index, target):
        if index == 0:
            (ours / "late.txt").write_text("mine too")
    hooks["commit_step"] = plant
    assert cli.main(["compare", str(g), str(cand), "--report", str(ours), "--json",
                     str(tmp_path / "m.json"), "-q"]) == 2
    assert (ours / "late.txt").read_text() == "mine too"
    assert (tmp_path / "m.json").read_text() == "old metrics"
    assert sorted(p for p in names(tmp_path) if p.startswith(".")) == []


# --- 4. at every instant --out holds the old or the new golden -----------------------------------

KILL = """
import os, signal, sys
from refraster import golden
from refraster.golden.io import write
write.FORCE_FALLBACK = sys.argv[3] == "journal"
write.HOOKS[sys.argv[2]] = lambda **info: os.kill(os.getpid(), signal.SIGKILL)
golden.generate(sys.argv[1], ["render_multi_draw"], sizes=["32x24"], update=True)
"""


def _killed(out, hook, how):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-c", KILL, str(out), hook, how], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]


@pytest.mark.parametrize("next_command", ["compare", "generate"])
def test_killed_between_the_two_renames_the_journal_rolls_forward(g, next_command):
    old = tree_digest(g)
    _killed(g, "between_renames", "journal")
    assert not g.exists()                                   # between the two renames ...
    assert (g.parent / ".g.journal").is_file()              # ... the journal says what to do
    if next_command == "compare":
        # compare only reads the golden: it names the journal and acts on nothing (issue 48,
        # item 10); the next command that writes there finishes the swap
        before = sorted(names(g.parent))
        assert cli.main(["compare", str(g), str(g), "-q"]) == 2
        assert sorted(names(g.parent)) == before
        gen(g, "render_cube", update=True)
        assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI]
    else:                                                   # the next writer finishes it
        gen(g, "render_torus_ortho", update=True)
        assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI, TORUS]
    assert {k: v for k, v in tree_digest(g).items() if k.startswith(CUBE)} == \
        {k: v for k, v in old.items() if k.startswith(CUBE)}
    assert names(g.parent) == ["g"]                         # journal and old tree gone


def test_killed_after_the_exchange_the_next_run_cleans_the_debris(g):
    _killed(g, "after_swap", "renameat2")
    assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI]   # the new golden is in place
    # the old one, of a dead run (and its lock file, unlocked since the process died); a file
    # system without RENAME_EXCHANGE takes the journal's two renames: then it is .g.old-…
    debris = [n for n in names(g.parent) if n not in ("g", ".g.lock")]
    assert len(debris) == 1 and debris[0].startswith((".g.tmp-", ".g.old-")), debris
    assert golden.compare(g, g).exit_code == 0
    gen(g, "render_torus_ortho", update=True)
    assert names(g.parent) == ["g"]
    assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI, TORUS]


def test_killed_while_rendering_leaves_the_old_golden(g):
    before = tree_digest(g)
    _killed(g, "before_commit", "renameat2")
    assert tree_digest(g) == before
    debris = [n for n in names(g.parent) if n not in ("g", ".g.lock")]
    assert len(debris) == 1 and debris[0].startswith(".g.tmp-")
    assert cli.main(["compare", str(g), str(g), "-q"]) == 0      # debris does not disturb it
    gen(g, "render_multi_draw", update=True)
    assert names(g.parent) == ["g"]


def test_a_live_runs_debris_is_never_cleaned(g):
    sleeper = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"],
                               stdin=subprocess.PIPE)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    try:
        live = g.parent / f".g.tmp-{sleeper.pid}-abc"
        gone = g.parent / f".g.tmp-{int(dead.stdout)}-abc"
        for d in (live, gone):
            (d / "sub").mkdir(parents=True)
            (d / "sub" / "a.npz").write_bytes(b"x")
        gen(g, "render_multi_draw", update=True)
        assert live.is_dir() and not gone.exists()
        # the same for a report killed while it was being built
        rep = g.parent / "rep"
        live, gone = (g.parent / f".rep.tmp-{pid}-abc" for pid in (sleeper.pid, int(dead.stdout)))
        for d in (live, gone):
            (d / "img").mkdir(parents=True)
            (d / "img" / "a.png").write_bytes(b"x")
        assert cli.main(["compare", str(g), str(g), "--report", str(rep), "-q"]) == 0
        assert live.is_dir() and not gone.exists() and (rep / "index.html").is_file()
    finally:
        sleeper.communicate(b"")


SIGTERM = """
import os, signal, sys
from refraster import cli
from refraster.golden.io import write
write.HOOKS["before_commit"] = lambda **info: os.kill(os.getpid(), signal.SIGTERM)
sys.exit(cli.main(["golden", "generate", "--out", sys.argv[1], "--scene", "render_multi_draw",
                   "--size", "32x24", "--update", "-q"]))
"""


def test_sigterm_cleans_up_like_ctrl_c(g):
    before = tree_digest(g)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, "-c", SIGTERM, str(g)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 143, proc.stderr[-2000:]
    assert proc.stderr.strip() == "golden generate: interrupted"   # one line, naming the command
    assert tree_digest(g) == before
    assert names(g.parent) == ["g"]                          # no temporary tree, no lock


# --- 5. several outputs: all or nothing ----------------------------------------------------------

def _render_args(tmp_path, out, buf):
    import trimesh
    mesh = tmp_path / "box.ply"
    if not mesh.exists():
        trimesh.creation.box().export(mesh)
    return ["render", str(mesh), "--out", str(out), "--buffers", str(buf), "--width", "32",
            "--height", "24", "-q"]


def test_render_failing_png_restores_both_files(tmp_path, hooks, capsys):
    out, buf = tmp_path / "o" / "x.png", tmp_path / "o" / "x.npz"
    out.parent.mkdir()

    def fail(index, target):
        if index == 1:
            raise OSError(28, "No space left on device", str(target))
    hooks["commit_step"] = fail
    assert rcli.main(_render_args(tmp_path, out, buf)) == 2      # nothing there before
    assert "No space left" in capsys.readouterr().err
    assert names(out.parent) == []
    out.write_bytes(b"old png")
    buf.write_bytes(b"old npz")
    assert rcli.main(_render_args(tmp_path, out, buf)) == 2      # earlier files restored
    assert out.read_bytes() == b"old png" and buf.read_bytes() == b"old npz"
    assert names(out.parent) == ["x.npz", "x.png"]
    hooks.clear()
    assert rcli.main(_render_args(tmp_path, out, buf)) == 0
    with np.load(buf, allow_pickle=False) as z:
        assert (z["prim_id"] >= 0).any()
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert names(out.parent) == ["x.npz", "x.png"]


def test_staged_files_of_dead_runs_are_removed_of_live_ones_kept(tmp_path):
    sleeper = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"],
                               stdin=subprocess.PIPE)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    try:
        out, buf = tmp_path / "o" / "x.png", tmp_path / "o" / "x.npz"
        out.parent.mkdir()
        live = out.parent / f".x.png.tmp-{sleeper.pid}-abc"
        gone = out.parent / f".x.png.tmp-{int(dead.stdout)}-abc"
        other = out.parent / f".x.png.bak-{int(dead.stdout)}-abc"   # replaced data: kept
        for f in (live, gone, other):
            f.write_bytes(b"staged")
        assert rcli.main(_render_args(tmp_path, out, buf)) == 0
        assert live.exists() and other.exists() and not gone.exists()
    finally:
        sleeper.communicate(b"")


def test_compare_json_failure_restores_the_previous_report(g, tmp_path, hooks):
    cand = candidate(g, tmp_path)
    rep, js = tmp_path / "rep", tmp_path / "m.json"
    assert cli.main(["compare", str(g), str(cand), "--report", str(rep), "--json", str(js),
                     "-q"]) == 0
    before, before_json = tree_digest(rep), js.read_bytes()

    def fail(index, target):
        if index == 1:
            raise OSError(28, "No space left on device", str(target))
    hooks["commit_step"] = fail
    assert cli.main(["compare", str(g), str(cand), "--report", str(rep), "--json", str(js),
                     "--mode", "exact", "-q"]) == 2
    assert tree_digest(rep) == before and js.read_bytes() == before_json
    assert names(tmp_path) == ["cand", "g", "m.json", "rep"]


# --- 6. --update through a symlink updates the golden it points to -------------------------------

def test_update_through_a_symlink_updates_the_target(g, tmp_path):
    link = tmp_path / "link"
    link.symlink_to(g)
    gen(link, "render_multi_draw", update=True)
    assert link.is_symlink() and os.readlink(link) == str(g)
    assert sorted(load_manifest(g)["scenes"]) == [CUBE, MULTI]
    with pytest.raises(FileExistsError, match="update"):
        gen(link, "render_multi_draw")
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    with pytest.raises(write.RefusedError, match="does not exist"):
        gen(dangling, "render_cube")
    assert not (tmp_path / "nowhere").exists()


# --- 7. flags and modes --------------------------------------------------------------------------

def test_quiet_and_debug_after_the_subcommand(g, tmp_path, capsys):
    out = tmp_path / "new"
    assert cli.main(["generate", "--out", str(out), "--scene", "render_cube", "--size", "32x24",
                     "-q", "--debug"]) == 0
    assert capsys.readouterr().err == ""
    assert cli.main(["compare", str(g), str(g), "--debug", "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert rcli.main(["golden", "compare", str(g), str(g), "-q"]) == 0
    assert rcli.main(["golden", "-q", "compare", str(g), str(g)]) == 0
    assert capsys.readouterr().out == ""
    assert rcli.main(["golden", "compare", str(g), str(g)]) == 0   # not quiet: a summary
    assert "result: PASS" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [
    ["golden", "generate", "--out", "X", "--bogus", "--debug"],
    ["--debug", "golden", "generate", "--out", "X", "--workers", "0"],
    ["golden", "generate", "--out", "X", "--workers", "-3", "--debug"],
    ["golden", "generate", "--out", "X", "--workers", "two"],
    ["golden", "generate", "--debug"],
    ["golden", "--debug"],
    ["--debug", "render"],
    ["golden", "compare", "--debug"],
])
def test_usage_errors_stay_one_line_with_debug(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert rcli.main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    if "--workers" in argv:
        assert "--workers" in err and ">= 1" in err
    if argv[0] == "golden":  # the same through python -m refraster.golden.cli
        assert cli.main(argv[1:]) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert names(tmp_path) == []


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_directories_follow_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        out = tmp_path / "g"
        gen(out, "render_cube")
        rep = tmp_path / "rep"
        golden.compare(out, out, report=rep)
    finally:
        os.umask(old)
    for d in (out, out / CUBE, rep, rep / "img"):
        assert d.stat().st_mode & 0o777 == 0o777 & ~umask, d
    for f in (out / "manifest.json", out / CUBE / "buffers.npz", rep / "index.html"):
        assert f.stat().st_mode & 0o777 == 0o666 & ~umask, f


def test_discarding_a_tree_deletes_only_what_its_listing_names(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "a.npz").write_text("not refraster's")
    tree = tmp_path / ".g.tmp-1-x"
    (tree / "scene").mkdir(parents=True)
    (tree / "scene" / "b.npz").write_text("b")
    (tree / "linked").symlink_to(outside)                 # a planted link to another directory
    (tree / "notes.txt").write_text("mine")
    (tree / "manifest.json").write_text(json.dumps(
        {"files": {"scene/b.npz": "0" * 64, "linked/a.npz": "0" * 64}}))
    kept = write.discard_tree(tree, "g")
    assert (outside / "a.npz").read_text() == "not refraster's"
    assert kept is not None and kept.name.startswith("g.kept-") and not tree.exists()
    assert sorted(p.relative_to(kept).as_posix() for p in kept.rglob("*")) == \
        ["linked", "notes.txt"]
    assert (kept / "notes.txt").read_text() == "mine"
