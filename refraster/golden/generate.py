"""``golden generate``: render scenes and write a golden directory.

Layout of a golden directory::

    manifest.json                       index: scenes, buffers, tolerances, versions, sha256
    <scene>/package/...                 the scene package (:mod:`refraster.golden.io.package`)
    <scene>/buffers.npz                 the golden buffers (no pickle)
    <scene>/preview/<buffer>.png        pictures for humans

The directory is built in a temporary sibling (``.<name>.tmp-…``) and swapped into place at the
end by :mod:`refraster.golden.io.write` (under a lock, after checking that ``out`` still holds what
the run found, atomically), so a failure or an interruption never leaves a half-written golden;
an existing golden is replaced only with ``update=True`` (and then scenes that were not
regenerated are kept).
"""

from __future__ import annotations

import inspect
import json
import platform
import re
import tempfile
from pathlib import Path

import numpy as np

from .. import io as rio
from .._validate import check_shape
from .io.buffers import DTYPES, KINDS, infer_kind, preview, preview_range
from .io.package import export_package, npz_bytes, sha256_file
from .io.read import copy_listed_scene
from .scenes import (DEFAULT_RASTER, GoldenScene, SceneEntry, available_scenes, id_range,
                     manifest_raster, raster_state)
from .io.schema import MANIFEST_SCHEMA, MANIFEST_SCHEMA_VERSION, validate
from .allowances.precision import (CANDIDATE_BITS, as_candidate_bits, declared,
                                   manifest_candidate_bits)
from .compare.profiles import default_tolerances
from .io import write

__all__ = ["generate", "versions", "swap_directory", "suite", "render_task", "parse_sweep",
           "parse_size", "GenerationError", "WORKER_GROUPS", "WITHOUT_PIPELINE", "worker_groups"]


def versions():
    """Versions of what made the golden (``manifest.json`` "generator")."""
    import numba
    import trimesh

    from .. import __version__
    return {"refraster": __version__, "numpy": np.__version__, "numba": numba.__version__,
            "trimesh": trimesh.__version__, "python": platform.python_version()}


def swap_directory(tmp, out):
    """Move the finished ``tmp`` to ``out``, replacing what is there (kept for callers of the
    old name): under ``out``'s lock, atomically (:func:`refraster.golden.io.write.commit_tree`);
    of the tree replaced only the files its manifest or report marker lists are deleted."""
    out = write.resolve_target(out)
    with write.locked(out, command="refraster"):
        write.commit_tree(tmp, out, write.snapshot(out))


def _check_scene(name, scene):
    if not isinstance(scene, GoldenScene):
        raise TypeError(f"scene {name!r}: its function must return a GoldenScene, "
                        f"got {type(scene).__name__}")
    if not scene.buffers:
        raise ValueError(f"scene {name!r} has no buffers")
    h, w = scene.camera.height, scene.camera.width
    for key, a in scene.buffers.items():
        a = np.asarray(a)
        check_shape(a, f"scene {name!r} buffer {key!r}", (h, w) + (None,) * (a.ndim - 2))
        if a.ndim not in (2, 3) or str(a.dtype) not in DTYPES:
            raise ValueError(f"scene {name!r} buffer {key!r}: expected (H, W) or (H, W, C) of "
                             f"{DTYPES}, got {a.dtype} {a.shape}")
    for key, kind in scene.kinds.items():
        if key not in scene.buffers or kind not in KINDS:
            raise ValueError(f"scene {name!r}: kinds[{key!r}] = {kind!r} does not name a "
                             f"buffer and one of {KINDS}")


def _id_range(name, key, scene, a):
    """The id range of buffer ``key``, checked against the golden's own ids: a scene whose
    ids break its stated convention is a bug in the scene, refused here."""
    rng = id_range(scene, key)
    if rng is None:
        raise ValueError(f"scene {name!r}: id buffer {key!r} has no id convention; state its "
                         "range in GoldenScene.ids")
    lo, hi = rng
    if a.size and (int(a.min()) < lo or int(a.max()) > hi):
        raise ValueError(f"scene {name!r}: buffer {key!r} holds ids {int(a.min())}..."
                         f"{int(a.max())}, outside its convention [{lo}, {hi}]")
    return [lo, hi]


def _write_scene(root, name, scene):
    """Write one scene under ``root``; return its manifest entry. The allowances are derived
    for the declared candidate bits (:func:`render_task`)."""
    from .allowances.core import scene_allowances
    from .allowances.samples import msaa_allowances
    raster = raster_state(scene.raster)
    export_package(root / name / "package", name, scene, raster)
    rio.atomic_write_bytes(root / name / "buffers.npz", npz_bytes(scene.buffers))
    # multisampled scenes: per sample, on the scene moved by each sample's offset
    # technique scenes at samples > 1: the single-sample allowances per sample (clip surfaces:
    # the clip-surface ones per sample, allowances/samples.py)
    from .allowances.sampled import sampled_allowances
    samples = int(raster.get("samples", 1))
    allowances = (msaa_allowances if scene.technique == "msaa"
                  or (scene.technique == "clipsurface" and samples > 1)
                  else sampled_allowances if samples > 1 else scene_allowances)
    try:
        arrays, info, tolerant = allowances(scene, raster)
    except ValueError as exc:
        raise ValueError(f"scene {name!r}: its allowances: {exc}") from None
    rio.atomic_write_bytes(root / name / "tolerance.npz", npz_bytes(arrays))
    buffers = {}
    for key in sorted(scene.buffers):
        a = np.asarray(scene.buffers[key])
        kind = scene.kinds.get(key) or infer_kind(key, a)
        rel = f"{name}/preview/{key}.png"
        rio.write_png(root / rel, preview(a, kind, preview_range(a, kind)))
        buffers[key] = {"shape": list(a.shape), "dtype": str(a.dtype), "kind": kind,
                        "preview": rel,
                        "tolerance": default_tolerances(key, kind, scene.tolerances.get(key)),
                        "tolerant": tolerant[key]}
        if kind == "id":
            buffers[key]["ids"] = _id_range(name, key, scene, a)
    allowances = {"file": f"{name}/tolerance.npz", **info,
                  "arrays": {k: {"shape": list(v.shape), "dtype": str(v.dtype)}
                             for k, v in sorted(arrays.items())}}
    return {"technique": scene.technique, "description": scene.description,
            "package": f"{name}/package/scene.json", "buffers_file": f"{name}/buffers.npz",
            "buffers": buffers,
            "parameters": {"raster": manifest_raster(raster), "technique": scene.parameters},
            "allowances": allowances}


# --- suites: scenes × parameter sweeps × resolutions ---------------------------------------------

_SLUG = re.compile(r"[^a-z0-9]+")


def _slug(value):
    return _SLUG.sub("_", str(value).lower()).strip("_") or "x"


def parse_sweep(text):
    """``KEY=V1,V2,…`` → ``(key, [values])``; values are int, float or str (``true``/``false``
    are bools)."""
    if not isinstance(text, str) or "=" not in text:
        raise ValueError(f"a sweep looks like KEY=V1,V2,..., got {text!r}")
    key, values = text.split("=", 1)
    key = key.strip()
    if not re.match(r"^[a-z_][a-z0-9_]*$", key):
        raise ValueError(f"sweep key must be a lower-case identifier, got {key!r}")
    out = []
    for v in values.split(","):
        v = v.strip()
        if not v:
            raise ValueError(f"empty value in sweep {text!r}")
        low = v.lower()
        if low in ("true", "false"):
            out.append(low == "true")
            continue
        for conv in (int, float):
            try:
                out.append(conv(v))
                break
            except ValueError:
                continue
        else:
            out.append(v)
    return key, out


def parse_size(text):
    """``WxH`` → ``(width, height)``."""
    m = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$", str(text))
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise ValueError(f"a size looks like WIDTHxHEIGHT (e.g. 64x48), got {text!r}")
    return int(m.group(1)), int(m.group(2))


def _takes(fn, key):
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return False
    return key in sig.parameters or any(p.kind == p.VAR_KEYWORD
                                        for p in sig.parameters.values())


def suite(entries, *, sweeps=(), sizes=()):
    """Expand scenes × parameter sweeps × resolutions into tasks.

    Parameters
    ----------
    entries : dict of str → SceneEntry
    sweeps : sequence of ``(key, values)``
        Keyword arguments passed to the scene functions, every combination.
    sizes : sequence of ``(width, height)``
        Passed as ``width=`` and ``height=``.

    Returns
    -------
    list of ``(name, entry, params)``
        ``name`` is the scene's own without sweeps or sizes, else
        ``<scene>__<key>_<value>…__<W>x<H>``.
    """
    combos = [{}]
    for key, values in sweeps:
        combos = [{**c, key: v} for c in combos for v in values]
    size_list = list(sizes) or [None]
    tasks = []
    for name, entry in entries.items():
        for combo in combos:
            for size in size_list:
                params = dict(combo)
                parts = [f"{k}_{_slug(v)}" for k, v in combo.items()]
                if size is not None:
                    params.update(width=size[0], height=size[1])
                    parts.append(f"{size[0]}x{size[1]}")
                for key in params:
                    if not _takes(entry.build, key):
                        raise ValueError(f"scene {name!r} does not take parameter {key!r} "
                                         "(sweeps and sizes apply to scenes whose function "
                                         "accepts them)")
                tasks.append(("__".join([name, *parts]), entry, params))
    names = [t[0] for t in tasks]
    if len(set(names)) != len(names):
        raise ValueError("the suite gives two scenes the same name; use distinct sweep values")
    return tasks


def render_task(name, entry, params, bits=CANDIDATE_BITS):
    """Build and write one scene (in a private temporary directory) and return
    ``(name, manifest entry, {relative path: bytes})``: the unit of work of a serial or a
    distributed run, so both write the same bytes. ``bits``: the candidate's declared
    sub-pixel bits (4 to 8), which the scene's allowances assume — those the scene function
    derives while it builds (:func:`refraster.golden.allowances.precision.candidate_bits`)
    and those of :func:`refraster.golden.allowances.core.scene_allowances`."""
    with declared(bits):
        scene = entry.build(**params)
        _check_scene(name, scene)
        if not scene.description:
            scene.description = entry.description
        with tempfile.TemporaryDirectory(prefix="refraster-golden-task-") as tmp:
            root = Path(tmp)
            item = _write_scene(root, name, scene)
            if params:
                item["parameters"]["variant"] = {"scene": entry.name, **params}
            files = {p.relative_to(root).as_posix(): p.read_bytes()
                     for p in sorted(root.rglob("*")) if p.is_file()}
    return name, item, files


class GenerationError(RuntimeError):
    """A scene failed twice (once and its retry) in a distributed run, or once in a worker
    process of ``jobs > 1``."""


def _run_serial(tasks, progress, bar, bits):
    for name, entry, params in tasks:
        if progress is not None:
            progress(name)
        yield render_task(name, entry, params, bits)
        bar.update(1)


# --- worker processes of one thread each (jobs > 1) -------------------------------------------

#: Worker processes of ``generate(jobs=N)``, by technique, started in this order as workers free
#: up: each group's scenes render in one process, so that each kernel compiles in one process.
#: On a first run the clip surfaces' scenes compile longest (~half of a cold generation's
#: compile time, 2026-12-02: ``_fused_clip_pass`` alone ~30 %), so they start first; the
#: others share the second worker (the layered depth images and the parity test there too:
#: with the clip surfaces they would lengthen the critical path), the halos after. Techniques
#: not listed (new ones) join the second group.
WORKER_GROUPS = [("clipsurface",), ("render", "edges", "cutaway", "ldi", "vds"), ("halos4d",)]
#: Techniques whose scenes use none of the pipeline's kernels: on a first run their worker
#: starts while this process compiles those (then ``warm-clipsurface``, the clip surfaces'
#: kernels that need no pipeline kernel, runs after them in the same worker). None today:
#: unlike the gallery's halos section, the halos' golden scenes use the pipeline's kernels (a
#: fresh cache rendering only them compiles ``_bin_pass``, ``_stream_pass``, ``_resolve``…);
#: so on a first run one worker compiles only ``warm-clipsurface`` and ``warm-fused-clip`` (the
#: clip surfaces' fused tile pass, the largest single compile) while this process compiles the
#: pipeline; the clip surfaces' group starts when that worker has ended.
WITHOUT_PIPELINE = set()
#: The module a worker process runs (``python -m``).
WORKER_MODULE = "refraster.golden.worker"


def _in_worker(entry):
    """Whether a worker process builds the same scene from its name: a scene registered by
    :mod:`refraster.golden.scenes` or a module of its ``SCENE_MODULES`` (not a TOML scene file,
    not one registered at run time by other code)."""
    from . import scenes
    return scenes.SCENES.get(entry.name) is entry and getattr(
        entry.build, "__module__", None) in (scenes.__name__, *scenes.SCENE_MODULES)


def worker_groups(tasks, jobs):
    """The task names split into groups for ``jobs`` worker processes (:data:`WORKER_GROUPS`,
    the longest first; empty groups dropped), or None when they run in this process: one job,
    one task, or a task a worker cannot build (:func:`_in_worker`)."""
    if jobs < 2 or len(tasks) < 2 or not all(_in_worker(entry) for _, entry, _ in tasks):
        return None
    groups = [[n for n, e, _ in tasks if e.technique in techniques]
              for techniques in WORKER_GROUPS]
    listed = {t for g in WORKER_GROUPS for t in g}
    groups[1] += [n for n, e, _ in tasks if e.technique not in listed]
    return [g for g in groups if g]


_SAFE_REL = re.compile(r"^[A-Za-z0-9_.\-]+(/[A-Za-z0-9_.\-]+)*$")


def _answer(name, result):
    """The manifest entry and files of a worker's answer for task ``name``, checked: a dict
    entry, and files only under ``name/`` (relative, no ``..``), base64 bytes."""
    import base64
    import binascii
    try:
        item, files = result["item"], result["files"]
        if not isinstance(item, dict) or not isinstance(files, dict):
            raise TypeError("item and files must be objects")
        out = {}
        for rel, text in files.items():
            parts = rel.split("/") if isinstance(rel, str) else []
            if (not _SAFE_REL.match(rel or "") or parts[0] != name or len(parts) < 2
                    or any(p in (".", "..") for p in parts)):
                raise ValueError(f"file {rel!r} is not under {name}/")
            out[rel] = base64.b64decode(text.encode("ascii"), validate=True)
    except (KeyError, TypeError, ValueError, AttributeError, binascii.Error) as exc:
        raise GenerationError(f"scene {name} failed in a worker process: unreadable answer "
                              f"({type(exc).__name__}: {exc})") from None
    return item, out


def _run_jobs(tasks, groups, jobs, progress, bar, compile_progress, bits):
    """Render ``tasks`` in worker processes of one thread each (:mod:`refraster.golden.worker`
    by :func:`refraster._workers.run_groups`), ``groups`` of them at most ``jobs`` at a time;
    yield ``(name, entry, files)`` as each arrives. The first failure stops the run
    (:class:`GenerationError` naming the scene; every worker is killed); nothing is written
    here."""
    import contextlib

    from .._workers import cold_start_groups, run_groups
    spec = {name: [entry.name, params, bits] for name, entry, params in tasks}
    technique = {name: entry.technique for name, entry, _ in tasks}

    def command(group):
        return [json.dumps({n: spec[n] for n in group if n in spec}, sort_keys=True), *group]

    def clip_group(g):
        return any(technique.get(n) == "clipsurface" for n in g)

    def cold_start(queue, side_cold):
        return cold_start_groups(queue, jobs, lambda n: technique[n] in WITHOUT_PIPELINE,
                                 side_cold, clip_group=clip_group, fused_clip=True)

    answers = run_groups(WORKER_MODULE, groups, jobs, key="scene",
                         command=command, progress=compile_progress, cold_start=cold_start,
                         fail_fast=True, after_warm=clip_group)
    with contextlib.closing(answers):
        for name, result, error in answers:
            if error is not None:
                raise GenerationError(f"scene {name} failed in a worker process: {error}")
            item, files = _answer(name, result)
            if progress is not None:
                progress(name)
            bar.update(1)
            yield name, item, files


def _open_client(workers, scheduler):
    import logging

    import dask
    from dask.distributed import Client, LocalCluster
    if scheduler is not None:
        return Client(scheduler), None
    # a worker that dies takes its task down: report it and retry once ourselves instead of
    # letting the scheduler re-run it silently
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _run_distributed(tasks, workers, scheduler, progress, bar, on_retry, bits):
    from dask.distributed import as_completed
    client, cluster = _open_client(workers, scheduler)
    try:
        by_key = {}
        futures = []
        for task in tasks:
            fut = client.submit(render_task, *task, bits, pure=False)
            by_key[fut.key] = (task, 0)
            futures.append(fut)
        failed = []
        pending = as_completed(futures, with_results=False)
        for fut in pending:
            task, attempt = by_key.pop(fut.key)
            try:
                result = fut.result()
            except Exception as exc:  # anything a scene or a dying worker raises
                reason = f"{type(exc).__name__}: {exc}"
                if attempt == 0:
                    if on_retry is not None:
                        on_retry(task[0], reason)
                    again = client.submit(render_task, *task, bits, pure=False)
                    by_key[again.key] = (task, 1)
                    pending.add(again)
                else:
                    failed.append(f"{task[0]}: {reason}")
                    bar.update(1)
                continue
            if progress is not None:
                progress(task[0])
            bar.update(1)
            yield result
        if failed:
            raise GenerationError("scene(s) failed twice (the first failure was retried): "
                                  + "; ".join(failed))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _old_manifest(out):
    from .compare.run import load_manifest
    return load_manifest(out)


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def generate(out, scenes=None, *, update=False, scene_files=(), progress=None, sweeps=(),
             sizes=(), workers=1, scheduler=None, progress_bar=False, on_retry=None,
             wait=True, jobs=1, compile_progress=None, candidate_subpixel_bits=CANDIDATE_BITS):
    """Render ``scenes`` (names; default all registered) and write a golden directory ``out``.

    Parameters
    ----------
    out : path
        The golden directory. It must not exist unless ``update`` is true, and then it must be a
        golden directory (a ``manifest.json`` this refraster reads).
    scenes : sequence of str or SceneEntry, optional
        Registered scene names, or entries (a scene in another API's conventions:
        :func:`refraster.golden.conventions.in_convention`); ``None`` means every registered
        scene (and none when only ``scene_files`` are given).
    update : bool
        Replace an existing golden; scenes it holds that are not regenerated are kept.
    scene_files : sequence of paths
        TOML scene descriptions (:func:`refraster.golden.load_scene_file`), added to the run.
    progress : callable, optional
        ``progress(name)`` before each scene (serial) or when it is done (distributed).
    sweeps : sequence of ``(key, values)`` or ``"KEY=V1,V2"`` strings
        Parameter sweeps: every combination is passed to every scene function (:func:`suite`).
    sizes : sequence of ``(width, height)`` or ``"WxH"`` strings
        Resolutions, passed as ``width=`` / ``height=``.
    workers : int
        More than 1: render on a Dask ``LocalCluster`` of that many single-threaded processes.
    scheduler : str, optional
        Address of a running Dask scheduler to render on instead (``workers`` is ignored).
    progress_bar : bool
        Show a tqdm progress bar on stderr.
    on_retry : callable, optional
        ``on_retry(name, reason)`` when a distributed task failed and is run once more. A task
        that fails twice makes the whole run fail (:class:`GenerationError`).
    wait : bool or callable
        Another run writing ``out`` holds its lock: wait for it (true, default), or raise
        :class:`refraster.golden.io.write.LockedError` naming it (false). A callable waits
        too and is called as ``wait(holder)`` before waiting (``holder`` describes the other
        run).
    jobs : int
        More than 1 (and no ``workers``/``scheduler``): render in that many worker processes
        of one thread each, the scenes grouped by technique (:data:`WORKER_GROUPS`), each
        process answering this one with the bytes it would have written; on a first run the
        pipeline's kernels compile here while a worker compiles kernels that need none of
        them. Scenes a worker cannot build from their name (TOML scene files, scenes
        registered at run time) make the run serial. The bytes written do not depend on it.
    compile_progress : refraster.warmup.CompileProgress, optional
        Counts the kernels the worker processes compile (the command's progress line).
    candidate_subpixel_bits : int
        The sub-pixel precision of the candidates the golden is for, 4 to 8 (default 8, as the
        CTS reference renderer and current desktop GPUs; 4 for devices at OpenGL's minimum).
        Every allowance that depends on vertex snapping assumes it (docs/tolerance.md); the
        manifest records it (``candidate.subpixel_bits``). ``update`` keeps old scenes only if
        they were derived for the same bits.

    A symbolic link at ``out`` is followed: the golden it points to is updated, the link stays.
    The run refuses (:class:`refraster.golden.io.write.RefusedError`, nothing deleted) if at the
    end ``out`` no longer holds what it found (nothing, or the same golden).

    Returns
    -------
    dict
        The manifest written; byte-identical whether serial or distributed.
    """
    from .scenes import load_scene_file
    out = Path(out)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an int >= 1, got {jobs!r}")
    bits = as_candidate_bits(candidate_subpixel_bits)
    on_wait = wait if callable(wait) else None
    sweeps = [parse_sweep(x) if isinstance(x, str) else (x[0], list(x[1])) for x in sweeps]
    sizes = [parse_size(x) if isinstance(x, str) else tuple(x) for x in sizes]
    registry = available_scenes()
    given = {}
    if scenes is None:
        names = [] if scene_files else list(registry)
    else:
        given = {s.name: s for s in scenes if isinstance(s, SceneEntry)}
        names = [s.name if isinstance(s, SceneEntry) else s for s in scenes]
        unknown = [n for n in names if n not in registry and n not in given]
        if unknown:
            raise ValueError(f"unknown golden scene(s) {unknown}; known: {sorted(registry)}")
    entries = {n: given.get(n) or registry[n] for n in names}
    for path in scene_files:
        entry = load_scene_file(path)
        if entry.name in entries or entry.name in registry:
            raise ValueError(f"scene file {path} names {entry.name!r}, which is already taken")
        entries[entry.name] = entry
    if not entries:
        raise ValueError("no scenes to generate")
    tasks = suite(entries, sweeps=sweeps, sizes=sizes)
    out = write.resolve_target(out)  # through a symlink: the golden it points to
    with write.locked(out, wait=bool(wait), command="refraster golden generate",
                      on_wait=on_wait):
        write._hook("locked", target=out)
        write.clean_debris(out)
        return _generate_locked(out, tasks, update, progress, workers, scheduler, progress_bar,
                                on_retry, jobs, compile_progress, bits)


def _generate_locked(out, tasks, update, progress, workers, scheduler, progress_bar, on_retry,
                     jobs=1, compile_progress=None, bits=CANDIDATE_BITS):
    generated = {t[0] for t in tasks}
    old = None
    found = write.snapshot(out)
    if found is not None:
        if not update:
            raise FileExistsError(f"{out} exists; pass update=True (--update) to replace it")
        if found[0] != "golden":
            raise FileExistsError(f"{out} exists and is not a golden directory (no "
                                  "manifest.json); refusing to replace it")
        if found[2]:
            raise write.RefusedError(f"golden {out} holds files refraster did not write or "
                                     f"that changed since ({', '.join(found[2][:5])}); "
                                     "refusing to replace it")
        old = _old_manifest(out)
        kept = [n for n in old["scenes"] if n not in generated]
        old_bits = manifest_candidate_bits(old)
        if kept and old_bits != bits:
            raise ValueError(f"candidate_subpixel_bits is {bits} but the golden {out} was "
                             f"generated for {old_bits}, and its scenes {kept[:3]} would be "
                             f"kept with allowances for {old_bits}; regenerate every scene or "
                             f"declare {old_bits}")
    tmp = write.make_tree(out)
    bar = _NoBar()
    if progress_bar:
        from tqdm import tqdm
        bar = tqdm(total=len(tasks), desc="golden", unit="scene")
    try:
        manifest_scenes = {}
        groups = worker_groups(tasks, jobs)
        if scheduler is not None or workers > 1:
            results = _run_distributed(tasks, workers, scheduler, progress, bar, on_retry,
                                       bits)
        elif groups is not None:
            results = _run_jobs(tasks, groups, jobs, progress, bar, compile_progress, bits)
        else:
            results = _run_serial(tasks, progress, bar, bits)
        try:
            for name, item, files in results:
                for rel, data in files.items():
                    rio.atomic_write_bytes(tmp / rel, data)
                manifest_scenes[name] = item
        finally:
            results.close()   # worker processes still running are stopped now
        if old is not None:
            for name, item in old["scenes"].items():
                if name not in manifest_scenes:
                    # the manifest's file list only, no link followed (unlisted: a warning)
                    copy_listed_scene(out, old, name, tmp)
                    manifest_scenes[name] = item
        files = {}
        for path in sorted(p for p in tmp.rglob("*") if p.is_file()):
            files[path.relative_to(tmp).as_posix()] = sha256_file(path)
        if old is not None:
            for rel, digest in old["files"].items():
                if rel in files and rel.split("/")[0] not in generated and files[rel] != digest:
                    raise ValueError(f"{out / rel} does not match its sha256 in the manifest; "
                                     "the old golden is corrupt, not updating it")
        manifest = {
            "schema": "refraster.golden",
            "schema_version": MANIFEST_SCHEMA_VERSION,
            "generator": versions(),
            "raster": {"subpixel_bits": DEFAULT_RASTER["subpixel_bits"],
                       "fill_rule": DEFAULT_RASTER["fill_rule"]},
            "candidate": {"subpixel_bits": bits},
            "scenes": dict(sorted(manifest_scenes.items())),
            "files": files,
        }
        validate(json.loads(json.dumps(manifest)), MANIFEST_SCHEMA)
        rio.write_json(tmp / "manifest.json", manifest)
        write._hook("before_commit", target=out, tmp=tmp)
        write.commit_tree(tmp, out, found, what="golden generate")
    except BaseException:
        write.discard_tree(tmp, out.name, building=True)
        raise
    finally:
        bar.close()
    return manifest
