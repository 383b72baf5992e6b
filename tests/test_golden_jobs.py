"""``golden generate --jobs N`` (issue 27): scenes rendered in worker processes of one thread
each give the bytes of the in-process run, whatever order the workers answer in; a worker
that fails (a scene raising, a process dying, an answer naming a file outside its scene) is
one error line and exit status 2, with no golden and no temporary left behind."""

import importlib
import json
import os
from io import StringIO
from pathlib import Path

import numpy as np
import pytest

from refraster import golden
from refraster.golden import cli
from refraster.golden.compare.run import load_manifest

gen = importlib.import_module("refraster.golden.generate")   # the module, not the function

#: One scene of each worker group, the cheapest of each (warm: ~1 s each).
SCENES = ["render_cube", "edges_c1_paper", "clipsurface_relief_plane", "halos4d_perspective"]
FAULT = "REFRASTER_TEST_WORKER_FAULT"
LOG = "REFRASTER_TEST_WORKER_LOG"


def _files(root):
    root = Path(root)
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _same_golden(a, b):
    fa, fb = _files(a), _files(b)
    assert sorted(fa) == sorted(fb)
    assert fa["manifest.json"] == fb["manifest.json"]
    different = [rel for rel in fa if fa[rel] != fb[rel]]
    assert different == []
    for rel in (r for r in fa if r.endswith(".npz")):     # every array, by value and dtype too
        with np.load(Path(a) / rel) as za, np.load(Path(b) / rel) as zb:
            assert sorted(za.files) == sorted(zb.files)
            for key in za.files:
                assert za[key].dtype == zb[key].dtype and za[key].tobytes() == zb[key].tobytes()


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "g"
    golden.generate(out, SCENES, jobs=1)
    return out


@pytest.fixture
def fault_worker(monkeypatch):
    """Run the workers of this test through tests/golden_worker_fault.py."""
    here = str(Path(__file__).parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [here] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    monkeypatch.setattr(gen, "WORKER_MODULE", "golden_worker_fault")
    return monkeypatch


def test_worker_groups_longest_first_and_serial_when_a_worker_cannot_build_a_scene():
    reg = golden.available_scenes()
    tasks = gen.suite({n: reg[n] for n in SCENES + ["ldi_nested_shells", "clipsurface_building"]})
    groups = gen.worker_groups(tasks, 2)
    assert groups == [["clipsurface_relief_plane", "clipsurface_building"],
                      ["render_cube", "edges_c1_paper", "ldi_nested_shells"],
                      ["halos4d_perspective"]]
    assert gen.worker_groups(tasks, 1) is None
    assert gen.worker_groups(tasks[:1], 2) is None
    own = golden.scenes.SceneEntry("mine", "render", "", lambda: None)   # not a worker's
    assert gen.worker_groups(tasks + [("mine", own, {})], 2) is None


def test_jobs_2_gives_the_bytes_of_jobs_1(serial, tmp_path):
    manifest = golden.generate(tmp_path / "g", SCENES, jobs=2)
    _same_golden(serial, tmp_path / "g")
    assert sorted(manifest["scenes"]) == sorted(SCENES)
    assert load_manifest(tmp_path / "g")                  # every sha256 verified


def test_the_bytes_do_not_depend_on_which_worker_answers_first(serial, tmp_path, monkeypatch):
    from refraster import _workers
    real = _workers.run_groups
    seen = []

    def reversed_answers(*args, **kwargs):
        answers = list(real(*args, **kwargs))
        seen.extend(a[0] for a in answers[::-1])
        yield from answers[::-1]
    monkeypatch.setattr(_workers, "run_groups", reversed_answers)
    golden.generate(tmp_path / "g", SCENES, jobs=2)
    assert len(seen) == len(SCENES)
    _same_golden(serial, tmp_path / "g")


def test_cli_jobs_1_and_2_write_the_same_golden(serial, tmp_path, capsys):
    scenes = [a for n in SCENES for a in ("--scene", n)]
    assert cli.main(["generate", "--out", str(tmp_path / "j2"), "--jobs", "2", *scenes]) == 0
    assert cli.main(["-q", "generate", "--out", str(tmp_path / "j1"), "--jobs", "1", *scenes]) == 0
    err = capsys.readouterr().err
    assert "wrote 4 scene(s)" in err and "golden: 100%" in err
    _same_golden(serial, tmp_path / "j2")
    _same_golden(serial, tmp_path / "j1")
    assert cli.main(["generate", "--out", str(tmp_path / "x"), "--jobs", "2",
                     "--workers", "2"]) == 2
    assert "--jobs excludes --workers" in capsys.readouterr().err
    assert cli.main(["generate", "--out", str(tmp_path / "x"), "--jobs", "0"]) == 2
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("kind, says", [
    ("raise", "RuntimeError: planted fault in edges_c1_paper"),
    ("die", "worker process failed (exit status 7): dying on purpose"),
    ("escape", "unreadable answer (ValueError: file "
               "'edges_c1_paper/../escaped.txt' is not under edges_c1_paper/)"),
])
def test_a_failing_worker_is_one_error_line_and_leaves_nothing(fault_worker, tmp_path, capsys,
                                                                kind, says):
    fault_worker.setenv(FAULT, f"{kind}:edges_c1_paper")
    out = tmp_path / "golden" / "g"
    out.parent.mkdir()
    status = cli.main(["generate", "--out", str(out), "--jobs", "2",
                       *[a for n in SCENES for a in ("--scene", n)]])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert status == 2
    assert lines == [f"golden generate: error: GenerationError: scene edges_c1_paper failed in "
                     f"a worker process: {says}"]
    assert "Traceback" not in err
    assert list(out.parent.iterdir()) == []            # no golden, no temporary tree
    assert not (tmp_path / "golden" / "escaped.txt").exists()
    assert not (tmp_path / "escaped.txt").exists()


def test_a_failing_worker_fails_the_api_call_and_the_other_workers_stop(fault_worker, tmp_path):
    fault_worker.setenv(FAULT, "die:clipsurface_relief_plane")
    with pytest.raises(gen.GenerationError, match="clipsurface_relief_plane failed in a worker"):
        golden.generate(tmp_path / "g", SCENES, jobs=2)
    assert list(tmp_path.iterdir()) == []


def test_worker_compiles_reach_the_progress_line(fault_worker, tmp_path):
    from refraster.warmup import COMPILING, CompileProgress
    fault_worker.setenv(FAULT, "compiled:refraster.edges.operators._edge_map_kernel")
    stream = StringIO()
    with CompileProgress(stream=stream) as progress:
        golden.generate(tmp_path / "g", SCENES[:2], jobs=2, compile_progress=progress)
    assert "refraster.edges.operators._edge_map_kernel" in progress.done
    assert f"{COMPILING}:" in stream.getvalue()


def test_a_worker_s_warning_is_the_command_s_one_line_warning(fault_worker, tmp_path, capsys):
    fault_worker.setenv(FAULT, "warn:edges_c1_paper")
    scenes = [a for n in SCENES[:2] for a in ("--scene", n)]
    assert cli.main(["generate", "--out", str(tmp_path / "g"), "--jobs", "2", *scenes]) == 0
    err = capsys.readouterr().err
    assert "refraster: warning: trimesh: planted warning in edges_c1_paper\n" in err
    assert cli.main(["-q", "generate", "--out", str(tmp_path / "q"), "--jobs", "2", *scenes]) == 0
    assert "planted warning" not in capsys.readouterr().err


def test_first_run_compiles_the_pipeline_here_and_clip_surface_kernels_beside_it(
        fault_worker, serial, tmp_path):
    """On a cold cache (told so here) this process compiles the pipeline's kernels while one
    worker compiles the clip surfaces' side kernels ("warm-clipsurface") and their fused pass
    ("warm-fused-clip"); then the groups run, the clip surfaces' once that worker has ended.
    The bytes are the same."""
    from refraster import warmup
    log = tmp_path / "groups.jsonl"
    fault_worker.setenv(LOG, str(log))
    calls = []
    real_warm = warmup.warm_core
    fault_worker.setattr(warmup, "cache_state", lambda modules=None, only=None: (0, 1))
    fault_worker.setattr(warmup, "warm_core",
                         lambda *a, **k: (calls.append(k), real_warm(*a, **k))[1])
    golden.generate(tmp_path / "g", SCENES, jobs=2)
    groups = [json.loads(ln) for ln in log.read_text().splitlines()]   # as the workers start
    assert sorted(groups) == sorted([["warm-clipsurface", "warm-fused-clip"],
                                     ["clipsurface_relief_plane"],
                                     ["render_cube", "edges_c1_paper"], ["halos4d_perspective"]])
    assert calls == [dict(clip=True, stream=True, multisample=True)]   # the 4x scenes: int32 twins
    _same_golden(serial, tmp_path / "g")


def test_a_group_waits_for_the_worker_compiling_its_kernel_ahead(monkeypatch, tmp_path):
    """On a first run the clip surfaces' group does not start while the worker given
    ``warm-fused-clip`` runs (it would compile the fused pass a second time beside it); the
    next group that may start does (``run_groups(after_warm=…)``, issue 27)."""
    from refraster import _workers, warmup
    log = tmp_path / "events.jsonl"
    here = str(Path(__file__).parent)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [here] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    monkeypatch.setenv(LOG, str(log))
    monkeypatch.setenv("REFRASTER_TEST_WARM_SECONDS", "3")
    monkeypatch.setattr(warmup, "cache_state", lambda modules=None, only=None: (0, 1))
    monkeypatch.setattr(warmup, "warm_core", lambda *a, **k: None)

    def run(after_warm):
        log.write_text("")
        answers = list(_workers.run_groups(
            "warm_wait_worker", [["clip"], ["other"], ["last"]], 2, key="task",
            cold_start=lambda queue, cold: _workers.cold_start_groups(
                queue, 2, lambda n: False, True, clip_group=lambda g: "clip" in g,
                fused_clip=True),
            after_warm=after_warm))
        assert sorted(n for n, _, _ in answers) == ["clip", "last", "other"]
        assert all(e is None for _, _, e in answers)
        events = [json.loads(ln) for ln in log.read_text().splitlines()]
        at = {(ev, tuple(g)): t for ev, g, t in events}
        warm = ("warm-clipsurface", "warm-fused-clip")
        assert ("start", warm) in at, events
        return at, warm

    at, warm = run(lambda g: "clip" in g)
    assert at[("start", ("clip",))] >= at[("end", warm)]
    assert at[("start", ("other",))] < at[("end", warm)]
    # the fault: without the wait the clip group starts beside the warm worker
    at, warm = run(None)
    assert at[("start", ("clip",))] < at[("end", warm)]
