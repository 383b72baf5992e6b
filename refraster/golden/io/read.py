"""Reading a golden directory and a candidate without trusting either.

What a reader trusts and what it checks is listed in ``docs/golden.md`` ("What a golden reader
trusts"). In short:

* **No link is followed.** Every file the manifest lists is opened only when no component of
  its path below the golden directory is a symbolic link and it is a regular file (a FIFO or a
  device is refused before it is read); candidate files likewise, and a candidate scene
  directory that is a link is refused.
* **The manifest's file list is the golden.** Every listed file matches its sha256; every path
  the manifest or a scene package names is listed; kept scenes are copied from that list only
  (:func:`copy_listed_scene`), unlisted files are skipped and named.
* **Scene packages are validated on every read** (:func:`check_package`): ``scene.json``
  against :data:`~refraster.golden.io.schema.SCENE_SCHEMA` (finite numbers, plain relative paths,
  sizes ≥ 1), its name, technique and viewport against the manifest, and every mesh and map
  it names against the manifest's file list.
* **Headers first.** ``.npy`` headers (also inside ``.npz`` members) and PNG ``IHDR`` chunks
  are read before any data; a shape or dtype the golden does not expect is refused before
  anything is decompressed, and ``.npz`` members the golden does not have are skipped unread.
  So reading costs about the size of the golden's own buffers, whatever the candidate holds.
* **Archives sized from their end records.** An ``.npz`` of more than
  :data:`MAX_NPZ_MEMBERS` members, or a member stored twice, is refused before any member is
  read (:func:`read_npz`).
* **Files are opened by** :mod:`refraster.golden.io.safe`: ``lstat``, ``O_NOFOLLOW |
  O_NONBLOCK``, ``fstat``; side files size-capped before they are read; JSON parsed into one
  error line (nesting, integers past the conversion limit named by JSON path).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import stat
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..._validate import MAX_PIXELS, MAX_SIDE
from .errors import CandidateError, GoldenError
from .safe import MAX_SIDE_FILE_BYTES, loads_json, open_regular, read_capped
from .schema import (MANIFEST_SCHEMA, MANIFEST_SCHEMA_OLDEST, MANIFEST_SCHEMA_VERSION, SCENE_SCHEMA,
                     SCENE_SCHEMA_VERSION, SchemaError, check_version, is_safe_relpath,
                     validate)

__all__ = ["GoldenError", "CandidateError", "load_manifest", "check_package", "open_listed",
           "copy_listed_scene", "load_candidate", "reference_buffers", "allowance_arrays",
           "read_npz", "read_npy", "png_header", "MAX_JSON_BYTES"]

log = logging.getLogger("refraster.golden")

#: Largest ``manifest.json`` or ``scene.json`` read (bytes).
MAX_JSON_BYTES = MAX_SIDE_FILE_BYTES
#: Largest number of channels (layers) of a buffer or an allowance array.
MAX_CHANNELS = 256
#: Largest number of elements of one golden array (1 GiB of float32).
MAX_ELEMENTS = 1 << 28




# --- files: no links, regular files only ---------------------------------------------------------

def _no_links_below(root, rel, error, what):
    """Refuse ``root/rel`` when a directory on the way from ``root`` is a symbolic link."""
    parts = rel.split("/")
    path = root
    for part in parts[:-1]:
        path = path / part
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            raise error(f"{what} {root / rel} is missing") from None
        except OSError as exc:
            raise error(f"cannot read {what} {root / rel}: {exc}") from None
        if stat.S_ISLNK(st.st_mode):
            raise error(f"{what} {root / rel}: directory {path} is a symbolic link; links are "
                        "never followed")
    return root / rel


def _inside(root, rel, where):
    """``root / rel`` resolved, refusing anything that leaves ``root`` (``..``, absolute paths,
    symlinks pointing out)."""
    if not is_safe_relpath(rel):
        raise GoldenError(f"{where}: path {rel!r} leaves the golden directory or is not a plain "
                          "relative path; refusing to read it")
    path = (root / rel).resolve()
    if not path.is_relative_to(root.resolve()):
        raise GoldenError(f"{where}: path {rel!r} resolves to {path}, outside the golden "
                          "directory; refusing to read it")
    return path


def _sha256(fh):
    h = hashlib.sha256()
    for block in iter(lambda: fh.read(1 << 20), b""):
        h.update(block)
    return h.hexdigest()


def open_listed(golden_dir, manifest, rel, *, verify=True):
    """Open the golden file ``rel`` (binary, positioned at 0): it must be listed in the
    manifest's ``files``, stay inside the directory, pass through no symbolic link, be a
    regular file and (``verify``) match its sha256. Raises :class:`GoldenError`."""
    root = Path(golden_dir)
    if rel not in manifest["files"]:
        raise GoldenError(f"golden file {rel!r} is not listed in {root / 'manifest.json'}")
    _inside(root, rel, f"{root / 'manifest.json'} $.files")
    path = _no_links_below(root, rel, GoldenError, "golden file")
    fh = open_regular(path, GoldenError, "golden file")
    if verify:
        try:
            digest = _sha256(fh)
        except OSError as exc:
            fh.close()
            raise GoldenError(f"cannot read golden file {path}: {exc}") from None
        if digest != manifest["files"][rel]:
            fh.close()
            raise GoldenError(f"golden file {path} does not match its sha256 in the manifest "
                              "(corrupt or edited)")
        fh.seek(0)
    return fh


def _read_json(fh, path, error):
    if os.fstat(fh.fileno()).st_size > MAX_JSON_BYTES:
        raise error(f"cannot read {path}: larger than {MAX_JSON_BYTES >> 20} MiB")
    data = read_capped(fh, MAX_JSON_BYTES)
    if len(data) > MAX_JSON_BYTES:
        raise error(f"cannot read {path}: larger than {MAX_JSON_BYTES >> 20} MiB")
    return loads_json(data, path, error)


# --- the manifest --------------------------------------------------------------------------------

def _manifest_paths(manifest):
    """(JSON path, relative path) of every file the manifest points at."""
    scenes = manifest.get("scenes")
    for name, scene in (scenes.items() if isinstance(scenes, dict) else ()):
        if not isinstance(scene, dict):
            continue
        for key in ("package", "buffers_file"):
            if key in scene:
                yield f"$.scenes.{name}.{key}", scene[key]
        allowances = scene.get("allowances")
        if isinstance(allowances, dict) and "file" in allowances:
            yield f"$.scenes.{name}.allowances.file", allowances["file"]
        buffers = scene.get("buffers")
        for bname, buf in (buffers.items() if isinstance(buffers, dict) else ()):
            if isinstance(buf, dict) and "preview" in buf:
                yield f"$.scenes.{name}.buffers.{bname}.preview", buf["preview"]
    files = manifest.get("files")
    for rel in (files if isinstance(files, dict) else ()):
        yield "$.files", rel


def _check_shape_size(shape, where):
    """A buffer or allowance array: (H, W) or (H, W, C), H, W ≤ MAX_SIDE, H·W ≤ MAX_PIXELS,
    C ≤ MAX_CHANNELS, H·W·C ≤ MAX_ELEMENTS — so reading it costs a bounded amount of memory."""
    if len(shape) not in (2, 3) or (len(shape) == 3 and not 1 <= shape[2] <= MAX_CHANNELS):
        raise GoldenError(f"{where}: shape {shape} is not (H, W) or (H, W, C ≤ {MAX_CHANNELS})")
    h, w = shape[:2]
    if h > MAX_SIDE or w > MAX_SIDE or h * w > MAX_PIXELS \
            or h * w * (shape[2] if len(shape) == 3 else 1) > MAX_ELEMENTS:
        raise GoldenError(f"{where}: shape {shape} exceeds the largest supported image "
                          f"({MAX_SIDE} per side, {MAX_PIXELS} pixels)")


def _check_table_size(shape, where):
    """A face-set table of ``tolerance.npz`` (``set_*``, ``draw_offsets``): (N,) or (N, C),
    C ≤ MAX_CHANNELS, N·C ≤ MAX_ELEMENTS; its consistency with the frame is checked when read
    (:func:`refraster.golden.allowances.core.check_face_sets`)."""
    if len(shape) not in (1, 2) or (len(shape) == 2 and not 1 <= shape[1] <= MAX_CHANNELS):
        raise GoldenError(f"{where}: shape {shape} is not (N,) or (N, C ≤ {MAX_CHANNELS})")
    if shape[0] * (shape[1] if len(shape) == 2 else 1) > MAX_ELEMENTS:
        raise GoldenError(f"{where}: shape {shape} exceeds {MAX_ELEMENTS} elements")


def load_manifest(golden_dir, *, verify=True):
    """Read, check and return ``golden_dir/manifest.json``.

    Raises :class:`GoldenError` for a missing or unparsable manifest, one of another kind or a
    newer schema version, a schema violation, a path leaving the directory, a buffer shape
    beyond the supported image size, a scene package that breaks its schema or names an
    unlisted file (:func:`check_package`), or (``verify``) a listed file that is a link, not
    a regular file, or whose sha256 differs from the manifest's.
    """
    root = Path(golden_dir)
    path = root / "manifest.json"
    if not path.is_file() and not path.is_symlink():
        raise GoldenError(f"{root} is not a golden directory: {path} not found")
    with open_regular(path, GoldenError, "manifest") as fh:
        manifest = _read_json(fh, path, GoldenError)
    try:
        check_version(manifest, kind="refraster.golden", supported=MANIFEST_SCHEMA_VERSION,
                      oldest=MANIFEST_SCHEMA_OLDEST, what=str(path))
        for where, rel in _manifest_paths(manifest):
            _inside(root, rel, f"{path} {where}")
        validate(manifest, MANIFEST_SCHEMA)
    except SchemaError as exc:
        raise GoldenError(str(exc) if str(exc).startswith(str(path)) else f"{path}: {exc}") \
            from None
    except RecursionError:
        raise GoldenError(f"{path}: JSON nested too deeply") from None
    for where, rel in _manifest_paths(manifest):
        if rel not in manifest["files"]:
            raise GoldenError(f"{path} {where}: {rel!r} is not listed in $.files")
    for name, entry in manifest["scenes"].items():
        for key, spec in entry["buffers"].items():
            _check_shape_size(spec["shape"], f"{path} $.scenes.{name}.buffers.{key}")
        for full, spec in entry.get("allowances", {}).get("arrays", {}).items():
            where = f"{path} $.scenes.{name}.allowances.arrays.{full}"
            key = _unprefixed(full)
            if key.startswith("set_") or key == "draw_offsets" or (
                    key.startswith("ldi_") and not key.startswith("ldi_count")) or (
                    key.startswith("cs_") and key != "cs_bg"):
                _check_table_size(spec["shape"], where)
            else:
                _check_shape_size(spec["shape"], where)
    if verify:
        for rel in manifest["files"]:
            open_listed(root, manifest, rel).close()
    for name in manifest["scenes"]:
        check_package(root, manifest, name, verify=False)
    return manifest


def check_package(golden_dir, manifest, scene, *, verify=True):
    """Validate the scene package of ``scene`` and return ``scene.json`` (parsed).

    ``scene.json`` must follow :data:`~refraster.golden.io.schema.SCENE_SCHEMA` (a version this
    refraster reads), carry the scene's name and technique, have the viewport of the golden's
    buffers, and every mesh and map it names must be listed in the manifest's ``files``
    (whose sha256 ``verify`` checks again). Raises :class:`GoldenError`.
    """
    root = Path(golden_dir)
    entry = manifest["scenes"][scene]
    rel = entry["package"]
    where = root / rel
    with open_listed(root, manifest, rel, verify=verify) as fh:
        doc = _read_json(fh, where, GoldenError)
    try:
        check_version(doc, kind="refraster.scene", supported=SCENE_SCHEMA_VERSION,
                      what=str(where))
        validate(doc, SCENE_SCHEMA)
    except SchemaError as exc:
        raise GoldenError(str(exc) if str(exc).startswith(str(where)) else f"{where}: {exc}") \
            from None
    except RecursionError:
        raise GoldenError(f"{where}: JSON nested too deeply") from None
    if doc["name"] != scene:
        raise GoldenError(f"{where} $.name: {doc['name']!r} is not the scene's name {scene!r}")
    if doc["technique"] != entry["technique"]:
        raise GoldenError(f"{where} $.technique: {doc['technique']!r} differs from the "
                          f"manifest's {entry['technique']!r}")
    size = [doc["viewport"]["height"], doc["viewport"]["width"]]
    for key, spec in entry["buffers"].items():
        if spec["shape"][:2] != size:
            raise GoldenError(f"{where} $.viewport: {size[1]}x{size[0]} does not match buffer "
                              f"{key!r} of shape {spec['shape']}")
    base = rel.rsplit("/", 1)[0] + "/" if "/" in rel else ""
    named = [(f"$.draws[{i}].mesh", d["mesh"]) for i, d in enumerate(doc["draws"])]
    named += [(f"$.maps.{k}.{kind}", m[kind]) for k, m in doc["maps"].items()
              for kind in ("npy", "png")]
    for jpath, target in named:
        full = base + target
        if full not in manifest["files"]:
            raise GoldenError(f"{where} {jpath}: {target!r} is not listed in the manifest's "
                              "files; refusing to use it")
        if verify:
            open_listed(root, manifest, full).close()
    for i, d in enumerate(doc["draws"]):
        with open_listed(root, manifest, base + d["mesh"], verify=False) as fh:
            _check_ply_header(fh, root / (base + d["mesh"]), d, f"{where} $.draws[{i}]")
    for key, m in doc["maps"].items():
        with open_listed(root, manifest, base + m["npy"], verify=False) as fh:
            shape, _, dtype = _npy_header(fh, root / (base + m["npy"]), GoldenError)
        if list(shape) != m["shape"] or str(dtype) != m["dtype"]:
            raise GoldenError(f"{where} $.maps.{key}: {m['dtype']} {m['shape']} but "
                              f"{m['npy']} holds {dtype} {list(shape)}")
    return doc


def _check_ply_header(fh, path, draw, where):
    """The PLY a draw names: binary little-endian, its vertex and face counts those of
    ``scene.json`` (header only, at most 4 KiB read)."""
    head = fh.read(4096)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise GoldenError(f"{path}: not a PLY file with a header of at most 4 KiB")
    lines = head[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in [ln.strip() for ln in lines]:
        raise GoldenError(f"{path}: not a binary little-endian PLY")
    counts = {}
    for ln in lines:
        parts = ln.split()
        if len(parts) == 3 and parts[0] == "element" and parts[2].isdigit():
            counts[parts[1]] = int(parts[2])
    got = (counts.get("vertex"), counts.get("face"))
    if got != (draw["n_vertices"], draw["n_faces"]):
        raise GoldenError(f"{where}: n_vertices {draw['n_vertices']}, n_faces "
                          f"{draw['n_faces']} but {path.name} declares {got[0]} vertices and "
                          f"{got[1]} faces")


# --- kept scenes (generate --update) ------------------------------------------------------------

def copy_listed_scene(golden_dir, manifest, scene, dest):
    """Copy the files of ``scene`` that the manifest lists from ``golden_dir`` into ``dest``
    (same relative paths), never following a link and checking each sha256 on the bytes
    copied. Files or links under the scene's directory that the manifest does not list are
    skipped and named in a warning (logger ``refraster.golden``). Returns the paths copied."""
    root, dest = Path(golden_dir), Path(dest)
    prefix = f"{scene}/"
    listed = sorted(rel for rel in manifest["files"] if rel.startswith(prefix))
    copied = []
    for rel in listed:
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        with open_listed(root, manifest, rel, verify=False) as src, open(target, "xb") as dst:
            h = hashlib.sha256()
            for block in iter(lambda: src.read(1 << 20), b""):
                h.update(block)
                dst.write(block)
        if h.hexdigest() != manifest["files"][rel]:
            raise GoldenError(f"golden file {root / rel} does not match its sha256 in the "
                              "manifest (corrupt or edited); not copying it")
        copied.append(rel)
    unlisted = []
    top = root / scene
    if top.is_dir() and not top.is_symlink():
        for dirpath, dirnames, filenames in os.walk(top, followlinks=False):
            here = Path(dirpath)
            for d in dirnames:
                if (here / d).is_symlink():
                    unlisted.append((here / d).relative_to(root).as_posix())
            for f in filenames:
                rel = (here / f).relative_to(root).as_posix()
                if rel not in manifest["files"]:
                    unlisted.append(rel)
    if unlisted:
        log.warning("kept scene %s: skipped %d file(s) the manifest does not list: %s", scene,
                    len(unlisted), ", ".join(sorted(unlisted)))
    return copied


# --- arrays: headers first ------------------------------------------------------------------------

_ACCEPTED_KINDS = "fiub"   # float, signed, unsigned, bool: no objects, strings or records


def _npy_header(fh, where, error):
    """(shape, fortran_order, dtype) from an ``.npy`` stream, reading only the header."""
    try:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy format version {version}")
    except (ValueError, EOFError, OSError, SyntaxError, zipfile.BadZipFile, zlib.error) as exc:
        raise error(f"cannot read {where}: not an .npy array ({exc})") from None
    if dtype.hasobject:
        raise error(f"cannot read {where}: object arrays are not accepted (no pickle)")
    if dtype.kind not in _ACCEPTED_KINDS or dtype.fields is not None or dtype.subdtype \
            or dtype.itemsize > 8:
        raise error(f"cannot read {where}: dtype {dtype} is not a plain number or bool")
    return tuple(shape), fortran, dtype


def _read_data(fh, shape, fortran, dtype, where, error):
    """The array's data: exactly ``prod(shape)·itemsize`` bytes, then end of stream."""
    count = int(np.prod(shape, dtype=np.int64)) if shape else 1
    out = np.empty(count, dtype)
    view = memoryview(out).cast("B")
    got = 0
    try:
        while got < len(view):
            n = fh.readinto(view[got:])
            if not n:
                raise error(f"cannot read {where}: truncated ({got} of {len(view)} data bytes)")
            got += n
        if fh.read(1):
            raise error(f"cannot read {where}: data continues past the array its header "
                        "describes")
    except (OSError, EOFError, zipfile.BadZipFile, zlib.error, RuntimeError) as exc:
        raise error(f"cannot read {where}: {type(exc).__name__}: {exc}") from None
    return out.reshape(shape, order="F" if fortran else "C")


def read_npy(fh, where, error, accept=None):
    """Read one ``.npy`` stream; ``accept(shape, dtype)`` (raising ``error``) is called on the
    header before any data is read."""
    shape, fortran, dtype = _npy_header(fh, where, error)
    if accept is not None:
        accept(shape, dtype)
    return _read_data(fh, shape, fortran, dtype, where, error)


#: Most members of an ``.npz`` read (a golden's ``tolerance.npz`` has a few dozen).
MAX_NPZ_MEMBERS = 1024
#: Largest central directory of an ``.npz`` read (its member names, bytes).
MAX_NPZ_DIRECTORY = 1 << 20

_EOCD = struct.Struct("<4s4H2LH")           # end of central directory record
_EOCD64_LOCATOR = struct.Struct("<4sLQL")
_EOCD64 = struct.Struct("<4sQ2H2L4Q")       # zip64 end of central directory record


def _zip_directory_size(fh, where, error):
    """``(members, central directory bytes)`` from a zip's end records (at most 64 KiB and
    a few bytes read), so that a directory of 200,000 members is refused before ``zipfile``
    builds it; ``None`` without an end record."""
    try:
        end = fh.seek(0, os.SEEK_END)
        tail_len = min(end, _EOCD.size + 0xFFFF + _EOCD64_LOCATOR.size)
        fh.seek(end - tail_len)
        tail = fh.read(tail_len)
        i = tail.rfind(b"PK\x05\x06")
        if i < 0 or len(tail) - i < _EOCD.size:
            return None
        _, _, _, _, members, size, _, _ = _EOCD.unpack_from(tail, i)
        j = i - _EOCD64_LOCATOR.size
        if j >= 0 and tail[j:j + 4] == b"PK\x06\x07":     # zip64: the counts are there
            _, _, at, _ = _EOCD64_LOCATOR.unpack_from(tail, j)
            fh.seek(at)
            record = fh.read(_EOCD64.size)
            if len(record) == _EOCD64.size and record[:4] == b"PK\x06\x06":
                fields = _EOCD64.unpack(record)
                members, size = fields[7], fields[8]
        fh.seek(0)
    except (OSError, ValueError, struct.error) as exc:
        raise error(f"cannot read {where}: {type(exc).__name__}: {exc}") from None
    return members, size


def read_npz(fh, where, error, accept):
    """Read the members of an ``.npz`` stream that ``accept`` knows.

    ``accept(key)`` returns ``None`` for a member to skip (unread), else a function
    ``check(shape, dtype)`` called on the member's ``.npy`` header before its data is
    decompressed. Only stored and deflated members are read (what NumPy writes). Refused
    (``error``) before any member is read: more than :data:`MAX_NPZ_MEMBERS` members or a
    central directory over :data:`MAX_NPZ_DIRECTORY` bytes, and a member stored twice
    (``depth.npy`` twice, or ``depth`` and ``depth.npy``: readers disagree on which one
    counts). Returns ``(arrays, skipped member names)``.
    """
    found = _zip_directory_size(fh, where, error)
    if found is None:
        raise error(f"cannot read {where}: not an .npz archive (no end of central directory "
                    "record: truncated, or not a zip file)")
    members, size = found
    if members > MAX_NPZ_MEMBERS or size > MAX_NPZ_DIRECTORY:
        raise error(f"cannot read {where}: {members} members in a central directory of "
                    f"{size} bytes (at most {MAX_NPZ_MEMBERS} members and "
                    f"{MAX_NPZ_DIRECTORY >> 20} MiB are read)")
    try:
        zf = zipfile.ZipFile(fh)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise error(f"cannot read {where}: not an .npz archive ({type(exc).__name__}: "
                    f"{exc})") from None
    arrays, skipped = {}, []
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_NPZ_MEMBERS:
            raise error(f"cannot read {where}: {len(infos)} members (at most "
                        f"{MAX_NPZ_MEMBERS} are read)")
        seen = set()
        for info in infos:
            key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            if key in seen:
                raise error(f"cannot read {where}: member {key!r} is stored twice (readers "
                            "disagree on which copy counts); refusing the archive")
            seen.add(key)
        for info in infos:
            key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            check = accept(key)
            if check is None:
                skipped.append(info.filename)
                continue
            member = f"{where}:{key}"
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise error(f"cannot read {member}: compression method {info.compress_type} "
                            "(only stored or deflated members are read)")
            if info.flag_bits & 0x1:
                raise error(f"cannot read {member}: encrypted")
            try:
                stream = zf.open(info)
            except (zipfile.BadZipFile, OSError, RuntimeError, NotImplementedError) as exc:
                raise error(f"cannot read {member}: {type(exc).__name__}: {exc}") from None
            with stream:
                arrays[key] = read_npy(stream, member, error, check)
    return arrays, skipped


def some_names(names, limit=10, width=80):
    """``names`` joined for one line: the first ``limit`` (each cut to ``width`` characters),
    then how many more."""
    names = list(names)
    shown = [n if len(n) <= width else n[:width - 1] + "…" for n in names[:limit]]
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(shown) + more


def _expect(spec, what, error, where):
    """A header check: the manifest's exact shape and dtype (golden files)."""
    def check(shape, dtype):
        if list(shape) != spec["shape"] or str(dtype) != spec["dtype"]:
            raise error(f"golden {where}: {what} does not match the manifest "
                        f"({spec['dtype']} {spec['shape']}; the file has {dtype} "
                        f"{list(shape)})")
    return check


def _golden_npz(root, manifest, rel, specs, kind):
    with open_listed(root, manifest, rel, verify=False) as fh:
        arrays, _ = read_npz(fh, rel, GoldenError,
                             lambda key: (_expect(specs[key], f"{kind} {key!r}", GoldenError,
                                                  rel) if key in specs else None))
    missing = [k for k in specs if k not in arrays]
    if missing:
        raise GoldenError(f"golden {rel}: {kind}(s) {missing} listed in the manifest are "
                          "missing")
    return arrays


def reference_buffers(golden_dir, manifest, name):
    """The golden buffers of scene ``name`` (the ones its manifest entry lists)."""
    entry = manifest["scenes"][name]
    return _golden_npz(Path(golden_dir), manifest, entry["buffers_file"], entry["buffers"],
                       "buffer")


def allowance_arrays(golden_dir, manifest, name):
    """The allowance arrays (``tolerance.npz``) of scene ``name``."""
    entry = manifest["scenes"][name]
    spec = entry["allowances"]
    arrays = _golden_npz(Path(golden_dir), manifest, spec["file"], spec["arrays"], "array")
    for key, b in entry["buffers"].items():
        t = b.get("tolerant", {})
        needed = _needed(key, t)
        if "sample" in t:   # a multisampled golden's buffer reads its sample's arrays
            needed = [f"s{t['sample']}_{n}" for n in needed]
        missing = [n for n in needed if n not in arrays]
        if missing:
            raise GoldenError(f"golden {spec['file']}: buffer {key!r} needs arrays {missing}")
    from ..allowances.core import check_face_sets
    shape = next(iter(entry["buffers"].values()))["shape"] if entry["buffers"] else [0, 0]
    samples = sorted({b["tolerant"]["sample"] for b in entry["buffers"].values()
                      if "sample" in b.get("tolerant", {})})
    try:
        for sub in [arrays] + [{k[len(f"s{s}_"):]: v for k, v in arrays.items()
                                if k.startswith(f"s{s}_")} for s in samples]:
            check_face_sets(sub, shape[0], shape[1])
        from ..allowances.layers import check_layer_arrays
        check_layer_arrays(arrays, shape[0], shape[1])
        from ..allowances.clip import check_clip_arrays
        check_clip_arrays(arrays, shape[0], shape[1])
    except (ValueError, KeyError) as exc:
        raise GoldenError(f"golden {spec['file']}: {exc}") from None
    return arrays


_SAMPLE_PREFIX = re.compile(r"^s[0-9]{1,2}_")


def _unprefixed(name):
    """An allowance array's name without a multisampled golden's sample prefix ``s<s>_``."""
    return _SAMPLE_PREFIX.sub("", name, count=1)


def _needed(key, t):
    """The allowance arrays a buffer's ``tolerant`` entry ``t`` reads."""
    needed = [t[k] for k in ("lo", "hi", "angle", "may", "zero") if k in t]
    needed += ["id_may"] + (["coverage"] if "coverage" in t.get("checks", ()) else [])
    if "face" in t.get("checks", ()):
        needed += ["set_offsets", "set_face", "set_facing", "set_normal",
                   "set_normal_angle", "draw_offsets"]
        needed += [n for pair in _SET_INTERVAL_NAMES for n in pair]
    if "layers" in t.get("checks", ()):
        from ..allowances.layers import LAYER_ARRAYS
        needed += list(LAYER_ARRAYS)
    if "clip" in t.get("checks", ()):
        from ..allowances.clip import CLIP_ARRAYS, CLIP_VALUES
        needed += list(CLIP_ARRAYS)
        if key in CLIP_VALUES:   # the values of the entries the candidate names
            needed += list(CLIP_VALUES[key]) + ["golden_face", "golden_object",
                                                "face_sliver"]
    return needed


_SET_INTERVAL_NAMES = (("set_depth_lo", "set_depth_hi"), ("set_eye_depth_lo", "set_eye_depth_hi"),
                       ("set_barycentric_lo", "set_barycentric_hi"),
                       ("set_color_lo", "set_color_hi"))


# --- the candidate -------------------------------------------------------------------------------

_FLOAT_KINDS = ("unorm", "snorm", "float", "color")


def _candidate_accept(scene, key, spec, source):
    """Header check of a candidate array: the golden's shape and a dtype its kind takes."""
    shape, kind = tuple(spec["shape"]), spec["kind"]
    where = f"candidate {source} ({scene}/{key})"

    def check(got_shape, dtype):
        if tuple(got_shape) != shape:
            raise CandidateError(f"{where}: shape {tuple(got_shape)} differs from the golden's "
                                 f"{shape}")
        if kind in _FLOAT_KINDS and dtype.kind != "f":
            raise CandidateError(f"{where}: expected floating-point values ({kind}), got "
                                 f"{dtype}")
        if kind == "id" and dtype.kind not in "iu":
            raise CandidateError(f"{where}: expected integer ids, got {dtype}")
        if kind == "bool" and dtype.kind not in "iub":
            raise CandidateError(f"{where}: expected bool (or integer 0/1), got {dtype}")
    return check


def _check_candidate(scene, key, spec, a, source):
    kind = spec["kind"]
    where = f"candidate {source} ({scene}/{key})"
    if a.dtype == object:
        raise CandidateError(f"{where}: object arrays are not accepted")
    _candidate_accept(scene, key, spec, source)(a.shape, a.dtype)
    if kind == "bool" and a.dtype != np.bool_:
        a = a != 0  # values other than 0/1 fail the domain check on the raw array
    return a


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}


def png_header(fh, where, error):
    """``(height, width, channels, bit depth)`` from a PNG's ``IHDR`` chunk (33 bytes read)."""
    head = fh.read(33)
    if len(head) < 33 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise error(f"cannot use {where}: not a PNG file")
    width, height, depth, colour = struct.unpack(">IIBB", head[16:26])
    if colour not in _PNG_CHANNELS or depth not in (1, 2, 4, 8, 16):
        raise error(f"cannot use {where}: PNG colour type {colour} / bit depth {depth} is not "
                    "valid")
    return height, width, _PNG_CHANNELS[colour], depth


def _candidate_file(path, error, what):
    """Open a candidate file: a regular file, no link followed."""
    return open_regular(path, error, what)


def _exists(path):
    try:
        os.lstat(path)
    except OSError:
        return False
    return True


#: The file in a candidate's scene directory that states the candidate's sample pattern (a
#: multisampled golden's candidate: ``{"samples": S, "positions": [[x, y], ...]}``).
PATTERN_FILE = "sample_pattern.json"


def load_candidate(candidate_dir, scene, specs, skipped=None):
    """Candidate buffers of ``scene``: ``{key: (array, source, step, raw)}``; ``step`` is the
    PNG quantisation step (0 for exact files), ``raw`` the array as sent (before integer bools
    became bools, for the domain checks). Headers are read first: a shape or dtype the golden
    does not expect is refused before any data is decompressed. ``.npz`` members the golden
    does not have are not read; their names are appended to ``skipped`` (a list) and logged.
    No link is followed: not the scene's directory, not a file in it. Raises
    :class:`CandidateError`."""
    from .buffers import png_decode
    base = Path(candidate_dir) / scene
    try:
        linked = stat.S_ISLNK(os.lstat(base).st_mode)
    except OSError:
        linked = False      # missing: each buffer is then named as missing
    if linked:
        raise CandidateError(f"candidate scene directory {base} is a symbolic link; links are "
                             "never followed")
    npz = base / "buffers.npz"
    packed = {}
    if _exists(npz):
        source = f"{scene}/buffers.npz"
        with _candidate_file(npz, CandidateError, "candidate file") as fh:
            packed, extra = read_npz(
                fh, f"candidate {source}", CandidateError,
                lambda key: (_candidate_accept(scene, key, specs[key], f"{source}:{key}")
                             if key in specs else None))
        if extra:
            log.warning("candidate %s: skipped %d member(s) the golden does not have (not "
                        "read): %s", source, len(extra), some_names(extra))
            if skipped is not None:
                skipped.extend(f"{source}:{m}" for m in extra)
    out = {}
    for key, spec in specs.items():
        if key in packed:
            a, source, step = packed[key], f"{scene}/buffers.npz:{key}", 0.0
        elif _exists(base / f"{key}.npy"):
            source, step = f"{scene}/{key}.npy", 0.0
            with _candidate_file(base / f"{key}.npy", CandidateError, "candidate file") as fh:
                a = read_npy(fh, f"candidate {source}", CandidateError,
                             _candidate_accept(scene, key, spec, source))
        elif _exists(base / f"{key}.png"):
            source = f"{scene}/{key}.png"
            img = _read_png(base / f"{key}.png", source, spec)
            try:
                a, step = png_decode(img, spec["kind"], spec["shape"])
            except ValueError as exc:
                raise CandidateError(f"cannot use candidate {source}: {exc}") from None
        else:
            looked = [f"{scene}/buffers.npz", f"{scene}/{key}.npy", f"{scene}/{key}.png"]
            raise CandidateError(f"candidate buffer {scene}/{key} is missing (looked for "
                                 f"{', '.join(looked)} in {candidate_dir})")
        a = np.asarray(a)
        out[key] = (_check_candidate(scene, key, spec, a, source), source, step, a)
    return out


def _read_png(path, source, spec):
    """Decode a PNG candidate after checking its IHDR against the golden's shape."""
    import imageio.v3 as iio
    from PIL import Image
    shape = tuple(spec["shape"])
    with _candidate_file(path, CandidateError, "candidate file") as fh:
        height, width, channels, depth = png_header(fh, f"candidate {source}", CandidateError)
        if (height, width) != shape[:2]:
            raise CandidateError(f"cannot use candidate {source}: the PNG is {width}x{height}, "
                                 f"the golden's buffer {shape[1]}x{shape[0]}; not decoding it")
        fh.seek(0)
        try:
            return iio.imread(fh, extension=".png", index=0)
        except (OSError, ValueError, SyntaxError, Image.DecompressionBombError, MemoryError,
                zlib.error) as exc:
            raise CandidateError(f"cannot use candidate {source}: {type(exc).__name__}: "
                                 f"{exc}") from None
