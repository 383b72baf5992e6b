"""Distributed golden generation on Dask (issue 11): byte-identical to serial, a dying worker is
retried once and reported, a scene failing twice leaves no partial golden."""

import logging
import os
import signal
import sys
from pathlib import Path

import pytest

from refraster import golden
from refraster.golden import cli
from refraster.golden.compare.run import load_manifest
from refraster.golden.generate import GenerationError

KILL_MARKER = "REFRASTER_TEST_KILL_MARKER"
SUITE = dict(sweeps=["cull=none,back"], sizes=["48x36"])


def _killer_scene(**params):
    """Kills its own worker process the first time it runs (a marker file remembers)."""
    marker = Path(os.environ[KILL_MARKER])
    if not marker.exists():
        marker.write_text("killed once")
        os.kill(os.getpid(), signal.SIGKILL)
    return golden.scenes._solid_scene("cube", width=48, height=36)


def _always_fails(**params):
    raise RuntimeError("scene exploded on purpose")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    from conftest import require
    require("distributed")
    import cloudpickle
    import dask
    from dask.distributed import LocalCluster
    marker = tmp_path_factory.mktemp("kill") / "marker"
    old = os.environ.get(KILL_MARKER)
    os.environ[KILL_MARKER] = str(marker)          # inherited by the worker processes
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    golden.register_scene("test_dask_killer", technique="render")(_killer_scene)
    golden.register_scene("test_dask_fails", technique="render")(_always_fails)
    # as generate(workers=N) does: a dead worker fails its task, and generate retries it
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        lc = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=":0", silence_logs=logging.ERROR)
    try:
        yield lc, marker
    finally:
        lc.close()
        golden.SCENES.pop("test_dask_killer")
        golden.SCENES.pop("test_dask_fails")
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
        if old is None:
            os.environ.pop(KILL_MARKER)
        else:
            os.environ[KILL_MARKER] = old


def test_suite_names_and_bad_sweeps():
    tasks = golden.generate.__globals__["suite"](
        {"render_cube": golden.SCENES["render_cube"]}, sweeps=[("cull", ["none", "back"])],
        sizes=[(48, 36), (32, 24)])
    assert [t[0] for t in tasks] == ["render_cube__cull_none__48x36",
                                     "render_cube__cull_none__32x24",
                                     "render_cube__cull_back__48x36",
                                     "render_cube__cull_back__32x24"]
    assert tasks[0][2] == {"cull": "none", "width": 48, "height": 36}
    with pytest.raises(ValueError, match="does not take parameter 'width'"):
        golden.generate("/nonexistent/x", ["edges_building"], sizes=["48x36"])
    with pytest.raises(ValueError, match="WIDTHxHEIGHT"):
        golden.generate("/nonexistent/x", ["render_cube"], sizes=["48*36"])
    with pytest.raises(ValueError, match="KEY=V1,V2"):
        golden.generate("/nonexistent/x", ["render_cube"], sweeps=["cull"])
    with pytest.raises(ValueError, match="workers"):
        golden.generate("/nonexistent/x", ["render_cube"], workers=0)


def test_two_workers_give_the_serial_bytes(cluster, tmp_path):
    lc, _ = cluster
    scenes = ["render_cube", "render_multi_draw"]
    serial = golden.generate(tmp_path / "serial", scenes, **SUITE)
    dist = golden.generate(tmp_path / "dask", scenes, scheduler=lc.scheduler_address, **SUITE)
    assert len(serial["scenes"]) == 4
    assert dist["files"] == serial["files"]
    assert load_manifest(tmp_path / "dask")["files"] == serial["files"]
    compare = golden.compare(tmp_path / "serial", tmp_path / "dask", mode="exact")
    assert compare.exit_code == 0


def test_killed_worker_is_retried_and_reported(cluster, tmp_path):
    lc, marker = cluster
    retried = []
    manifest = golden.generate(tmp_path / "g", ["test_dask_killer", "render_cube"],
                               scheduler=lc.scheduler_address, sizes=["48x36"],
                               on_retry=lambda name, why: retried.append((name, why)))
    assert marker.exists()
    assert [name for name, _ in retried] == ["test_dask_killer__48x36"]
    assert "KilledWorker" in retried[0][1]
    assert sorted(manifest["scenes"]) == ["render_cube__48x36", "test_dask_killer__48x36"]
    # complete and correct: the killer scene renders the cube, byte for byte
    serial = golden.generate(tmp_path / "serial", ["render_cube"], sizes=["48x36"])
    cube = {k.split("/", 1)[1]: v for k, v in serial["files"].items()}
    killer = {k.split("/", 1)[1]: v for k, v in manifest["files"].items()
              if k.startswith("test_dask_killer__48x36/")}
    different = {k for k in cube if cube[k] != killer.get(k)}
    assert different <= {"package/scene.json"}        # it names itself
    assert load_manifest(tmp_path / "g")               # every sha256 verified


def test_failing_twice_is_a_clear_error_and_no_partial_golden(cluster, tmp_path):
    lc, _ = cluster
    retried = []
    with pytest.raises(GenerationError, match="test_dask_fails: RuntimeError: scene exploded"):
        golden.generate(tmp_path / "g", ["render_cube", "test_dask_fails"],
                        scheduler=lc.scheduler_address, on_retry=lambda *a: retried.append(a))
    assert [a[0] for a in retried] == ["test_dask_fails"]
    assert list(tmp_path.iterdir()) == []              # no golden, no temporary left


def test_cli_workers(cluster, tmp_path, capsys):
    # its own LocalCluster of 2 processes, with a progress bar
    out = tmp_path / "g"
    assert cli.main(["generate", "--out", str(out), "--scene", "render_cube", "--size", "32x24",
                     "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "golden: 100%" in err and "wrote 1 scene(s)" in err
    assert sorted(load_manifest(out)["scenes"]) == ["render_cube__32x24"]
    assert cli.main(["generate", "--out", str(tmp_path / "x"), "--workers", "2",
                     "--scheduler", "tcp://127.0.0.1:1"]) == 2
