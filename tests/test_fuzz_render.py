"""Fuzz harness of ``refraster.render`` (issue 48, docs/reliability.md "Fuzz harness").

Hypothesis draws whole calls: one or two small meshes (degenerate faces, coordinates up to
±1e38, NaN, indices out of range), a camera (``look_at`` and a perspective or orthographic
projection, each possibly scaled by a hostile factor — 1e-46 … 1e38, 0, −1, NaN — or a raw
4×4 of random numbers), models, viewports (0, negative, too large, not an int), raster states
(valid and not) and backgrounds. Every case must end in exactly one of:

* one clear error line: ``ValueError`` or ``TypeError`` with a one-line message (any other
  exception, a warning, or a message over several lines fails);
* a frame satisfying the stated properties:

  1. **coverage inside the faces**: every covered pixel's centre lies inside the window-space
     box of its visible face, projected independently here in float64 (faces whose three
     corners have w > 0: clipping only keeps a part of the triangle, whose projection stays
     inside the triangle's), widened by one pixel, and — for a face of a pixel's area or more
     — within a quarter pixel of the projected triangle itself; both widened by a bound of the
     float32 vertex stage's and the float64 clipper's rounding;
  2. **render = draw + resolve + from_fragments**: ``render`` (the fused tile path) gives the
     bytes of every buffer, the colour included, of ``Framebuffer.from_fragments(draw(...),
     resolve(...))`` (the fragment stream);
  3. **threads do not matter**: the frame's digest is the same on one thread (this process,
     ``REFRASTER_THREADS=1``) and on two (a worker process started once with
     ``NUMBA_NUM_THREADS=2 REFRASTER_THREADS=2``: every kernel splits its work), for every
     successful case.

CI runs ``FUZZ_EXAMPLES`` (200) examples per test, derandomized (tests/conftest.py's profile);
the long tier is ``REFRASTER_FUZZ_EXAMPLES=10000 python -m pytest tests/test_fuzz_render.py``
(docs/testing.md). At the end of a run the counts of each outcome are printed (``-s``)."""

from __future__ import annotations

import collections
import hashlib
import json
import math
import os
import re
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import refraster as rf

FB_FIELDS = ("depth", "eye_depth", "normal", "prim_id", "object_id", "front_facing",
             "barycentric", "color")
FUZZ_EXAMPLES = int(os.environ.get("REFRASTER_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=FUZZ_EXAMPLES, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])
#: Outcomes of this run, printed at the end (docs/reliability.md keeps the last long run's).
COUNTS = collections.Counter()

# ---------------------------------------------------------------------------------------------
# Strategies

HOSTILE_SCALES = [2.0 ** -66, 1e-20, 1e-29, 1e-31, 1e-35, 1e-40, 1e-46, 2.0 ** 60, 1e30,
                  1e38, 0.0, -1.0, math.nan, math.inf]


def _mostly(good, bad, one_in=6):
    """``good``, except one draw in ``one_in`` from ``bad``."""
    # (the middle value: Hypothesis favours the ends of a range)
    return st.integers(0, one_in - 1).flatmap(lambda k: bad if k == one_in // 2 else good)


scales = _mostly(st.just(1.0), st.sampled_from(HOSTILE_SCALES), 5)
plain = st.floats(-1.5, 1.5, allow_nan=False)
hostile = st.one_of(plain, st.sampled_from([0.0, 1e-30, -1e-30, 1e30, -1e30, 1e38, -1e38,
                                            1e300, math.nan]))


@st.composite
def meshes(draw):
    """Up to 7 vertices and 6 faces (repeated corners: degenerate faces); one mesh in eight
    has hostile coordinates (±1e30, ±1e38, 1e300, NaN) and indices (−1, V)."""
    bad = draw(st.integers(0, 7)) == 0
    coord = hostile if bad else plain
    nv = draw(_mostly(st.integers(3, 7), st.integers(0, 2), 8))
    v = draw(st.lists(st.tuples(coord, coord, coord), min_size=nv, max_size=nv))
    vertices = np.array(v, np.float64).reshape(nv, 3)
    nf = draw(_mostly(st.integers(1, 6), st.just(0), 8))
    hi = max(nv - 1, 0)
    index = st.one_of(st.integers(0, hi), st.integers(0, hi), st.sampled_from([-1, nv])) \
        if bad else st.integers(0, hi)
    any_face = st.tuples(index, index, index)   # repeated corners: degenerate
    face = any_face if bad or nv < 3 else _mostly(
        st.lists(st.integers(0, hi), min_size=3, max_size=3, unique=True), any_face, 4)
    f = draw(st.lists(face, min_size=nf, max_size=nf))
    faces = np.array(f, np.int64).reshape(nf, 3)
    return vertices, faces


def _eye():
    return st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(1.0, 6))


@st.composite
def cameras(draw):
    """A camera to build in the call (its own errors are the call's): usually ``look_at`` and
    a perspective or orthographic projection looking at the meshes, one of them scaled by a
    hostile factor sometimes; rarely raw random matrices (NaN included)."""
    if draw(st.integers(0, 15)) == 0:
        raw = st.lists(st.one_of(st.floats(-4, 4), st.sampled_from([0.0, math.nan, 1e300])),
                       min_size=16, max_size=16)
        return dict(raw=(draw(raw), draw(raw)))
    cam = dict(eye=draw(_eye()),
               target=draw(st.one_of(st.just((0.0, 0.0, 0.0)),
                                     st.tuples(*[st.floats(-1, 1)] * 3))),
               up=draw(st.sampled_from([(0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])))
    if draw(st.booleans()):
        near = draw(_mostly(st.floats(0.01, 1), st.sampled_from([1e-12, 1e-40]), 8))
        cam["perspective"] = (
            draw(_mostly(st.floats(5, 120), st.sampled_from([1e-30, 179.99]), 8)),
            draw(st.floats(0.25, 4)), near,
            near * draw(_mostly(st.floats(1.5, 1000), st.sampled_from([1.0 + 1e-9, 1e12]), 8)))
    else:
        s = draw(st.floats(0.5, 8))
        cam["orthographic"] = (-s, s, -s, s, 0.1, draw(st.floats(2, 50)))
    cam["scaled"] = draw(st.sampled_from(["view", "proj"]))
    cam["scale"] = draw(scales)
    return cam


def _camera(cam):
    """``(view, proj)`` of a :func:`cameras` draw (``look_at`` and the projections may
    refuse it: a one-line ValueError like any other)."""
    if "raw" in cam:
        return (np.array(cam["raw"][0], np.float64).reshape(4, 4),
                np.array(cam["raw"][1], np.float64).reshape(4, 4))
    view = rf.look_at(list(cam["eye"]), list(cam["target"]), cam["up"])
    proj = (rf.perspective(*cam["perspective"]) if "perspective" in cam
            else rf.orthographic(*cam["orthographic"]))
    with np.errstate(all="ignore"):   # 1e38 · a matrix may overflow: the call refuses it
        if cam["scaled"] == "view":
            view = view * cam["scale"]
        else:
            proj = proj * cam["scale"]
    return view, proj


sizes = _mostly(st.one_of(st.integers(8, 40), st.integers(8, 40), st.integers(1, 7)),
                st.sampled_from([0, -3, (1 << 15) + 1, 2.0, "8", True]), 12)
states = _mostly(
    st.one_of(st.none(), st.builds(
        rf.RasterState,
        depth_func=_mostly(st.sampled_from(["less", "lequal", "always"]),
                           st.sampled_from(["greater", "gequal", "never", "equal",
                                            "notequal"]), 3),
        clear_depth=_mostly(st.just(1.0), st.sampled_from([0.0, 0.5]), 3),
        cull=st.sampled_from(["none", "back", "front"]),
        front_face=st.sampled_from(["ccw", "cw"]),
        subpixel_bits=st.sampled_from([8, 4]),
        fill_rule=st.sampled_from(["llvmpipe", "top-left"]),
        precision=st.sampled_from(["float32", "float64"]),
        normals=st.sampled_from(["flat", "smooth"]))),
    st.sampled_from([dict(cull="sideways"), dict(subpixel_bits=5),
                     dict(clear_depth=math.nan)]), 12)
backgrounds = _mostly(st.one_of(st.just((1.0, 1.0, 1.0)), st.tuples(*[st.floats(0, 1)] * 3)),
                      st.just((math.nan, 0.0, 0.0)), 16)


@st.composite
def calls(draw):
    n = draw(st.integers(1, 2))
    ms = [draw(meshes()) for _ in range(n)]
    camera = draw(cameras())
    model = draw(st.sampled_from([None, None, "scaled", "moved", "moved"]))
    if model == "scaled":
        with np.errstate(all="ignore"):   # inf · 0: NaN entries, which the call refuses
            model = [np.eye(4) * draw(scales) for _ in range(n)]
    elif model == "moved":
        model = []
        for _ in range(n):
            m = np.eye(4)
            m[:3, 3] = draw(st.tuples(*[st.floats(-1, 1)] * 3))
            model.append(m)
    return dict(meshes=ms, camera=camera, width=draw(sizes), height=draw(sizes),
                model=model, raster=draw(states), background=draw(backgrounds))


# ---------------------------------------------------------------------------------------------
# Running a call

def _state(raster):
    return rf.RasterState(**raster) if isinstance(raster, dict) else raster


def _render(call):
    view, proj = _camera(call["camera"])
    return rf.render(call["meshes"], view=view, proj=proj, width=call["width"],
                     height=call["height"], model=call["model"], raster=_state(call["raster"]),
                     background=call["background"])


def _reference(call):
    """draw + resolve + Framebuffer.from_fragments: the fragment stream's frame."""
    state = _state(call["raster"])
    view, proj = _camera(call["camera"])
    frags = rf.draw(call["meshes"], view=view, proj=proj, width=call["width"],
                    height=call["height"], model=call["model"], raster=state)
    return rf.Framebuffer.from_fragments(frags, rf.resolve(frags, raster=state), raster=state,
                                         background=call["background"])


def _outcome(fn, call):
    """``("frame", fb)`` or ``("error", message)``; anything else fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")   # a warning is not a clear line
        try:
            return "frame", fn(call)
        except (ValueError, TypeError) as exc:
            text = str(exc)
            assert text and "\n" not in text, f"not one line: {type(exc).__name__}: {text!r}"
            return "error", f"{type(exc).__name__}: {text}"


def _digest(fb):
    h = hashlib.sha256()
    for f in FB_FIELDS:
        h.update(getattr(fb, f).tobytes())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------
# Property 1: coverage inside the projected faces' boxes (independent float64 projection)

def outside_boxes(fb, call):
    """The covered pixels whose centre lies outside their visible face as projected here
    (float64), widened by a rounding bound: ``[(row, col, object, prim)]``. Outside the face's
    window-space box, or — when the projected face has an area of a pixel or more — more than
    a quarter pixel plus the bound outside one of its edges (the snapped edges are within
    1/32 pixel of the true ones)."""
    h, w = fb.depth.shape
    state = _state(call["raster"]) or rf.RasterState()
    unit = 2.0 ** -21 if state.precision == "float32" else 2.0 ** -48
    meshes = call["meshes"]
    models = call["model"] if call["model"] is not None else [np.eye(4)] * len(meshes)
    bad = []
    rows, cols = np.nonzero(fb.prim_id >= 0)
    with np.errstate(all="ignore"):
        for r, c in zip(rows, cols):
            k, p = int(fb.object_id[r, c]), int(fb.prim_id[r, c])
            vertices, faces = meshes[k]
            mvp = fb.proj @ fb.view @ models[k]
            hv = np.c_[vertices[faces[p]], np.ones(3)]
            clip = hv @ mvp.T                               # (3, 4) float64
            wv = clip[:, 3]
            if not (np.all(np.isfinite(clip)) and np.all(wv > 0)):
                continue                                    # crosses the eye plane: no box
            mag = np.abs(hv) @ np.abs(mvp).T                # each coordinate's size
            err = unit * mag + 2.0 ** -50 * mag.max()       # vertex stage + clipper
            ndc = clip[:, :2] / wv[:, None]
            dn = (err[:, :2] + np.abs(ndc) * err[:, 3:4]) / wv.min()
            win = (ndc * 0.5 + 0.5) * (w, h)
            bound = dn.max(axis=0) * (w, h) + 2.0 ** -18 * (np.abs(win).max(axis=0) + (w, h))
            if not np.all(np.isfinite(bound)):
                continue
            centre = np.array([c + 0.5, (h - 1 - r) + 0.5])   # GL window y is up
            lo, hi = win.min(axis=0) - 1.0 - bound, win.max(axis=0) + 1.0 + bound
            if not (np.all(lo <= centre) and np.all(centre <= hi)):
                bad.append((int(r), int(c), k, p))
                continue
            e1, e2 = win[1] - win[0], win[2] - win[0]
            area = e1[0] * e2[1] - e1[1] * e2[0]
            if abs(area) < 2.0:                              # a sliver: the box only
                continue
            slack = 0.25 + float(np.hypot(*bound))
            for i in range(3):
                a_, b_ = win[i], win[(i + 1) % 3]
                edge = b_ - a_
                d = (edge[0] * (centre[1] - a_[1]) - edge[1] * (centre[0] - a_[0]))
                d = np.sign(area) * d / np.hypot(*edge)     # > 0 inside
                if d < -slack:
                    bad.append((int(r), int(c), k, p))
                    break
    return bad


# ---------------------------------------------------------------------------------------------
# Property 3: the same frame on two threads (a worker process)

WORKER = textwrap.dedent("""
    import hashlib, json, sys
    import numpy as np
    import refraster as rf
    FIELDS = {fields!r}
    for line in sys.stdin:
        c = json.loads(line)
        meshes = [(np.array(v, np.float64).reshape(-1, 3), np.array(f, np.int64).reshape(-1, 3))
                  for v, f in c["meshes"]]
        model = None if c["model"] is None else [np.array(m) for m in c["model"]]
        raster = None if c["raster"] is None else rf.RasterState(**c["raster"])
        fb = rf.render(meshes, view=np.array(c["view"]), proj=np.array(c["proj"]),
                       width=c["width"], height=c["height"], model=model, raster=raster,
                       background=tuple(c["background"]))
        h = hashlib.sha256()
        for f in FIELDS:
            h.update(getattr(fb, f).tobytes())
        print(h.hexdigest(), flush=True)
""").format(fields=FB_FIELDS)


@pytest.fixture(scope="module")
def two_threads():
    env = dict(os.environ, NUMBA_NUM_THREADS="2", REFRASTER_THREADS="2")
    proc = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env)

    def digest(call):
        state = _state(call["raster"])
        line = json.dumps(dict(
            meshes=[(v.tolist(), f.tolist()) for v, f in call["meshes"]],
            view=_camera(call["camera"])[0].tolist(), proj=_camera(call["camera"])[1].tolist(),
            width=call["width"],
            height=call["height"],
            model=None if call["model"] is None else [m.tolist() for m in call["model"]],
            raster=None if state is None else {
                f: getattr(state, f) for f in state.__dataclass_fields__},
            background=list(call["background"])))
        proc.stdin.write(line + "\n")
        proc.stdin.flush()
        answer = proc.stdout.readline().strip()
        assert answer, "the two-thread worker stopped"
        return answer

    yield digest
    proc.stdin.close()
    proc.wait(60)
    proc.stdout.close()


@pytest.fixture(scope="module", autouse=True)
def report_counts():
    yield
    if COUNTS:
        print("\nfuzz outcomes:", dict(sorted(COUNTS.items())))


# ---------------------------------------------------------------------------------------------
# The harness

@FUZZ
@given(call=calls())
def test_render_ends_in_one_line_or_a_frame_with_its_properties(call, two_threads):
    old = os.environ.get("REFRASTER_THREADS")
    os.environ["REFRASTER_THREADS"] = "1"
    try:
        kind, got = _outcome(_render, call)
        ref_kind, ref = _outcome(_reference, call)
    finally:
        if old is None:
            del os.environ["REFRASTER_THREADS"]
        else:
            os.environ["REFRASTER_THREADS"] = old
    if kind == "error":
        COUNTS["error"] += 1
        COUNTS["error: " + re.sub(r"\d+", "N", " ".join(got.split()[1:4]))] += 1
        # the fragment stream refuses the same call (it validates the same inputs)
        assert ref_kind == "error", f"render refused ({got}) but draw drew"
        return
    assert ref_kind == "frame", f"render drew but draw + resolve refused: {ref}"
    COUNTS["frame"] += 1
    COUNTS["frame, covered"] += bool(got.mask.any())
    # 1. coverage inside the projected faces' boxes
    bad = outside_boxes(got, call)
    assert not bad, f"covered pixels outside their projected face: {bad[:5]}"
    # 2. render == draw + resolve + from_fragments, every buffer
    diff = [f for f in FB_FIELDS if getattr(got, f).tobytes() != getattr(ref, f).tobytes()]
    assert not diff, f"render differs from draw + resolve + from_fragments in {diff}"
    # 3. one thread and two threads
    assert two_threads(call) == _digest(got), "one and two threads differ"
    COUNTS["frame, two threads checked"] += 1


def test_the_box_property_sees_a_frame_drawn_off_its_faces():
    """The coverage check itself, on a frame moved by 3 pixels (the property must see it)."""
    verts = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.5, 0.0]])
    camera = dict(eye=(0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0),
                  perspective=(40.0, 1.0, 0.5, 10.0), scaled="view", scale=1.0)
    call = dict(meshes=[(verts, np.array([[0, 1, 2]]))], camera=camera, width=32, height=32,
                model=None, raster=None, background=(1.0, 1.0, 1.0))
    fb = _render(call)
    assert fb.mask.any() and not outside_boxes(fb, call)
    moved = _render(dict(call, meshes=[(verts + [0.6, 0.0, 0.0], np.array([[0, 1, 2]]))]))
    assert outside_boxes(moved, call)
