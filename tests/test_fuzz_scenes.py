"""Fuzz harness of the command line's inputs (issue 48, docs/reliability.md "The fuzz harness"):
TOML scenes through ``refraster golden generate --scene-file``, and the camera options and
viewports of ``refraster render``, drawn at random with Hypothesis — valid values mostly,
hostile ones sometimes (control characters and 300-character names, viewports of 0, −1,
32,769 or 2.5 pixels, ``near = 1e-300``, ``far = 1e300``, ``fovy = 1e-30``, NaN, wrong TOML
types, unknown keys, meshes with coordinates up to 3e38 and indices out of range).

Every case ends in exactly one of:

* **one clear error line**: exit status 2 and exactly one line on stderr, ``golden generate:
  error: …`` or ``refraster: error: …`` (no traceback), and nothing written (no output
  directory or file, no temporary beside it);
* **a result with its properties**: exit status 0 and

  - ``golden generate``: every covered pixel of the scene's ``buffers.npz`` lies inside the
    window-space box (and, for faces of a pixel or more, the triangle) of its face, projected
    independently in float64 from what the golden stores — ``scene.json``'s view, projection
    and models and the package's PLY meshes (``outside_boxes`` of tests/test_fuzz_render.py);
    and ``compare(golden, golden)`` passes;
  - ``render``: the same coverage property for the G-buffer written by ``--buffers``, with the
    camera the command built (:func:`refraster.cli._camera`) and the mesh file's triangles;
    the PNG is there.

CI runs 50 TOML scenes and 150 option sets (derandomized: tests/conftest.py's profile); the
long tier is ``REFRASTER_FUZZ_EXAMPLES=10000 python -m pytest -q -s tests/test_fuzz_scenes.py``.
The counts of each outcome are printed at the end (``-s``)."""

from __future__ import annotations

import collections
import json
import math
import os
import re
import types
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import refraster as rf
from refraster import cli as rcli
from refraster.golden import cli as gcli

from test_fuzz_render import outside_boxes

#: Examples per test: 50 TOML scenes and 150 option sets by default (a golden takes ~0.4 s);
#: REFRASTER_FUZZ_EXAMPLES sets both.
FUZZ_EXAMPLES = int(os.environ.get("REFRASTER_FUZZ_EXAMPLES", "0")) or None
FUZZ = dict(deadline=None, derandomize=True,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                   HealthCheck.filter_too_much,
                                   HealthCheck.function_scoped_fixture])
COUNTS = collections.Counter()


def _mostly(good, bad, one_in=6):
    """``good``, except one draw in ``one_in`` from ``bad``."""
    # (the middle value: Hypothesis favours the ends of a range)
    return st.integers(0, one_in - 1).flatmap(lambda k: bad if k == one_in // 2 else good)


def _rarely(draw, one_in):
    """True once in ``one_in`` draws (the middle value, as in :func:`_mostly`)."""
    return draw(st.integers(0, one_in - 1)) == one_in // 2


# ---------------------------------------------------------------------------------------------
# TOML, written by hand so that any value (wrong types included) can be drawn

def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)          # JSON's escapes are TOML basic-string escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(type(v))


def toml_text(spec):
    lines = [f"{k} = {_toml_value(v)}" for k, v in spec.items()
             if not isinstance(v, dict) and k != "draw"]
    for table in ("viewport", "camera", "raster", "parameters"):
        if table in spec:
            lines.append(f"[{table}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in spec[table].items()]
    for d in spec.get("draw", ()):
        lines.append("[[draw]]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in d.items()]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Strategies

plain = st.floats(-1.5, 1.5, allow_nan=False)
coordinate = _mostly(plain, st.sampled_from([1e30, -1e30, 3e38, 1e-30, 0.0]), 10)


@st.composite
def obj_meshes(draw):
    """An OBJ file's text: 3–6 vertices, 1–4 faces (an index out of range sometimes)."""
    nv = draw(st.integers(3, 6))
    vertices = [[draw(coordinate) for _ in range(3)] for _ in range(nv)]
    hi = draw(_mostly(st.just(nv), st.just(nv + 2), 12))
    nf = draw(st.integers(1, 4))
    faces = [draw(st.lists(st.integers(1, hi), min_size=3, max_size=3, unique=True))
             for _ in range(nf)]
    return ("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices)
            + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))


names = _mostly(st.from_regex(r"[a-z0-9][a-z0-9_]{0,12}", fullmatch=True),
                st.sampled_from(["cube\n", "Cube", "a" * 300, "a" * 128, "x\ty", "", "x/y",
                                 "caf\u00e9", 42]), 6)
sides = _mostly(st.integers(4, 32), st.sampled_from([0, -1, 32769, 2.5, "8", True]), 10)
vec3 = st.tuples(*[st.floats(-6, 6, allow_nan=False)] * 3).map(list)
#: on the command line: fixed notation (argparse reads "-1e-05" as an option, not a number)
cli_vec3 = st.tuples(*[st.floats(-6, 6, allow_nan=False)] * 3).map(
    lambda v: [f"{x:.6f}" for x in v])
hostile_vec3 = st.sampled_from([[0.0, 0.0, 0.0], [math.nan, 0.0, 1.0], [1e300, 0.0, 0.0],
                                [1.0, 2.0], "up"])


@st.composite
def toml_cameras(draw):
    kind = draw(st.sampled_from(["frame", "frame", "perspective", "orthographic", None,
                                 "fisheye"]))
    cam = {} if kind is None else {"kind": kind}
    eye = draw(_mostly(st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(1.0, 6))
                       .map(list), hostile_vec3, 10))
    near = draw(_mostly(st.floats(0.01, 1.0), st.sampled_from([1e-300, 1e-40, 0.0, -1.0]), 8))
    far = draw(_mostly(st.floats(1.5, 1000).map(lambda k: near * k),
                       st.sampled_from([1e300, near, math.inf, 1e39]), 8))
    fovy = draw(_mostly(st.floats(5, 120), st.sampled_from([1e-30, 1e-38, 179.99, 180.0, 0.0,
                                                            -5.0, math.nan, "wide"]), 8))
    if kind in ("perspective", "orthographic"):
        cam.update(eye=eye, target=draw(_mostly(st.just([0.0, 0.0, 0.0]), vec3, 4)),
                   near=near, far=far)
        if kind == "perspective":
            cam["fovy"] = fovy
        else:
            s = draw(_mostly(st.floats(0.5, 8), st.sampled_from([0.0, 1e-39, 1e39]), 8))
            cam["extent"] = [-s, s, -s, s]
    elif kind == "frame" or kind is None:
        if draw(st.booleans()):
            cam["fovy"] = fovy
        if draw(st.booleans()):
            cam["direction"] = draw(_mostly(vec3, hostile_vec3, 6))
        if _rarely(draw, 6):
            cam["margin"] = draw(st.sampled_from([0.5, 1.1, 0.0, -1.0, 1e300]))
    if _rarely(draw, 8):
        cam["up"] = draw(st.sampled_from([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.8, 1.4]]))
    if _rarely(draw, 16):
        cam["zoom"] = 2.0                       # an unknown key
    return cam


rasters = st.fixed_dictionaries({}, optional={
    "cull": _mostly(st.sampled_from(["none", "back", "front"]), st.just("sideways"), 8),
    "depth_func": _mostly(st.sampled_from(["less", "lequal", "always"]), st.just("lesser"), 8),
    "precision": _mostly(st.sampled_from(["float32", "float64"]), st.just(64), 8),
    "normals": st.sampled_from(["flat", "smooth"]),
    "subpixel_bits": _mostly(st.sampled_from([8, 4]), st.sampled_from([5, -1, 99, 8.0]), 8),
    "clear_depth": _mostly(st.just(1.0), st.sampled_from([0.5, 2.0, math.nan]), 8),
})


@st.composite
def toml_scenes(draw):
    """``(spec, {file name: OBJ text})``: a TOML scene and the mesh files beside it."""
    spec, files = {}, {}
    if draw(st.integers(0, 3)):
        spec["name"] = draw(names)
    vp = {}
    for key in ("width", "height"):
        if draw(st.integers(0, 7)):
            vp[key] = draw(sides)
    spec["viewport"] = vp
    if draw(st.integers(0, 3)):
        spec["camera"] = draw(toml_cameras())
    raster = draw(rasters)
    if raster:
        spec["raster"] = raster
    draws = []
    for i in range(draw(_mostly(st.integers(1, 2), st.just(0), 16))):
        d = {}
        what = draw(st.sampled_from(["mesh", "mesh", "mesh", "solid", "both"]))
        if what in ("mesh", "both"):
            files[f"m{i}.obj"] = draw(obj_meshes())
            d["mesh"] = draw(_mostly(st.just(f"m{i}.obj"),
                                     st.sampled_from([f"m{i}.obj\n", "missing.obj", "..",
                                                      "/dev/null"]), 10))
        if what in ("solid", "both"):
            d["solid"] = draw(_mostly(st.just("cube"), st.just("dodecahedron"), 6))
        if _rarely(draw, 3):
            d["name"] = draw(names)
        if _rarely(draw, 4):
            m = np.eye(4) * draw(_mostly(st.floats(0.25, 2), st.sampled_from(
                [0.0, 1e-20, 1e30, -1.0]), 4))
            m[3, 3] = 1.0
            m[:3, 3] = [draw(st.floats(-1, 1)) for _ in range(3)]
            d["model"] = m.tolist()
        draws.append(d)
    spec["draw"] = draws
    if _rarely(draw, 16):
        spec["technique"] = draw(st.sampled_from(["render", "raytrace"]))
    if _rarely(draw, 21):
        spec["colour"] = "red"                  # an unknown top-level key
    return spec, files


# ---------------------------------------------------------------------------------------------
# Checks

def _one_error_line(err, prefix):
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), f"not one clear line: {err!r}"
    assert "Traceback" not in err and "error: error:" not in err, err
    assert "Warning: " not in lines[0], f"a warning, not a line naming the cause: {err!r}"
    return lines[0]


#: REFRASTER_FUZZ_PROGRESS=FILE: the counts so far, rewritten every 100 cases (a long run that
#: is stopped still says how far it came).
PROGRESS = os.environ.get("REFRASTER_FUZZ_PROGRESS")


def _progress():
    done = COUNTS["error"] + COUNTS["golden"]
    if PROGRESS and done % 100 == 0:
        with open(PROGRESS, "w") as f:
            f.write(f"{done} cases: {dict(sorted(COUNTS.items(), key=lambda kv: -kv[1]))}\n")


def _count(kind, line):
    COUNTS[kind] += 1
    _progress()
    # the error's first words, numbers and paths folded
    words = re.sub(r"/\S+", "PATH", re.sub(r"-?\d[\d.e+-]*", "N", line)).split(": ")
    COUNTS[": ".join(words[2:4])[:80]] += 1


def golden_coverage(golden_dir, scene):
    """``outside_boxes`` for one scene of a golden, from what the golden stores."""
    from refraster.gl.package import read_ply
    package = golden_dir / scene / "package"
    doc = json.loads((package / "scene.json").read_text())
    buffers = np.load(golden_dir / scene / "buffers.npz")
    meshes, models = [], []
    for d in doc["draws"]:
        vertices, faces, _ = read_ply(package / d["mesh"])
        meshes.append((vertices.astype(np.float64), faces.astype(np.int64)))
        models.append(np.array(d["model"], np.float64))
    fb = types.SimpleNamespace(depth=buffers["depth"], prim_id=buffers["prim_id"],
                               object_id=buffers["object_id"],
                               view=np.array(doc["camera"]["view"], np.float64),
                               proj=np.array(doc["camera"]["projection"], np.float64))
    raster = {k: v for k, v in doc["raster"].items() if k in rf.RasterState.__dataclass_fields__}
    call = dict(meshes=meshes, model=models, raster=rf.RasterState(**raster))
    return fb, outside_boxes(fb, call)


@pytest.fixture(scope="module", autouse=True)
def report_counts():
    yield
    if COUNTS:
        print("\nfuzz outcomes:", dict(sorted(COUNTS.items(), key=lambda kv: -kv[1])))


# ---------------------------------------------------------------------------------------------
# The harness: TOML scenes

@settings(max_examples=FUZZ_EXAMPLES or 50, **FUZZ)
@given(scene=toml_scenes())
def test_toml_scene_ends_in_one_line_or_a_golden_with_its_properties(scene, tmp_path_factory,
                                                                     capsys):
    from refraster import golden
    spec, files = scene
    root = tmp_path_factory.mktemp("toml")
    for name, text in files.items():
        (root / name).write_text(text)
    path = root / "scene.toml"
    path.write_text(toml_text(spec))
    work = root / "out"
    work.mkdir()
    out = work / "g"
    capsys.readouterr()
    code = gcli.main(["generate", "--out", str(out), "--scene-file", str(path), "--jobs", "1",
                      "-q"])
    err = capsys.readouterr().err
    if code == 2:
        _count("error", _one_error_line(err, "golden generate: error: "))
        assert os.listdir(work) == [], f"an error left {os.listdir(work)}"
        return
    assert code == 0 and err == "", (code, err)
    manifest = json.loads((out / "manifest.json").read_text())
    (scene_name,) = manifest["scenes"]
    fb, bad = golden_coverage(out, scene_name)
    assert not bad, f"covered pixels outside their projected face: {bad[:5]}"
    COUNTS["golden, covered"] += bool((fb.prim_id >= 0).any())
    COUNTS["golden"] += 1
    _progress()
    for mode in (None, "tolerant"):   # its own mode, and within its allowances
        assert golden.compare(out, out, mode=mode).exit_code == 0, (
            f"the golden does not pass against itself (mode {mode})")


# ---------------------------------------------------------------------------------------------
# The harness: refraster render's camera options and viewports

def _num(x):
    return x if isinstance(x, str) else repr(x)


option_floats = st.sampled_from([math.nan, math.inf, 1e300, 1e-300, 0.0, -1.0])
cli_sides = _mostly(st.integers(4, 40), st.sampled_from(["0", "-3", "32769", "2.5", "x"]), 10)


@st.composite
def render_argvs(draw):
    argv = ["--width", str(draw(cli_sides)), "--height", str(draw(cli_sides))]
    for option in ("--eye", "--target", "--up"):
        if _rarely(draw, 4):
            v = draw(_mostly(cli_vec3, st.tuples(option_floats, plain, plain).map(
                lambda t: [_num(t[0]), f"{t[1]:.6f}", f"{t[2]:.6f}"]), 5))
            argv += [option, *v]
    if draw(st.booleans()):
        argv += ["--fov", _num(draw(_mostly(st.floats(5, 120).map(lambda f: round(f, 4)), st.sampled_from(
            [1e-30, 1e-38, 179.999, 180.0, 0.0, math.nan]), 6)))]
    near = None
    if _rarely(draw, 3):
        near = draw(_mostly(st.floats(0.01, 2.0).map(lambda f: round(f, 6)), option_floats, 5))
        argv += ["--near", _num(near)]
    if _rarely(draw, 3):
        base = near if isinstance(near, float) and math.isfinite(near) and near > 0 else 1.0
        argv += ["--far", _num(draw(_mostly(st.floats(1.5, 1000).map(lambda k: base * k),
                                            option_floats, 5)))]
    argv += ["--cull", draw(st.sampled_from(["none", "back", "front"])),
             "--normals", draw(st.sampled_from(["flat", "smooth"]))]
    return argv


@settings(max_examples=FUZZ_EXAMPLES or 150, **FUZZ)
@given(mesh=obj_meshes(), options=render_argvs())
def test_render_options_end_in_one_line_or_a_frame_with_its_properties(mesh, options,
                                                                       tmp_path_factory, capsys):
    from refraster.mesh import load_mesh_file
    root = tmp_path_factory.mktemp("render")
    path = root / "m.obj"
    path.write_text(mesh)
    work = root / "out"
    work.mkdir()
    argv = ["render", str(path), "--out", str(work / "x.png"), "--buffers",
            str(work / "x.npz"), *options, "-q"]
    capsys.readouterr()
    code = rcli.main(argv)
    err = capsys.readouterr().err
    if code == 2:
        _count("render error", _one_error_line(err, "refraster: error: "))
        assert os.listdir(work) == [], f"an error left {os.listdir(work)}"
        return
    assert code == 0 and err == "", (code, err)
    assert sorted(os.listdir(work)) == ["x.npz", "x.png"]
    args = rcli._build_parser().parse_args(argv)
    m = load_mesh_file(path)
    view, proj = rcli._camera(args, m.bounds)
    buffers = np.load(work / "x.npz")
    fb = types.SimpleNamespace(depth=buffers["depth"], prim_id=buffers["prim_id"],
                               object_id=buffers["object_id"], view=view, proj=proj)
    call = dict(meshes=[(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))],
                model=None, raster=rf.RasterState(cull=args.cull, normals=args.normals))
    bad = outside_boxes(fb, call)
    assert not bad, f"covered pixels outside their projected face: {bad[:5]}"
    COUNTS["render frame"] += 1
    COUNTS["render frame, covered"] += bool((fb.prim_id >= 0).any())


def test_the_golden_coverage_check_sees_a_moved_camera(tmp_path):
    """The property itself must fail on a golden whose stored camera is not the one it was
    rendered with (the view moved by a third of the frame)."""
    (tmp_path / "m.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "s.toml").write_text('[viewport]\nwidth = 32\nheight = 24\n[[draw]]\n'
                                     'mesh = "m.obj"\n')
    out = tmp_path / "g"
    assert gcli.main(["generate", "--out", str(out), "--scene-file", str(tmp_path / "s.toml"),
                      "--jobs", "1", "-q"]) == 0
    fb, bad = golden_coverage(out, "s")
    assert (fb.prim_id >= 0).any() and not bad
    scene = out / "s" / "package" / "scene.json"
    doc = json.loads(scene.read_text())
    doc["camera"]["view"][0][3] += 0.6
    scene.write_text(json.dumps(doc))
    assert golden_coverage(out, "s")[1]
