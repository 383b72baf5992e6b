"""Hostile numbers (issue 48 items 3 and 6, docs/reliability.md "Limits"): a matrix scaled so
small that the vertex stage's products fall under the w plane or underflow is refused with one
line naming it, never rendered as a silently empty frame — and a scaled matrix that still
renders is not refused and gives the same frame; ``REFRASTER_POOL_MB`` of any value gives the
documented behaviour (no traceback)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import FB_FIELDS, camera_kw, mesh_of
import refraster as rf
from refraster import _scratch
from refraster.raster.primitive import W_EPS
from refraster.scenes import cube, icosphere

KW = camera_kw(64, 48)


@pytest.fixture(scope="module")
def box():
    return mesh_of(cube())


def _one_line(exc):
    text = str(exc.value)
    assert "\n" not in text and text, text
    return text


@pytest.mark.parametrize("prec", ["float32", "float64"])
@pytest.mark.parametrize("which, scale", [("proj", 1e-40), ("proj", 1e-35), ("proj", 1e-31), ("proj", 1e-46),
                                          ("view", 1e-40), ("view", 1e-35)])
def test_a_uniformly_scaled_matrix_under_the_w_plane_is_refused(box, prec, which, scale):
    kw = dict(KW)
    kw[which] = kw[which] * scale
    with pytest.raises(ValueError) as e:
        rf.render(box, **kw, raster=rf.RasterState(precision=prec))
    text = _one_line(e)
    assert text.startswith("proj @ view @ model ")
    assert ("underflows " + prec in text) or "below the w plane" in text, text
    with pytest.raises(ValueError):   # draw (the fragment stream) checks the same
        rf.draw(box, **kw, raster=rf.RasterState(precision=prec))


def test_the_float32_w_row_underflow_is_named(box):
    kw = dict(KW, proj=KW["proj"] * 1e-40)
    with pytest.raises(ValueError, match=r"^proj @ view @ model underflows float32: its w row's "
                                         r"largest entry is 3.12e-40, below the smallest "
                                         r"normal float32 1.18e-38; scale the matrices up"):
        rf.render(box, **kw)


def test_the_draw_call_whose_model_is_scaled_is_named(box):
    ico = mesh_of(icosphere(2))
    models = [np.eye(4), np.eye(4) * 1e-35]
    with pytest.raises(ValueError, match=r"^proj @ view @ model \(draw call 1\) scales clip "
                                         r"coordinates below the w plane: every vertex of "
                                         r"meshes\[1\]"):
        rf.render([box, ico], **KW, model=models)


@pytest.mark.parametrize("prec", ["float32", "float64"])
@pytest.mark.parametrize("exp", [-66, -96, 60])
def test_a_scaled_matrix_that_renders_is_not_refused_and_gives_the_same_frame(box, prec, exp):
    """A power-of-two scale (exact in both precisions while nothing underflows) of the
    projection moves no window coordinate: the frame has the same bytes. 2**-96 ≈ 1.3e-29
    keeps the cube's w (about 3) above the 1e-30 w plane."""
    want = rf.render(box, **KW, raster=rf.RasterState(precision=prec))
    fb = rf.render(box, **dict(KW, proj=KW["proj"] * 2.0 ** exp),
                   raster=rf.RasterState(precision=prec))
    assert fb.mask.any()
    for f in FB_FIELDS:
        assert getattr(fb, f).tobytes() == getattr(want, f).tobytes(), f


def test_legitimate_edges_of_the_check_are_not_refused():
    """w exactly 0 at every vertex (a mesh in the eye's plane) is an empty frame, not an error;
    a mesh with some vertices under the w plane and some above renders what is above."""
    tri = (np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]),
           np.array([[0, 1, 2]]))
    proj = rf.perspective(60, 1.0, 0.1, 10)
    fb = rf.render(tri, view=np.eye(4), proj=proj, width=16, height=16)
    assert not fb.mask.any()
    # a draw call with one triangle under the w plane (|w| ~ 1e-31 at its three corners) and
    # one in front of the camera: drawn (the first clipped away, the second covering pixels)
    mixed = (np.array([[1e-31, 0.0, -1e-31], [0.0, 1e-31, -1e-31], [0.0, 0.0, -2e-31],
                       [-1.0, -1.0, -3.0], [1.0, -1.0, -3.0], [0.0, 1.0, -3.0]]),
             np.array([[0, 1, 2], [3, 4, 5]]))
    fb = rf.render(mixed, view=np.eye(4), proj=proj, width=32, height=32)
    assert fb.mask.any() and set(np.unique(fb.prim_id)) == {-1, 1}
    assert W_EPS == 1e-30


@pytest.mark.parametrize("raw, want_mb", [
    ("1e308", _scratch.MAX_POOL_MB), ("-1e308", 0.0), ("1e400", _scratch.POOL_MB),
    ("nan", _scratch.POOL_MB), ("9" * 400, _scratch.POOL_MB), ("-5", 0.0), ("1e15", 1e15),
    ("0x10", _scratch.POOL_MB), ("  64  ", 64.0)])
def test_pool_mb_of_any_value_gives_the_documented_limit(monkeypatch, box, raw, want_mb):
    monkeypatch.setenv("REFRASTER_POOL_MB", raw)
    limit = _scratch._pool_limit()
    assert isinstance(limit, int) and limit == int(min(want_mb, _scratch.MAX_POOL_MB) * 2 ** 20)
    rf.render(box, **camera_kw(256, 192)).color
    _scratch.OUTPUTS.clear()


def test_pool_mb_1e308_leaves_the_commands_working():
    env = dict(os.environ, REFRASTER_POOL_MB="1e308")
    proc = subprocess.run([sys.executable, "-m", "refraster.cli", "info"], env=env,
                          capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    rows = dict(line.split(":", 1) for line in proc.stdout.splitlines() if ":" in line)
    assert rows["output pool"].strip().startswith("up to 8.38861e+06 MiB"), rows["output pool"]


@pytest.mark.parametrize("normals", ["flat", "smooth"])
def test_an_empty_mesh_is_an_empty_frame(box, normals):
    """Found by the fuzz harness: smooth normals of a mesh with no faces raised "memoryview:
    cannot cast view with zeros in shape or strides" (its cache key)."""
    for mesh in [(np.zeros((5, 3)), np.zeros((0, 3), np.int64)),
                 (np.zeros((0, 3)), np.zeros((0, 3), np.int64))]:
        fb = rf.render(mesh, **KW, raster=rf.RasterState(normals=normals))
        assert not fb.mask.any()
        fb = rf.render([box, mesh], **KW, raster=rf.RasterState(normals=normals))
        assert fb.mask.any()


def test_from_fragments_checks_its_background(box):
    """Found by the fuzz harness: render refused a NaN background, from_fragments used it."""
    frags = rf.draw(box, **KW)
    with pytest.raises(ValueError, match=r"^background contains 1 non-finite value"):
        rf.Framebuffer.from_fragments(frags, rf.resolve(frags), background=(np.nan, 0, 0))


@pytest.mark.parametrize("exp", [127, 128, 140])
def test_a_float64_stage_beyond_the_float32_divide_is_refused(box, exp):
    """Found by the fuzz harness: with precision="float64", a view scaled by 2**127 (clip w
    ~ 1.4e38, x beyond float32's 3.4e38) reached the float32 perspective divide as inf and
    the frame was silently empty; 2**126 still renders the same frame."""
    f64 = rf.RasterState(precision="float64")
    want = rf.render(box, **KW, raster=f64)
    same = rf.render(box, **dict(KW, view=KW["view"] * 2.0 ** 126), raster=f64)
    assert same.prim_id.tobytes() == want.prim_id.tobytes() and want.mask.any()
    with pytest.raises(ValueError, match=r"^meshes\[0\]: clip coordinates exceed float32 where "
                                         r"the perspective divide"):
        rf.render(box, **dict(KW, view=KW["view"] * 2.0 ** exp), raster=f64)


def test_a_huge_mesh_clipped_away_in_float64_is_not_refused():
    """Vertices far beyond float32 that every clip plane removes never reach the divide: a
    box of 1e300 around the camera is an empty frame in float64, not an error."""
    import trimesh
    b = trimesh.creation.box()
    fb = rf.render((np.asarray(b.vertices) * 1e300, np.asarray(b.faces)),
                   view=rf.look_at((3.0, 2.0, 4.0), (0.0, 0.0, 0.0)),
                   proj=rf.perspective(40.0, 4 / 3, 1.0, 20.0), width=32, height=24,
                   raster=rf.RasterState(precision="float64"))
    assert not fb.mask.any()


@pytest.mark.parametrize("prec", ["float32", "float64"])
@pytest.mark.parametrize("which, scale", [("proj", 1e300), ("view", 1e300), ("proj", 1e-300),
                                          ("view", 1e155), ("both", 1e300)])
def test_huge_and_tiny_matrices_give_one_line_and_no_warning(box, prec, which, scale):
    """Found by the fuzz harness: 1e300 matrices gave NumPy overflow warnings (errors under
    this suite's filterwarnings) before the refusal, and an invertible projection whose
    determinant overflows was called singular. The warnings filter is 'error' here, so a
    warning escaping would fail the test as a RuntimeWarning."""
    kw = dict(KW)
    for name in (("proj", "view") if which == "both" else (which,)):
        kw[name] = kw[name] * scale
    with pytest.raises(ValueError) as e:
        rf.render(box, **kw, raster=rf.RasterState(precision=prec))
    text = _one_line(e)
    assert "singular" not in text, text


def test_the_w_plane_check_decides_on_every_vertex(box):
    """``_check_w`` looks no further than the first vertex when its |w| reaches the w plane
    (the largest |w| then does too), else at every vertex: refused only when every |w| is below
    the plane and one is not 0."""
    from refraster.raster import W_EPS, _check_w
    def clip(*ws):
        c = np.ones((len(ws), 4))
        c[:, 3] = ws
        return c
    meshes = [box]
    _check_w(clip(5.0, 1e-40, 0.0), [0, 3], meshes, "float64")
    _check_w(clip(1e-40, 0.0, -W_EPS), [0, 3], meshes, "float64")
    _check_w(clip(0.0, 0.0, 0.0), [0, 3], meshes, "float64")
    for ws in [(1e-31, 0.0, 1e-35), (0.0, 0.0, -1e-31), (-1e-31, 2e-31, 0.5 * W_EPS)]:
        with pytest.raises(ValueError, match="below the w plane"):
            _check_w(clip(*ws), [0, 3], meshes, "float64")
