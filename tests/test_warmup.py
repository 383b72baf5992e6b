"""The first run says that it compiles: the progress line, the cache state, ``refraster warmup``.

The command tests run ``refraster render`` in a fresh ``NUMBA_CACHE_DIR`` filled with this
checkout's compiled kernels except one (``gbuffer.shade``): the first run compiles that one and
says so, the second run loads it and says nothing. (A cache with nothing in it takes the whole
pipeline's compile, 15 s to minutes: ``benchmarks/cold_start.py`` measures that.)
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refraster import warmup
from refraster.warmup import COMPILING, CompileProgress

REPO = Path(__file__).resolve().parents[1]
LEFT_OUT = "refraster.raster.gbuffer.shade"


def test_render_kernels_exist_and_are_the_core_s():
    names = {warmup._name(d) for d in warmup.kernels(warmup.CORE_MODULES)}
    assert set(warmup.STREAM_KERNELS) <= {warmup._name(d) for d in warmup.kernels()}
    assert set(warmup.RENDER_KERNELS) <= names
    assert set(warmup.GALLERY_SKIPS) <= {warmup._name(d) for d in warmup.kernels()}
    # the inlined helpers have no cache entry of their own, so they are not counted
    assert all(d.targetoptions.get("inline") != "always" for d in warmup.kernels())


def test_progress_line_only_when_something_compiles():
    quiet = io.StringIO()
    with CompileProgress(warmup.CORE_MODULES, stream=quiet) as p:
        pass
    assert quiet.getvalue() == "" and p.k == 0

    out = io.StringIO()
    with CompileProgress(warmup.CORE_MODULES, only=(), stream=out) as p:
        p.add("refraster.x.kernel_a")
        p.add("refraster.x.kernel_a")      # the same kernel twice counts once
        p.add("refraster.x.kernel_b")
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and lines[0].startswith(COMPILING)
    assert re.fullmatch(rf"{COMPILING}: 2 of 2, \d+\.\d s \(later runs load them from the "
                        r"cache\)", lines[1])

    silenced = io.StringIO()
    with CompileProgress(warmup.CORE_MODULES, only=(), stream=silenced, quiet=True) as p:
        p.add("refraster.x.kernel_a")
    assert silenced.getvalue() == ""


def test_progress_counts_a_real_compile():
    from numba import njit

    @njit(cache=False)
    def refraster_probe(x):     # defined here: compiled on its first call, never cached
        return x + 1

    refraster_probe.py_func.__module__ = "refraster.probe"
    out = io.StringIO()
    with CompileProgress(warmup.CORE_MODULES, only=(), stream=out) as p:
        refraster_probe(1)
    assert p.done == {"refraster.probe.test_progress_counts_a_real_compile.<locals>."
                      "refraster_probe"}
    assert "1 of 1" in out.getvalue()


def _cache_paths(env):
    """``{module.qualname: (cache directory, index file name)}`` of the core kernels, as a
    process with ``env`` sees them."""
    code = ("import json\nfrom refraster import warmup\n"
            "print(json.dumps({warmup._name(d): [d._cache._cache_path, "
            "d._cache._cache_file._index_name] for d in warmup.kernels(warmup.CORE_MODULES)}))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, stdin=subprocess.DEVNULL).stdout
    return json.loads(out)


@pytest.fixture
def nearly_warm_cache(tmp_path):
    """A fresh ``NUMBA_CACHE_DIR`` holding this checkout's core kernels but ``LEFT_OUT``."""
    return _cache_without(tmp_path, (LEFT_OUT,))


def _cache_without(tmp_path, left_out):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    here = _cache_paths(env)
    cache = tmp_path / "numba-cache"
    env["NUMBA_CACHE_DIR"] = str(cache)
    there = _cache_paths(env)
    for name, (src, index) in here.items():
        if name in left_out:
            continue
        stem = index[:-len(".nbi")]
        dst = Path(there[name][0])
        dst.mkdir(parents=True, exist_ok=True)
        for f in Path(src).glob(f"{stem}.*"):
            if f.suffix in (".nbi", ".nbc"):
                shutil.copy2(f, dst / f.name)
    return env


def _render(env, tmp_path, name):
    import trimesh
    mesh = tmp_path / "cube.ply"
    if not mesh.exists():
        trimesh.creation.box((1.0, 1.0, 1.0)).export(mesh)
    return subprocess.run([sys.executable, "-m", "refraster.cli", "render", str(mesh), "--out",
                           str(tmp_path / f"{name}.png"), "--width", "64", "--height", "48"],
                          env=env, capture_output=True, text=True, timeout=600,
                          stdin=subprocess.DEVNULL)


def test_first_render_in_a_fresh_cache_says_it_compiles(nearly_warm_cache, tmp_path):
    env = dict(nearly_warm_cache, REFRASTER_TIER="auto")   # as a user runs it
    first = _render(env, tmp_path, "first")
    assert first.returncode == 0, first.stderr
    lines = [ln for ln in first.stderr.splitlines() if ln.startswith(COMPILING)]
    assert lines, first.stderr
    m = re.search(rf"{COMPILING}: (\d+) of (\d+), (\d+\.\d) s", first.stderr)
    assert m and int(m.group(1)) == int(m.group(2)) >= 1, first.stderr
    info = subprocess.run([sys.executable, "-m", "refraster.cli", "info"], env=env,
                          capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL).stdout
    assert re.search(r"kernels: +(cold|partly warm|warm): \d+ of \d+ kernels", info), info

    second = _render(env, tmp_path, "second")
    assert second.returncode == 0, second.stderr
    assert COMPILING not in second.stderr and "compil" not in second.stderr.lower()
    # the bytes do not depend on whether the kernels were compiled or loaded
    assert (tmp_path / "first.png").read_bytes() == (tmp_path / "second.png").read_bytes()


def test_info_tells_a_cold_cache_from_a_warm_one(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_CACHE_DIR=str(tmp_path / "empty"))
    out = subprocess.run([sys.executable, "-m", "refraster.cli", "info"], env=env,
                         capture_output=True, text=True, timeout=300,
                         stdin=subprocess.DEVNULL).stdout
    m = re.search(r"kernels: +cold: 0 of (\d+) kernels compiled and cached; the first run "
                  r"compiles the rest \(minutes\), 'refraster warmup' does it ahead", out)
    assert m and int(m.group(1)) == len(warmup.kernels()), out
    assert np.isfinite(float(m.group(1)))


def test_kernel_modules_cover_every_kernel():
    """A module with kernels missing from ``KERNEL_MODULES`` would compile without being
    counted in ``n`` (and ``info`` would call a cold cache warm)."""
    import importlib
    import pkgutil

    import refraster
    from numba.core.registry import CPUDispatcher
    found = set()
    for m in pkgutil.walk_packages(refraster.__path__, "refraster."):
        if m.name in ("refraster.cli", "refraster.warmup") or m.name.startswith(
                ("refraster.gallery", "refraster.gl")):
            continue
        mod = importlib.import_module(m.name)
        found |= {v.py_func.__module__ for v in vars(mod).values()
                  if isinstance(v, CPUDispatcher) and v.targetoptions.get("inline") != "always"}
    assert found and found <= set(warmup.KERNEL_MODULES), found - set(warmup.KERNEL_MODULES)


def _specialisations(disp):
    return [str(s) for s in disp.signatures]


def test_pipeline_and_cap_helpers_compile_one_specialisation():
    """``raster.primitive._clip_polygon``/``_clipped_face`` (a literal and a variable count or
    outcode), ``capping._face_box`` (the parallel loop body's uint64 face index and read-only
    or writable cap vertices) and ``mesh._bounds`` (read-only or writable vertices) compile
    once each (issue 27, docs/performance.md "The first run")."""
    import numba
    from numba.core.caching import NullCache
    from numba.core.registry import CPUDispatcher

    import refraster
    from refraster.clipsurface import offsetmaps as om
    from refraster._config import PJIT
    from refraster.camera import look_at, perspective
    from refraster.clipsurface import ClipSurface, capping
    from refraster.ldi import VolumetricDepthSprite
    from refraster.mesh import Mesh, bounds
    from refraster.raster import primitive

    v, f = warmup._box()
    ro = v.copy()
    ro.setflags(write=False)
    assert np.array_equal(bounds(v), bounds(ro))
    # record the arguments the wrappers pass, then compile fresh, uncached copies of the
    # parallel kernels so that the helpers they call are typed here (a kernel loaded from the
    # cache types nothing)
    calls = {}
    real = {name: getattr(mod, name) for mod, name in (
        (primitive, "_clip_pass"), (capping, "_footprint_kernel"), (capping, "_sure_kernel"))}

    def spy(name):
        def run(*args):
            calls.setdefault(name, []).append(args)
            return real[name](*args)
        return run

    for mod, name in ((primitive, "_clip_pass"), (capping, "_footprint_kernel"),
                      (capping, "_sure_kernel")):
        setattr(mod, name, spy(name))
    try:
        mesh = refraster.as_mesh((v, f))
        refraster.render(mesh, view=look_at((0.3, 0.4, 2.0), (0.0, 0.0, 0.0)),
                         proj=perspective(40.0, 4 / 3, 1.9, 10.0), width=16, height=12)
        sprite = VolumetricDepthSprite.from_mesh(Mesh(v, f), resolution=16)
        cs = ClipSurface([0.05, 0, 0], [0, 2.0, 0.4], [0, -0.4, 2.0], (1, 1, 0.4),
                         om.perlin_noise(8, seed=5))
        cap = capping.cap_mesh(cs, bounds(v))
        writable = Mesh(np.array(cap.vertices), np.array(cap.faces))
        for m in (cap, writable):
            capping.surely_inside(capping.cull_cap(m, sprite), sprite)
    finally:
        for mod, name in ((primitive, "_clip_pass"), (capping, "_footprint_kernel"),
                          (capping, "_sure_kernel")):
            setattr(mod, name, real[name])
    assert set(calls) == set(real)
    helpers = [primitive._clip_polygon, primitive._clipped_face, capping._face_box,
               refraster.mesh._bounds]
    assert all(isinstance(h, CPUDispatcher) for h in helpers)
    fresh = dict(PJIT, cache=False)
    saved = [h._cache for h in helpers]
    try:
        for h in helpers[:3]:   # a helper loaded from the cache would not type its callees
            h._cache = NullCache()
        for name, arglists in calls.items():
            k = numba.njit(**fresh)(real[name].py_func)
            for args in arglists:
                k(*args)
    finally:
        for h, c in zip(helpers, saved):
            h._cache = c
    twins = {h.py_func.__qualname__: _specialisations(h) for h in helpers}
    bad = {name: sigs for name, sigs in twins.items()
           if len(sigs) != 1 or "uint64" in sigs[0] or "Literal" in sigs[0]}
    assert bad == {}


def test_clipsurface_side_warmup_compiles_what_the_section_uses(tmp_path):
    """``warm_clipsurface_side`` types each of its kernels exactly as the gallery's
    clip-surface section calls them: after it, the section (quick) adds no specialisation to
    any of them, and uses every one (so that a worker compiling them ahead saves the section
    that compile; issue 27)."""
    from refraster.gallery import clipsurface

    ks = {warmup._name(k): k for k in warmup.kernels()}
    side = [ks[n] for n in warmup.CLIPSURFACE_SIDE_KERNELS]
    warmup.warm_clipsurface_side()
    warmed = {warmup._name(k): list(k.signatures) for k in side}
    assert all(len(s) == 1 for s in warmed.values()), warmed
    calls, real = [], {}

    def spy(name, fn):
        def run(*args):
            calls.append(name)
            return fn(*args)
        return run

    import importlib
    for name in warmup.CLIPSURFACE_SIDE_KERNELS:
        mod, attr = name.rsplit(".", 1)
        m = importlib.import_module(mod)
        real[name] = (m, attr, getattr(m, attr))
        setattr(m, attr, spy(name, getattr(m, attr)))
    try:
        clipsurface.render(tmp_path, quick=True)
    finally:
        for m, attr, fn in real.values():
            setattr(m, attr, fn)
    assert {warmup._name(k): list(k.signatures) for k in side} == warmed
    assert set(calls) == set(warmup.CLIPSURFACE_SIDE_KERNELS)


def test_first_gallery_run_compiles_clip_surface_kernels_beside_the_pipeline():
    """On a first run the worker that needs no pipeline kernels (the halos) also compiles the
    clip surfaces' side kernels ("warm-clipsurface"), only while they are cold, only with the
    clip-surface section queued and two or more jobs."""
    from refraster.cli import _while_the_pipeline_compiles as first
    groups = [["ldi", "clipsurface"], ["edges", "cutaway", "basic"], ["halos4d"]]
    q = [list(g) for g in groups]
    assert first(q, 2, True) == [["halos4d", "warm-clipsurface"]]
    assert q == groups[:2]
    assert first([list(g) for g in groups], 2, False) == [["halos4d"]]
    assert first([list(g) for g in groups], 1, True) == [["halos4d"]]
    assert first([["ldi", "clipsurface"], ["edges"]], 2, True) == [["warm-clipsurface"]]
    assert first([["edges"], ["halos4d"]], 2, True) == [["halos4d"]]


def test_worker_warm_task_compiles_ahead_and_answers_without_pictures(tmp_path, capsys):
    from refraster.gallery import worker
    assert worker.main([str(tmp_path), "warm-clipsurface"]) == 0
    out = [json.loads(ln) for ln in capsys.readouterr().out.splitlines()]
    assert out == [{"section": "warm-clipsurface", "items": [], "error": None}]
    assert list(tmp_path.iterdir()) == []


_TWIN_KERNEL = '''
import sys
import numpy as np
from numba import njit, prange

@njit(cache=True, parallel=True)
def k(a, out):
    for i in prange(a.shape[0]):
        s = 0.0
        for j in range(a.shape[1]):
            s += np.sin(a[i, j]) * np.cos(a[i, j] * 0.5)
        out[i] = s

if __name__ == "__main__":
    a = np.arange(12.0).reshape(3, 4)
    out = np.zeros(3)
    k(a, out)
    print(repr(out.tolist()), k.stats.cache_hits.get(k.signatures[0], 0) if k.signatures else -1)
'''


def test_two_processes_compiling_the_same_kernel_at_once_share_one_cache(tmp_path):
    """Two processes compiling the same kernel (same signature) into one cache at the same
    time — as a gallery worker warming kernels ahead and the section that needs them may —
    both succeed, and a third process loads the entry and computes the same numbers (Numba
    writes the index and the data atomically, under the same names for the same key)."""
    (tmp_path / "twin.py").write_text(_TWIN_KERNEL)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_NUM_THREADS="1")
    cmd = [sys.executable, str(tmp_path / "twin.py")]
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True, stdin=subprocess.DEVNULL) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    third = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300,
                           stdin=subprocess.DEVNULL)
    assert third.returncode == 0, third.stderr
    values = {o.rsplit(" ", 1)[0] for o, _ in outs} | {third.stdout.strip().rsplit(" ", 1)[0]}
    assert len(values) == 1
    assert third.stdout.strip().rsplit(" ", 1)[1] == "1"   # loaded from the cache
    assert len(list((tmp_path / "cache").rglob("*.nbi"))) == 1


# ---------------------------------------------------------------- the first render on two cores

_SIGNATURES = """
import json, sys
from refraster import warmup
ks = {warmup._name(d): d for d in warmup.kernels(warmup.CORE_MODULES)}
def sigs():
    return {n: [str(s) for s in ks[n].signatures] for n in warmup.RENDER_KERNELS}
out = []
warmup.warm_only([warmup.SPLIT_KERNEL])            # what the second process does
out.append(sigs())
warmup.warm_only([k for k in warmup.RENDER_KERNELS if k != warmup.SPLIT_KERNEL])
out.append(sigs())
import trimesh, refraster as rf
from refraster.camera import frame_bounds
for mesh, (w, h) in ((trimesh.creation.box(), (640, 480)), (trimesh.creation.icosphere(3), (96, 64))):
    for normals in ("flat", "smooth"):
        cam = frame_bounds(mesh.bounds, width=w, height=h, margin=1.0)
        fb = rf.render((mesh.vertices, mesh.faces), view=cam.view, proj=cam.proj, width=w,
                       height=h, raster=rf.RasterState(normals=normals))
        fb.color
out.append(sigs())
print(json.dumps(out))
"""


def test_split_halves_compile_render_s_kernels_with_render_s_types():
    """The two halves of ``warm_core_split`` (issue 27): the second process's half
    (``warm_only([SPLIT_KERNEL])``) gives the fused tile kernel a specialisation and no other
    kernel of the path one; this process's half gives the other six one each and the fused
    kernel none more; real renders (the cube at 640×480, a sphere, flat and smooth) then add
    no specialisation to any of the seven: the halves typed them as ``render`` does, so the
    cache entries they write are the ones a render loads. Run in a process of its own (the
    dispatchers of this one may have been called by other tests); the kernels load from this
    checkout's cache."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", _SIGNATURES], env=env, capture_output=True,
                       text=True, timeout=900, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    child, parent, after = json.loads(r.stdout.strip().splitlines()[-1])
    split = warmup.SPLIT_KERNEL
    assert {n for n, s in child.items() if s} == {split}, child
    assert len(child[split]) == 1
    assert all(len(s) == 1 for s in parent.values()), parent
    assert parent[split] == child[split]
    assert after == parent, (after, parent)


def test_split_call_sites_are_the_kernels_render_calls():
    """Each kernel of ``RENDER_KERNELS`` has the module attribute through which ``render``
    calls it in ``_CALL_SITES``, and that attribute is that kernel (a stale entry would
    leave a kernel compiling in both halves, or in neither)."""
    import importlib
    ks = {warmup._name(d): d for d in warmup.kernels(warmup.CORE_MODULES)}
    assert set(warmup._CALL_SITES) == set(warmup.RENDER_KERNELS)
    for name, sites in warmup._CALL_SITES.items():
        for site in sites:
            mod, attr = site.rsplit(".", 1)
            assert getattr(importlib.import_module(mod), attr) is ks[name], site
    # the stubs are put back, whatever happens inside
    with pytest.raises(RuntimeError):
        with warmup._stubbed(["refraster.framebuffer.shade"]):
            raise RuntimeError
    import refraster.framebuffer
    assert refraster.framebuffer.shade is ks["refraster.raster.gbuffer.shade"]


def test_the_fused_pass_stand_in_leaves_a_valid_empty_face_image():
    """With the fused tile pass replaced (``_stubbed``, as a half of ``warm_core_split`` runs
    it), a render sees no fragment anywhere: the face image is −1 everywhere (the pass writes
    it, not a fill before it), so the G-buffer after it is the background, not whatever the
    recycled arrays held."""
    import numpy as np

    import refraster
    from refraster.camera import look_at, perspective
    mesh = refraster.as_mesh(warmup._box())
    kw = dict(view=look_at((0.3, 0.4, 2.0), (0.0, 0.0, 0.0)),
              proj=perspective(40.0, 4 / 3, 0.5, 10.0), width=16, height=12)
    for _ in range(2):   # the second frame's arrays are the first's, recycled
        refraster.render(mesh, **kw)
        with warmup._stubbed([warmup.SPLIT_KERNEL]):
            fb = refraster.render(mesh, **kw)
        assert (fb.prim_id == -1).all() and (fb.object_id == -1).all()
        assert np.isinf(fb.eye_depth).all() and (fb.normal == 0).all()


def test_first_render_compiles_the_fused_kernel_in_a_second_process(tmp_path):
    """A first ``render`` with the fused tile kernel cold (and ``shade``): a second process
    compiles the fused kernel into the cache (this one does not: Numba's cache log of this
    process names only ``shade`` among the saved entries), the progress line counts both,
    and the picture is byte for byte the one a warm run makes."""
    if not warmup._split_worth_it():
        pytest.skip("one CPU: render compiles in one process by design (warm_core_split)")
    env = _cache_without(tmp_path, (warmup.SPLIT_KERNEL, LEFT_OUT))
    env["NUMBA_DEBUG_CACHE"] = "1"
    first = _render(env, tmp_path, "first")
    assert first.returncode == 0, first.stderr
    assert re.search(rf"{COMPILING}: 2 of 2, \d+\.\d s", first.stderr), first.stderr
    saved = [ln for ln in first.stdout.splitlines() + first.stderr.splitlines()
             if "data saved to" in ln]
    assert any("shade" in ln for ln in saved), first.stdout + first.stderr
    assert not any("_fused_pass" in ln for ln in saved), saved
    cache = Path(env["NUMBA_CACHE_DIR"])
    assert any(p.name.startswith("rasterizer._fused_pass") for p in cache.rglob("*.nbi"))
    second = _render(env, tmp_path, "second")
    assert second.returncode == 0 and "data saved to" not in second.stdout, second.stderr
    assert (tmp_path / "first.png").read_bytes() == (tmp_path / "second.png").read_bytes()


def test_warmup_command_warms_the_reusable_framebuffer_s_span_clear():
    # `refraster warmup` calls warm_core(reusable=True): the span clear of a
    # Framebuffer.reusable gets its one specialisation (the one a reusable frame uses: a third
    # frame adds none); without the option it gets none (so the test can fail).
    code = ("import sys\n"
            "from refraster import warmup\n"
            "from refraster.raster import gbuffer\n"
            "warmup.warm_core(('flat',), reusable=sys.argv[1] == '1')\n"
            "n = len(gbuffer.clear_spans.signatures)\n"
            "if n:\n"
            "    import refraster\n"
            "    from refraster.camera import look_at, perspective\n"
            "    from refraster.framebuffer import Framebuffer\n"
            "    fb = Framebuffer.reusable(40, 30)\n"
            "    for near in (0.5, 1.9):\n"
            "        refraster.render(refraster.as_mesh(warmup._box()), view=look_at((0.3, 0.4, 2.0),"
            " (0, 0, 0)), proj=perspective(40.0, 4 / 3, near, 10.0), width=40, height=30, out=fb)\n"
            "print(n, len(gbuffer.clear_spans.signatures))\n")
    cli = (Path(warmup.__file__).parent / "cli.py").read_text()
    assert "warm_core(clip=True, stream=True, reusable=True, multisample=True)" in cli
    on = subprocess.run([sys.executable, "-c", code, "1"], capture_output=True, text=True,
                        check=True, timeout=600).stdout.split()
    off = subprocess.run([sys.executable, "-c", code, "0"], capture_output=True, text=True,
                         check=True, timeout=600).stdout.split()
    assert on == ["1", "1"]
    assert off == ["0", "0"]


_FACE_IMAGES = """
import json
import numpy as np
import refraster as rf
from refraster import warmup
from refraster.framebuffer import _build
from refraster.raster import gbuffer
def dtypes():
    return [sorted(str(s[0].dtype) for s in k.signatures) for k in (gbuffer.finalize, gbuffer.shade)]
out = []
warmup.warm_core(("flat",))
out.append(dtypes())
box = rf.as_mesh(warmup._box())
cam = rf.camera.frame_bounds(((-1, -1, -1), (1, 1, 1)), width=40, height=30, margin=1.0)
for raster in (dict(samples=4), dict(samples=4, sample_locations="gl_llvmpipe",
                                     interpolation="sample", normals="smooth")):
    rf.render_samples(box, **cam.kwargs, raster=rf.RasterState(**raster)).color
rf.render(box, **cam.kwargs, fragment_stage=lambda f: f.world_position()[:, 0] <= 0.0).color
faces = np.zeros((2, 3), np.int64)           # an int64 face list, as the allowances pass
_build([box], [np.eye(4)], cam.view, cam.proj, np.zeros((2, 3), np.float32), faces,
       np.array([0, 12]), np.zeros((2, 3), np.bool_), np.full((2, 3, 3), 1 / 3, np.float32),
       None, np.ones(3)).color
out.append(dtypes())
print(json.dumps(out))
"""


def test_finalize_and_shade_compile_once_for_the_int32_face_image():
    """``warm_core`` (``refraster warmup``'s, and the gallery's and goldens' cold start) gives
    ``finalize`` and ``shade`` their one specialisation, the int32 face image of every path;
    4x frames (the gallery's raster state among them), the fragment-stream path and an int64
    face list given to ``_build`` (the allowances') then add none. In a process of its own,
    from this checkout's cache."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-c", _FACE_IMAGES], env=env, capture_output=True,
                       text=True, timeout=900, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    warmed, after = json.loads(r.stdout.strip().splitlines()[-1])
    assert warmed == [["int32"], ["int32"]]
    assert after == warmed


def test_fused_clip_warmup_types_the_pass_as_the_golden_clip_scenes_do():
    """``warm_fused_clip`` (a worker's ``warm-fused-clip`` task on a first golden generation,
    beside the pipeline's compile, issue 27) calls the clip surfaces' fused tile pass with
    exactly the argument types the golden clip-surface scenes then pass it: the dispatcher
    types each argument as below, so a cache it filled holds the specialisation those scenes
    load, and they compile none of their own. Its stubs of the pipeline's kernels are put
    back."""
    from refraster import golden
    from refraster.clipsurface import fused
    from refraster.raster import primitive, rasterizer
    gen = sys.modules["refraster.golden.generate"]

    real = fused._fused_clip_pass
    seen = []

    def spy(*args):
        seen.append(tuple(str(real.typeof_pyval(a)) for a in args))
        return real(*args)

    before = {n: getattr(importlib_module(n), n.rsplit(".", 1)[1])
              for n in warmup._FUSED_CLIP_STUBS}
    fused._fused_clip_pass = spy
    try:
        warmup.warm_fused_clip()
        warmed = set(seen)
        seen.clear()
        reg = golden.available_scenes()
        scenes = [n for n, e in reg.items() if e.technique == "clipsurface"]
        assert len(scenes) >= 2, scenes
        for name, entry, params in gen.suite({n: reg[n] for n in scenes}):
            gen.render_task(name, entry, params)
    finally:
        fused._fused_clip_pass = real
    assert {n: getattr(importlib_module(n), n.rsplit(".", 1)[1])
            for n in warmup._FUSED_CLIP_STUBS} == before
    assert primitive._vertex_pass is before["refraster.raster.primitive._vertex_pass"]
    assert rasterizer._bin_pass is before["refraster.raster.rasterizer._bin_pass"]
    assert len(warmed) == 1
    assert seen and set(seen) == warmed, (set(seen) - warmed)


def importlib_module(name):
    import importlib
    return importlib.import_module(name.rsplit(".", 1)[0])


#: The kernels a cold `refraster gallery` compiles (2026-12-02, 09:42 UTC, a fresh cache: every
#: kernel of KERNEL_MODULES not in GALLERY_SKIPS was in the cache after it, and no other), plus
#: issue 46's ``halos4d.slicing._window_vertex``, which the halo kernels (every halo
#: picture) call; and since issue 44's pictures and issue 46's pair search: the δd pair search's
#: three kernels (``halos4d.thicken``, every halo picture's δd), ``raster.multisample._msaa_pass``
#: (the 4× edge picture's ``render_samples``) and ``_sample_stream_pass`` (the 4× clip-surface
#: picture). Since issue 46's fused slicing the halo pictures compile ``render._bin_tets`` and
#: ``_render_tets`` (in place of ``_bin_bands`` and ``_render_bands``) and no longer the
#: slicing's ``_count_pass``, ``_place``, ``_write_pass`` and ``window_setup`` (now skipped);
#: and ``render._fill_off_core``, ``_triangle_off_core``, ``_span_off_core`` and
#: ``_band_slices``, which ``_render_tets`` calls (not inlined, for its compile time) in every
#: default halo picture; and ``primitive.count_pieces`` (the binning's count of clipped
#: pieces, 2026-12-05), which the gallery's warm-up compiles with the clipping kernels; and
#: ``ldi._bucket_pass`` and ``_bucket_scan`` in place of ``_bucket_by_pixel`` (the peel's
#: chunked bucket sort; a cold gallery at 22:41 UTC, 2026-12-05, left all 80 in its cache);
#: and ``capping._cap_rows`` and ``_cap_indices`` (the caps' pixels of every capped clip
#: picture, 2026-12-06).
GALLERY_KERNEL_COUNT = 82


def test_every_new_kernel_is_classified_for_the_gallery():
    # The gallery takes its warm plan (the halo section split over both workers) only when
    # every kernel not in GALLERY_SKIPS is cached. A kernel added to a core module that the
    # gallery never compiles (as Framebuffer.reusable's clear_spans was) made every warm
    # gallery take the cold plan: 35 s instead of ~26 s. This fails when the number of kernels
    # the gallery must find cached changes, so that whoever adds one decides which it is.
    names = [warmup._name(d) for d in warmup.kernels()]
    assert set(warmup.GALLERY_SKIPS) <= set(names), set(warmup.GALLERY_SKIPS) - set(names)
    gallery = [n for n in names if n not in warmup.GALLERY_SKIPS]
    assert len(gallery) == GALLERY_KERNEL_COUNT, (
        f"{len(gallery)} kernels must be cached for the gallery's warm plan, "
        f"{GALLERY_KERNEL_COUNT} expected: add a kernel the gallery never compiles to "
        "warmup.GALLERY_SKIPS, or raise the count after a cold gallery compiled it")
    assert "refraster.raster.gbuffer.clear_spans" not in gallery
