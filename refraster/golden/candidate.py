"""``refraster golden candidate``: render a golden directory's scene packages with another
backend and write a candidate directory that ``golden compare`` reads.

The backend sees only the scene packages (``<scene>/package/``); this module, on the command's
side, reads and verifies the golden's manifest (:func:`refraster.golden.io.read.load_manifest`:
schema, paths, sha256 of every file), hands each package to the backend, and writes
``OUT/<scene>/buffers.npz`` per rendered scene with the golden write rules
(:mod:`refraster.golden.io.write`): under ``OUT``'s lock, into a temporary tree beside it, committed
by one atomic swap; ``OUT`` must be nothing, an empty directory or a candidate refraster wrote
(its marker ``.refraster-candidate`` lists every file with its sha256, the scenes rendered, the
scenes skipped and why, the backend and the renderer); it may not overlap the golden directory.

Backends: ``gl`` (:mod:`refraster.gl`, the optional extra ``gl``) and ``wgpu``
(:mod:`refraster.wgpu`, WebGPU in WGSL, the optional extra ``wgpu``).
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from .io import write
from .io.errors import GoldenError
from .io.read import PATTERN_FILE, load_manifest

__all__ = ["BACKENDS", "candidate"]

#: Backends ``golden candidate`` can drive.
BACKENDS = ("gl", "wgpu")


def _open_backend(backend, faults, threads):
    if backend not in BACKENDS:
        raise ValueError(f"--backend must be one of {list(BACKENDS)}, got {backend!r}")
    if backend == "wgpu":
        try:
            from ..wgpu.driver import Backend as WGPUBackend
            from ..wgpu.device import WGPUUnavailable
        except ImportError as exc:
            raise GoldenError(f"the wgpu backend cannot be imported ({exc}); install the "
                              "'wgpu' extra: pip install refraster[wgpu]") from None
        try:
            return WGPUBackend(faults=faults, threads=threads)
        except WGPUUnavailable as exc:
            raise GoldenError(f"the wgpu backend has no WebGPU device: {exc}") from None
    try:
        from ..gl.driver import Backend, GLUnavailable
    except ImportError as exc:
        raise GoldenError(f"the gl backend cannot be imported ({exc}); install the 'gl' extra: "
                          "pip install refraster[gl]") from None
    try:
        return Backend(faults=faults, threads=threads)
    except GLUnavailable as exc:
        raise GoldenError(f"the gl backend has no OpenGL context: {exc}") from None


def candidate(golden_dir, out, *, backend="gl", scenes=None, faults=(), threads=None,
              wait=True, on_wait=None, on_scene=None):
    """Render the scenes of ``golden_dir`` that ``backend`` supports into the candidate
    directory ``out``.

    Returns ``{"rendered": [names], "skipped": {name: reason}, "renderer": str}``. Raises
    :class:`GoldenError` (the golden, the backend or the output path is unusable) or
    :class:`refraster.golden.io.write.RefusedError` (``out`` holds something else).
    ``faults`` (tests only) plants :data:`refraster.gl.FAULTS` (``backend="wgpu"``:
    :data:`refraster.wgpu.FAULTS`).
    """
    golden_dir = Path(golden_dir)
    names = None if scenes is None else list(scenes)
    twice = next((n for i, n in enumerate(names or ()) if n in names[:i]), None)
    if twice is not None:
        raise GoldenError(f"scenes: {twice!r} is given twice")
    write.pending_swap(golden_dir)   # the golden is only read: its journal is not acted on
    manifest = load_manifest(golden_dir)
    names = list(manifest["scenes"]) if names is None else names
    unknown = [n for n in names if n not in manifest["scenes"]]
    if unknown:
        raise GoldenError(f"scene(s) {unknown} are not in the golden; it has "
                          f"{sorted(manifest['scenes'])}")
    target = write.resolve_target(out)
    real_golden = Path(os.path.realpath(golden_dir))
    if target == real_golden or target.is_relative_to(real_golden) \
            or real_golden.is_relative_to(target):
        raise GoldenError(f"--out {out} overlaps the golden directory {golden_dir}; choose "
                          "another")
    gl = _open_backend(backend, tuple(faults), threads)
    try:
        with write.locked(target, wait=wait, command="refraster golden candidate",
                          on_wait=on_wait):
            write.clean_debris(target)
            return _candidate_locked(golden_dir, manifest, names, target, gl, backend,
                                     on_scene)
    finally:
        gl.release()


def _candidate_locked(golden_dir, manifest, names, target, gl, backend, on_scene):
    from ..gl.package import PackageError
    if backend == "wgpu":
        from ..wgpu.driver import Unsupported
    else:
        from ..gl.driver import Unsupported
    found = write.snapshot(target)
    if found is not None and found[0] != "empty":
        if found[0] != "candidate":
            raise write.RefusedError(f"{target} exists and is not a candidate directory "
                                     f"refraster wrote (no {write.CANDIDATE_MARKER} listing its "
                                     "files); refusing to replace it")
        if found[2]:
            raise write.RefusedError(f"candidate {target} holds files refraster did not write "
                                     f"or that changed since ({', '.join(found[2][:5])}); "
                                     "refusing to replace it")
    tmp = write.make_tree(target)
    try:
        rendered, skipped = [], {}
        for name in names:
            entry = manifest["scenes"][name]
            package = (golden_dir / entry["package"]).parent
            layers = None
            if "layer_depth" in entry["buffers"]:
                layers = entry["buffers"]["layer_depth"]["shape"][-1]
            try:
                buffers = gl.render(package, layers=layers)
            except Unsupported as exc:
                skipped[name] = str(exc)
                if on_scene is not None:
                    on_scene(name, f"skipped: {exc}")
                continue
            except PackageError as exc:
                raise GoldenError(f"scene {name}: {exc}") from None
            missing = sorted(set(entry["buffers"]) - set(buffers))
            if missing:
                skipped[name] = (f"the golden stores buffer(s) {missing} that the {backend} "
                                 "backend does not render")
                if on_scene is not None:
                    on_scene(name, f"skipped: {skipped[name]}")
                continue
            data = io.BytesIO()
            np.savez_compressed(data, **{k: buffers[k] for k in entry["buffers"]})
            (tmp / name).mkdir()
            with open(tmp / name / "buffers.npz", "xb") as fh:
                fh.write(data.getvalue())
            declared = (entry["parameters"].get("technique") or {}).get("sample_pattern")
            if declared is not None:
                # the backend states its own sample pattern (the compare checks it)
                own = gl.sample_pattern(int(declared["samples"]))
                with open(tmp / name / PATTERN_FILE, "x", encoding="utf-8") as fh:
                    fh.write(json.dumps(own, sort_keys=True) + "\n")
            rendered.append(name)
            if on_scene is not None:
                on_scene(name, "rendered")
        files = {p.relative_to(tmp).as_posix(): write._sha256(p)
                 for p in sorted(tmp.rglob("*")) if p.is_file()}
        marker = {"written_by": "refraster golden candidate", "backend": backend,
                  "renderer": gl.renderer, "faults": list(gl.faults),
                  "golden": str(golden_dir), "rendered": rendered, "skipped": skipped,
                  "files": files}
        (tmp / write.CANDIDATE_MARKER).write_text(json.dumps(marker, indent=1, sort_keys=True)
                                                  + "\n", encoding="utf-8")
        write._hook("before_commit", target=target, tmp=tmp)
        write.commit_tree(tmp, target, found, what="golden candidate")
    except BaseException:
        write.discard_tree(tmp, target.name, building=True)
        raise
    return {"rendered": rendered, "skipped": skipped, "renderer": gl.renderer}
