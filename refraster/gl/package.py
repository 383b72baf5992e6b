"""Reading one scene package of a golden directory (``docs/golden-schema.md``).

Standard library and NumPy only: a backend in another language does the same with its own JSON
and PLY readers. Every problem is a :class:`PackageError` (a ``ValueError``) naming the file and
the key; nothing in the package is trusted (sizes are bounded, paths must stay inside the
package directory, no pickles).
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np

__all__ = ["PackageError", "read_scene", "read_ply", "read_map", "matrix", "conventions",
           "CONVENTION_DEFAULTS", "edges_options", "edges_npr_options", "edges_near_far",
           "edges_supports", "CUTAWAY_VARIANTS", "cutaway_step_schedule", "cutaway_options",
           "cutaway_supports", "cutaway_feature_segments", "cutaway_ghost_lines",
           "halos_options", "halos_supports", "halos_prepare", "halos_paper_split",
           "halos_screen_bounds", "halos_frame"]

#: The API-convention fields of ``scene.json``'s ``"raster"`` (issue 39) and their values when
#: a package leaves them out (OpenGL's: a package written before they existed).
CONVENTION_DEFAULTS = {"depth_range": "negative_one_to_one", "origin": "lower_left",
                       "ndc_y": "up", "depth_clamp": False, "depth_format": "float32"}
_CONVENTION_VALUES = {"depth_range": ("negative_one_to_one", "zero_to_one"),
                      "origin": ("lower_left", "upper_left"), "ndc_y": ("up", "down"),
                      "depth_clamp": (False, True),
                      "depth_format": ("float32", "unorm24", "unorm16")}

#: Largest ``scene.json`` read.
MAX_SCENE_BYTES = 16 << 20
#: Largest PLY read.
MAX_PLY_BYTES = 1 << 31
_SEGMENT = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")


class PackageError(ValueError):
    """A scene package this backend cannot use; the message names the file and key."""


def _inside(package_dir, rel, where):
    if not isinstance(rel, str) or not rel or not all(_SEGMENT.match(s) for s in rel.split("/")):
        raise PackageError(f"{where}: {rel!r} is not a plain relative path")
    path = Path(package_dir) / rel
    real, root = os.path.realpath(path), os.path.realpath(package_dir)
    if os.path.commonpath([real, root]) != root:
        raise PackageError(f"{where}: {rel!r} leaves the package directory")
    return path


def _read_bytes(path, limit, what):
    """The bytes of ``path``: a regular file (checked before the open and on the descriptor),
    no link followed, never blocking on a FIFO, at most ``limit`` bytes."""
    import stat
    try:
        st = os.lstat(path)
        if stat.S_ISLNK(st.st_mode):
            raise PackageError(f"cannot open {what} {path}: a symbolic link (links are not "
                               "followed)")
        if not stat.S_ISREG(st.st_mode):
            raise PackageError(f"{what} {path} is not a regular file")
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise PackageError(f"cannot open {what} {path}: {exc.strerror or exc}") from None
    with os.fdopen(fd, "rb") as fh:
        fst = os.fstat(fh.fileno())
        if not stat.S_ISREG(fst.st_mode) or (fst.st_dev, fst.st_ino) != (st.st_dev, st.st_ino):
            raise PackageError(f"{what} {path} is not a regular file")
        if fst.st_size > limit:
            raise PackageError(f"{what} {path} is larger than {limit} bytes")
        data = fh.read()
    if len(data) > limit:
        raise PackageError(f"{what} {path} is larger than {limit} bytes")
    return data


def matrix(value, where):
    """A 4×4 row-major nested list of finite numbers → float64 (4, 4)."""
    try:
        m = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise PackageError(f"{where} must be a 4x4 list of numbers") from None
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise PackageError(f"{where} must be a 4x4 list of finite numbers")
    return m


def _multisample(path, raster, parameters):
    """A multisampled scene's fields (technique ``msaa``): ``raster.samples`` and the pattern
    it declares (``parameters.sample_pattern``: the count and ``[x, y]`` positions in 1/16
    pixel, y down from the pixel's upper-left corner), consistent with each other."""
    samples = raster.get("samples", 1)
    if samples not in (2, 4, 8, 16):
        raise PackageError(f"{path}: an msaa scene's raster.samples must be one of 2, 4, 8, 16, "
                           f"got {samples!r}")
    p = (parameters or {}).get("sample_pattern") if isinstance(parameters, dict) else None
    pos = p.get("positions") if isinstance(p, dict) else None
    if (not isinstance(pos, list) or p.get("samples") != samples or len(pos) != samples
            or not all(isinstance(q, list) and len(q) == 2
                       and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 15
                               for c in q) for q in pos)):
        raise PackageError(f"{path}: an msaa scene's parameters.sample_pattern must give "
                           f"samples = raster.samples ({samples}) and as many [x, y] positions "
                           "(integers 0..15)")


def read_scene(package_dir):
    """``scene.json`` of ``package_dir`` as a dict, with the fields this backend relies on
    checked (schema, version, viewport, camera matrices, raster state, draws)."""
    path = Path(package_dir) / "scene.json"
    raw = _read_bytes(path, MAX_SCENE_BYTES, "scene file")
    huge = []

    def parse_int(text):        # past the int-string conversion limit: found by key below
        try:
            return int(text)
        except ValueError:
            huge.append(len(text.lstrip("-")))
            return huge

    try:
        scene = json.loads(raw.decode("utf-8"), parse_int=parse_int,
                           parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    except RecursionError:
        raise PackageError(f"{path}: not valid JSON (nested too deeply)") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise PackageError(f"{path}: not valid JSON ({exc})") from None
    if huge:
        stack, key = [(scene, "")], None
        while key is None and stack:
            node, at = stack.pop()
            if node is huge:
                key = at.lstrip(".") or "the document"
            elif isinstance(node, dict):
                stack.extend(reversed([(v, f"{at}.{k}") for k, v in node.items()]))
            elif isinstance(node, list):
                stack.extend(reversed([(v, f"{at}[{i}]") for i, v in enumerate(node)]))
        raise PackageError(f"{path}: {key} is an integer of {huge[0]} digits, beyond the "
                           "int-string conversion limit")
    if not isinstance(scene, dict) or scene.get("schema") != "refraster.scene":
        raise PackageError(f"{path}: schema is not 'refraster.scene'")
    if scene.get("schema_version") != 1:
        raise PackageError(f"{path}: schema_version {scene.get('schema_version')!r} is not 1, "
                           "the version this backend reads")
    try:
        vp = scene["viewport"]
        w, h = vp["width"], vp["height"]
        if not (isinstance(w, int) and isinstance(h, int) and 1 <= w <= 32768
                and 1 <= h <= 32768):
            raise PackageError(f"{path}: viewport must be integers in 1..32768")
        matrix(scene["camera"]["view"], f"{path}: camera.view")
        matrix(scene["camera"]["projection"], f"{path}: camera.projection")
        raster = scene["raster"]
        for key, allowed in (("cull", ("none", "back", "front")),
                             ("depth_func", ("less", "lequal", "greater", "gequal", "equal",
                                             "notequal", "always", "never")),
                             ("front_face", ("ccw", "cw")), ("normals", ("flat", "smooth"))):
            if raster.get(key) not in allowed:
                raise PackageError(f"{path}: raster.{key} must be one of {list(allowed)}, got "
                                   f"{raster.get(key)!r}")
        for key, allowed in _CONVENTION_VALUES.items():
            value = raster.get(key, CONVENTION_DEFAULTS[key])
            if key == "depth_clamp" and not isinstance(value, bool):
                raise PackageError(f"{path}: raster.depth_clamp must be true or false, got "
                                   f"{value!r}")
            if value not in allowed:
                raise PackageError(f"{path}: raster.{key} must be one of {list(allowed)}, got "
                                   f"{value!r}")
        if scene.get("technique") == "msaa" or (
                scene.get("technique") in ("edges", "cutaway", "clipsurface")
                and raster.get("samples", 1) != 1):
            # msaa scenes (issue 43) and technique scenes per sample (issue 44)
            _multisample(path, raster, scene.get("parameters"))
        elif raster.get("samples", 1) != 1 or raster.get("sample_locations", "standard") \
                != "standard":
            raise PackageError(f"{path}: raster.samples must be 1 for this backend (one sample "
                               f"per pixel), got samples={raster.get('samples', 1)!r}, "
                               f"sample_locations={raster.get('sample_locations', 'standard')!r}")
        cd = raster["clear_depth"]
        if not isinstance(cd, (int, float)) or not 0.0 <= cd <= 1.0:
            raise PackageError(f"{path}: raster.clear_depth must be a number in [0, 1]")
        for i, d in enumerate(scene["draws"]):
            matrix(d["model"], f"{path}: draws[{i}].model")
            _inside(package_dir, d["mesh"], f"{path}: draws[{i}].mesh")
            oid = d["object_id"]
            if not isinstance(oid, int) or isinstance(oid, bool) or not 0 <= oid <= 2 ** 31 - 2:
                raise PackageError(f"{path}: draws[{i}].object_id must be an integer in "
                                   f"0..2147483646 (the id buffers are int32), got "
                                   f"{str(oid)[:40]}")
        sh = scene["shading"]
        for key in ("ambient", "diffuse", "specular", "shininess"):
            if not isinstance(sh[key], (int, float)) or not math.isfinite(sh[key]):
                raise PackageError(f"{path}: shading.{key} must be a finite number")
        if not sh["palette"]:
            raise PackageError(f"{path}: shading.palette is empty")
    except (KeyError, TypeError) as exc:
        raise PackageError(f"{path}: missing or malformed field {exc}") from None
    return scene


def conventions(raster):
    """The API-convention fields of a scene's ``"raster"`` (checked by :func:`read_scene`), with
    :data:`CONVENTION_DEFAULTS` where the package leaves one out → dict."""
    return {k: raster.get(k, v) for k, v in CONVENTION_DEFAULTS.items()}


def read_ply(path, n_vertices=None, n_faces=None):
    """A binary little-endian PLY as the golden export writes it: ``float x y z``
    [``float nx ny nz``], faces ``uchar count, int i0 i1 i2``.

    Returns ``(vertices (V, 3) float32, faces (F, 3) int32, normals (V, 3) float32 or None)``.
    """
    data = _read_bytes(path, MAX_PLY_BYTES, "mesh")
    end = data.find(b"end_header\n", 0, 4096)
    if not data.startswith(b"ply\n") or end < 0:
        raise PackageError(f"mesh {path}: not a PLY file (no header in its first 4 KiB)")
    header = data[:end].decode("ascii", "replace").splitlines()
    body = end + len(b"end_header\n")
    if "format binary_little_endian 1.0" not in header:
        raise PackageError(f"mesh {path}: only binary little-endian PLY is read")
    counts, props, element, face_prop = {}, [], None, None
    for line in header:
        words = line.split()
        if words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
            element = words[1]
            counts[element] = int(words[2])
        elif words[:1] == ["property"] and element == "vertex":
            if words[1:2] != ["float"] or len(words) != 3:
                raise PackageError(f"mesh {path}: vertex property {' '.join(words[1:])} is not "
                                   "'float NAME'")
            props.append(words[2])
        elif words[:1] == ["property"] and element == "face":
            face_prop = words[1:]
    nv, nf = counts.get("vertex", 0), counts.get("face", 0)
    if set(counts) - {"vertex", "face"}:
        raise PackageError(f"mesh {path}: elements other than vertex and face")
    if face_prop is not None and face_prop[:3] not in (["list", "uchar", "int"],
                                                       ["list", "uint8", "int32"]):
        raise PackageError(f"mesh {path}: faces must be 'list uchar int'")
    if n_vertices is not None and (nv, nf) != (n_vertices, n_faces):
        raise PackageError(f"mesh {path}: {nv} vertices and {nf} faces, scene.json says "
                           f"{n_vertices} and {n_faces}")
    need = nv * 4 * len(props) + nf * 13
    if len(data) - body != need:
        raise PackageError(f"mesh {path}: body is {len(data) - body} bytes, the header "
                           f"needs {need}")
    if not {"x", "y", "z"} <= set(props):
        raise PackageError(f"mesh {path}: vertices need x, y and z")
    vdata = np.frombuffer(data, "<f4", nv * len(props), body).reshape(nv, len(props))
    fd = np.frombuffer(data, np.dtype([("n", "u1"), ("i", "<i4", (3,))]), nf,
                       body + vdata.nbytes)
    if nf and not np.all(fd["n"] == 3):
        raise PackageError(f"mesh {path}: only triangles are read")
    faces = np.ascontiguousarray(fd["i"], np.int32)
    if nf and (faces.min() < 0 or faces.max() >= nv):
        raise PackageError(f"mesh {path}: a face index is out of range")
    col = {name: k for k, name in enumerate(props)}
    vertices = np.ascontiguousarray(vdata[:, [col["x"], col["y"], col["z"]]], np.float32)
    normals = (np.ascontiguousarray(vdata[:, [col["nx"], col["ny"], col["nz"]]], np.float32)
               if {"nx", "ny", "nz"} <= set(col) else None)
    if not np.all(np.isfinite(vertices)):
        raise PackageError(f"mesh {path}: a vertex is not finite")
    return vertices, faces, normals


def read_map(package_dir, scene, name):
    """The exact values of map ``name`` (its ``.npy``; no pickles)."""
    where = f"{Path(package_dir) / 'scene.json'}: maps.{name}"
    try:
        rel = scene["maps"][name]["npy"]
    except (KeyError, TypeError):
        raise PackageError(f"{where} is missing") from None
    path = _inside(package_dir, rel, where)
    import io
    try:
        return np.load(io.BytesIO(_read_bytes(path, MAX_PLY_BYTES, "map")), allow_pickle=False)
    except ValueError as exc:
        raise PackageError(f"map {path}: {exc}") from None


# --- the edges technique's parameters (both GPU backends read them so) -------------------------

#: The edge G-buffer's and edge map's formats a package may name (each backend maps them).
EDGE_FORMATS = ("rgba8", "rgba32f", "float32")

NORMAL_FILTERS = {"diagonal": 0, "sobel": 1, "angle": 2}
DEPTH_FILTERS = {"diagonal": 0, "c1": 1, "c1-paper": 2, "sobel": 3, "diagonal2": 4}
#: The presets' option defaults (as the scene may name a preset and override options).
PRESETS = {
    "paper": dict(normal_filter="diagonal", depth_filter="diagonal", ids=False,
                  inner_threshold=0.0, profile_threshold=0.0),
    "clean": dict(normal_filter="diagonal", depth_filter="diagonal2", ids=True,
                  inner_threshold=0.1, profile_threshold=0.03),
}


def _number(v, lo, hi):
    return (not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
            and lo <= v <= hi)


def edges_options(params, where="parameters"):
    """The operator options of a scene's parameters, checked → dict (raises PackageError)."""
    if not isinstance(params, dict):
        raise PackageError(f"{where} must be an object")
    preset = params.get("preset", "paper")
    if preset not in PRESETS:
        raise PackageError(f"{where}.preset must be one of {sorted(PRESETS)}, got {preset!r}")
    opt = dict(PRESETS[preset])
    opt.update({k: params[k] for k in opt if params.get(k) is not None})
    if opt["normal_filter"] not in NORMAL_FILTERS:
        raise PackageError(f"{where}.normal_filter must be one of {sorted(NORMAL_FILTERS)}")
    if opt["depth_filter"] not in DEPTH_FILTERS:
        raise PackageError(f"{where}.depth_filter must be one of {sorted(DEPTH_FILTERS)}")
    if not isinstance(opt["ids"], bool):
        raise PackageError(f"{where}.ids must be true or false")
    for key in ("inner_threshold", "profile_threshold"):
        if not _number(opt[key], 0.0, 1.0):
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
    for key in ("k_n", "k_z"):
        v = params.get(key, 1.0)
        if not _number(v, 0.0, math.inf):
            raise PackageError(f"{where}.{key} must be a finite number >= 0")
        opt[key] = float(v)
    width = params.get("width", 1)
    if isinstance(width, bool) or not isinstance(width, int) or not 1 <= width <= 64:
        raise PackageError(f"{where}.width must be an integer in 1..64")
    opt["width"] = width
    for key in ("gbuffer_format", "output_format"):
        v = params.get(key, "float32")
        if v not in EDGE_FORMATS:
            raise PackageError(f"{where}.{key} must be one of {sorted(EDGE_FORMATS)}, got {v!r}")
        opt[key] = v
    if params.get("npr") is not None:
        opt["npr"] = edges_npr_options(params["npr"], f"{where}.npr")
    return opt


def edges_npr_options(npr, where):
    """The NPR pass's options (style ``gooch``; ``mask`` ``objects``) → dict."""
    if not isinstance(npr, dict) or npr.get("style") != "gooch":
        raise PackageError(f"{where}.style must be 'gooch' (the only style the backends have)")
    if npr.get("mask", "objects") != "objects":
        raise PackageError(f"{where}.mask must be 'objects'")
    light = npr.get("light")
    if not (isinstance(light, list) and len(light) == 3
            and all(_number(c, -math.inf, math.inf) for c in light)) or not any(light):
        raise PackageError(f"{where}.light must be a non-zero direction of 3 numbers")
    out = {"light": (np.array(light, np.float64) / np.linalg.norm(light)).tolist()}
    for key in ("base", "cool", "warm", "background", "inner_color", "profile_color"):
        v = npr.get(key)
        if not (isinstance(v, list) and len(v) == 3 and all(_number(c, 0.0, 1.0) for c in v)):
            raise PackageError(f"{where}.{key} must be 3 numbers in [0, 1]")
        out[key] = [float(c) for c in v]
    for key in ("alpha", "beta"):
        if not _number(npr.get(key), 0.0, 1.0):
            raise PackageError(f"{where}.{key} must be a number in [0, 1]")
        out[key] = float(npr[key])
    return out


def edges_near_far(scene, package_dir=None):
    """Near and far (float64) fitted to ``parameters.bounds`` (the eight corners of the world
    box in eye space; Sec. 4.1.1), or without bounds to the eye-space depth of every vertex of
    the draws; a flat range is widened by a relative 1e-6 (as refraster's ``fit_near_far``)."""
    view = matrix(scene["camera"]["view"], "camera.view")
    bounds = scene.get("parameters", {}).get("bounds")
    if bounds is not None:
        try:
            b = np.array(bounds, np.float64)
        except (TypeError, ValueError):
            b = None
        if b is None or b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
            raise PackageError("parameters.bounds must be [[xmin, ymin, zmin], [xmax, ymax, "
                               "zmax]] of finite numbers")
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        z = -(corners @ view[2, :3] + view[2, 3])
    else:
        zs = []
        for i, d in enumerate(scene["draws"]):
            v, _, _ = read_ply(package_dir / d["mesh"], d.get("n_vertices"), d.get("n_faces"))
            mv = view @ matrix(d["model"], f"draws[{i}].model")
            zs.append(-(v.astype(np.float64) @ mv[2, :3] + mv[2, 3]))
        z = np.concatenate(zs) if zs else np.zeros(0)
        if z.size == 0:
            raise PackageError("edges: no bounds and no vertices to fit near and far to")
    near, far = float(z.min()), float(z.max())
    if not far > near:
        far = near + max(abs(near), 1.0) * 1e-6
    return near, far


def edges_supports(scene):
    """``None`` if the edges scene can be rendered, else the reason."""
    try:
        edges_options(scene.get("parameters", {}))
    except PackageError as exc:
        return f"edges: {exc}"
    return None


#: The clip surfaces either backend draws in one pass (a uniform block of this many).
CLIP_MAX_SURFACES = 2


def clipsurface_supports(scene):
    """``None`` if a backend can draw the clip-surface scene from its package, else the reason:
    mesh caps, the world-space clip test, diffuse caps, 1 to :data:`CLIP_MAX_SURFACES`
    surfaces, and the derived maps a package since issue 25 carries."""
    p = scene.get("parameters", {})
    surfaces = p.get("surfaces") or []
    if p.get("cap_mode", "mesh") != "mesh":
        return f"clipsurface cap_mode {p.get('cap_mode')!r}: only 'mesh' (the exported grid)"
    if p.get("space", "world") != "world" or p.get("evaluation_space", "world") != "world":
        return "clipsurface: only the world-space clip test (space 'world') is implemented"
    if p.get("caps") and p.get("cap_style", "diffuse") != "diffuse":
        return f"clipsurface cap_style {p.get('cap_style')!r}: only 'diffuse'"
    if not 1 <= len(surfaces) <= CLIP_MAX_SURFACES:
        return (f"clipsurface: 1 to {CLIP_MAX_SURFACES} surfaces, the scene has "
                f"{len(surfaces)}")
    if p.get("caps") and ("cap_meshes" not in p or "sprites" not in p
                          or any("normal_map" not in s for s in surfaces)):
        return ("clipsurface: the package lacks the cap meshes, sprites or derived maps "
                "(golden written before issue 25 item 2)")
    return None


# --- the cutaway technique's parameters (both GPU backends read them so) -----------------------

#: The jump-flooding schedules a GPU backend draws (``parameters.variant``).
CUTAWAY_VARIANTS = ("jfa", "jfa+1", "jfa+2", "1+jfa")


def cutaway_step_schedule(height, width, variant):
    """The jump lengths of one flooding run, in order (as refraster.cutaway.flood.step_schedule):
    n/2 … 1 with n the power of two ≥ max(W, H), then 1 (``jfa+1``) or 2, 1 (``jfa+2``), or 1
    first (``1+jfa``)."""
    n = 1
    while n < max(height, width):
        n *= 2
    plain, k = [], n // 2
    while k >= 1:
        plain.append(k)
        k //= 2
    plain = plain or [1]
    return {"jfa": plain, "jfa+1": plain + [1], "jfa+2": plain + [2, 1],
            "1+jfa": [1] + plain}[variant]


def _draw_names(scene, key):
    p = scene.get("parameters", {})
    names = p.get(key)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise PackageError(f"parameters.{key} must be a list of draw names")
    by_name = {d.get("name"): i for i, d in enumerate(scene["draws"])}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise PackageError(f"parameters.{key} names draws {missing} the scene does not have")
    return [by_name[n] for n in names]


def cutaway_options(scene):
    """A cutaway scene's parameters, checked → ``(options, None)``, or ``(None, reason)`` for
    an option the GPU backends do not draw; a malformed one raises PackageError naming it."""
    p = scene.get("parameters", {})
    if not isinstance(p, dict):
        raise PackageError("parameters must be an object")
    opt = {}
    variant = p.get("variant", "jfa")      # Cutaway().variant: the paper's schedule
    if variant not in CUTAWAY_VARIANTS:
        return None, (f"cutaway variant {variant!r}: only the jump-flooding schedules "
                      f"{list(CUTAWAY_VARIANTS)} are implemented")
    opt["variant"] = variant
    for key in ("stand_ins", "cutaway_size", "cut_color"):
        if p.get(key) is not None:
            return None, f"cutaway parameter {key!r} is not implemented by the GPU backends"
    if p.get("ghost", "lines") != "lines":
        return None, "cutaway ghost 'visible' is not implemented (only 'lines')"
    angle = p.get("angle")
    angles = angle if isinstance(angle, list) else [angle]
    if not 1 <= len(angles) <= 8 or not all(
            isinstance(a, (int, float)) and not isinstance(a, bool) and 0 < a < math.pi / 2
            for a in angles):
        raise PackageError("parameters.angle must be a number (or up to 8) in (0, π/2) rad")
    opt["angles"] = [float(a) for a in angles]
    ec = p.get("edge_compression", 0.1)
    if ec is None:
        ec = 0.0
    if isinstance(ec, bool) or not isinstance(ec, (int, float)) or not ec >= 0:
        raise PackageError("parameters.edge_compression must be a number >= 0 or null")
    opt["r"] = float(ec)
    for key, default in (("perspective_compensation", True), ("dilation", True),
                         ("ghost_fade", True), ("outlines", True)):
        v = p.get(key, default)
        if not isinstance(v, bool):
            raise PackageError(f"parameters.{key} must be true or false")
        opt[key] = v
    for key, default in (("ghost_distance", None), ("crease_angle", 30.0)):
        v = p.get(key, default)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                              or not math.isfinite(v) or v < 0):
            raise PackageError(f"parameters.{key} must be a finite number >= 0")
        opt[key] = v
    fn = p.get("floor_normal")
    if fn is not None:
        if not (isinstance(fn, list) and len(fn) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                for c in fn)) or not any(fn):
            raise PackageError("parameters.floor_normal must be 3 finite numbers, not all 0")
        fn = [float(c) for c in fn]
    opt["floor_normal"] = fn
    fm = p.get("floor_margin", math.radians(2.0))
    if isinstance(fm, bool) or not isinstance(fm, (int, float)) or not 0 <= fm <= math.pi / 2:
        raise PackageError("parameters.floor_margin must be a number in [0, π/2] rad")
    opt["floor_margin"] = float(fm)
    opt["interest"] = _draw_names(scene, "interest")
    opt["secondary"] = _draw_names(scene, "secondary")
    return opt, None


def cutaway_supports(scene):
    """``None`` if a GPU backend can draw the cutaway scene, else the reason. The cutaway
    function is stated in OpenGL's NDC depth of a glFrustum- or glOrtho-shaped projection
    (``docs/golden-schema.md``, "Cutaways: what the package carries"): a package must declare
    ``depth_range`` ``negative_one_to_one`` and ``ndc_y`` ``up``."""
    try:
        _, reason = cutaway_options(scene)
    except PackageError as exc:
        return f"cutaway: {exc}"
    if reason is None:
        proj = np.asarray(scene["camera"]["projection"], np.float64)
        if not (np.array_equal(proj[3], [0, 0, -1, 0]) or np.array_equal(proj[3], [0, 0, 0, 1])):
            reason = "cutaway: the projection is neither glFrustum- nor glOrtho-shaped"
    if reason is None:
        raster = scene.get("raster", {})
        if (raster.get("depth_range", "negative_one_to_one") != "negative_one_to_one"
                or raster.get("ndc_y", "up") != "up"):
            reason = ("cutaway: the cutaway function is defined in OpenGL's NDC (depth_range "
                      "'negative_one_to_one', ndc_y 'up'); the scene declares another")
    return reason


def _face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def cutaway_feature_segments(vertices, faces, view, model, ortho, crease_angle):
    """World-space feature lines (N, 2, 3) of one mesh for one view: silhouettes (front and back
    faces meet; front: the CCW normal toward the eye), borders (one face) and creases (dihedral
    angle > crease_angle degrees; for more than two faces the largest), vertices merged by
    exact position first. A GPU team's preprocessing of the ghost lines (Sec. 4.3)."""
    v = np.asarray(vertices, np.float64)
    uniq, inv = np.unique(v, axis=0, return_inverse=True)
    f = inv.reshape(-1)[np.asarray(faces, np.int64)]
    if len(f) == 0:
        return np.zeros((0, 2, 3))
    mv = view @ model
    fn = _face_normals(uniq, f)
    im = np.linalg.inv(mv)
    towards = (np.broadcast_to(im[:3, :3] @ np.array([0.0, 0.0, 1.0]), fn.shape) if ortho
               else im[:3, 3] - uniq[f[:, 0]])
    front = np.einsum("ij,ij->i", fn, towards) > 0.0
    if np.linalg.det(mv[:3, :3]) < 0:
        front = ~front
    nf = len(f)
    pairs = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    face_of = np.tile(np.arange(nf), 3)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    ne = len(edges)
    count = np.bincount(inverse, minlength=ne)
    n_front = np.bincount(inverse, weights=front[face_of], minlength=ne)
    order = np.lexsort((face_of, inverse))
    start = np.cumsum(count) - count
    sf = face_of[order]
    two = count >= 2
    dihedral = np.full(ne, np.nan)
    dihedral[two] = _angle_deg(fn[sf[start[two]]], fn[sf[start[two] + 1]])
    for e in np.flatnonzero(count > 2):
        adj = fn[sf[start[e]:start[e] + count[e]]]
        i, j = np.triu_indices(len(adj), 1)
        dihedral[e] = _angle_deg(adj[i], adj[j]).max()
    with np.errstate(invalid="ignore"):
        crease = dihedral > crease_angle
    silhouette = two & (n_front > 0) & (n_front < count)
    keep = silhouette | (count == 1) | (two & crease)
    seg = uniq[edges[keep]]                                  # object space
    hom = np.concatenate([seg, np.ones(seg.shape[:2] + (1,))], axis=-1)
    return (hom @ model.T)[..., :3]


def cutaway_ghost_lines(scene, package_dir, opt):
    """The ghost lines' world segments (N, 2, 3) of the secondary draws and g_max (eye units;
    default 10 % of the secondary meshes' bounding-box diagonal); none when nothing is carved
    (no secondary draw) or g_max is 0."""
    view = matrix(scene["camera"]["view"], "camera.view")
    proj = matrix(scene["camera"]["projection"], "camera.projection")
    ortho = not np.array_equal(proj[3], [0, 0, -1, 0])
    meshes = []
    for i in opt["secondary"]:
        d = scene["draws"][i]
        v, f, _ = read_ply(package_dir / d["mesh"], d.get("n_vertices"), d.get("n_faces"))
        meshes.append((v, f, matrix(d["model"], f"draws[{i}].model")))
    g_max = opt["ghost_distance"]
    if g_max is None:
        vs = [v.astype(np.float64) for v, _, _ in meshes]
        g_max = 0.0
        if vs:
            v = np.concatenate(vs)
            g_max = 0.1 * float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    if not g_max > 0 or not meshes:
        return np.zeros((0, 2, 3)), float(g_max)
    segs = [cutaway_feature_segments(v, f, view, model, ortho, float(opt["crease_angle"]))
            for v, f, model in meshes]
    return np.concatenate(segs), float(g_max)


# --- the 4D halos' parameters and per-frame setup (both GPU backends read them so) -----------

HALO_RHO_FRACTION = 0.02
HALO_NORMAL_EPS = 1e-6
HALO_AMBIENT = 0.3
HALO_DELTA_MIN = 1e-3
HALO_MAX_SLICES = 4096
HALO_SPLITS = ("paper", "global_index")


def _halo_num(p, key, lo=None, hi=None, default=None):
    v = p.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
            or (lo is not None and v < lo) or (hi is not None and v > hi):
        raise PackageError(f"parameters.{key} must be a finite number"
                           + (f" in [{lo}, {hi}]" if lo is not None and hi is not None else ""))
    return float(v)


def halos_options(scene):
    """A halos4d scene's parameters, checked → ``(options, None)``, or ``(None, reason)`` for an
    option the GPU backends do not draw; a malformed one raises PackageError naming it."""
    p = scene.get("parameters", {})
    if not isinstance(p, dict):
        raise PackageError("parameters must be an object")
    for key in ("stereo", "boundary_color"):
        if p.get(key):
            return None, f"halos4d parameter {key!r} is not implemented by the GPU backends"
    opt = {}
    if p.get("projection") not in ("orthographic", "perspective"):
        raise PackageError("parameters.projection must be 'orthographic' or 'perspective'")
    opt["projection"] = p["projection"]
    slices = p.get("slices")
    if isinstance(slices, bool) or not isinstance(slices, int) \
            or not 1 <= slices <= HALO_MAX_SLICES:
        raise PackageError(f"parameters.slices must be an integer in 1..{HALO_MAX_SLICES}")
    opt["slices"] = slices
    for key in ("width", "height"):
        v = p.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 32768:
            raise PackageError(f"parameters.{key} must be an integer in 1..32768")
        opt[key] = v
    opt["delta_t"] = _halo_num(p, "delta_t", 0.0, 1.0)
    opt["surface_width"] = _halo_num(p, "surface_width", 0.0, 1.0)
    opt["opacity"] = _halo_num(p, "opacity", 0.0, 1.0)
    opt["delta_d"] = _halo_num(p, "delta_d", 0.0, None)
    opt["antialias"] = _halo_num(p, "antialias", 0.0, 1.0, default=opt["surface_width"])
    opt["halo_opacity"] = _halo_num(p, "halo_opacity", 0.0, 1.0, default=0.0)
    opt["scale"] = _halo_num(p, "scale", 0.0, None, default=1.0)
    opt["eye"] = None if p.get("eye") is None else _halo_num(p, "eye")
    opt["rho"] = None if p.get("rho") is None else _halo_num(p, "rho", 0.0, None)
    opt["depth_eps"] = (None if p.get("depth_eps") is None
                        else _halo_num(p, "depth_eps", 0.0, None))
    halos = p.get("halos", True)
    if not isinstance(halos, bool):
        raise PackageError("parameters.halos must be true or false")
    opt["halos"] = halos
    hc = p.get("halo_color", [0.5, 0.5, 0.5])
    bg = p.get("background", [0.0, 0.0, 0.0])
    for key, v in (("halo_color", hc), ("background", bg)):
        if not (isinstance(v, list) and len(v) == 3
                and all(isinstance(c, (int, float)) and math.isfinite(c) for c in v)):
            raise PackageError(f"parameters.{key} must be 3 finite numbers")
    opt["halo_color"], opt["background"] = [float(c) for c in hc], [float(c) for c in bg]
    try:
        rot = np.array(p.get("rotation", np.eye(4).tolist()), np.float64)
    except (TypeError, ValueError):
        rot = None
    if rot is None or rot.shape != (4, 4) or not np.all(np.isfinite(rot)) \
            or not np.allclose(rot @ rot.T, np.eye(4), atol=1e-9, rtol=0):
        raise PackageError("parameters.rotation must be an orthogonal 4x4 matrix")
    opt["rotation"] = rot
    sb = p.get("screen_bounds")
    if sb is not None:
        try:
            sb = np.array(sb, np.float64)
        except (TypeError, ValueError):
            sb = None
        if sb is None or sb.shape != (2, 3) or not np.all(np.isfinite(sb)) \
                or not np.all(sb[1] > sb[0]):
            raise PackageError("parameters.screen_bounds must be [[x0, y0, z0], [x1, y1, z1]]")
    opt["screen_bounds"] = sb
    split = p.get("split", "paper")
    if split not in HALO_SPLITS:
        raise PackageError(f"parameters.split must be one of {list(HALO_SPLITS)}")
    opt["split"] = split
    return opt, None


def halos_supports(scene):
    """``None`` if a GPU backend can draw the halos4d scene, else the reason."""
    try:
        _, reason = halos_options(scene)
    except PackageError as exc:
        return f"halos4d: {exc}"
    return reason


def halos_prepare(vertices4d, faces, tangents, colors, opt):
    """Project, thicken and tetrahedralize (float64) → ``(points (2V + 2K, 3), attr (2V + 2K, 5)
    = (δ, t, r, g, b), tets (T, 4), projected points (V, 3))``, K the vertices inserted by the
    paper's split."""
    f = np.asarray(faces, np.int64)
    f = f[~((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2]))]
    if len(f) == 0:
        raise PackageError("surface has no non-degenerate faces")
    r = opt["rotation"]
    v = np.asarray(vertices4d, np.float64) @ r.T
    t = np.asarray(tangents, np.float64).reshape(len(v), 2, 4) @ r.T
    radius = float(np.abs(v).max()) if v.size else 1.0
    e = 3.0 * max(radius, 1.0 / 3.0) if opt["eye"] is None else opt["eye"]
    depth = e - v[:, 3]
    s = opt["scale"]
    if opt["projection"] == "orthographic":
        pts, t3 = s * v[:, :3], s * t[..., :3]
    else:
        if e <= 0 or np.any(depth <= HALO_DELTA_MIN * e):
            raise PackageError("a vertex is at or behind the 4D eye")
        fl = s * e
        pts = fl * v[:, :3] / depth[:, None]
        t3 = fl * (t[..., :3] * depth[:, None, None] + v[:, None, :3] * t[..., 3:4]) \
            / (depth ** 2)[:, None, None]
    n = np.cross(t3[:, 0], t3[:, 1])
    ln = np.linalg.norm(n, axis=1)
    sc = np.linalg.norm(t3[:, 0], axis=1) * np.linalg.norm(t3[:, 1], axis=1)
    bad = ~(ln > HALO_NORMAL_EPS * sc) | (sc == 0.0)
    normals = np.zeros_like(n)
    normals[~bad] = n[~bad] / ln[~bad, None]
    if bad.any():
        a = pts[f[:, 0]]
        fn = np.cross(pts[f[:, 1]] - a, pts[f[:, 2]] - a)
        acc = np.zeros_like(pts)
        for k in range(3):
            np.add.at(acc, f[:, k], fn)
        fb = acc[bad]
        lf = np.linalg.norm(fb, axis=1)
        ok = lf > 0
        fb[ok] /= lf[ok, None]
        fb[~ok] = (0.0, 0.0, 1.0)
        normals[bad] = fb
    rho = opt["rho"]
    if rho is None:
        diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        rho = HALO_RHO_FRACTION * diag if diag > 0 else 1.0
    verts = np.concatenate([pts - rho * normals, pts + rho * normals])
    tt = np.concatenate([np.zeros(len(pts)), np.ones(len(pts))])
    shade = HALO_AMBIENT + (1.0 - HALO_AMBIENT) * np.abs(normals[:, 2])
    rgb = np.asarray(colors, np.float64) * shade[:, None]
    attr = np.column_stack([np.concatenate([depth, depth]), tt, np.concatenate([rgb, rgb])])
    nv = len(pts)
    if opt.get("split", "paper") == "global_index":
        srt = np.sort(f, axis=1)
        a, b, c = srt[:, 0], srt[:, 1], srt[:, 2]
        tets = np.stack([np.stack([a, b, c, c + nv], 1), np.stack([a, b, c + nv, b + nv], 1),
                         np.stack([a, a + nv, b + nv, c + nv], 1)], 1).reshape(-1, 4)
        return verts, attr, tets, pts, rho
    tets, cyc = halos_paper_split(f, nv)
    if len(cyc):
        def centroids(x):
            lo = (x[cyc[:, 0]] + x[cyc[:, 1]] + x[cyc[:, 2]]) / 3.0
            hi = (x[cyc[:, 0] + nv] + x[cyc[:, 1] + nv] + x[cyc[:, 2] + nv]) / 3.0
            return np.concatenate([x, lo, hi])
        verts, attr = centroids(verts), centroids(attr)
    return verts, attr, tets, pts, rho


def _halo_apex(a, b, c, a1, b1, c1, cb):
    """Prisms whose lower vertex a starts the diagonals to b⁺ and c⁺; side (b, c) split b–c⁺, or
    c–b⁺ where ``cb``: (F, 3, 4)."""
    t0 = np.where(cb[:, None], np.stack([a, b, c, b1], 1), np.stack([a, b, c, c1], 1))
    t1 = np.where(cb[:, None], np.stack([a, b1, c, c1], 1), np.stack([a, b, c1, b1], 1))
    return np.stack([t0, t1, np.stack([a, a1, b1, c1], 1)], 1)


def halos_paper_split(f, nv):
    """Wang et al. Sec. 4.4/5.1: each prism in its face's order (diagonals v0–v1⁺, v1–v2⁺,
    v0–v2⁺), each later prism's diagonal on a shared side flipped to the first prism's, a
    cyclic prism rebuilt as (m, v_k, v_k+1) with its triangles' centroids m, m⁺ (numbered
    2·nv + k and 2·nv + K + k). Returns (tets, the rebuilt prisms' faces)."""
    d = np.zeros((len(f), 3), np.int64)
    d[:, 2] = 1                                  # 0: side k split v_k → v_k+1⁺; 1: the other
    nxt = np.roll(f, -1, axis=1)
    start = np.where(d == 0, f, nxt).ravel()
    key = (np.minimum(f, nxt) * np.int64(nv) + np.maximum(f, nxt)).ravel()
    order = np.lexsort((np.arange(key.size), key))
    first = np.ones(key.size, bool)
    first[1:] = key[order][1:] != key[order][:-1]
    head = order[np.maximum.accumulate(np.where(first, np.arange(key.size), 0))]
    flip = order[start[order] != start[head]]
    d.reshape(-1)[flip] ^= 1
    cyc = (d[:, 0] == d[:, 1]) & (d[:, 1] == d[:, 2])
    ok, cy = np.flatnonzero(~cyc), np.flatnonzero(cyc)
    apex = np.argmax((d[ok] == 0).astype(np.int64) + (np.roll(d[ok], 1, axis=1) == 1), axis=1)
    abc = f[ok[:, None], (apex[:, None] + np.arange(3)) % 3]
    valid = _halo_apex(*abc.T, *(abc + nv).T, d[ok, (apex + 1) % 3] == 1)
    m = 2 * nv + np.arange(len(cy), dtype=np.int64)
    rebuilt = np.concatenate([_halo_apex(m, f[cy, k], f[cy, (k + 1) % 3], m + len(cy),
                                    f[cy, k] + nv, f[cy, (k + 1) % 3] + nv, d[cy, k] == 1)
                              for k in range(3)], axis=1)
    count = np.where(cyc, 9, 3)
    offset = np.concatenate([[0], np.cumsum(count)])
    tets = np.zeros((int(offset[-1]), 4), np.int64)
    tets[(offset[ok][:, None] + np.arange(3)).ravel()] = valid.reshape(-1, 4)
    tets[(offset[cy][:, None] + np.arange(9)).ravel()] = rebuilt.reshape(-1, 4)
    return tets, f[cy]


def halos_screen_bounds(points, width, height, margin):
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo[:2] + hi[:2])
    half = 0.5 * (hi[:2] - lo[:2]) * (1.0 + 2.0 * margin)
    half = np.maximum(half, 1e-9 * max(1.0, float(np.abs(hi).max())))
    if half[0] / half[1] < width / height:
        half[0] = half[1] * width / height
    else:
        half[1] = half[0] * height / width
    zlo, zhi = lo[2], hi[2]
    if not zhi > zlo:
        zlo, zhi = zlo - 0.5, zhi + 0.5
    return np.array([[centre[0] - half[0], centre[1] - half[1], zlo],
                     [centre[0] + half[0], centre[1] + half[1], zhi]])


def halos_frame(scene, package_dir):
    """Everything a GPU backend draws a halos4d scene from, computed per frame on the CPU from
    the package's maps and parameters (``docs/golden-schema.md``, "4D halos: what the package
    carries"): a dict with

    ``data`` (N, 8) float32
        per vertex of the thickened, tetrahedralized surface: NDC x, y of the sliced box
        (glOrtho of ``screen_bounds``' x, y: y up), z − ``z0`` (the slicing axis relative to
        the first plane), δ − δ_ref (4D depth relative to the middle of its range), t, r, g, b;
    ``tets`` (T, 4) int32
        the tetrahedra's global vertex indices;
    ``planes`` (slices,) float64
        the slicing planes' z − ``z0``, back (smallest z) to front: the slab centres;
    ``dz``, ``alpha``, ``halo_alpha``, ``eps``, ``d_range``, ``opt``
        the slab thickness, the surface and halo slice opacities, ε of the occlusion rule, the
        range of δ − δ_ref (for a depth key), the checked options."""
    opt, reason = halos_options(scene)
    if reason is not None:
        raise PackageError(reason)
    v4 = read_map(package_dir, scene, "surface_vertices4d")
    faces = read_map(package_dir, scene, "surface_faces")
    tang = read_map(package_dir, scene, "surface_tangents")
    cols = read_map(package_dir, scene, "surface_colors")
    nv = len(v4)
    if v4.ndim != 2 or v4.shape[1] != 4 or faces.ndim != 2 or faces.shape[1] != 3 \
            or tang.shape != (nv, 8) or cols.shape != (nv, 3) \
            or not np.issubdtype(faces.dtype, np.integer) \
            or (faces.size and (faces.min() < 0 or faces.max() >= nv)):
        raise PackageError("halos4d maps: vertices (V, 4), faces (F, 3) in range, tangents "
                           "(V, 8), colours (V, 3)")
    verts, attr, tets, pts, rho = halos_prepare(v4, faces, tang, cols, opt)
    w, h = opt["width"], opt["height"]
    vw, vh = scene["viewport"]["width"], scene["viewport"]["height"]
    if (w, h) != (vw, vh):
        raise PackageError(f"parameters.width/height {(w, h)} differ from the viewport")
    bounds = opt["screen_bounds"]
    if bounds is None:
        bounds = halos_screen_bounds(verts, w, h, float(scene["parameters"].get("margin", 0.05)))
    n = opt["slices"]
    dz = (bounds[1, 2] - bounds[0, 2]) / n
    centres = bounds[0, 2] + (np.arange(n) + 0.5) * dz
    ws, aa = opt["surface_width"], opt["antialias"]

    def slice_alpha(opacity, width_):
        if opacity >= 1.0:
            return 1.0
        return float(1.0 - (1.0 - opacity) ** (dz / (2.0 * width_ * rho)))
    alpha = slice_alpha(opt["opacity"], ws)
    halo_alpha = (slice_alpha(opt["halo_opacity"], max(1.0 - ws - aa, 1e-6))
                  if opt["halos"] and opt["halo_opacity"] > 0 else 0.0)
    depth = attr[:, 0]
    eps = 1e-6 * float(np.abs(depth).max()) if opt["depth_eps"] is None else opt["depth_eps"]
    d_ref = float(0.5 * (depth.min() + depth.max()))
    rel = attr.copy()
    rel[:, 0] -= d_ref
    # x, y into the NDC of glOrtho(x0, x1, y0, y1)
    sx, sy = 2.0 / (bounds[1, 0] - bounds[0, 0]), 2.0 / (bounds[1, 1] - bounds[0, 1])
    span = bounds[1, :2] - bounds[0, :2]
    mid = (bounds[1, :2] + bounds[0, :2]) / span
    xy = np.stack([sx * verts[:, 0] - mid[0], sy * verts[:, 1] - mid[1]], 1)
    # z relative to the first centre keeps float32 steps fine
    z0 = float(centres[0])
    data = np.concatenate([xy, (verts[:, 2] - z0)[:, None], rel], 1).astype(np.float32)
    return {"data": np.ascontiguousarray(data), "tets": np.ascontiguousarray(tets, np.int32),
            "planes": centres - z0, "dz": float(dz), "alpha": alpha, "halo_alpha": halo_alpha,
            "eps": eps, "d_range": (float(rel[:, 0].min()), float(rel[:, 0].max())),
            "opt": opt}
