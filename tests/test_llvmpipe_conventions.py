"""refraster against Mesa's llvmpipe (OpenGL 4.5) in the API conventions of issue 39, item 3's
llvmpipe half: ``glClipControl(GL_UPPER_LEFT, GL_ZERO_TO_ONE)`` (Direct3D's, Metal's and
WebGPU's frame), Vulkan's ``ndc_y="down"`` (through GL a negation of the clip y in the vertex
shader: GL's NDC y points up), reversed-Z float32 with an infinite far plane, ``GL_DEPTH_CLAMP``,
and the depth formats WebGPU cannot read back (``GL_DEPTH_COMPONENT24``) or that lavapipe checks
through WebGPU too (``GL_DEPTH_COMPONENT16``).

The scenes, the clip coordinates, the exact referee, the depth allowance and the verdict are
``tests/test_lavapipe_oracle.py``'s (held-out scenes of seed 3939 and two crossing z = 0 and the
eye plane); only the outside renderer changes: ``oracles.llvmpipe`` with its conventions, not
refraster.gl (written separately from the backend it judges). Per convention, over the counted
scenes: prim-id agreement ≥ 99.99 % of covered pixels (ties within 1/128 px of an edge and pixels
the referee decides against llvmpipe not held against refraster), facing equal where the ids
agree, window depth within the allowance there (plus 0.6 of a quantum of the depth format).

llvmpipe's fill rule under ``GL_UPPER_LEFT``: measured here (:func:`test_fill_rule_under_
upper_left`) — the same as under ``GL_LOWER_LEFT`` as the picture is seen (left edges and the
horizontal edges at the bottom of the picture: Mesa's GL state tracker flips its edge rule with
the origin), so refraster runs with its ``fill_rule="llvmpipe"`` in every convention here.

Both directions: :func:`test_planted_convention_faults_are_caught` runs refraster with a
convention planted wrong and the same verdict fails. Skips locally without moderngl/EGL, fails
under ``CI=true`` (``conftest.require``). ``test_agreement_table_in_docs`` holds the table of
docs/backends.md to this run (``docs/scripts/convention_agreement_tables.py`` rewrites it).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import refraster as rf
import test_lavapipe_oracle as L
from conftest import require
from refraster.conformance import DEPTH_EPS

_UL = dict(depth_range="zero_to_one", origin="upper_left", fill_rule="llvmpipe")

#: name → Convention (test_lavapipe_oracle's: refraster's state, the projection, the oracle's
#: keywords — here :class:`_GL`'s, which names the GL state)
CONVENTIONS = {c.name: c for c in (
    L.Convention("gl_upper_left_zero_to_one", rf.RasterState(ndc_y="up", **_UL),
                 L.zero_to_one, dict(ndc_y="up", origin="upper_left",
                                     depth_range="zero_to_one")),
    L.Convention("gl_vulkan_ndc_y_down", rf.RasterState(ndc_y="down", **_UL), L.zero_to_one,
                 dict(ndc_y="down", origin="upper_left", depth_range="zero_to_one")),
    L.Convention("gl_reversed_z_infinite",
                 rf.RasterState(ndc_y="up", depth_func="greater", clear_depth=0.0, **_UL),
                 L.reversed_infinite,
                 dict(ndc_y="up", origin="upper_left", depth_range="zero_to_one",
                      depth_compare="greater", clear_depth=0.0)),
    L.Convention("gl_depth_clamp", rf.RasterState(ndc_y="up", depth_clamp=True, **_UL),
                 L.zero_to_one, dict(ndc_y="up", origin="upper_left",
                                     depth_range="zero_to_one", unclipped_depth=True)),
)}
#: depth formats checked (convention, depth_format)
FORMATS = [("gl_upper_left_zero_to_one", "unorm24"), ("gl_upper_left_zero_to_one", "unorm16"),
           ("gl_reversed_z_infinite", "unorm24")]


class _GL:
    """``oracles.llvmpipe`` behind the interface ``test_lavapipe_oracle.compare`` drives
    (``clip_positions``, ``rasterize`` → prim ids numbered over the draws, depth, facing)."""

    def __init__(self, llvmpipe):
        self.llvmpipe = llvmpipe
        self.clip_positions = llvmpipe.clip_positions
        self.outside = 0      #: covered pixels whose depth buffer holds a depth outside [0, 1]

    def rasterize(self, draws, width, height, *, ndc_y="up", origin="lower_left",
                  depth_range="negative_one_to_one", depth_compare="less", clear_depth=1.0,
                  unclipped_depth=False, depth_format="float32"):
        fr = self.llvmpipe.rasterize(draws, width, height, conventions=dict(
            ndc_y=ndc_y, origin=origin, depth_range=depth_range, depth_func=depth_compare,
            clear_depth=clear_depth, depth_clamp=unclipped_depth, depth_format=depth_format))
        offsets = np.cumsum([0] + [len(f) for _, f in draws])
        prim = np.where(fr.mask, offsets[np.maximum(fr.object_id, 0)] + fr.prim_id, -1)
        # the candidate's depth is its depth buffer: quantised under the unorm formats, and
        # clamped to [0, 1] by GL — llvmpipe's gl_FragCoord.z is not, under GL_DEPTH_CLAMP nor
        # a few ulp past an edge clipped at z = 0 (−6.8e-6 measured in 05-near_crossing_near1)
        depth = fr.depth_buffer
        self.outside += int(np.count_nonzero(fr.mask & ((depth < 0) | (depth > 1))))
        return SimpleNamespace(prim_id=prim.astype(np.int32), depth=depth,
                               front=fr.front_facing, mask=prim >= 0)


_ORACLE: list = []


def _gl():
    if not _ORACLE:
        _ORACLE.append(_GL(require("oracles.llvmpipe")))
    return _ORACLE[0]


def depth_allowance(tri, width, height, ndc_y):
    """``test_lavapipe_oracle.depth_allowance`` (docs/tolerance.md, "Conventions": relative,
    so reversed-Z's small depths keep their precision), and for a face the near or the eye
    plane clips at least refraster.conformance's ``DEPTH_EPS`` (4e-5): that model's
    conditioning κ is the unclipped face's (1 for a face reaching behind the eye), while
    llvmpipe sets the plane up from the clipped piece — measured 1.35× the relative allowance
    (8.4e-6) on one pixel of ``19-slivers`` under Vulkan's conventions, a face through the eye
    plane."""
    a = L.depth_allowance(tri, width, height, ndc_y)
    t = tri.astype(np.float64)
    clipped = (t[:, 3] <= 0).any() or (t[:, 2] < 0).any() or (t[:, 2] > t[:, 3]).any()
    return max(a, DEPTH_EPS) if clipped else a


def compare(sc, conv, gl, **kw):
    return L.compare(sc, conv, gl, allowance=depth_allowance, **kw)


_RESULTS: dict = {}


def _results(name, gl):
    if name not in _RESULTS:
        conv = CONVENTIONS[name]
        _RESULTS[name] = [compare(sc, conv, gl) for sc in L.SCENES]
    return _RESULTS[name]


@pytest.mark.parametrize("name", list(CONVENTIONS))
def test_agreement_with_llvmpipe(name):
    gl = _gl()
    results = [r for r, sc in zip(_results(name, gl), L.SCENES) if L.counted(sc)]
    ok, agreement, why = L._check(results)
    assert ok, f"{name}: " + "; ".join(why)
    assert sum(r.covered for r in results) > 50_000
    assert gl.outside == 0


@pytest.mark.parametrize("name, depth_format", FORMATS)
def test_depth_formats(name, depth_format):
    """``GL_DEPTH_COMPONENT24`` / ``16``: llvmpipe's depth buffer (k / (2^n − 1)) lies within
    the float allowance plus 0.6 of a quantum of refraster's float32 depth; ids may differ only
    where the quantisation merges two surfaces or at edge ties."""
    gl = _gl()
    conv = CONVENTIONS[name]
    for sc in L.SCENES[:13]:
        if not L.counted(sc):
            continue
        r = compare(sc, conv, gl, state=conv.state.replace(depth_format=depth_format),
                    depth_format=depth_format)
        assert r.depth_over == 0 and r.facing == 0, r
        assert r.unexplained <= max(0.01 * r.covered, 2), r


def test_fill_rule_under_upper_left():
    """The lattice scene (every edge through pixel centres, nothing clipped): under either
    origin llvmpipe agrees with refraster's ``llvmpipe`` rule (bottom-left as the picture is
    seen) on every pixel and not with ``top-left`` (300 pixels differ): the rule does not
    change with the origin as the picture is seen."""
    llvmpipe = require("oracles.llvmpipe")
    w, h = 64, 32
    clip, faces = L._lattice_scene(w, h, "up")
    for origin in ("upper_left", "lower_left"):
        fr = llvmpipe.rasterize([(clip, faces)], w, h, conventions=dict(
            origin=origin, depth_range="zero_to_one"))
        for fill, agree in (("llvmpipe", True), ("top-left", False)):
            st = rf.RasterState(depth_range="zero_to_one", origin=origin, fill_rule=fill)
            frags = rf.rasterize(clip.astype(np.float64), faces, w, h, raster=st)
            res = rf.resolve(frags, raster=st)
            ours = np.where(res.winner >= 0, frags.prim_id[np.maximum(res.winner, 0)], -1)
            same = np.array_equal(ours, fr.prim_id)
            assert same == agree, (origin, fill, int(np.count_nonzero(ours != fr.prim_id)))
            if agree:
                assert np.array_equal(res.depth, fr.depth)


#: Planted faults: (convention, the wrong state, what it stands for).
PLANTED = [
    ("gl_upper_left_zero_to_one", dict(depth_range="negative_one_to_one"),
     "GL's depth remap (0.5·z/w + 0.5, clip at z = −w) on a zero-to-one projection"),
    ("gl_vulkan_ndc_y_down", dict(ndc_y="up"), "Vulkan's NDC y not negated"),
    ("gl_reversed_z_infinite", dict(depth_func="less"), "reversed-Z drawn with less"),
    ("gl_reversed_z_infinite", dict(clear_depth=1.0), "reversed-Z cleared to 1"),
    ("gl_depth_clamp", dict(depth_clamp=False), "near/far clipping kept under depth clamp"),
]


@pytest.mark.parametrize("name, fault, what", PLANTED, ids=[p[2] for p in PLANTED])
def test_planted_convention_faults_are_caught(name, fault, what):
    gl = _gl()
    conv = CONVENTIONS[name]
    bad = conv.state.replace(**fault)
    picks = [sc for sc in L.SCENES if L.counted(sc)
             and (name != "gl_depth_clamp" or "near1" in sc.name)][:4]
    results = [compare(sc, conv, gl, state=bad) for sc in picks]
    ok, agreement, why = L._check(results)
    assert not ok, f"the planted fault ({what}) passed the check"


def test_agreement_table_in_docs():
    """docs/backends.md's llvmpipe table is this run's (``docs/scripts/convention_agreement_
    tables.py`` measures and rewrites it)."""
    _gl()
    tables = L.agreement_tables_script()
    text = tables.BACKENDS_MD.read_text(encoding="utf-8")
    new = tables.table("llvmpipe")
    assert tables.replaced(text, "llvmpipe", new) == text, (
        "docs/backends.md's llvmpipe agreement table differs from this run; run python "
        "docs/scripts/convention_agreement_tables.py and review the change\n" + new)
