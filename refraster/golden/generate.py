"""``golden generate``: render scenes and write a golden directory.

Layout of a golden directory::

    manifest.json                       index: scenes, buffers, tolerances, versions, sha256
    <scene>/package/...                 the scene package (:mod:`refraster.golden.package`)
    <scene>/buffers.npz                 the golden buffers (no pickle)
    <scene>/preview/<buffer>.png        pictures for humans

The directory is built in a temporary sibling (``.<name>.tmp-…``) and renamed into place at the
end, so a failure or an interruption never leaves a half-written golden; an existing golden is
replaced only with ``update=True`` (and then scenes that were not regenerated are kept).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .. import io as rio
from .._validate import check_shape
from .buffers import DTYPES, KINDS, infer_kind, preview, preview_range
from .package import export_package, npz_bytes, sha256_file
from .scenes import DEFAULT_RASTER, GoldenScene, available_scenes, raster_state
from .schema import MANIFEST_SCHEMA, MANIFEST_SCHEMA_VERSION, validate
from .tolerance import default_tolerances

__all__ = ["generate", "versions", "swap_directory"]


def versions():
    """Versions of what made the golden (``manifest.json`` "generator")."""
    import numba
    import trimesh

    from .. import __version__
    return {"refraster": __version__, "numpy": np.__version__, "numba": numba.__version__,
            "trimesh": trimesh.__version__, "python": platform.python_version()}


def swap_directory(tmp, out):
    """Move the finished ``tmp`` to ``out``, replacing an existing ``out`` (two renames on the
    same filesystem; the old tree is removed only once the new one is in place)."""
    tmp, out = Path(tmp), Path(out)
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
        os.rename(out, old / "tree")
        os.rename(tmp, out)
        shutil.rmtree(old)
    else:
        os.rename(tmp, out)


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


def _write_scene(root, name, scene):
    """Write one scene under ``root``; return its manifest entry."""
    raster = raster_state(scene.raster)
    export_package(root / name / "package", name, scene, raster)
    rio.atomic_write_bytes(root / name / "buffers.npz", npz_bytes(scene.buffers))
    buffers = {}
    for key in sorted(scene.buffers):
        a = np.asarray(scene.buffers[key])
        kind = scene.kinds.get(key) or infer_kind(key, a)
        rel = f"{name}/preview/{key}.png"
        rio.write_png(root / rel, preview(a, kind, preview_range(a, kind)))
        buffers[key] = {"shape": list(a.shape), "dtype": str(a.dtype), "kind": kind,
                        "preview": rel,
                        "tolerance": default_tolerances(key, kind, scene.tolerances.get(key))}
    return {"technique": scene.technique, "description": scene.description,
            "package": f"{name}/package/scene.json", "buffers_file": f"{name}/buffers.npz",
            "buffers": buffers, "parameters": {"raster": raster, "technique": scene.parameters}}


def _old_manifest(out):
    from .compare import load_manifest
    return load_manifest(out)


def generate(out, scenes=None, *, update=False, scene_files=(), progress=None):
    """Render ``scenes`` (names; default all registered) and write a golden directory ``out``.

    Parameters
    ----------
    out : path
        The golden directory. It must not exist unless ``update`` is true, and then it must be a
        golden directory (a ``manifest.json`` this refraster reads).
    scenes : sequence of str, optional
        Registered scene names; ``None`` means every registered scene (and none when only
        ``scene_files`` are given).
    update : bool
        Replace an existing golden; scenes it holds that are not regenerated are kept.
    scene_files : sequence of paths
        TOML scene descriptions (:func:`refraster.golden.load_scene_file`), added to the run.
    progress : callable, optional
        ``progress(name)`` before each scene.

    Returns
    -------
    dict
        The manifest written.
    """
    from .scenes import load_scene_file
    out = Path(out)
    registry = available_scenes()
    if scenes is None:
        names = [] if scene_files else list(registry)
    else:
        names = list(scenes)
        unknown = [n for n in names if n not in registry]
        if unknown:
            raise ValueError(f"unknown golden scene(s) {unknown}; known: {sorted(registry)}")
    entries = {n: registry[n] for n in names}
    for path in scene_files:
        entry = load_scene_file(path)
        if entry.name in entries or entry.name in registry:
            raise ValueError(f"scene file {path} names {entry.name!r}, which is already taken")
        entries[entry.name] = entry
    if not entries:
        raise ValueError("no scenes to generate")
    old = None
    if out.exists() or out.is_symlink():
        if not update:
            raise FileExistsError(f"{out} exists; pass update=True (--update) to replace it")
        if not (out / "manifest.json").is_file():
            raise FileExistsError(f"{out} exists and is not a golden directory (no "
                                  "manifest.json); refusing to replace it")
        old = _old_manifest(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        manifest_scenes = {}
        for name, entry in entries.items():
            if progress is not None:
                progress(name)
            scene = entry.build()
            _check_scene(name, scene)
            if not scene.description:
                scene.description = entry.description
            manifest_scenes[name] = _write_scene(tmp, name, scene)
        if old is not None:
            for name, item in old["scenes"].items():
                if name not in manifest_scenes:
                    shutil.copytree(out / name, tmp / name, symlinks=False)
                    manifest_scenes[name] = item
        files = {}
        for path in sorted(p for p in tmp.rglob("*") if p.is_file()):
            files[path.relative_to(tmp).as_posix()] = sha256_file(path)
        if old is not None:
            for rel, digest in old["files"].items():
                if rel in files and rel.split("/")[0] not in entries and files[rel] != digest:
                    raise ValueError(f"{out / rel} does not match its sha256 in the manifest; "
                                     "the old golden is corrupt, not updating it")
        manifest = {
            "schema": "refraster.golden",
            "schema_version": MANIFEST_SCHEMA_VERSION,
            "generator": versions(),
            "raster": {"subpixel_bits": DEFAULT_RASTER["subpixel_bits"],
                       "fill_rule": DEFAULT_RASTER["fill_rule"]},
            "scenes": dict(sorted(manifest_scenes.items())),
            "files": files,
        }
        validate(json.loads(json.dumps(manifest)), MANIFEST_SCHEMA)
        rio.write_json(tmp / "manifest.json", manifest)
        swap_directory(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return manifest
